"""A trust model with more state than T through the node graph: the planner mirrors the
monitor's model (lock-step), and the run equals the in-process one, trust constraint and all."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from support.graph import assert_records_equal, run_command

from preceding_traffic.sources import load_trace
from preceding_traffic.traces import truncate
from trust_av.graph.bag_records import records_from_bag
from trust_av.system.closed_loop import simulate
from trust_av.system.config import load_run_config

STEPS = 30
BETA_BINDING = ('/**:\n  ros__parameters:\n    trust_model: beta_bernoulli\n'
                '/**/planner:\n  ros__parameters:\n    trust_min: 0.6\n')
"""Beta(1, 1) starts at trust 0.5 < T_min: the bound binds in the first steps, and there it
depends on the Beta counts, not only on T."""


def test_beta_bernoulli_in_the_graph_equals_in_process(tmp_path: Path) -> None:
    params = tmp_path / 'beta.yaml'
    params.write_text(BETA_BINDING)
    bag = tmp_path / 'beta'
    command = [*run_command(bag, '--max-steps', str(STEPS)), '--params-file', str(params)]
    proc = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    config = load_run_config([params], {'planner': {'alpha': 0.5, 'predictor': 'ca'}})
    trace = truncate(load_trace('us06', config.planner.dt_s, config.trace), STEPS)
    reference = simulate(config, trace).records
    binding = [r.explicability_max for r in reference if r.explicability_max < 1.0]
    assert len(binding) >= 3, 'the trust constraint must bind for this test to mean anything'
    assert reference[0].trust == pytest.approx(2 / 3, rel=0.01)  # a Beta mean, not T units
    assert_records_equal(records_from_bag(bag), reference)


def test_wall_mode_refuses_a_model_with_more_state_than_t(tmp_path: Path) -> None:
    """The trust topic carries T: in wall mode the planner cannot mirror the monitor."""
    params = tmp_path / 'beta.yaml'
    params.write_text(BETA_BINDING)
    proc = subprocess.run([sys.executable, '-m', 'trust_av_planner.planner_node', '--ros-args',
                           '--params-file', str(params), '-p', 'clock_mode:=wall'],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert "trust model 'beta_bernoulli' has a state beyond" in proc.stderr
    assert proc.stderr.strip().count('\n') == 0, proc.stderr
