"""The wall-clock run engine: a graph of node processes run on wall time, recorded in this
process, every recorded message accounted for. ``trust-av shadow`` (:mod:`.shadow`),
``trust-av shadow --whole-graph`` and the person's drive (:mod:`trust_av.drive.graph_run`)
are configurations of it: a :class:`WallPlan` says what runs and what is recorded, a
:class:`WallHooks` subclass what this process does meanwhile (its state is the subclass's).

:func:`run_wall`:

1. leases a private domain (:func:`~trust_av.graph.domains.lease_domain`), starts the
   graph's processes and this process's node (:func:`~trust_av.graph.session.graph_session`);
2. opens the bag (:class:`~trust_av.graph.bag_writer.BagWriter`, its ``custom_data``
   :attr:`WallPlan.custom_data`), lets the hooks make their publishers
   (:meth:`WallHooks.setup`), adds every topic of :attr:`WallPlan.topics` in order (the
   bag's channels) and subscribes those recorded from the wire raw: each message is
   written (log time :attr:`WallPlan.receive_time`), entered in the publication ledger
   (:mod:`~trust_av.graph.publication_ledger`) under the publishers
   :meth:`WallHooks.publishers` names, and given to :meth:`WallHooks.on_message`;
3. brings the managed nodes to ``active`` (those of :attr:`WallPlan.activate_at_start` to
   ``inactive``) and waits until every topic has its publishers and subscribers
   (:attr:`WallPlan.needs`) and :meth:`WallHooks.pending` names nothing;
4. :meth:`WallHooks.start` (False: the run never starts; on to 6), then activates
   :attr:`WallPlan.activate_at_start`;
5. turns until :meth:`WallHooks.should_stop`: a turn every :attr:`WallPlan.tick_s` (the
   executor spun until it is due) or, with ``tick_s`` 0, after each executor event (at
   most :attr:`WallPlan.spin_s` apart); each turn :meth:`WallHooks.every_tick` and the
   processes' health; once a second a chunk of the bag (a full disk ends the turns) and
   :meth:`WallHooks.every_second`;
6. :meth:`WallHooks.stopping`; stops the nodes (the managed ones deactivated first with
   :attr:`WallPlan.deactivate_on_stop`) while taking what they publish, drains;
   :meth:`WallHooks.after_stop`;
7. reads every node's loop report (what it published per topic), counts what the recording
   lost (:meth:`~trust_av.graph.publication_ledger.PublicationLedger.lost`), writes the
   account into the bag's ``custom_data`` (:func:`loss_entries`), lets
   :meth:`WallHooks.finish` add its own, and finishes the bag.

However it ends, the bag is finished and the nodes are stopped (the context managers); a
full disk raises :class:`~trust_av.graph.bag_writer.DiskFullError` once the nodes are
stopped and the bag holds every complete second.

The lock-step ``trust-av run`` (:func:`~trust_av.graph.orchestrator.run_graph`) is not a
configuration of this engine: there the recorder is a node of the graph that the step
authority waits for (back-pressure, :mod:`trust_av_common.record_window`), so nothing can
be lost and this process only follows; here this process is the recorder and nothing waits
for it.
"""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Callable, Collection, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from trust_av.graph import stop_signals
from trust_av.graph.bag_writer import BagWriter, DiskFullError
from trust_av.graph.domains import lease_domain
from trust_av.graph.lifecycle_client import MANAGED_NODES, set_states
from trust_av.graph.processes import Graph, GraphError, NodeSpec
from trust_av.graph.publication_ledger import Lost, PublicationLedger, Publisher
from trust_av.graph.session import foreign_participants, graph_session
from trust_av_common.topics import TOPIC, Topic, qualified
from trust_av_common.wall_clock import NS_PER_S

__all__ = ['DRAIN_S', 'RecordedTopic', 'WallHooks', 'WallPlan', 'WallResult', 'WallRun',
           'initial_messages', 'loss_entries', 'node_loops', 'run_wall', 'tf_frames']

DRAIN_S = 0.5
"""After the nodes stopped, what is still on its way is taken until nothing has come for
this long (at most :data:`DRAIN_MAX_S`)."""
DRAIN_MAX_S = 30.0
QUEUED_PER_TURN = 64
"""A turn takes at most this many queued messages besides its own spin: a busy host that
let a backlog build up is caught up with, and the turn's own work still comes round."""


@dataclass(frozen=True)
class RecordedTopic:
    """One topic of the bag: its full name, type and offered QoS (one profile per
    publisher); ``qos`` the subscription's profile when it is recorded from the wire, None
    when this process writes it itself."""

    name: str
    msgtype: str
    offered: Any
    qos: Any = None


@dataclass
class WallPlan:
    """What a wall run starts and records."""

    name: str
    """This process's node."""
    specs: Callable[[Path], list[NodeSpec]]
    """The node processes, given the log directory."""
    params_files: tuple[Path, ...]
    bag: Path
    topics: list[RecordedTopic]
    needs: dict[str, tuple[int, int]]
    """Topic -> (publishers, subscribers) to wait for before the start."""
    nodes: tuple[str, ...]
    """The nodes stopped at the end, whose loop reports are read."""
    startup_timeout_s: float
    custom_data: Callable[[Graph], Mapping[str, str]] = lambda _graph: {}
    receive_time: bool = True
    """Log time = receive time (as ``ros2 bag record``); False: the header stamp."""
    tick_s: float = 0.0
    spin_s: float = 0.05
    activate_at_start: tuple[str, ...] = ()
    deactivate_on_stop: bool = True
    from_first: Collection[Publisher] = ()
    stop_edge: Collection[Publisher] = ()
    initial: Mapping[Publisher, int] = field(default_factory=dict)
    """Messages a publisher sends before its loop counts (its initial state)."""

    @property
    def log_dir(self) -> Path:
        return self.bag.with_name(self.bag.name + '.logs')


@dataclass
class WallResult:
    """What a wall run gave: message counts per topic, the loop reports, the losses."""

    bag: Path
    counts: dict[str, int]
    loops: dict[str, Any]
    losses: tuple[Lost, ...]
    ledger: PublicationLedger
    """What the recording received, per publisher."""


class WallRun:
    """A running wall run, as the hooks see it."""

    def __init__(self, plan: WallPlan, graph: Graph, session: Any, recording: BagWriter) -> None:
        self.plan = plan
        self.graph = graph
        self.node = session.node
        self.executor = session.executor
        self.recording = recording
        self.ledger = PublicationLedger()
        self.subscriptions: list[Any] = []
        self.started = False
        self.taken = 0
        """Messages recorded from the wire so far."""

    def spin(self, timeout_s: float) -> None:
        """Take this process's events for at most ``timeout_s`` (a stop signal raises)."""
        stop_signals.spin_once(self.executor, timeout_s)

    def take_queued(self) -> None:
        """Take what is queued already (at most :data:`QUEUED_PER_TURN` messages): one spin
        takes one message, and a turn that took one while more came fell behind."""
        for _ in range(QUEUED_PER_TURN):
            before = self.taken
            self.spin(0.0)
            if self.taken == before:
                return

    def write(self, topic: str, data: bytes) -> None:
        """Write a message of this process's own (unless a full disk finished the bag)."""
        if not self.recording.finished:
            self.recording.write(topic, data)


class WallHooks:
    """What a configuration does during a run (every hook a no-op here)."""

    def setup(self, run: WallRun) -> None:
        """Make this process's publishers (before any topic is subscribed)."""

    def publishers(self, topic: str, data: bytes) -> Iterable[str]:
        """The nodes that published ``data`` on ``topic`` (the ledger's publishers): the
        topic table's first publisher."""
        return (TOPIC[topic.lstrip('/')].publishers[0],)

    def on_message(self, run: WallRun, topic: str, data: bytes, info: dict[str, Any]) -> None:
        """A message recorded from the wire (written and counted already)."""

    def pending(self, run: WallRun) -> list[str]:
        """What the start still waits for besides the topics' endpoints."""
        return []

    def start(self, run: WallRun) -> bool:
        """Start the run (False: it never started)."""
        return True

    def every_tick(self, run: WallRun, now_ns: int) -> None:
        """One turn of the run (monotonic ``now_ns``)."""

    def should_stop(self, run: WallRun, now_ns: int) -> bool:
        """Whether the run is over (asked before every turn)."""
        return True

    def every_second(self, run: WallRun, now_ns: int) -> None:
        """About once a second, after the bag's chunk is written."""

    def stopping(self, run: WallRun) -> None:
        """The turns are over; the nodes are still up."""

    def after_stop(self, run: WallRun) -> None:
        """The nodes are stopped; the bag is still open."""

    def own_loops(self) -> dict[str, Any]:
        """This process's own loop reports (besides the nodes')."""
        return {}

    def finish(self, run: WallRun, result: WallResult) -> None:
        """The last chance to write into the bag (its metadata) before it is finished."""


def run_wall(plan: WallPlan, hooks: WallHooks) -> WallResult:
    """Run ``plan`` with ``hooks`` (see the module's docstring for the sequence).

    Raises:
        GraphError: the nodes did not connect in time, one died, or one wrote no loop
            report (after the bag is finished).
        DiskFullError: the disk filled up; the nodes were stopped and the bag finished with
            every complete second.
    """
    with lease_domain(foreign_participants) as domain:  # skips a domain with leftovers
        graph = Graph(plan.specs(plan.log_dir), plan.params_files, domain, plan.log_dir)
        with graph_session(graph, plan.name) as session, \
                BagWriter(plan.bag, custom_data=plan.custom_data(graph)) as recording:
            run = WallRun(plan, graph, session, recording)
            hooks.setup(run)
            _record(run, hooks)
            set_states(run.node, run.executor,
                       [n for n in MANAGED_NODES if n not in plan.activate_at_start], 'active',
                       plan.startup_timeout_s, graph)
            set_states(run.node, run.executor, plan.activate_at_start, 'inactive',
                       plan.startup_timeout_s, graph)
            _wait_topics(run, lambda: hooks.pending(run))
            if hooks.start(run):
                run.started = True
                set_states(run.node, run.executor, plan.activate_at_start, 'active',
                           plan.startup_timeout_s, graph)
                _turns(run, hooks)
            hooks.stopping(run)
            stop_and_drain(graph, run.executor, plan.nodes,
                           node=run.node if plan.deactivate_on_stop else None,
                           taken=lambda: run.taken)
            hooks.after_stop(run)
            result, error = _account(run, hooks)
            hooks.finish(run, result)
            recording.finish()
            if recording.disk_full:
                raise DiskFullError(recording.disk_full)
            if error is not None:
                raise error
            result.counts = dict(recording.counts)
    return result


def _record(run: WallRun, hooks: WallHooks) -> None:
    """Add every topic to the bag; subscribe those recorded from the wire."""
    from trust_av_common.ros.messages import message_class

    recording, ledger = run.recording, run.ledger
    receive_time = run.plan.receive_time

    def record(topic: str, data: bytes, info: dict[str, Any]) -> None:
        if recording.finished:        # finished early only by a full disk
            return
        recording.write(topic, data, receive_time_ns=int(info['received_timestamp'])
                        if receive_time else None)
        run.taken += 1
        sequence = int(info['publication_sequence_number'])
        for name in hooks.publishers(topic, data):
            ledger.received(topic, name, sequence)
        hooks.on_message(run, topic, data, info)

    for topic in run.plan.topics:
        recording.add_topic(topic.name, topic.msgtype, topic.offered)
    for topic in run.plan.topics:
        if topic.qos is not None:
            run.subscriptions.append(run.node.create_subscription(
                message_class(topic.msgtype), topic.name,
                lambda d, info, t=topic.name: record(t, d, info), topic.qos, raw=True))


def _wait_topics(run: WallRun, pending: Callable[[], list[str]]) -> None:
    """Wait until every topic has its (publishers, subscribers) and ``pending`` names
    nothing more."""
    node, timeout_s = run.node, run.plan.startup_timeout_s
    deadline = time.monotonic() + timeout_s
    missing: list[str] = []
    while time.monotonic() < deadline:
        run.spin(0.05)
        run.take_queued()
        run.graph.check_alive(set())
        missing = [f'{topic} ({node.count_publishers(topic)}/{pubs} publishers, '
                   f'{node.count_subscribers(topic)}/{subs} subscribers)'
                   for topic, (pubs, subs) in run.plan.needs.items()
                   if node.count_publishers(topic) < pubs or node.count_subscribers(topic) < subs]
        missing += pending()
        if not missing:
            return
    raise GraphError(f'shadow nodes not connected after {timeout_s:g} s: ' + '; '.join(missing))


def _turns(run: WallRun, hooks: WallHooks) -> None:
    """The run's turns until the hooks stop it or the disk is full."""
    period_ns = round(run.plan.tick_s * NS_PER_S)
    next_tick = time.monotonic_ns()
    next_chunk = next_tick + NS_PER_S
    while True:
        now = time.monotonic_ns()
        if period_ns:
            if now < next_tick:
                run.spin((next_tick - now) / NS_PER_S)
                continue
            next_tick += period_ns
        if hooks.should_stop(run, now):
            return
        hooks.every_tick(run, now)
        run.graph.check_alive(set())
        if now >= next_chunk:
            if not run.recording.end_step():
                return                   # the disk is full: raised once the nodes stop
            next_chunk += NS_PER_S
            hooks.every_second(run, now)
        if not period_ns:
            run.spin(run.plan.spin_s)
            run.take_queued()


def _account(run: WallRun, hooks: WallHooks) -> tuple[WallResult, GraphError | None]:
    """The loop reports and what the recording lost (written into the bag's metadata);
    a node without a report is the error returned (raised once the bag is finished)."""
    plan, error = run.plan, None
    try:
        loops = {**hooks.own_loops(), **node_loops(run.graph, plan.log_dir, plan.nodes)}
    except GraphError as err:
        loops, error = {}, err
    losses: tuple[Lost, ...] = ()
    if error is None:
        recorded = {t.name for t in plan.topics if t.qos is not None}
        published = {(topic, node): int(count) for node, loop in loops.items()
                     for topic, count in loop.get('published', {}).items()
                     if topic in recorded}
        for publisher, count in plan.initial.items():
            published[publisher] = published.get(publisher, 0) + count
        losses = tuple(run.ledger.lost(published, plan.from_first, plan.stop_edge))
        for entry, value in loss_entries(losses).items():
            run.recording.set_custom_data(entry, value)
    result = WallResult(plan.bag, dict(run.recording.counts), loops, losses, run.ledger)
    return result, error


def loss_entries(losses: Iterable[Lost]) -> dict[str, str]:
    """The bag's ``custom_data`` entries of a recording's loss account:
    ``trust_av.recording.lost`` the messages lost (0: none) and, per publisher that lost
    any, ``trust_av.recording.lost.<topic>.<node>`` its count and first-last publication
    numbers (``'3 (publications 17-19)'``)."""
    losses = list(losses)
    entries = {'trust_av.recording.lost': str(sum(loss.count for loss in losses))}
    for loss in losses:
        key = f'trust_av.recording.lost.{loss.topic.strip("/").replace("/", ".")}.{loss.node}'
        entries[key] = loss.describe().split(': ', 1)[1]
    return entries


def initial_messages(recorded: Iterable[Topic], nodes: dict[str, str]) -> dict[Publisher, int]:
    """What each vehicle node publishes before its loop starts, which its loop report does
    not count: the table's initial messages, one per vehicle node (the traffic node
    publishes nothing before /sim/start). ``nodes`` renames a table's node to the one that
    runs in its place (the drive's ``follower_plant`` for ``human_driver``)."""
    initial: dict[Publisher, int] = {}
    for topic in recorded:
        vehicles = [n for n in topic.publishers if n != 'preceding_traffic']
        for name in vehicles if topic.initial else ():
            key = (qualified(topic.name), nodes.get(name, name))
            initial[key] = initial.get(key, 0) + topic.initial // len(vehicles)
    return initial


def tf_frames(data: bytes) -> list[str]:
    """The child frames of a serialized ``tf2_msgs/msg/TFMessage``."""
    from rclpy.serialization import deserialize_message
    from tf2_msgs.msg import TFMessage

    return [t.child_frame_id for t in deserialize_message(data, TFMessage).transforms]


def stop_and_drain(graph: Graph, executor: Any, names: tuple[str, ...],
                   drain_s: float = DRAIN_S, node: Any = None,
                   taken: Callable[[], int] | None = None) -> None:
    """Deactivate the managed nodes through ``node`` if given (the planner hands over), stop
    the nodes (they write their loop statistics) while taking what they publish, then the
    last: until ``taken`` (the messages taken so far) has not changed for ``drain_s`` (a
    recording behind a backlog takes it all, up to :data:`DRAIN_MAX_S`); without it, for
    ``drain_s``.

    The stop runs in a thread so that the executor keeps spinning: the command topics keep
    only the last message (keep-last 1), so a node that ticks twice while being stopped
    (seen under a load average of 21: two ticks between the last take and the node's
    exit) would otherwise overwrite the first before it was recorded.
    """
    set_states(node, executor, MANAGED_NODES if node is not None else (), 'inactive', graph=graph)
    errors: list[BaseException] = []

    def stop() -> None:
        try:
            graph.stop(list(names))
        except BaseException as err:  # re-raised below, in the caller's thread
            errors.append(err)

    stopper = threading.Thread(target=stop, name='stop-nodes')
    stopper.start()
    while stopper.is_alive():
        stop_signals.spin_once(executor, 0.02)
    stopper.join()
    if errors:
        raise errors[0]
    now = time.monotonic()
    quiet_until, give_up = now + drain_s, now + DRAIN_MAX_S
    while now < min(quiet_until, give_up):
        before = taken() if taken is not None else 0
        stop_signals.spin_once(executor, 0.05)
        now = time.monotonic()
        if taken is not None and taken() != before:
            quiet_until = now + drain_s


def node_loops(graph: Graph, log_dir: Path, names: tuple[str, ...]) -> dict[str, Any]:
    """After a wall run: every node exited cleanly and wrote its loop statistics.

    Raises:
        GraphError: a node exited with an error or wrote no statistics.
    """
    for process in graph.processes:
        if process.popen.returncode not in (0, None):
            raise GraphError(process.exit_message(process.popen.returncode))
    loops = {}
    for name in names:
        path = log_dir / f'{name}.jitter.json'
        if not path.exists():
            raise GraphError(f'node {name} wrote no loop statistics ({path}); node logs in '
                             f'{log_dir}')
        loops[name] = json.loads(path.read_text())
    return loops
