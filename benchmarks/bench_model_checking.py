"""Model checking on synthetic participants: is a participant whose trust follows no registered
model flagged as fitted by none, and one whose trust follows a registered model not?

Two trust models outside the zoo, written here from published equations (neither is
registered, nor a special case of a registered model):

- ``kalman`` (the linear Gaussian state-space trust of Azevedo-Sa, Jayaraman, Esterwood,
  Yang, Robert & Tilbury 2021, the model their Kalman filter estimates): per control step
  ``T[k+1] = a T[k] + (1 - a) (c0 + c1 E[k]) + w[k]``, ``w ~ N(0, q^2)``, T kept in [0, 1];
- ``lee_moray`` (the first-order autoregression of Lee & Moray 1992, trust updated once per
  rating from the period's performance): ``T[n] = phi T[n-1] + (1 - phi) (c + A1 Ebar[n])
  + A2 (Ebar[n] - Ebar[n-1]) + a[n]``, ``a ~ N(0, sigma^2)``, Ebar the mean explicability
  since the last rating.

Their participants rate ``100 T`` plus 5-point Gaussian noise (whole ratings in 0-100), on
drives of the in-process simulator (:func:`trust_av.study.trust_recovery.drive_scores`); the
in-zoo participants are drawn as the recovery benchmark draws them
(:func:`~trust_av.study.trust_recovery.make_participant`). Every registered model is fitted
to every participant and checked as ``trust-av fit-trust`` checks it
(:mod:`trust_monitor.model_check`). Prints and writes DIR/model_checking.json: the share of
out-of-zoo participants flagged as fitted by no registered model (goal >= 0.9) and the share
of in-zoo participants so flagged (goal <= 0.1), with counts and every participant's checks.

    python benchmarks/bench_model_checking.py --out DIR [--per-model 12] [--per-zoo-model 6]
        [--drives 4] [--rating-period-s 2.5] [--conditions rough_random] [--seed 0]
        [--workers 1]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from trust_av.study.trust_recovery import (
    DRIVE_S,
    RATING_NOISE,
    drive_scores,
    drive_seed,
    make_participant,
)
from trust_av.system.config import load_run_config
from trust_av_common.registry import names
from trust_monitor import model_check
from trust_monitor.model_interface import TRUST_MODELS
from trust_monitor.trust_fit import (
    RatedDrive,
    fit,
    held_out,
    model_spec,
    preferred,
)

OUT_OF_ZOO = ('kalman', 'lee_moray')


def _rate(name: str, drive: str, times: np.ndarray, scores: np.ndarray, period_s: float,
          trust_at: Callable[[np.ndarray], np.ndarray], rng: np.random.Generator,
          noise: float) -> RatedDrive:
    rating_times = np.arange(0.0, times[-1] + 1.0 + 1e-9, period_s)
    trust = trust_at(rating_times)
    ratings = np.clip(np.round(100.0 * trust + rng.normal(0.0, noise, len(trust))), 0, 100)
    return RatedDrive(name, drive, times, scores, rating_times, ratings)


def kalman_participant(name: str, drives: Sequence[tuple[str, np.ndarray, np.ndarray]],
                       rng: np.random.Generator, period_s: float,
                       noise: float = RATING_NOISE) -> tuple[dict[str, float], list[RatedDrive]]:
    """A participant whose trust is the state of a linear Gaussian system (Azevedo-Sa et al.
    2021), carried from drive to drive."""
    theta = {'a': float(rng.uniform(0.85, 0.98)), 'c0': float(rng.uniform(0.1, 0.4)),
             'c1': float(rng.uniform(0.3, 0.7)), 'q': float(rng.uniform(0.01, 0.03)),
             'T0': float(rng.uniform(0.3, 0.7))}
    trust = theta['T0']
    out = []
    for drive, times, scores in drives:
        path, start = np.empty(len(times)), trust
        for k, e in enumerate(scores):
            trust = (theta['a'] * trust + (1 - theta['a']) * (theta['c0'] + theta['c1'] * e)
                     + theta['q'] * rng.standard_normal())
            trust = min(max(trust, 0.0), 1.0)
            path[k] = trust
        ends = times + np.append(np.diff(times), np.median(np.diff(times)))

        def at(t: np.ndarray, ends: np.ndarray = ends, path: np.ndarray = path,
               start: float = start) -> np.ndarray:
            done = np.searchsorted(ends, t + 1e-9, side='right')
            return np.where(done > 0, path[np.maximum(done - 1, 0)], start)
        out.append(_rate(name, drive, times, scores, period_s, at, rng, noise))
    return theta, out


def lee_moray_participant(name: str, drives: Sequence[tuple[str, np.ndarray, np.ndarray]],
                          rng: np.random.Generator, period_s: float,
                          noise: float = RATING_NOISE
                          ) -> tuple[dict[str, float], list[RatedDrive]]:
    """A participant whose trust follows a first-order autoregression updated once per
    rating (Lee & Moray 1992), carried from drive to drive."""
    theta = {'phi': float(rng.uniform(0.5, 0.9)), 'c': float(rng.uniform(0.1, 0.4)),
             'A1': float(rng.uniform(0.3, 0.7)), 'A2': float(rng.uniform(0.0, 0.5)),
             'sigma': float(rng.uniform(0.03, 0.08)), 'T0': float(rng.uniform(0.3, 0.7))}
    trust, last = theta['T0'], 1.0
    out = []
    for drive, times, scores in drives:
        rating_times = np.arange(0.0, times[-1] + 1.0 + 1e-9, period_s)
        values = np.empty(len(rating_times))
        previous = 0.0
        for n, t in enumerate(rating_times):
            inside = (times >= previous) & (times < t) if n else np.zeros(len(times), bool)
            if inside.any():
                mean = float(np.mean(scores[inside]))
                trust = (theta['phi'] * trust
                         + (1 - theta['phi']) * (theta['c'] + theta['A1'] * mean)
                         + theta['A2'] * (mean - last) + theta['sigma'] * rng.standard_normal())
                trust, last = min(max(trust, 0.0), 1.0), mean
            values[n] = trust
            previous = float(t)
        table = dict(zip(rating_times.tolist(), values.tolist(), strict=True))
        out.append(_rate(name, drive, times, scores, period_s,
                         lambda t, table=table: np.array([table[float(x)] for x in t]),
                         rng, noise))
    return theta, out


_JOB: dict[str, Any] = {}


def _check_one(item: tuple[str, str, list[RatedDrive]]) -> dict[str, Any]:
    """Every registered model fitted to one participant, scored, checked."""
    name, true, drives = item
    specs, sizes = _JOB['specs'], _JOB['sizes']
    checks, lodo = [], {}
    for m, spec in specs.items():
        own = fit(spec, drives)
        lodo[m] = held_out(spec, [[d] for d in drives], 'leave_one_drive_out')
        checks += model_check.check_model(name, spec, own, drives, lodo[m])
    fine = [m for m, ok in model_check.adequate(checks).items() if ok]
    pick = preferred(list(lodo.values()), sizes)
    weights = model_check.stacking_weights({m: lodo[m] for m in fine}) if len(fine) >= 2 \
        else {}
    return {'participant': name, 'true': true, 'adequate': fine, 'flagged': not fine,
            'preferred': pick, 'stacking': weights,
            'misfit': model_check.misfit_text(checks) if not fine else '',
            'checks': [{'model': c.model, 'statistic': c.statistic, 'value': c.value,
                        'p_value': c.p_value} for c in checks]}


def _mapped(function: Callable[[Any], Any], items: list[Any], workers: int) -> list[Any]:
    if workers <= 1:
        return [function(item) for item in items]
    import multiprocessing
    with multiprocessing.get_context('fork').Pool(workers) as pool:
        return pool.map(function, items, chunksize=1)


def participants(config: Any, per_model: int, per_zoo_model: int, drives: int,
                 period_s: float, conditions: Sequence[str], seed: int,
                 zoo: Sequence[str], workers: int = 1
                 ) -> list[tuple[str, str, list[RatedDrive]]]:
    """The synthetic participants: ``per_model`` of each out-of-zoo model, then
    ``per_zoo_model`` of each registered model in ``zoo``."""
    rng = np.random.Generator(np.random.PCG64(seed))
    count = max(per_model * len(OUT_OF_ZOO), per_zoo_model * len(zoo))
    keys = [(conditions[j % len(conditions)], drive_seed(seed + 7, 100 * i + j))
            for i in range(count) for j in range(drives)]
    _JOB['config'] = config
    traces = _mapped(_drive, keys, workers)
    data = {i: [(f'{c}_{j + 1}', *traces[i * drives + j])
                for j, c in enumerate(conditions[j % len(conditions)] for j in range(drives))]
            for i in range(count)}
    out = []
    makers = {'kalman': kalman_participant, 'lee_moray': lee_moray_participant}
    specs = {true: model_spec(config.trust, true) for true in zoo}
    for i in range(count):      # interleaved: a run stopped early holds every kind
        for true, make in makers.items():
            if i < per_model:
                name = f'{true}_{i:02d}'
                out.append((name, true, make(name, data[i], rng, period_s)[1]))
        for true in zoo:
            if i < per_zoo_model:
                who = make_participant(specs[true], f'{true}_{i:02d}', data[i], rng,
                                       rating_period_s=period_s)
                out.append((who.name, true, list(who.drives)))
    return out


def _drive(key: tuple[str, int]) -> tuple[np.ndarray, np.ndarray]:
    return drive_scores(_JOB['config'], key[0], key[1], DRIVE_S)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--out', type=Path, required=True, help='output directory')
    parser.add_argument('--per-model', type=int, default=12,
                        help='participants per out-of-zoo model')
    parser.add_argument('--per-zoo-model', type=int, default=6,
                        help='participants per registered model')
    parser.add_argument('--drives', type=int, default=4)
    parser.add_argument('--rating-period-s', type=float, default=2.5)
    parser.add_argument('--conditions', default='rough_random',
                        help='comma-separated perturbation conditions, cycled over the drives')
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--workers', type=int, default=1)
    args = parser.parse_args(argv)
    if args.drives < 2 or args.workers < 1 or args.rating_period_s <= 0:
        print('need --drives >= 2, --workers >= 1, --rating-period-s > 0', file=sys.stderr)
        return 2
    config = load_run_config([])
    zoo = list(names(TRUST_MODELS))
    specs = {m: model_spec(config.trust, m) for m in zoo}
    _JOB.update(specs=specs, sizes={m: model_check.parameter_count(s) for m, s in specs.items()})
    start = time.perf_counter()
    people = participants(config, args.per_model, args.per_zoo_model, args.drives,
                          args.rating_period_s, args.conditions.split(','), args.seed, zoo,
                          args.workers)
    results: list[dict[str, Any]] = []
    args.out.mkdir(parents=True, exist_ok=True)
    for k in range(0, len(people), 2 * args.workers):
        for row in _mapped(_check_one, people[k:k + 2 * args.workers], args.workers):
            results.append(row)
            said = (f"FLAGGED {row['misfit']}" if row['flagged']
                    else f"fits {', '.join(row['adequate'])}")
            print(f"{row['participant']}: {said} (preferred {row['preferred']}) "
                  f'{time.perf_counter() - start:.0f} s', flush=True)
        _summarise(args, results, start, done=False)
    _summarise(args, results, start, done=True)
    return 0


def _summarise(args: argparse.Namespace, results: list[dict[str, Any]], start: float,
               done: bool) -> None:
    """The shares flagged so far, written to DIR/model_checking.json (``complete`` false
    until every participant is in); printed at the end."""
    outside = [r for r in results if r['true'] in OUT_OF_ZOO]
    inside = [r for r in results if r['true'] not in OUT_OF_ZOO]
    summary = {
        'out_of_zoo_flagged': sum(r['flagged'] for r in outside),
        'out_of_zoo_participants': len(outside),
        'out_of_zoo_flagged_share': (sum(r['flagged'] for r in outside) / len(outside)
                                     if outside else math.nan),
        'out_of_zoo_flagged_by_model': {m: sum(r['flagged'] for r in outside if r['true'] == m)
                                        for m in OUT_OF_ZOO},
        'in_zoo_flagged': sum(r['flagged'] for r in inside),
        'in_zoo_participants': len(inside),
        'in_zoo_flagged_share': (sum(r['flagged'] for r in inside) / len(inside)
                                 if inside else math.nan),
        'in_zoo_true_model_rejected': sum(r['true'] not in r['adequate'] for r in inside),
        'alpha': model_check.ALPHA, 'rating_period_s': args.rating_period_s,
        'drives': args.drives, 'conditions': args.conditions, 'seed': args.seed,
        'rating_noise_points': RATING_NOISE, 'wall_s': round(time.perf_counter() - start, 1),
        'complete': done}
    (args.out / 'model_checking.json').write_text(
        json.dumps({**summary, 'participants': results}, indent=1) + '\n')
    if done:
        print(json.dumps(summary, indent=1))


if __name__ == '__main__':
    sys.exit(main())
