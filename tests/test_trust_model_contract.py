"""The contract every registered trust model must meet (shipped or a plug-in's).

Parametrised from the registry (``trust_av.trust_models``), so a package that registers a
model is held to the same rules: time consistency, determinism, a monotone update (what
the numeric NMPC bound assumes), a numeric bound that keeps T >= T_min on the propagated
update, the closed form equal to the numeric one, a one-line refusal of a bad parameter
value, and graph == in-process: 30 lock-step steps of ``trust-av run`` with the model chosen
by ``trust_model`` equal the in-process loop (trust, E, plans), with T_min set above the
model's initial trust so that the NMPC's trust constraint binds.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from test_component_contract import GRAPH_STEPS, assert_same_records, cli, trace_csv

from preceding_traffic.sources import load_trace
from preceding_traffic.traces import truncate
from trust_av_planner.system.closed_loop import simulate
from trust_av_planner.system.config import load_run_config
from trust_monitor.common import registry
from trust_monitor.common.params import ParamsError, build_config
from trust_monitor.trust_interface import (
    TrustModel,
    make_trust_model,
    numeric_bound,
    propagate,
    trust_model_component,
)
from trust_monitor.trust_model import TrustConfig

NAMES = registry.names(registry.TRUST_MODELS)
__all__ = ['trace_csv']  # the 30-step trace of test_component_contract, a fixture here too
BASE = TrustConfig(epsilon_mps2=6.0, trust_growth_rate=0.1, performance_threshold=0.8,
                   trust_initial=0.0)
SCORES = (0.0, 0.001, 0.02, 0.15, 0.2027, 0.21, 0.4, 0.9)


def model(name: str, **trust: Any) -> TrustModel:
    return make_trust_model(dataclasses.replace(BASE, trust_model=name, **trust))


def close(a: Any, b: Any, tol: float = 1e-9) -> bool:
    """Equal states: floats within ``tol`` (relative), dataclasses field by field."""
    if dataclasses.is_dataclass(a):
        return all(close(getattr(a, f.name), getattr(b, f.name), tol)
                   for f in dataclasses.fields(a))
    if a is None or b is None:
        return a is b
    return math.isclose(a, b, rel_tol=tol, abs_tol=tol)


def test_the_shipped_models_are_registered() -> None:
    assert {'paper', 'asymmetric', 'beta_bernoulli', 'optimo'} <= set(NAMES)


@pytest.mark.parametrize('name', NAMES)
def test_is_a_trust_model(name: str) -> None:
    m = model(name)
    assert isinstance(m, TrustModel)
    assert m.name == name
    assert math.isfinite(m.trust(m.initial_state()))


@pytest.mark.parametrize('name', NAMES)
def test_ten_tenths_equal_one_second(name: str) -> None:
    m = model(name)
    coarse = fine = m.initial_state()
    for score in SCORES:
        coarse = m.step(coarse, score, 1.0)
        for _ in range(10):
            fine = m.step(fine, score, 0.1)
        assert close(coarse, fine), (score, coarse, fine)
    assert close(m.trust(coarse), m.trust(fine))


@pytest.mark.parametrize('name', NAMES)
def test_deterministic(name: str) -> None:
    runs = []
    for _ in range(2):
        m = model(name)
        state = m.initial_state()
        trail = []
        for score in SCORES * 3:
            state = m.step(state, score, 0.5)
            trail.append((m.trust(state), m.variance(state)))
        runs.append(trail)
    assert runs[0] == runs[1]


@pytest.mark.parametrize('name', NAMES)
def test_step_does_not_change_its_input(name: str) -> None:
    m = model(name)
    state = m.step(m.initial_state(), 0.1, 1.0)
    before = m.trust(state)
    m.step(state, 0.9, 1.0)
    assert m.trust(state) == before


@pytest.mark.parametrize('name', NAMES)
def test_trust_does_not_rise_with_the_score(name: str) -> None:
    """What the numeric bound assumes: the admissible E form an interval [0, E_max]."""
    m = model(name)
    state = m.step(m.initial_state(), 0.05, 1.0)
    grid = [i / 200 for i in range(201)]
    for steps in (1, 3):
        trusts = [propagate(m, state, e, steps, 1.0)[-1] for e in grid]
        assert all(b <= a + 1e-12 for a, b in itertools.pairwise(trusts))


def states(m: TrustModel) -> list[Any]:
    """A spread of reachable states: good and bad histories, short and long."""
    out = [m.initial_state()]
    for score, n in ((0.001, 30), (0.5, 5), (0.25, 10), (0.9, 40)):
        state = m.initial_state()
        for _ in range(n):
            state = m.step(state, score, 1.0)
        out.append(state)
    return out


@pytest.mark.parametrize('name', NAMES)
@pytest.mark.parametrize('steps, dt_s', [(3, 1.0), (30, 0.1), (1, 1.0)])
def test_numeric_bound_keeps_trust_above_the_minimum(name: str, steps: int,
                                                     dt_s: float) -> None:
    m = model(name)
    binding = 0
    for state in states(m):
        now = m.trust(state)
        for trust_min in (now - 1.0, now - 0.05, now - 1e-3, now, now + 0.02):
            bound = numeric_bound(m, state, trust_min, steps, dt_s)
            if bound is None:  # not even E = 0 keeps it: check that
                assert min(propagate(m, state, 0.0, steps, dt_s)) < trust_min
                continue
            if bound == math.inf:
                assert min(propagate(m, state, 1.0, steps, dt_s)) >= trust_min
                continue
            binding += 1
            assert min(propagate(m, state, bound, steps, dt_s)) >= trust_min
            # ... and it is the largest: a little more E breaks the constraint
            assert min(propagate(m, state, bound + 1e-9, steps, dt_s)) < trust_min
    assert binding > 0, 'the bound never bound: the test checked nothing'


@pytest.mark.parametrize('name', NAMES)
def test_closed_form_equals_numeric(name: str) -> None:
    m = model(name)
    if m.closed_form_bound is None:
        pytest.skip(f'{name} has no closed form')
    compared = 0
    for steps, dt_s in ((3, 1.0), (30, 0.1)):
        for state in states(m):
            now = m.trust(state)
            for trust_min in (now - 2.0, now - 0.2, now - 0.01, now, now + 0.05, now + 0.5):
                closed = m.closed_form_bound(state, trust_min, steps, dt_s)
                numeric = numeric_bound(m, state, trust_min, steps, dt_s)
                if closed is None or numeric is None:
                    assert closed is numeric, (state, trust_min, closed, numeric)
                    continue
                assert min(closed, 1.0) == pytest.approx(min(numeric, 1.0), abs=1e-9)
                compared += 1
    assert compared > 10


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


@pytest.mark.parametrize('name', NAMES)
def test_own_parameters_are_named_after_the_model(name: str) -> None:
    """One flat namespace of ROS parameters: a model's own start with its name."""
    for field in fields_of(name):
        assert field.name.startswith(f'{name}_'), field.name


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
    proc = subprocess.run([sys.executable, '-m', 'trust_av_planner.cli', 'simulate',
                           '--params-file', str(params), '--no-progress', '--out', str(out)],
                          capture_output=True, text=True, check=False, timeout=120)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert proc.stderr.count('\n') == 1 and bad[0] in proc.stderr, proc.stderr
    assert not out.exists()


TRUST_MIN_ABOVE_INITIAL = 0.1
"""T_min - T(0) in the graph test: above the initial trust, so the NMPC starts on its
fallback and then plans under a binding E_max while trust climbs past T_min (for the
shipped models on a 0-1 scale: 2 to 5 of the 30 steps bind)."""


@pytest.mark.parametrize('name', NAMES)
def test_graph_equals_in_process(name: str, tmp_path: Path, trace_csv: Path) -> None:
    """``trust-av run`` (the node graph, lock-step) with ``trust_model: NAME`` equals
    ``system.closed_loop.simulate`` over 30 steps: every recorded field (trust, E, E_max,
    the plans) but the solve times."""
    from trust_av_planner.graph.bag_records import records_from_bag

    shipped = load_run_config().trust
    m = make_trust_model(dataclasses.replace(shipped, trust_model=name))
    trust_min = m.trust(m.initial_state()) + TRUST_MIN_ABOVE_INITIAL
    params = tmp_path / 'model.yaml'
    params.write_text(f'/**:\n  ros__parameters:\n    trust_model: {name}\n'
                      f'/**/planner:\n  ros__parameters:\n    trust_min: {trust_min!r}\n')
    config = load_run_config([params])
    assert config.trust.trust_model == name and config.planner.trust_min == trust_min
    trace = truncate(load_trace(str(trace_csv), config.planner.dt_s, config.trace),
                     GRAPH_STEPS)
    reference = simulate(config, trace).records
    binding = [r.t_s for r in reference if 0.0 < r.explicability_max < 1.0]
    assert len(binding) >= 2, f'{name}: the trust constraint must bind for this test to mean ' \
                              f'anything (E_max < 1 at t = {binding})'
    bag = tmp_path / 'run'
    proc = cli('run', '--trace', str(trace_csv), '--params-file', str(params),
               '--max-steps', str(GRAPH_STEPS), '--bag', str(bag), '--no-plot',
               '--no-progress', cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert_same_records(records_from_bag(bag), reference)
