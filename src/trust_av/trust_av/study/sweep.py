"""A sweep of closed loops: traces x predictors x trust models x followers x alpha, cached, on
a pluggable executor (the paper's sweep is traces x TAC-GRU/TAC-CA x alpha).

Every case is one closed loop: in-process by default, or through the ROS 2 node graph
(:class:`RunSettings`, ``--graph``; each case then leaves its MCAP recording in
``<results>/graph_bags/``). A finished case is cached as JSON under
``<results>/cache/<key>.json``; the key hashes the case, the run settings, the whole params
file and the source of the six packages (so a code or parameter change re-runs what it affects
and an unchanged rerun is read back). Cases run on an :class:`Executor`: local processes by
default (one per core), or Ray (optional extra, ``--executor ray``).
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import hashlib
import json
import logging
import os
import socket
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

from human_driver_sim.population import WEIGHT_NAMES
from preceding_traffic.sources import load_trace
from preceding_traffic.traces import truncate
from trust_av.errors import TrustAvAppError
from trust_av.study.fingerprint import code_fingerprint, plugin_sources
from trust_av.study.workers import joined_ray, worker_pool
from trust_av.system.closed_loop import simulate
from trust_av.system.config import RunConfig, load_run_config
from trust_av.system.metrics import StepRecord, compute_metrics
from trust_av_common import output_files

__all__ = ['ALPHAS', 'METRICS', 'PAPER_PREDICTORS', 'TRACES', 'Case', 'Executor', 'LocalExecutor',
           'RayExecutor', 'RunSettings', 'check_axis', 'check_ray_address', 'code_fingerprint',
           'parameter_value', 'plugin_sources', 'run_case', 'run_sweep', 'sweep_cases']

LOG = logging.getLogger(__name__)

TRACES = ('us06', 'nycc', 'commute_am', 'commute_pm')
PAPER_PREDICTORS = ('gru', 'ca')
"""The paper's plan estimators (TAC-GRU, TAC-CA): ``reproduce``'s default axis."""
ALPHAS = (0.0, 0.25, 0.5, 0.75, 1.0)
METRICS = ('final_trust', 'mean_explicability', 'rmse_mps2')
RUNNERS = ('in-process', 'graph')
@dataclass(frozen=True)
class Case:
    """One closed loop of the sweep.

    Attributes:
        trace: a shipped trace's name, a CSV or a bag.
        predictor: a registered plan estimator.
        alpha: the explicability weight.
        driver: 0 for the human driver of the params file; k >= 1 for the k-th driver of a
            sampled population (``--drivers K``), whose parameters are ``driver_params``.
        driver_params: (name, value) pairs that replace the params file's ``human_driver``
            values for that driver (its weights W and the fitted tau_H); empty for driver 0.
        driver_model: a registered follower model ('' = the params file's).
        trust_model: a registered trust model, set as the ``trust_model`` parameter ('' =
            the params file's).
    """

    trace: str
    predictor: str
    alpha: float
    driver: int = 0
    driver_params: tuple[tuple[str, float], ...] = ()
    driver_model: str = ''
    trust_model: str = ''

    @property
    def label(self) -> str:
        """``us06/TAC-CA/alpha=0.5`` (``.../driver=3`` for a population member, then the
        follower and trust model when they are not the params file's)."""
        label = f'{self.trace}/TAC-{self.predictor.upper()}/alpha={self.alpha:g}'
        label += f'/driver={self.driver}' if self.driver else ''
        label += f'/follower={self.driver_model}' if self.driver_model else ''
        return label + (f'/trust_model={self.trust_model}' if self.trust_model else '')

    @property
    def base(self) -> Case:
        """The same case with the params file's driver (population members grouped)."""
        return dataclasses.replace(self, driver=0, driver_params=())


@dataclass(frozen=True)
class RunSettings:
    """How every case of a sweep runs.

    Attributes:
        runner: ``in-process`` (the simulator) or ``graph`` (the six ROS 2 node processes in
            lock-step, recorded to MCAP and read back; same numbers, about 100x slower).
        max_steps: stop each case after this many control steps (0: the whole trace).
        bags_dir: where graph runs write their bag directories
            ``<trace>_<predictor>_alpha<alpha>/``.
    """

    runner: str = 'in-process'
    max_steps: int = 0
    bags_dir: str = 'graph_bags'

    def __post_init__(self) -> None:
        if self.runner not in RUNNERS:
            raise TrustAvAppError(f'runner must be one of {list(RUNNERS)}, got '
                                  f'{self.runner!r}')
        if self.max_steps < 0:
            raise TrustAvAppError(f'max_steps must be >= 0, got {self.max_steps}')


def case_key(case: Case, params_text: str, fingerprint: str,
             settings: RunSettings = RunSettings()) -> str:
    """Cache key of a case: its fields, how it runs, the params file's text and the code."""
    blob = json.dumps({'case': dataclasses.asdict(case), 'params': params_text,
                       'code': fingerprint, 'runner': settings.runner,
                       'max_steps': settings.max_steps}, sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()[:24]


ParamsFiles = str | Path | Sequence[str | Path]
"""One params file, or several layered in order (each over the shipped file)."""


def layers(params_files: ParamsFiles) -> tuple[str, ...]:
    """The params files as a tuple of paths, bottom first."""
    if isinstance(params_files, (str, Path)):
        return (str(params_files),)
    return tuple(str(p) for p in params_files)


def parameter_value(config: RunConfig, name: str) -> Any:
    """The value of parameter ``name`` in the run configuration (None when no component
    declares it): the trust-model axis reads ``trust_model`` this way."""
    for field in dataclasses.fields(config):
        value = getattr(config, field.name)
        if dataclasses.is_dataclass(value) and any(f.name == name
                                                   for f in dataclasses.fields(value)):
            return getattr(value, name)
    return None


def case_settings(case: Case, config: RunConfig, settings: RunSettings) -> dict[str, Any]:
    """Every setting of a run as it ran (the params files resolved): the tidy table's
    leading columns, then the chosen components' own parameters."""
    trust_model = parameter_value(config, 'trust_model')
    out: dict[str, Any] = {
        'trace': case.trace, 'predictor': config.planner.predictor,
        'trust_model': '' if trust_model is None else trust_model,
        'driver_model': config.follower.driver_model, 'alpha': case.alpha,
        'driver': case.driver,
        **{name: getattr(config.driver, name)
           for name in (*WEIGHT_NAMES, 'time_headway_s', 'desired_standstill_gap_m', 'cautious',
                        'av_extra_decel_mps2')},
        **{name: getattr(config.trust, name)
           for name in ('epsilon_mps2', 'trust_growth_rate', 'performance_threshold',
                        'trust_initial')},
        'runner': settings.runner, 'max_steps': settings.max_steps}
    for params in (config.predictor_params, config.driver_params):
        if params is not None:
            out.update(dataclasses.asdict(params))
    # the chosen trust model's own parameters (each named after its model)
    out.update((name, value) for name, value in config.trust_model_params
               if name.startswith(f'{config.trust.trust_model}_'))
    return out


def case_config(case: Case, params_file: ParamsFiles) -> RunConfig:
    """The configuration ``case`` runs with: the params file(s) with the case's alpha,
    plan estimator, driver and models set over them."""
    overrides: dict[str, dict[str, Any]] = {
        'planner': {'alpha': case.alpha, 'predictor': case.predictor}}
    driver: dict[str, Any] = dict(case.driver_params)
    if case.driver_model:
        driver['driver_model'] = case.driver_model
    if driver:
        overrides['human_driver'] = driver
    if case.trust_model:
        overrides['/**'] = {'trust_model': case.trust_model}
    return load_run_config(layers(params_file), overrides)


def run_case(case: Case, params_file: ParamsFiles,
             settings: RunSettings = RunSettings()) -> dict[str, Any]:
    """Run ``case`` (with the params file(s) layered in order over the shipped one, as
    ``settings`` say) and return its settings, metrics and the series the figures need."""
    config = case_config(case, params_file)
    trace = truncate(load_trace(case.trace, config.planner.dt_s, config.trace),
                     settings.max_steps)
    records: list[StepRecord]
    if settings.runner == 'graph':
        # Imported here: the in-process sweep never loads rclpy.
        from trust_av.graph.orchestrator import run_graph_records
        from trust_av.system.outputs import replacing_outputs
        models = ''.join(f'_{m}' for m in (case.driver_model, case.trust_model) if m)
        bag = Path(settings.bags_dir) / (f'{Path(case.trace).stem}_{case.predictor}{models}_'
                                         f'alpha{case.alpha:g}')
        # A bag and logs left by an interrupted sweep (its case is not cached) are replaced,
        # if its marker proves a trust-av command wrote them (system.outputs).
        with replacing_outputs(bag, overwrite=True, command='reproduce',
                               option='--results-dir') as outputs:
            _, records = run_graph_records(config, case.trace, trace, outputs.bag,
                                           max_steps=settings.max_steps,
                                           log_dir=outputs.logs)
    else:
        records = simulate(config, trace).records
    metrics = compute_metrics(records, config.min_safe_gap_m)
    return {
        'case': dataclasses.asdict(case),
        'settings': case_settings(case, config, settings),
        'runner': settings.runner,
        # every metric is a number (means over drivers, tables); a collision is its own entry
        'metrics': {k: v for k, v in dataclasses.asdict(metrics).items() if k != 'collision'},
        'collision': None if metrics.collision is None else metrics.collision.line(),
        'time_s': [r.t_s for r in records],
        'trust': [r.trust for r in records],
        'explicability': [r.explicability for r in records],
    }


class Executor(Protocol):
    """Runs cases somewhere and reports each result as it arrives."""

    def run(self, cases: Sequence[Case], params_file: ParamsFiles,
            on_result: Callable[[Case, dict[str, Any]], None],
            settings: RunSettings = RunSettings()) -> None:
        """Run every case (:func:`run_case`); call ``on_result`` in the calling process."""


class LocalExecutor:
    """A process pool on this machine (spawned workers, one per core by default)."""

    def __init__(self, workers: int | None = None) -> None:
        self.workers = workers or os.cpu_count() or 1

    def run(self, cases: Sequence[Case], params_file: ParamsFiles,
            on_result: Callable[[Case, dict[str, Any]], None],
            settings: RunSettings = RunSettings()) -> None:
        """Run the cases on the pool; the first failure, or a stop signal, stops the sweep
        and its workers (:func:`~.workers.worker_pool`)."""
        if not cases:
            return
        with worker_pool(min(self.workers, len(cases))) as pool:  # stops with the sweep
            futures = {pool.submit(run_case, case, params_file, settings): case for case in cases}
            for future in concurrent.futures.as_completed(futures):
                case = futures[future]
                try:
                    result = future.result()
                except Exception as err:
                    raise TrustAvAppError(f'case {case.label} failed: {err}') from err
                on_result(case, result)


RAY_CONNECT_TIMEOUT_S = 5.0
"""How long a Ray cluster's address may take to accept a TCP connection (not ray.init's)."""


def check_ray_address(address: str | None, timeout_s: float = RAY_CONNECT_TIMEOUT_S) -> None:
    """Refuse, within ``timeout_s``, a Ray cluster address nothing listens on.

    ``None``, ``auto`` and ``local`` are Ray's own choices (a local cluster, or the one in
    ``RAY_ADDRESS``) and are not probed. ``HOST:PORT`` and ``ray://HOST:PORT`` are.

    Args:
        address: ``--ray-address``.
        timeout_s: connect timeout, s.

    Raises:
        TrustAvAppError: not HOST:PORT, or nothing accepts a connection there.
    """
    if address is None or address in ('auto', 'local'):
        return
    text = address.removeprefix('ray://')
    host, _, port_text = text.rpartition(':')
    if not host or not port_text.isdigit() or not 0 < int(port_text) < 65536:
        raise TrustAvAppError(f'--ray-address {address!r}: expected HOST:PORT, '
                              'ray://HOST:PORT, auto or local')
    try:
        with socket.create_connection((host.strip('[]'), int(port_text)), timeout=timeout_s):
            pass
    except OSError as err:
        reason = err.strerror or str(err) or type(err).__name__
        raise TrustAvAppError(f'--ray-address {address}: cannot connect within '
                              f'{timeout_s:g} s ({reason})') from err


class RayExecutor:
    """The same cases as Ray tasks (``pip install ray``; local cluster unless ``address``).

    Raises:
        TrustAvAppError: ``address`` is unreachable (:func:`check_ray_address`).
    """

    def __init__(self, address: str | None = None, num_cpus: int | None = None) -> None:
        check_ray_address(address)
        self.address = address
        self.num_cpus = num_cpus

    def run(self, cases: Sequence[Case], params_file: ParamsFiles,
            on_result: Callable[[Case, dict[str, Any]], None],
            settings: RunSettings = RunSettings()) -> None:
        """Submit one Ray task per case and collect them as they finish."""
        with joined_ray('--executor ray', self.address, num_cpus=self.num_cpus) as ray:
            remote = ray.remote(run_case)
            pending = {remote.remote(case, params_file, settings): case for case in cases}
            while pending:
                done, _ = ray.wait(list(pending), num_returns=1)
                case = pending.pop(done[0])
                try:
                    result = ray.get(done[0])
                except Exception as err:
                    raise TrustAvAppError(f'case {case.label} failed: {err}') from err
                on_result(case, result)


def check_axis(name: str, values: Sequence[str] | Sequence[float]) -> None:
    """Refuse an axis of a study that asks for nothing, or for a case twice (a second row of
    the same case would weigh twice in every mean).

    Args:
        name: the axis as the user named it, e.g. ``--alphas``.
        values: its values (names compared as the trace reader does, case-blind for the
            shipped traces; numbers by value, so ``0.5`` and ``.50`` are one).

    Raises:
        TrustAvAppError: no value, or a value given twice (one line naming it).
    """
    if not values:
        raise TrustAvAppError(f'{name}: no value given (a study of no cases); give at '
                              'least one, comma-separated')
    seen: dict[object, object] = {}
    for value in values:
        key = value.lower() if isinstance(value, str) and value.lower() in TRACES else value
        if key in seen:
            shown = f'{value!r}' if value == seen[key] else f'{seen[key]!r} and {value!r}'
            raise TrustAvAppError(f'{name}: {shown} given twice (each case runs once; a '
                                  'duplicate row would weigh twice in every mean)')
        seen[key] = value


def sweep_cases(traces: Iterable[str] = TRACES, predictors: Iterable[str] = PAPER_PREDICTORS,
                alphas: Iterable[float] = ALPHAS, driver_models: Iterable[str] = ('',),
                trust_models: Iterable[str] = ('',)) -> list[Case]:
    """Every combination, in table order ('' in a model axis: the params file's); one case
    each.

    Raises:
        TrustAvAppError: an axis is empty or holds a value twice (:func:`check_axis`).
    """
    names = {'traces': list(traces), 'predictors': list(predictors),
             'driver models': list(driver_models), 'trust models': list(trust_models)}
    values = list(alphas)
    for name, axis in names.items():
        check_axis(name, axis)
    check_axis('alphas', values)
    return [Case(t, p, a, driver_model=d, trust_model=m) for t in names['traces']
            for p in names['predictors'] for m in names['trust models']
            for d in names['driver models'] for a in values]


def run_sweep(cases: Sequence[Case], params_file: ParamsFiles, results_dir: Path,
              executor: Executor,
              on_progress: Callable[[int, int], None] | None = None, *,
              runner: str = 'in-process', max_steps: int = 0) -> dict[Case, dict[str, Any]]:
    """Run the cases that are not cached, read the others back; return every result.

    A result is written to the cache as soon as it arrives, so an interrupted sweep resumes
    where it stopped. ``params_file``: one file or several, layered in order over the shipped
    one (the cache key holds every layer's text). ``runner`` and ``max_steps`` are
    :class:`RunSettings`'; graph runs record to ``<results_dir>/graph_bags/``.
    """
    settings = RunSettings(runner, max_steps, str(Path(results_dir).resolve() / 'graph_bags'))
    cache = results_dir / 'cache'
    cache.mkdir(parents=True, exist_ok=True)
    files = layers(params_file)
    params_text = (Path(files[0]).read_text() if len(files) == 1 else
                   json.dumps([Path(f).read_text() for f in files]))
    fingerprint = code_fingerprint()
    keys = {case: case_key(case, params_text, fingerprint, settings) for case in cases}
    results: dict[Case, dict[str, Any]] = {}
    for case, key in keys.items():
        path = cache / f'{key}.json'
        if path.exists():
            results[case] = json.loads(path.read_text())
    todo = [c for c in cases if c not in results]
    LOG.info('%d cases cached, %d to run', len(results), len(todo))
    if on_progress is not None:
        on_progress(len(results), len(cases))

    def store(case: Case, result: dict[str, Any]) -> None:
        output_files.write_text(cache / f'{keys[case]}.json', json.dumps(result))
        results[case] = result
        if on_progress is not None:
            on_progress(len(results), len(cases))

    executor.run(todo, files if len(files) > 1 else files[0], store, settings)
    return results
