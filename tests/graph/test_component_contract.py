"""The contract every registered plan estimator and follower model is held to, shipped or
installed (a plug-in is tested by installing it into the environment and running this file).

Parametrised from the registry at collection time. The rules themselves are the shipped
contract, :func:`trust_av.contract.check_component` (declaration, build, output
shape and bounds, determinism, bad parameters, and with ``graph=True`` graph == in-process:
30 steps through the node graph equal the in-process loop), which a plug-in's own CI runs
the same way (here the shipped default plan estimator and follower model, whose graph runs
are one and the same run, share it). Here also, through the command line: a bad value of
one of its parameters in a params file (or, when it has none, a parameter it does not
have) is one line on stderr, exit 2 and nothing written; and the declared needs decide what
runs without the follower.
"""

from __future__ import annotations

import dataclasses
import typing
from pathlib import Path
from typing import Any

import pytest
from support.contract import cli, trace_csv

from human_driver_sim.followers import DRIVERS
from trust_av.contract import check_component
from trust_av.system.config import load_run_config
from trust_av_common import registry
from trust_av_common.errors import TrustAvError
from trust_av_common.params import PARAM_METADATA_KEY
from trust_av_planner.predictors import PREDICTORS

__all__ = ['trace_csv']   # the shared fixture, found by pytest by its name

SECTIONS = {PREDICTORS: ('planner', 'predictor', '--predictor'),
            DRIVERS: ('human_driver', 'driver_model', '--driver-model')}
"""Group -> (node section, the parameter that chooses it, its command-line option)."""
CASES = [(group, name) for group in SECTIONS for name in registry.names(group)]
IDS = [f'{group.rsplit(".", 1)[-1]}-{name}' for group, name in CASES]


@pytest.mark.parametrize(('group', 'name'), CASES, ids=IDS)
def test_contract(group: str, name: str) -> None:
    report = check_component(group, name)
    assert {'loads', 'declaration', 'builds', 'outputs', 'deterministic'} <= \
        set(report.passed), report


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


@pytest.mark.parametrize('name', registry.names(PREDICTORS))
def test_the_declared_needs_decide_what_runs_without_the_follower(name: str,
                                                                  tmp_path: Path) -> None:
    """Without the follower's odometry the planner and ``trust-av shadow`` refuse exactly
    the estimators that declare ``follower_state``, whatever their name."""
    from trust_av_common.kinematics import VehicleState
    from trust_av_planner.planner import AvPlanner

    needs = registry.FOLLOWER_STATE in registry.get(PREDICTORS, name).needs
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


def chosen(group: str, name: str) -> Any:
    """The run configuration the contract's graph run of ``name`` has: the shipped one with
    only its chooser set (its params file sets nothing else)."""
    node, chooser, _ = SECTIONS[group]
    return load_run_config(overrides={node: {chooser: name}})


def same_runs() -> list[list[tuple[str, str]]]:
    """:data:`CASES` grouped by their graph run's configuration: the shipped default plan
    estimator and the shipped default follower model choose the same run (the shipped
    configuration), which the graph then starts once for both."""
    groups: list[list[tuple[str, str]]] = []
    configs: list[Any] = []
    for case in CASES:
        try:
            config = chosen(*case)
        except TrustAvError:    # a run of its own, whose test reports why it cannot load
            config = case
        if config in configs:
            groups[configs.index(config)].append(case)
        else:
            configs.append(config)
            groups.append([case])
    return groups


GRAPH_CASES = same_runs()
GRAPH_IDS = ['+'.join(IDS[CASES.index(case)] for case in cases) for cases in GRAPH_CASES]


@pytest.mark.parametrize('cases', GRAPH_CASES, ids=GRAPH_IDS)
def test_graph_equals_in_process(cases: list[tuple[str, str]]) -> None:
    """The shipped contract's graph == in-process for every component; components whose
    graph run is the same run (:func:`same_runs`) share it (their other rules are
    test_contract's, each on its own)."""
    assert all(chosen(*case) == chosen(*cases[0]) for case in cases)
    report = check_component(*cases[0], graph=True)
    assert 'graph == in-process' in report.passed, report
