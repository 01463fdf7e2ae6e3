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

import numpy as np
import pytest

from trust_av.contract import check_component
from trust_av_common import registry
from trust_av_common.params import ParamsError, build_config
from trust_monitor.model_interface import (
    TRUST_MODELS,
    TrustModel,
    common_trust,
    make_trust_model,
    trust_model_component,
    trust_trajectory,
)
from trust_monitor.paper_trust import TrustConfig
from trust_monitor.trust_fit import RatedDrive, _Timeline, _trust_on, model_spec

NAMES = registry.names(TRUST_MODELS)
SHIPPED = ('paper', 'asymmetric', 'beta_bernoulli', 'optimo')
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


def random_drive(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """E and step lengths of a random drive: 1 s steps, or a mix of 0, 0.1, 1 s and odd
    lengths (episodes of beta_bernoulli then end inside steps; a step of no time)."""
    steps = int(rng.integers(1, 400))
    scores = rng.uniform(0.0, 0.8, steps) * (rng.random(steps) < 0.9)
    dts = (np.ones(steps) if rng.random() < 0.3 else
           rng.choice([0.0, 0.1, 1.0, 0.37, 2.6], steps) * rng.uniform(0.5, 1.5, steps))
    return scores, dts


@pytest.mark.parametrize('name', NAMES)
def test_the_fast_path_is_the_step_loop(name: str) -> None:
    """A model's ``trajectory`` over a drive (what the fit runs) gives the trust the step
    loop gives, within 1e-12 on the common scale, for parameters anywhere in the fit's
    bounds and random drives; the shipped models have one."""
    rng = np.random.Generator(np.random.PCG64(51))
    spec = model_spec(BASE, name)
    if name in SHIPPED:
        assert callable(getattr(spec.build({}), 'trajectory', None))
    worst = 0.0
    for _ in range(60):
        theta = {p.name: float(rng.uniform(p.low, p.high)) for p in spec.parameters}
        built = spec.build(theta)
        scores, dts = random_drive(rng)
        loop = [common_trust(built, built.initial_state())]
        state = built.initial_state()
        for score, dt in zip(scores, dts, strict=True):
            state = built.step(state, float(score), float(dt))
            loop.append(common_trust(built, state))
        times = np.concatenate(([0.0], np.cumsum(dts[:-1] + 1e-3)))
        drive = RatedDrive('p', 'd', times, scores, np.array([]), np.array([]))
        timeline = dataclasses.replace(_Timeline.of(drive), dts_s=dts,
                                       done=np.arange(len(scores) + 1))
        after, at = _trust_on(built, timeline, every_step=True)
        worst = max(worst, float(np.max(np.abs(after - loop[1:]))),
                    float(np.max(np.abs(at - loop))))
    assert worst <= 1e-12, f'{name}: fast path and step loop differ by {worst:.3g}'


def test_a_model_without_a_fast_path_runs_its_steps() -> None:
    """A plug-in that gives only ``step`` is run step by step (the same trust)."""
    class Stepped:
        name = 'stepped'
        closed_form_bound = None

        def initial_state(self) -> float:
            return 0.5

        def step(self, state: float, score: float, dt_s: float) -> float:
            return state - score * dt_s

        def trust(self, state: float) -> float:
            return state

        def variance(self, state: float) -> float | None:
            return None

    got = trust_trajectory(Stepped(), np.array([0.1, 0.2]), np.array([1.0, 0.5]))
    assert got.tolist() == pytest.approx([0.4, 0.3])
    with pytest.raises(ValueError, match='as many of each'):
        trust_trajectory(Stepped(), np.array([0.1, 0.2]), np.array([1.0]))
