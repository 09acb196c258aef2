"""Run an element-wise or row-local job over horizontal bands of an image, in threads.

NumPy ufuncs release the GIL on large arrays, so splitting a whole-image pass into row
bands and running them in a thread pool uses every core without copying the image (each
band writes its own rows of a shared output). On 2 cores this halves the sRGB curves and
the final clipping of a 12 MP photo. (The alignment warp needs none of this: OpenCV's
``remap`` threads itself.)
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from typing import Callable

from .fftutils import usable_cpus

__all__ = ["for_row_bands", "MIN_BAND_ROWS"]

#: Bands shorter than this are not worth a thread (per-call overhead ~50 us).
MIN_BAND_ROWS: int = 64


def for_row_bands(job: Callable[[int, int], object], rows: int, *,
                  workers: int | None = None, min_rows: int = MIN_BAND_ROWS) -> None:
    """Call ``job(r0, r1)`` for consecutive row ranges covering ``0 .. rows``.

    Parameters
    ----------
    job : callable
        ``job(r0, r1)`` processes rows ``r0:r1`` (half-open). Jobs run concurrently and
        must only write rows of their own band.
    rows : int
        Number of rows to cover.
    workers : int, optional
        Threads (default :func:`gyrodeblur.fftutils.usable_cpus`, one per core). The rows
        are split into ``workers`` equal bands (fewer when bands would be shorter than
        ``min_rows``); with one band the job runs in the calling thread.
    min_rows : int
        Smallest band worth a thread.

    Examples
    --------
    >>> seen = []
    >>> for_row_bands(lambda a, b: seen.append((a, b)), 10, workers=2, min_rows=1)
    >>> sorted(seen)
    [(0, 5), (5, 10)]
    """
    workers = usable_cpus() if workers is None else max(1, int(workers))
    n = max(1, min(workers, rows // max(1, min_rows)))
    if n == 1:
        job(0, rows)
        return
    edges = [rows * k // n for k in range(n + 1)]
    with ThreadPoolExecutor(max_workers=n) as pool:
        for fut in [pool.submit(job, a, b) for a, b in zip(edges[:-1], edges[1:])]:
            fut.result()
