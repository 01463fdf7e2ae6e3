"""Start the node graph as separate processes, step it in lock-step, stop it cleanly.

ROS 2 launch is not available here, so this module does its job: every node is its own
process (:mod:`trust_av.graph.processes`), each run leases a free, private
``ROS_DOMAIN_ID`` (:mod:`trust_av.graph.domains`) with localhost-only discovery,
and this process follows the run through its own node (:mod:`trust_av.graph.session`).

Sequence: lease a domain that holds no one else's participants (or, on a domain the caller
names, check that nothing there clashes with the run's namespace); start the nodes; wait until
every topic of the table has its publishers and subscribers and the recorder has matched
every publisher; publish ``sim/start``; follow the recorder's status for progress (no
per-step subscriber of our own), the nodes' health and the domain's privacy; the run is
complete when the recorder, holding every message of every step, finishes its bag and exits
(until then every publisher stays up); then stop the rest.

However it ends, the recording is a finished rosbag2 bag directory: on an interrupt
(SIGINT, SIGTERM) or an error the nodes are stopped step authority first and recorder last
(:meth:`~trust_av.graph.processes.Graph.stop`); if the recorder itself died it is
repaired from its chunks (:func:`~trust_av.graph.bag_repair.repair_bag`); a full
disk finishes it with every complete step
(:class:`~trust_av.graph.bag_writer.DiskFullError`).
If this process is killed, the nodes stop by themselves and the recorder finishes the bag.
"""

from __future__ import annotations

import contextlib
import shutil
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from preceding_traffic.traces import SpeedTrace
from trust_av.errors import TrustAvAppError
from trust_av.graph.bag_records import records_from_bag
from trust_av.graph.bag_repair import finished, repair_bag
from trust_av.graph.bag_writer import EXIT_DISK_FULL, DiskFullError
from trust_av.graph.domains import check_domain_id, check_namespace, lease_domain
from trust_av.graph.lifecycle_client import MANAGED_NODES, set_states
from trust_av.graph.processes import RECORDER, Graph, GraphError, NodeSpec
from trust_av.graph.session import clashing_participants, foreign_participants, graph_session
from trust_av.graph.stalls import BUSY_SHARE, cpu_s, waited_for
from trust_av.system import run_record
from trust_av.system.closed_loop import InitialState, equilibrium_start
from trust_av.system.config import RunConfig
from trust_av.system.metrics import StepRecord, first_collision
from trust_av_common.errors import TrustAvError
from trust_av_common.output_files import stop_signals_held
from trust_av_common.record_window import window_steps
from trust_av_common.topics import qualified

__all__ = ['GraphRun', 'missing_messages', 'node_specs', 'run_graph', 'run_graph_records',
           'write_record']


def node_specs(config: RunConfig, trace_arg: str, trace: SpeedTrace, initial: InitialState,
               bag: Path, max_steps: int) -> list[NodeSpec]:
    """The six processes of a simulated run and their per-run parameters."""
    cfg = config.for_trace(trace)
    start = trace.t0_s
    shared = {'speed_max_mps': cfg.planner.speed_max_mps, 'speed_max_from_trace': False}
    return [
        NodeSpec('recorder', 'trust_av.graph.recorder_node',
                 {'bag_path': str(bag), 'expected_steps': trace.steps}),
        NodeSpec('trust_monitor', 'trust_monitor.monitor_node', {'autostart': False}),
        NodeSpec('ego_plant', 'trust_av_planner.ego_plant_node',
                 {'initial_position_m': initial.av.position_m,
                  'initial_speed_mps': initial.av.speed_mps, 'start_time_s': start}),
        NodeSpec('human_driver', 'human_driver_sim.driver_node',
                 {**shared, 'initial_position_m': initial.human.position_m,
                  'initial_speed_mps': initial.human.speed_mps, 'start_time_s': start,
                  'driver_model': cfg.follower.driver_model}),
        NodeSpec('planner', 'trust_av_planner.planner_node',
                 {**shared, 'alpha': cfg.planner.alpha, 'predictor': cfg.planner.predictor,
                  'perturbation': cfg.planner.perturbation,
                  'perturbation_seed': cfg.planner.perturbation_seed,
                  'lead_preview': cfg.planner.lead_preview, 'autostart': False}),
        NodeSpec('preceding_traffic', 'preceding_traffic.traffic_node',
                 {'trace': trace_arg, 'initial_position_m': initial.traffic.position_m,
                  'max_steps': max_steps, 'recorder_window_steps': window_steps(),
                  'bag_topic': config.trace.bag_topic,
                  'bag_message_type': config.trace.bag_message_type,
                  'max_sample_gap_s': config.trace.max_sample_gap_s}),
    ]


@dataclass
class GraphRun:
    """Outcome of a graph run."""

    bag: Path
    domain_id: int
    steps: int
    wall_s: float
    startup_s: float
    steps_s: float = 0.0
    """From the start signal to the last step recorded (within ``wall_s``, after
    ``startup_s``; the rest of ``wall_s`` is finishing the recording)."""


def run_graph(config: RunConfig, trace_arg: str, trace: SpeedTrace, bag: Path, *,
              max_steps: int = 0, startup_timeout_s: float = 30.0,
              step_timeout_s: float = 30.0, log_dir: Path | None = None,
              on_step: Callable[[int, int], None] | None = None,
              on_clock: Callable[[int], None] | None = None, namespace: str = '/',
              domain_id: int | None = None) -> GraphRun:
    """Run the whole graph over ``trace`` (already truncated to ``max_steps``) into the bag
    directory ``bag`` (it must not exist).

    Args:
        config: the run configuration (its params files, in order, are what every node
            gets; the command's overrides become per-run values).
        trace_arg: the trace as the traffic node gets it (name, CSV or bag path).
        trace: the loaded trace (its steps decide when the run is complete).
        bag: the bag directory to record to.
        max_steps: stop after this many steps (0: the whole trace).
        startup_timeout_s: how long the graph may take to connect, s.
        step_timeout_s: how long a step may take, s.
        log_dir: where the node logs and the per-run params file go (default:
            ``<bag>.logs`` beside the bag).
        on_step: progress: called with (steps recorded, total steps), at most twice a second.
        on_clock: benchmarks: called with every step's 1-based index as this process
            receives the step clock (adds a per-step subscriber).
        namespace: the ROS namespace every node (and this process's node) runs in: its
            topics are ``<namespace>/ego/odom`` ..., and so are the recorded names.
        domain_id: the ROS domain to run on, shared with whatever else is there (other
            graphs in other namespaces); the run refuses to start if a node in
            ``namespace`` or a publisher on one of its topics is already there. None:
            lease a free, private domain (nothing else may be on it).

    Raises:
        TrustAvAppError: ``namespace`` or ``domain_id`` is invalid (one line naming it).
        GraphError: the configuration's ``clock_mode`` is not ``lockstep``.
        GraphError: the graph did not connect in time, a node died, a step stalled, or a
            foreign publisher appeared (on one of this graph's topics).
        DiskFullError: the disk filled up; the bag is finished with every complete step.
    """
    from rosgraph_msgs.msg import Clock
    from std_msgs.msg import Empty

    from trust_av_common.ros.qos import QOS

    if config.clock.wall:
        raise GraphError(f'clock_mode {config.clock.clock_mode} (params file): this command steps '
                         'the graph on sim time (lockstep); wall-clock runs are trust-av '
                         'shadow, or the nodes started by hand')
    check_namespace(namespace)
    if domain_id is not None:
        check_domain_id(domain_id)
    initial = equilibrium_start(config.for_trace(trace), trace)
    specs = node_specs(config, trace_arg, trace, initial, bag, max_steps)
    started = time.monotonic()
    logs = log_dir if log_dir is not None else bag.with_name(bag.name + '.logs')
    with _domain(domain_id, namespace) as domain:
        graph = Graph(specs, config.params_files, domain, logs, namespace)
        try:
            write_record(config, trace, graph)   # a full disk: said as for the node logs
            with graph_session(graph, 'orchestrator') as session:
                node = session.node
                if on_clock is not None:
                    node.create_subscription(
                        Clock, session.topic('clock'),
                        lambda msg: on_clock(round((msg.clock.sec + msg.clock.nanosec * 1e-9
                                                    - trace.t0_s) / trace.dt_s) + 1),
                        QOS['CLOCK'])
                start_pub = node.create_publisher(Empty, session.topic('sim/start'),
                                                  QOS['LATCHED'])
                # the managed nodes wait unconfigured: configured and activated here, as a
                # lifecycle manager does, before the graph is checked and started
                set_states(node, session.executor,
                           [_managed(namespace, name) for name in MANAGED_NODES], 'active',
                           startup_timeout_s, graph)
                session.wait_connected(startup_timeout_s)
                startup = time.monotonic() - started
                start_pub.publish(Empty())
                _follow(session, trace.steps, step_timeout_s, on_step)
                stepped = time.monotonic() - started - startup
        except TrustAvError as err:
            # The run failed: finish the recording, but a failure to do so must not hide
            # why the run failed (an exception raised in a `finally` would replace it).
            told = _failure(err, graph, bag, namespace, trace.steps)
            if told is not None:
                raise told from err
            raise
        except BaseException:
            _finish_recording(graph, bag)   # a stop: finish the bag, then go on stopping
            _drop_if_no_step(bag, namespace)
            raise
        _finish_recording(graph, bag)
    return GraphRun(bag=bag, domain_id=domain, steps=trace.steps,
                    wall_s=time.monotonic() - started, startup_s=startup, steps_s=stepped)


def _failure(err: TrustAvError, graph: Graph, bag: Path, namespace: str,
             steps: int) -> GraphError | None:
    """After a failed run: the recording finished, and the error that tells why with what
    the bag lacks, which node a stall waited for, that no step was kept or that the disk is
    nearly full (None: ``err`` says it all).

    Raises:
        DiskFullError: the recorder ran out of disk (that is the cause).
    """
    try:
        _finish_recording(graph, bag)
        lost = (missing_messages(bag, steps, namespace)
                if isinstance(err, IncompleteRecordingError) else '')
    except DiskFullError:
        raise                       # the recorder ran out of disk: that is the cause
    except TrustAvError as finishing:
        return GraphError(f'{err}; {finishing}{_low_disk(bag)}')
    if lost:
        return GraphError(f'{err}; the bag lacks {lost} messages')
    if isinstance(err, StallError):
        return GraphError(f'{err}{waited_for(bag, namespace)}')
    if _drop_if_no_step(bag, namespace):
        return GraphError(f'{err}; no step was recorded, so no bag was kept')
    low_disk = '' if isinstance(err, DiskFullError) else _low_disk(bag)
    return GraphError(f'{err}{low_disk}') if low_disk else None


def write_record(config: RunConfig, trace: SpeedTrace, graph: Graph) -> dict[str, str]:
    """Write the record of ``graph``'s run of ``config`` on ``trace`` into its logs
    directory, before it starts (:mod:`trust_av.system.run_record`): the effective
    parameters of every node (``effective_params.yaml``) and the bag's ``custom_data``
    entries (``run_record.yaml``), which its recorder node, if it has one (its
    ``record_file``, set here), writes into the bag's metadata.

    Returns:
        The ``custom_data`` entries (for a bag written in this process).

    Raises:
        GraphError: the files cannot be written (one line naming the directory).
    """
    logs = graph.log_dir
    record = logs / run_record.RECORD_FILE_NAME
    for spec in graph.specs:
        if spec.name == RECORDER:
            spec.params['record_file'] = str(record)
    per_run = {spec.name: spec.params for spec in graph.specs}
    entries = run_record.custom_data(config.for_trace(trace), per_run)
    try:
        logs.mkdir(parents=True, exist_ok=True)
        (logs / run_record.PARAMS_FILE_NAME).write_text(
            '# The effective parameters of every node of this run: the params files, the '
            "command line's options and the per-run values merged.\n"
            + entries[run_record.PARAMS_KEY])
        record.write_text(yaml.safe_dump(entries, default_flow_style=False, sort_keys=True))
    except OSError as err:
        raise GraphError(f'{logs}: cannot write the node logs and per-run parameters there '
                         f'({err.strerror})') from err
    return entries


def _managed(namespace: str, name: str) -> str:
    """A managed node's name in the run's namespace, as :func:`set_states` takes it."""
    return f'{namespace.strip("/")}/{name}'.lstrip('/')


@contextlib.contextmanager
def _domain(domain_id: int | None, namespace: str) -> Iterator[int]:
    """The run's domain: a leased private one, or ``domain_id`` once nothing on it clashes
    with a graph in ``namespace``."""
    if domain_id is None:
        with lease_domain(foreign_participants) as domain:
            yield domain
        return
    clash = clashing_participants(domain_id, namespace)
    if clash:
        raise GraphError(f'domain {domain_id} already has a graph in namespace {namespace}: '
                         f'{clash}')
    yield domain_id


OWN_PAUSE_S = 2.0
"""A turn of the follow loop (a spin of at most 0.05 s) that took longer than this means this
process itself was suspended (Ctrl-Z then ``fg``, SIGSTOP) or not scheduled at all: that
time was not the graph's and does not count towards a stall."""


class IncompleteRecordingError(GraphError):
    """The graph finished every step but the recorder did not receive every message."""


class StallError(GraphError):
    """No step recorded for the stall timeout, and no node stopped or busy: the finished
    bag tells which node the chain waits for (:func:`trust_av.graph.stalls.waited_for`)."""


def _drop_if_no_step(bag: Path, namespace: str) -> bool:
    """Remove the finished bag of a run that ended before its first step (its ``clock``
    topic holds no message: only the initial states, if anything); True if removed. A run
    stopped or failed during start-up leaves no bag rather than an empty one; its node logs
    stay. A bag that does not read, or not finished, is left as it is."""
    from rosbags.rosbag2 import Reader, ReaderError

    if not (bag / 'metadata.yaml').is_file() or bag.is_symlink():
        return False
    try:
        with Reader(bag) as reader:
            counts = {c.topic: c.msgcount for c in reader.connections}
    except (ReaderError, OSError):
        return False
    if counts.get(qualified('clock', namespace), 0):
        return False
    with stop_signals_held():
        shutil.rmtree(bag)
    return True


def _follow(session: Any, steps: int, step_timeout_s: float,
            on_step: Callable[[int, int], None] | None) -> None:
    """Until the recorder has every step and exits: health, privacy, progress, stalls.

    A stall is ``step_timeout_s`` without a step recorded (once every step is: a message),
    not counting the time this process was suspended itself (a loop turn longer than
    :data:`OWN_PAUSE_S`: the nodes went on without it). Time a node of the graph spends
    stopped (SIGSTOP, a debugger), deadlocked or busy does count: it makes no progress, and
    the run ends naming it (:mod:`trust_av.graph.stalls`).
    """
    graph = session.graph
    recorder = graph.by_name(RECORDER)
    last, messages, last_change = -1, -1, time.monotonic()
    turn = last_change
    cpu_at_change = _cpu(graph)
    while recorder.popen.poll() is None:
        session.spin(0.05)
        now = time.monotonic()
        if now - turn > OWN_PAUSE_S:
            last_change += now - turn      # this process was suspended, not the graph
        turn = now
        session.check({RECORDER})
        if session.recorder_steps != last:
            last, last_change = session.recorder_steps, now
            cpu_at_change = _cpu(graph)
            if on_step is not None:
                on_step(min(last, steps), steps)
        elif last >= steps and session.recorder_messages != messages:
            messages, last_change = session.recorder_messages, now
        elif now - last_change > step_timeout_s:
            if last >= steps:
                raise IncompleteRecordingError(
                    f'node recorder did not receive every message of the run in '
                    f'{step_timeout_s:g} s; node logs in {graph.log_dir}')
            head = f'no progress after {last} steps in {step_timeout_s:g} s'
            tail = f'node logs in {graph.log_dir}'
            stopped = graph.suspended()
            if stopped:
                raise GraphError(f'{head}: node {", ".join(stopped)} is stopped (state T: '
                                 f'SIGSTOP, Ctrl-Z or a debugger); {tail}')
            used = {name: cpu - cpu_at_change.get(name, 0.0)
                    for name, cpu in _cpu(graph).items()}
            busy = [f'{name} ({used[name]:.1f} s of CPU)' for name in sorted(used)
                    if used[name] > BUSY_SHARE * (now - last_change)]
            if busy:
                raise GraphError(f'{head}: node {", ".join(busy)} is busy without making '
                                 f'progress; {tail}')
            if recorder.state() == 'D':
                raise GraphError(f'{head} (the recorder is blocked writing to its disk); '
                                 f'{tail}')
            raise StallError(f'{head} (the graph stalled); {tail}')
    if recorder.popen.returncode == EXIT_DISK_FULL:
        return
    session.check({RECORDER})
    if on_step is not None:
        on_step(steps, steps)


def _cpu(graph: Graph) -> dict[str, float]:
    """CPU time each node process has used so far, s."""
    return {p.spec.name: cpu_s(p.popen.pid) for p in graph.processes}


def missing_messages(bag: Path, steps: int, namespace: str = '/') -> str:
    """What a finished bag of a ``steps``-step run lacks, as ``'/tf 43 of 1802, ...'`` (''
    when it holds every message of every step).

    Args:
        bag: the bag directory.
        steps: the steps of the run.
        namespace: the run's namespace (the recorded topic names are in it).

    Raises:
        TrustAvAppError: the bag cannot be read.
    """
    from rosbags.rosbag2 import Reader, ReaderError

    from trust_av_common.topics import TOPICS, qualified

    try:
        with Reader(bag) as reader:
            counts = {c.topic: c.msgcount for c in reader.connections}
    except (ReaderError, OSError) as err:
        raise TrustAvAppError(f'{bag}: cannot read the recording ({err})') from err
    lacking = []
    for row in TOPICS:
        if 'recorder' in row.subscribers:
            name, expected = qualified(row.name, namespace), row.messages(steps)
            if counts.get(name, 0) < expected:
                lacking.append(f'{name} {expected - counts.get(name, 0)} of {expected}')
    return ', '.join(lacking)


LOW_DISK_BYTES = 1 << 20
"""Below this much free space where the bag goes, a failed run says so: a recorder that
could not even write its log dies without a word."""


def _low_disk(bag: Path) -> str:
    """``'; the disk holding BAG has only N kB free'`` when it is nearly full, else ''."""
    try:
        free = shutil.disk_usage(bag.parent).free
    except OSError:
        return ''
    return (f'; the disk holding {bag} has only {free // 1024} kB free'
            if free < LOW_DISK_BYTES else '')


def _finish_recording(graph: Graph, bag: Path) -> None:
    """After the nodes are stopped: a full disk is reported, a recording whose recorder
    died is repaired (every complete chunk kept) unless the recorder had finished it before
    it was stopped (:func:`~trust_av.graph.bag_repair.finished`: a stop signal can reach it
    after its bag is whole)."""
    if not any(p.spec.name == RECORDER for p in graph.processes):
        return
    recorder = graph.by_name(RECORDER)
    code = recorder.popen.returncode
    if code == EXIT_DISK_FULL:
        raise DiskFullError(recorder.error_line() or f'{bag}: the disk filled up')
    if code not in (0, None) and bag.exists() and not finished(bag):
        repair_bag(bag)


def run_graph_records(config: RunConfig, trace_arg: str, trace: SpeedTrace, bag: Path,
                      **options: Any) -> tuple[GraphRun, list[StepRecord]]:
    """:func:`run_graph`, then its recording read back: a record per step, to a collision.

    Raises:
        GraphError: as :func:`run_graph`.
        TrustAvAppError: the recording does not hold every step of the run.
    """
    result = run_graph(config, trace_arg, trace, bag, **options)
    records = records_from_bag(bag, options.get('namespace', '/'))
    crash = first_collision(records)
    if len(records) != trace.steps and (crash is None or crash.step != len(records) - 1):
        raise TrustAvAppError(f'{bag}: {len(records)} complete steps recorded, expected '
                              f'{trace.steps}')
    result.steps = len(records)
    return result, records
