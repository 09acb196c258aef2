"""Shared fixtures: synthetic captures and the shared test data folder."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from threadpoolctl import threadpool_limits

# Under pytest-xdist (``-n auto``) every core already runs a test, so each worker keeps to
# one CPU:
# - GYRODEBLUR_THREADS=1 (read as gyrodeblur is imported, so set before the imports
#   below): one FFT thread and row band (the deblurring tests took about 20 % less time on
#   2 cores, session 54), and ``calibrate`` takes one process. A calibration that forked a
#   worker per core besides would only crowd the cores, and would fork beside execnet's
#   reader thread, which :func:`gyrodeblur.calibration_workers._can_fork` cannot see (a
#   fork beside scipy's FFT threads hung one such run, session 50). A calibration's figures
#   do not depend on its worker count (``test_calibration_workers.py``, which still forks,
#   asks it).
# - NumPy's BLAS (loaded above; the calibration's matrix products and small solves) on one
#   thread: OpenBLAS starts a thread per core, and its threads spin while they wait, so two
#   workers' four threads on 2 cores fought for the CPUs (``tests/test_calibrate.py`` on 2
#   cores: 320 s, 205 s with one BLAS thread each; session 54). ``calibrate``'s own limit
#   stands aside here, beside execnet's thread.
if os.environ.get("PYTEST_XDIST_WORKER"):
    os.environ["GYRODEBLUR_THREADS"] = "1"
    threadpool_limits(1, user_api="blas")

from gyrodeblur.camera import Camera  # noqa: E402
from gyrodeblur.capture import Capture  # noqa: E402
from gyrodeblur.gyrolog import GyroLog  # noqa: E402

SHARED_DATA = Path(os.environ.get("GYRODEBLUR_SHARED_DATA",
                                  Path(__file__).resolve().parents[1].parent / "shared" / "data"))


@pytest.fixture
def shared_data() -> Path:
    """``../shared/data`` beside the checkout; tests using it skip when it is absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"shared test data not found at {SHARED_DATA}")
    return SHARED_DATA


def constant_rate_capture(rate, *, width=320, height=240, f=300.0, exposure=0.03,
                          readout=0.0, start=0.05, rate_hz=200.0, duration=0.2) -> Capture:
    """A capture whose camera turns at a constant ``rate`` (rad/s, camera frame)."""
    t = np.arange(0.0, duration, 1.0 / rate_hz)
    w = np.tile(np.asarray(rate, dtype=np.float64), (t.size, 1))
    return Capture(start, exposure, readout, Camera.centred(width, height, f), GyroLog(t, w))


@pytest.fixture
def make_capture():
    return constant_rate_capture
