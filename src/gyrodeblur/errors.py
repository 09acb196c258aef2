"""The one exception type for input a user can fix.

Every problem with a user's file or option (unreadable photo, gyro log that does not
cover the exposure, bad axis mapping...) is raised as :class:`InputError`, whose message
names the file (or option) and the problem in one line. The CLI prints that line and exits
with status 2; library users can catch it like any ``ValueError``.
"""

from __future__ import annotations

import os

__all__ = ["InputError"]


class InputError(ValueError):
    """Bad user input: a one-line message naming the source and the problem.

    Parameters
    ----------
    source : str or os.PathLike or None
        The file or option at fault (e.g. ``"gyro.csv"`` or ``"--grid"``); ``None`` when
        the problem is not tied to one source.
    problem : str
        What is wrong, phrased for the user, e.g. ``"timestamps are not increasing
        (row 12)"``.
    """

    def __init__(self, source: str | os.PathLike | None, problem: str):
        self.source = None if source is None else os.fspath(source)
        self.problem = problem
        super().__init__(problem if self.source is None else f"{self.source}: {problem}")
