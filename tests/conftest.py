"""The suite's fixtures (a leased ROS domain, the shipped configuration, a small disk), its
tiers and its xdist grouping. Helpers shared between test modules are in ``support/``."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from trust_av.system.config import RunConfig, load_run_config
from trust_av_common.held_stops import STOP_SIGNALS


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


@pytest.fixture(scope='session')
def us06_graph_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    """One graph run read by many tests (test_graph, test_foxglove_layout,
    test_compare_trust_models, test_compare_runs): ``trust-av run`` on US06, TAC-CA, alpha
    0.5, 120 steps, with its plot (support.graph.run_command); the bag directory and the
    command's stdout. Tests only read it. The tests that use it form one xdist group
    (pytest_collection_modifyitems), so the suite runs it once."""
    from support.graph import run_command

    bag = tmp_path_factory.mktemp('graph') / 'us06'
    proc = subprocess.run(run_command(bag, plot=True), capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return bag, proc.stdout


SHARED_RUNS = ('us06_graph_run',)
"""Session fixtures that record a run many modules' tests read: each is one xdist group."""


TESTS = Path(__file__).resolve().parent
TIERS = ('core', 'graph', 'browser')
"""The suite's tiers, one folder each, and the marker every test of the folder carries:
``core`` the pure core and whatever runs without a ROS graph (no node process, no rclpy
context), ``graph`` multi-process node-graph runs and rclpy contexts, ``browser`` the drive
page in Chromium. ``pytest tests/core -m "not slow"`` is the fast lane (docs/contributing.md)."""


LAST_ENDED: list[tuple[str, dict[str, set[str]]]] = []
"""The last test this process ended, and the stop signals' state it left."""
SIGNALS_BEFORE = pytest.StashKey[tuple[dict[int, Any], dict[str, set[str]], set[int]]]()


def os_signal_state() -> dict[str, set[str]]:
    """The stop signals this thread blocks and this process ignores, as the kernel holds
    them (``/proc/thread-self/status``: a C library can change them behind Python's back,
    and a child process inherits both)."""
    fields = dict(line.split(':', 1) for line in
                  Path('/proc/thread-self/status').read_text().splitlines() if ':' in line)
    return {key: {signal.Signals(signum).name for signum in STOP_SIGNALS
                  if int(fields[key], 16) >> (signum - 1) & 1}
            for key in ('SigBlk', 'SigIgn')}


def pytest_configure(config: pytest.Config) -> None:
    """Take SIGINT as a command started from a terminal does, in this process and in each
    worker: a shell starts a background job (``cmd &``) with SIGINT ignored, a child
    process inherits that, and the suite's Ctrl-C tests would then send Ctrl-C to children
    that never see it."""
    if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_setup(item: pytest.Item) -> None:
    """Note the stop signals' state before the test and its fixtures are set up (see
    :func:`pytest_runtest_teardown`); fail if it changed since the previous test ended (a
    thread or process that test left behind)."""
    kernel_now = os_signal_state()
    if LAST_ENDED and LAST_ENDED[-1][1] != kernel_now:
        previous, kernel_then = LAST_ENDED.pop()
        raise AssertionError(f'the stop signals changed from {kernel_then} to {kernel_now} '
                             f'after the previous test in this process ended: {previous}')
    item.stash[SIGNALS_BEFORE] = (
        {signum: signal.getsignal(signum) for signum in STOP_SIGNALS}, os_signal_state(),
        signal.pthread_sigmask(signal.SIG_BLOCK, set()))


@pytest.hookimpl(wrapper=True)
def pytest_runtest_teardown(item: pytest.Item) -> Iterator[None]:
    """A test (its fixtures included, module-wide ones too) that leaves a stop signal's
    handler changed, or the signal blocked or ignored, fails in its teardown, and the state
    is put back: a child process inherits an ignored or blocked SIGINT, so one test's
    leftover would change what later tests in the same worker see (a Ctrl-C that never
    arrives)."""
    result = yield
    if SIGNALS_BEFORE not in item.stash:
        return result
    handlers, kernel_before, mask = item.stash[SIGNALS_BEFORE]
    changed: dict[str, object] = {signal.Signals(signum).name: after for signum in STOP_SIGNALS
                                  if (after := signal.getsignal(signum)) != handlers[signum]}
    kernel_after = os_signal_state()
    if kernel_after != kernel_before:
        changed['kernel'] = kernel_after
    for signum, handler in handlers.items():
        if handler is not None:
            signal.signal(signum, handler)   # the kernel's state follows Python's again
    signal.pthread_sigmask(signal.SIG_SETMASK, mask)
    LAST_ENDED[:] = [(item.nodeid, os_signal_state())]
    assert not changed, (f'the test or its fixtures left these signal handlers changed: '
                         f'{changed} (before: {kernel_before})')
    return result


def tier(path: Path) -> str | None:
    """The tier of the test module at ``path`` (None outside the tier folders)."""
    try:
        parts = path.resolve().relative_to(TESTS).parts
    except ValueError:
        return None
    return parts[0] if len(parts) > 1 and parts[0] in TIERS else None


WALL_GROUP = 'wall:'
"""The prefix of the xdist group of a ``wall_clock`` test (one group per test, or per module
whose tests share a module-scoped fixture): the scheduler runs these units on its wall
lanes (:func:`pytest_xdist_make_scheduler`)."""


def _group_name(text: str) -> str:
    """``text`` as an xdist group name: xdist reads the group after the last ``@`` of an id
    unless a ``]`` follows it, so neither may appear in the name."""
    return re.sub(r'[\[\]@]', '_', text)


@pytest.hookimpl(tryfirst=True)   # before pytest-xdist reads the xdist_group marks
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Mark each test with its tier (its folder), then order and group the suite for
    ``pytest -n 6 --dist loadgroup`` (scripts/test.sh).

    * Tests that share a module-scoped fixture (a colcon build, one graph run read by many
      tests) form one xdist group per module, and the tests of any module that read a
      shared run (:data:`SHARED_RUNS`) one group per run, so that the fixture is built once.
    * A ``wall_clock`` test (it mostly waits for real time: a soak at 10 Hz, a browser
      session) is a unit of its own, or its module's group is one, named
      :data:`WALL_GROUP` ``...``: the scheduler runs such units on its wall lanes, half of
      the workers, and every other unit on the others, so that the waiting tests wait side
      by side while the CPU-bound ones keep both cores busy (when every worker took a
      waiting test at the start, the CPU idled for the first minutes of the run).
    * Every other test is a unit of its own, handed to whichever free worker is not a wall
      lane.
    * The wall-clock tests first, then the others, each kind longest unit first (seconds
      from :data:`DURATIONS`), so that none of them ends the run alone (scripts/test.sh
      keeps this order: ``--no-loadscope-reorder``).
    Without xdist the groups do nothing and only the order changes.
    """
    del config
    groups: dict[pytest.Item, str] = {}
    for item in items:
        name = tier(item.path)
        if name is not None:
            item.add_marker(getattr(pytest.mark, name))
        shared = [run for run in SHARED_RUNS if run in getattr(item, 'fixturenames', ())]
        if shared:
            groups[item] = shared[0]
            continue
        fixture_info = getattr(item, '_fixtureinfo', None)
        # one group per module, whichever of its module-scoped fixtures a test uses (a
        # group per fixture split a module's tests that share one run over two workers)
        if fixture_info is not None and any(
                definitions and definitions[-1].scope == 'module'
                for definitions in fixture_info.name2fixturedefs.values()):
            groups[item] = f'{item.module.__name__}.module_fixtures'
    walls = {groups[item] for item in items
             if item in groups and item.get_closest_marker('wall_clock') is not None}
    for item in items:
        group = groups.get(item)
        if group in walls:
            group = _group_name(WALL_GROUP + group)
        elif group is None and item.get_closest_marker('wall_clock') is not None:
            group = _group_name(WALL_GROUP + item.nodeid)
        if group is not None:
            item.add_marker(pytest.mark.xdist_group(group))

    # each unit's expected seconds (a group's: its tests' sum), from the last stored run
    known = stored_durations()
    unit_s: dict[str, float] = {}
    for item in items:
        unit = _unit(item)
        unit_s[unit] = unit_s.get(unit, 0.0) + known.get(item.nodeid, DEFAULT_DURATION_S)

    def rank(item: pytest.Item) -> tuple[int, float, str]:
        unit = _unit(item)
        return (0 if item.get_closest_marker('wall_clock') is not None else 1,
                -unit_s[unit], unit)

    items.sort(key=rank)


def _unit(item: pytest.Item) -> str:
    """The xdist unit of ``item``: its group, or itself."""
    mark = item.get_closest_marker('xdist_group')
    return f'@{mark.args[0]}' if mark is not None else item.nodeid


DURATIONS = TESTS / 'durations.json'
"""Each test's seconds (setup, call and teardown) in a whole run of scripts/test.sh, rounded:
the order of the queue (the longest units first on each lane, as pytest-split and LPT
scheduling do). Rewritten by a run with ``TRUST_AV_STORE_DURATIONS=1``; a test missing from
it counts :data:`DEFAULT_DURATION_S`. It only orders the queue: a stale file makes a run
slower, never wrong."""
DEFAULT_DURATION_S = 0.5
MEASURED: dict[str, float] = {}


def stored_durations() -> dict[str, float]:
    """:data:`DURATIONS` as a dict (empty when there is none)."""
    if not DURATIONS.is_file():
        return {}
    data = json.loads(DURATIONS.read_text(encoding='utf-8'))
    return {str(k): float(v) for k, v in data.items()}


def pytest_runtest_logreport(report: pytest.TestReport) -> None:
    """Sum each test's phases (in the xdist controller: every worker's reports), without the
    ``@group`` xdist puts into a grouped test's id."""
    nodeid = report.nodeid
    if nodeid.rfind('@') > nodeid.rfind(']'):
        nodeid = nodeid.rsplit('@', 1)[0]
    MEASURED[nodeid] = MEASURED.get(nodeid, 0.0) + report.duration


def pytest_sessionfinish(session: pytest.Session) -> None:
    """With ``TRUST_AV_STORE_DURATIONS=1`` (not in a worker): the tests this run ran get their
    new seconds in :data:`DURATIONS`, the others keep theirs."""
    if os.environ.get('TRUST_AV_STORE_DURATIONS') != '1' or hasattr(session.config,
                                                                      'workerinput'):
        return
    merged = {**stored_durations(), **MEASURED}
    stored = {k: round(v, 1) for k, v in sorted(merged.items()) if v >= DEFAULT_DURATION_S}
    DURATIONS.write_text(json.dumps(stored, indent=0) + '\n', encoding='utf-8')


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config: pytest.Config, log: object) -> object | None:
    """``--dist loadgroup`` with lanes, and two mends for a worker that dies.

    Lanes: the even-numbered workers (``gw0``, ``gw2``, ...) are wall lanes: each takes the
    next :data:`WALL_GROUP` unit in the queue, the others the next other unit, and a lane
    whose own kind has run out takes the other kind. So half of the workers wait on the
    ``wall_clock`` tests while the rest keep the CPU busy.

    The mends, for pytest-timeout's thread method, which ends a hung test's worker (xdist
    then starts a new one), so that such a test fails once and alone and the run goes on:

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

        def _assign_work_unit(self, node: Any) -> None:
            # xdist 3.8's LoadScopeScheduling._assign_work_unit, but the unit is the first
            # of the node's lane (the first of any kind when its lane's have run out)
            wall_lane = int(node.gateway.id.removeprefix('gw')) % 2 == 0
            scope = next((s for s in self.workqueue
                          if s.startswith(WALL_GROUP) == wall_lane), next(iter(self.workqueue)))
            work_unit = self.workqueue.pop(scope)
            self.assigned_work.setdefault(node, {})[scope] = work_unit
            collection = self.registered_collections[node]
            node.send_runtest_some([collection.index(nodeid)
                                    for nodeid, done in work_unit.items() if not done])

        def _reschedule(self, node: Any) -> None:
            if node in self.registered_collections:
                super()._reschedule(node)

    return Scheduling(config, log)


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
