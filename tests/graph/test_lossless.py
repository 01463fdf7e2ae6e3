"""A recording loses nothing whatever the load: the step authority runs at most a window of
steps ahead of what the recorder acknowledges (trust_av_common.record_window), so a
recorder that is suspended (SIGSTOP) or writes slowly holds the graph back instead of
dropping messages from an overflowing DDS history."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from rosbags.rosbag2 import Reader
from support.processes import assert_every_topic_complete, children_of, long_trace, recorded_chunks
from support.rosbag2_rules import check_bag_directory  # the test-side oracle module

from trust_av.graph.bag_records import records_from_bag
from trust_av.graph.bag_writer import qos_profile
from trust_av_common.errors import TrustAvError
from trust_av_common.output_lock import OutputLockedError, hold_output_lock, lock_path
from trust_av_common.record_window import (
    ACK_EVERY_STEPS,
    HISTORY_DEPTH,
    may_start,
    recorded_topics,
    window_steps,
)
from trust_av_common.topics import TOPICS

QOS_RECORDED = qos_profile(reliable=True, transient_local=True, depth=HISTORY_DEPTH)


def test_the_window_keeps_every_topic_within_half_the_history() -> None:
    window = window_steps()
    assert window > ACK_EVERY_STEPS
    for row in recorded_topics():
        # messages published but not yet taken by the recorder, at most (module docstring)
        assert row.per_step * window <= HISTORY_DEPTH // 2, row.name
    assert {t.name for t in recorded_topics()} == {
        t.name for t in TOPICS if 'recorder' in t.subscribers and t.per_step}
    tf = next(t for t in TOPICS if t.name == 'tf')
    assert tf.per_step == 3 and window == HISTORY_DEPTH // 6


def test_a_window_that_cannot_be_acknowledged_is_refused() -> None:
    with pytest.raises(ValueError, match='acknowledgement period'):
        window_steps(depth=6 * ACK_EVERY_STEPS)


def test_a_step_starts_only_within_the_window_of_the_acknowledgement() -> None:
    assert may_start(0, 0, 10) and may_start(9, 0, 10) and not may_start(10, 0, 10)
    assert may_start(10, 1, 10) and may_start(10**6, 0, 0)


def test_a_bag_short_of_messages_is_named_topic_by_topic(tmp_path: Path) -> None:
    """What the run says when the recorder did not receive every message."""
    from support.bags import odometry

    from trust_av.graph.bag_writer import BagWriter
    from trust_av.graph.orchestrator import missing_messages

    bag = tmp_path / 'short'
    writer = BagWriter(bag)
    for topic in ('/ego/odom', '/human/odom'):
        writer.add_topic(topic, 'nav_msgs/msg/Odometry', QOS_RECORDED)
    for step in range(6):           # the initial state and 5 steps
        writer.write('/ego/odom', odometry(step * 10**9, 1.0))
        if step < 4:
            writer.write('/human/odom', odometry(step * 10**9, 1.0))
        writer.end_step()
    writer.finish()
    lacking = missing_messages(bag, 5)
    assert '/human/odom 2 of 6' in lacking and '/ego/odom' not in lacking
    assert '/clock 5 of 5' in lacking and '/tf 17 of 17' in lacking
    assert missing_messages(bag, 5, '/car1').startswith('/car1/clock 5 of 5')


# --- the whole graph ------------------------------------------------------------------------

STEPS = 1200
STOP_AT_STEP = 400
STOPPED_S = 3.0
STOPS = 2


def run(bag: Path, env: dict[str, str] | None = None,
        steps: int = STEPS) -> subprocess.Popen[str]:
    trace = long_trace(bag.parent)
    return subprocess.Popen([sys.executable, '-m', 'trust_av.cli', 'run', '--trace',
                             str(trace), '--max-steps', str(steps), '--bag', str(bag),
                             '--no-progress', '--no-plot'], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def recorder_pid(run_pid: int) -> int:
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        for pid in children_of(run_pid):
            try:
                command = Path(f'/proc/{pid}/cmdline').read_bytes()
            except OSError:
                continue
            if b'trust_av.graph.recorder_node' in command:
                return pid
        time.sleep(0.1)
    raise AssertionError('no recorder process')


def assert_lossless(bag: Path, steps: int = STEPS) -> dict[str, int]:
    """Every message of every step of every recorded topic is in the bag."""
    assert check_bag_directory(bag) == []
    with Reader(bag) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
    expected = {f'/{t.name}': t.messages(steps) for t in TOPICS if 'recorder' in t.subscribers}
    assert counts == expected
    assert assert_every_topic_complete(bag) == steps
    return counts


@pytest.mark.wall_clock
def test_a_slow_disk_and_a_suspended_recorder_hold_the_graph_back_and_lose_nothing(
        tmp_path: Path) -> None:
    """Both ways a recorder falls behind, in one run of 1200 steps (more than the DDS
    history of 1000 samples holds):

    * a slow disk: every chunk write of the recorder sleeps 8 ms (the test-only slow disk),
      the graph, about three times faster, waits for it (without the window this run
      failed, "no progress after 1181 steps");
    * the recorder suspended: SIGSTOP twice for 3 s after 400 steps (pauses of 1.5-3 s lost
      hundreds of steps mid-bag before the window existed); the run waits for it.

    Every message of every step is in the bag."""
    bag = tmp_path / 'slow'
    proc = run(bag, dict(os.environ, TRUST_AV_TEST_WRITE_DELAY_S='0.008'))
    recorder = recorder_pid(proc.pid)
    mcap = bag / f'{bag.name}.mcap'
    deadline = time.monotonic() + 120
    while recorded_chunks(mcap) < STOP_AT_STEP and time.monotonic() < deadline:
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.02)
    stalled_at = recorded_chunks(mcap)
    for _ in range(STOPS):
        os.kill(recorder, signal.SIGSTOP)
        try:
            time.sleep(STOPPED_S)
            assert proc.poll() is None          # the run waits for its recorder
        finally:
            os.kill(recorder, signal.SIGCONT)
        time.sleep(0.3)
    out, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, out + err
    assert stalled_at < STEPS - window_steps()
    counts = assert_lossless(bag)
    print(f'slow disk, recorder stopped {STOPS} x {STOPPED_S:g} s from step {stalled_at} of '
          f'{STEPS}: {sum(counts.values())} messages recorded, none lost')


# --- one command per output -----------------------------------------------------------------

def test_a_held_output_is_refused_with_its_path_and_holder(tmp_path: Path) -> None:
    bag = tmp_path / 'new' / 'deeper' / 'bag'
    with hold_output_lock(bag) as lock:
        assert lock == tmp_path / 'new' / 'deeper' / 'bag.lock'
        assert lock.read_text() == ''
        with pytest.raises(OutputLockedError) as refused, hold_output_lock(bag):
            pass
        assert str(refused.value) == (f'{bag}: another run is writing it (pid {os.getpid()}; '
                                      f'lock {lock})')
        assert lock.exists()                    # the refused one removed nothing
    assert not (tmp_path / 'new').exists()      # the directories it made, removed again
    with hold_output_lock(bag):                 # free again
        pass


def test_a_lock_left_by_a_killed_holder_does_not_block(tmp_path: Path) -> None:
    bag = tmp_path / 'bag'
    holder = subprocess.Popen(
        [sys.executable, '-c', 'import sys, time\n'
         'from pathlib import Path\n'
         'from trust_av_common.output_lock import hold_output_lock\n'
         f'with hold_output_lock(Path({str(bag)!r})):\n'
         '    print("held", flush=True); time.sleep(60)\n'],
        stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout is not None and holder.stdout.readline() == 'held\n'
        with pytest.raises(OutputLockedError, match=f'pid {holder.pid};'), hold_output_lock(bag):
            pass
    finally:
        holder.kill()
        holder.wait()
    assert lock_path(bag).exists()              # left behind by SIGKILL, and harmless:
    with hold_output_lock(bag):
        pass
    assert not lock_path(bag).exists()


def test_a_lock_file_that_is_a_link_or_a_directory_is_one_line(tmp_path: Path) -> None:
    target = tmp_path / 'elsewhere'
    lock_path(tmp_path / 'bag').symlink_to(target)
    link = r'bag.lock: cannot create the lock file \(a symbolic link\)'
    with pytest.raises(TrustAvError, match=link), hold_output_lock(tmp_path / 'bag'):
        pass
    assert not target.exists()
    lock_path(tmp_path / 'other').mkdir()
    with pytest.raises(TrustAvError, match=r'other\.lock: cannot create the lock file'), \
            hold_output_lock(tmp_path / 'other'):
        pass


def test_where_nothing_can_be_written_the_command_s_own_check_speaks(tmp_path: Path) -> None:
    """Under a file (or in /proc, read-only places): no lock file, no output either; the
    block runs unlocked and the command's output checks name the reason."""
    (tmp_path / 'file').write_text('')
    for output in (tmp_path / 'file' / 'bag', tmp_path / 'file' / 'a' / 'bag'):
        with hold_output_lock(output) as lock:
            assert lock is None
    assert sorted(p.name for p in tmp_path.iterdir()) == ['file']


@pytest.mark.wall_clock
def test_two_runs_started_together_on_one_bag_one_records(tmp_path: Path) -> None:
    """Both started at the same instant (600 steps: the first is still running when the
    second has loaded): exactly one records the whole run, the other is
    refused with one line, exit 2, before it writes anything."""
    bag = tmp_path / 'shared'
    command = [sys.executable, '-m', 'trust_av.cli', 'run', '--trace', 'us06',
               '--max-steps', '600', '--bag', str(bag), '--no-progress', '--no-plot']
    runs = [subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                             text=True) for _ in range(2)]
    outputs = [p.communicate(timeout=300) for p in runs]
    results = [(p.returncode, out, err) for p, (out, err) in zip(runs, outputs, strict=True)]
    codes = sorted(code for code, _, _ in results)
    assert codes == [0, 2], results
    winner = next(p for p, (code, _, _) in zip(runs, results, strict=True) if code == 0)
    _, out, err = next(r for r in results if r[0] == 2)
    assert out == '' and err.count('\n') == 1, err
    assert err.startswith(f'trust-av run: error: {bag}: another run is writing it (pid '
                          f'{winner.pid}; lock {bag}.lock)'), err
    assert check_bag_directory(bag) == []
    with Reader(bag) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
    assert counts == {f'/{t.name}': t.messages(600) for t in TOPICS
                      if 'recorder' in t.subscribers}
    assert not lock_path(bag).exists()


# --- the stall detector -----------------------------------------------------------------------

SUSPENDED_S = 33.0
"""Longer than the stall timeout of a run (30 s without a recorded step)."""


def wait_for_chunks(bag: Path, steps: int, proc: subprocess.Popen[str]) -> None:
    mcap = bag / f'{bag.name}.mcap'
    deadline = time.monotonic() + 120
    while recorded_chunks(mcap) < steps and time.monotonic() < deadline:
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.02)


SUSPENDED_RUN_STEPS = 300
"""Steps of the suspended run: it is stopped at step 50, mid-run and within the first
window, and needs no more (its nodes may finish while it is stopped; the pause that the
stall detector must not count: the next test)."""


@pytest.mark.wall_clock
def test_a_run_suspended_for_longer_than_the_stall_timeout_succeeds(tmp_path: Path) -> None:
    """Ctrl-Z, 33 s, ``fg``: SIGSTOP here (what Ctrl-Z's SIGTSTP does to it; a process group
    without a terminal ignores SIGTSTP). The nodes go on meanwhile; the run then reports
    success and its metrics, not a stall."""
    bag = tmp_path / 'own'
    proc = run(bag, steps=SUSPENDED_RUN_STEPS)
    wait_for_chunks(bag, 50, proc)
    proc.send_signal(signal.SIGSTOP)
    try:
        time.sleep(SUSPENDED_S)
    finally:
        proc.send_signal(signal.SIGCONT)
    out, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, out + err
    assert 'final trust' in out and err == ''
    assert_lossless(bag, SUSPENDED_RUN_STEPS)


@pytest.mark.wall_clock
def test_the_followers_own_pause_does_not_count_as_a_stall(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The loop that follows the run held up for longer than the stall timeout while the
    graph could not go on either (its recorder stopped: the run is certainly still under
    way when the loop resumes, which the CLI test above cannot make sure of, as the nodes go
    on without a suspended ``trust-av run``), then both going on: the run succeeds, because
    a turn of the loop longer than ``OWN_PAUSE_S`` (2 s) is the process's own pause, not the
    graph's. In process, with a 20 s stall timeout (8 s stalled once after the pause on a
    loaded CI host) and the test-only slow disk (20 ms per
    chunk: the run lasts at least 6 s, so the pause comes mid-run); the pause is taken in
    ``on_step`` once the recorder's progress has been reported twice, lasts 24 s, and the
    recorder stays stopped 1 s beyond it, so that without the rule the first turn after the
    pause would end the run naming the stopped recorder. The 25 s pause is within the DDS
    lease (60 s, config/fastdds_graph.xml); with Fast DDS's default of 20 s the recorder was
    dropped from the graph during it and its messages of the step under way were lost."""
    from preceding_traffic.sources import load_trace
    from preceding_traffic.traces import truncate
    from trust_av.graph.orchestrator import run_graph
    from trust_av.system.config import load_run_config

    step_timeout_s, pause_s = 20.0, 24.0
    assert pause_s > step_timeout_s
    monkeypatch.setenv('TRUST_AV_TEST_WRITE_DELAY_S', '0.02')
    config = load_run_config()
    trace_path = long_trace(tmp_path)
    trace = truncate(load_trace(str(trace_path), config.planner.dt_s, config.trace),
                     SUSPENDED_RUN_STEPS)
    bag = tmp_path / 'paused'
    recorder: list[int] = []
    paused: list[int] = []
    resumes: list[threading.Timer] = []

    def on_step(done: int, _total: int) -> None:
        if not recorder:
            recorder.append(next(pid for pid in children_of(os.getpid())
                                 if b'trust_av.graph.recorder_node'
                                 in Path(f'/proc/{pid}/cmdline').read_bytes()))
        elif not paused:
            os.kill(recorder[0], signal.SIGSTOP)
            paused.append(done)
            time.sleep(pause_s)
            resumes.append(threading.Timer(1.0, os.kill, (recorder[0], signal.SIGCONT)))
            resumes[0].start()

    try:
        run_graph(config, str(trace_path), trace, bag, max_steps=SUSPENDED_RUN_STEPS,
                  step_timeout_s=step_timeout_s, on_step=on_step)
    finally:
        for timer in resumes:
            timer.join()
    assert paused and paused[0] < SUSPENDED_RUN_STEPS - window_steps()
    assert_lossless(bag, SUSPENDED_RUN_STEPS)


@pytest.mark.wall_clock
@pytest.mark.parametrize('node', ['planner', 'recorder'])
def test_a_node_stopped_for_longer_than_the_stall_timeout_ends_the_run(
        tmp_path: Path, node: str) -> None:
    """A node stopped by a signal makes no progress: the run ends within the stall timeout
    with one line naming it, and the bag is finished (the stop continues the node so it
    takes its stop signal). In process, with a 4 s stall timeout; the node is stopped at
    step 50 and never continued by the test."""
    from preceding_traffic.sources import load_trace
    from preceding_traffic.traces import truncate
    from trust_av.graph.orchestrator import run_graph
    from trust_av.graph.processes import GraphError
    from trust_av.system.config import load_run_config

    config = load_run_config()
    trace_path = long_trace(tmp_path)
    trace = truncate(load_trace(str(trace_path), config.planner.dt_s, config.trace), STEPS)
    bag = tmp_path / 'stopped'
    stopped: list[int] = []
    module = {'planner': b'trust_av_planner.planner_node',
              'recorder': b'trust_av.graph.recorder_node'}[node]

    def on_step(done: int, _total: int) -> None:
        if done >= 50 and not stopped:
            pid = next(pid for pid in children_of(os.getpid())
                       if module in Path(f'/proc/{pid}/cmdline').read_bytes())
            os.kill(pid, signal.SIGSTOP)
            stopped.append(pid)

    with pytest.raises(GraphError, match=rf'no progress after \d+ steps in 4 s: node {node} is '
                                         r'stopped \(state T'):
        run_graph(config, str(trace_path), trace, bag, max_steps=STEPS, step_timeout_s=4.0,
                  on_step=on_step)
    assert stopped and not children_of(os.getpid())           # the stopped node too
    assert (bag / 'metadata.yaml').exists()
    assert check_bag_directory(bag) == []
    assert 50 <= len(records_from_bag(bag)) < STEPS


# --- a stop is complete whatever signals arrive --------------------------------------------------

@pytest.mark.wall_clock
def test_sigint_sigterm_sigint_in_quick_succession_stop_everything(tmp_path: Path) -> None:
    """Each further signal escalates the stop (SIGTERM, then SIGKILL of the nodes, the bag
    finished from its chunks); the command returns only once every node is gone, and says
    so."""
    bag = tmp_path / 'signals'
    proc = subprocess.Popen([sys.executable, '-m', 'trust_av.cli', 'run', '--trace',
                             str(long_trace(tmp_path)), '--bag', str(bag), '--no-progress',
                             '--no-plot'], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True)
    wait_for_chunks(bag, 20, proc)
    nodes = children_of(proc.pid)
    assert len(nodes) == 6
    for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGINT):
        proc.send_signal(signum)
        time.sleep(0.15)
    _out, err = proc.communicate(timeout=120)
    alive = [pid for pid in nodes if Path(f'/proc/{pid}').exists()]
    assert alive == []
    assert proc.returncode == 128 + signal.SIGINT, err
    assert err == ('trust-av run: interrupted; everything it started was stopped and its '
                   'recordings finished\n')
    assert (bag / 'metadata.yaml').is_file()
    assert check_bag_directory(bag) == []
    # reads fully: every message the metadata lists, and whole steps (the nodes killed by
    # the escalation may leave the last steps of some topics short)
    with Reader(bag) as reader:
        listed = sum(c.msgcount for c in reader.connections)
        assert sum(1 for _ in reader.messages()) == listed > 0
    assert 0 < len(records_from_bag(bag)) < 3000
