"""Every registered trust model scored on the same runs: offline and in closed loop.

Usage: python scripts/compare_trust_models.py [--trace us06] [--predictor ca] [--alpha 0.5]
       [--params-file F ...] [--max-steps N] [--bag BAG] [--out results/trust_models]

- **Offline**: one closed loop with the params files' trust model (default ``paper``) is
  recorded, or a node-graph recording is read (``--bag``, a ``trust-av run --bag``
  recording); every registered model is run over its recorded explicability scores (what
  ``trust-monitor-estimate --trust-model NAME`` does on the recorded plans).
- **Closed loop**: the same case is run once per model, the model feeding both the
  monitor and the NMPC's trust constraint (``trust_model: NAME``).

Writes ``trust_models.csv`` (one row per mode and model: final trust, its variance, mean E,
RMSE, steps where the trust constraint was active, i.e. E_max < 1) and
``trust_models.png`` (trust over time per model, offline and closed loop, mean +- 2 sd
shaded where the model has a variance) to ``--out``.
"""

from __future__ import annotations

import argparse
import csv
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

from preceding_traffic.traces import truncate
from trust_av.system.closed_loop import control_trace, simulate
from trust_av.system.config import load_run_config
from trust_av_common.registry import names
from trust_monitor.model_interface import TRUST_MODELS


def run(files: list[Path], trace: str, predictor: str, alpha: float, model: str | None,
        max_steps: int | None) -> Any:
    overrides: dict[str, dict[str, Any]] = {
        'preceding_traffic': {'trace': trace},
        'planner': {'predictor': predictor, 'alpha': alpha}}
    if model is not None:
        overrides['/**'] = {'trust_model': model}
    config = load_run_config(files, overrides)
    speeds = control_trace(config)
    if max_steps is not None:
        speeds = truncate(speeds, max_steps)
    return config, simulate(config, speeds)


def replay(model: Any, scores: list[float], dt_s: float
           ) -> tuple[list[float], list[float | None]]:
    """Trust and variance after each step of ``model`` over recorded scores E."""
    state = model.initial_state()
    trusts, variances = [], []
    for score in scores:
        state = model.step(state, score, dt_s)
        trusts.append(model.trust(state))
        variances.append(model.variance(state))
    return trusts, variances


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--trace', default='us06')
    parser.add_argument('--predictor', default='ca')
    parser.add_argument('--alpha', type=float, default=0.5)
    parser.add_argument('--params-file', type=Path, action='append', default=[])
    parser.add_argument('--max-steps', type=int, default=None,
                        help='stop every run after this many steps (a quick check)')
    parser.add_argument('--bag', type=Path, default=None,
                        help='score the models offline on this trust-av run recording '
                             '(default: an in-process run of the same case)')
    parser.add_argument('--out', type=Path, default=Path('results/trust_models'))
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    models = names(TRUST_MODELS)
    base_config, recorded = run(args.params_file, args.trace, args.predictor, args.alpha, None,
                                args.max_steps)
    if args.bag is not None:
        from trust_av.graph.bag_records import records_from_bag
        from trust_av.system.metrics import compute_metrics
        records = records_from_bag(args.bag)
        m = compute_metrics(records, base_config.min_safe_gap_m)
    else:
        records = recorded.records
        m = recorded.metrics
    scores = [r.explicability for r in records]
    dt_s = base_config.planner.dt_s
    rows: list[list[object]] = []
    curves: dict[tuple[str, str], tuple[list[float], list[float | None]]] = {}
    for name in models:
        model = replace(base_config, trust=replace(base_config.trust,
                                                   trust_model=name)).trust_model()
        trusts, variances = replay(model, scores, dt_s)
        curves['offline', name] = trusts, variances
        rows.append(['offline', name, trusts[-1], variances[-1], m.mean_explicability,
                     m.rmse_mps2, ''])
    for name in models:
        config, result = run(args.params_file, args.trace, args.predictor, args.alpha, name,
                             args.max_steps)
        # the monitor's variance: the same model replayed over the run's own E
        trusts, variances = replay(config.trust_model(),
                                   [r.explicability for r in result.records], dt_s)
        assert trusts == [r.trust for r in result.records], name  # the monitor's trust
        curves['closed loop', name] = trusts, variances
        cm = result.metrics
        active = sum(1 for r in result.records if r.explicability_max < 1.0)
        rows.append(['closed loop', name, cm.final_trust, variances[-1],
                     cm.mean_explicability, cm.rmse_mps2, active])
    header = ['mode', 'trust_model', 'final_trust', 'final_variance', 'mean_E', 'rmse_mps2',
              'constraint_active_steps']
    with (args.out / 'trust_models.csv').open('w', newline='') as handle:
        writer = csv.writer(handle)
        writer.writerow(header)
        writer.writerows(rows)
    print('| ' + ' | '.join(header) + ' |')
    print('|' + '---|' * len(header))
    for row in rows:
        print('| ' + ' | '.join(f'{v:.4g}' if isinstance(v, float) else str(v) for v in row)
              + ' |')
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(len(models), 2, figsize=(10, 2.2 * len(models)), sharex=True,
                             squeeze=False)
    for i, name in enumerate(models):
        for j, mode in enumerate(('offline', 'closed loop')):
            ax = axes[i][j]
            trusts, variances = curves[mode, name]
            times = [base_config.planner.dt_s * k for k in range(len(trusts))]
            ax.plot(times, trusts)
            if variances[-1] is not None:
                sd = [2.0 * float(v) ** 0.5 for v in variances]  # type: ignore[arg-type]
                ax.fill_between(times, [t - s for t, s in zip(trusts, sd, strict=True)],
                                [t + s for t, s in zip(trusts, sd, strict=True)], alpha=0.3,
                                label='mean +- 2 sd')
                ax.legend(fontsize=7, loc='lower right')
            ax.set_title(f'{name}, {mode}', fontsize=9)
            ax.set_ylabel('trust')
    for ax in axes[-1]:
        ax.set_xlabel('t (s)')
    files = ', '.join(p.name for p in args.params_file) or 'shipped config'
    fig.suptitle(f'Trust per model: {args.trace}, TAC-{args.predictor.upper()}, '
                 f'alpha {args.alpha:g} ({files})')
    fig.tight_layout()
    fig.savefig(args.out / 'trust_models.png', dpi=100)
    print(f'wrote {args.out / "trust_models.csv"} and {args.out / "trust_models.png"}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
