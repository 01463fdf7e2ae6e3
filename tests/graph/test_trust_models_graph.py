"""A trust model with more state than T in the node graph: in wall mode the planner cannot
mirror the monitor's model, and refuses it. (In lock-step it mirrors it: graph ==
in-process for ``beta_bernoulli`` with a binding trust constraint is the graph half of the
trust-model contract, tests/graph/test_trust_model_contract_graph.py; the in-process run's
Beta mean and binding constraint: tests/core/test_trust_models.py.)"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

BETA_BINDING = ('/**:\n  ros__parameters:\n    trust_model: beta_bernoulli\n'
                '/**/planner:\n  ros__parameters:\n    trust_min: 0.6\n')
"""Beta(1, 1) starts at trust 0.5 < T_min."""


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
