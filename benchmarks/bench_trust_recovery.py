"""Recovery of trust models from synthetic participants' ratings.

For every registered trust model: ``--participants`` synthetic participants, each driving
``--drives`` drives of the study's conditions in which trust moves (the shipped follower in
the in-process loop, :mod:`trust_av.study.trust_recovery`), their ratings generated
by that model with parameters drawn from its declared prior (or from the study's
``TRUE_RANGES``, where a parameter changes the ratings), a known observation model and
Gaussian rating noise (5 points, whole ratings in 0-100, one every 2.5 s from the start).
Every model is fitted to every participant (``trust_monitor.trust_fit``). Reports:

- ``parameter_r``: the correlation of true and fitted values per model and parameter, of
  their logs for a ``log_scale`` parameter (null for one its model declares not
  identifiable);
- ``confusion``: {true model: {preferred model: participants}}, preferred by
  leave-one-drive-out elpd with the parsimony rule of
  :func:`trust_monitor.trust_fit.preferred` (a model with more parameters must beat
  a simpler one by more than one standard error of the elpd difference);
  ``confusion_best_elpd``: the same without the rule;
- ``power``: for each ordered pair (true, other), the fewest participants (at this many
  drives each) whose summed held-out elpd prefers the true model at 80 % power (bootstrap
  over the synthetic participants, one-sided 5 %); null when not reached by 96.

Writes DIR/trust_recovery.json (with every participant's true and fitted values,
``true_and_fitted``, preferred model and held-out elpds, in the same order) and
DIR/trust_recovery.png. Not a test; the suite runs a small version (tests/graph/test_trust_fit.py).

    python benchmarks/bench_trust_recovery.py --out DIR [--participants 24] [--drives 4]
        [--seed 0] [--workers 1]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from trust_av.study.trust_design import (
    POWER_SIZES,
    WIDE_RANGES,
    Design,
    Recovery,
    recover,
)
from trust_av.study.trust_recovery import CONDITIONS, RATING_SPAN, TRUE_RANGES
from trust_av.system.config import load_run_config
from trust_av_common.registry import names
from trust_monitor.model_check import parameter_count
from trust_monitor.model_interface import TRUST_MODELS
from trust_monitor.trust_fit import PARSIMONY_SE, model_spec

__all__ = ['POWER_SIZES', 'Recovery', 'recover']

def figure(path: Path, result: Any, specs: dict[str, Any], r: dict[str, Any]) -> None:
    """True vs fitted per identifiable parameter, and the confusion matrix."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    panels = [(m, p) for m in result.true_and_fitted for p in result.true_and_fitted[m]]
    cols = 4
    rows = (len(panels) + 1 + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 2.9 * rows), squeeze=False)
    flat = list(axes.flat)
    for ax, (model, param) in zip(flat, panels, strict=False):
        pairs = np.array(result.true_and_fitted[model][param])
        ax.scatter(pairs[:, 0], pairs[:, 1], s=10)
        low, high = pairs.min(), pairs.max()
        ax.plot([low, high], [low, high], color='grey', lw=0.8)
        value = r[model][param]
        ax.set_title(f'{model}\n{param} (r = {value:.2f})' if value is not None
                     else f'{model}\n{param} (r: n/a)', fontsize=8)
        ax.set_xlabel('true', fontsize=8)
        ax.set_ylabel('fitted', fontsize=8)
        ax.tick_params(labelsize=7)
    ax = flat[len(panels)]
    models = list(result.confusion)
    matrix = np.array([[result.confusion[t][b] for b in models] for t in models])
    ax.imshow(matrix, cmap='Blues')
    for i in range(len(models)):
        for j in range(len(models)):
            ax.text(j, i, str(matrix[i, j]), ha='center', va='center', fontsize=8)
    ax.set_xticks(range(len(models)), models, rotation=45, ha='right', fontsize=7)
    ax.set_yticks(range(len(models)), models, fontsize=7)
    ax.set_xlabel('preferred by held-out elpd', fontsize=8)
    ax.set_ylabel('true model', fontsize=8)
    ax.set_title('confusion', fontsize=8)
    for extra in flat[len(panels) + 1:]:
        extra.axis('off')
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--out', type=Path, required=True, help='output directory')
    parser.add_argument('--participants', type=int, default=24)
    parser.add_argument('--drives', type=int, default=4)
    parser.add_argument('--models', default='', help='comma-separated (default: all)')
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--workers', type=int, default=1,
                        help='processes for the drives and fits (the result is the same)')
    parser.add_argument('--conditions', default=','.join(dict.fromkeys(CONDITIONS)),
                        help='comma-separated perturbation conditions, cycled over the drives')
    parser.add_argument('--drive-s', type=int, default=120, help='drive length, s')
    parser.add_argument('--rating-period-s', type=float, default=2.5)
    parser.add_argument('--rating-span', default=f'{RATING_SPAN[0]:g},{RATING_SPAN[1]:g}',
                        help="low,high: the span of a linear model's ratings, points")
    parser.add_argument('--ranges', default='benchmark',
                        help="true-value ranges: 'benchmark' (TRUE_RANGES), 'wide' "
                             "(WIDE_RANGES) or a JSON file {model: {parameter: [low, high]}}")
    args = parser.parse_args()
    if args.participants < 3 or args.drives < 2 or args.workers < 1:
        print('need --participants >= 3, --drives >= 2 and --workers >= 1', file=sys.stderr)
        return 2
    try:
        low, high = (float(v) for v in args.rating_span.split(','))
        ranges = (TRUE_RANGES if args.ranges == 'benchmark' else WIDE_RANGES
                  if args.ranges == 'wide' else {
                      m: {k: (float(v[0]), float(v[1])) for k, v in row.items()}
                      for m, row in json.loads(Path(args.ranges).read_text()).items()})
    except (ValueError, OSError, TypeError, AttributeError, IndexError) as error:
        print(f'--rating-span or --ranges: {error}', file=sys.stderr)
        return 2
    design = Design(tuple(c for c in args.conditions.split(',') if c), args.drives,
                    args.drive_s, args.rating_period_s, args.participants,
                    rating_span=(low, high), true_ranges=dict(ranges))
    models = [m for m in args.models.split(',') if m] or list(names(TRUST_MODELS))
    unknown = sorted(set(models) - set(names(TRUST_MODELS)))
    if unknown:
        print(f'--models: not registered: {", ".join(unknown)}', file=sys.stderr)
        return 2
    config = load_run_config([])
    start = time.perf_counter()
    result = recover(config, models, design, seed=args.seed,
                     workers=args.workers, on_progress=lambda done, total: print(
                         f'{done}/{total} participants {time.perf_counter() - start:.0f} s',
                         flush=True))
    wall = time.perf_counter() - start
    specs = {m: model_spec(config.trust, m) for m in models}
    r = result.parameter_r(specs)
    confusion = result.confusion
    diagonal = [confusion[m][m] / args.participants for m in models]
    power: dict[str, dict[str, int | None]] = {}
    for true in models:
        power[true] = {}
        for other in models:
            if other == true:
                continue
            power[true][other] = result.needed(true, other)
    margin = {t: {o: float(np.median([row[t] - row[o] for row in result.elpd[t]]))
                  for o in models if o != t} for t in models}
    out: dict[str, Any] = {
        'participants': args.participants, 'drives_per_participant': args.drives,
        'wall_s': round(wall, 1), 'parameter_r': r, 'confusion': confusion,
        'confusion_best_elpd': result.confusion_best, 'parsimony_se': PARSIMONY_SE,
        'confusion_diagonal_mean': float(np.mean(diagonal)),
        'confusion_diagonal_min': float(np.min(diagonal)),
        'participants_for_80_percent_power': power,
        'median_elpd_margin': margin,
        'rating_noise_points': design.rating_noise, 'rating_period_s': design.rating_period_s,
        'drive_s': design.drive_s, 'conditions': design.drive_conditions(),
        'rating_span': list(design.rating_span),
        'true_ranges': {m: {k: list(v) for k, v in ranges[m].items()}
                        for m in models if m in ranges},
        'parameters_counted': {m: parameter_count(specs[m]) for m in models},
        'unidentifiable': {m: {p.name: p.note for p in specs[m].fixed} for m in models},
        'seed': args.seed,
        'true_and_fitted': result.true_and_fitted,
        'preferred_per_participant': result.chosen, 'elpd_per_participant': result.elpd}
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / 'trust_recovery.json').write_text(json.dumps(out, indent=1) + '\n')
    figure(args.out / 'trust_recovery.png', result, specs, r)
    print(json.dumps({k: out[k] for k in ('parameter_r', 'confusion',
                                          'confusion_diagonal_mean',
                                          'participants_for_80_percent_power')}, indent=1))
    print(f'wall {wall:.0f} s; {args.out / "trust_recovery.json"}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
