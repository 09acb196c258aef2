"""What the Python API promises a researcher building their own pipeline: values in
[0, 1], a simulate -> deblur round trip in one transfer curve, methods of one's own, and
options that apply (or are refused)."""

import threading

import numpy as np
import pytest
from scipy import ndimage

from gyrodeblur.deblur import METHODS, deblur, register_method
from gyrodeblur.errors import InputError
from gyrodeblur.metrics import psnr, ssim
from gyrodeblur.simulate import simulate_blur


@pytest.fixture
def scene():
    """A textured grey scene (smooth blobs and edges), 96 x 128."""
    rng = np.random.default_rng(3)
    y, x = np.mgrid[0:96, 0:128]
    u = 0.5 + 0.25 * np.sin(x / 5.0) * np.cos(y / 7.0)
    u[30:60, 40:90] += 0.2
    return np.clip(u + 0.02 * rng.standard_normal(u.shape), 0, 1).astype(np.float32)


@pytest.fixture
def own_method():
    """Registers methods for one test and removes them afterwards."""
    names = []

    def add(name, factory, **kw):
        names.append(name)
        register_method(name, factory, **kw)

    yield add
    for name in names:
        METHODS.pop(name, None)


def test_photos_far_below_black_are_refused(scene, make_capture):
    cap = make_capture([0.0, 0.4, 0.1], width=128, height=96, f=120.0)
    blurred = simulate_blur(scene, cap, transfer="linear")
    for bad in (blurred - 0.5, -255 * blurred):
        with pytest.raises(InputError, match="values down to .*below black"):
            deblur(bad, cap)
    slight = blurred.copy()
    slight[0, 0] = -0.01                      # a little undershoot from earlier processing
    assert deblur(slight, cap).min() >= 0


def test_metrics_refuse_0_255_floats_and_leave_alpha_out(scene):
    other = np.clip(scene + 0.05, 0, 1)
    with pytest.raises(InputError, match="values up to 2[0-9][0-9]"):
        psnr(scene * 255, other * 255)
    with pytest.raises(InputError, match="values up to 2[0-9][0-9]"):
        ssim(scene * 255, other * 255)
    alpha = np.ones_like(scene)[..., None]
    grey = psnr(scene, other)
    assert psnr(np.dstack([scene, alpha]), np.dstack([other, alpha])) == pytest.approx(grey)
    rgb, rgb2 = np.dstack([scene] * 3), np.dstack([other] * 3)
    assert psnr(np.dstack([rgb, alpha]), np.dstack([rgb2, alpha])) == pytest.approx(grey)


def test_simulate_with_the_srgb_curve_is_what_deblur_expects(scene, make_capture):
    """``simulate_blur`` blurs light; given an sRGB photo and ``transfer="srgb"`` (its
    default, as ``deblur``'s) it decodes, blurs and encodes, so the default ``deblur``
    undoes the default blur; blurring the encoded values as light (``"linear"`` on an
    sRGB photo) does not match it."""
    from gyrodeblur.tonecurve import linear_to_srgb, srgb_to_linear

    cap = make_capture([0.2, 0.5, 0.1], width=128, height=96, f=120.0)
    y, x = np.mgrid[0:96, 0:128]
    scene = np.where((x // 16 + y // 16) % 2, 0.9, 0.05)                     # contrast,
    scene = ndimage.gaussian_filter(scene, 1.5).astype(np.float32)  # edges a lens passes
    by_hand = linear_to_srgb(simulate_blur(srgb_to_linear(scene), cap, transfer="linear"))
    assert np.allclose(simulate_blur(scene, cap, transfer="srgb"), by_hand, atol=1e-5)
    matched = psnr(scene, deblur(simulate_blur(scene, cap), cap), 12)       # the defaults
    assert np.array_equal(simulate_blur(scene, cap), simulate_blur(scene, cap, transfer="srgb"))
    mismatched = psnr(scene, deblur(simulate_blur(scene, cap, transfer="linear"), cap), 12)
    assert matched > mismatched + 1.0, (matched, mismatched)
    with pytest.raises(InputError, match="transfer"):
        simulate_blur(scene, cap, transfer="gamma 2.2")


def test_simulated_srgb_photos_hold_no_light_below_black_and_deblur_takes_them(make_capture):
    """Hard 0/1 edges (the cubic spline undershoots beside them) and strong noise near
    black give a little negative light; encoded by sRGB's 12.92 foot it came out far
    below black (-0.36), and ``deblur`` refused the photo it had been told to expect.
    An encoded result holds no light below black; a linear one keeps its undershoot."""
    cap = make_capture([0.0, 0.5, 0.0], width=96, height=64, f=100.0)
    y, x = np.mgrid[0:64, 0:96]
    checker = ((x // 8 + y // 8) % 2).astype(np.float32)
    linear = simulate_blur(checker, cap, transfer="linear")
    assert linear.min() < -0.01                                # the spline's undershoot
    for out in (simulate_blur(checker, cap, transfer="srgb"),
                simulate_blur(0.02 + 0.1 * checker, cap, transfer="srgb", snr_db=10, seed=1)):
        assert out.min() >= 0.0 and out.max() <= 1.5
        assert deblur(out, cap).shape == out.shape
    encoded = simulate_blur(checker, cap, transfer="srgb")
    from gyrodeblur.tonecurve import linear_to_srgb
    np.testing.assert_allclose(encoded, linear_to_srgb(np.maximum(linear, 0)), atol=1e-5)


def test_a_method_of_ones_own_gets_what_it_names(scene, make_capture, own_method):
    cap = make_capture([0.0, 0.4, 0.1], width=128, height=96, f=120.0)
    blurred = simulate_blur(scene, cap, transfer="linear")
    own_method("identity", lambda image, phi=0.01: (lambda sub, psf: sub))   # no `encoded`
    out = deblur(blurred, cap, method="identity", grid=(2, 2), align=False)
    assert np.allclose(out, blurred, atol=2e-3)          # the curve's round trip only
    seen = {}

    def factory(image, *, encoded, clip):
        seen.update(encoded=encoded.shape, clip=clip)
        return lambda sub, psf: sub

    own_method("names-them", factory)
    deblur(blurred, cap, method="names-them", grid=(2, 2), clip=False)
    assert seen == {"encoded": blurred.shape, "clip": False}
    with pytest.raises(TypeError, match="callable"):
        register_method("five", 5)
    own_method("nan", lambda image: (lambda sub, psf: sub * np.nan))
    with pytest.raises(ValueError, match="'nan' returned NaN"):
        deblur(blurred, cap, method="nan", grid=(2, 2))


def test_a_method_that_is_not_thread_safe_runs_its_patches_one_at_a_time(
        scene, make_capture, own_method, monkeypatch):
    cap = make_capture([0.0, 0.4, 0.1], width=128, height=96, f=120.0)
    blurred = simulate_blur(scene, cap, transfer="linear")
    busy = threading.Lock()
    overlaps = []

    def factory(image):
        def deconvolve(sub, psf):
            if not busy.acquire(blocking=False):
                overlaps.append(1)
                busy.acquire()
            try:
                threading.Event().wait(0.01)       # long enough for a second thread
                return sub
            finally:
                busy.release()
        return deconvolve

    own_method("serial", factory, thread_safe=False)
    deblur(blurred, cap, method="serial", grid=(3, 3))
    assert overlaps == []
    # nor from two deblur() calls in two threads: the state it keeps is the process's
    done = []

    def call():
        done.append(deblur(blurred, cap, method="serial", grid=(2, 2)).shape)

    calls = [threading.Thread(target=call) for _ in range(2)]
    for c in calls:
        c.start()
    for c in calls:
        c.join()
    assert overlaps == [] and done == [blurred.shape] * 2
    # the built-in sparse method registered so keeps its global model, whose patch-wise
    # start then solves its patches one at a time too
    import gyrodeblur.deblur as deblur_module

    sparse, patchwise, workers = METHODS["sparse"], deblur_module.deconvolve_patchwise, []

    def spy(*args, **kwargs):
        workers.append(kwargs.get("workers"))
        return patchwise(*args, **kwargs)

    monkeypatch.setattr(deblur_module, "deconvolve_patchwise", spy)
    alone = deblur(blurred, cap, grid=(2, 2), model="global")
    try:
        register_method("sparse", sparse, thread_safe=False)
        assert np.array_equal(deblur(blurred, cap, grid=(2, 2), model="global"), alone)
    finally:
        register_method("sparse", sparse)
    assert workers == [None, 1]
    # its flags are flags: "no" is not read as true (nor registered)
    for flag in ("thread_safe", "default"):
        with pytest.raises(TypeError, match=f"{flag} must be True or False, got 'no'"):
            register_method("said no", factory, **{flag: "no"})
    assert "said no" not in METHODS
    from gyrodeblur.fftutils import usable_cpus

    if usable_cpus() > 1:                # one core: no thread to overlap with
        own_method("parallel", factory)
        deblur(blurred, cap, method="parallel", grid=(3, 3))
        assert overlaps, "the default runs patches side by side (the test's own check)"


def test_a_method_that_writes_its_input_cannot_change_the_callers_photo(
        scene, make_capture, own_method):
    """A method whose ``deconvolve`` works in place on its sub-image works on the deblur's
    own copy, also in linear light (whose decoding is the caller's array itself), and the
    photo as given reaches its factory read-only."""
    cap = make_capture([0.0, 0.4, 0.1], width=128, height=96, f=120.0)
    seen = []

    def factory(image, encoded):
        seen.append(encoded.flags.writeable)

        def deconvolve(sub, psf):
            sub *= 0.5                                    # in place
            return sub
        return deconvolve

    own_method("in place", factory)
    for transfer in ("linear", "srgb"):
        photo = simulate_blur(scene, cap, transfer=transfer)
        kept = photo.copy()
        deblur(photo, cap, method="in place", transfer=transfer, grid=(2, 2))
        assert np.array_equal(photo, kept), transfer
    assert seen == [False, False]
    with pytest.raises(InputError, match="unknown method ''"):    # not the default
        deblur(photo, cap, method="")


def test_options_that_do_not_apply_are_refused_and_defaults_fit_the_photo(
        scene, make_capture):
    cap = make_capture([0.0, 0.4, 0.1], width=128, height=96, f=120.0)
    blurred = simulate_blur(scene, cap, transfer="linear")
    with pytest.raises(InputError, match="^grid: does not apply with mode='invariant'") as err:
        deblur(blurred, cap, mode="invariant", grid="bogus")
    assert err.value.argument                   # the command line would say --grid
    with pytest.raises(InputError, match="overlap: does not apply"):
        deblur(blurred, cap, mode="invariant", overlap=0.1)
    with pytest.raises(InputError, match="model: does not apply"):   # it was dropped
        deblur(blurred, cap, mode="invariant", model="global")
    with pytest.raises(TypeError, match="return_report must be True or False"):
        deblur(blurred, cap, return_report="no")                  # "no" returned a report
    for phi in (0, -1):                  # one rule, before any work
        with pytest.raises(InputError, match="^phi: must be a positive number"):
            deblur(blurred, cap, method="wiener", phi=phi)
    _, report = deblur(blurred, cap, grid="3x2", return_report=True)
    assert report.grid == (3, 2)
    small = make_capture([0.0, 0.04, 0.01], width=60, height=40, f=70.0)
    _, report = deblur(np.full((40, 60), 0.5, np.float32), small, method="wiener",
                       return_report=True)
    assert report.grid[0] < 6 and report.grid[1] < 8     # the chapter's 6 x 8 does not fit


def test_grey_plus_alpha_keeps_its_alpha(scene, make_capture):
    cap = make_capture([0.0, 0.4, 0.1], width=128, height=96, f=120.0)
    alpha = (np.indices(scene.shape).sum(0) % 2).astype(np.float32)
    la = np.dstack([scene, alpha])
    blurred = simulate_blur(la, cap, transfer="linear")
    assert np.array_equal(blurred[..., 1], alpha)
    assert np.array_equal(blurred[..., 0], simulate_blur(scene, cap, transfer="linear"))
    out = deblur(blurred, cap)
    assert out.shape == la.shape and np.array_equal(out[..., 1], alpha)
    assert np.array_equal(out[..., 0], deblur(blurred[..., 0], cap))


def test_psf_helpers_refuse_what_they_cannot_draw(make_capture):
    from gyrodeblur.psf import lanczos_splat, psf_extent, psf_variation, render_psf, splat, trace

    cap = make_capture([0.0, 0.4, 0.1], width=128, height=96, f=120.0)
    with pytest.raises(ValueError, match="offsets must be"):
        lanczos_splat(np.zeros((0, 2)))
    with pytest.raises(ValueError, match="one per point"):
        splat(np.zeros((2, 2)), weights=np.array([1.0]))
    assert splat(np.array([0.0, 0.0])).shape == (3, 3)        # one point, as (2,)
    with pytest.raises(ValueError, match="positive sample"):
        psf_extent(np.zeros((3, 3)))
    for n in (0, 2.5, True):
        with pytest.raises(ValueError, match="whole number of samples"):
            trace(cap, 10, 10, n)
    with pytest.raises(InputError, match="two numbers"):
        render_psf(cap, "10", 10)
    with pytest.raises(ValueError, match="probes"):
        psf_variation(cap, probes=(1, 1))


def test_logs_and_captures_are_hashable_and_refuse_complex_rates(make_capture):
    from gyrodeblur.gyrolog import GyroLog

    cap = make_capture([0.0, 0.4, 0.1])
    assert cap == cap and cap != cap.replace() and len({cap, cap.log}) == 2
    t = np.arange(5) * 0.01
    with pytest.raises(InputError, match="real numbers"):
        GyroLog(t, np.ones((5, 3)) * (1 + 1j))


def test_logs_captures_and_patch_windows_of_the_wrong_kind_are_named(scene, make_capture):
    """A log's meta and source, a capture's times given as True, and patches given as
    tuples: each refused by name at once (meta=None failed later inside ``rotated``,
    True read as one second, a tuple gave an AttributeError deep in the deblur)."""
    from pathlib import Path

    from gyrodeblur.deblur import deblur_with_psfs
    from gyrodeblur.gyrolog import GyroLog
    from gyrodeblur.tiling import Patch
    t, w = np.arange(5) * 0.01, np.zeros((5, 3))
    with pytest.raises(TypeError, match="GyroLog meta must be a mapping"):
        GyroLog(t, w, "g.csv", None)
    with pytest.raises(TypeError, match="GyroLog source must be a file name"):
        GyroLog(t, w, 5)
    meta = {"frame_readout_time": 20.0}
    log = GyroLog(t, w, Path("g.csv"), meta)
    meta["frame_readout_time"] = 1.0                     # the log keeps its own copy
    assert log.source == "g.csv" and log.meta == {"frame_readout_time": 20.0}
    assert log.rotated(np.eye(3)).meta == log.meta
    cap = make_capture([0.0, 0.4, 0.1], width=128, height=96, f=120.0)
    for name in ("exposure_time", "readout_time", "time_offset"):
        with pytest.raises(InputError, match=f"{name} must be a number, got True"):
            cap.replace(**{name: True})
    psf = np.zeros((5, 5), np.float32)
    psf[2] = 0.2
    with pytest.raises(TypeError, match="must be gyrodeblur.tiling.Patch windows"):
        deblur_with_psfs(scene, [(0, 96, 0, 128)], [psf])
    with pytest.raises(TypeError, match="whole numbers of pixels"):
        deblur_with_psfs(scene, [Patch(0.0, 96.0, 0, 128)], [psf])
    with pytest.raises(ValueError, match="is empty or leaves the 96x128 image"):
        deblur_with_psfs(scene, [Patch(0, 100, 0, 128)], [psf])
    out = deblur_with_psfs(scene, [Patch(0, 96, 0, 128)], [psf])
    assert out.shape == scene.shape
    streak = np.zeros((3, 201), np.float32)            # light over 201 px: another photo's
    streak[1] = 1.0
    with pytest.raises(InputError, match="PSF 1 spreads light over 201 px, more than the "
                                         "128x96 photo"):
        deblur_with_psfs(scene, [Patch(0, 96, 0, 128)], [streak])
    streak[1, :67] = 0.0              # 134 px: a blur as long as the photo, and its lobes
    assert deblur_with_psfs(scene, [Patch(0, 96, 0, 128)], [streak]).shape == scene.shape


def test_arguments_of_the_wrong_kind_are_refused_before_any_work(scene, make_capture):
    cap = make_capture([0.0, 0.4, 0.1], width=128, height=96, f=120.0)
    blurred = simulate_blur(scene, cap, transfer="linear")
    # None is not a transfer curve (it read as "none", i.e. linear, instead of the default)
    with pytest.raises(InputError, match="transfer curve is a name"):
        deblur(blurred, cap, transfer=None)
    with pytest.raises(InputError, match="transfer curve is a name"):
        simulate_blur(scene, cap, transfer=None)
    # a flag given as a string is truthy: "no" clipped the output
    for kw in ({"clip": "no"}, {"align": "yes"}, {"clip": 1}):
        with pytest.raises(TypeError, match=f"{next(iter(kw))} must be True or False"):
            deblur(blurred, cap, **kw)
    with pytest.raises(TypeError, match="quantize must be True or False"):
        simulate_blur(scene, cap, quantize="no", transfer="linear")
    calls = []
    with pytest.raises(TypeError, match="progress must be a callable"):
        deblur(blurred, cap, progress=5)
    deblur(blurred, cap, progress=lambda done, total: calls.append((done, total)))
    assert calls and calls[-1][0] == calls[-1][1]
    # a capture left out
    from gyrodeblur.psf import (displacement_field, landing_pixel, psf_variation, render_psf,
                                trace)
    for call in (lambda: simulate_blur(scene, None, transfer="linear"),
                 lambda: render_psf(None, 10, 10),
                 lambda: trace(None, 10.0, 10.0, 3), lambda: deblur(blurred, {"fx": 1}),
                 lambda: landing_pixel(None, 10, 10), lambda: psf_variation({"fx": 1}),
                 lambda: displacement_field("capture.json")):
        with pytest.raises(TypeError, match="capture must be a Capture"):
            call()
    # simulate's numbers, named
    with pytest.raises(TypeError, match="snr_db must be a number"):
        simulate_blur(scene, cap, snr_db="abc", transfer="linear")
    with pytest.raises(TypeError, match="snr_db must be a number"):
        simulate_blur(scene, cap, snr_db=[40], transfer="linear")
    with pytest.raises(TypeError, match="seed must be a whole number"):
        simulate_blur(scene, cap, snr_db=40, seed="x", transfer="linear")
    assert np.array_equal(simulate_blur(scene, cap, snr_db=40, seed=[1, 2], transfer="linear"),
                          simulate_blur(scene, cap, snr_db=40, seed=[1, 2], transfer="linear"))


def test_simulate_refuses_encoded_photos_that_are_offset_negated_or_unscaled(
        scene, make_capture):
    cap = make_capture([0.0, 0.4, 0.1], width=128, height=96, f=120.0)
    for bad in (scene - 0.5, -scene):
        with pytest.raises(InputError, match="below black"):
            simulate_blur(bad, cap, transfer="srgb")
    with pytest.raises(InputError, match="values up to 2[0-9][0-9]"):
        simulate_blur(scene * 255, cap, transfer="srgb")
    # linear values are blurred as they are: the warp is linear in them
    hdr = scene.copy()
    hdr[40:44, 60:64] = 20.0                 # a light far above 1
    out = simulate_blur(hdr, cap, order=1, transfer="linear")
    assert out.max() > 1.5
    assert np.allclose(simulate_blur(scene - 0.5, cap, transfer="linear"),
                       simulate_blur(scene, cap, transfer="linear") - 0.5, atol=1e-5)


def test_psf_positions_and_timing_rows_are_checked(make_capture):
    from gyrodeblur.psf import render_psf, trace
    cap = make_capture([0.0, 0.4, 0.1], width=128, height=96, f=120.0)
    with pytest.raises(InputError, match="pixel position must be finite"):
        trace(cap, np.nan, 10.0, 3)
    for row in (np.nan, "a", 24000, -3):
        with pytest.raises(InputError, match="row must be"):
            render_psf(cap, 64, 48, row=row)
        with pytest.raises(InputError, match="row must be"):
            trace(cap, 64.0, 48.0, 3, row=row)
    assert render_psf(cap, 64, 48, row=47.5).sum() == pytest.approx(1.0, abs=1e-5)
    # a frame row's timing is used: row 0's under a rolling shutter is the global shutter's
    rolling = make_capture([0.0, 2.0, 0.0], width=128, height=96, f=120.0, readout=0.02)
    global_ = make_capture([0.0, 2.0, 0.0], width=128, height=96, f=120.0)
    at_row0 = trace(rolling, 64.0, 48.0, 5, row=0)
    assert np.allclose(at_row0, trace(global_, 64.0, 48.0, 5), atol=0.05)
    # its own row starts 10 ms later: the yaw has moved its light 2.4 px further to -x
    shift = trace(rolling, 64.0, 48.0, 5) - at_row0
    assert np.allclose(shift[:, 0], -120.0 * 2.0 * 0.01, atol=0.1)


def test_flags_and_numbers_of_the_solvers_are_checked_by_name():
    """Found by a hunt: "no" read as true, and numbers the solvers cannot hold, were taken
    without a word (a NaN image, a silently truncated order, a TypeError from inside)."""
    from gyrodeblur.sparse import sparse_deconvolve
    from gyrodeblur.wiener import wiener_deconvolve

    img = np.random.default_rng(0).random((32, 40)).astype(np.float32)
    psf = np.full((1, 3), 1 / 3)
    for name in ("taper", "normalize"):
        with pytest.raises(TypeError, match=name):
            wiener_deconvolve(img, psf, **{name: "no"})
    with pytest.raises(TypeError, match="clip"):
        sparse_deconvolve(img, psf, noise_sigma=0.01, clip="no")
    for weight in (1e38, 1e-42):
        with pytest.raises(ValueError, match="weight"):
            sparse_deconvolve(img, psf, weight=weight)
    for dilation in ("2", -1, 1.5):
        with pytest.raises(ValueError, match="saturation_dilation"):
            sparse_deconvolve(img, psf, noise_sigma=0.01, saturation_dilation=dilation)


def test_render_psf_and_simulate_blur_check_their_options(make_capture):
    from gyrodeblur.psf import render_psf
    from gyrodeblur.simulate import simulate_blur

    cap = make_capture([0, 0.3, 0], width=64, height=48, f=60.0)
    with pytest.raises(TypeError, match="centred"):
        render_psf(cap, 10, 10, centred="no")
    img = np.random.default_rng(1).random((48, 64)).astype(np.float32)
    for order in (3.0, True):
        with pytest.raises(ValueError, match="order"):
            simulate_blur(img, cap, order=order, transfer="linear")
    for snr in (1e308, -1e308):
        with pytest.raises(ValueError, match="snr_db"):
            simulate_blur(img, cap, snr_db=snr, transfer="linear")


def test_every_warning_of_the_library_is_its_own_category(tmp_path):
    """What the library warns of is a ``GyrodeblurWarning`` (a ``UserWarning``), so a
    pipeline can escalate this library's warnings alone: a log with a missing sample
    raises under ``simplefilter("error", GyrodeblurWarning)``. And every
    ``warnings.warn`` in the package names a category (this one, or DeprecationWarning for
    an ignored option), so none falls back to a plain UserWarning."""
    import ast
    import pathlib
    import warnings

    import gyrodeblur
    from gyrodeblur.errors import GyrodeblurWarning
    from gyrodeblur.gyrolog import read_gyro_log

    assert issubclass(GyrodeblurWarning, UserWarning)
    log = tmp_path / "g.csv"
    log.write_text("t_s,wx,wy,wz\n" + "".join(f"{i * 0.005:.3f},0.1,0.2,0.3\n"
                                             for i in range(40)) + "0.2,0.1,,0.3\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error", GyrodeblurWarning)
        with pytest.raises(GyrodeblurWarning, match="g.csv: 1 sample"):
            read_gyro_log(log)
    unnamed = []
    for path in pathlib.Path(gyrodeblur.__file__).parent.glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                    and node.func.attr == "warn" and getattr(node.func.value, "id", "") == "warnings"):
                category = node.args[1] if len(node.args) > 1 else next(
                    (k.value for k in node.keywords if k.arg == "category"), None)
                if getattr(category, "id", None) not in ("GyrodeblurWarning", "DeprecationWarning"):
                    unnamed.append(f"{path.name}:{node.lineno}")
    assert not unnamed
