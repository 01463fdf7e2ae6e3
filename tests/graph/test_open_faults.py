"""The fault cases left open by the fault rounds: each is one line and exit 2, or the
documented behaviour (docs/operations/failures.md)."""

from __future__ import annotations

import contextlib
import math
import os
import signal
import struct
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from support.cli import one_line, trust_av
from support.graph import stoppable_run
from support.processes import (
    INTERRUPTED_RUN_STEPS,
    assert_every_topic_complete,
    children_of,
    recorded_chunks,
    wait_for_steps,
)
from support.rosbag2_rules import check_bag_directory
from support.synthetic_car_following import write_ngsim_chain

from trust_av.graph.stalls import steps_done, waiting_for
from trust_av_common.kinematics import VehicleState
from trust_av_common.topics import TOPICS, qualified
from trust_av_planner.planner import observe


def _trace_bag(directory: Path) -> Path:
    """A 30-sample Odometry bag written by trust-av (trace-to-bag)."""
    trace = directory / 'lead.csv'
    trace.write_text('time_s,speed_mps\n' + ''.join(f'{t},{10 + 0.1 * t}\n' for t in range(30)))
    bag = directory / 'lead_bag'
    assert trust_av('trace-to-bag', str(trace), str(bag))[0] == 0
    return bag


def _corrupt_chunk_index(bag: Path) -> None:
    """Make the compression name of the MCAP's chunk index (summary section) one byte that
    is not UTF-8 (its length 0 -> 1, the byte 0xff): rosbags raised UnicodeDecodeError."""
    mcap = next(bag.glob('*.mcap'))
    data = bytearray(mcap.read_bytes())
    footer = len(data) - 8 - 29                     # Footer record before the closing magic
    assert data[footer] == 0x02
    record = struct.unpack_from('<Q', data, footer + 9)[0]        # summary_start
    while data[record] != 0x08:                     # the ChunkIndex record
        record += 9 + struct.unpack_from('<Q', data, record + 1)[0]
    body = record + 9
    offsets = struct.unpack_from('<I', data, body + 32)[0]         # message_index_offsets
    compression = body + 32 + 4 + offsets + 8                      # after message_index_length
    assert struct.unpack_from('<I', data, compression)[0] == 0     # '' (not compressed)
    struct.pack_into('<I', data, compression, 1)
    data[compression + 4] = 0xff
    mcap.write_bytes(bytes(data))


def _foreign_odometry(directory: Path) -> Path:
    """An MCAP whose ``nav_msgs/msg/Odometry`` schema is another tool's (two floats)."""
    from mcap.writer import Writer

    path = directory / 'foreign.mcap'
    with path.open('wb') as stream:
        writer = Writer(stream)
        writer.start(profile='ros2', library='another tool')
        schema = writer.register_schema('nav_msgs/msg/Odometry', 'ros2msg',
                                        b'float64 speed\nfloat64 time')
        channel = writer.register_channel('/preceding_vehicle/odom', 'cdr', schema)
        for i in range(10):
            writer.add_message(channel, log_time=i * 10**9, publish_time=i * 10**9,
                               data=b'\x00\x01\x00\x00' + struct.pack('<dd', 10.0, float(i)))
        writer.finish()
    return path


class TestOneLine:
    """Each case: exit 2 and one line naming the bad thing, never a traceback."""

    def test_a_corrupt_chunk_index(self, tmp_path: Path) -> None:
        bag = _trace_bag(tmp_path)
        _corrupt_chunk_index(bag)
        code, err = trust_av('simulate', '--trace', str(bag), '--max-steps', '3',
                             '--no-progress')
        assert code == 2, err
        line = one_line(err)
        assert str(bag) in line and 'cannot read bag (damaged: UnicodeDecodeError' in line

    def test_a_foreign_odometry_schema(self, tmp_path: Path) -> None:
        mcap = _foreign_odometry(tmp_path)
        code, err = trust_av('simulate', '--trace', str(mcap), '--max-steps', '3',
                             '--no-progress')
        assert code == 2, err
        line = one_line(err)
        assert str(mcap) in line and 'defines it differently from ROS 2 Jazzy' in line

    @pytest.mark.parametrize(('option', 'value', 'words'), [
        ('--window-s', '0.5', '--window-s 0.5: a window needs at least 5 steps'),
        ('--window-s', 'inf', '--window-s must be > 0 and finite'),
        ('--vehicle-length-m', 'nan', '--vehicle-length-m must be in [0, 30] m, got nan'),
        ('--vehicle-length-m', '-1', '--vehicle-length-m must be in [0, 30] m'),
    ])
    def test_eval_driver_odd_numbers(self, tmp_path: Path, option: str, value: str,
                                     words: str) -> None:
        write_ngsim_chain(tmp_path / 'a.csv', [1, 2, 3])
        code, err = trust_av('eval-driver', '--data', str(tmp_path), option, value)
        assert code == 2, err
        assert words in one_line(err)

    @pytest.mark.parametrize('kind', ['csv', 'bag'])
    def test_a_stationary_lead_names_the_trace(self, tmp_path: Path, kind: str) -> None:
        trace = tmp_path / 'parked.csv'
        trace.write_text('time_s,speed_mps\n' + ''.join(f'{t},0\n' for t in range(6)))
        if kind == 'bag':
            bag = tmp_path / 'parked_bag'
            assert trust_av('trace-to-bag', str(trace), str(bag))[0] == 0
            trace = bag
        code, err = trust_av('simulate', '--trace', str(trace), '--no-progress')
        assert code == 2, err
        line = one_line(err)
        assert str(trace) in line and 'the lead never moves' in line
        assert 'speed_max_from_trace' in line


def test_a_stationary_lead_runs_without_the_speed_limit_from_it(tmp_path: Path) -> None:
    """What the line offers works: the speed limit from the params file instead."""
    trace = tmp_path / 'parked.csv'
    trace.write_text('time_s,speed_mps\n' + ''.join(f'{t},0\n' for t in range(6)))
    params = tmp_path / 'limit.yaml'
    params.write_text('/**:\n  ros__parameters:\n    speed_max_from_trace: false\n')
    code, err = trust_av('simulate', '--trace', str(trace), '--params-file', str(params),
                         '--no-progress')
    assert code == 0, err


def test_headway_after_the_follower_reached_the_car_in_front() -> None:
    """``dt_s: 0.01`` on US06: the human, whose 3-step horizon is 0.03 s there, drove into the
    AV and stopped with the gap below zero; the headway divided by its speed of 0
    (ZeroDivisionError). A gap at or below zero leaves no headway."""
    av, human = VehicleState(100.0, 0.0), VehicleState(120.0, 0.0)     # 24.5 m overlap
    seen = observe(av, human, 0.0, 4.5, 5.0)
    assert seen.time_headway_s == 0.0 and math.isfinite(seen.gap_m) and seen.gap_m < 0
    moving = observe(VehicleState(100.0, 5.0), VehicleState(90.0, 5.0), 0.0, 4.5, 5.0)
    assert moving.time_headway_s == pytest.approx(5.5 / 5.0)


def _state(pid: int) -> str:
    """The kernel's one-letter state of ``pid`` ('' once it is gone or a zombie)."""
    try:
        state = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()[0]
    except (OSError, IndexError):
        return ''
    return '' if state == 'Z' else state


def _until(condition: Callable[[], bool], timeout_s: float, what: str) -> None:
    """Wait for ``condition`` (polled every 0.1 s), failing with ``what`` after the time."""
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, what
        time.sleep(0.1)


@pytest.mark.wall_clock
def test_a_killed_orchestrator_leaves_no_node_even_a_stopped_one(tmp_path: Path) -> None:
    """The planner stopped with SIGSTOP, then ``trust-av run`` killed with SIGKILL: the
    stopped planner stayed (its parent-death SIGTERM waited for a SIGCONT that never came),
    with another node. Now every node is gone, the stopped one and the five running ones
    (the plain kill of the orchestrator), and the recorder finished the bag itself with
    every complete step on every topic."""
    bag = tmp_path / 'orphan'
    proc = stoppable_run(bag)
    wait_for_steps(bag, 8, proc=proc)
    nodes = children_of(proc.pid)
    assert len(nodes) == 6
    planner = next(pid for pid in nodes if b'trust_av_planner.planner_node'
                   in Path(f'/proc/{pid}/cmdline').read_bytes())
    os.kill(planner, signal.SIGSTOP)
    _until(lambda: _state(planner) in ('T', 't'), 30, 'the planner did not stop')
    proc.kill()
    proc.communicate(timeout=60)
    _until(lambda: not any(_state(pid) for pid in nodes), 60,
           f'nodes left: {[pid for pid in nodes if _state(pid)]}')
    assert (bag / 'metadata.yaml').exists()               # finished by the recorder itself
    assert check_bag_directory(bag) == []
    assert 0 < assert_every_topic_complete(bag) < INTERRUPTED_RUN_STEPS


def test_the_node_a_stalled_chain_waits_for() -> None:
    """From the messages recorded per topic: the first node, in the order they act within a
    step, that has done fewer steps than the step source."""
    def counts(steps: dict[str, int]) -> dict[str, int]:
        out = {}
        for row in TOPICS:
            if len(row.publishers) == 1 and row.per_step:
                out[qualified(row.name)] = row.initial + row.per_step * steps[row.publishers[0]]
        return out

    everyone = {'preceding_traffic': 11, 'planner': 11, 'ego_plant': 11, 'human_driver': 11,
                'trust_monitor': 11}
    assert waiting_for(counts(everyone)) == ''
    assert steps_done(counts(everyone)) == everyone
    assert waiting_for(counts({**everyone, 'planner': 10, 'ego_plant': 10,
                               'human_driver': 10, 'trust_monitor': 10})) == 'planner'
    assert waiting_for(counts({**everyone, 'trust_monitor': 10})) == 'trust_monitor'
    assert waiting_for(counts({**everyone, 'human_driver': 10, 'trust_monitor': 10}),
                       ) == 'human_driver'


def _node(pids: list[int], module: bytes) -> int:
    """The pid among ``pids`` running the node module ``module``."""
    return next(pid for pid in pids if module in Path(f'/proc/{pid}/cmdline').read_bytes())


@pytest.mark.wall_clock
def test_a_recorder_killed_with_its_orchestrator_leaves_a_bag_repair_restores(
        tmp_path: Path) -> None:
    """SIGKILL to the recorder, with ``trust-av run`` killed too (nobody repairs it): the
    bag directory holds the MCAP of every complete step without a summary, and
    ``trust-av repair-bag`` restores it."""
    bag = tmp_path / 'killed'
    proc = stoppable_run(bag)
    wait_for_steps(bag, 8, proc=proc)
    nodes = children_of(proc.pid)
    recorder = _node(nodes, b'trust_av.graph.recorder_node')
    proc.send_signal(signal.SIGSTOP)         # so that it cannot repair the bag in between
    os.kill(recorder, signal.SIGKILL)
    proc.kill()
    proc.communicate(timeout=60)
    _until(lambda: not any(_state(pid) for pid in nodes), 60,
           f'nodes left: {[pid for pid in nodes if _state(pid)]}')
    assert not (bag / 'metadata.yaml').exists() and (bag / f'{bag.name}.mcap').is_file()
    code, err = trust_av('repair-bag', str(bag))
    assert code == 0, err
    assert check_bag_directory(bag) == []
    assert 8 <= assert_every_topic_complete(bag) < INTERRUPTED_RUN_STEPS


@pytest.mark.wall_clock
def test_a_run_stopped_before_its_first_step_leaves_no_bag(tmp_path: Path) -> None:
    """SIGINT while the graph starts (the recorder has created the bag, the planner is held
    stopped so that no step can begin): no bag is left (it held no step), the node logs
    are, and the line is the stop's."""
    bag = tmp_path / 'early'
    proc = stoppable_run(bag)
    _until(lambda: len(children_of(proc.pid)) == 6, 120, 'the nodes did not start')
    planner = _node(children_of(proc.pid), b'trust_av_planner.planner_node')
    os.kill(planner, signal.SIGSTOP)
    _until(lambda: (bag / f'{bag.name}.mcap').exists(), 120, 'the recorder made no bag')
    proc.send_signal(signal.SIGINT)
    _out, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert err.count('\n') == 1 and 'interrupted; everything it started was stopped' in err
    assert not bag.exists()
    assert (tmp_path / 'early.logs' / 'recorder.log').is_file()


# --- every stop signal is honoured by every long in-process command -------------------------

def test_a_swallowed_stop_is_raised_again_where_the_command_works(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A stop raised into code that swallowed it (native code turning it into its own
    error): the command went on, and every further signal only escalated a stop that was
    not under way (fit-driver needed a third). The next progress update raises it again,
    and so does a command that returns success after it."""
    from trust_av.cli import simulate
    from trust_av.cli.options import Progress
    from trust_av.graph import stop_signals

    with stop_signals.installed():
        with contextlib.suppress(stop_signals.Stopped):      # swallowed
            stop_signals.handle(signal.SIGTERM, None)
        stop_signals.handle(signal.SIGTERM, None)           # the second: no exception here
        with pytest.raises(stop_signals.Stopped) as again:
            Progress('work', 10, shown=False).update(1)
        assert again.value.signum == signal.SIGTERM

    def swallowing(_args: object) -> int:
        with contextlib.suppress(stop_signals.Stopped):
            stop_signals.handle(signal.SIGTERM, None)
        return 0

    monkeypatch.setattr(simulate, 'run', swallowing)
    code, err = trust_av('simulate')
    assert code == 143 and 'stopped by SIGTERM' in err


def _write_fit_data(directory: Path) -> list[str]:
    from support.synthetic_car_following import write_openacc

    directory.mkdir()
    write_openacc(directory / 'JRC-VC_280219_part2.csv', duration_s=70.0)
    write_openacc(directory / 'JRC-VC_280219_part3.csv', duration_s=70.0)
    return ['fit-driver', '--data', str(directory), '--out', str(directory / 'fit.yaml'),
            '--iterations', '1000', '--no-progress']


def _write_eval_data(directory: Path) -> list[str]:
    from support.synthetic_car_following import write_openacc

    directory.mkdir()
    write_openacc(directory / 'trip_part1.csv', duration_s=1500.0, cars=5)
    params = directory / 'fine.yaml'
    params.write_text('/**:\n  ros__parameters:\n    dt_s: 0.1\n')
    return ['eval-driver', '--data', str(directory), '--params-file', str(params)]


def _write_long_trace(directory: Path) -> list[str]:
    directory.mkdir()
    trace = directory / 'long.csv'          # 20000 steps: about 10 CPU-s in process
    trace.write_text('time_s,speed_mps\n' + ''.join(
        f'{t},{10.0 + 5.0 * math.sin(t / 30.0):.3f}\n' for t in range(20001)))
    return ['simulate', '--trace', str(trace), '--no-progress',
            '--out', str(directory / 'out.csv')]


STOP_GRACE_S = 10.0
"""An in-process command ends this soon after a stop signal (docs/operations/failures.md)."""


def _handles_sigterm(pid: int) -> bool:
    """Whether ``pid`` has a handler for SIGTERM (``SigCgt`` in ``/proc/PID/status``): the
    command has installed its stop handlers and started its work."""
    try:
        status = Path(f'/proc/{pid}/status').read_text()
    except OSError:
        return False
    caught = next(line.split()[1] for line in status.splitlines() if line.startswith('SigCgt'))
    return bool(int(caught, 16) >> (signal.SIGTERM - 1) & 1)


@pytest.mark.wall_clock
class TestStopSignalsEndLongCommands:
    """SIGTERM, and a second one, to a long in-process command once it works: exit 143 and
    one line within :data:`STOP_GRACE_S`, nothing written."""

    @pytest.mark.parametrize('make', [_write_fit_data, _write_eval_data, _write_long_trace],
                             ids=['fit-driver', 'eval-driver', 'simulate'])
    def test_sigterm_and_another(self, tmp_path: Path, make: Callable[[Path], list[str]]
                                 ) -> None:
        import subprocess
        import sys

        from trust_av.graph.stalls import cpu_s

        argv = make(tmp_path / 'data')
        proc = subprocess.Popen([sys.executable, '-m', 'trust_av.cli', *argv],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        _until(lambda: _handles_sigterm(proc.pid) or proc.poll() is not None, 120,
               'no stop handler')
        started = cpu_s(proc.pid)
        _until(lambda: cpu_s(proc.pid) > started + 1.0 or proc.poll() is not None, 120,
               'no work')
        assert proc.poll() is None, proc.communicate()
        proc.send_signal(signal.SIGTERM)
        with contextlib.suppress(ProcessLookupError):
            proc.send_signal(signal.SIGTERM)
        _out, err = proc.communicate(timeout=STOP_GRACE_S)
        assert proc.returncode == 143, err
        assert err.strip().splitlines() == [
            f'trust-av {argv[0]}: stopped by SIGTERM; everything it started was stopped and '
            'its recordings finished']
        assert not (tmp_path / 'data' / 'fit.yaml').exists()
        assert not (tmp_path / 'data' / 'out.csv').exists()


@pytest.mark.wall_clock
def test_sigterm_and_another_end_shadow_with_a_finished_bag(tmp_path: Path) -> None:
    """``trust-av shadow`` (wall-clock nodes, its own recording): SIGTERM and a second one
    once it records end it with one line, 143, no node left and the bag finished."""
    import subprocess
    import sys

    lead = tmp_path / 'lead.csv'
    lead.write_text('time_s,speed_mps\n' + ''.join(f'{t},{10 + 0.1 * t}\n' for t in range(120)))
    source = tmp_path / 'lead_bag'
    assert trust_av('trace-to-bag', str(lead), str(source))[0] == 0
    out = tmp_path / 'shadow'
    proc = subprocess.Popen([sys.executable, '-m', 'trust_av.cli', 'shadow', '--bag',
                             str(source), '--out', str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    # it records once its first chunk is written (its nodes are up and the replay runs);
    # a stop before that, while the bag is made, leaves none (test_recording.py)
    _until(lambda: recorded_chunks(out / f'{out.name}.mcap') > 0 or proc.poll() is not None,
           120, 'no recording')
    nodes = children_of(proc.pid)
    assert proc.poll() is None and nodes, proc.communicate()
    proc.send_signal(signal.SIGTERM)
    proc.send_signal(signal.SIGTERM)
    _out, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, err
    assert err.strip().splitlines() == [
        'trust-av shadow: stopped by SIGTERM; everything it started was stopped and its '
        'recordings finished']
    assert not any(_state(pid) for pid in nodes)
    assert (out / 'metadata.yaml').exists()
    assert check_bag_directory(out) == []
