"""A stop signal (SIGINT, SIGTERM, SIGHUP) is never lost by ``trust-av``: not where Python discards
an exception (a destructor: "Exception ignored in ..."), not while rclpy's executor spins.

The graph's own Ctrl-C and SIGTERM tests (tests/graph/test_graph.py) stop real runs at chosen
moments; a stop that lands in a destructor is a matter of timing there (seen once in CI:
rclpy's ``Future.__del__`` took the KeyboardInterrupt and the run finished with exit 0), so
these tests put it there on purpose.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
from support.processes import children_of, hangup_by_default

from trust_av.graph import stop_signals
from trust_av_common import output_files

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
from trust_av.graph import stop_signals

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
    from trust_av.graph import stop_signals
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
    assert signal.getsignal(signal.SIGTERM) is not stop_signals.handle  # restored


def test_renames_hold_back_every_stop_signal() -> None:
    """trust_monitor cannot import this module; its own list must be the same."""
    assert set(stop_signals.STOP_SIGNALS) == output_files.HELD_SIGNALS


@pytest.mark.parametrize('nohup', [False, True], ids=['terminal', 'nohup'])
def test_a_closed_terminal_stops_a_command_unless_started_under_nohup(nohup: bool) -> None:
    """SIGHUP (the terminal or ssh session closed) stops like SIGTERM; a command started
    under ``nohup`` (SIGHUP ignored) keeps running, as the user asked; SIGINT inherited as
    ignored (a shell's background job) is still taken."""
    program = """
    import os, signal, sys, time
    from trust_av.graph import stop_signals
    if sys.argv[1:] == ['nohup']:
        signal.signal(signal.SIGHUP, signal.SIG_IGN)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    with stop_signals.installed():
        print('SIGINT taken:', signal.getsignal(signal.SIGINT) is stop_signals.handle)
        try:
            os.kill(os.getpid(), signal.SIGHUP)
            time.sleep(0.05)
            print('went on')
        except stop_signals.Stopped as stop:
            print('stopped by', signal.Signals(stop.signum).name)
    print('after:', signal.getsignal(signal.SIGHUP) == signal.SIG_IGN)
    """
    done = subprocess.run([sys.executable, '-c', textwrap.dedent(program),
                           *(['nohup'] if nohup else [])],
                          capture_output=True, text=True, timeout=300,
                          preexec_fn=hangup_by_default)
    assert done.stderr == ''
    assert done.stdout.splitlines() == ['SIGINT taken: True',
                                        'went on' if nohup else 'stopped by SIGHUP',
                                        f'after: {nohup}']


def test_a_stop_lost_in_a_destructor_stops_trust_av_simulate_at_the_next_step() -> None:
    """Through the command: exit 130, its one line, no results; the run did not go on."""
    program = SIGNAL_IN_A_DESTRUCTOR + """
import trust_av.cli.simulate as command
from trust_av.cli.main import main

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
    header, *rest = done.stdout.splitlines()    # what runs is said before it starts
    assert header.startswith('components: ') and rest == ['steps 5']   # no metrics: stopped


def descendants(pid: int) -> set[int]:
    """Every live process started, directly or not, by ``pid``."""
    found: set[int] = set()
    frontier = [pid]
    while frontier:
        frontier = [child for parent in frontier for child in children_of(parent)]
        found.update(frontier)
    return found


def assert_all_exit(pids: set[int]) -> None:
    """None of ``pids`` is alive after a moment (zombies count as gone)."""
    deadline = time.monotonic() + 60
    alive = pids
    while alive and time.monotonic() < deadline:
        alive = {pid for pid in alive if Path(f'/proc/{pid}').exists()
                 and 'Z' not in (Path(f'/proc/{pid}/stat').read_text()
                                 .rsplit(')', 1)[1].split()[0])}
        time.sleep(0.1)
    assert not alive, f'still running: {alive}'


def trust_av(*args: str) -> subprocess.Popen[str]:
    """``trust-av ARGS`` as the leader of its own process group (as a terminal starts it)."""
    return subprocess.Popen([sys.executable, '-m', 'trust_av.cli', *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True, preexec_fn=hangup_by_default)


def stored_cases(cache: Path) -> list[Path]:
    """The cases stored in a sweep's cache: ``<key>.json``, not the temporary file
    ``.<key>.json.XXXX.tmp.json`` a case is written to before its rename (pathlib's glob
    matches names that start with a dot; a stop before the rename removes it)."""
    return [path for path in cache.glob('*.json') if not path.name.startswith('.')]


@pytest.mark.parametrize('signum', [signal.SIGTERM, signal.SIGHUP], ids=['SIGTERM', 'SIGHUP'])
def test_a_stop_ends_a_sweep_and_its_workers(tmp_path: Path, signum: int) -> None:
    """SIGTERM to ``trust-av reproduce`` alone (as ``docker stop`` or systemd send it), or
    SIGHUP to its whole process group (its terminal closed; the workers get it too): the
    queued cases do not run, no worker is left, every stored case is whole (a rerun
    resumes from them: tests/graph/test_reproduce.py). A process pool's own shutdown used to run
    every queued case first."""
    sweep = ('reproduce', '--traces', 'us06,nycc', '--predictors', 'ca', '--drivers', '2',
             '--workers', '2', '--results-dir', str(tmp_path), '--no-progress')
    cases = 2 * 5 * 2                            # traces x alpha x drivers
    proc = trust_av(*sweep)
    cache = tmp_path / 'cache'
    deadline = time.monotonic() + 120
    while not stored_cases(cache) and time.monotonic() < deadline:
        time.sleep(0.05)
    workers = descendants(proc.pid)
    assert len(workers) >= 2                     # the two workers (and Python's helpers)
    if signum == signal.SIGTERM:
        proc.send_signal(signum)
    else:
        os.killpg(proc.pid, signum)
    _out, err = proc.communicate(timeout=120)
    assert proc.returncode == 128 + signum, err
    assert err.splitlines() == [f'trust-av reproduce: stopped by {signal.Signals(signum).name}; '
                                'everything it started was stopped and its recordings finished']
    assert_all_exit(workers)
    stored = stored_cases(cache)
    assert 1 <= len(stored) < cases, len(stored)
    for path in stored:
        json.loads(path.read_text())
    assert not list(cache.glob('.*')), 'a temporary file was left'


CUT_OFF_RESULT = textwrap.dedent("""
    import os, struct, sys, time
    from trust_av.study.workers import worker_pool
    try:
        with worker_pool(1) as pool:
            pool.submit(time.sleep, 60)
            time.sleep(1.0)                 # the worker is in its call
            # what a worker stopped while sending its result leaves in the result pipe: a
            # header promising 1000 bytes, and 10 of them
            os.write(pool._result_queue._writer.fileno(), struct.pack('!i', 1000) + b'x' * 10)
            time.sleep(0.5)                 # the pool's thread is inside recv() for the rest
            raise RuntimeError('a stop')
    except RuntimeError:
        print('stopped', flush=True)
    sys.exit(3)
""")


def test_a_result_cut_off_by_the_stop_does_not_hang_the_exit() -> None:
    """A worker stopped while it sends its result back leaves part of a message in the pool's
    result pipe (seen once in a suite run: `trust-av reproduce` printed its stop line after
    SIGTERM and never exited). The pool is stopped, its thread ends and the process exits
    (it hung at exit, joining the pool's thread)."""
    proc = subprocess.run([sys.executable, '-c', CUT_OFF_RESULT], capture_output=True,
                          text=True, timeout=60)
    assert (proc.returncode, proc.stdout) == (3, 'stopped\n'), proc.stderr


CTRL_C_WHILE_WORKERS_START = textwrap.dedent("""
    import os, signal, sys, threading, time
    from pathlib import Path
    from trust_av.study.workers import worker_pool

    def starting_worker() -> bool:
        for entry in Path('/proc').iterdir():
            if entry.name.isdigit():
                try:
                    stat = (entry / 'stat').read_text().rsplit(')', 1)[1].split()
                    line = (entry / 'cmdline').read_bytes()
                except OSError:
                    continue
                if int(stat[1]) == os.getpid() and b'spawn_main' in line:
                    return True
        return False

    def ctrl_c_once_a_worker_exists() -> None:
        while not starting_worker():
            time.sleep(0.001)
        os.killpg(os.getpgrp(), signal.SIGINT)   # the terminal's Ctrl-C, to the whole group

    threading.Thread(target=ctrl_c_once_a_worker_exists, daemon=True).start()
    try:
        with worker_pool(2) as pool:
            pool.submit(time.sleep, 60).result()
    except KeyboardInterrupt:
        print('interrupted', flush=True)
    sys.exit(3)
""")


def test_ctrl_c_while_the_workers_start_reaches_only_the_command() -> None:
    """A Ctrl-C that comes while the pool's workers are still starting Python: the command
    is interrupted and stops them; no worker prints a traceback of its own (a worker started
    on demand, with Python's default SIGINT handler, printed ``KeyboardInterrupt``)."""
    proc = subprocess.run([sys.executable, '-c', CTRL_C_WHILE_WORKERS_START],
                          capture_output=True, text=True, timeout=120, start_new_session=True)
    assert (proc.returncode, proc.stdout) == (3, 'interrupted\n'), proc.stderr
    assert 'Traceback' not in proc.stderr, proc.stderr


def worker_processes(pids: set[int]) -> list[int]:
    """Those of ``pids`` that are multiprocessing spawn workers (not its resource tracker)."""
    found = []
    for pid in pids:
        with contextlib.suppress(OSError):
            if b'spawn_main' in Path(f'/proc/{pid}/cmdline').read_bytes():
                found.append(pid)
    return found


@pytest.mark.parametrize('how', ['SIGTERM to it', 'Ctrl-C at the terminal', 'SIGKILL',
                                 'its child killed'])
def test_train_gru_stops_its_pinned_child_and_workers(tmp_path: Path, how: str) -> None:
    """``trust-av train-gru`` trains in a child process (pinned numerics) with worker
    processes: a stop reaches each of them once, whichever way it comes, and nothing is
    left running or written."""
    out = tmp_path / 'model.npz'
    proc = subprocess.Popen([sys.executable, '-m', 'trust_av.cli', 'train-gru',
                             '--out', str(out), '--jobs', '2'], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)
    assert proc.stderr is not None
    lines = [proc.stderr.readline()]             # (a CPU without the pinned kernels warns)
    while lines[-1] and 'TAC-CA runs on the training traces' not in lines[-1]:
        lines.append(proc.stderr.readline())
    assert 'TAC-CA runs' in lines[-1], lines    # the child is running its first stage
    # its two workers were started, and had installed their stop rules, before the stage
    # began (a stop that reached one still starting Python printed that one's traceback)
    started = descendants(proc.pid)
    assert len(worker_processes(started)) == 2, started
    if how == 'SIGTERM to it':
        proc.send_signal(signal.SIGTERM)
    elif how == 'Ctrl-C at the terminal':
        os.killpg(proc.pid, signal.SIGINT)      # the terminal's process group
    elif how == 'SIGKILL':
        proc.kill()
    else:                                       # as the OOM killer would
        os.kill(min(children_of(proc.pid)), signal.SIGKILL)
    _out, rest = proc.communicate(timeout=120)
    if how == 'SIGKILL':
        assert proc.returncode == -signal.SIGKILL
    elif how == 'its child killed':
        assert proc.returncode == 2
        # the killed child's multiprocessing resource tracker may add its own warning about
        # the child's semaphores (Python's, printed when it notices the child is gone)
        assert ('trust-av train-gru: error: the training process (pinned numerics) was '
                'killed by SIGKILL; nothing was written') in rest.splitlines()
        assert 'Traceback' not in rest
    else:
        assert proc.returncode == (143 if how == 'SIGTERM to it' else 130), rest
        what = 'stopped by SIGTERM' if how == 'SIGTERM to it' else 'interrupted'
        lines = [line for line in rest.splitlines() if not line.startswith('[')]
        assert lines == [f'trust-av train-gru: {what}; everything it started was stopped '
                         'and its recordings finished']
    assert_all_exit(started)
    assert not out.exists() and not list(tmp_path.iterdir())
