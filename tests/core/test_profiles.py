"""The `as_reported` profile is a params-file layer that changes only what the evidence says
the paper's implementation did differently: epsilon and the explicability cost scale."""

from __future__ import annotations

from pathlib import Path

from support.paths import REPO

from trust_av.system.config import DEFAULT_PARAMS_FILE, load_run_config
from trust_av_common.param_layers import read_layer

AS_REPORTED = REPO / 'config' / 'paper_as_reported.yaml'


def test_as_reported_changes_only_epsilon_and_the_explicability_scale() -> None:
    layer = read_layer(AS_REPORTED)
    values = {(section, key): value for section, params in layer.items()
              for key, value in params.items()}
    assert {key: value for (_, key), value in values.items()} == {
        'epsilon_mps2': 3.0, 'explicability_scale': 0.02}
    default = load_run_config()
    reported = load_run_config(AS_REPORTED, {})
    assert (default.trust.epsilon_mps2, default.planner.explicability_scale) == (6.0, 0.005)
    assert (reported.trust.epsilon_mps2, reported.planner.explicability_scale) == (3.0, 0.02)
    assert reported.params_files == (DEFAULT_PARAMS_FILE, AS_REPORTED)
    same = [field for field in ('alpha', 'time_headway_s', 'tracking_cost_scale_m2')
            if getattr(reported.planner, field) == getattr(default.planner, field)]
    assert len(same) == 3 and reported.driver == default.driver


FITTED = AS_REPORTED.with_name('paper_fitted_threshold.yaml')


def test_paper_fitted_is_as_reported_with_the_fitted_threshold_only() -> None:
    """The fitted profile = as_reported + P_thre 0.97 (nothing else), labelled as fitted."""
    def values(path: Path) -> dict[tuple[str, str], object]:
        return {(section, key): value for section, params in read_layer(path).items()
                for key, value in params.items()}
    fitted, reported = values(FITTED), values(AS_REPORTED)
    assert {k: v for k, v in fitted.items() if k[1] != 'performance_threshold'} == reported
    assert fitted[('/**', 'performance_threshold')] == 0.97
    assert 'FITTED' in FITTED.read_text() and 'hypothesis' in FITTED.read_text()
    config = load_run_config(FITTED, {})
    assert (config.trust.performance_threshold, config.trust.epsilon_mps2) == (0.97, 3.0)
    assert config.trust.trust_model == 'paper'


def test_the_shipped_driver_is_the_selected_fit_and_the_cautious_profile_changes_only_it() -> None:
    """config/trust_av.yaml's driver = `pooled` of models/driver_fit_caution.yaml (the model
    picked on the validation split); config/human_cautious.yaml = `pooled` of
    models/driver_fit.yaml with the worst-case bound, and every other parameter is the shipped
    one."""
    import dataclasses

    import yaml

    from human_driver_sim.population import CAUTIOUS_FIT_FILE, DRIVER_FIT_FILE, WEIGHT_NAMES
    from trust_av.system.config import HUMAN_CAUTIOUS_PARAMS_FILE

    names = (*WEIGHT_NAMES, 'time_headway_s', 'desired_standstill_gap_m')
    default = load_run_config()
    pooled = yaml.safe_load(DRIVER_FIT_FILE.read_text())['pooled']
    for name in (*names, 'cautious', 'av_extra_decel_mps2'):
        assert getattr(default.driver, name) == pooled[name], name
    assert not default.driver.cautious

    layer = read_layer(HUMAN_CAUTIOUS_PARAMS_FILE)
    assert list(layer) == ['/**/human_driver']
    cautious = load_run_config(HUMAN_CAUTIOUS_PARAMS_FILE, {})
    before = yaml.safe_load(CAUTIOUS_FIT_FILE.read_text())['pooled']
    for name in names:
        assert getattr(cautious.driver, name) == before[name], name
    assert cautious.driver.cautious
    assert dataclasses.replace(cautious.driver, cautious=False,
                               **{n: getattr(default.driver, n) for n in names}) == default.driver
    assert (cautious.planner, cautious.trust) == (default.planner, default.trust)
