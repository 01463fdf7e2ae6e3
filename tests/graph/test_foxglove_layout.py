"""The shipped Foxglove layout (config/foxglove_layout.json) against a real recording: every
topic, message path and frame it names exists in a bag the graph recorded, every plot line
reads one number from every message of its topic, and the lines are labelled in words.

The bag is recorded by the graph (the suite's shared US06 run, which other modules read
too) rather than built from the topic table: a layout path is only worth something if the
nodes really publish that field with that type.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from rosbags.highlevel import AnyReader
from support.graph import STEPS

from trust_av.graph.bag_records import TYPESTORE
from trust_av.study.layout_plots import (
    LAYOUT_FILE,
    LayoutError,
    load_layout,
    parse_path,
    read_series,
    render_plots,
)
from trust_av_common.topics import VEHICLE_FRAMES


@pytest.fixture
def bag(us06_graph_run: tuple[Path, str]) -> Path:
    """The suite's shared US06 graph run (tests/conftest.py), STEPS steps."""
    return us06_graph_run[0]


def recorded(bag: Path) -> tuple[dict[str, int], set[str]]:
    """Topic -> message count, and every child frame on tf."""
    frames = set()
    with AnyReader([bag], default_typestore=TYPESTORE) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
        tf = [c for c in reader.connections if c.topic == '/tf']
        for connection, _t, raw in reader.messages(connections=tf):
            msg = reader.deserialize(raw, connection.msgtype)
            frames |= {t.child_frame_id for t in msg.transforms}
    return counts, frames


def test_every_layout_path_reads_a_number_from_every_message(bag: Path) -> None:
    layout = load_layout()
    counts, _ = recorded(bag)
    paths = [s.path for p in layout.plots for s in p.series]
    assert layout.topics <= set(counts), layout.topics - set(counts)
    series = read_series(bag, paths)
    for path in paths:
        times, values = series[path.text]
        assert len(values) == counts[path.topic] >= STEPS, path.text
        assert times == sorted(times)


def test_the_3d_panel_shows_the_platoon(bag: Path) -> None:
    layout = load_layout()
    counts, frames = recorded(bag)
    assert layout.scene_topics == ('/vehicle_markers',)
    assert counts['/vehicle_markers'] == STEPS
    assert frames == set(VEHICLE_FRAMES.values())
    assert set(layout.follow_frames) <= frames
    scene = json.loads(LAYOUT_FILE.read_text())['configById']['3D!platoon']
    named = {key.split(':', 1)[1] for key in scene['transforms']}
    assert named <= frames | {'odom'}


def test_markers_placed_by_tf_show_the_recorded_gaps(bag: Path) -> None:
    """At every step, the boxes placed through tf stand as far apart as the planner and the
    driver say the gaps are: the 3D panel shows the platoon as it was."""
    by_stamp: dict[int, dict[str, object]] = {}
    with AnyReader([bag], default_typestore=TYPESTORE) as reader:
        for connection, log_time, raw in reader.messages():
            msg = reader.deserialize(raw, connection.msgtype)
            entry = by_stamp.setdefault(log_time, {})
            if connection.topic == '/tf':
                for transform in msg.transforms:
                    assert transform.header.frame_id == 'odom'
                    entry[transform.child_frame_id] = transform.transform.translation.x
            elif connection.topic in ('/vehicle_markers', '/ego/planner_status',
                                      '/human/driver_status'):
                entry[connection.topic] = msg
    checked = 0
    for entry in by_stamp.values():
        if '/vehicle_markers' not in entry:
            continue
        boxes = {m.header.frame_id: m for m in entry['/vehicle_markers'].markers  # type: ignore[attr-defined]
                 if m.type == m.CUBE}
        # box extent in odom: tf position + the box's centre -/+ half its length
        rear = {f: entry[f] + b.pose.position.x - b.scale.x / 2  # type: ignore[operator]
                for f, b in boxes.items()}
        front = {f: entry[f] + b.pose.position.x + b.scale.x / 2  # type: ignore[operator]
                 for f, b in boxes.items()}
        for frame, x in front.items():      # the front bumper is the odometry position
            assert x == pytest.approx(entry[frame], abs=1e-9)  # type: ignore[arg-type]
        for lead, follower, status in (('preceding_vehicle', 'ego', '/ego/planner_status'),
                                       ('ego', 'human', '/human/driver_status')):
            gap = next(float(kv.value) for kv in entry[status].status[0].values  # type: ignore[attr-defined]
                       if kv.key == 'gap_m')
            assert rear[lead] - front[follower] == pytest.approx(gap, abs=1e-9)
        checked += 1
    assert checked == STEPS


def test_layout_covers_the_quantities_in_words() -> None:
    layout = load_layout()
    lines = {s.path.text: s.label for p in layout.plots for s in p.series}
    for topic in ('/preceding_vehicle/odom', '/ego/odom', '/human/odom'):
        assert 'speed' in lines[f'{topic}.twist.twist.linear.x']
    gaps = [text for text in lines if 'gap_m' in text]
    assert {parse_path(text).topic for text in gaps} == {'/ego/planner_status',
                                                          '/human/driver_status'}
    assert 'plan' in lines['/ego/plan.points[0].accelerations[0]']
    assert 'expected' in lines['/ego/expected_plan.points[0].accelerations[0]']
    # the trust topic's x, y, z in words, where a Foxglove user reads them
    assert lines['/trust_monitor/trust.vector.x'].startswith('E: explicability')
    assert lines['/trust_monitor/trust.vector.y'].startswith('P: performance')
    assert lines['/trust_monitor/trust.vector.z'].startswith('trust')
    titles = ' '.join(p.title for p in layout.plots
                      if p.series[0].path.topic == '/trust_monitor/trust')
    assert all(words in titles for words in ('vector.x = E', 'vector.y = P',
                                             'vector.z = trust'))


def test_every_panel_is_placed_once() -> None:
    data = json.loads(LAYOUT_FILE.read_text())

    def leaves(node: object) -> list[str]:
        if isinstance(node, str):
            return [node]
        assert isinstance(node, dict) and node['direction'] in ('row', 'column')
        return leaves(node['first']) + leaves(node['second'])

    placed = leaves(data['layout'])
    assert sorted(placed) == sorted(data['configById'])


def test_a_wrong_path_is_named(bag: Path) -> None:
    for text, problem in (('/ego/odom.twist.twist.linear.q', "no field 'q'"),
                          ('/ego/plan.points[7].accelerations[0]', 'index 7'),
                          ('/ego/planner_status.status[0].values[:]{key=="no_such"}.value',
                           '0 values'),
                          ('/ego/planner_status.status[0].values[:]{key=="status"}.value',
                           'is not a number'),
                          ('/no/such/topic.x', 'no topic /no/such/topic')):
        with pytest.raises(LayoutError, match=problem):
            read_series(bag, [parse_path(text)])
    for bad in ('ego/odom.x', '/ego/odom..x', '/ego/odom.x[', '/ego/odom.x{key=1'):
        with pytest.raises(LayoutError):
            parse_path(bad)


def test_plot_panels_render_to_png(bag: Path, tmp_path: Path) -> None:
    png = tmp_path / 'panels.png'
    render_plots(bag, png)
    assert png.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n' and png.stat().st_size > 20_000
