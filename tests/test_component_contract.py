"""The contract every registered plan estimator and follower model is held to, shipped or
installed (a plug-in is tested by installing it into the environment and running this file).

Parametrised from the registry at collection time; only the declared interface is used:
the :class:`~trust_monitor.common.registry.Component` (factory, config_type, needs), the
group's factory arguments (:mod:`trust_av_planner.predictors`,
:mod:`human_driver_sim.followers`), the params file and the command line. Per component:

- declaration: its parameters are a frozen dataclass whose every field is declared with
  ``param()`` and has a default, and no field shares a name with its node's parameters or
  another component's;
- shape: ``horizon_steps`` finite values within the bounds of the AV (estimator) or the
  human (follower);
- determinism: two instances fed the same inputs give the same outputs;
- refusal: a bad value of one of its parameters in a params file (or, when it has none, a
  parameter it does not have) is one line on stderr, exit 2 and nothing written;
- graph == in-process: 30 steps through the node graph equal the in-process loop.
"""

from __future__ import annotations

import dataclasses
import math
import subprocess
import sys
import typing
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from test_graph import assert_records_equal

from human_driver_sim.followers import FollowerConfig, make_follower
from preceding_traffic.sources import load_trace
from preceding_traffic.traces import truncate
from trust_av_planner.planner import make_predictor
from trust_av_planner.predictors import Observation
from trust_av_planner.system.closed_loop import simulate
from trust_av_planner.system.config import NODE_COMPONENTS, load_run_config
from trust_av_planner.system.metrics import StepRecord
from trust_monitor.common import registry
from trust_monitor.common.params import PARAM_METADATA_KEY, ParamSpec

GRAPH_STEPS = 30
SECTIONS = {registry.PREDICTORS: ('planner', 'predictor', '--predictor'),
            registry.DRIVERS: ('human_driver', 'driver_model', '--driver-model')}
"""Group -> (node section, the parameter that chooses it, its command-line option)."""
CASES = [(group, name) for group in SECTIONS for name in registry.names(group)]
IDS = [f'{group.rsplit(".", 1)[-1]}-{name}' for group, name in CASES]


def cli(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    """``trust-av ARGS`` in a fresh process (which finds the components as a user's does)."""
    return subprocess.run([sys.executable, '-m', 'trust_av_planner.cli', *args], cwd=cwd,
                          capture_output=True, text=True, timeout=300, stdin=subprocess.DEVNULL)


@pytest.fixture(scope='module')
def trace_csv(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 30-step speed trace (1 s steps, a slow and a fast phase)."""
    path = tmp_path_factory.mktemp('contract') / 'contract.csv'
    path.write_text('time_s,speed_mps\n' + ''.join(
        f'{t},{12.0 + 6.0 * math.sin(t / 5.0):.3f}\n' for t in range(GRAPH_STEPS + 1)))
    return path


def observations(seed: int, count: int = 15) -> list[Observation]:
    """Seeded, physically plausible observations of the AV by the human."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(count):
        gap, speed = rng.uniform(8.0, 40.0), rng.uniform(2.0, 25.0)
        out.append(Observation(gap_m=gap, relative_speed_mps=rng.uniform(-3.0, 3.0),
                               time_headway_s=min(gap / speed, 10.0),
                               av_accel_mps2=rng.uniform(-3.0, 3.0)))
    return out


def predictions(name: str) -> list[np.ndarray]:
    """A fresh estimator ``name`` (shipped planner parameters): its prediction before and
    after each of :func:`observations`."""
    config = load_run_config(overrides={'planner': {'predictor': name}})
    predictor = make_predictor(config.planner, config.predictor_params)
    out = [np.array(predictor.predict(), dtype=float)]
    for observation in observations(seed=7):
        predictor.observe(observation)
        out.append(np.array(predictor.predict(), dtype=float))
    return out


def follower_plans(name: str) -> list[np.ndarray]:
    """A fresh follower ``name`` (shipped human_driver parameters): its plans over seeded
    inputs (gap, speeds, the expected AV plan)."""
    config = load_run_config(overrides={'human_driver': {'driver_model': name}})
    follower = make_follower(config.driver, FollowerConfig(name), config.driver_params)
    rng = np.random.default_rng(11)
    plans = []
    for _ in range(10):
        expected = rng.uniform(-3.0, 3.0, config.driver.horizon_steps)
        result = follower.step(float(rng.uniform(8.0, 40.0)), float(rng.uniform(2.0, 25.0)),
                               float(rng.uniform(2.0, 25.0)), expected)
        plans.append(np.array(result.plan_mps2, dtype=float))
    return plans


def outputs(group: str, name: str) -> list[np.ndarray]:
    return predictions(name) if group == registry.PREDICTORS else follower_plans(name)


@pytest.mark.parametrize(('group', 'name'), CASES, ids=IDS)
def test_declaration(group: str, name: str) -> None:
    component = registry.get(group, name)
    assert component.name == name and component.description
    assert set(component.needs) <= registry.KNOWN_NEEDS
    if component.config_type is None:
        return
    cls = component.config_type
    assert dataclasses.is_dataclass(cls) and cls.__dataclass_params__.frozen  # type: ignore[attr-defined]
    for field in dataclasses.fields(cls):
        assert isinstance(field.metadata.get(PARAM_METADATA_KEY), ParamSpec), field.name
        assert field.default is not dataclasses.MISSING, f'{field.name} has no default'
    cls()  # the defaults are valid
    node = SECTIONS[group][0]
    others = [c.config_type for g in SECTIONS for c in registry.components(g)
              if c.config_type is not None and c.name != name]
    taken = {f.name for c in (*NODE_COMPONENTS[node], *others) for f in dataclasses.fields(c)}
    clash = {f.name for f in dataclasses.fields(cls)} & taken
    assert not clash, f'{name}: parameter(s) {sorted(clash)} already belong to another component'


@pytest.mark.parametrize(('group', 'name'), CASES, ids=IDS)
def test_output_shape_and_bounds(group: str, name: str) -> None:
    config = load_run_config()
    if group == registry.PREDICTORS:
        steps, low, high = (config.planner.horizon_steps, config.planner.accel_min_mps2,
                            config.planner.accel_max_mps2)
    else:
        steps, low, high = (config.driver.horizon_steps, config.driver.accel_min_mps2,
                            config.driver.accel_max_mps2)
    for out in outputs(group, name):
        assert out.shape == (steps,)
        assert np.all(np.isfinite(out))
        assert np.all(out >= low - 1e-9) and np.all(out <= high + 1e-9), out


@pytest.mark.parametrize(('group', 'name'), CASES, ids=IDS)
def test_deterministic(group: str, name: str) -> None:
    first, second = outputs(group, name), outputs(group, name)
    assert len(first) == len(second)
    for a, b in zip(first, second, strict=True):
        np.testing.assert_array_equal(a, b)


def bad_value(field: dataclasses.Field[Any], hint: Any) -> Any:
    """A value of ``field`` that its declaration refuses: out of its range or choices, or
    of the wrong type when it has neither."""
    spec = field.metadata[PARAM_METADATA_KEY]
    if spec.choices:
        return 'not_a_choice'
    if hint in (int, float) and spec.low is not None:
        return spec.low - 1
    if hint in (int, float) and spec.high is not None:
        return spec.high + 1
    return 'not a number' if hint in (int, float, bool) else 12


@pytest.mark.parametrize(('group', 'name'), CASES, ids=IDS)
def test_bad_parameter_is_refused_in_one_line(group: str, name: str, tmp_path: Path,
                                              trace_csv: Path) -> None:
    node, chooser, _ = SECTIONS[group]
    cls = registry.get(group, name).config_type
    if cls is None:
        key, value, named = f'{name}_no_such_parameter', 1.0, f'{name}_no_such_parameter'
    else:
        field = dataclasses.fields(cls)[0]
        key, named = field.name, field.name
        value = bad_value(field, typing.get_type_hints(cls)[field.name])
    params = tmp_path / 'bad.yaml'
    params.write_text(f'/**/{node}:\n  ros__parameters:\n    {chooser}: {name}\n'
                      f'    {key}: {value!r}\n')
    before = sorted(p.name for p in tmp_path.iterdir())
    proc = cli('simulate', '--trace', str(trace_csv), '--params-file', str(params),
               '--no-progress', cwd=tmp_path)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and named in lines[0] and 'Traceback' not in proc.stderr, lines
    assert sorted(p.name for p in tmp_path.iterdir()) == before


@pytest.mark.parametrize('name', registry.names(registry.PREDICTORS))
def test_the_declared_needs_decide_what_runs_without_the_follower(name: str,
                                                                  tmp_path: Path) -> None:
    """Without the follower's odometry the planner and ``trust-av shadow`` refuse exactly
    the estimators that declare ``follower_state``, whatever their name."""
    from trust_av_planner.planner import AvPlanner
    from trust_monitor.common.kinematics import VehicleState

    needs = registry.FOLLOWER_STATE in registry.get(registry.PREDICTORS, name).needs
    config = load_run_config(overrides={'planner': {'predictor': name}})
    planner = AvPlanner(config.planner, config.trust, config.shared.vehicle_length_m,
                        predictor_params=config.predictor_params)
    lead, av = VehicleState(40.0, 10.0), VehicleState(0.0, 10.0)
    preview = [10.0] * config.planner.horizon_steps
    if needs:
        with pytest.raises(ValueError, match=f'predictor {name} needs the human follower'):
            planner.step(lead, preview, av, None, 0.0)
    else:
        planner.step(lead, preview, av, None, 0.0)
    proc = cli('shadow', '--bag', str(tmp_path / 'missing_bag'), '--predictor', name,
               '--out', str(tmp_path / 'out'), cwd=tmp_path)
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    assert ('has no human follower state' in proc.stderr) == needs, proc.stderr


def assert_same_records(graph: list[StepRecord], ref: list[StepRecord]) -> None:
    assert len(ref) == GRAPH_STEPS
    assert_records_equal(graph, ref)


@pytest.mark.parametrize(('group', 'name'), CASES, ids=IDS)
def test_graph_equals_in_process(group: str, name: str, tmp_path: Path,
                                 trace_csv: Path) -> None:
    from trust_av_planner.graph.bag_records import records_from_bag

    node, chooser, option = SECTIONS[group]
    bag = tmp_path / 'run'
    proc = cli('run', '--trace', str(trace_csv), option, name, '--max-steps', str(GRAPH_STEPS),
               '--bag', str(bag), '--no-plot', '--no-progress', cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    config = load_run_config(overrides={node: {chooser: name}})
    trace = truncate(load_trace(str(trace_csv), config.planner.dt_s, config.trace),
                     GRAPH_STEPS)
    assert_same_records(records_from_bag(bag), simulate(config, trace).records)
