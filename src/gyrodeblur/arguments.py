"""Checks of the plain keyword arguments that the public functions take.

A flag given as ``"no"`` is truthy, a progress callback given as a number fails only
after the work has started, and ``float("abc")`` fails without naming the argument. These
helpers say which argument is wrong before any work is done.
"""

from __future__ import annotations

import numpy as np

__all__ = ["check_flag", "check_callback", "check_real", "check_seed", "is_whole",
           "is_count"]


def check_flag(value, name: str) -> bool:
    """``value`` as a ``bool``; a ``TypeError`` naming ``name`` for anything but a
    ``bool`` or ``numpy.bool_`` (``"no"`` and ``1`` are refused, not read as true)."""
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    raise TypeError(f"{name} must be True or False, got {value!r}")


def is_whole(value) -> bool:
    """Whether ``value`` is a whole number: a Python or numpy integer, not a ``bool``
    (``True`` is an ``int``, and ``3.0`` or ``"3"`` are not whole numbers here). The
    callers add their own range and message."""
    return not isinstance(value, bool) and isinstance(value, (int, np.integer))


def is_count(value) -> bool:
    """Whether ``value`` is a whole number (:func:`is_whole`) >= 1: a count of iterations,
    samples, workers or pixels. The callers add their own message."""
    return is_whole(value) and value >= 1


def check_callback(value, name: str):
    """``value`` unchanged when it is ``None`` or callable, else a ``TypeError``."""
    if value is None or callable(value):
        return value
    raise TypeError(f"{name} must be a callable or None, got {value!r}")


def check_real(value, name: str, *, allow_inf: bool = False) -> float:
    """``value`` as a ``float``; a ``TypeError`` naming ``name`` for anything but a real
    number (a ``bool``, a string or a list is refused), a ``ValueError`` for NaN (and for
    an infinity unless ``allow_inf``)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer,
                                                                      np.floating)):
        raise TypeError(f"{name} must be a number, got {value!r}")
    x = float(value)
    if np.isnan(x) or (np.isinf(x) and not allow_inf):
        raise ValueError(f"{name} must be a finite number, got {value!r}")
    return x


def check_seed(value, name: str = "seed"):
    """``value`` unchanged when :func:`numpy.random.default_rng` takes it (a whole number
    >= 0 or a sequence of them, a ``Generator``, ``BitGenerator`` or ``SeedSequence``, or
    ``None``), else a ``TypeError`` naming ``name`` (a ``bool`` is refused, not read as 0
    or 1)."""
    try:
        if isinstance(value, (bool, np.bool_)):
            raise TypeError
        np.random.default_rng(value)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be a whole number >= 0 (or a sequence of them), a numpy "
                        f"Generator or SeedSequence, or None, got {value!r}") from None
    return value
