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
  inconsistent (the nodes avoid it the same way, ``trust_monitor/ros/spin.py``).

So a stop that could not be raised is kept: while rclpy spins (:func:`spin_once`) the
handler only records it, and a ``KeyboardInterrupt`` that Python discarded as unraisable is
recorded by :func:`sys.unraisablehook` instead of printed. :func:`deliver_pending` raises a
recorded stop; it runs after every spin, at every progress update of the long in-process
commands, and when a command returns.
"""

from __future__ import annotations

import contextlib
import ctypes
import signal
import sys
from collections.abc import Iterator
from types import FrameType
from typing import Any

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
"""The signals that stop a command (Ctrl-C; ``timeout``, ``docker stop``, systemd; a closed
terminal)."""

_state: dict[str, int] = {'deferring': 0, 'pending': 0}


class Stopped(KeyboardInterrupt):
    """A stop signal, raised like Ctrl-C; ``signum`` says which."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def handle(signum: int, _frame: FrameType | None) -> None:
    """The signal handler: raise :class:`Stopped`, or record it inside :func:`deferred`."""
    if _state['deferring']:
        _state['pending'] = signum
        return
    _state['pending'] = 0
    raise Stopped(signum)


def unraisable_hook(unraisable: Any) -> None:
    """``sys.unraisablehook``: record a discarded ``KeyboardInterrupt`` (a stop), print
    anything else as Python does."""
    error = unraisable.exc_value
    if isinstance(error, KeyboardInterrupt):
        _state['pending'] = getattr(error, 'signum', signal.SIGINT)
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
    _state['pending'] = 0
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


def ignored_on_purpose(signum: int, handler: Any) -> bool:
    """True for SIGHUP started as ignored (``nohup``): the user asked to outlive the
    terminal. (A shell starts a background job with SIGINT ignored, which nobody asked for;
    SIGTERM is never ignored by a launcher.)"""
    return signum == signal.SIGHUP and handler == signal.SIG_IGN


def deliver_pending() -> None:
    """Raise the stop that arrived where it could not be raised, if any."""
    signum, _state['pending'] = _state['pending'], 0
    if signum:
        raise Stopped(signum)


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
