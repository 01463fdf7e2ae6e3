"""This process's own rclpy node beside a run's node processes (:class:`Session`): it waits
until the graph is connected and the recorder is ready, follows the recorder's progress,
and watches the domain for publishers that are not the run's.

A leased domain must be private (:func:`foreign_participants`, the domain's RTPS ports in
the kernel's socket table, is the check before a domain is used); a domain given by the
user may be shared with graphs in other namespaces (:func:`clashing_participants` refuses
only what would clash with this graph's namespace).
During the run, a publisher on any of the graph's topics (resolved in its namespace) from a
node that is not one of the run's, or a second node under one of the run's names, stops the
run with one line naming the topic and the intruder; the topics of graphs in other
namespaces are not watched.
"""

from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Iterator
from typing import Any

from trust_av.graph import stop_signals
from trust_av.graph.domains import domain_ports_in_use
from trust_av.graph.processes import RECORDER, Graph, GraphError, use_run_discovery
from trust_av_common.topics import TOPICS, expected_endpoints, qualified

__all__ = ['PROBE_S', 'RECORDER_STATUS', 'clashing_participants', 'foreign_participants',
           'graph_session']

RECORDER_STATUS = 'recorder/status'
"""The recorder's latched status (``state`` ready/recording/finished/disk_full, ``steps``)."""
PROBE_S = 3.5
"""How long a ROS node observes a domain before a graph joins it, where the socket table
cannot answer (a domain shared with graphs in other namespaces: which nodes, in which
namespace, is for ROS discovery to say). A new participant lists one already on the domain
either at once (about 0.1 s) or only after that one's next periodic announcement (Fast DDS
``leaseDuration_announcementperiod``: 3 s by default): ten fresh participants on an idle
machine listed a node that had been up for a second after 0.10 s three times and after
2.10-2.69 s seven times. 3 s plus a margin covers one period; what this misses, the watch
during the run catches and names."""
WATCH_PERIOD_S = 1.0
"""How often the graph's topics are checked for foreign publishers during a run."""
DEATH_ATTRIBUTION_S = 4.0
"""When a node dies, how long the graph's topics are watched for an intruder (the likely
cause) before the node's death is reported. A node can hear an intruder's message seconds
before this process has discovered it: a participant that misses a new participant's
initial announcements (Fast DDS: 5 at 0.1 s) learns of it only from its next periodic one
(Fast DDS ``leaseDuration_announcementperiod``, 3 s by default). Measured on a CPU-bound
2-core machine: an orchestrator that had not listed an intruder 3.4 s after its publisher
was up, while a participant started 1 s before the intruder listed it after 0.06 s."""
UNNAMED_GRACE_S = 5.0
"""A publisher is listed before the name of its node arrives (rmw shows
``_NODE_NAME_UNKNOWN_``); one that stays unnamed this long (a plain DDS participant) counts
as foreign."""
UNKNOWN_NAME = '_NODE_NAME_UNKNOWN_'


def foreign_participants(domain: int, wait_s: float | None = None) -> str:
    """Participants already on ``domain`` on this machine, as one line; '' if none.

    A DDS participant binds UDP ports of its domain's block as it is created, so the
    kernel's socket table tells at once and exactly whether anyone is there (any RTPS
    vendor, any ROS or no ROS), with no discovery to wait for: a ROS probe can need a
    whole announcement period, 3 s (:data:`PROBE_S`). Only without the socket tables is
    the domain observed with a ROS node for ``wait_s`` (default :data:`PROBE_S`).
    """
    ports = domain_ports_in_use(domain)
    if ports is None:
        return _probe(domain, None, wait_s)
    if not ports:
        return ''
    shown = ', '.join(str(p) for p in ports[:4]) + (', ...' if len(ports) > 4 else '')
    return f'DDS participants on this machine (UDP ports {shown} in use)'


def clashing_participants(domain: int, namespace: str, wait_s: float | None = None) -> str:
    """On a shared ``domain``: what would clash with a graph in ``namespace``, as one line
    ('' if nothing): a node in that very namespace (another graph there: same node names,
    same topics) or a publisher on one of the graph's topics in it. Nodes in other
    namespaces (another graph under ``/car2``) and subscribers (a viewer) are left alone."""
    return _probe(domain, namespace, wait_s)


def _probe(domain: int, namespace: str | None, wait_s: float | None) -> str:
    """Observe ``domain`` for ``wait_s`` (default :data:`PROBE_S`): every other node
    (``namespace`` None) or only what clashes with a graph in ``namespace``."""
    import rclpy
    from rclpy.context import Context
    from rclpy.signals import SignalHandlerOptions
    from rclpy.utilities import try_shutdown

    use_run_discovery(os.environ)
    context = Context()
    rclpy.init(context=context, domain_id=domain, signal_handler_options=SignalHandlerOptions.NO)
    try:
        node = rclpy.create_node('trust_av_domain_probe', namespace=namespace or '/',
                                 context=context)
        try:
            time.sleep(PROBE_S if wait_s is None else wait_s)
            names = sorted(f'{ns.rstrip("/")}/{name}'
                           for name, ns in node.get_node_names_and_namespaces()
                           if name != node.get_name() and
                           (namespace is None or ns == node.get_namespace()))
            publishers = [] if namespace is None else sorted(
                {qualified(row.name, namespace) for row in TOPICS
                 if node.count_publishers(qualified(row.name, namespace))})
        finally:
            node.destroy_node()
    finally:
        try_shutdown(context=context)
    found = [f'nodes {", ".join(names[:4])}'] if names else []
    if publishers:
        found.append(f'publishers on {", ".join(publishers[:4])}')
    return '; '.join(found)


class Session:
    """The orchestrator's (or the shadow player's) node on a run's domain.

    Args:
        graph: the run's node processes.
        node: this process's rclpy node (in the graph's namespace).
        executor: the executor spinning ``node``.
    """

    def __init__(self, graph: Graph, node: Any, executor: Any) -> None:
        from diagnostic_msgs.msg import DiagnosticArray

        from trust_av_common.ros.qos import QOS

        self.graph = graph
        self.node = node
        self.executor = executor
        self.recorder_state = ''
        self.recorder_steps = 0
        self.recorder_messages = 0
        self._ours = {(graph.namespace.rstrip('/') or '/', spec.name) for spec in graph.specs}
        self._ours.add((node.get_namespace(), node.get_name()))
        self._next_watch = 0.0
        self._unnamed: dict[tuple[str, bytes], float] = {}
        # The DDS participant (first 12 bytes of an endpoint's gid) of each of our nodes
        # that publishes on the table, learnt from its named endpoints: once every one is
        # known, an endpoint whose node name has not arrived yet is told apart at once.
        ns = graph.namespace.rstrip('/') or '/'
        self._publishing = {(ns, spec.name) for spec in graph.specs
                            if any(spec.name in row.publishers for row in TOPICS)}
        self._participants: dict[tuple[str, str], bytes] = {}
        self._foreign_pending = False   # a foreign endpoint seen, its node name not yet
        if any(spec.name == RECORDER for spec in graph.specs):
            node.create_subscription(DiagnosticArray, RECORDER_STATUS, self._on_status,
                                     QOS['LATCHED'])

    def _on_status(self, msg: Any) -> None:
        values = {kv.key: kv.value for kv in msg.status[0].values}
        self.recorder_state = values.get('state', '')
        self.recorder_steps = int(values.get('steps', '0'))
        self.recorder_messages = int(values.get('messages', '0'))

    def spin(self, timeout_s: float) -> None:
        """Process this node's callbacks for at most ``timeout_s`` (a stop signal is raised
        after it)."""
        stop_signals.spin_once(self.executor, timeout_s)

    def topic(self, name: str) -> str:
        """A table topic as resolved in the graph's namespace."""
        return qualified(name, self.graph.namespace)

    def foreign_publishers(self) -> str:
        """A publisher on any of the graph's topics from a node that is not the run's, as
        one line ('' if none)."""
        now = time.monotonic()
        self._foreign_pending = False
        endpoints = {self.topic(row.name): self.node.get_publishers_info_by_topic(
            self.topic(row.name)) for row in TOPICS}
        for infos in endpoints.values():
            for info in infos:
                key = (info.node_namespace.rstrip('/') or '/', info.node_name)
                if key in self._publishing:
                    self._participants[key] = bytes(info.endpoint_gid)[:12]
        all_known = self._publishing <= self._participants.keys()
        ours = set(self._participants.values())
        for name, infos in endpoints.items():
            seen: set[tuple[str, str]] = set()
            for info in infos:
                if info.node_name == UNKNOWN_NAME:
                    participant = bytes(info.endpoint_gid)[:12]
                    if participant in ours:
                        continue
                    first = self._unnamed.setdefault((name, bytes(info.endpoint_gid)), now)
                    if now - first < UNNAMED_GRACE_S:
                        # foreign for sure once every node of the run is known: wait for
                        # its name (check() spins for it) rather than report it unnamed
                        self._foreign_pending = self._foreign_pending or all_known
                        continue
                    return (f'a foreign publisher on {name}: a participant without a ROS '
                            f'node name (domain {self.graph.domain} is not private)')
                key = (info.node_namespace.rstrip('/') or '/', info.node_name)
                if key not in self._ours:
                    return (f'a foreign publisher on {name}: node '
                            f'{info.node_namespace.rstrip("/")}/{info.node_name} (domain '
                            f'{self.graph.domain} is not private)')
                if key in seen:      # each of our nodes publishes a topic once
                    return (f'a foreign publisher on {name}: a second node named '
                            f'{info.node_namespace.rstrip("/")}/{info.node_name} (another '
                            f'graph in namespace {self.graph.namespace} on domain '
                            f'{self.graph.domain}?)')
                seen.add(key)
        return ''

    def check(self, allowed_done: set[str]) -> None:
        """Raise :class:`GraphError` for a dead node or a foreign publisher (the intruder
        is named first: it is the likely cause of a node's death)."""
        now = time.monotonic()
        dead = any(p.popen.poll() not in (None, 0) or
                   (p.popen.poll() == 0 and p.spec.name not in allowed_done)
                   for p in self.graph.processes)
        if dead or now >= self._next_watch:
            self._next_watch = now + WATCH_PERIOD_S
            intruder = self.foreign_publishers()
            # A node killed by an intruder's message heard it before this process may have
            # discovered the intruder: give discovery a moment before blaming the node.
            until = now + (DEATH_ATTRIBUTION_S if dead else 0.0)
            while not intruder and (time.monotonic() < until or self._foreign_pending):
                self.spin(0.05)
                intruder = self.foreign_publishers()
            if intruder:
                raise GraphError(f'stopped: {intruder}')
        self.graph.check_alive(allowed_done)

    def wait_connected(self, timeout_s: float) -> None:
        """Wait until every topic has its publishers and subscribers and the recorder (if
        any) has matched every publisher (``recorder/status`` says ready).

        Raises:
            GraphError: not connected in time (naming what is missing), or a node died.
        """
        expected = expected_endpoints({spec.name for spec in self.graph.specs})
        has_recorder = any(spec.name == RECORDER for spec in self.graph.specs)
        deadline = time.monotonic() + timeout_s
        missing: list[str] = []
        while time.monotonic() < deadline:
            self.spin(0.05)
            self.check(set())
            missing = []
            for row in TOPICS:
                pubs, subs = expected[row.name]
                name = self.topic(row.name)
                have_pubs = self.node.count_publishers(name)
                have_subs = self.node.count_subscribers(name)
                if have_pubs < pubs or have_subs < subs:
                    missing.append(f'{name} ({have_pubs}/{pubs} publishers, '
                                   f'{have_subs}/{subs} subscribers)')
            if has_recorder and self.recorder_state != 'ready':
                missing.append('the recorder has not matched every publisher')
            if not missing:
                return
        raise GraphError(f'graph not connected after {timeout_s:g} s: ' + '; '.join(missing))


@contextlib.contextmanager
def graph_session(graph: Graph, name: str) -> Iterator[Session]:
    """This process's rclpy node ``name`` on the graph's domain and namespace (a
    single-threaded executor: it only follows the recorder's status, at most twice a second),
    then the graph's node processes; on exit, also on errors, destroy the
    node, shut its context down and stop every process (:meth:`Graph.stop`).

    No rclpy signal handler is installed: SIGINT (and SIGTERM, which ``trust-av`` turns into
    the same exception) must reach the caller so that the nodes are stopped and the
    recording is finished.
    """
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions
    from rclpy.utilities import try_shutdown

    use_run_discovery(os.environ)
    context = Context()
    try:
        rclpy.init(context=context, domain_id=graph.domain,
                   signal_handler_options=SignalHandlerOptions.NO)
        node = rclpy.create_node(name, namespace=graph.namespace, context=context)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        try:
            graph.start()
            yield Session(graph, node, executor)
        finally:
            executor.remove_node(node)
            executor.shutdown()
            node.destroy_node()
    finally:
        try_shutdown(context=context)
        graph.stop()
