"""Worker processes for the long study commands (the sweep's cases, the GRU's training
loops) that stop when the command stops.

A plain ``concurrent.futures.ProcessPoolExecutor`` leaves its ``with`` block through
``shutdown(wait=True)``, which runs every queued call first: SIGTERM sent to ``trust-av
reproduce`` 6 s into a 20 s sweep ended it after 14 s more, with the whole sweep run.
:func:`worker_pool` instead, when its block ends with an exception (a stop signal, a failed
case):

1. cancels every call that has not started;
2. sends SIGTERM to the workers: a worker inside a call unwinds it (its ``finally`` blocks
   run: a graph case stops its nodes and finishes its recording) and exits with 128 + the
   signal; a worker waiting for work exits at once;
3. waits :data:`WORKER_GRACE_S` for them, then sends SIGKILL.

Workers ignore SIGINT and SIGHUP: a Ctrl-C at the terminal, or the terminal closing, reaches
the whole process group, and the command that owns the pool decides what its workers do
(the graph's node processes are handled the same way, in their own process groups). A
worker whose command dies (even by SIGKILL) gets SIGTERM and stops as above.

:func:`call_runner` runs a command's independent calls (``trust-av fit-trust``'s fits) in
this process, on such a pool, or as Ray tasks when a Ray address is given; each way gives
the same results.
"""

from __future__ import annotations

import contextlib
import functools
import multiprocessing
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator, Mapping
from concurrent.futures import Future, ProcessPoolExecutor, as_completed
from multiprocessing import resource_tracker
from types import FrameType
from typing import Any, TypeVar

from trust_av.errors import TrustAvAppError
from trust_av.graph import stop_signals
from trust_av_common.held_stops import STOP_SIGNALS, held

__all__ = ['Calls', 'call_runner', 'joined_ray', 'stop_handlers_kept', 'worker_pool']

T = TypeVar('T')

WORKER_GRACE_S = 20.0
"""How long a stopped worker may take to unwind its call before it is killed (a graph
case stops its nodes in at most 13 s: graph/processes.py)."""

_in_call = {'now': False}

_STOPS = STOP_SIGNALS
"""Blocked while a worker starts; unblocked when its handlers are installed."""

WORKER_START_TIMEOUT_S = 120.0
"""How long the pool waits for a worker to start (import the study's modules) on a loaded
2-core machine before it gives up with an error."""


def _on_stop(signum: int, frame: FrameType | None) -> None:
    if not _in_call['now']:
        os._exit(128 + signum)      # waiting for work: nothing to unwind
    stop_signals.handle(signum, frame)  # raised (recorded while rclpy spins)


def _initialize_worker(parent: int, ready: Any) -> None:
    stop_signals.stop_with_parent()
    if os.getppid() != parent:  # the command died before this worker was up: no signal comes
        os._exit(128 + signal.SIGTERM)
    signal.signal(signal.SIGINT, signal.SIG_IGN)   # the command passes a stop on, once
    signal.signal(signal.SIGHUP, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _on_stop)
    sys.unraisablehook = stop_signals.unraisable_hook
    signal.pthread_sigmask(signal.SIG_UNBLOCK, _STOPS)  # one that came meanwhile runs now
    ready.release()


def _call(fn: Callable[..., T], *args: Any, **kwargs: Any) -> T:
    """``fn(*args, **kwargs)`` in a worker; on SIGTERM, unwind it and end the worker."""
    _in_call['now'] = True
    try:
        result = fn(*args, **kwargs)
        stop_signals.deliver_pending(working=True)  # one not raised, or swallowed
        return result
    except stop_signals.Stopped as stop:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(128 + stop.signum)
    finally:
        _in_call['now'] = False


def _start_resource_tracker() -> None:
    """Start multiprocessing's resource tracker (a helper process the pool's queues need)
    with SIGHUP blocked, as it already blocks SIGINT and SIGTERM while it starts: in the
    terminal's process group it would otherwise die when the terminal closes, and Python
    warns that resources may leak. (A blocked signal stays blocked across the tracker's
    exec; one that reaches this process meanwhile is delivered when it is unblocked. The
    tracker ends when this process does, as before.)"""
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGHUP})
    try:
        resource_tracker.ensure_running()
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


@contextlib.contextmanager
def _starting_worker() -> Iterator[None]:
    """Start a worker inside the block: it inherits the stop signals blocked (its
    initializer unblocks them once its handlers are in place), and a stop that reaches this
    process meanwhile is handled after the block, once the worker has its start-up data.
    (Blocking them in this thread is not enough: another thread, a worker's or torch's,
    takes the signal and Python runs the handler in the main thread at once, which cut the
    start-up data short and left the worker an ``EOFError``.)"""
    with held(_STOPS):
        mask = signal.pthread_sigmask(signal.SIG_BLOCK, _STOPS)
        try:
            yield
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, mask)


class WorkerPool(ProcessPoolExecutor):
    """A spawn-context process pool whose workers follow the rules above; use it through
    :func:`worker_pool`."""

    def __init__(self, workers: int) -> None:
        _start_resource_tracker()
        context = multiprocessing.get_context('spawn')
        ready = context.Semaphore(0)
        super().__init__(workers, mp_context=context, initializer=_initialize_worker,
                         initargs=(os.getpid(), ready))
        try:
            self._start_workers(workers, ready)
        except BaseException:
            self.stop_workers()
            raise

    def _start_workers(self, workers: int, ready: Any) -> None:
        """Start all ``workers`` now, each with the stop signals blocked, and wait until
        each has installed its handlers. (A spawn-context pool on 3.11 would start them one
        per submitted call, ``_adjust_process_count``; with all of them in ``_processes``
        it starts no more.)"""
        for _ in range(workers):
            with _starting_worker():
                self._spawn_process()  # type: ignore[attr-defined]
        processes = list(self._processes.values())
        deadline = time.monotonic() + WORKER_START_TIMEOUT_S
        up = 0
        while up < workers:
            if ready.acquire(timeout=0.1):
                up += 1
                continue
            for process in processes:
                if process.exitcode is not None:
                    raise TrustAvAppError(f'worker process {process.pid} ended while it '
                                          f'was starting (exit code {process.exitcode})')
            if time.monotonic() > deadline:
                raise TrustAvAppError(f'{workers - up} of {workers} worker processes did '
                                      f'not start within {WORKER_START_TIMEOUT_S:.0f} s')

    def submit(self, fn: Callable[..., T], /, *args: Any, **kwargs: Any) -> Future[T]:
        return super().submit(functools.partial(_call, fn), *args, **kwargs)

    def stop_workers(self) -> None:
        """Cancel what has not started; SIGTERM, then after the grace SIGKILL, to every
        worker; wait for them and for the pool's own thread.

        A worker stopped while it was sending a result back leaves part of a message in the
        result pipe, and the pool's thread waits in ``recv()`` for the rest, which never
        comes: this process holds the pipe's write end too, so no end of file either. The
        command then printed its stop line and hung at exit, where Python joins that thread
        (``shutdown(wait=False)`` drops it, so ``shutdown(wait=True)`` does not join it).
        Once every worker is gone, closing this process's write end gives the thread its end
        of file: it marks the pool broken and ends, and it is joined here.

        The pool's queues are held until the workers are gone: ``shutdown`` drops them, and
        a queue's last reference unlinks its named semaphores, so a worker still starting
        (its stop signals blocked until its handlers are in place) failed to rebuild them
        with ``FileNotFoundError``."""
        # CPython 3.14 adds ProcessPoolExecutor.terminate_workers() for this; on 3.11 the
        # workers are the executor's ``_processes`` (pid -> multiprocessing.Process), its
        # thread ``_executor_manager_thread`` and its result queue ``_result_queue``.
        processes = list((getattr(self, '_processes', None) or {}).values())
        thread = getattr(self, '_executor_manager_thread', None)
        results = getattr(self, '_result_queue', None)
        held = (getattr(self, '_call_queue', None), getattr(self, '_initargs', None))
        self.shutdown(wait=False, cancel_futures=True)
        for process in processes:
            if process.is_alive():
                process.terminate()
        for process in processes:
            process.join(WORKER_GRACE_S)
            if process.is_alive():
                process.kill()
                process.join()
        if results is not None:
            results._writer.close()
        if thread is not None:
            thread.join()
        del held


@contextlib.contextmanager
def worker_pool(workers: int) -> Iterator[WorkerPool]:
    """A :class:`WorkerPool` of ``workers`` processes; on leaving the block normally it
    waits for every call, on an exception (a stop signal included) it stops the workers
    first (:meth:`WorkerPool.stop_workers`) and re-raises."""
    pool = WorkerPool(workers)
    try:
        yield pool
    except BaseException:
        pool.stop_workers()
        raise
    pool.shutdown(wait=True)


Calls = Mapping[Any, tuple[Callable[..., Any], tuple[Any, ...]]]
"""Independent calls by key: ``key -> (function, arguments)`` (a module-level function and
picklable arguments, for a pool or Ray)."""
RunCalls = Callable[[Calls, Callable[[int, int], None] | None], dict[Any, Any]]
"""What :func:`call_runner` yields: runs the calls, reports ``(done, total)`` after each,
returns ``key -> result``; the first call that raises ends it with that exception."""


@contextlib.contextmanager
def call_runner(workers: int, ray_address: str | None = None) -> Iterator[RunCalls]:
    """A runner of independent calls: in this process (``workers`` 1, no Ray), on a
    :func:`worker_pool` of ``workers`` processes kept for the block, or as Ray tasks on
    the cluster at ``ray_address`` (``auto``, ``local`` or HOST:PORT; ``pip install ray``).

    Raises:
        TrustAvAppError: ray is not installed, or the address does not answer
            (:func:`trust_av.study.sweep.check_ray_address`).
    """
    if ray_address is not None:
        with _ray_runner(ray_address) as run:
            yield run
        return
    if workers <= 1:
        def here(calls: Calls, progress: Callable[[int, int], None] | None) -> dict[Any, Any]:
            out = {}
            for key, (function, args) in calls.items():
                out[key] = function(*args)
                if progress is not None:
                    progress(len(out), len(calls))
            return out

        yield here
        return
    with worker_pool(workers) as pool:
        def pooled(calls: Calls, progress: Callable[[int, int], None] | None
                   ) -> dict[Any, Any]:
            futures = {pool.submit(function, *args): key
                       for key, (function, args) in calls.items()}
            out = {}
            for future in as_completed(futures):
                out[futures[future]] = future.result()
                if progress is not None:
                    progress(len(out), len(futures))
            return out

        yield pooled


@contextlib.contextmanager
def stop_handlers_kept() -> Iterator[None]:
    """Put the stop signals' handlers back after the block: ``ray.init`` replaces this
    process's SIGTERM handler with one that exits at once, so a ``docker stop`` would have
    ended a sweep without the command's own stop (workers ended, its one line)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    handlers = {signum: signal.getsignal(signum) for signum in STOP_SIGNALS}
    try:
        yield
    finally:
        for signum, handler in handlers.items():
            if handler is not None:
                signal.signal(signum, handler)


@contextlib.contextmanager
def joined_ray(option: str, address: str | None, **init: Any) -> Iterator[Any]:
    """The ``ray`` module, joined to the cluster at ``address`` for the block (``ray.init``
    with ``init``, unless this process has joined one already; left again after it), the
    stop signals' handlers kept.

    Raises:
        TrustAvAppError: ray is not installed (one line naming ``option``).
    """
    try:
        import ray
    except ImportError as err:
        raise TrustAvAppError(f'{option} needs the optional dependency ray '
                              '(pip install ray)') from err
    started = not ray.is_initialized()
    if started:
        with stop_handlers_kept():   # ray.init installs a SIGTERM handler of its own
            ray.init(address=address, include_dashboard=False, log_to_driver=False, **init)
    try:
        yield ray
    finally:
        if started:
            ray.shutdown()


@contextlib.contextmanager
def _ray_runner(address: str) -> Iterator[RunCalls]:
    """:func:`call_runner` on Ray (a cluster this process joins for the block)."""
    with joined_ray('--ray-address', address) as ray:
        yield _on_ray(ray)


def _on_ray(ray: Any) -> RunCalls:
    remotes: dict[Callable[..., Any], Any] = {}

    def on_ray(calls: Calls, progress: Callable[[int, int], None] | None) -> dict[Any, Any]:
        pending = {}
        for key, (function, args) in calls.items():
            remote = remotes.setdefault(function, ray.remote(function))
            pending[remote.remote(*args)] = key
        out = {}
        total = len(pending)
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1)
            out[pending.pop(done[0])] = ray.get(done[0])
            if progress is not None:
                progress(len(out), total)
        return out

    return on_ray
