"""Smoke test: the benchmark suite runs on tiny inputs and writes its figures."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from support.paths import REPO

sys.path.insert(0, str(REPO / 'benchmarks'))
from soak_wall import NODES, RECORDER, recorded_topics
from soak_wall_checks import (
    STOP_EDGE,
    Recorded,
    Sequences,
    growth_checks,
    topic_checks,
)


def test_benchmark_suite_smoke(tmp_path: Path) -> None:
    out = tmp_path / 'results.json'
    proc = subprocess.run([sys.executable, str(REPO / 'benchmarks' / 'run_all.py'), '--quick',
                           '--out', str(out)], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    results = json.loads(out.read_text())
    core = results['parts']['core']['figures']
    assert core['steps'] == 30 and results['cpu_count'] >= 1
    assert core['nmpc_solve_ms']['p99'] > 0 and core['closed_loop_steps_per_s']['median'] > 0
    assert core['baseline']['steps_compared'] >= 25
    assert core['baseline']['max_plan_difference_mps2'] < 1e-4
    assert results['parts']['sweep']['cases'] == 5
    assert 'speed-up at p99' in out.with_suffix('.md').read_text()


@pytest.mark.parametrize('inputs', ['messages', 'raw'])
def test_floor_benchmark_smoke(tmp_path: Path, inputs: str) -> None:
    """bench_floor.py, 20 steps, its nodes taking rclpy messages (the specified floor) or
    bytes (``--raw-inputs``): every step's /clock is observed and the raw recorder holds
    one message per topic and step of the table (plus the initial states), each stamp once
    (no timing threshold)."""
    from mcap.reader import make_reader

    from trust_av_common.step_chain import step_chain
    from trust_av_common.topics import TOPICS

    out = tmp_path / 'floor.json'
    proc = subprocess.run([sys.executable, str(REPO / 'benchmarks' / 'bench_floor.py'),
                           '--steps', '20', '--keep', str(tmp_path), '--out', str(out),
                           *(['--raw-inputs'] if inputs == 'raw' else [])],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert json.loads(out.read_text())['raw_inputs'] == (inputs == 'raw')
    run = json.loads(out.read_text())['runs'][0]
    assert run['steps'] == run['clocks_seen'] == 20
    assert run['steady_ms_per_step'] > 0 and run['startup_s'] > 0 and run['shutdown_s'] > 0
    assert {'preceding_traffic', 'planner', 'recorder', 'orchestrator'} <= set(
        run['cpu_ms_per_step'])
    stamps: dict[str, list[int]] = {}
    with (tmp_path / 'floor_0' / 'floor.mcap').open('rb') as handle:
        for _, channel, message in make_reader(handle).iter_messages():
            stamps.setdefault(channel.topic, []).append(message.log_time)
    state = step_chain().state_topics
    recorded = [t for t in TOPICS if 'recorder' in t.subscribers]
    assert set(stamps) == {t.name for t in recorded}
    for topic in recorded:
        extra = 1 if topic.name in state else 0
        # every publisher once per step (tf: three), the states also at start-up
        assert sorted(stamps[topic.name]) == [k * 1_000_000_000 for k in range(20 + extra)
                                              for _ in range(topic.per_step)], topic.name


def test_soak_short_version(tmp_path: Path) -> None:
    """The soak, short: every node's RSS grows by < 20 MB from the baseline to the end
    (the full hour: `python benchmarks/soak.py`)."""
    out = tmp_path / 'soak.json'
    proc = subprocess.run([sys.executable, str(REPO / 'benchmarks' / 'soak.py'),
                           '--duration-s', '300', '--baseline-s', '60', '--out', str(out)],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    figures = json.loads(out.read_text())
    assert set(figures['growth_mb']) == {'preceding_traffic', 'planner', 'ego_plant',
                                         'human_driver', 'trust_monitor', 'recorder'}
    assert figures['steps'] >= 300
    assert all(mb < 20.0 for mb in figures['growth_mb'].values()), figures['growth_mb']


@pytest.mark.wall_clock
def test_shadow_benchmark_smoke(tmp_path: Path) -> None:
    """bench_shadow.py, 2 s of every node in wall mode: per-loop figures are written (no
    timing threshold; the 10 ms acceptance figure is reported, not asserted)."""
    out = tmp_path / 'shadow.json'
    proc = subprocess.run([sys.executable, str(REPO / 'benchmarks' / 'bench_shadow.py'),
                           '--duration-s', '2', '--whole-graph', '--out', str(out)],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    figures = json.loads(out.read_text())
    assert figures['whole_graph'] and figures['duration_s'] == 2.0
    assert set(figures['loops']) == {'preceding_traffic', 'planner', 'ego_plant',
                                     'human_driver', 'trust_monitor'}
    assert all(loop['ticks'] > 0 for loop in figures['loops'].values())
    assert figures['worst_p99_jitter_ms'] == max(loop['jitter_ms']['p99']
                                                 for loop in figures['loops'].values())


SECOND = 1_000_000_000
PERIOD = SECOND // 10


def _topic(first_seq: int, last_seq: int, start_ns: int, skip: tuple[int, ...] = (),
           first_ns: int | None = None, late: int = 0) -> tuple[Recorded, Sequences]:
    """A topic received as sequence numbers ``first_seq..last_seq`` (without ``skip``),
    one per period from ``first_ns``; message ``late`` (if any) arrives 2 s late."""
    recorded, sequences = Recorded(), Sequences()
    t = start_ns - 5 * PERIOD if first_ns is None else first_ns
    for seq in range(first_seq, last_seq + 1):
        t += PERIOD + (2 * SECOND if seq == late else 0)
        if seq in skip:
            continue
        recorded.add(t, start_ns)
        sequences.add(seq, t)
    return recorded, sequences


def test_soak_wall_topic_checks() -> None:
    """The soak's bag checks: the start and stop edges are the only messages allowed to be
    missing; a hole, a late start, a long stop edge and a long gap each fail."""
    start = 1000 * SECOND
    ok = _topic(4, 300, start)
    rows, problems = topic_checks({'/a': 300}, {'/a': ok[0]}, {'/a': ok[1]}, start_ns=start,
                                  max_gap_s=1.0)
    assert problems == [], problems
    assert {k: rows[0][k] for k in ('published', 'recorded', 'start_edge', 'holes',
                                    'stop_edge')} == {'published': 300, 'recorded': 297,
                                                      'start_edge': 3, 'holes': 0,
                                                      'stop_edge': 0}
    cases = {
        'hole': (300, _topic(1, 300, start, skip=(150,))),
        'start edge after /sim/start': (300, _topic(20, 300, start, first_ns=start + SECOND)),
        'stop edge': (300 + STOP_EDGE + 1, _topic(1, 300, start)),
        'gap': (300, _topic(1, 300, start, late=100)),
        'nothing after the start': (10, _topic(1, 3, start, first_ns=start - SECOND)),
    }
    expected = {'hole': 'missing between', 'start edge after /sim/start': 'after /sim/start',
                'stop edge': 'after the last recorded', 'gap': 'a gap of 2.1',
                'nothing after the start': 'nothing recorded after /sim/start'}
    for name, (sent, (recorded, sequences)) in cases.items():
        _, problems = topic_checks({'/a': sent}, {'/a': recorded}, {'/a': sequences},
                                   start_ns=start, max_gap_s=1.0)
        assert any(expected[name] in p for p in problems), (name, problems)


def test_soak_wall_several_publishers() -> None:
    """A topic with several publishers (``tf``): each publisher's sequence numbers are
    checked on their own; published counts are summed and each publisher may have its own
    start and stop edge; a hole in one publisher fails although the interleaved numbers of
    the others fill it."""
    start = 1000 * SECOND

    def two(skip_b: tuple[int, ...] = ()) -> tuple[Recorded, Sequences]:
        recorded, sequences = Recorded(), Sequences()
        t = start - 5 * PERIOD
        for seq in range(1, 301):
            t += PERIOD
            for source, first in (('a', 3), ('b', 1)):
                if seq >= first and not (source == 'b' and seq in skip_b):
                    recorded.add(t, start)
                    sequences.add(seq, t, source)
        return recorded, sequences

    recorded, sequences = two()
    # a: 2 before its first recorded (start edge); each one after its last (stop edges)
    rows, problems = topic_checks({'/tf': 602}, {'/tf': recorded}, {'/tf': sequences},
                                  start_ns=start, max_gap_s=1.0, publishers={'/tf': 2})
    assert problems == [], problems
    assert {k: rows[0][k] for k in ('recorded', 'start_edge', 'stop_edge', 'holes',
                                    'publishers_seen')} == {
        'recorded': 598, 'start_edge': 2, 'stop_edge': 2, 'holes': 0, 'publishers_seen': 2}
    _, problems = topic_checks({'/tf': 602 + 1}, {'/tf': recorded},
                               {'/tf': sequences}, start_ns=start, max_gap_s=1.0,
                               publishers={'/tf': 2})
    assert any('after the last recorded' in p for p in problems), problems
    recorded, sequences = two(skip_b=(150,))
    _, problems = topic_checks({'/tf': 600}, {'/tf': recorded}, {'/tf': sequences},
                               start_ns=start, max_gap_s=1.0, publishers={'/tf': 2})
    assert any('1 messages missing' in p for p in problems), problems
    _, problems = topic_checks({'/tf': 601}, {'/tf': recorded, '/x': recorded},
                               {'/tf': sequences}, start_ns=start, max_gap_s=1.0,
                               publishers={'/tf': 2})
    assert any(p.startswith('/x: ') and 'does not record' in p for p in problems), problems


def test_soak_wall_growth_checks() -> None:
    """Growth is measured from the baseline minute to the last sample: RSS above the limit,
    one more fd or one more thread each fail; growth before the baseline does not count."""
    def series(rss: list[float], fds: list[int], threads: list[int]) -> list[dict[str, float]]:
        return [{'t_min': float(k), 'rss_mb': r, 'fds': f, 'threads': t}
                for k, (r, f, t) in enumerate(zip(rss, fds, threads, strict=True))]

    flat = series([50, 90, 91, 95], [10, 20, 20, 20], [5, 9, 9, 9])
    growth, problems = growth_checks({'planner': flat}, 1.0, 20.0)
    assert problems == [] and growth['planner']['rss_mb'] == 5.0
    bad = {'rss': series([50, 50, 60, 71], [9, 9, 9, 9], [5, 5, 5, 5]),
           'fds': series([50, 50, 50, 50], [9, 9, 9, 10], [5, 5, 5, 5]),
           'threads': series([50, 50, 50, 50], [9, 9, 9, 9], [5, 5, 6, 6])}
    _, problems = growth_checks(bad, 1.0, 20.0)
    assert [p.split(':')[0] for p in problems] == ['rss', 'fds', 'threads'], problems
    _, problems = growth_checks({'x': flat}, 3.0, 20.0)
    assert problems and 'no sample after the baseline' in problems[0]


@pytest.mark.wall_clock
def test_soak_wall_short(tmp_path: Path) -> None:
    """benchmarks/soak_wall.py for 45 s of wall time (baseline at 15 s): every node and
    the recorder sampled every 15 s, every published message in the bag but the
    documented start and stop edges, no hole, no gap over 1 s, no fd or thread growth (the
    30-minute run: `python benchmarks/soak_wall.py`; no timing threshold)."""
    out = tmp_path / 'soak_wall.json'
    proc = subprocess.run([sys.executable, str(REPO / 'benchmarks' / 'soak_wall.py'),
                           '--duration-min', '0.75', '--baseline-min', '0.25', '--sample-s', '15',
                           '--out', str(out)],
                          capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    from trust_av_common.topics import TOPICS, qualified

    figures = json.loads(out.read_text())
    assert figures['problems'] == []
    assert set(figures['growth']) == {*NODES, RECORDER}
    assert all(len(s) >= 4 for s in figures['series'].values())   # 0, 15, 30 s, the end
    assert all(g['fds'] <= 0 and g['threads'] <= 0 and g['rss_mb'] <= 20.0
               for g in figures['growth'].values())
    table = {qualified(t.name): t for t in recorded_topics()}
    assert {row['topic'] for row in figures['topics']} == set(table)
    assert len(table) == len(TOPICS) - 2  # all but the lock-step clock and /sim/start
    for row in figures['topics']:
        publishers = table[row['topic']].publishers
        assert row['publishers_seen'] == len(publishers), row
        assert row['holes'] == 0 and 0 <= row['stop_edge'] <= STOP_EDGE * len(publishers), row
        assert row['published'] - row['recorded'] == row['start_edge'] + row['stop_edge'], row
        assert row['recorded'] >= 0.5 * 45 * figures['rate_hz'], row
        assert row['max_gap_s'] <= 1.0, row
    assert all(figures['loops'][node]['ticks'] > 0 for node in NODES)


def test_component_checks_benchmark_smoke(tmp_path: Path) -> None:
    """bench_component_checks.py on 5 steps writes the per-step cost of the output checks
    beside the cost of a step (no timing threshold)."""
    from bench_component_checks import main

    out = tmp_path / 'checks.json'
    assert main(['--steps', '5', '--repeats', '2', '--out', str(out)]) == 0
    figures = json.loads(out.read_text())
    assert figures['steps'] == 5 and figures['step_ms_median'] > 0
    assert figures['component_calls_checked_us_per_step'] > 0
    assert 'checks_percent_of_step' in figures


def test_bag_writer_memory_benchmark_smoke(tmp_path: Path) -> None:
    """bench_bag_writer.py --memory on 600 steps split every 100: both recordings run in their
    own process and their slopes are written (no threshold: the figure is the benchmark's)."""
    out = tmp_path / 'memory.json'
    proc = subprocess.run([sys.executable, str(REPO / 'benchmarks' / 'bench_bag_writer.py'),
                           '--memory', '--steps', '600', '--topics', '2',
                           '--max-chunks-per-file', '100', '--out', str(out)],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    figures = json.loads(out.read_text())
    assert (figures['split']['files'], figures['one file']['files']) == (7, 1)
    assert all(len(figures[label]['samples']) == 2 and 'slope_kb_per_step' in figures[label]
               for label in ('split', 'one file'))
    assert 'kB/step' in proc.stdout
