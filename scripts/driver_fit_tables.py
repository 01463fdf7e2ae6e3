"""Print the test tables of docs/DRIVER_IRL.md from a ``trust-av fit-driver`` evaluation.

Usage: python scripts/driver_fit_tables.py [EVAL_JSON]
(default: human_driver_sim/models/driver_fit_caution_eval.json). Markdown: per data set and
protocol, every model's pooled scores (mean over pairs ± 95 % CI) beside the noise floor,
then the selected model's paired difference to each IDM (from the per-pair scores).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from human_driver_sim.evaluation import mean_ci95
from human_driver_sim.population import DRIVER_FIT_FILE


def main() -> None:
    """Print the tables."""
    path = Path(sys.argv[1]) if len(sys.argv) > 1 else DRIVER_FIT_FILE.with_name(
        DRIVER_FIT_FILE.stem + '_eval.json')
    document = json.loads(path.read_text())
    selected = document['selected']
    print(f'selected on validation: {selected}\n')
    print('| model | ' + ' | '.join(next(iter(document['validation_loss'].values()))) + ' |')
    print('| --- |' + ' --- |' * len(next(iter(document['validation_loss'].values()))))
    for model, losses in document['validation_loss'].items():
        print(f'| {model} | ' + ' | '.join(f'{v:.3f}' for v in losses.values()) + ' |')
    for name, sets in document['sets'].items():
        for protocol in ('window', 'full'):
            models = sets[protocol]
            print(f'\n**{name}, {protocol}** ({len(sets["pairs"])} pairs; mean over pairs ± '
                  '95 % CI)\n')
            print('| model | gap NRMSE | speed NRMSE | gap RMSE (m) | collisions (pairs) | '
                  'sim. steps with gap < 2 m | closest gap (m) |')
            print('| --- | --- | --- | --- | --- | --- | --- |')
            for model, scores in models.items():
                p = scores['pooled']
                print(f'| {model} | {p["gap_nrmse"]:.3f} ± {p["gap_nrmse_ci95"]:.3f} | '
                      f'{p["speed_nrmse"]:.3f} ± {p["speed_nrmse_ci95"]:.3f} | '
                      f'{p["gap_rmse_m"]:.2f} | {p["collisions"]} | {p["steps_below_2m"]} | '
                      f'{p["min_gap_m"]:.2f} |')
            mine = models[selected]['per_pair']
            for other in ('IDM pooled (bounded)', 'IDM textbook'):
                theirs = models[other]['per_pair']
                diffs = [mine[k]['gap_nrmse'] - theirs[k]['gap_nrmse'] for k in sorted(mine)]
                mean, half = mean_ci95(diffs)
                ratio = (np.mean([mine[k]['gap_nrmse'] for k in mine])
                         / np.mean([theirs[k]['gap_nrmse'] for k in theirs]))
                print(f'\npaired difference {selected} - {other}: {mean:+.3f} ± {half:.3f} '
                      f'(better on {sum(d < 0 for d in diffs)} of {len(diffs)}); ratio '
                      f'{ratio:.3f}')


if __name__ == '__main__':
    main()
