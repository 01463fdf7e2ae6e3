"""Smoke test: the benchmark suite runs on tiny inputs and writes its figures."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


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


def test_floor_benchmark_smoke(tmp_path: Path) -> None:
    """bench_floor.py, 20 steps: every step's /clock is observed and the raw recorder holds
    one message per topic and step of the table (plus the initial states), each stamp once
    (no timing threshold)."""
    from mcap.reader import make_reader

    from trust_monitor.common.step_chain import step_chain
    from trust_monitor.common.topics import TOPICS

    out = tmp_path / 'floor.json'
    proc = subprocess.run([sys.executable, str(REPO / 'benchmarks' / 'bench_floor.py'),
                           '--steps', '20', '--keep', str(tmp_path), '--out', str(out)],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
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
