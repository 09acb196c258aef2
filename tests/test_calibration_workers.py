"""Calibration steps side by side: the same results with any number of workers, messages
and basins in order, errors raised in the caller."""

from __future__ import annotations

import os
import sys

import numpy as np
import pytest

import gyrodeblur.calibration_workers as cw
from gyrodeblur.axes import parse_axes
from gyrodeblur.calibrate import calibrate
from gyrodeblur.calibration_workers import MAX_WORKERS, StepRunner, available_workers
from gyrodeblur.camera import Camera
from gyrodeblur.capture import Capture
from gyrodeblur.errors import InputError
from gyrodeblur.gyrolog import GyroLog
from gyrodeblur.simulate import add_noise, quantize_8bit, simulate_blur
from gyrodeblur.tonecurve import linear_to_srgb, srgb_to_linear

forks = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="workers fork (Linux)")


class _Spectra:
    """The state :func:`calibration_workers._run_step` holds and hands back."""

    def __init__(self):
        self.E, self.evaluations, self.fft_threads, self.fresh = None, 0, 2, 0

    def held_state(self):
        return (self.E, self.evaluations)

    def restore(self, state):
        self.E, self.evaluations = state

    def start_afresh(self):
        self.fresh += 1


class _Fit:
    def __init__(self):
        self.fine, self.coarse = _Spectra(), _Spectra()
        self.basins, self.said = [], []
        self.say = self.said.append

    def step(self, k):
        assert self.fine.E is None          # every step starts from the caller's state
        self.fine.E = f"held by step {k}"
        self.say(f"step {k} in {os.getpid()}")
        self.basins.append(k)
        self.fine.evaluations += k
        self.coarse.evaluations += 1
        return k * k

    def fail(self, name):
        raise InputError(name, "cannot be calibrated")

    def die_in_a_worker(self, parent, k, marker=None):
        if os.getpid() != parent:
            if marker is not None:
                open(f"{marker}.{k}", "w").close()
            os._exit(1)                     # as if killed (out of memory)
        return k


@pytest.mark.parametrize("workers", [1, 2, 3])
def test_steps_report_in_the_order_given_whoever_ran_them(workers):
    fit = _Fit()
    fit.basins.append("before")
    assert StepRunner(fit, workers).map("step", [(1,), (2,), (3,), (4,)]) == [1, 4, 9, 16]
    assert [m.split(" in ")[0] for m in fit.said] == ["step 1", "step 2", "step 3", "step 4"]
    assert fit.basins == ["before", 1, 2, 3, 4]
    assert fit.fine.evaluations == 10 and fit.coarse.evaluations == 4
    assert fit.fine.E is None               # what a step held is not left behind


@forks
def test_two_workers_run_the_steps_in_other_processes():
    fit = _Fit()
    StepRunner(fit, 2).map("step", [(1,), (2,)])
    pids = {int(m.split(" in ")[1]) for m in fit.said}
    assert os.getpid() not in pids


@pytest.fixture
def ctrl_c_live():
    """Ctrl-C raising ``KeyboardInterrupt``, as at a terminal, for the test's length: a
    suite run as a background job (``pytest &`` from a script) starts with SIGINT ignored,
    which Python keeps, and which the processes it starts inherit."""
    import signal
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


@forks
def test_an_interrupt_while_the_pool_is_made_waits_and_then_stops_the_batch(monkeypatch,
                                                                           ctrl_c_live):
    """Making the pool imports modules, and an interrupt that lands as an import lets go
    of its lock is dropped by Python ("Exception ignored in ... _get_module_lock"; the
    batch then ran on, 1 in about 350 signals at a batch's start, session 45). So SIGINT
    and SIGTERM are only recorded while the pool is made and forks its workers; one that
    came then stops the batch right after, and the workers are gone."""
    import signal
    real = cw.ProcessPoolExecutor
    before = (signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM))
    seen = []

    def made(*args, **kwargs):
        seen.append((signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)))
        signal.raise_signal(signal.SIGINT)                 # Ctrl-C as the pool is made
        return real(*args, **kwargs)

    def kill(pool):                     # the workers the batch forked, then killed
        workers.extend(p.pid for p in pool._processes.values())
        kill_workers(pool)

    workers, kill_workers = [], cw._kill_workers
    monkeypatch.setattr(cw, "ProcessPoolExecutor", made)
    monkeypatch.setattr(cw, "_kill_workers", kill)
    with pytest.raises(KeyboardInterrupt):
        StepRunner(_Fit(), 2).map("step", [(1,), (2,), (3,)])
    assert len(seen) == 1 and not set(seen[0]) & set(before)     # recorders, not handlers
    assert (signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)) == before
    assert len(workers) == 2
    _wait_until_gone(workers)


@forks
def test_beside_another_thread_the_steps_run_here():
    """A fork beside another running thread can deadlock (scipy's FFT pool held its lock
    in a worker under three calibrations in three threads), and two threads' batches
    would share the forked one: with other Python threads alive every step runs in the
    caller, with the same results; alone again, it forks."""
    import threading
    stop = threading.Event()
    other = threading.Thread(target=stop.wait)
    other.start()
    try:
        fit = _Fit()
        assert StepRunner(fit, 2).map("step", [(1,), (2,), (3,)]) == [1, 4, 9]
        assert {int(m.split(" in ")[1]) for m in fit.said} == {os.getpid()}
        results = {}

        def calibrate_in_a_thread(k):
            f = _Fit()
            results[k] = (StepRunner(f, 2).map("step", [(k,), (k + 1,)]), f.said)

        threads = [threading.Thread(target=calibrate_in_a_thread, args=(k,)) for k in (1, 5)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        assert results[1][0] == [1, 4] and results[5][0] == [25, 36]
        assert all(int(m.split(" in ")[1]) == os.getpid() for _, said in results.values()
                   for m in said)
    finally:
        stop.set()
        other.join()
    fit = _Fit()
    StepRunner(fit, 2).map("step", [(1,), (2,)])
    assert os.getpid() not in {int(m.split(" in ")[1]) for m in fit.said}


@pytest.mark.parametrize("workers", [1, 2])
def test_a_failing_step_raises_its_own_error_in_the_caller(workers):
    with pytest.raises(InputError, match="photo.png: cannot be calibrated"):
        StepRunner(_Fit(), workers).map("fail", [("photo.png",), ("photo.png",)])


@forks
def test_steps_a_dead_worker_left_undone_run_in_the_caller(tmp_path):
    marker = tmp_path / "died"
    steps = [(os.getpid(), 1, marker), (os.getpid(), 2, marker)]
    assert StepRunner(_Fit(), 2).map("die_in_a_worker", steps) == [1, 2]
    assert list(tmp_path.glob("died.*"))            # a worker did start, and died


@pytest.mark.parametrize("cpus, expected", [(1, 1), (3, 3), (8, MAX_WORKERS), (64, MAX_WORKERS)])
def test_available_workers_is_the_cpus_allowed_up_to_the_cap(monkeypatch, cpus, expected):
    monkeypatch.delenv("GYRODEBLUR_THREADS", raising=False)
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: set(range(cpus)), raising=False)
    assert available_workers() == expected


def test_workers_must_be_a_whole_number():
    img = np.zeros((64, 64), np.float32)
    cap = Capture(0.0, 0.01, 0.0, Camera.centred(64, 64, 60.0),
                  GyroLog(np.arange(0, 1, 0.005), np.zeros((200, 3))))
    for bad in (0, 1.5, True):
        with pytest.raises(InputError, match="^workers: "):
            calibrate([img], cap, workers=bad)


@forks
def test_a_calibration_is_the_same_with_one_worker_or_two(monkeypatch, tmp_path):
    """A warped 9 px shake, four candidate mappings: every figure and note alike (the last
    note, the time taken, aside), and the second run did use other processes."""
    from skimage import data, transform

    W, H = 320, 224
    t = np.arange(0.0, 1.2, 1 / 200)
    wc = np.stack([0.5 * np.sin(2 * np.pi * 3.1 * t + 0.4) + 0.2 * np.sin(2 * np.pi * 7.7 * t),
                   0.7 * np.cos(2 * np.pi * 2.3 * t + 1.0),
                   0.2 * np.sin(2 * np.pi * 4.3 * t + 0.7)], 1)
    true = Capture(0.5, 0.04, 0.03, Camera.centred(W, H, 1.3 * W), GyroLog(t, wc), axes="Xyz")
    sharp = transform.resize(data.astronaut(), (H, W), anti_aliasing=True).astype(np.float32)
    blurred = quantize_8bit(add_noise(linear_to_srgb(
        simulate_blur(srgb_to_linear(sharp), true, transfer="linear")), 40.0, 0))
    bad = true.replace(time_offset=0.012, readout_time=0.036, bias=np.array([0.02, -0.02, 0.0]),
                       axes=parse_axes("YXz"))
    kw = dict(mappings=["Xyz", "xYz", "YXz", "yXZ"], n_patches=6)

    run_step = cw._run_step
    ran = tmp_path / "pids"

    def spy(fit, method, args):            # in a worker too: it was forked with it
        with open(ran, "a") as f:
            f.write(f"{os.getpid()}\n")
        return run_step(fit, method, args)

    one = calibrate([blurred], bad, workers=1, **kw)
    monkeypatch.setattr(cw, "_run_step", spy)
    two = calibrate([blurred], bad, workers=2, **kw)
    assert set(ran.read_text().split()) - {str(os.getpid())}
    a, b = one.capture, two.capture
    assert (a.time_offset, a.readout_time, a.camera.fx) == (b.time_offset, b.readout_time, b.camera.fx)
    assert np.array_equal(a.bias, b.bias) and np.array_equal(a.axes, b.axes)
    assert one.notes[:-1] == two.notes[:-1] and one.ranking == two.ranking
    assert repr(one.estimates) == repr(two.estimates)


_SLEEPING_CALLER = r"""
import os, signal, sys, time
sys.path.insert(0, {tests!r})
from test_calibration_workers import _Fit
from gyrodeblur.calibration_workers import StepRunner

class Stop(BaseException):
    pass

def stop(signum, frame):
    raise Stop

class Sleepy(_Fit):
    def nap(self, folder, k):
        open(os.path.join(folder, f"worker{{k}}-{{os.getpid()}}"), "w").close()
        time.sleep(60)
        return k

signal.signal(signal.SIGTERM, stop)
signal.signal(signal.SIGINT, signal.default_int_handler)    # live even if started ignored
try:                                # the marker inside: a signal as it is written is caught
    open(os.path.join({folder!r}, "ready-0"), "w").close()
    StepRunner(Sleepy(), 2).map("nap", [({folder!r}, 1), ({folder!r}, 2), ({folder!r}, 3)])
    sys.exit(0)
except Stop:
    sys.stderr.write("terminated\n")
    sys.exit(143)
except KeyboardInterrupt:
    sys.stderr.write("interrupted\n")
    sys.exit(130)
"""


def _workers(folder) -> list[int]:
    """The pids of the workers that started a step (their marker files in ``folder``)."""
    return [int(p.name.split("-")[1]) for p in folder.glob("worker*")]


def _wait_until_gone(pids, seconds: float = 10.0) -> None:
    import time
    deadline = time.monotonic() + seconds
    while not all(_gone(p) for p in pids):
        assert time.monotonic() < deadline, "workers outlived their caller"
        time.sleep(0.05)


def _gone(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/status") as f:
            return any(line.split()[1:2] == ["Z"] for line in f if line.startswith("State:"))
    except FileNotFoundError:
        return True


@forks
@pytest.mark.parametrize("how", ["SIGTERM", "SIGKILL"])
def test_workers_do_not_outlive_a_caller_that_is_stopped(tmp_path, how):
    """A batch system's timeout: the caller is terminated (its SIGTERM handler raises, as
    the CLI's does) or killed outright while its workers run long steps. The workers go
    with it (killed, or by the kernel when their parent dies), rather than waiting for
    tasks forever with the caller's pipes open; the terminated caller does not wait for
    their steps either."""
    import signal
    import subprocess
    import time
    script = _SLEEPING_CALLER.format(tests=os.path.dirname(__file__), folder=str(tmp_path))
    child = subprocess.Popen([sys.executable, "-c", script])
    try:
        deadline = time.monotonic() + 60
        while len(list(tmp_path.glob("worker*"))) < 2:
            assert time.monotonic() < deadline and child.poll() is None, "no workers started"
            time.sleep(0.05)
        workers = _workers(tmp_path)
        t0 = time.monotonic()
        child.send_signal(getattr(signal, how))
        rc = child.wait(timeout=20)
        assert time.monotonic() - t0 < 10                 # not the steps' 60 s
        assert rc == (143 if how == "SIGTERM" else -signal.SIGKILL)
        _wait_until_gone(workers)
    finally:
        if child.poll() is None:
            child.kill()


@forks
@pytest.mark.parametrize("how", ["SIGTERM", "SIGINT"])
def test_a_signal_to_the_process_group_stops_a_batch_cleanly(tmp_path, how):
    """Ctrl-C, or a timeout that signals the whole process group, at any moment of a batch:
    while the pool forks its workers (an interrupt there was dropped, and the batch ran
    on), as its thread starts, or while the steps run. The caller stops at once with its
    own one line (no traceback from the pool's thread, no "Process ForkProcess" from a
    worker), and no worker is left."""
    import signal
    import subprocess
    import time
    sig = getattr(signal, how)
    for k, delay in enumerate((0.0, 0.001, 0.003, 0.01, 0.3)):
        folder = tmp_path / str(k)
        folder.mkdir()
        script = _SLEEPING_CALLER.format(tests=os.path.dirname(__file__), folder=str(folder))
        child = subprocess.Popen([sys.executable, "-c", script], stderr=subprocess.PIPE,
                                 text=True, start_new_session=True)
        try:
            deadline = time.monotonic() + 60
            while not (folder / "ready-0").exists():
                assert time.monotonic() < deadline and child.poll() is None, "no start"
                time.sleep(0.0005)
            time.sleep(delay)
            os.killpg(child.pid, sig)
            _, err = child.communicate(timeout=20)
            assert child.returncode == (143 if how == "SIGTERM" else 130), (delay, err)
            assert err == ("terminated\n" if how == "SIGTERM" else "interrupted\n"), (delay, err)
            _wait_until_gone(_workers(folder))
        finally:
            if child.poll() is None:
                os.killpg(child.pid, signal.SIGKILL)


# ------------------------------------------------ from a mutation audit (session 47)

class _WarmSpectra(_Spectra):
    """A criterion with a warm start: part of the state handed back, and cleared by
    ``start_afresh`` (as :class:`PatchSpectra`'s noise-ratio warm starts are)."""

    def __init__(self):
        super().__init__()
        self.warm = "the caller's warm start"

    def held_state(self):
        return (self.E, self.evaluations, self.warm)

    def restore(self, state):
        self.E, self.evaluations, self.warm = state

    def start_afresh(self):
        self.warm = None


class _WarmFit(_Fit):
    def __init__(self):
        super().__init__()
        self.fine, self.coarse = _WarmSpectra(), _WarmSpectra()

    def warm_step(self, k):
        seen = (self.fine.warm, self.coarse.warm, self.fine.fft_threads, os.getpid())
        self.fine.warm = self.coarse.warm = f"warmed by step {k}"
        self.fine.evaluations += k
        return seen

    def fail_in_a_worker(self, parent, k):
        if os.getpid() != parent:
            raise ValueError("a step that only fails in a worker")
        return k


@pytest.mark.parametrize("workers", [1, 2])
def test_every_step_starts_from_fresh_warm_starts_and_the_caller_s_come_back(workers):
    """Kills C6 and C7 (the fine or the coarse criterion's warm starts not cleared before
    a step) and C14 (a worker's FFTs not limited to one thread). Every step starts from
    the same state whatever ran before it, which is what makes one worker and several
    give the same figures; afterwards the caller's warm starts are as they were. In a
    worker the FFTs use one thread (the workers share the CPUs), the caller's own setting
    untouched."""
    fit = _WarmFit()
    fit.fine.warm = "the caller's fine warm start"
    seen = StepRunner(fit, workers).map("warm_step", [(1,), (2,), (3,)])
    assert [s[:2] for s in seen] == [(None, None)] * 3
    assert (fit.fine.warm, fit.coarse.warm) == ("the caller's fine warm start",
                                                "the caller's warm start")
    in_workers = [s[2] for s in seen if s[3] != os.getpid()]
    assert [s[2] for s in seen if s[3] == os.getpid()] == [2] * (3 - len(in_workers))
    assert in_workers == [1] * len(in_workers)
    if workers == 2 and sys.platform.startswith("linux"):
        assert in_workers                       # the worker case was seen
    assert fit.fine.fft_threads == 2


def _blas_threads() -> list[int]:
    from threadpoolctl import threadpool_info
    return [lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"]


class _BlasFit(_Fit):
    def blas_step(self, k):
        return os.getpid(), _blas_threads()


@forks
def test_a_worker_makes_its_blas_calls_on_one_thread():
    """Each worker's BLAS (OpenBLAS's threads, which spin while they wait) keeps to one
    thread: two workers with two BLAS threads each on two cores made the coarse ranking of
    a 12 MP photo 2.2 s instead of 1.0 (session 54). The caller's own setting stays."""
    from threadpoolctl import threadpool_limits
    import scipy.linalg  # noqa: F401  (scipy's BLAS loaded too)
    with threadpool_limits(2, user_api="blas"):
        before = _blas_threads()
        assert before and set(before) == {2}
        seen = StepRunner(_BlasFit(), 2).map("blas_step", [(1,), (2,), (3,)])
        assert _blas_threads() == before
    in_workers = [threads for pid, threads in seen if pid != os.getpid()]
    assert in_workers and all(t and set(t) == {1} for t in in_workers)


def test_a_calibration_keeps_blas_to_one_thread_and_gives_the_setting_back(monkeypatch):
    """The search's BLAS calls are small, and OpenBLAS's idle threads spin: ``calibrate``
    runs on one BLAS thread and restores the caller's setting after (also when it fails);
    beside another Python thread, whose BLAS shares the setting, it leaves it alone."""
    import threading

    import gyrodeblur.calibrate as cal
    from threadpoolctl import threadpool_limits
    import scipy.linalg  # noqa: F401  (scipy's BLAS loaded too)
    seen = []

    def search_space(*args, **kwargs):
        seen.append(_blas_threads())
        raise InputError(None, "stopped here")

    monkeypatch.setattr(cal, "SearchSpace", search_space)
    image = np.full((64, 64), 0.5, np.float32)
    capture = Capture(0.05, 0.03, 0.0, Camera.centred(64, 64, 60.0),
                      GyroLog(np.arange(0.0, 0.2, 0.005), np.zeros((40, 3))))
    with threadpool_limits(2, user_api="blas"):
        with pytest.raises(InputError, match="stopped here"):
            calibrate([image], capture)
        assert set(seen.pop()) == {1} and set(_blas_threads()) == {2}
        stop = threading.Event()
        other = threading.Thread(target=stop.wait)
        other.start()
        try:
            with pytest.raises(InputError, match="stopped here"):
                calibrate([image], capture)
        finally:
            stop.set()
            other.join()
        assert set(seen.pop()) == {2} and set(_blas_threads()) == {2}


@forks
def test_a_step_that_fails_in_a_worker_is_run_again_in_the_caller():
    """Kills C24 (a worker's error raised in the caller as it stands). A step that failed
    or died in a worker is run again here, so that an error is raised as it would be
    without workers (with its own traceback, and not at all when the failure was the
    worker's, as here)."""
    steps = [(os.getpid(), 1), (os.getpid(), 2)]
    assert StepRunner(_WarmFit(), 2).map("fail_in_a_worker", steps) == [1, 2]


@forks
def test_one_worker_or_a_batch_of_one_step_forks_nothing(monkeypatch):
    """Kills C25 (a pool forked for one worker) and C26 (a pool of two forked for one
    step). ``workers=1`` runs every step in this process, as documented, and a batch of
    one step has nothing to run beside it."""
    def no_pool(*args, **kwargs):
        raise AssertionError("a pool was made")

    monkeypatch.setattr(cw, "ProcessPoolExecutor", no_pool)
    for workers, steps in ((1, [(1,), (2,), (3,)]), (2, [(5,)]), (4, [(6,)])):
        fit = _Fit()
        assert StepRunner(fit, workers).map("step", steps) == [k * k for (k,) in steps]
        assert {int(m.split(" in ")[1]) for m in fit.said} == {os.getpid()}


@forks
def test_the_batch_is_let_go_after_it_has_run(tmp_path):
    """Kills C27 (``_BATCH`` left holding the last batch). The batch holds the fit, and
    with it the photos' patches: it is let go when the batch is done, failed or not."""
    StepRunner(_Fit(), 2).map("step", [(1,), (2,)])
    assert cw._BATCH is None
    with pytest.raises(InputError):
        StepRunner(_Fit(), 2).map("fail", [("a.png",), ("b.png",)])
    assert cw._BATCH is None


def _steps_in_a_daemon(queue):
    fit = _Fit()
    try:
        out = StepRunner(fit, 2).map("step", [(1,), (2,), (3,)])
        queue.put((out, {int(m.split(" in ")[1]) for m in fit.said}, os.getpid()))
    except BaseException as exc:          # noqa: BLE001 - reported to the test
        queue.put(repr(exc))


@forks
def test_where_workers_cannot_be_forked_the_steps_run_here(monkeypatch):
    """Kills C4 (no test for a daemonic process) and C5 (no test for the platform). A
    daemonic process may not have children (a batch of calibrations in a multiprocessing
    pool), and other systems do not fork: there the steps run one after another in the
    caller, with the same results."""
    import multiprocessing

    ctx = multiprocessing.get_context("fork")
    queue = ctx.Queue()
    proc = ctx.Process(target=_steps_in_a_daemon, args=(queue,), daemon=True)
    proc.start()
    got = queue.get(timeout=30)
    proc.join(timeout=10)
    assert not isinstance(got, str), got
    out, pids, daemon = got
    assert out == [1, 4, 9] and pids == {daemon}
    monkeypatch.setattr(sys, "platform", "darwin")
    fit = _Fit()
    assert StepRunner(fit, 2).map("step", [(1,), (2,)]) == [1, 4]
    assert {int(m.split(" in ")[1]) for m in fit.said} == {os.getpid()}


def test_gyrodeblur_threads_caps_the_workers(monkeypatch):
    """``GYRODEBLUR_THREADS`` (several processes at once) caps the workers as well."""
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: set(range(8)), raising=False)
    monkeypatch.setenv("GYRODEBLUR_THREADS", "1")
    assert available_workers() == 1
    monkeypatch.setenv("GYRODEBLUR_THREADS", "3")
    assert available_workers() == 3


@pytest.mark.parametrize("cpus, expected", [(3, 3), (16, MAX_WORKERS), (None, 1)])
def test_without_cpu_affinity_the_cpu_count_is_used(monkeypatch, cpus, expected):
    """Kills C2 (an unknown CPU count not read as one). Where ``os.sched_getaffinity`` does
    not exist (macOS, Windows) the CPU count is used, capped the same way, and a count
    the system cannot tell (``None``) is one CPU."""
    monkeypatch.delenv("GYRODEBLUR_THREADS", raising=False)
    monkeypatch.delattr(os, "sched_getaffinity", raising=False)
    monkeypatch.setattr(os, "cpu_count", lambda: cpus)
    assert available_workers() == expected


@forks
def test_settle_threads_waits_while_another_thread_runs():
    """A thread sorting outside the GIL keeps running: settle_threads waits its whole
    timeout and says they did not settle; once it has stopped, they settle at once."""
    import threading
    import time

    stop = threading.Event()
    a = np.random.default_rng(0).random(2_000_000)

    def busy():
        while not stop.is_set():
            np.sort(a)

    th = threading.Thread(target=busy)
    th.start()
    try:
        time.sleep(0.05)
        t0 = time.monotonic()
        settled = cw.settle_threads(timeout=0.3)
        waited = time.monotonic() - t0
    finally:
        stop.set()
        th.join()
    assert not settled and waited >= 0.3
    t0 = time.monotonic()
    assert cw.settle_threads(timeout=2.0)
    assert time.monotonic() - t0 < 1.0


@forks
def test_each_of_a_batchs_forks_lets_the_other_threads_settle_first(monkeypatch):
    """scipy's FFT pool stops its threads before a fork and hung on one that was just
    going to sleep (session 50): each fork of a batch's pool (two workers: two forks)
    first waits for the other threads to sleep; a fork outside a batch does not."""
    seen = []
    monkeypatch.setattr(cw, "settle_threads", lambda: seen.append(os.getpid()))
    fit = _Fit()
    assert StepRunner(fit, 2).map("step", [(1,), (2,), (3,)]) == [1, 4, 9]
    assert seen == [os.getpid()] * 2
    pid = os.fork()
    if pid == 0:
        os._exit(0)
    os.waitpid(pid, 0)
    assert seen == [os.getpid()] * 2
