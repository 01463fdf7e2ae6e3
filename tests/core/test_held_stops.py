"""A stop signal that arrives while CasADi solves: CasADi polls for signals
(``PyErr_CheckSignals``) and turned the handler's exception into its own error or a failed
solve; the project's solves hold the stop signals until they return
(``trust_av_common/held_stops.py``). Same on every CPU: nothing numeric is compared."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import threading
from typing import Any

import casadi as ca
import pytest

from trust_av.graph import stop_signals
from trust_av_common.held_stops import held
from trust_av_common.solver import solve, sqp_options


class SignalOnEvaluation(ca.Callback):
    """f(x) = (x - 1)^2 that sends ``signum`` to this process on its first evaluation, i.e.
    while the solver that calls it is running."""

    def __init__(self, signum: int) -> None:
        ca.Callback.__init__(self)
        self.signum = signum
        self.sent = False
        self.construct('signal_on_evaluation', {'enable_fd': True})  # derivatives by FD

    def get_n_in(self) -> int:
        return 1

    def get_n_out(self) -> int:
        return 1

    def eval(self, arg: list[Any]) -> list[Any]:
        if not self.sent:
            self.sent = True
            os.kill(os.getpid(), self.signum)
        return [(arg[0] - 1) ** 2]


def solver_signalling(signum: int) -> tuple[ca.Function, SignalOnEvaluation]:
    x = ca.MX.sym('x')
    objective = SignalOnEvaluation(signum)
    options = sqp_options(20)
    options['hessian_approximation'] = 'limited-memory'   # a callback has no Hessian
    return ca.nlpsol('signalling', 'sqpmethod', {'x': x, 'f': objective(x)}, options), objective


def test_casadi_turns_a_stop_during_a_solve_into_its_own_error() -> None:
    """Why the solves hold the signals: called directly, the handler's ``Stopped`` raised
    inside the solver comes out as CasADi's ``RuntimeError``, not as the stop."""
    solver, _objective = solver_signalling(signal.SIGTERM)
    with stop_signals.installed(), pytest.raises(RuntimeError, match='KeyboardInterrupt'):
        solver(x0=5.0)


@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM])
def test_a_stop_during_a_solve_is_raised_after_it_returns(signum: int) -> None:
    solver, objective = solver_signalling(signum)
    result: dict[str, Any] = {}
    with stop_signals.installed(), pytest.raises(stop_signals.Stopped) as stop:
        result = solve(solver, x0=5.0)
    assert objective.sent and stop.value.signum == signum
    assert result == {}                         # raised as solve() returned ...
    assert solver.stats()['success']            # ... from a solve that ran to its end
    assert signal.getsignal(signum) != stop_signals.handle   # installed() put back its own


def test_every_held_signal_is_delivered_in_order_and_the_first_stop_wins() -> None:
    """Two stops during one solve: the first is raised, the second escalates it (as it would
    have without the hold)."""
    with stop_signals.installed():
        with pytest.raises(stop_signals.Stopped) as stop, held():
            os.kill(os.getpid(), signal.SIGTERM)
            os.kill(os.getpid(), signal.SIGINT)
        assert stop.value.signum == signal.SIGTERM
        assert stop_signals.escalations() == 1


def test_an_ignored_signal_stays_ignored_and_other_threads_hold_nothing() -> None:
    """SIGHUP ignored stays ignored through a hold; a hold in another thread leaves the
    main thread's handler as it was (this test's own: what an earlier test in the same
    worker process left on SIGINT does not matter)."""
    def own_handler(_signum: int, _frame: Any) -> None:
        raise AssertionError('SIGINT was delivered')

    previous = signal.signal(signal.SIGHUP, signal.SIG_IGN)
    previous_int = signal.signal(signal.SIGINT, own_handler)
    try:
        with held():
            assert signal.getsignal(signal.SIGHUP) == signal.SIG_IGN
            os.kill(os.getpid(), signal.SIGHUP)            # nothing happens, then or later
        seen: list[Any] = []

        def in_a_thread() -> None:
            with held():
                seen.append(signal.getsignal(signal.SIGINT))
        thread = threading.Thread(target=in_a_thread)
        thread.start()
        thread.join()
        assert seen == [own_handler]
        assert signal.getsignal(signal.SIGINT) is own_handler
    finally:
        signal.signal(signal.SIGHUP, previous)
        signal.signal(signal.SIGINT, previous_int)


def test_the_solves_of_both_mpcs_go_through_the_hold() -> None:
    """The AV's NMPC and the driver's MPC solve through :func:`solve` (a new call site that
    calls its CasADi function directly would lose stops again)."""
    import inspect

    from human_driver_sim import driver_mpc
    from trust_av_planner import nmpc
    for module in (nmpc, driver_mpc):
        source = inspect.getsource(module)
        assert 'self._solver(' not in source, module.__name__
        assert 'solve(self._solver' in source, module.__name__


RENAMES_WITH_ANOTHER_THREAD = textwrap.dedent("""
    import os, signal, threading, time
    from trust_av.graph import stop_signals
    from trust_av_common.output_files import stop_signals_held

    done = threading.Event()
    other = threading.Thread(target=done.wait)
    other.start()
    steps = []
    try:
        with stop_signals.installed(), stop_signals_held():
            os.kill(os.getpid(), signal.SIGTERM)
            until = time.monotonic() + 0.2     # bytecodes, where a handler would run
            while time.monotonic() < until:
                steps.append('renamed')
            steps.append('all renamed')
    except stop_signals.Stopped:
        print('stopped after', steps[-1])
    finally:
        done.set()
        other.join()
""")


def test_the_renames_hold_a_stop_while_other_threads_run() -> None:
    """The outputs' renames (``output_files.stop_signals_held``) with another thread alive,
    as torch's and rclpy's are: the stop waits for the block (blocking the signal for the
    main thread only let that thread take it, and the handler ran inside the block). In a
    fresh process: pytest's own threads and handlers are not part of the case."""
    proc = subprocess.run([sys.executable, '-c', RENAMES_WITH_ANOTHER_THREAD],
                          capture_output=True, text=True, timeout=60)
    assert proc.stdout == 'stopped after all renamed\n', proc.stderr
