"""The lock-step chain derived from the topic table (trust_av_common.step_chain)."""

from __future__ import annotations

import dataclasses
import sys
from collections import Counter, deque

import pytest
from support.paths import REPO

from trust_av_common.step_chain import Port, StepChain, StepChainError, step_chain
from trust_av_common.topics import TOPICS, Topic

sys.path.insert(0, str(REPO / 'benchmarks'))
from step_gate import StepGate

DT_NS = 1_000_000_000


def ports(node: str, chain: StepChain | None = None) -> tuple[set[Port], set[Port]]:
    """(inputs, outputs) of a node as sets."""
    c = (chain or step_chain()).node(node)
    return set(c.inputs), set(c.outputs)


def test_chain_is_the_protocol_of_graph_interface() -> None:
    """Each node's waits and stamps as graph_interface's docstring states them."""
    chain = step_chain()
    assert chain.source == 'preceding_traffic'
    assert [n.name for n in chain.nodes][:2] == ['preceding_traffic', 'planner']
    assert set(chain.state_topics) == {'ego/odom', 'human/odom'}
    expected = {
        'preceding_traffic': (
            {Port('ego/odom', 1), Port('human/odom', 1), Port('trust_monitor/trust', 0),
             Port('ego/planner_status', 0), Port('human/driver_status', 0)},
            {Port('clock', 0), Port('preceding_vehicle/odom', 0),
             Port('preceding_vehicle/speed_preview', 0), Port('tf', 0)}),
        'planner': (
            {Port('preceding_vehicle/odom', 0), Port('preceding_vehicle/speed_preview', 0),
             Port('ego/odom', 0), Port('human/odom', 0), Port('trust_monitor/trust', -1)},
            {Port('ego/plan', 0), Port('ego/expected_plan', 0), Port('ego/accel_cmd', 0),
             Port('ego/planner_status', 0), Port('vehicle_markers', 0)}),
        'ego_plant': ({Port('ego/accel_cmd', 0)}, {Port('ego/odom', 1), Port('tf', 0)}),
        'human_driver': ({Port('ego/expected_plan', 0), Port('ego/odom', 0)},
                         {Port('human/plan', 0), Port('human/driver_status', 0),
                          Port('human/odom', 1), Port('tf', 0)}),
        'trust_monitor': ({Port('ego/plan', 0), Port('ego/expected_plan', 0)},
                          {Port('trust_monitor/trust', 0)}),
    }
    assert {n.name: ports(n.name) for n in chain.nodes} == expected
    assert chain.node('preceding_traffic').start == ('sim/start',)
    assert chain.node('ego_plant').initial == ('ego/odom',)
    assert chain.node('planner').needed(0) == 4 and chain.node('planner').needed(1) == 5


def simulate(chain: StepChain, steps: int) -> tuple[Counter[str], Counter[str]]:
    """Deliver messages through StepGates (FIFO, no timing) for ``steps`` steps.

    Returns (messages per topic, acts per node)."""
    subscribers = {t.name: [s for s in t.subscribers if s in {n.name for n in chain.nodes}]
                   for t in TOPICS}
    gates = {n.name: StepGate(n, 0, DT_NS) for n in chain.nodes}
    queue: deque[tuple[str, int]] = deque()
    sent: Counter[str] = Counter()
    acts: Counter[str] = Counter()

    def publish(node: str, step: int) -> None:
        acts[node] += 1
        for port in chain.node(node).outputs:
            queue.append((port.topic, (step + port.offset) * DT_NS))

    for node in chain.nodes:
        queue.extend((topic, 0) for topic in node.initial)
    publish(chain.source, 0)
    while queue:
        topic, stamp = queue.popleft()
        sent[topic] += 1
        for node in subscribers.get(topic, []):
            for step in gates[node].put(topic, stamp):
                if node != chain.source:
                    publish(node, step)
                elif step + 1 < steps:
                    publish(node, step + 1)
    return sent, acts


def test_chain_runs_every_step_without_deadlock() -> None:
    chain = step_chain()
    sent, acts = simulate(chain, 7)
    assert set(acts.values()) == {7} and len(acts) == 5
    for topic in TOPICS:
        if 'orchestrator' in topic.publishers:
            continue
        # every publisher once per step (tf: the three vehicles), the states also at start-up
        assert sent[topic.name] == topic.per_step * 7 + (topic.name in chain.state_topics), \
            topic.name


def test_gate_waits_for_previous_step_input_and_ignores_the_initial_state() -> None:
    chain = step_chain()
    planner = StepGate(chain.node('planner'), 5 * DT_NS, DT_NS)
    for topic in ('preceding_vehicle/odom', 'preceding_vehicle/speed_preview', 'ego/odom'):
        assert planner.put(topic, 5 * DT_NS) == []
    assert planner.put('human/odom', 5 * DT_NS) == [0]  # no trust needed at step 0
    for topic in ('preceding_vehicle/odom', 'preceding_vehicle/speed_preview', 'ego/odom',
                  'human/odom'):
        assert planner.put(topic, 6 * DT_NS) == []
    assert planner.put('trust_monitor/trust', 5 * DT_NS) == [1]  # step 0's trust
    source = StepGate(chain.node('preceding_traffic'), 0, DT_NS)
    assert source.put('ego/odom', 0) == []  # the initial odometry: before step 0
    assert source.put('human/odom', 0) == []
    for topic in ('ego/odom', 'human/odom'):
        assert source.put(topic, DT_NS) == []
    assert source.put('trust_monitor/trust', 0) == []
    assert source.put('human/driver_status', 0) == []   # its gap: a collision ends the run
    assert source.put('ego/planner_status', 0) == [0]


def replace(name: str, **changes: object) -> tuple[Topic, ...]:
    """TOPICS with one row changed."""
    return tuple(dataclasses.replace(t, **changes) if t.name == name else t for t in TOPICS)


def test_chain_follows_the_table() -> None:
    """Without the initial-state mark the ego odometry closes a cycle planner -> ego_plant ->
    planner, so the planner takes it from the previous step; a new subscriber gets it too."""
    chain = step_chain(replace('ego/odom', rate='once per step'))
    inputs, _ = ports('planner', chain)
    assert Port('ego/odom', -1) in inputs
    assert chain.node('ego_plant').initial == () and Port('ego/odom', 0) in ports(
        'ego_plant', chain)[1]
    subs = ('trust_monitor', 'recorder')
    chain = step_chain(replace('human/plan', subscribers=subs))
    assert Port('human/plan', 0) in ports('trust_monitor', chain)[0]
    assert [n.name for n in chain.nodes].index('human_driver') < [
        n.name for n in chain.nodes].index('trust_monitor')


def test_bad_tables_are_refused() -> None:
    with pytest.raises(StepChainError, match='one clock'):
        step_chain(t for t in TOPICS if t.name != 'clock')
    with pytest.raises(StepChainError, match=r'not reached.*ego_plant'):
        step_chain(replace('ego/accel_cmd', subscribers=('recorder',)))
    both_ways = (Topic('a', 'std_msgs/msg/Empty', ('human_driver',), ('trust_monitor',),
                       'STEP', 'once per step', '', ''),
                 Topic('b', 'std_msgs/msg/Empty', ('trust_monitor',), ('human_driver',),
                       'STEP', 'once per step', '', ''))
    with pytest.raises(StepChainError, match='no stamp offset breaks'):
        step_chain(TOPICS + both_ways)
    with pytest.raises(StepChainError, match='subscribes no orchestrator'):
        step_chain(t for t in TOPICS if t.name != 'sim/start')
