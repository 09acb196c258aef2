"""The one exception type for input a user can fix.

Every problem with a user's file or option (unreadable photo, gyro log that does not
cover the exposure, bad axis mapping...) is raised as :class:`InputError`, whose message
names the file (or argument) and the problem in one line. The CLI prints that line and
exits with status 2; library users can catch it like any ``ValueError``.

What the library warns of (a blur the photo does not show, a log in a device's axes read
with a default mapping, clipped highlights...) comes as :class:`GyrodeblurWarning`, a
``UserWarning``, so a pipeline can filter or escalate this library's warnings alone
(``warnings.simplefilter("error", GyrodeblurWarning)``).

A bad keyword argument of a public function is named as the caller spelled it
(``kernel_size: must be odd``); the command line names the option that set it instead
(``--kernel-size: must be odd``).
"""

from __future__ import annotations

import os

__all__ = ["InputError", "GyrodeblurWarning"]


class InputError(ValueError):
    """Bad user input: a one-line message naming the source and the problem.

    Parameters
    ----------
    source : str or os.PathLike or None
        The file or option at fault (e.g. ``"gyro.csv"`` or ``"--grid"``), or with
        ``argument`` the keyword argument (``"grid"``); ``None`` when the problem is not
        tied to one source.
    problem : str
        What is wrong, phrased for the user, e.g. ``"timestamps are not increasing
        (row 12)"``.
    argument : bool
        Whether ``source`` is the name of a public function's keyword argument (see
        :meth:`of_argument`).
    """

    def __init__(self, source: str | os.PathLike | None, problem: str, *,
                 argument: bool = False):
        self.source = None if source is None else os.fspath(source)
        self.problem = problem
        self.argument = bool(argument) and self.source is not None
        super().__init__(problem if self.source is None else f"{self.source}: {problem}")

    @classmethod
    def of_argument(cls, name: str, problem: str) -> "InputError":
        """A bad value of the keyword argument ``name`` (as the function spells it, e.g.
        ``"kernel_size"``): the message reads ``kernel_size: problem``, and the command
        line names its option instead (``--kernel-size: problem``)."""
        return cls(name, problem, argument=True)

    def reworded(self, problem: str) -> "InputError":
        """The same source (a file, an option or an argument), another problem text."""
        return InputError(self.source, problem, argument=self.argument)


class GyrodeblurWarning(UserWarning):
    """Something the library noticed that may make its result wrong or worse than
    expected, though it could go on (a ``UserWarning``; the CLI prints it as
    ``gyrodeblur: warning: ...``)."""
