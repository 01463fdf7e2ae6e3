"""Study designs for telling trust models apart, judged by simulated recovery.

A :class:`Design` is what a researcher chooses (the drives' conditions, their length, the
rating period, participants x drives) and what the simulation assumes about people (rating
noise, the span of their ratings, the ranges of their true parameters). :func:`recover`
draws synthetic participants of every registered model under a design
(:mod:`trust_av.study.trust_recovery`), fits every model to each and returns the
:class:`Recovery`: the confusion of the preferred models, the true and fitted parameters,
every model's held-out elpd. ``trust-av design-evaluate``, ``design-power`` and
``design-propose`` print it (docs/tutorials/fit-trust-models.md); the recovery benchmark
(benchmarks/bench_trust_recovery.py) runs it at full size.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from trust_av.errors import TrustAvAppError
from trust_av.study.trust_recovery import (
    CONDITIONS,
    DRIVE_S,
    DRIVES_PER_SEED,
    RATING_NOISE,
    RATING_PERIOD_S,
    RATING_SPAN,
    TRUE_RANGES,
    Ranges,
    drive_scores,
    drive_seed,
    make_participant,
)
from trust_av.study.workers import call_runner
from trust_av.system.config import RunConfig
from trust_av_common.errors import with_suggestions
from trust_av_common.input_files import not_regular
from trust_av_common.registry import names
from trust_monitor.model_check import parameter_count
from trust_monitor.model_interface import TRUST_MODELS
from trust_monitor.paper_trust import TrustConfig
from trust_monitor.trust_fit import (
    ModelSpec,
    Score,
    fit,
    held_out,
    model_spec,
    preferred,
)

__all__ = ['GOAL', 'MAX_RANGES_BYTES', 'POWER_SIZES', 'WIDE_RANGES', 'Design', 'Recovery',
           'read_ranges', 'recover']

POWER_SIZES = (2, 3, 4, 6, 8, 12, 16, 24, 32, 48, 64, 96)
"""Participant counts the power analysis tries."""
GOAL = {'diagonal_mean': 0.8, 'diagonal_min': 0.5, 'r_min': 0.8}
"""The recovery goal a design should meet: confusion diagonal >= 0.8 on average and >= 0.5
in every row, every identifiable parameter r >= 0.8."""
WIDE_RANGES: Ranges = {
    'paper': {'performance_threshold': (0.6, 0.98), 'trust_growth_rate': (0.01, 1.0)},
    'asymmetric': {'performance_threshold': (0.6, 0.98),
                   'asymmetric_loss_ratio': (1.0, 10.0)},
    'optimo': {'optimo_performance_rate_per_s': (0.002, 0.05),
               'optimo_initial_trust': (0.1, 0.9)},
}
"""True-value ranges wider than :data:`~trust_av.study.trust_recovery.TRUE_RANGES`,
covering the published estimates: the paper's P_thre (0.8) and δ (0.1 /s), a loss ratio of
1-10 (the loss-aversion ratio of about 2 of Kahneman & Tversky and the 2-10 of trust studies'
negativity bias), OPTIMo rates from slow to saturating within a drive."""


MAX_RANGES_BYTES = 1024 * 1024
"""Largest ranges file read, bytes (a few hundred bytes per model)."""


def read_ranges(path: Path, trust: TrustConfig) -> Ranges:
    """True-value ranges from a JSON file ``{model: {parameter: [low, high]}}``, checked as
    the draw needs them: registered models, parameters each model fits (not one it holds
    fixed), two finite numbers low < high inside the parameter's bounds (a range past them
    draws people the fit can never recover).

    Raises:
        TrustAvAppError: one line naming the file and the model, parameter or value.
    """
    kind = not_regular(path)
    if kind is not None:
        raise TrustAvAppError(f'{path}: not a regular file ({kind}; expected a JSON file)')
    try:
        with path.open('rb') as handle:
            text = handle.read(MAX_RANGES_BYTES + 1)
    except OSError as err:
        raise TrustAvAppError(f'{path}: cannot read ({err.strerror})') from err
    if len(text) > MAX_RANGES_BYTES:
        raise TrustAvAppError(f'{path}: larger than the {MAX_RANGES_BYTES // 1024} KiB a '
                              'ranges file may be')

    def no_constant(name: str) -> None:
        raise ValueError(f'{name} is not a number JSON allows')

    try:
        raw = json.loads(text.decode('utf-8-sig'), parse_constant=no_constant)
    except (UnicodeDecodeError, ValueError) as err:
        raise TrustAvAppError(f'{path}: not JSON ({err})') from err
    if not isinstance(raw, dict) or not raw:
        raise TrustAvAppError(f'{path}: expected {{model: {{parameter: [low, high]}}}}, got '
                              f'{type(raw).__name__ if raw else "nothing"}')
    registered = list(names(TRUST_MODELS))
    unknown = [model for model in raw if model not in registered]
    if unknown:
        raise TrustAvAppError(f'{path}: not registered trust models: '
                              f'{with_suggestions(unknown, registered)} (registered: '
                              f'{", ".join(registered)})')
    out: Ranges = {}
    for model, row in raw.items():
        fitted = {p.name: p for p in model_spec(trust, model).parameters}
        if not isinstance(row, dict):
            raise TrustAvAppError(f'{path}: {model}: expected {{parameter: [low, high]}}, '
                                  f'got {type(row).__name__}')
        others = [name for name in row if name not in fitted]
        if others:
            raise TrustAvAppError(f'{path}: {model}: not a parameter {model} fits: '
                                  f'{with_suggestions(others, fitted)} (fitted: '
                                  f'{", ".join(fitted)})')
        out[model] = {}
        for name, value in row.items():
            where, bounds = f'{path}: {model}.{name}', fitted[name]
            if not (isinstance(value, list) and len(value) == 2
                    and all(isinstance(v, (int, float)) and not isinstance(v, bool)
                            for v in value)):
                raise TrustAvAppError(f'{where}: expected [low, high], two numbers, got '
                                      f'{json.dumps(value)[:60]}')
            low, high = float(value[0]), float(value[1])
            if not low < high:
                raise TrustAvAppError(f'{where}: [{low:g}, {high:g}]: low must be below high')
            if low < bounds.low or high > bounds.high:
                raise TrustAvAppError(f'{where}: [{low:g}, {high:g}] reaches past the '
                                      f"parameter's bounds [{bounds.low:g}, {bounds.high:g}]")
            out[model][name] = (low, high)
    return out


@dataclass(frozen=True)
class Design:
    """A study design and what the simulation assumes of its participants.

    Attributes:
        conditions: each drive's perturbation (cycled over the drives; ``*_random`` ones
            drawn anew per drive).
        drives: drives per participant.
        drive_s: a drive's length, s (control steps of 1 s).
        rating_period_s: a rating at the start of each drive and this often after.
        participants: participants per true model.
        rating_noise: the rating noise's standard deviation, rating points.
        rating_span: a ``linear`` model's trust range maps to a span drawn from this,
            rating points.
        true_ranges: where true parameter values are drawn (others: the declared prior).
        planner: per condition name, the settings it sets (``alpha``, ``predictor``,
            ``perturbation``, ``trace``: a drive file's conditions); a name not listed
            is a perturbation under the run configuration's settings.
    """

    conditions: tuple[str, ...] = CONDITIONS
    drives: int = 4
    drive_s: int = DRIVE_S
    rating_period_s: float = RATING_PERIOD_S
    participants: int = 24
    rating_noise: float = RATING_NOISE
    rating_span: tuple[float, float] = RATING_SPAN
    true_ranges: Ranges = field(default_factory=lambda: dict(TRUE_RANGES))
    planner: dict[str, dict[str, Any]] = field(default_factory=dict)

    def perturbation(self, condition: str) -> str:
        """The perturbation of ``condition``."""
        return str(self.planner.get(condition, {}).get('perturbation', condition))

    def randomised(self, condition: str) -> bool:
        """Whether ``condition`` draws its events anew per drive."""
        return self.perturbation(condition).endswith('_random')

    @property
    def minutes_per_participant(self) -> float:
        """Driving time per participant, min."""
        return self.drives * self.drive_s / 60.0

    def drive_conditions(self) -> list[str]:
        """Each drive's condition, in order."""
        return [self.conditions[j % len(self.conditions)] for j in range(self.drives)]

    def describe(self) -> str:
        """One line naming the design."""
        return (f'{self.participants} participants x {self.drives} drives of '
                f'{self.drive_s} s ({", ".join(self.drive_conditions())}), a rating every '
                f'{self.rating_period_s:g} s, noise {self.rating_noise:g} points, span '
                f'{self.rating_span[0]:g}-{self.rating_span[1]:g}')


@dataclass
class Recovery:
    """What :func:`recover` measured."""

    participants: int
    drives_per_participant: int
    true_and_fitted: dict[str, dict[str, list[tuple[float, float]]]]
    elpd: dict[str, list[dict[str, float]]]
    """Per true model, per participant: every model's leave-one-drive-out elpd."""
    chosen: dict[str, list[str]]
    """Per true model, per participant: the preferred model
    (:func:`~trust_monitor.trust_fit.preferred`)."""

    @property
    def confusion(self) -> dict[str, dict[str, int]]:
        """{true model: {preferred model: participants}}."""
        out = {true: dict.fromkeys(self.elpd, 0) for true in self.elpd}
        for true, picks in self.chosen.items():
            for pick in picks:
                out[true][pick] += 1
        return out

    @property
    def confusion_best(self) -> dict[str, dict[str, int]]:
        """{true model: {model of the highest held-out elpd: participants}} (no
        parsimony rule)."""
        out = {true: dict.fromkeys(self.elpd, 0) for true in self.elpd}
        for true, rows in self.elpd.items():
            for row in rows:
                out[true][max(row, key=lambda m: row[m])] += 1
        return out

    def diagonal(self) -> dict[str, float]:
        """Per true model, the share preferred correctly."""
        return {m: row[m] / max(sum(row.values()), 1) for m, row in self.confusion.items()}

    def power(self, true: str, other: str, participants: int, draws: int = 2000,
              seed: int = 0, rows: Sequence[int] | None = None) -> float:
        """Simulated power to prefer ``true`` over ``other`` with ``participants``
        participants generated by ``true``: the fraction of bootstrap samples (participants
        resampled from the recovery's, or from ``rows`` of them) whose summed elpd
        difference is positive by more than 1.645 standard errors (one-sided, 5 %)."""
        diff = np.array([row[true] - row[other] for row in self.elpd[true]])
        if rows is not None:
            diff = diff[np.asarray(rows)]
        rng = np.random.Generator(np.random.PCG64(seed))
        sample = diff[rng.integers(0, len(diff), (draws, participants))]
        mean = sample.mean(axis=1)
        se = sample.std(axis=1, ddof=1) / math.sqrt(participants) if participants > 1 \
            else np.full(draws, np.inf)
        with np.errstate(divide='ignore', invalid='ignore'):
            return float(np.mean(mean > 1.645 * se))

    def needed(self, true: str, other: str, target: float = 0.8,
               rows: Sequence[int] | None = None, draws: int = 2000) -> int | None:
        """The fewest of :data:`POWER_SIZES` participants reaching ``target`` power (None:
        not reached by the largest)."""
        return next((n for n in POWER_SIZES
                     if self.power(true, other, n, draws, rows=rows) >= target), None)

    def needed_interval(self, true: str, other: str, target: float = 0.8,
                        outer: int = 100, seed: int = 1) -> tuple[int | None, int | None]:
        """The uncertainty of :meth:`needed`: its 5th and 95th percentile over ``outer``
        bootstrap resamples of the simulated participants (None: beyond the largest size
        tried)."""
        rng = np.random.Generator(np.random.PCG64(seed))
        count = len(self.elpd[true])
        big = POWER_SIZES[-1] * 2
        values = sorted((self.needed(true, other, target,
                                     rng.integers(0, count, count).tolist(),
                                     draws=400) or big) for _ in range(outer))
        low, high = values[int(0.05 * (outer - 1))], values[math.ceil(0.95 * (outer - 1))]
        return (low if low < big else None), (high if high < big else None)

    def parameter_r(self, specs: dict[str, ModelSpec]) -> dict[str, dict[str, float | None]]:
        """Correlation of true and fitted values per model and parameter, of their logs
        for a ``log_scale`` parameter (the scale it is declared and searched on; None for a
        parameter its model declares not identifiable, or when either side is constant)."""
        out: dict[str, dict[str, float | None]] = {}
        for name, pairs in self.true_and_fitted.items():
            row: dict[str, float | None] = {}
            logs = {p.name for p in specs[name].parameters if p.log_scale}
            for param, values in pairs.items():
                arr = np.log(np.array(values)) if param in logs else np.array(values)
                ok = len(arr) > 2 and np.std(arr[:, 0]) > 0 and np.std(arr[:, 1]) > 0
                row[param] = float(np.corrcoef(arr[:, 0], arr[:, 1])[0, 1]) if ok else None
            for fixed in specs[name].fixed:
                row[fixed.name] = None
            out[name] = row
        return out

    def meets_goal(self, specs: dict[str, ModelSpec]) -> dict[str, bool]:
        """Each part of :data:`GOAL`: met or not."""
        diagonal = list(self.diagonal().values())
        rs = [v for row in self.parameter_r(specs).values() for v in row.values()
              if v is not None]
        return {'diagonal_mean': float(np.mean(diagonal)) >= GOAL['diagonal_mean'],
                'diagonal_min': min(diagonal) >= GOAL['diagonal_min'],
                'r_min': bool(rs) and min(rs) >= GOAL['r_min']}


def _scores_of(config: RunConfig, seed: int, design: Design,
               key: tuple[str, int]) -> tuple[np.ndarray, np.ndarray]:
    """One condition's drive under ``design`` (the simulated AV's scores)."""
    settings = {k: v for k, v in design.planner.get(key[0], {}).items()
                if k in ('alpha', 'predictor')}
    if settings:
        config = dataclasses.replace(config, planner=dataclasses.replace(
            config.planner, **settings))
    trace = design.planner.get(key[0], {}).get('trace')
    if trace:
        config = dataclasses.replace(config, trace=dataclasses.replace(config.trace,
                                                                       trace=trace))
    return drive_scores(config, design.perturbation(key[0]), drive_seed(seed, key[1]),
                        design.drive_s)


def _score_one(specs: dict[str, Any], sizes: dict[str, int], fit_seed: int,
               who: Any) -> tuple[dict[str, float], dict[str, float], str]:
    """One participant: its true model's fit, every model's leave-one-drive-out elpd, the
    preferred model."""
    fitted = fit(specs[who.model], who.drives, fit_seed)
    held: list[Score] = [held_out(specs[m], [[d] for d in who.drives], 'leave_one_drive_out',
                                  fit_seed) for m in specs]
    return fitted.theta, {s.model: s.elpd for s in held}, preferred(held, sizes)


def recover(config: RunConfig, models: Sequence[str], design: Design, seed: int = 0,
            values: dict[str, Any] | None = None,
            on_progress: Callable[[int, int], None] | None = None,
            workers: int = 1) -> Recovery:
    """For each true model in ``models``: ``design.participants`` synthetic participants
    drawn under ``design``, every model fitted to each (parameters: full fit; preferred
    model: leave-one-drive-out elpd with :func:`~trust_monitor.trust_fit.preferred`'s
    parsimony rule, every fitted parameter counted); drives and fits in ``workers``
    processes of the study's worker pool (:func:`~trust_av.study.workers.call_runner`;
    the result does not depend on it); ``on_progress(done, total)`` after each participant
    is fitted.

    Raises:
        FitError: fewer than two drives (no held-out drive).
    """
    rng = np.random.Generator(np.random.PCG64(seed))
    specs = {m: model_spec(config.trust, m, values) for m in models}
    fit_seed = seed + 1   # not the participants' stream: a start must not be the truth
    sizes = {m: parameter_count(specs[m]) for m in models}
    names = design.drive_conditions()
    keys = list(dict.fromkeys(
        (c, DRIVES_PER_SEED * i + j if design.randomised(c) else 0)
        for i in range(design.participants) for j, c in enumerate(names)))
    with call_runner(workers) as run_calls:   # the study's worker pool (workers.py)
        cache = run_calls({key: (_scores_of, (config, seed, design, key)) for key in keys},
                          None)
        people = []
        for true in models:   # drawn in order from one stream: the same for any `workers`
            for i in range(design.participants):
                data = [(f'{c}_{j + 1}', *cache[(c, DRIVES_PER_SEED * i + j
                                                 if design.randomised(c) else 0)])
                        for j, c in enumerate(names)]
                people.append(make_participant(
                    specs[true], f'{true}_{i:02d}', data, rng, design.rating_noise,
                    design.rating_period_s, design.rating_span, design.true_ranges))
        results = run_calls({k: (_score_one, (specs, sizes, fit_seed, who))
                             for k, who in enumerate(people)}, on_progress)
    pairs: dict[str, dict[str, list[tuple[float, float]]]] = {
        m: {p.name: [] for p in specs[m].parameters} for m in models}
    elpd: dict[str, list[dict[str, float]]] = {m: [] for m in models}
    chosen: dict[str, list[str]] = {m: [] for m in models}
    for k, who in enumerate(people):
        theta, scores, pick = results[k]
        for p in specs[who.model].parameters:
            pairs[who.model][p.name].append((who.theta[p.name], theta[p.name]))
        elpd[who.model].append(scores)
        chosen[who.model].append(pick)
    return Recovery(design.participants, design.drives, pairs, elpd, chosen)
