"""The checks of plain keyword arguments (gyrodeblur.arguments), on their own: what each
accepts, what it hands back, and that what it refuses is named. The public functions'
use of them is tested in test_api_contracts.py; these tests come from a mutation audit
(session 47) of the helpers themselves."""

from __future__ import annotations

import numpy as np
import pytest

from gyrodeblur.arguments import check_callback, check_flag, check_real, check_seed, is_whole


def test_a_numpy_bool_is_a_flag_and_comes_back_as_a_python_bool():
    """Kills A1 (``numpy.bool_`` refused) and A3 (the flag handed back as given). A mask's
    ``.any()`` is a ``numpy.bool_``, a documented flag value; the caller gets ``True`` or
    ``False`` themselves, so ``flag is True`` and JSON encoding work."""
    for value, expected in ((np.bool_(True), True), (np.bool_(False), False),
                            (True, True), (False, False)):
        assert check_flag(value, "clip") is expected
    for bad in ("no", 1, 0, None, np.int64(1)):
        with pytest.raises(TypeError, match="clip must be True or False"):
            check_flag(bad, "clip")


def test_a_numpy_integer_is_a_whole_number_and_a_flag_or_a_float_is_not():
    """Kills A5 (numpy integers not whole numbers). An image's ``shape`` or an
    ``np.argmax`` gives numpy integers, which must pass where a Python ``int`` does;
    ``True``, ``3.0`` and ``"3"`` do not."""
    for value in (3, 0, -2, np.int64(3), np.int32(7), np.uint8(2)):
        assert is_whole(value), value
    for value in (True, False, np.bool_(True), 3.0, np.float64(3.0), "3", None, [3]):
        assert not is_whole(value), value


def test_a_real_number_of_any_numpy_type_is_taken_and_comes_back_as_a_float():
    """Kills A11 (``numpy.float32`` refused), A12 (numpy integers refused), A9 (``True``
    read as 1.0) and A18 (the number handed back as given, not as a float). The number
    comes back as a Python float of the same value."""
    for value, expected in ((np.float32(0.5), 0.5), (np.int64(3), 3.0), (np.uint16(7), 7.0),
                            (2, 2.0), (-1.25, -1.25), (np.float64(1e-3), 1e-3)):
        got = check_real(value, "snr_db")
        assert type(got) is float and got == expected, (value, got)
    for bad in (True, False, np.bool_(True), "40", [40], None, 1 + 0j):
        with pytest.raises(TypeError, match="snr_db must be a number"):
            check_real(bad, "snr_db")


def test_nan_is_always_refused_and_an_infinity_unless_allowed():
    """Kills A14 (``allow_inf`` ignored: an infinity always refused) and A15 (an infinity
    always allowed). NaN is never a value, whatever ``allow_inf`` says."""
    for allow in (False, True):
        with pytest.raises(ValueError, match="limit must be a finite number, got nan"):
            check_real(float("nan"), "limit", allow_inf=allow)
    for inf in (float("inf"), -np.inf, np.float32("inf")):
        with pytest.raises(ValueError, match="limit must be a finite number"):
            check_real(inf, "limit")
        assert check_real(inf, "limit", allow_inf=True) == float(inf)


def test_a_seed_numpy_refuses_is_a_type_error_naming_the_argument():
    """Kills A17 (numpy's ``ValueError`` for a negative seed let through unnamed). Anything
    :func:`numpy.random.default_rng` refuses is one ``TypeError`` naming the argument; what
    it takes is handed back unchanged."""
    for bad in (-1, [1, -2], "x", 1.5, np.bool_(False), True):
        with pytest.raises(TypeError, match=r"^noise_seed must be a whole number >= 0"):
            check_seed(bad, "noise_seed")
    gen = np.random.default_rng(4)
    for good in (0, 7, np.int64(3), [1, 2], None, gen, np.random.SeedSequence(5)):
        assert check_seed(good, "noise_seed") is good


def test_a_callback_is_a_callable_or_none():
    """``check_callback`` hands back ``None`` or a callable unchanged and refuses the rest
    (a number given as ``progress`` otherwise failed only after the work had started)."""
    assert check_callback(None, "progress") is None
    assert check_callback(print, "progress") is print
    for bad in (5, "print", [print]):
        with pytest.raises(TypeError, match="progress must be a callable or None"):
            check_callback(bad, "progress")
