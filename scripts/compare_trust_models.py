"""Every registered trust model scored on the same runs: offline and in closed loop.

Usage: python scripts/compare_trust_models.py [--trace us06] [--predictor ca] [--alpha 0.5]
       [--params-file F ...] [--out results/trust_models]

- **Offline**: one closed loop with the params files' trust model (default ``paper``) is
  recorded; every registered model is run over its recorded explicability scores (what
  ``trust-monitor-estimate --trust-model NAME`` does on the recorded plans).
- **Closed loop**: the same case is run once per model, the model feeding both the
  monitor and the NMPC's trust constraint (``trust_model: NAME``).

Writes ``trust_models.csv`` (one row per mode and model: final trust, its variance, mean E,
RMSE, steps where the trust constraint was active, i.e. E_max < 1) and
``trust_models.png`` (trust over time per model, offline and closed loop) to ``--out``.
"""

from __future__ import annotations

import argparse
import csv
import sys
from pathlib import Path
from typing import Any

from trust_av_planner.system.closed_loop import control_trace, simulate
from trust_av_planner.system.config import load_run_config
from trust_monitor.common.registry import TRUST_MODELS, names


def run(files: list[Path], trace: str, predictor: str, alpha: float,
        model: str | None) -> Any:
    overrides: dict[str, dict[str, Any]] = {
        'preceding_traffic': {'trace': trace},
        'planner': {'predictor': predictor, 'alpha': alpha}}
    if model is not None:
        overrides['/**'] = {'trust_model': model}
    config = load_run_config(files, overrides)
    return config, simulate(config, control_trace(config))


def offline(config: Any, model_name: str, scores: list[float], dt_s: float
            ) -> tuple[list[float], float | None]:
    from dataclasses import replace
    model = replace(config, trust=replace(config.trust, trust_model=model_name)).trust_model()
    state = model.initial_state()
    trusts = []
    for score in scores:
        state = model.step(state, score, dt_s)
        trusts.append(model.trust(state))
    return trusts, model.variance(state)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--trace', default='us06')
    parser.add_argument('--predictor', default='ca')
    parser.add_argument('--alpha', type=float, default=0.5)
    parser.add_argument('--params-file', type=Path, action='append', default=[])
    parser.add_argument('--out', type=Path, default=Path('results/trust_models'))
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    models = names(TRUST_MODELS)
    base_config, recorded = run(args.params_file, args.trace, args.predictor, args.alpha, None)
    scores = [r.explicability for r in recorded.records]
    times = [r.t_s for r in recorded.records]
    dt_s = times[1] - times[0]
    rows: list[list[object]] = []
    curves: dict[tuple[str, str], list[float]] = {}
    m = recorded.metrics
    for name in models:
        trusts, variance = offline(base_config, name, scores, dt_s)
        curves['offline', name] = trusts
        rows.append(['offline', name, trusts[-1], variance, m.mean_explicability, m.rmse_mps2,
                     ''])
    for name in models:
        config, result = run(args.params_file, args.trace, args.predictor, args.alpha, name)
        model = config.trust_model()
        state = model.initial_state()
        for r in result.records:
            state = model.step(state, r.explicability, dt_s)
        curves['closed loop', name] = [r.trust for r in result.records]
        cm = result.metrics
        active = sum(1 for r in result.records if r.explicability_max < 1.0)
        rows.append(['closed loop', name, cm.final_trust, model.variance(state),
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
            ax.plot(times, curves[mode, name])
            ax.set_title(f'{name}, {mode}', fontsize=9)
            ax.set_ylabel('trust')
    for ax in axes[-1]:
        ax.set_xlabel('t (s)')
    fig.suptitle(f'Trust per model: {args.trace}, TAC-{args.predictor.upper()}, '
                 f'alpha {args.alpha:g}')
    fig.tight_layout()
    fig.savefig(args.out / 'trust_models.png', dpi=100)
    print(f'wrote {args.out / "trust_models.csv"} and {args.out / "trust_models.png"}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
