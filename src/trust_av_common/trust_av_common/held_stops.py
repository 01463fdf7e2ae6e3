"""Stop signals held back while native code runs that would turn them into something else.

Python runs a signal handler in the main thread between bytecodes, and also whenever native
code calls ``PyErr_CheckSignals``. CasADi's solvers poll it; a handler that raises (Ctrl-C's
``KeyboardInterrupt``, the command line's stop) then raises inside the solver, which catches
the exception and reports it its own way: ``sqpmethod`` as ``RuntimeError: Error in
Function::call ... KeyboardInterrupt`` (``trust-av simulate`` exited 1 with a traceback), or
as a failed solve (the step fell back and the run went on to its end, exit 0; a worker of
``train-gru`` ignored its stop). Measured: SIGTERM sent to ``trust-av simulate`` at eight
moments of a 10 Hz commute ended it as a stop 3 times, with exit 1 four times and ran to the
end once.

:func:`held` keeps the stop signals' handlers from running inside its block: a signal that
arrives is recorded and sent again to this process when the block ends, so the handler that
was installed runs then, between bytecodes, where its exception means what it says. A solve
takes milliseconds, so the stop is late by at most that.
"""

from __future__ import annotations

# The C module under :mod:`signal`: its wrappers convert every handler to and from an enum,
# which made a hold cost 20 us per solve (4 % of a 600-step run); without them, 5 us.
import _signal
import contextlib
import signal
import threading
from collections.abc import Iterator
from types import FrameType
from typing import Any

__all__ = ['STOP_SIGNALS', 'held']

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
"""The signals that stop a command (Ctrl-C; ``timeout``, ``docker stop``, systemd; a closed
terminal)."""


@contextlib.contextmanager
def held(signums: tuple[int, ...] = STOP_SIGNALS) -> Iterator[None]:
    """Inside the block, ``signums`` are recorded instead of handled; each one that came is
    raised again (:func:`signal.raise_signal`), in order, once the block ends, however it
    ends, to the handler installed before the block (or the signal's default action).

    Handlers can only be changed in the main thread, and only there does Python run them:
    in another thread the block holds nothing (there is nothing to hold). A signal that is
    ignored stays ignored."""
    arrived: list[int] = []
    previous: dict[int, Any] = {}

    def record(signum: int, _frame: FrameType | None) -> None:
        arrived.append(signum)

    if threading.current_thread() is threading.main_thread():
        for signum in signums:
            handler = _signal.getsignal(signum)
            if callable(handler) or handler == signal.SIG_DFL:
                previous[signum] = _signal.signal(signum, record)
    try:
        yield
    finally:
        for signum, handler in previous.items():
            _signal.signal(signum, handler)
        _deliver(arrived)


def _deliver(signums: list[int]) -> None:
    """Raise ``signums`` again, in the order they came, each to its handler. Every one is
    delivered even when a handler raises (a second Ctrl-C escalates a stop under way); an
    exception from a later one carries the earlier one as its context."""
    if signums:
        try:
            signal.raise_signal(signums[0])
        finally:
            _deliver(signums[1:])
