"""A stop signal (SIGINT, SIGTERM) is never lost by ``trust-av``: not where Python discards
an exception (a destructor: "Exception ignored in ..."), not while rclpy's executor spins.

The graph's own Ctrl-C and SIGTERM tests (tests/test_graph.py) stop real runs at chosen
moments; a stop that lands in a destructor is a matter of timing there (seen once in CI:
rclpy's ``Future.__del__`` took the KeyboardInterrupt and the run finished with exit 0), so
these tests put it there on purpose.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest

from trust_av_planner.graph import stop_signals

SIGNAL_IN_A_DESTRUCTOR = '''
import contextlib, os, signal, sys

class SignalInADestructor:
    """Sends the signal to this process from its destructor and runs Python code there,
    where the handler's exception is raised and then discarded."""
    def __init__(self, signum):
        self.signum = signum
    def __del__(self):
        os.kill(os.getpid(), self.signum)
        for _ in range(100_000):
            pass
'''


def run_python(code: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, '-c', textwrap.dedent(code)], capture_output=True,
                          text=True, timeout=300)


@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM], ids=['SIGINT', 'SIGTERM'])
def test_a_stop_discarded_in_a_destructor_is_raised_at_the_next_check(signum: int) -> None:
    program = SIGNAL_IN_A_DESTRUCTOR + f"""
from trust_av_planner.graph import stop_signals

def raise_it(signum, frame):
    raise KeyboardInterrupt(signum)

if sys.argv[1:] == ['python']:  # a handler that raises, as Python's own for SIGINT
    signal.signal(signal.SIGINT, raise_it)
    signal.signal(signal.SIGTERM, raise_it)
    context = contextlib.nullcontext()
else:
    context = stop_signals.installed()
with context:
    try:
        SignalInADestructor({int(signum)})
        print('went on after the destructor')
        stop_signals.deliver_pending()
        print('not stopped')
    except KeyboardInterrupt as err:
        print('stopped by', getattr(err, 'signum', 'KeyboardInterrupt'))
"""
    # the case is real: with Python's handlers the stop is lost
    plain = subprocess.run([sys.executable, '-c', program, 'python'], capture_output=True,
                           text=True, timeout=300)
    assert 'Exception ignored' in plain.stderr
    assert plain.stdout.splitlines() == ['went on after the destructor', 'not stopped']
    kept = run_python(program)
    assert kept.stderr == ''                    # nothing printed: the stop is still to come
    assert kept.stdout.splitlines() == ['went on after the destructor',
                                        f'stopped by {int(signum)}']


def test_other_discarded_exceptions_are_still_printed() -> None:
    program = """
    from trust_av_planner.graph import stop_signals
    class Broken:
        def __del__(self):
            raise ValueError('a defect in a destructor')
    with stop_signals.installed():
        Broken()
        stop_signals.deliver_pending()
        print('done')
    """
    done = run_python(program)
    assert done.stdout == 'done\n'
    assert 'Exception ignored' in done.stderr and 'ValueError: a defect' in done.stderr


def test_a_stop_while_deferred_is_raised_when_the_block_ends() -> None:
    reached: list[str] = []
    with stop_signals.installed():
        with pytest.raises(stop_signals.Stopped) as stopped, stop_signals.deferred():
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(0.05)                # the handler has run by now
            reached.append('end of the block')
        assert reached == ['end of the block'] and stopped.value.signum == signal.SIGTERM
        stop_signals.deliver_pending()          # delivered once, not again
    assert signal.getsignal(signal.SIGTERM) is not stop_signals._handler  # restored


def test_a_stop_lost_in_a_destructor_stops_trust_av_simulate_at_the_next_step() -> None:
    """Through the command: exit 130, its one line, no results; the run did not go on."""
    program = SIGNAL_IN_A_DESTRUCTOR + """
import trust_av_planner.cli.simulate as command
from trust_av_planner.cli.main import main

simulate, steps = command.simulate, []

def with_a_signal_in_a_destructor(config, trace, on_step):
    def step(done, total):
        steps.append(done)
        if done == 5:
            SignalInADestructor(signal.SIGINT)
        on_step(done, total)
    return simulate(config, trace, on_step=step)

command.simulate = with_a_signal_in_a_destructor
code = main(['simulate', '--trace', 'us06', '--no-progress'])
print('steps', steps[-1])
sys.exit(code)
"""
    done = run_python(program)
    assert done.returncode == 130, done.stderr
    assert done.stderr == ('trust-av simulate: interrupted; everything it started was stopped '
                           'and its recordings finished\n')
    assert done.stdout == 'steps 5\n'           # no metrics: stopped at that step's progress
