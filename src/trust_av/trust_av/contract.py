"""The plug-in contract, shipped: one call checks a component of any group (as gymnasium's
``check_env`` checks an environment). A plug-in author runs it in their own CI::

    from trust_av.contract import check_component

    def test_my_estimator_keeps_the_contract():
        check_component('trust_av.predictors', 'ses')               # in-process rules
        check_component('trust_av.predictors', 'ses', graph=True)   # and graph == in-process

:func:`check_component` raises :class:`ContractError` naming every rule broken and returns a
:class:`ContractReport` of the rules kept: it **loads** (a ``Component`` whose factory takes
``(shared, params)``); its **declaration** (a description; parameters a frozen dataclass of
``param()`` fields with valid defaults and names no other component or its node uses; a trust
model's start with its name); it **builds** from the shipped configuration; its **outputs** over
seeded inputs pass the loop's own per-step checks (:mod:`trust_av_common.component_checks`); it
is **deterministic**; a **bad parameter** is refused in one line naming it; a trust model's
**time consistency**, **pure step**, **monotone** update, **bound** and **closed form**; with
``graph=True``, **graph == in-process** over 30 steps (it starts processes: 10-30 s).
docs/reference/components.md says each in full.

It drives the system a component plugs into (the configuration, the planner, the loop, the
CLI), imported inside the functions that use them (so the type checker and the layer test see
every one): importing the contract loads only the modules that declare the three groups.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import subprocess
import sys
import tempfile
import typing
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from human_driver_sim.followers import DRIVERS
from trust_av_common import registry
from trust_av_common.errors import TrustAvError, one_line
from trust_av_common.params import PARAM_METADATA_KEY, ParamsError, ParamSpec, build_config
from trust_av_planner.predictors import PREDICTORS
from trust_monitor.model_interface import TRUST_MODELS

__all__ = ['ContractError', 'ContractReport', 'check_component']

GRAPH_STEPS = 30
"""Steps of the graph == in-process rule."""
RECORD_TOLERANCE = 1e-7
"""How far a value the graph recorded may be from the in-process one (the two paths agree
to ~1e-16 per step; an iterative solve turns that into up to ~1e-8)."""
NODE_OF = {PREDICTORS: 'planner', DRIVERS: 'human_driver'}
"""The node section that runs a group (a trust model's parameters are shared: ``/**``)."""
TRUST_BASE = {'epsilon_mps2': 6.0, 'trust_growth_rate': 0.1, 'performance_threshold': 0.8,
              'trust_initial': 0.0}
"""The shared trust parameters the trust-model rules run with."""
NEEDS = {'declaration': ('loads',), 'builds': ('loads',), 'outputs': ('builds',),
         'deterministic': ('outputs',), 'bad parameters': ('loads',),
         'time consistency': ('builds',), 'pure step': ('builds',), 'monotone': ('builds',),
         'bound': ('builds',), 'closed form': ('builds',),
         'graph == in-process': ('outputs', 'deterministic')}
"""Rules that run only when these ones held (a component that does not build has no
outputs to check)."""
TRUST_SCORES = (0.0, 0.001, 0.02, 0.15, 0.2027, 0.21, 0.4, 0.9)
"""Explicability scores the trust-model rules feed (around the shipped P_thre's E)."""


class ContractError(TrustAvError):
    """A component breaks its contract; the message names it and every rule it breaks."""


@dataclass(frozen=True)
class ContractReport:
    """The rules component ``name`` of ``group`` kept (``passed``, in order) and those that
    do not apply to it, each with why (``skipped``: ``'closed form: none given'``)."""

    group: str
    name: str
    passed: tuple[str, ...]
    skipped: tuple[str, ...]


class _DoesNotApplyError(Exception):
    """A rule that does not apply to this component (the message says why)."""


def check_component(group: str, name: str, *, graph: bool = False, steps: int = 15,
                    seed: int = 7) -> ContractReport:
    """Check component ``name`` of ``group`` against its group's contract (module docstring).

    Args:
        group: its entry-point group (``'trust_av.predictors'``, ``'trust_av.trust_models'``,
            ``'trust_av.drivers'``).
        name: its registered name.
        graph: also run the node graph and compare it with the in-process loop (starts
            processes: 10-30 s).
        steps: steps of seeded inputs the output rules feed.
        seed: their seed.

    Returns:
        The rules it kept and the ones that do not apply.

    Raises:
        ContractError: it breaks one or more rules (each named, with why).
        RegistryError: ``group`` is not a group, or ``name`` is not registered in it.
    """
    if name not in registry.names(group):   # (names() refuses an unknown group)
        registry.get(group, name)   # raises: unknown, listing the registered names
    rules: list[tuple[str, Callable[[], None]]] = [
        ('loads', lambda: _loads(group, name)),
        ('declaration', lambda: _declaration(group, name)),
        ('builds', lambda: _ignore(_outputs(group, name, 0, seed))),
        ('outputs', lambda: _ignore(_outputs(group, name, steps, seed))),
        ('deterministic', lambda: _deterministic(group, name, steps, seed)),
        ('bad parameters', lambda: _bad_parameters(group, name)),
    ]
    if group == TRUST_MODELS:
        rules += [('time consistency', lambda: _time_consistent(name)),
                  ('pure step', lambda: _pure_step(name)),
                  ('monotone', lambda: _monotone(name)),
                  ('bound', lambda: _bound(name)),
                  ('closed form', lambda: _closed_form(name))]
    if graph:
        rules.append(('graph == in-process', lambda: _graph_equals_in_process(group, name)))
    passed, skipped, broken = [], [], []
    for rule, check in rules:
        needed = [r for r in NEEDS.get(rule, ()) if r not in passed]
        if needed:
            skipped.append(f'{rule}: not run ({", ".join(needed)} broken)')
            continue
        try:
            check()
        except _DoesNotApplyError as why:
            skipped.append(f'{rule}: {why}')
        except KeyboardInterrupt:
            raise
        except (AssertionError, TrustAvError) as err:
            broken.append(f'{rule}: {one_line(err)}')
        except BaseException as err:   # a component may raise anything, SystemExit too
            broken.append(f'{rule}: {type(err).__name__}: {one_line(err)}')
        else:
            passed.append(rule)
    if broken:
        raise ContractError(f'{registry.describe(group, name)} breaks its contract: '
                            f'{"; ".join(broken)}')
    return ContractReport(group, name, tuple(passed), tuple(skipped))


def _ignore(_value: Any) -> None:   # a rule that only needs its call to succeed
    pass


def _require(condition: bool, message: str) -> None:
    if not condition:
        raise AssertionError(message)


# --- every group ------------------------------------------------------------------------

def _loads(group: str, name: str) -> None:
    component = registry.get(group, name)   # the entry point, the Component, the factory
    _require(component.name == name, f'named {component.name!r} inside')


def _declaration(group: str, name: str) -> None:
    component = registry.get(group, name)
    _require(bool(component.description.strip()), 'no description (one line for --help)')
    cls = component.config_type
    if cls is None:
        return
    _require(cls.__dataclass_params__.frozen, f'{cls.__name__} is not frozen')  # type: ignore[attr-defined]
    for field in dataclasses.fields(cls):
        _require(isinstance(field.metadata.get(PARAM_METADATA_KEY), ParamSpec),
                 f'{field.name} is not declared with param()')
        _require(field.default is not dataclasses.MISSING, f'{field.name} has no default')
        if group == TRUST_MODELS:
            _require(field.name.startswith(f'{name}_'),
                     f'{field.name} does not start with {name}_ (one flat namespace)')
    cls()  # the defaults are valid
    from trust_av.system import config
    node = NODE_OF.get(group)
    own = (config.node_components(node) if node is not None else config.all_components())
    taken = {f.name for c in own if c is not cls for f in dataclasses.fields(c)}
    clash = sorted({f.name for f in dataclasses.fields(cls)} & taken)
    _require(not clash, f'parameter(s) {clash} already belong to another component or the '
                        'node')


def _run_config(group: str, name: str) -> Any:
    """The shipped run configuration with ``name`` chosen."""
    chooser = {PREDICTORS: ('planner', 'predictor'),
               DRIVERS: ('human_driver', 'driver_model')}.get(
                   group, ('/**', 'trust_model'))
    from trust_av.system.config import load_run_config
    return load_run_config((), {chooser[0]: {chooser[1]: name}})


def _outputs(group: str, name: str, steps: int, seed: int) -> list[Any]:
    """A fresh instance's outputs over ``steps`` seeded inputs, each through the loop's own
    checks (a bad one raises :class:`~trust_av_common.component_checks.ComponentError`)."""
    feed = {PREDICTORS: _predictions, DRIVERS: _follower_plans}
    return feed.get(group, _trust_readings)(name, steps, np.random.default_rng(seed))


def _predictions(name: str, steps: int, rng: np.random.Generator) -> list[Any]:
    from trust_av_planner import planner
    from trust_av_planner.predictors import Observation
    config = _run_config(PREDICTORS, name)
    predictor = planner.CheckedPredictor(planner.make_predictor(
        config.planner, config.predictor_params), config.planner)
    out = [predictor.predict()]
    for _ in range(steps):
        gap, speed = rng.uniform(8.0, 40.0), rng.uniform(2.0, 25.0)
        predictor.observe(Observation(
            gap_m=gap, relative_speed_mps=rng.uniform(-3.0, 3.0),
            time_headway_s=min(gap / speed, 10.0), av_accel_mps2=rng.uniform(-3.0, 3.0)))
        out.append(predictor.predict())
    return out


def _follower_plans(name: str, steps: int, rng: np.random.Generator) -> list[Any]:
    from human_driver_sim import followers
    config = _run_config(DRIVERS, name)
    follower = followers.make_follower(config.driver, followers.FollowerConfig(name),
                                       config.driver_params)   # checks every step
    out = []
    for _ in range(steps):
        expected = rng.uniform(-3.0, 3.0, config.driver.horizon_steps)
        result = follower.step(float(rng.uniform(8.0, 40.0)), float(rng.uniform(2.0, 25.0)),
                               float(rng.uniform(2.0, 25.0)), expected)
        out.append(result.plan_mps2)
    return out


def _trust_config(name: str) -> Any:
    from trust_monitor.paper_trust import TrustConfig
    return TrustConfig(**TRUST_BASE, trust_model=name)


def _model(name: str) -> Any:
    from trust_monitor.model_interface import make_trust_model
    return make_trust_model(_trust_config(name))


def _trust_readings(name: str, steps: int, rng: np.random.Generator) -> list[Any]:
    from trust_monitor import model_interface as interface
    from trust_monitor.paper_trust import TrustEstimator
    config = _trust_config(name)
    model = interface.make_trust_model(config)
    estimator = TrustEstimator(config, model)   # checks trust and variance every step
    bound = interface.CheckedBound(model, name)
    out = []
    for _ in range(steps):
        plan, expected = rng.uniform(-3.0, 3.0, 3), rng.uniform(-3.0, 3.0, 3)
        estimate = estimator.step(plan, expected, float(rng.choice([0.1, 0.5, 1.0])))
        e_max = bound(estimator.state, estimate.trust - 0.01, 3, 1.0)
        out.append((estimate.trust, estimate.variance, e_max))
    return out


def _deterministic(group: str, name: str, steps: int, seed: int) -> None:
    first, second = _outputs(group, name, steps, seed), _outputs(group, name, steps, seed)
    for k, (a, b) in enumerate(zip(first, second, strict=True)):
        _require(np.array_equal(np.asarray(a, dtype=float), np.asarray(b, dtype=float),
                                equal_nan=True),
                 f'two instances differ at step {k}: {a!r} vs {b!r}')


def _bad_value(field: dataclasses.Field[Any], hint: Any) -> Any:
    """A value of ``field`` its declaration refuses (None: it refuses none of its type)."""
    spec = field.metadata[PARAM_METADATA_KEY]
    if spec.choices:
        return 'not_a_choice'
    if hint in (int, float) and spec.low is not None:
        return spec.low - 1
    if hint in (int, float) and spec.high is not None:
        return spec.high + 1
    return None


def _bad_parameters(group: str, name: str) -> None:
    cls = registry.get(group, name).config_type
    if cls is None:
        raise _DoesNotApplyError('no parameters of its own')
    hints = typing.get_type_hints(cls)
    checked = 0
    for field in dataclasses.fields(cls):
        for value in (_bad_value(field, hints[field.name]), object()):
            if value is None:
                continue
            try:
                build_config(cls, {field.name: value})
            except ParamsError as err:
                _require(field.name in str(err) and '\n' not in str(err),
                         f'{field.name} = {value!r}: the refusal does not name it in one line '
                         f'({err!r})')
            else:
                raise AssertionError(f'{field.name} = {value!r} is accepted')
            checked += 1
    _require(checked > 0, 'no parameter to check')


# --- trust models -----------------------------------------------------------------------

def _close(a: Any, b: Any, tol: float = 1e-9) -> bool:
    """Equal states: floats within ``tol`` (relative), dataclasses field by field."""
    if dataclasses.is_dataclass(a):
        return all(_close(getattr(a, f.name), getattr(b, f.name), tol)
                   for f in dataclasses.fields(a))
    if a is None or b is None:
        return a is b
    return math.isclose(a, b, rel_tol=tol, abs_tol=tol)


def _time_consistent(name: str) -> None:
    m = _model(name)
    coarse = fine = m.initial_state()
    for score in TRUST_SCORES:
        coarse = m.step(coarse, score, 1.0)
        for _ in range(10):
            fine = m.step(fine, score, 0.1)
        _require(_close(coarse, fine), f'E = {score}: one 1 s step gives {coarse!r}, ten of '
                                       f'0.1 s {fine!r}')


def _pure_step(name: str) -> None:
    m = _model(name)
    state = m.step(m.initial_state(), 0.1, 1.0)
    before = m.trust(state)
    m.step(state, 0.9, 1.0)
    _require(m.trust(state) == before, 'a step changed the state it was given')


def _states(m: Any) -> list[Any]:
    """A spread of reachable states: good and bad histories, short and long."""
    out = [m.initial_state()]
    for score, n in ((0.001, 30), (0.5, 5), (0.25, 10), (0.9, 40)):
        state = m.initial_state()
        for _ in range(n):
            state = m.step(state, score, 1.0)
        out.append(state)
    return out


def _monotone(name: str) -> None:
    from trust_monitor.model_interface import propagate
    m = _model(name)
    state = m.step(m.initial_state(), 0.05, 1.0)
    grid = [i / 200 for i in range(201)]
    for steps in (1, 3):
        trusts = [propagate(m, state, e, steps, 1.0)[-1] for e in grid]
        for (e, a), b in zip(zip(grid, trusts, strict=True), trusts[1:], strict=False):
            _require(b <= a + 1e-12, f'trust after {steps} step(s) rises with E near {e}')


def _bound(name: str) -> None:
    from trust_monitor import model_interface as interface
    m = _model(name)
    binding = 0
    for (steps, dt_s), state in itertools.product(((3, 1.0), (30, 0.1), (1, 1.0)), _states(m)):
        now = m.trust(state)

        def lowest(e: float, s: Any = state, n: int = steps, d: float = dt_s) -> float:
            return float(min(interface.propagate(m, s, e, n, d)))

        for trust_min in (now - 1.0, now - 0.05, now - 1e-3, now, now + 0.02):
            bound = interface.numeric_bound(m, state, trust_min, steps, dt_s)
            if bound is None:
                _require(lowest(0.0) < trust_min, 'E_max None though E = 0 keeps T >= T_min')
            elif bound == math.inf:
                _require(lowest(1.0) >= trust_min, 'E_max inf though E = 1 breaks T >= T_min')
            else:
                binding += 1
                _require(lowest(bound) >= trust_min, f'E_max {bound} breaks T >= T_min')
                _require(lowest(bound + 1e-9) < trust_min, f'E_max {bound} is not the largest')
    _require(binding > 0, 'the bound never bound: nothing was checked')


def _closed_form(name: str) -> None:
    from trust_monitor import model_interface as interface
    m = _model(name)
    if m.closed_form_bound is None:
        raise _DoesNotApplyError('none given')
    for (steps, dt_s), state in itertools.product(((3, 1.0), (30, 0.1)), _states(m)):
        now = m.trust(state)
        for trust_min in (now - 2.0, now - 0.2, now - 0.01, now, now + 0.05, now + 0.5):
            closed = m.closed_form_bound(state, trust_min, steps, dt_s)
            numeric = interface.numeric_bound(m, state, trust_min, steps, dt_s)
            if closed is None or numeric is None:
                _require(closed is numeric, f'closed form {closed}, numeric {numeric}')
            else:
                _require(abs(min(closed, 1.0) - min(numeric, 1.0)) <= 1e-9,
                         f'closed form {closed}, numeric {numeric} (T_min {trust_min})')


# --- graph == in-process ----------------------------------------------------------------

def _graph_equals_in_process(group: str, name: str) -> None:
    with tempfile.TemporaryDirectory(prefix='trust_av_contract_') as folder:
        _compare_graph(group, name, Path(folder))


def _compare_graph(group: str, name: str, folder: Path) -> None:
    trace_csv = folder / 'contract.csv'
    trace_csv.write_text('time_s,speed_mps\n' + ''.join(
        f'{t},{12.0 + 6.0 * math.sin(t / 5.0):.3f}\n' for t in range(GRAPH_STEPS + 1)))
    params = folder / 'component.yaml'
    if group == TRUST_MODELS:   # T_min above its initial trust: the bound binds
        model = _run_config(group, name).trust_model()
        trust_min = model.trust(model.initial_state()) + 0.1
        params.write_text(f'/**:\n  ros__parameters:\n    trust_model: {name}\n'
                          f'/**/planner:\n  ros__parameters:\n    trust_min: {trust_min!r}\n')
    else:
        chooser = 'predictor' if group == PREDICTORS else 'driver_model'
        params.write_text(f'/**/{NODE_OF[group]}:\n  ros__parameters:\n'
                          f'    {chooser}: {name}\n')
    from preceding_traffic.sources import load_trace
    from preceding_traffic.traces import truncate
    from trust_av.graph.bag_records import records_from_bag
    from trust_av.system.closed_loop import simulate
    from trust_av.system.config import load_run_config

    config = load_run_config([params])
    trace = truncate(load_trace(str(trace_csv), config.planner.dt_s, config.trace), GRAPH_STEPS)
    reference = simulate(config, trace).records
    if group == TRUST_MODELS:
        binding = sum(1 for r in reference if 0.0 < r.explicability_max < 1.0)
        _require(binding >= 2, f'the trust constraint bound at {binding} step(s) of '
                               f'{GRAPH_STEPS}: the comparison would check little')
    bag = folder / 'run'
    proc = subprocess.run([sys.executable, '-m', 'trust_av.cli', 'run', '--trace',
                           str(trace_csv), '--params-file', str(params), '--max-steps',
                           str(GRAPH_STEPS), '--bag', str(bag), '--no-plot', '--no-progress'],
                          cwd=folder, capture_output=True, text=True, timeout=600,
                          stdin=subprocess.DEVNULL, check=False)
    _require(proc.returncode == 0, f'trust-av run exited with {proc.returncode}: '
                                   f'{" ".join(proc.stderr.split()[-40:])}')
    recorded = records_from_bag(bag)
    _require(len(recorded) == len(reference),
             f'the graph recorded {len(recorded)} steps, the loop made {len(reference)}')
    for g, r in zip(recorded, reference, strict=True):
        for field in dataclasses.fields(r):
            a, b = getattr(g, field.name), getattr(r, field.name)
            if 'solve_time' in field.name or (field.name in ('solver_status',
                                                             'solver_iterations')
                                              and g.solver_success and r.solver_success):
                continue   # how a successful SQP got there differs in the last bits
            same = (np.allclose(a, b, rtol=0.0, atol=RECORD_TOLERANCE)
                    if isinstance(b, tuple | float) else a == b)
            _require(bool(same), f't = {r.t_s} s: {field.name} is {a!r} in the graph, '
                                 f'{b!r} in-process')
