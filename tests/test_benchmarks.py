"""Smoke test: the benchmark scripts run on a tiny input and write their figures."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def test_core_benchmark_smoke(tmp_path: Path) -> None:
    out = tmp_path / 'core.json'
    proc = subprocess.run([sys.executable, str(REPO / 'benchmarks' / 'bench_core.py'),
                           '--steps', '20', '--repeats', '1', '--out', str(out)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    figures = json.loads(out.read_text())
    assert figures['steps'] == 20 and figures['cpu_count'] >= 1
    assert figures['nmpc_solve_ms']['p99'] > 0 and figures['closed_loop_steps_per_s']['median'] > 0
    assert 'NMPC solve time' in proc.stdout
