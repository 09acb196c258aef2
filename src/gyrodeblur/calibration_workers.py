"""Independent steps of a calibration search, side by side in worker processes.

A calibration refines many starts that do not depend on one another: the coarse ranking's
mappings, the candidates, the winner's other starts and scans (see
:mod:`gyrodeblur.calibrate`, Search). Each is a Python loop over small arrays, so threads
would wait on each other; :class:`StepRunner` runs a batch of them in forked processes,
which inherit the fitting context (the photos' patches) without copying it, and return
only their results.

Every step starts from the same state, however many workers there are: the criterion's
warm starts and caches are cleared (:meth:`PatchSpectra.start_afresh`), and a step run in
this process hands the state it changed back (:meth:`PatchSpectra.restore`). So a
calibration gives the same figures with one worker as with several, to the last digit
(tested). What a step reports (its messages, the basins it reached, its cost evaluations)
is replayed in the order the steps were given.

Processes are forked, so workers are used on Linux only (elsewhere, and inside a daemonic
process, the steps run one after another), and only while the caller's thread is the
process's only Python thread: a fork beside another running thread can deadlock on a lock
that thread holds (scipy's FFT pool's, seen under three calibrations in three threads),
and batches of calibrations in two threads would share the forked batch (:data:`_BATCH`).
A pipeline that calibrates in threads gets the same figures, one step after another.

Even with one Python thread the process has others: scipy's FFT pool (and OpenCV's,
OpenBLAS's). The FFT pool stops its threads in a handler run before each fork, and that
handler waits forever for a thread that was just going to sleep as it was told to stop (a
lost wake-up: seen once, the calibration's pool forking its second worker right after the
first fork had restarted the FFT threads, on a loaded machine, session 50). So before each
of a batch's forks, :func:`settle_threads` waits (at most :data:`SETTLE_TIMEOUT`) until no
other thread of the process is running.

In a worker the FFTs and BLAS (through ``threadpoolctl``) use one thread each: the workers
share the CPUs, and OpenBLAS's threads spin while they wait, so two workers with two BLAS
threads each on two cores took twice as long (a 12 MP photo's coarse ranking: 2.2 s
against 1.0 s; its whole calibration about 21 s against 16 s, session 54).
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import sys
import threading
import time
import warnings
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass
from functools import wraps

from threadpoolctl import threadpool_limits

from .fftutils import usable_cpus

__all__ = ["StepRunner", "available_workers", "settle_threads", "on_one_blas_thread",
           "MAX_WORKERS", "SETTLE_TIMEOUT"]

#: At most this many worker processes by default: a batch holds up to about seven steps
#: (a calibration's candidates); each worker runs its FFTs and BLAS on one thread.
MAX_WORKERS = 4

# (fit, method name, argument tuples) of the batch being run: set before the workers are
# forked, which is how they receive it
_BATCH = None

#: Longest wait (s) before one of a batch's forks for the process's other threads to go
#: to sleep (:func:`settle_threads`); the fork then goes ahead.
SETTLE_TIMEOUT = 0.1

# True while a batch's pool forks its workers: the before-fork hook then settles threads
_SETTLING = False


def _running_threads(own: int) -> int:
    """How many threads of this process, other than the one of native id ``own``, are
    running or waiting for a CPU (state R in ``/proc/self/task/*/stat``); 0 where that
    cannot be read (not Linux)."""
    try:
        tids = os.listdir("/proc/self/task")
    except OSError:
        return 0
    n = 0
    for tid in tids:
        if tid == str(own):
            continue
        try:
            with open(f"/proc/self/task/{tid}/stat", "rb") as f:
                stat = f.read()
        except OSError:                    # the thread has ended
            continue
        end = stat.rfind(b")")             # the name, in parentheses, may hold anything
        if stat[end + 2:end + 3] == b"R":
            n += 1
    return n


def settle_threads(timeout: float = SETTLE_TIMEOUT) -> bool:
    """Wait until no other thread of this process runs (two looks 0.5 ms apart), at most
    ``timeout`` seconds; returns whether they did. A thread asleep is waiting on a lock or
    condition it has already registered with, so a wake-up sent now reaches it."""
    own = threading.get_native_id()
    end = time.monotonic() + timeout
    quiet = 0
    while True:
        quiet = quiet + 1 if _running_threads(own) == 0 else 0
        if quiet >= 2:
            return True
        if time.monotonic() >= end:
            return False
        time.sleep(0.0005)


def _before_fork() -> None:
    if _SETTLING:
        settle_threads()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(before=_before_fork)


def available_workers() -> int:
    """The CPUs this process may run on, at most :data:`MAX_WORKERS`."""
    return max(1, min(usable_cpus(), MAX_WORKERS))


def on_one_blas_thread(func):
    """Decorator: ``func`` runs with BLAS on one thread (``threadpoolctl``; the setting
    before is restored after), when the caller's is the process's only Python thread.

    The search's BLAS calls are small (the kernels' matrix products, the envelopes' 3 x 3
    to 8 x 8 solves): a second thread saves no time, and OpenBLAS's threads spin while
    they wait, so beside other work on the CPUs (other calibrations, a worker) they take
    it from that work. One calibration in one process on 2 cores (a 12 MP photo, session
    54): 27.9 s and 28.0 s of CPU on one BLAS thread, 29.0 s and 38.0 s of CPU on two.
    The limit is the process's, so beside other Python threads it is left alone: two
    threads setting and restoring it across each other could leave it wrong."""
    @wraps(func)
    def wrapped(*args, **kwargs):
        alone = threading.active_count() == 1
        with threadpool_limits(1, user_api="blas") if alone else nullcontext():
            return func(*args, **kwargs)
    return wrapped


def _can_fork() -> bool:
    return (sys.platform.startswith("linux") and "fork" in multiprocessing.get_all_start_methods()
            and not multiprocessing.current_process().daemon
            and threading.active_count() == 1)         # no other thread to fork beside


@dataclass
class _Done:
    """A step's result and what it reported."""

    result: object
    said: list
    basins: list
    fine_evaluations: int
    coarse_evaluations: int


def _run_step(fit, method: str, args: tuple) -> _Done:
    """``fit.method(*args)`` from fresh warm starts, the fit's state handed back after."""
    held = (fit.fine.held_state(), fit.coarse.held_state(), list(fit.basins), fit.say)
    counts = (fit.fine.evaluations, fit.coarse.evaluations)
    said: list = []
    try:
        fit.fine.start_afresh()
        fit.coarse.start_afresh()
        fit.say = said.append
        result = getattr(fit, method)(*args)
        return _Done(result, said, fit.basins[len(held[2]):],
                     fit.fine.evaluations - counts[0], fit.coarse.evaluations - counts[1])
    finally:
        fit.fine.restore(held[0])
        fit.coarse.restore(held[1])
        fit.basins[:] = held[2]
        fit.say = held[3]


def _start_worker(parent: int) -> None:
    fit = _BATCH[0]
    fit.fine.fft_threads = fit.coarse.fft_threads = 1      # the workers share the CPUs
    threadpool_limits(1)                                  # and so do their BLAS calls
    signal.signal(signal.SIGTERM, signal.SIG_DFL)         # not the CLI's handler
    signal.signal(signal.SIGINT, signal.SIG_IGN)          # Ctrl-C: the caller kills them
    _die_with_parent(parent)


@contextmanager
def _interrupts_deferred():
    """SIGINT and SIGTERM recorded, not acted on, while the pool is made, forks its
    workers and starts its thread, then raised again: an interrupt in the middle of a fork
    or of an import was dropped by Python ("Exception ignored in _releaseLock", or in
    ``_get_module_lock``: the batch then ran on), and one while the pool's thread started
    broke its shutdown (a RuntimeError traceback). Main thread only (signal handlers are
    set there)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    got: list = []
    old = {}
    for sig in (signal.SIGINT, signal.SIGTERM):
        try:
            old[sig] = signal.signal(sig, lambda signum, frame: got.append(signum))
        except (ValueError, OSError):
            pass
    try:
        yield
    finally:
        for sig, handler in old.items():
            signal.signal(sig, handler)
        for sig in dict.fromkeys(got):
            signal.raise_signal(sig)


def _die_with_parent(parent: int) -> None:
    """Have the kernel kill this worker when the process that forked it dies (Linux's
    ``PR_SET_PDEATHSIG``): a caller killed mid-calibration (a batch system's timeout)
    must not leave its workers waiting for tasks forever, holding its pipes open."""
    try:
        import ctypes
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGKILL, 0, 0, 0)           # 1 = PR_SET_PDEATHSIG
    except (OSError, AttributeError):                    # not Linux's libc: best effort
        return
    if os.getppid() != parent:                           # it died before the prctl
        os._exit(1)


def _kill_workers(pool) -> None:
    """Stop a pool's workers now (the caller is being interrupted: their steps are not
    wanted, and a shutdown would wait for them)."""
    for proc in list((getattr(pool, "_processes", None) or {}).values()):
        try:
            proc.kill()
        except (OSError, AttributeError):
            pass


def _worker(k: int):
    fit, method, arglist = _BATCH
    try:
        return _run_step(fit, method, arglist[k])
    except BaseException:           # raised again where it can be: in the caller
        return None


class StepRunner:
    """Runs batches of independent steps of one :class:`CalibrationFit`.

    Parameters
    ----------
    fit : CalibrationFit
        The fitting context; its methods are the steps.
    workers : int
        Processes to use at most (1: every step in this process).
    """

    def __init__(self, fit, workers: int):
        self.fit = fit
        self.workers = max(1, int(workers))

    @staticmethod
    def _map_in_workers(n: int, arglist, done: list) -> None:
        """The batch's steps in ``n`` forked workers, results into ``done``; interrupted
        (Ctrl-C, SIGTERM) or failing here, the workers are killed rather than waited for."""
        # Futures submitted one by one, not pool.map: interrupted, map's iterator cancels
        # the pending ones while the pool's own thread, its workers killed (or dead from a
        # signal to the process group), fails them as broken, and the two raced into an
        # InvalidStateError traceback before the one-line message (3 in 10 SIGTERMs of
        # calibrate, session 44). Nothing here cancels them: the pool's thread fails them.
        global _SETTLING
        pool = None
        try:
            # The pool is made inside the deferral too: making it imports modules, and an
            # interrupt that lands as an import's lock is let go is dropped by Python
            # ("Exception ignored in ... _get_module_lock"), and the batch ran on (1 in
            # about 350 signals to the process group at the start of a batch, session 45).
            with _interrupts_deferred():      # the first submit forks the workers
                _SETTLING = True
                try:
                    pool = ProcessPoolExecutor(n, multiprocessing.get_context("fork"),
                                               initializer=_start_worker,
                                               initargs=(os.getpid(),))
                    futures = [pool.submit(_worker, k) for k in range(len(arglist))]
                finally:
                    _SETTLING = False
            for k, future in enumerate(futures):
                done[k] = future.result()
        except BrokenProcessPool:
            raise
        except BaseException:
            if pool is not None:
                _kill_workers(pool)
            raise
        finally:
            if pool is not None:
                pool.shutdown(wait=True)

    def map(self, method: str, arglist) -> list:
        """``[fit.method(*args) for args in arglist]``, the steps side by side when there
        are workers; their messages, basins and evaluation counts are added to the fit's
        in order."""
        global _BATCH
        arglist = [tuple(a) for a in arglist]
        n = min(self.workers, len(arglist))
        done: list = [None] * len(arglist)
        if n > 1 and _can_fork():
            _BATCH = (self.fit, method, arglist)
            try:
                with warnings.catch_warnings():    # fork() with the FFT's threads idle
                    warnings.simplefilter("ignore", DeprecationWarning)
                    self._map_in_workers(n, arglist, done)
            except BrokenProcessPool:    # a worker died (killed, out of memory): the
                pass                     # steps it left undone run here
            finally:
                _BATCH = None
        fit = self.fit
        out = []
        for k, d in enumerate(done):
            # no workers, or the step failed or died there: run it here (an error is then
            # raised as it would be without workers)
            if d is None:
                d = _run_step(fit, method, arglist[k])
            for msg in d.said:
                fit.say(msg)
            fit.basins.extend(d.basins)
            fit.fine.evaluations += d.fine_evaluations
            fit.coarse.evaluations += d.coarse_evaluations
            out.append(d.result)
        return out
