"""``trust-av design-evaluate``, ``design-power``, ``design-propose``: can a study design tell
the registered trust models apart? Judged by simulated recovery
(:mod:`trust_av.study.trust_design`): synthetic participants of every model under the
design, every model fitted to each.

- ``design-evaluate`` prints the confusion (true model x preferred model), each row's share
  and every identifiable parameter's r, against the recovery goal (diagonal >= 0.8 on
  average and >= 0.5 in every row, r >= 0.8);
- ``design-power`` prints, for every ordered pair of models, the participants a comparison
  needs for 80 % power, with its 90 % bootstrap interval over the simulated participants;
- ``design-propose`` evaluates candidate designs within a budget of participant minutes and
  proposes the one that best separates the models by the worst pair's expected z of the
  summed held-out elpd difference (docs/tutorials/fit-trust-models.md says why).

A design comes from ``--drive-file`` (a study's ``config/drive.yaml``: its conditions, drive
length and rating period) or from ``--conditions``, ``--drive-s``, ``--rating-period-s``;
``--participants`` and ``--drives`` size it.
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import json
import math
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from trust_av.cli.options import bounded_int, positive_int, positive_seconds
from trust_av.cli.typed_options import add_command, option
from trust_av.errors import TrustAvAppError
from trust_av.study.trust_design import (
    GOAL,
    WIDE_RANGES,
    Design,
    Recovery,
    read_ranges,
    recover,
)
from trust_av.study.trust_recovery import RATING_SPAN, TRUE_RANGES
from trust_av.system.config import load_run_config
from trust_av_common.registry import names
from trust_av_planner.perturbations import LIBRARY
from trust_monitor.model_interface import TRUST_MODELS
from trust_monitor.trust_fit import model_spec

__all__: list[str] = []


def _participants(default: int) -> Any:
    """The field ``participants: int``, ``--participants`` defaulting to ``default``."""
    return option('--participants', type=bounded_int('--participants', 3, 500),
                  default=default, help=f'synthetic participants per model (default {default})')


@dataclasses.dataclass(frozen=True)
class DesignOptions:
    """The options every design command reads."""

    drive_file: Path | None = option(
        '--drive-file',
        help="a study's drive settings (config/drive.yaml): its conditions, "
             'drive length and rating period')
    conditions: str | None = option(
        '--conditions',
        help='comma-separated perturbations, cycled over the drives '
             "(default: the drive file's conditions, else rough_random)")
    drive_s: float | None = option('--drive-s', type=positive_seconds, help='drive length, s')
    rating_period_s: float | None = option(
        '--rating-period-s', type=positive_seconds,
        help='a rating at the start of each drive and this often after, s')
    drives: int | None = option(
        '--drives', type=bounded_int('--drives', 2, 20),
        help="drives per participant (default: one per drive file's condition, else 4)")
    participants: int = _participants(12)
    rating_span: str = option(
        '--rating-span', default=f'{RATING_SPAN[0]:g},{RATING_SPAN[1]:g}',
        help="low,high: the span of a linear model's ratings, rating points")
    ranges: str = option(
        '--ranges', default='benchmark',
        help="true values: 'benchmark' (TRUE_RANGES), 'wide' (WIDE_RANGES) "
             'or a JSON file {model: {parameter: [low, high]}}')
    models: str = option('--models', default='',
                         help='comma-separated registered trust models (default: all)')
    seed: int = option(
        '--seed', type=bounded_int('--seed', 0, 2 ** 31 - 1), default=0,
        help="the simulated participants' seed (default: 0); the same seed "
             'gives the same participants')
    workers: int = option('--workers', type=positive_int, default=1,
                          help='processes for the drives and fits (the result is the same)')
    out: Path | None = option('--out', help='also write the result as JSON here')
    params_files: tuple[Path, ...] = option(
        '--params-file', dest='params_files', type=Path, action='append', default=[],
        help='params file(s) of the simulated drives (repeatable)')


@dataclasses.dataclass(frozen=True)
class ProposeOptions(DesignOptions):
    """``design-propose``: the budget and the candidates (and 3 participants by default)."""

    participants: int = _participants(3)
    budget_min: float = option('--budget-min', type=positive_seconds, required=True,
                               help='participant minutes of driving in the whole study')
    periods: str = option('--periods', default='2.5,5,15',
                          help='candidate rating periods, s (comma-separated)')
    drive_lengths: str = option('--drive-lengths', default='120',
                                help='candidate drive lengths, s (comma-separated)')
    condition_sets: str = option(
        '--condition-sets', default='rough_random;mixed_random;rough_random,mixed_random',
        help='candidate condition sets (;-separated, each comma-separated)')


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add ``design-evaluate``, ``design-power`` and ``design-propose``."""
    evaluate = subparsers.add_parser(
        'design-evaluate', help='simulated recovery of the trust models under a study design',
        description='Draw synthetic participants of every registered trust model under a '
                    'study design, fit every model to each; print the confusion and every '
                    'parameter r against the recovery goal (docs/tutorials/fit-trust-models.md).')
    add_command(evaluate, DesignOptions, run_evaluate)
    power = subparsers.add_parser(
        'design-power', help='participants a model comparison needs under a study design',
        description='Simulated power of the summed held-out elpd difference to prefer the '
                    'true model, per ordered pair of models, with its bootstrap interval.')
    add_command(power, DesignOptions, run_power)
    propose = subparsers.add_parser(
        'design-propose', help='the design within a budget that best separates the models',
        description='Evaluate candidate designs (rating period x drive length x conditions, '
                    'drives filling the budget) by a small simulated recovery; propose the '
                    'one whose worst pair of models has the largest expected z of the '
                    'summed held-out elpd difference.')
    add_command(propose, ProposeOptions, run_propose)


def _numbers(option: str, text: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(',') if v.strip()]
    except ValueError as error:
        raise TrustAvAppError(f'{option}: not a list of numbers: {text!r}') from error
    if not values or not all(math.isfinite(v) and v > 0 for v in values):
        raise TrustAvAppError(f'{option}: need numbers > 0, got {text!r}')
    return values


def _conditions(option: str, text: str) -> tuple[str, ...]:
    chosen = tuple(c.strip() for c in text.split(',') if c.strip())
    unknown = [c for c in chosen if c not in LIBRARY]
    if not chosen or unknown:
        named = ', '.join(unknown) or repr(text)
        raise TrustAvAppError(f'{option}: not perturbations: {named} '
                                  f'(known: {", ".join(sorted(LIBRARY))})')
    return chosen


def design_of(args: DesignOptions) -> Design:
    """The design the options describe (drive file, then the explicit options over it).

    Raises:
        TrustAvAppError, ParamsError: a bad option or drive file (one line).
    """
    design = Design(participants=args.participants)
    if args.drive_file is not None:
        from trust_av.drive.study import load_drive_settings
        drive, _, listed = load_drive_settings(args.drive_file)
        design = dataclasses.replace(
            design, conditions=tuple(c.name for c in listed),
            drives=max(2, len(listed)), drive_s=round(drive.drive_duration_s),
            rating_period_s=drive.rating_period_s,
            planner={c.name: {'alpha': c.alpha, 'predictor': c.predictor,
                              'perturbation': c.perturbation, 'trace': c.trace}
                     for c in listed})
    if args.conditions is not None:
        design = dataclasses.replace(design, conditions=_conditions('--conditions',
                                                                    args.conditions),
                                     planner={})
    if args.drives is not None:
        design = dataclasses.replace(design, drives=args.drives)
    if args.drive_s is not None:
        design = dataclasses.replace(design, drive_s=round(args.drive_s))
    if args.rating_period_s is not None:
        design = dataclasses.replace(design, rating_period_s=args.rating_period_s)
    span = _numbers('--rating-span', args.rating_span)
    if len(span) != 2 or span[0] > span[1] or span[1] > 100:
        raise TrustAvAppError(f'--rating-span: need low,high in (0, 100], got '
                                  f'{args.rating_span!r}')
    return dataclasses.replace(design, rating_span=(span[0], span[1]),
                               true_ranges=_ranges(args.ranges, args.params_files))


def _ranges(text: str, params_files: Sequence[Path]) -> dict[str, dict[str, tuple[float, float]]]:
    """``benchmark``, ``wide`` or a JSON file's ranges, checked against the models the params
    files declare (:func:`~trust_av.study.trust_design.read_ranges`)."""
    if text == 'benchmark':
        return dict(TRUE_RANGES)
    if text == 'wide':
        return dict(WIDE_RANGES)
    path = Path(text)
    if not path.exists():
        raise TrustAvAppError(f'--ranges {text}: not benchmark, wide or a JSON file of '
                              '{model: {parameter: [low, high]}} (no such file)')
    return read_ranges(path, load_run_config(list(params_files)).trust)


def _models(option: str) -> list[str]:
    registered = list(names(TRUST_MODELS))
    chosen = list(dict.fromkeys(m.strip() for m in option.split(',') if m.strip())) \
        or registered
    unknown = [m for m in chosen if m not in registered]
    if unknown or len(chosen) < 2:
        raise TrustAvAppError(f'--models: need two or more registered models, got '
                                  f'{option!r} (registered: {", ".join(registered)})')
    return chosen


def _simulate(args: DesignOptions, design: Design) -> tuple[Recovery, list[str], float]:
    models = _models(args.models)
    config = load_run_config(args.params_files)
    print(f'design: {design.describe()}; models {", ".join(models)}', flush=True)
    start = time.perf_counter()

    def progress(done: int, total: int) -> None:
        print(f'  {done}/{total} participants fitted, {time.perf_counter() - start:.0f} s',
              flush=True)
    result = recover(config, models, design, seed=args.seed, workers=args.workers,
                     on_progress=progress)
    return result, models, time.perf_counter() - start


def _write(args: DesignOptions, payload: dict[str, Any]) -> None:
    if args.out is not None:
        from trust_av_common import output_files
        args.out.mkdir(parents=True, exist_ok=True)
        output_files.write_text(args.out / 'design.json', json.dumps(payload, indent=1) + '\n')
        print(f'{args.out / "design.json"}')


def evaluation(result: Recovery, models: Sequence[str], params_files: Sequence[Path]
               ) -> tuple[list[str], dict[str, Any]]:
    """The printed lines and the JSON of a recovery against :data:`GOAL`."""
    config = load_run_config(list(params_files))
    specs = {m: model_spec(config.trust, m) for m in models}
    confusion, diagonal = result.confusion, result.diagonal()
    r = result.parameter_r(specs)
    met = result.meets_goal(specs)
    width = max(len(m) for m in models) + 2
    lines = ['confusion (rows: true model; columns: preferred by leave-one-drive-out elpd, '
             'parsimony rule):', ' ' * width + ''.join(f'{m:>{width}s}' for m in models)
             + '   share']
    lines += [f'{t:<{width}s}' + ''.join(f'{confusion[t][m]:>{width}d}' for m in models)
              + f'   {diagonal[t]:.2f}' for t in models]
    values = list(diagonal.values())
    lines.append(f'diagonal mean {np.mean(values):.2f} (goal >= {GOAL["diagonal_mean"]:g}: '
                 f'{"met" if met["diagonal_mean"] else "NOT met"}), least row '
                 f'{min(values):.2f} (goal >= {GOAL["diagonal_min"]:g}: '
                 f'{"met" if met["diagonal_min"] else "NOT met"})')
    lines.append('parameter r (true against fitted; log scale for a log-scale parameter):')
    for m in models:
        for p, v in r[m].items():
            lines.append(f'  {m} {p}: ' + (f'{v:.2f}' + ('' if v >= GOAL['r_min'] else
                                                          '  (below the goal)')
                                           if v is not None else 'not identifiable (fixed)'))
    lines.append(f'identifiable r >= {GOAL["r_min"]:g}: {"met" if met["r_min"] else "NOT met"}'
                 f'; recovery goal {"MET" if all(met.values()) else "NOT MET"}')
    return lines, {'confusion': confusion, 'diagonal': diagonal, 'parameter_r': r,
                   'goal': GOAL, 'met': met}


def _design_json(design: Design) -> dict[str, Any]:
    return {**dataclasses.asdict(design), 'minutes_per_participant':
            design.minutes_per_participant}


def run_evaluate(args: DesignOptions) -> int:
    """Simulate, print the confusion and the r (see ``trust-av design-evaluate --help``)."""
    design = design_of(args)
    result, models, wall = _simulate(args, design)
    lines, payload = evaluation(result, models, args.params_files)
    print('\n'.join(lines))
    print(f'{design.participants} participants per model, seed {args.seed}, wall {wall:.0f} s')
    _write(args, {'design': _design_json(design), **payload, 'seed': args.seed,
                  'wall_s': wall, 'elpd_per_participant': result.elpd})
    return 0


def run_power(args: DesignOptions) -> int:
    """Simulate, print the participants each comparison needs (``design-power --help``)."""
    design = design_of(args)
    result, models, wall = _simulate(args, design)
    print(f'participants of {design.drives} drives for 80 % power to prefer the true model '
          f'(one-sided 5 %; bootstrap over the {design.participants} simulated per model; '
          f'[90 % interval over resampled simulations]; -: not reached by 96):')
    table: dict[str, dict[str, Any]] = {}
    for true in models:
        table[true] = {}
        for other in models:
            if other == true:
                continue
            needed = result.needed(true, other)
            low, high = result.needed_interval(true, other)
            table[true][other] = {'needed': needed, 'interval_90': [low, high]}
            print(f'  {true} over {other}: {needed if needed else "-"} '
                  f'[{low if low else "-"}, {high if high else "-"}]')
    print(f'seed {args.seed}, wall {wall:.0f} s')
    _write(args, {'design': _design_json(design), 'power': table, 'seed': args.seed,
                  'wall_s': wall, 'elpd_per_participant': result.elpd})
    return 0


def separation(result: Recovery, participants: int) -> tuple[float, str]:
    """The worst ordered pair's expected z of the summed held-out elpd difference (true
    model over the other) with ``participants`` participants: mean / sd of the simulated
    per-participant differences times sqrt(participants); and that pair."""
    worst, pair = math.inf, ''
    for true, rows in result.elpd.items():
        for other in rows[0]:
            if other == true:
                continue
            diff = np.array([row[true] - row[other] for row in rows])
            sd = float(np.std(diff, ddof=1)) if len(diff) > 1 else math.inf
            z = float(np.mean(diff)) / sd * math.sqrt(participants) if sd > 0 else \
                (math.inf if np.mean(diff) > 0 else -math.inf)
            if z < worst:
                worst, pair = z, f'{true} over {other}'
    return worst, pair


def run_propose(args: ProposeOptions) -> int:
    """Evaluate the candidates, propose one (``design-propose --help``)."""
    base = design_of(args)
    periods = _numbers('--periods', args.periods)
    lengths = [round(v) for v in _numbers('--drive-lengths', args.drive_lengths)]
    sets = [_conditions('--condition-sets', s) for s in args.condition_sets.split(';')
            if s.strip()]
    rows = []
    for period, length, conditions in itertools.product(periods, lengths, sets):
        drives = max(2, len(conditions))
        budget_people = int(args.budget_min // (drives * length / 60.0))
        if budget_people < 3:
            print(f'skip: {drives} drives of {length} s leave under 3 participants in '
                  f'{args.budget_min:g} min')
            continue
        design = dataclasses.replace(base, conditions=conditions, planner={}, drives=drives,
                                     drive_s=length, rating_period_s=period)
        result, _, wall = _simulate(args, design)
        z, pair = separation(result, budget_people)
        rows.append((z, design, budget_people, pair))
        print(f'  -> {budget_people} participants in the budget; worst pair {pair}: '
              f'expected z {z:.1f} ({wall:.0f} s)', flush=True)
    if not rows:
        raise TrustAvAppError(f'--budget-min {args.budget_min:g}: no candidate fits')
    z, best, people, pair = max(rows, key=lambda row: row[0])
    print(f'proposed: {dataclasses.replace(best, participants=people).describe()}; worst '
          f'pair {pair}, expected z {z:.1f} (criterion: the smallest, over ordered pairs of '
          f"models, expected z of the summed held-out elpd difference at the budget's "
          f'participants; check it with design-evaluate)')
    _write(args, {'proposed': _design_json(dataclasses.replace(best, participants=people)),
                  'criterion': 'min over ordered pairs of the expected z of the summed '
                               'held-out elpd difference',
                  'candidates': [{'design': _design_json(d), 'participants_in_budget': n,
                                  'expected_z': v, 'worst_pair': p} for v, d, n, p in rows]})
    return 0

