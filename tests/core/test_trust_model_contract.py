"""The contract every registered trust model must meet (shipped or a plug-in's).

Parametrised from the registry (``trust_av.trust_models``), so a package that registers a
model is held to the same rules, the shipped contract
(:func:`trust_av.contract.check_component`): time consistency, determinism, a
monotone update (what the numeric NMPC bound assumes), a numeric bound that keeps
T >= T_min on the propagated update, the closed form equal to the numeric one, a one-line
refusal of a bad parameter value; its graph == in-process rule is
tests/graph/test_trust_model_contract_graph.py. Here also: the commands' refusals and
``trust-monitor-estimate``.
"""

from __future__ import annotations

import dataclasses
import math
import subprocess
import sys
from typing import Any

import pytest

from trust_av.contract import check_component
from trust_av_common import registry
from trust_av_common.params import ParamsError, build_config
from trust_monitor.model_interface import (
    TRUST_MODELS,
    TrustModel,
    make_trust_model,
    trust_model_component,
)
from trust_monitor.paper_trust import TrustConfig

NAMES = registry.names(TRUST_MODELS)
BASE = TrustConfig(epsilon_mps2=6.0, trust_growth_rate=0.1, performance_threshold=0.8,
                   trust_initial=0.0)


def model(name: str, **trust: Any) -> TrustModel:
    return make_trust_model(dataclasses.replace(BASE, trust_model=name, **trust))


def test_the_shipped_models_are_registered() -> None:
    assert {'paper', 'asymmetric', 'beta_bernoulli', 'optimo'} <= set(NAMES)


@pytest.mark.parametrize('name', NAMES)
def test_contract(name: str) -> None:
    """The shipped contract: time consistency (ten steps of 0.1 s equal one of 1 s),
    determinism, a step that leaves its input as it was, trust that does not rise with E
    (what the numeric bound assumes), a numeric bound that keeps T >= T_min and is the
    largest, the closed form equal to it, parameters named after the model and refused in
    one line when bad."""
    report = check_component(TRUST_MODELS, name)
    assert {'outputs', 'deterministic', 'time consistency', 'pure step', 'monotone',
            'bound'} <= set(report.passed), report
    if model(name).closed_form_bound is not None:
        assert 'closed form' in report.passed, report


@pytest.mark.parametrize('name', NAMES)
def test_is_a_trust_model(name: str) -> None:
    m = model(name)
    assert isinstance(m, TrustModel)
    assert m.name == name
    assert math.isfinite(m.trust(m.initial_state()))


def fields_of(name: str) -> list[dataclasses.Field[Any]]:
    config_type = trust_model_component(name).config_type
    return list(dataclasses.fields(config_type)) if config_type is not None else []


def bad_value(field: dataclasses.Field[Any]) -> Any:
    """A value outside the field's declared range (None when it has no bound)."""
    spec = field.metadata['trust_av_param']
    if spec.low is not None:
        return spec.low - 1.0
    if spec.high is not None:
        return spec.high + 1.0
    return None


@pytest.mark.parametrize('name', NAMES)
def test_refuses_a_bad_parameter_with_one_line(name: str) -> None:
    config_type = trust_model_component(name).config_type
    checked = 0
    for field in fields_of(name):
        value = bad_value(field)
        if value is None:
            continue
        with pytest.raises(ParamsError) as err:
            build_config(config_type, {field.name: value})  # type: ignore[arg-type]
        assert field.name in str(err.value) and '\n' not in str(err.value)
        checked += 1
        with pytest.raises(ParamsError, match=field.name):
            make_trust_model(dataclasses.replace(BASE, trust_model=name),
                             {field.name: 'text'})
    # A model without parameters of its own uses the shared ones: those are refused too.
    with pytest.raises(ParamsError, match='trust_growth_rate'):
        dataclasses.replace(BASE, trust_model=name, trust_growth_rate=-1.0)
    assert checked or not fields_of(name) or all(bad_value(f) is None for f in fields_of(name))


def test_unknown_model_is_refused_in_one_line() -> None:
    with pytest.raises(registry.RegistryError, match=r"unknown trust model 'nope' \(registered"):
        make_trust_model(dataclasses.replace(BASE, trust_model='nope'))


def test_bad_model_on_the_command_line_exits_2(tmp_path: Any) -> None:
    """trust-monitor-estimate refuses an unknown trust_model: one line, exit 2."""
    params = tmp_path / 'p.yaml'
    params.write_text('/**:\n  ros__parameters:\n    trust_model: nope\n')
    plans = tmp_path / 'plans.csv'
    plans.write_text('t,plan_0,expected_0\n0,0.1,0.2\n1,0.0,0.0\n')
    out = tmp_path / 'out.csv'
    for extra in (['--params-file', str(params)], ['--trust-model', 'nope']):
        proc = subprocess.run([sys.executable, '-m', 'trust_monitor.estimate', str(plans),
                               '-o', str(out), *extra],
                              capture_output=True, text=True, check=False)
        assert proc.returncode == 2, proc.stderr
        assert proc.stderr.count('\n') == 1 and "unknown trust model 'nope'" in proc.stderr
        assert not out.exists()


@pytest.mark.parametrize('name', NAMES)
def test_estimate_runs_every_model(name: str, tmp_path: Any) -> None:
    """trust-monitor-estimate with --trust-model: the model's trust, and its variance."""
    plans = tmp_path / 'plans.csv'
    plans.write_text('t,plan_0,expected_0\n0,0.1,0.2\n1,0.0,0.0\n2,1.0,-1.0\n')
    out = tmp_path / 'out.csv'
    proc = subprocess.run([sys.executable, '-m', 'trust_monitor.estimate', str(plans),
                           '-o', str(out), '--trust-model', name],
                          capture_output=True, text=True, check=False)
    assert proc.returncode == 0, proc.stderr
    lines = out.read_text().splitlines()
    m = model(name)
    header = lines[0].split(',')
    assert header[:4] == ['t', 'E', 'P', 'trust']
    assert (header[4:] == ['trust_variance']) == (m.variance(m.initial_state()) is not None)
    state = m.initial_state()
    for line in lines[1:]:
        score = float(line.split(',')[1])
        state = m.step(state, score, 1.0)
        assert float(line.split(',')[3]) == m.trust(state)


@pytest.mark.parametrize('name', NAMES)
def test_simulate_refuses_a_bad_model_parameter_in_one_line(name: str, tmp_path: Any) -> None:
    """trust-av simulate with the model chosen and one of its parameters out of range:
    exit 2, one line naming the parameter, nothing written."""
    bad = next(((f.name, bad_value(f)) for f in fields_of(name) if bad_value(f) is not None),
               ('trust_growth_rate', -1.0))  # no own parameter: a shared one of the model
    params = tmp_path / 'bad.yaml'
    params.write_text(f'/**:\n  ros__parameters:\n    trust_model: {name}\n'
                      f'    {bad[0]}: {bad[1]!r}\n')
    out = tmp_path / 'out'
    proc = subprocess.run([sys.executable, '-m', 'trust_av.cli', 'simulate',
                           '--params-file', str(params), '--no-progress', '--out', str(out)],
                          capture_output=True, text=True, check=False, timeout=120)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert proc.stderr.count('\n') == 1 and bad[0] in proc.stderr, proc.stderr
    assert not out.exists()
