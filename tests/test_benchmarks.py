"""Smoke test: the benchmark suite runs on tiny inputs and writes its figures."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

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
