"""Shared fixtures: the shipped configuration and quick closed-loop runs (cached per session)."""

from __future__ import annotations

import dataclasses
import functools
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from preceding_traffic.sources import load_trace
from preceding_traffic.traces import SpeedTrace
from trust_av.system.closed_loop import SimResult, simulate
from trust_av.system.config import RunConfig, load_run_config

ALPHAS = (0.0, 0.25, 0.5, 0.75, 1.0)


@pytest.fixture
def ros_domain() -> Iterator[str]:
    """A ROS domain id leased for one test (the runs' lease: no other test or run uses it
    meanwhile; 230-232 stay free for the tests that need fixed domains)."""
    from trust_av.graph.domains import lease_domain

    with lease_domain() as domain:
        yield str(domain)


@pytest.fixture(scope='session')
def run_config() -> RunConfig:
    """The configuration in config/trust_av.yaml."""
    return load_run_config()


def with_alpha(config: RunConfig, alpha: float, predictor: str = 'ca') -> RunConfig:
    """``config`` with another alpha and predictor."""
    return dataclasses.replace(
        config, planner=dataclasses.replace(config.planner, alpha=alpha, predictor=predictor))


@functools.cache
def shipped_trace(name: str) -> SpeedTrace:
    """A shipped trace on the default grid."""
    config = load_run_config()
    return load_trace(name, config.planner.dt_s, config.trace)


@functools.cache
def closed_loop(trace: str, alpha: float, predictor: str = 'ca') -> SimResult:
    """One whole-trace in-process run with the shipped configuration (cached)."""
    return simulate(with_alpha(load_run_config(), alpha, predictor), shipped_trace(trace))


def assert_every_topic_complete(bag: Path) -> int:
    """Every recorded topic of the table holds every complete step, the topics within one
    step of each other (a topic absent from the bag holds none); returns the number of
    complete steps.

    Step k is complete with the vehicles' odometry and tf at stamp k, which the plants
    publish at the end of step k - 1 (stamp 0: the initial state, before the first step). So
    these topics run ahead: complete stamps when the run stopped before the plants finished
    the last complete step, complete + 1 once they had, complete + 2 when they had also
    finished the next step, which the other nodes had not.
    """
    from trust_av.graph.bag_records import read_topics, records_from_bag  # rosbags
    from trust_av_common.topics import TOPICS
    topics = read_topics(bag)
    complete = len(records_from_bag(bag))
    bad = {}
    for row in TOPICS:
        if 'recorder' in row.subscribers:
            name = row.name if row.name.startswith('/') else f'/{row.name}'
            stamps = len(topics.get(name, {}))
            ahead = name in ('/ego/odom', '/human/odom', '/tf')
            low, high = (complete, complete + 2) if ahead else (complete, complete + 1)
            if not low <= stamps <= high:
                bad[name] = (stamps, (low, high))
    assert not bad, f'{complete} complete steps; topics outside their range: {bad}'
    return complete


@pytest.hookimpl(tryfirst=True)   # before pytest-xdist reads the xdist_group marks
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Order and group the suite for ``pytest -n 4 --dist loadgroup`` (scripts/test.sh).

    * ``wall_clock`` tests (they mostly wait for real time, e.g. a soak at 10 Hz) form one
      xdist group: one worker runs them one after the other, from the start of the run
      (xdist hands out the largest group first), while the other workers run the
      CPU-bound tests on the two cores; the waiting overlaps with computing instead of
      adding to it.
    * ``slow`` tests (CPU-bound and long, e.g. the GRU retraining) come first among the
      rest, so that they start at once on the other workers instead of ending the run.
    * Tests that share a module-scoped fixture (a colcon build, one graph run) stay on one
      worker, so that the fixture is built once.
    Without xdist the marks do nothing and only the order changes.
    """
    del config
    for item in items:
        if item.get_closest_marker('wall_clock') is not None:
            item.add_marker(pytest.mark.xdist_group('wall_clock'))
            continue
        fixture_info = getattr(item, '_fixtureinfo', None)
        if fixture_info is None:
            continue
        # one group per module, whichever of its module-scoped fixtures a test uses (a
        # group per fixture split a module's tests that share one run over two workers)
        if any(definitions and definitions[-1].scope == 'module'
               for definitions in fixture_info.name2fixturedefs.values()):
            item.add_marker(pytest.mark.xdist_group(f'{item.module.__name__}.module_fixtures'))

    def rank(item: pytest.Item) -> int:
        if item.get_closest_marker('wall_clock') is not None:
            return 0
        return 1 if item.get_closest_marker('slow') is not None else 2

    items.sort(key=rank)


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config: pytest.Config, log: object) -> object | None:
    """``--dist loadgroup`` with two mends for a worker that dies (pytest-timeout's thread
    method ends a hung test's worker, and xdist starts a new one), so that such a test fails
    once and alone and the run goes on:

    * the dead worker's unfinished unit goes back to the queue without the test that killed
      it (xdist 3.8 requeued that test too: it hung again on every new worker until the
      restarts ran out);
    * a new worker gets work only once its collection is in (xdist 3.8 could hand it work
      before, and the run ended in an INTERNALERROR, ``KeyError: <WorkerController>``).
    """
    if config.getvalue('dist') != 'loadgroup':
        return None
    from xdist.scheduler import LoadGroupScheduling

    class Scheduling(LoadGroupScheduling):  # type: ignore[misc]
        def remove_node(self, node: Any) -> str | None:
            # xdist 3.8's LoadScopeScheduling.remove_node, but the test that was running
            # when the worker died is marked done before its unit goes back to the queue
            workload = self.assigned_work.pop(node)
            crashed = next((nodeid for unit in workload.values()
                            for nodeid, done in unit.items() if not done), None)
            if crashed is None:
                return None
            for scope, unit in workload.items():
                if crashed in unit:
                    unit[crashed] = True    # it failed: it is not sent again
                if not all(unit.values()):
                    self.workqueue[scope] = unit
            for other in self.assigned_work:
                self._reschedule(other)
            return crashed

        def _reschedule(self, node: Any) -> None:
            if node in self.registered_collections:
                super()._reschedule(node)

    return Scheduling(config, log)


def recorded_chunks(mcap: Path) -> int:
    """Chunks written so far to a growing MCAP (the recorder writes one chunk per step), read
    with mcap's stream reader up to the first incomplete record."""
    import struct

    from mcap.exceptions import McapError
    from mcap.records import Chunk
    from mcap.stream_reader import StreamReader

    chunks = 0
    try:
        with mcap.open('rb') as stream:
            for record in StreamReader(stream, emit_chunks=True).records:
                chunks += isinstance(record, Chunk)
    except FileNotFoundError:
        return 0                # not created yet
    except (McapError, struct.error):
        pass                    # the file ends mid-record while it is written: count so far
    return chunks


def wait_for_steps(bag: Path, steps: int, proc: subprocess.Popen[str] | None = None,
                   timeout_s: float = 120.0) -> None:
    """Wait until the run recording the bag directory ``bag`` holds ``steps`` steps (MCAP
    chunks); fail if ``proc`` (the run) ends first or the time runs out."""
    mcap = bag / f'{bag.name}.mcap'
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and recorded_chunks(mcap) < steps:
        assert proc is None or proc.poll() is None, proc.communicate()
        time.sleep(0.1)
    assert recorded_chunks(mcap) >= steps, f'{mcap}: fewer than {steps} steps in {timeout_s:g} s'


INTERRUPTED_RUN_STEPS = 3000
"""Steps of :func:`long_trace`: a run a test stops midway must not be able to finish first."""


def long_trace(directory: Path) -> Path:
    """A 3000-step CSV trace (a smooth 5-15 m/s profile, 1 s steps) in ``directory``, for
    runs that a test interrupts, kills or intrudes on after some recorded steps. With US06
    (600 steps) a run could step through all of them before the stop arrived on a loaded
    machine, where the recorder lags the graph (seen with four busy processes beside the
    SIGINT test: all 600 steps recorded after waiting for 150), and the test would then not
    test an interruption."""
    import math

    path = directory / 'long.csv'
    path.write_text('time_s,speed_mps\n' + ''.join(
        f'{t},{10.0 + 5.0 * math.sin(t / 30.0):.3f}\n'
        for t in range(INTERRUPTED_RUN_STEPS + 1)))
    return path


@pytest.fixture
def small_disk(tmp_path: Path) -> Iterator[Path]:
    """A real 200 kB tmpfs (needs the right to mount: skipped otherwise)."""
    mount = tmp_path / 'disk'
    mount.mkdir()
    done = subprocess.run(['mount', '-t', 'tmpfs', '-o', 'size=200k', 'tmpfs', str(mount)],
                          capture_output=True, text=True, check=False)
    if done.returncode != 0:
        pytest.skip(f'cannot mount a tmpfs here: {done.stderr.strip()}')
    try:
        yield mount
    finally:
        subprocess.run(['umount', '--lazy', str(mount)], check=False)


def children_of(pid: int) -> list[int]:
    """Every live process whose parent is ``pid``."""
    found = []
    for entry in Path('/proc').iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / 'stat').read_text().rsplit(')', 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == pid and fields[0] != 'Z':
                found.append(int(entry.name))
    return found


def wait_ready(process: subprocess.Popen[str]) -> None:
    """Read ``process``'s stdout up to its ``ready`` line; Fast DDS may log a transport
    error there first (seen: ``RTPS_TRANSPORT_SHM Error ... open_and_lock_file failed``).
    If it ends without one, it is killed and the lines are the assertion's message (a
    helper that raised with its process alive left an intruder on the domain for the next
    tests)."""
    assert process.stdout is not None
    lines = [process.stdout.readline()]
    while lines[-1] not in ('ready\n', ''):
        lines.append(process.stdout.readline())
    if lines[-1] != 'ready\n':
        process.kill()
        process.wait()
        raise AssertionError(f'no ready line: {lines}')
