"""Row-band threading: every row once, and whole-image jobs unchanged by the split."""

import threading

import numpy as np
import pytest

from gyrodeblur.bands import for_row_bands
from gyrodeblur.tonecurve import linear_to_srgb, srgb_to_linear


@pytest.mark.parametrize("rows, workers, min_rows", [(10, 2, 1), (7, 3, 1), (100, 4, 64), (1, 2, 1)])
def test_bands_cover_every_row_once(rows, workers, min_rows):
    hits = np.zeros(rows, int)

    def job(a, b):
        hits[a:b] += 1

    for_row_bands(job, rows, workers=workers, min_rows=min_rows)
    assert (hits == 1).all()


def test_band_errors_reach_the_caller():
    def job(a, b):
        raise RuntimeError(f"rows {a}:{b}")

    with pytest.raises(RuntimeError, match="rows"):
        for_row_bands(job, 200, workers=2, min_rows=1)


def test_threaded_curves_match_per_element_formula():
    rng = np.random.default_rng(4)
    x = rng.uniform(-0.1, 1.2, (513, 77, 3)).astype(np.float32)
    a = np.abs(x.astype(np.float64))
    lin = np.where(a <= 0.04045, a / 12.92, ((a + 0.055) / 1.055) ** 2.4) * np.sign(x)
    np.testing.assert_allclose(srgb_to_linear(x), lin, rtol=2e-6, atol=1e-7)
    np.testing.assert_allclose(linear_to_srgb(srgb_to_linear(x)), x, atol=2e-6)
    assert srgb_to_linear(np.float32(0.5)).shape == ()
    view = x[:, ::2]  # not contiguous
    np.testing.assert_array_equal(srgb_to_linear(view), srgb_to_linear(view.copy()))


def test_curves_accept_empty_arrays():
    assert srgb_to_linear(np.zeros((0, 4, 3), np.float32)).shape == (0, 4, 3)
    assert linear_to_srgb(np.array([], np.float32)).shape == (0,)


def test_bands_are_equal_split_by_workers_and_min_rows():
    """``workers`` equal bands, fewer when they would be shorter than ``min_rows``; several
    bands run in the pool's threads, a single band in the calling thread; no ``workers``
    means one per FFT worker."""
    import gyrodeblur.bands as bands_mod

    def run(rows, **kw):
        seen = []
        for_row_bands(lambda a, b: seen.append((a, b, threading.get_ident())), rows, **kw)
        return sorted(s[:2] for s in seen), {s[2] for s in seen}

    me = threading.get_ident()
    got, threads = run(10, workers=2, min_rows=1)
    assert got == [(0, 5), (5, 10)] and me not in threads
    got, threads = run(200, workers=4, min_rows=64)              # 200 // 64: three bands
    assert got == [(0, 66), (66, 133), (133, 200)] and me not in threads
    assert run(100, workers=4, min_rows=64) == ([(0, 100)], {me})   # one band: no thread
    assert run(7, workers=0, min_rows=1) == ([(0, 7)], {me})
    old = bands_mod.usable_cpus
    try:
        bands_mod.usable_cpus = lambda: 3
        assert run(9, min_rows=1)[0] == [(0, 3), (3, 6), (6, 9)]
    finally:
        bands_mod.usable_cpus = old
