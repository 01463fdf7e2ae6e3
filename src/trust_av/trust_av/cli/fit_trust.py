"""``trust-av fit-trust``: fit every registered trust model to a study's trust ratings.

Per participant and pooled over participants, through an explicit observation model
(:mod:`trust_monitor.trust_fit`); scored on held-out ratings (leave one drive
out per participant, leave one participant out pooled: beyond eight participants one of
eight folds of participants, :mod:`trust_av.drive.trust_fit_pooling`). The fits are
independent calls, run on ``--workers`` processes (or Ray tasks with ``--ray-address``;
:func:`trust_av.study.workers.call_runner`), with a progress bar on stderr; the results do
not depend on where they ran. Writes to ``--out``:

- ``fits.csv``: scope (a participant or ``pooled``), model, parameter, value, kind
  (``fitted``, ``fixed``: declared but not identifiable, ``observation``: a, b, s);
- ``scores.csv``: scope, model, scheme, ratings, elpd, elpd_se, rmse, rmse_se;
- ``comparison.csv``: the same per scope and scheme, best first, with elpd_diff (to the
  best) and elpd_diff_se, and ``preferred`` (1 for the model the scope and scheme prefer by
  :func:`~trust_monitor.trust_fit.preferred`'s parsimony rule, named in ``rule``: the rule the
  recovery benchmark's confusion matrix uses; the printed summary names it too), with
  every fitted parameter counted (:func:`~trust_monitor.model_check.parameter_count`: the
  model's and its observation's a, b, s), ``evidence`` (``not enough data`` below
  :data:`MIN_RATINGS_TO_PREFER` held-out ratings: then nothing is preferred; ``clear``: the
  preferred model is the best and beats every other by more than :data:`CLEAR_SE` standard
  errors and :data:`CLEAR_NATS` nats; else ``weak``) and ``stacking_weight`` (participants:
  the stacking weights of the models the checks find adequate, when two or more are;
  :func:`~trust_monitor.model_check.stacking_weights`);
- ``adequacy.csv``: participant, model, statistic, value, p_value, adequate (true/false),
  ratings: the absolute checks of :mod:`trust_monitor.model_check` (does the model describe
  the participant's ratings at all? the summary names a participant no model fits);
- ``partial_pooling.csv`` (two or more participants): scope (a participant, or
  ``population``), model, parameter, value, kind (``fitted``, ``observation``; for the
  population ``center``: the pooled value, ``spread``: the between-participant standard
  deviation in prior standard deviations): each participant's fit shrunk toward the pooled
  one (:mod:`trust_av.drive.trust_fit_pooling`); its held-out scores (three or more
  participants) are the scheme ``leave_one_drive_out_partial_pooling`` of the two tables;
- ``participant_<id>.png``: each drive's ratings and every model's fitted prediction (own
  fit solid, partially pooled dashed).

The files are written as one set (:func:`~trust_av.system.output_sets.writing_set`): all of
them or, when the run fails or is stopped, the previous set as it was; ``--out`` must be new,
empty or a set an earlier run wrote (its marker names every file), never a symbolic link.
"""

from __future__ import annotations

import argparse
import collections
import csv
import dataclasses
import io
import math
import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from trust_av.cli.options import Progress, positive_int
from trust_av.cli.typed_options import Exclusive, add_command, option
from trust_av.drive.table_input import RatingScale, file_safe
from trust_av.drive.trust_fit_data import read_ratings_table, read_study
from trust_av.drive.trust_fit_pooling import (
    MIN_PARTICIPANTS,
    PARTICIPANT_FOLDS,
    SCHEME,
    Population,
    fold_prior,
    participant_folds,
    population,
    shrunk,
)
from trust_av.errors import TrustAvAppError
from trust_av.study.sweep import check_ray_address
from trust_av.study.workers import call_runner
from trust_av.system.config import load_run_config
from trust_av.system.output_sets import check_set_folder, writing_set
from trust_av_common import output_files
from trust_av_common.registry import names
from trust_monitor import model_check
from trust_monitor.model_interface import TRUST_MODELS
from trust_monitor.trust_fit import (
    PARSIMONY_SE,
    Fit,
    FitError,
    ModelSpec,
    RatedDrive,
    Score,
    by_participant,
    compare,
    fit,
    held_out,
    model_spec,
    model_trust,
    predict,
    preferred,
)

__all__: list[str] = []

LODO, LOPO = 'leave_one_drive_out', 'leave_one_participant_out'
LOPFO = 'leave_one_participant_fold_out'
"""The pooled held-out scheme beyond :data:`~trust_av.drive.trust_fit_pooling.PARTICIPANT_FOLDS`
participants (each fold of participants predicted from the pooled fit to the others)."""
SCORE_FIELDS = ('scope', 'model', 'scheme', 'ratings', 'elpd', 'elpd_se', 'elpd_diff',
                'elpd_diff_se', 'rmse', 'rmse_se', 'preferred', 'rule', 'parameters',
                'evidence', 'stacking_weight')
ADEQUACY_FIELDS = ('participant', 'model', 'statistic', 'value', 'p_value', 'adequate',
                   'ratings')
MIN_RATINGS_TO_PREFER = 50
"""Below this many held-out ratings a scope's preference is ``not enough data``: the
standard error of an elpd difference is itself a poor estimate from few ratings, and one
badly predicted rating can carry the whole difference (Sivula, Magnusson & Vehtari 2020);
fewer than 50 ratings is a convention, not a derived bound."""
CLEAR_SE, CLEAR_NATS = 2.0, 4.0
"""A ``clear`` preference: every other model's elpd is more than 2 standard errors of
the paired difference and more than 4 nats below the preferred one's (a difference under 4
nats is small whatever its standard error: Sivula et al. 2020)."""
RULE = f'parsimony_{PARSIMONY_SE:g}se'
"""The ``rule`` column: :func:`~trust_monitor.trust_fit.preferred` (the simplest model within
``PARSIMONY_SE`` standard errors of the paired elpd difference to the best)."""
RULE_TEXT = (f"parsimony rule: the model with the fewest fitted parameters (the model's and "
             f"the observation's a, b, s) whose held-out elpd is within {PARSIMONY_SE:g} SE "
             f'of the paired difference to the best; none below {MIN_RATINGS_TO_PREFER} '
             f'held-out ratings')


_SOURCE = Exclusive('study or ratings', required=True)


@dataclasses.dataclass(frozen=True)
class FitTrustOptions:
    """``trust-av fit-trust``'s options (``--study`` or ``--ratings``, one of them)."""

    study: Path | None = option('--study', exclusive=_SOURCE,
                                help='a study directory of trust-av drive')
    ratings: Path | None = option(
        '--ratings', exclusive=_SOURCE,
        help='a tidy ratings table (CSV: participant, drive, t_s, explicability, rating)')
    out: Path = option('--out', required=True, help='output directory')
    models: str = option('--models', default='',
                         help='comma-separated registered trust models (default: all)')
    rating_scale: str = option(
        '--rating-scale', default='0-100', metavar='LOW-HIGH',
        help="the --ratings table's rating scale where it has no rating_scale "
             'column (default 0-100; e.g. 0-1, 1-7): ratings outside it, or '
             'all in its bottom tenth, are refused')
    params_files: tuple[Path, ...] = option(
        '--params-file', dest='params_files', type=Path, action='append', default=[],
        help="params file(s) for eps and the models' configured values (repeatable)")
    no_figures: bool = option('--no-figures', help='tables only')
    no_partial_pooling: bool = option(
        '--no-partial-pooling',
        help='skip the partially pooled fits (each participant shrunk toward '
             'the pooled fit by a fitted spread; about doubles the time)')
    workers: int | None = option(
        '--workers', type=positive_int, default=None,
        help='processes for the fits, 1..256 (default: one per core; the '
             'results do not depend on it)')
    ray_address: str | None = option(
        '--ray-address', default=None,
        help='run the fits as Ray tasks on this cluster (HOST:PORT, auto or '
             'local; pip install ray) instead of local processes')

    def __post_init__(self) -> None:
        if (self.study is None) == (self.ratings is None):
            raise TypeError('fit-trust: the parser gives --study or --ratings, one of them')

    @property
    def ratings_table(self) -> Path:
        """``--ratings`` (given when ``--study`` is not)."""
        if self.ratings is None:
            raise TypeError('fit-trust: no --ratings')
        return self.ratings


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add the ``fit-trust`` subcommand."""
    parser = subparsers.add_parser(
        'fit-trust', help="fit the trust models to a study's trust ratings and compare them",
        description=(
            "Fit every registered trust model's declared parameters and a rating "
            'observation model to the trust ratings of each participant and of all '
            'participants pooled; score each model on held-out ratings (leave one drive out, '
            'leave one participant out: log predictive density and RMSE with standard errors); '
            'write tables and a figure per participant (docs/tutorials/fit-trust-models.md).'))
    add_command(parser, FitTrustOptions, run)


def _models(option: str) -> list[str]:
    registered = list(names(TRUST_MODELS))
    chosen = [m.strip() for m in option.split(',') if m.strip()] or registered
    unknown = [m for m in chosen if m not in registered]
    twice = sorted({m for m in chosen if chosen.count(m) > 1})
    if twice:
        raise TrustAvAppError(f'--models: {", ".join(twice)} given twice (a model is not '
                                  'compared with itself)')
    if unknown:
        raise TrustAvAppError(f'--models: not registered: {", ".join(unknown)} '
                              f'(registered: {", ".join(registered)})')
    return chosen


def _evidence(rows: Sequence[dict[str, Any]], chosen: str) -> str:
    """How much the held-out ratings carry the preference for ``chosen`` (see
    :data:`MIN_RATINGS_TO_PREFER`, :data:`CLEAR_SE`)."""
    if rows[0]['ratings'] < MIN_RATINGS_TO_PREFER:
        return 'not enough data'
    if rows[0]['model'] != chosen:
        return 'weak'
    others = rows[1:]
    return 'clear' if all(-r['elpd_diff'] > max(CLEAR_NATS, CLEAR_SE * r['elpd_diff_se'])
                          for r in others) else 'weak'


def _rows(scope: str, scores: Sequence[Score], sizes: dict[str, int]) -> list[dict[str, Any]]:
    """The comparison rows of one scope and scheme, the preferred model marked (none when
    the ratings are too few to prefer one)."""
    chosen = preferred(scores, sizes)
    rows = compare(scores)
    evidence = _evidence(rows, chosen)
    if evidence == 'not enough data':
        chosen = ''
    return [{'scope': scope, **row, 'preferred': int(row['model'] == chosen), 'rule': RULE,
             'parameters': sizes[row['model']], 'evidence': evidence, 'stacking_weight': ''}
            for row in rows]


def _print_preferred(rows: Sequence[dict[str, Any]]) -> None:
    """Per scheme, the preferred model of each scope (the pooled one by name, the
    participants' as counts), and the rule."""
    chosen = [r for r in rows if r['preferred']]
    for scheme in dict.fromkeys(r['scheme'] for r in rows):
        picks = [r for r in chosen if r['scheme'] == scheme]
        pooled = [r['model'] for r in picks if r['scope'] == 'pooled']
        counts = collections.Counter(r['model'] for r in picks if r['scope'] != 'pooled')
        said = pooled[0] if pooled else ', '.join(
            f'{m} ({n} participant{"s" if n > 1 else ""})'
            for m, n in counts.most_common()) or 'none'
        print(f'preferred {scheme}: {said}')
        unsure = sorted({r['scope'] for r in rows if r['scheme'] == scheme
                         and r['evidence'] == 'not enough data'})
        if unsure:
            print(f'  not enough data to prefer (under {MIN_RATINGS_TO_PREFER} held-out '
                  f'ratings): {", ".join(unsure)}')
    if rows:
        sizes = dict.fromkeys(sorted({(r['model'], r['parameters']) for r in rows}))
        print(f'  ({RULE_TEXT}; parameters counted: '
              f'{", ".join(f"{m} {n}" for m, n in sizes)}; comparison.csv: preferred = 1)')


def _print_adequacy(checks: dict[str, list[model_check.Check]],
                    rows: Sequence[dict[str, Any]]) -> None:
    """Per participant: which models the checks find adequate (with the stacking weights
    when two or more are), or plainly that none is."""
    none = []
    for who, found in checks.items():
        fine = [m for m, ok in model_check.adequate(found).items() if ok]
        if not fine:
            none.append(who)
            print(f'none of the registered models fits {who}: '
                  f'{model_check.misfit_text(found)}')
            continue
        weights = {r['model']: r['stacking_weight'] for r in rows
                   if r['scope'] == who and r['scheme'] == LODO and r['stacking_weight'] != ''}
        said = ', '.join(f'{m} {weights[m]:.2f}' if m in weights else m for m in fine)
        print(f'{who}: fitted adequately by {said}'
              f'{" (stacking weights)" if weights else ""}')
    print(f'model checks (adequacy.csv): {len(checks) - len(none)} of {len(checks)} '
          f'participant(s) fitted adequately by a registered model; a model is rejected when '
          f'a check has p < {model_check.ALPHA:g} (residual lag-1 autocorrelation, held-out '
          f'{100 * model_check.INTERVAL:.0f} % interval coverage)')


def _fit_rows(scope: str, fitted: Fit) -> list[dict[str, Any]]:
    rows = [{'scope': scope, 'model': fitted.model, 'parameter': k, 'value': v,
             'kind': 'fitted'} for k, v in fitted.theta.items()]
    rows += [{'scope': scope, 'model': fitted.model, 'parameter': k, 'value': v,
              'kind': 'fixed'} for k, v in fitted.fixed.items()]
    obs = fitted.observation
    rows += [{'scope': scope, 'model': fitted.model, 'parameter': k, 'value': v,
              'kind': 'observation'} for k, v in (('a', obs.a), ('b', obs.b), ('s', obs.s))]
    return rows


def _csv(fields: Sequence[str], rows: Sequence[dict[str, Any]]) -> str:
    out = io.StringIO()
    writer = csv.DictWriter(out, list(fields), extrasaction='ignore', lineterminator='\n')
    writer.writeheader()
    for row in rows:
        writer.writerow({k: (f'{v:.6g}' if isinstance(v, float) else v)
                         for k, v in row.items()})
    return out.getvalue()


def figure(path: Path, participant: str, drives: Sequence[RatedDrive],
           fits: dict[str, tuple[ModelSpec, Fit]],
           partial: dict[str, Fit] | None = None) -> None:
    """Each drive's ratings and every fitted model's predicted rating over time (solid);
    dashed in the same colour, its partially pooled fit when ``partial`` has one."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(drives), 1, figsize=(8.0, 2.4 * len(drives)),
                             squeeze=False, sharey=True)
    for ax, drive in zip(axes[:, 0], drives, strict=True):
        ax.scatter(drive.rating_times_s, drive.ratings, color='black', s=14, zorder=3,
                   label='ratings')
        t = np.asarray(drive.times_s)
        ends = t + np.append(np.diff(t), np.median(np.diff(t)))
        for name, (spec, fitted) in fits.items():
            trust = model_trust(spec.build(fitted.theta), drive, every_step=True)[0]
            line = ax.plot(ends, 100.0 * fitted.observation.mean(trust), lw=1.2, label=name)
            shrunk = (partial or {}).get(name)
            if shrunk is not None:
                trust = model_trust(spec.build(shrunk.theta), drive, every_step=True)[0]
                ax.plot(ends, 100.0 * shrunk.observation.mean(trust), lw=1.0, linestyle='--',
                        color=line[0].get_color(), label=f'{name} (partial pooling)')
        ax.set_title(f'{participant}: {drive.drive}', fontsize=9)
        ax.set_ylabel('rating (0-100)', fontsize=8)
        ax.set_ylim(-2, 102)
    axes[-1, 0].set_xlabel('time in the drive (s)', fontsize=8)
    axes[0, 0].legend(fontsize=7, ncol=3, loc='lower right')
    fig.tight_layout()
    with output_files.replacing(path) as (temporary,):
        fig.savefig(temporary, dpi=100, format='png')
    plt.close(fig)


def _fit_all(args: FitTrustOptions, specs: dict[str, ModelSpec], rated: Sequence[RatedDrive],
             people: dict[str, list[RatedDrive]]
             ) -> tuple[dict[str, dict[str, Fit]], dict[str, Fit],
                        dict[str, tuple[Population, dict[str, Fit]]],
                        dict[tuple[str, str, str], Score]]:
    """Every fit and held-out score, as independent calls on ``--workers`` processes (or
    Ray): own fits and leave-one-drive-out scores, the pooled fit and the pooled fits outside
    each fold of participants (:func:`~trust_av.drive.trust_fit_pooling.participant_folds`),
    then the partially pooled fits and their held-out scores.

    Returns:
        own fits (model -> participant -> fit), pooled fits (model -> fit), partial pooling
        (model -> (population, participant -> fit); empty without it), scores by (scheme,
        participant or ``pooled``, model).
    """
    models = list(specs)
    folds = participant_folds(list(people)) if len(people) >= 2 else []
    outside = [[d for who, own in people.items() if who not in fold for d in own]
               for fold in folds]
    calls: dict[tuple[str, ...], tuple[Callable[..., Any], tuple[Any, ...]]] = {}
    for m in models:   # the largest first: the pool finishes together
        calls['pooled', m] = (fit, (specs[m], rated))
        for k, drives in enumerate(outside):
            calls['fold', str(k), m] = (fit, (specs[m], drives))
    for who, own in people.items():
        for m in models:
            calls['own', who, m] = (fit, (specs[m], own))
            if len(own) >= 2:
                calls[LODO, who, m] = (held_out, (specs[m], [[d] for d in own], LODO))
    with call_runner(args.workers or os.cpu_count() or 1, args.ray_address) as run_calls:
        with Progress('fit-trust: fits', len(calls)) as bar:
            done = run_calls(calls, bar.update)
        own_fits = {m: {who: done['own', who, m] for who in people} for m in models}
        scores: dict[tuple[str, str, str], Score] = {
            (LODO, who, m): done[LODO, who, m] for who, own in people.items() for m in models
            if len(own) >= 2}
        for m in models:
            if folds:
                scheme = LOPO if all(len(fold) == 1 for fold in folds) else LOPFO
                fold_of = {who: k for k, fold in enumerate(folds) for who in fold}
                predicted = {who: predict(specs[m], done['fold', str(fold_of[who]), m],
                                          people[who]) for who in people}
                scores[scheme, 'pooled', m] = Score(
                    m, scheme, np.concatenate([p.log_density for p in predicted.values()]),
                    np.concatenate([p.ratings - p.predicted for p in predicted.values()]))
        partial: dict[str, tuple[Population, dict[str, Fit]]] = {}
        if args.no_partial_pooling or len(people) < 2:
            return own_fits, {m: done['pooled', m] for m in models}, partial, scores
        populations = {m: population(specs[m], done['pooled', m], own_fits[m]) for m in models}
        calls = {('partial', who, m): (fit, (shrunk(specs[m], populations[m]), own))
                 for who, own in people.items() for m in models}
        if len(people) >= MIN_PARTICIPANTS:
            for k, fold in enumerate(folds):
                for m in models:
                    prior = fold_prior(specs[m], own_fits[m], fold, done['fold', str(k), m])
                    for who in fold:
                        if len(people[who]) >= 2:
                            calls[SCHEME, who, m] = (held_out, (prior, [[d] for d in people[who]],
                                                                SCHEME))
        with Progress('fit-trust: partial pooling', len(calls)) as bar:
            more = run_calls(calls, bar.update)
    for m in models:
        partial[m] = (populations[m], {who: more['partial', who, m] for who in people})
    scores.update({(SCHEME, who, m): more[SCHEME, who, m] for who in people for m in models
                   if (SCHEME, who, m) in more})
    return own_fits, {m: done['pooled', m] for m in models}, partial, scores


def run(args: FitTrustOptions) -> int:
    """Fit, score, write (see ``trust-av fit-trust --help``)."""
    models = _models(args.models)
    config = load_run_config(args.params_files)
    scale = RatingScale.parse(args.rating_scale)
    drives = (read_study(args.study, config.trust.epsilon_mps2) if args.study is not None
              else read_ratings_table(args.ratings_table, scale))
    rated = [d for d in drives if len(d.ratings)]
    if not rated:
        raise FitError(f'{args.study or args.ratings}: no drive has a rating')
    check_set_folder(args.out)              # before the fit: refused in seconds, not minutes
    if args.ray_address is not None:
        check_ray_address(args.ray_address)   # an address nothing listens on: one line
    specs = {m: model_spec(config.trust, m, dict(config.trust_model_params)) for m in models}
    sizes = {m: model_check.parameter_count(specs[m]) for m in models}
    people = by_participant(rated)
    fit_rows: list[dict[str, Any]] = []
    score_rows: list[dict[str, Any]] = []
    own_fits, pooled_fits, partial, scores = _fit_all(args, specs, rated, people)
    checks: dict[str, list[model_check.Check]] = {}
    for who, own in people.items():
        for m in models:
            fit_rows += _fit_rows(who, own_fits[m][who])
        lodo = {m: scores[LODO, who, m] for m in models if (LODO, who, m) in scores}
        checks[who] = [c for m in models for c in model_check.check_model(
            who, specs[m], own_fits[m][who], own, lodo.get(m))]
        if lodo:
            rows = _rows(who, list(lodo.values()), sizes)
            fine = [m for m, ok in model_check.adequate(checks[who]).items() if ok]
            if len(fine) >= 2:
                weights = model_check.stacking_weights({m: lodo[m] for m in fine})
                for row in rows:
                    row['stacking_weight'] = weights.get(row['model'], '')
            score_rows += rows
        else:
            print(f'{who}: one rated drive, no leave-one-drive-out score')
    for m in models:
        fit_rows += _fit_rows('pooled', pooled_fits[m])
    partial_rows: list[dict[str, Any]] = []
    if partial:
        for m in models:
            population = partial[m][0]
            partial_rows += [{'scope': 'population', 'model': m, 'parameter': k, 'value': v,
                              'kind': kind} for kind, values in (
                                  ('center', population.center), ('spread', population.spread))
                             for k, v in values.items()]
            for who, fitted in partial[m][1].items():
                partial_rows += [r for r in _fit_rows(who, fitted) if r['kind'] != 'fixed']
        for who in people:
            if (SCHEME, who, models[0]) in scores:
                score_rows += _rows(who, [scores[SCHEME, who, m] for m in models], sizes)
    if len(people) >= 2:
        scheme = LOPO if len(people) <= PARTICIPANT_FOLDS else LOPFO
        score_rows += _rows('pooled', [scores[scheme, 'pooled', m] for m in models], sizes)
    else:
        print('one participant: no leave-one-participant-out score')
    # one set: every table and figure, or (failed, stopped) the previous set untouched
    with writing_set(args.out, command='fit-trust') as new:
        if partial_rows:
            output_files.write_text(new / 'partial_pooling.csv', _csv(
                ('scope', 'model', 'parameter', 'value', 'kind'), partial_rows))
        if not args.no_figures:
            for who, own in people.items():
                safe = file_safe(who)   # the reader refused ids that share one
                figure(new / f'participant_{safe}.png', who, own,
                       {m: (specs[m], own_fits[m][who]) for m in models},
                       {m: partial[m][1][who] for m in partial})
        output_files.write_text(new / 'fits.csv', _csv(
            ('scope', 'model', 'parameter', 'value', 'kind'), fit_rows))
        output_files.write_text(new / 'scores.csv', _csv(
            ('scope', 'model', 'scheme', 'ratings', 'elpd', 'elpd_se', 'rmse', 'rmse_se'),
            score_rows))
        output_files.write_text(new / 'comparison.csv', _csv(SCORE_FIELDS, score_rows))
        output_files.write_text(new / 'adequacy.csv', _csv(ADEQUACY_FIELDS, [
            {**dataclasses.asdict(c), 'adequate': str(c.adequate).lower()}
            for found in checks.values() for c in found]))
    for row in score_rows:
        if row['scope'] == 'pooled' or len(people) == 1:
            diff = row['elpd_diff_se']
            print(f"{row['scope']:>10s} {row['scheme']:26s} {row['model']:16s} elpd "
                  f"{row['elpd']:9.1f} diff {row['elpd_diff']:7.1f}"
                  f" ± {diff if math.isfinite(diff) else float('nan'):.1f}  RMSE "
                  f"{row['rmse']:5.1f} ± {row['rmse_se']:.1f}")
    totals: dict[tuple[str, str], list[float]] = {}
    for row in score_rows:
        if row['scope'] != 'pooled':
            totals.setdefault((row['scheme'], row['model']), []).append(row['elpd'])
    for (scheme, model), values in sorted(totals.items(), key=lambda item: -sum(item[1])):
        print(f"{'all':>10s} {scheme:36s} {model:16s} elpd {sum(values):9.1f} summed over "
              f'{len(values)} participant(s)')
    _print_preferred(score_rows)
    _print_adequacy(checks, score_rows)
    print(f'{len(people)} participant(s), {len(rated)} rated drive(s); tables and figures in '
          f'{args.out}')
    return 0
