"""Writing output files whole or not at all, and checking beforehand that they can be.

Every file the library writes (photos, PSF arrays, capture descriptions) goes through
:func:`atomic_write`: into a hidden temporary file with a random name beside the
destination, then moved into place with :func:`os.replace`. An interrupted or failed write
(Ctrl-C, SIGTERM, a full disk) leaves the destination as it was and no temporary file;
an existing file of any other name is never touched. :func:`check_writable` probes the
destination's folder before the work, so that a folder the user may not write in is said
at once rather than after minutes of deblurring.
"""

from __future__ import annotations

import os
import secrets
import stat

from .errors import InputError

__all__ = ["atomic_write", "atomic_write_text", "check_writable", "check_folder_of"]


def _temporary_beside(path: str, kind: str) -> str:
    folder, name = os.path.split(os.path.abspath(path))
    return os.path.join(folder, f".{name}.{secrets.token_hex(4)}.{kind}")


def atomic_write(path: str | os.PathLike, write) -> None:
    """Run ``write(file)`` on a new binary file beside ``path``, then move it into place.

    Parameters
    ----------
    path : str or os.PathLike
        The destination (replaced if it exists: the caller decides whether it may be; the
        new file then takes the old one's permission bits).
    write : callable
        ``write(f)`` writes the whole content to the binary file object ``f``.

    Raises
    ------
    InputError
        The file cannot be written (permission, disk full...), naming ``path``.
    """
    path = os.fspath(path)
    tmp = _temporary_beside(path, "tmp")
    try:
        with open(tmp, "xb+") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        try:                           # a file written over keeps its permission bits
            os.chmod(tmp, stat.S_IMODE(os.stat(path).st_mode))
        except FileNotFoundError:
            pass
        os.replace(tmp, path)
    except BaseException as exc:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        if isinstance(exc, OSError) and exc.errno is not None:
            raise InputError(path, f"cannot write the file: {exc.strerror}") from exc
        raise


def atomic_write_text(path: str | os.PathLike, text: str) -> None:
    """:func:`atomic_write` of ``text``, UTF-8 encoded."""
    data = text.encode("utf-8")
    atomic_write(path, lambda f: f.write(data))


def check_writable(path: str | os.PathLike) -> None:
    """Check that a file can be created in ``path``'s folder, by creating and removing one.

    Raises
    ------
    InputError
        The folder does not exist, or refuses new files (permission, read-only file
        system), naming ``path``.
    """
    path = os.fspath(path)
    check_folder_of(path)
    folder = os.path.dirname(os.path.abspath(path))
    probe = _temporary_beside(path, "probe")
    try:
        fd = os.open(probe, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o600)
    except OSError as exc:
        raise InputError(path, f"cannot write in folder {folder}: "
                               f"{exc.strerror or exc}") from None
    os.close(fd)
    try:
        os.unlink(probe)
    except OSError:
        pass


def check_folder_of(path) -> None:
    """:class:`InputError` naming ``path`` unless the folder it would be written in exists
    (and is a folder, not a file of that name)."""
    folder = os.path.dirname(os.path.abspath(os.fspath(path)))
    if os.path.isdir(folder):
        return
    if os.path.exists(folder):
        raise InputError(os.fspath(path), f"{folder} is a file, not a folder")
    raise InputError(os.fspath(path), f"folder {folder} does not exist")
