"""SIGINT, SIGTERM and SIGHUP in ``trust-av``: raised as :class:`Stopped` (a
``KeyboardInterrupt``) so that every command takes the same way out (stop what it started,
finish its files), and never lost. SIGHUP (the terminal closed, e.g. an ssh session ended)
stops a command unless it was started ignoring it (``nohup``).

Python raises a signal handler's exception wherever the main thread happens to be. Two
places lose it:

- a destructor or a garbage-collector callback (``__del__``: rclpy's ``Future``, casadi's
  objects): Python prints "Exception ignored in ..." and goes on, so the command ran to its
  end and exited 0 after a Ctrl-C;
- rclpy's executor, where an exception raised half-way through ``spin_once`` can leave it
  inconsistent (the nodes avoid it the same way, ``trust_av_common/ros/spin.py``).
- a CasADi solve, which polls for signals and turns the handler's exception into its own
  error or a failed solve: the solves hold the stop signals until they return
  (``trust_av_common/held_stops.py``).

So a stop that could not be raised is kept: while rclpy spins (:func:`spin_once`) the
handler only records it, and a ``KeyboardInterrupt`` that Python discarded as unraisable is
recorded by :func:`sys.unraisablehook` instead of printed. :func:`deliver_pending` raises a
recorded stop; it runs after every spin, at every progress update of the long in-process
commands, and when a command returns.

A stop is carried out to its end whatever number and mix of signals arrive: once a stop has
been raised (the command is stopping what it started and finishing its files), or inside a
:func:`stopping` block (a graph being stopped), a further signal raises nothing. It
*escalates* the stop instead (:func:`escalations` counts them): the graph's stop goes on to
its next, harsher signal at once (SIGINT, SIGTERM, SIGKILL of its nodes, then finishing the
bag from what was recorded), and never abandons what it started.
"""

from __future__ import annotations

import contextlib
import ctypes
import signal
import sys
from collections.abc import Iterator
from types import FrameType
from typing import Any

from trust_av_common.held_stops import STOP_SIGNALS

__all__ = ['Stopped', 'continue_with_parent', 'deferred', 'deliver_pending', 'escalations',
           'handle', 'installed', 'spin_once', 'stop_with_parent', 'stopping', 'unraisable_hook']

_state: dict[str, int] = {'deferring': 0, 'pending': 0, 'raised': 0, 'quiet': 0,
                          'escalations': 0}


class Stopped(KeyboardInterrupt):
    """A stop signal, raised like Ctrl-C; ``signum`` says which."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def handle(signum: int, _frame: FrameType | None) -> None:
    """The signal handler: raise :class:`Stopped`; record it inside :func:`deferred`; count
    it as an escalation once a stop is under way (raised, or a :func:`stopping` block)."""
    if _state['raised'] or _state['quiet']:
        _state['escalations'] += 1
        if not _state['raised'] and not _state['pending']:
            _state['pending'] = signum      # raised once the stopping block is done
        return
    if _state['deferring']:
        _state['pending'] = signum
        return
    _raise(signum)


def _raise(signum: int) -> None:
    _state['pending'] = 0
    _state['raised'] = signum
    raise Stopped(signum)


def escalations() -> int:
    """Stop signals that arrived while a stop was under way (each asks for a harsher one)."""
    return _state['escalations']


@contextlib.contextmanager
def stopping() -> Iterator[None]:
    """A stop in progress (nodes being stopped): a stop signal inside the block does not
    interrupt it but escalates it (:func:`escalations`); one that is not yet being carried
    out is raised when the block ends."""
    _state['quiet'] += 1
    try:
        yield
    finally:
        _state['quiet'] -= 1
    if not _state['quiet'] and not _state['deferring']:
        deliver_pending()


def unraisable_hook(unraisable: Any) -> None:
    """``sys.unraisablehook``: record a discarded ``KeyboardInterrupt`` (a stop), print
    anything else as Python does."""
    error = unraisable.exc_value
    if isinstance(error, KeyboardInterrupt):
        _state['pending'] = getattr(error, 'signum', signal.SIGINT)
        _state['raised'] = 0                # discarded: not being carried out
        return
    sys.__unraisablehook__(unraisable)


@contextlib.contextmanager
def installed() -> Iterator[None]:
    """Inside the block, the :data:`STOP_SIGNALS` raise :class:`Stopped` (SIGINT also where a
    background start inherited it as ignored; SIGHUP not where it is ignored, as ``nohup``
    asks) and a stop Python could not raise is kept; the previous handlers and hook are
    back afterwards."""
    previous = {signum: signal.getsignal(signum) for signum in STOP_SIGNALS}
    previous_hook = sys.unraisablehook
    _state.update(pending=0, raised=0, escalations=0)
    for signum in STOP_SIGNALS:
        if not ignored_on_purpose(signum, previous[signum]):
            signal.signal(signum, handle)
    sys.unraisablehook = unraisable_hook
    try:
        yield
    finally:
        sys.unraisablehook = previous_hook
        for signum, handler in previous.items():
            signal.signal(signum, handler)
        _state.update(raised=0, escalations=0)


def ignored_on_purpose(signum: int, handler: Any) -> bool:
    """True for SIGHUP started as ignored (``nohup``): the user asked to outlive the
    terminal. (A shell starts a background job with SIGINT ignored, which nobody asked for;
    SIGTERM is never ignored by a launcher.)"""
    return signum == signal.SIGHUP and handler == signal.SIG_IGN


def deliver_pending(working: bool = False) -> None:
    """Raise the stop that arrived where it could not be raised, if any (not inside a
    :func:`stopping` block: there it waits for the block's end).

    ``working``: the caller is at a point of the command's own work (a progress update,
    the end of the command or of a worker's call), never on the way out of a stop. A stop
    that was raised and is still not carried out there was swallowed (native code that
    turned the exception into its own error, a library that caught it): it is raised
    again, so that no stop is lost and the further signals, which only escalate a stop
    under way, are not ignored with it."""
    if _state['quiet']:
        return
    signum, _state['pending'] = _state['pending'], 0
    if signum:
        _raise(signum)
    if working and _state['raised']:
        _raise(_state['raised'])


@contextlib.contextmanager
def deferred() -> Iterator[None]:
    """A stop inside the block is recorded, and raised when the block ends normally."""
    _state['deferring'] += 1
    try:
        yield
    finally:
        _state['deferring'] -= 1
    if not _state['deferring']:
        deliver_pending()


def spin_once(executor: Any, timeout_s: float) -> None:
    """``executor.spin_once`` with a stop deferred to its end (at most ``timeout_s``)."""
    with deferred():
        executor.spin_once(timeout_sec=timeout_s)


def stop_with_parent() -> None:
    """In a child process, before it runs (``preexec_fn``): SIGTERM, a clean stop, when the
    process that started it dies, even by SIGKILL (Linux ``PR_SET_PDEATHSIG``)."""
    libc = ctypes.CDLL('libc.so.6', use_errno=True)
    libc.prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG


def continue_with_parent() -> None:
    """In a node process, before it runs (``preexec_fn``): SIGCONT when the process that
    started it dies, even by SIGKILL (Linux ``PR_SET_PDEATHSIG``). A node checks its parent
    between spins and stops cleanly once it is gone (``trust_av_common.ros.spin.spin_node``);
    SIGTERM here would stay pending in a node stopped by SIGSTOP or a debugger, which then
    outlived the run. Continued, it makes the check within a spin (0.1 s)."""
    libc = ctypes.CDLL('libc.so.6', use_errno=True)
    libc.prctl(1, signal.SIGCONT)  # PR_SET_PDEATHSIG
