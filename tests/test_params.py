"""The params file: shipped values, and every kind of bad value rejected with its name."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from trust_av_planner.system.config import DEFAULT_PARAMS_FILE, load_run_config
from trust_monitor.common.params import ParamsError

REPO = Path(__file__).resolve().parents[1]


def test_packaged_params_file_is_the_repository_one() -> None:
    assert DEFAULT_PARAMS_FILE.resolve() == (REPO / 'config' / 'trust_av.yaml').resolve()


def test_shipped_values_are_table_one(run_config) -> None:
    p = run_config.planner
    assert (p.horizon_steps, p.dt_s, p.accel_min_mps2, p.accel_max_mps2) == (3, 1.0, -3.0, 3.0)
    assert (p.gap_min_m, p.gap_max_m, p.standstill_gap_m, p.time_headway_s) == (5, 60, 5, 1.2)
    assert (p.trust_min, run_config.trust.epsilon_mps2) == (0.0, 6.0)
    assert run_config.trust.trust_growth_rate == 0.1
    assert run_config.trust.performance_threshold == 0.8


@pytest.mark.parametrize(('node', 'values', 'message'), [
    ('/**', {'horizon_steps': -3}, r'horizon_steps must be in \[1, 50\]'),
    ('planner', {'alpha': 1.5}, r'alpha must be in \[0, 1\]'),
    ('planner', {'gap_min_m': 70.0}, r'gap_min_m < gap_max_m'),
    ('planner', {'predictor': 'lstm'}, r"predictor must be one of .*'lstm'"),
    ('planner', {'alpha': 'high'}, r'parameter alpha: expected a number'),
    ('planner', {'alhpa': 0.5}, r'unknown parameter\(s\) alhpa'),
    ('/**', {'horizon_steps': 3.0}, r'parameter horizon_steps: expected an integer'),
    ('human_driver', {'weight_relative_speed': -1.0}, r'weight_relative_speed must be >= 0'),
    ('nonsense_node', {'x': 1}, r"unknown node section 'nonsense_node'"),
    ('trust_monitor', {'performance_threshold': 1.0}, r'performance_threshold must be in'),
])
def test_bad_values_are_named(node: str, values: dict[str, object], message: str) -> None:
    with pytest.raises(ParamsError, match=message):
        load_run_config(DEFAULT_PARAMS_FILE, {node: values})


def test_bad_yaml_files(tmp_path: Path) -> None:
    broken = tmp_path / 'broken.yaml'
    broken.write_text('planner: [\n')
    with pytest.raises(ParamsError, match='not valid YAML'):
        load_run_config(broken)
    flat = tmp_path / 'flat.yaml'
    flat.write_text(yaml.safe_dump({'planner': {'alpha': 0.5}}))
    with pytest.raises(ParamsError, match="'planner' must hold exactly one key, ros__parameters"):
        load_run_config(flat)
    with pytest.raises(ParamsError, match='cannot read params file'):
        load_run_config(tmp_path / 'missing.yaml')


def test_missing_parameter_is_named(tmp_path: Path) -> None:
    data = yaml.safe_load(DEFAULT_PARAMS_FILE.read_text())
    del data['/**/planner']['ros__parameters']['gap_max_m']
    path = tmp_path / 'p.yaml'
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ParamsError, match='parameter gap_max_m is missing'):
        load_run_config(path)
