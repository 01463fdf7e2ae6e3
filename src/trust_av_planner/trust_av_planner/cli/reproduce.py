"""``trust-av reproduce``: the paper's Tables II-IV and Figures 2-3 from one command."""

from __future__ import annotations

import argparse
import csv
import itertools
import time
from pathlib import Path
from typing import Any

import yaml

from human_driver_sim.population import DRIVER_FIT_FILE, WEIGHT_NAMES
from preceding_traffic.sources import load_trace
from trust_av_planner.cli.options import (
    MAX_DRIVERS,
    MAX_SEED,
    MAX_WORKERS,
    Progress,
    add_lead_preview_option,
    bounded_int,
    positive_int,
    steps_value,
)
from trust_av_planner.errors import TrustAvPlannerError
from trust_av_planner.nmpc import PREDICTORS as KNOWN_PREDICTORS
from trust_av_planner.study import sweep, tables
from trust_av_planner.study.paper_results import TABLE_II_TAC_GRU_US06, TABLE_III_TAC_CA_US06
from trust_av_planner.study.plots import speed_profiles, trust_over_time
from trust_av_planner.study.sweep import Case
from trust_av_planner.system.config import DEFAULT_PARAMS_FILE, load_run_config
from trust_monitor.common import output_files
from trust_monitor.common.params import read_params_file

PROFILES = {'table_i': DEFAULT_PARAMS_FILE,
            'as_reported': DEFAULT_PARAMS_FILE.with_name('paper_as_reported.yaml')}
"""Parameter profiles: the paper's Table I, and the reading its printed mean E imply."""
DEFAULT_RESULTS = {'table_i': Path('results/paper'),
                   'as_reported': Path('results/paper_as_reported')}


def with_lead_preview(params_file: Path, lead_preview: str, out: Path) -> Path:
    """A copy of ``params_file`` in ``out`` whose planner has ``lead_preview`` (the sweep's
    cache keys on the params text, so each preview has its own cases)."""
    sections = read_params_file(params_file)
    sections.setdefault('planner', {})['lead_preview'] = lead_preview
    path = out / f'params_lead_preview_{lead_preview}.yaml'
    output_files.write_text(path, yaml.safe_dump({node: {'ros__parameters': values}
                                                 for node, values in sections.items()},
                                                sort_keys=False))
    return path


def csv_list(text: str) -> list[str]:
    """argparse type: comma-separated names."""
    return [t.strip() for t in text.split(',') if t.strip()]


def trend_checks(results: dict[Case, dict[str, Any]], traces: list[str],
                 predictors: list[str]) -> list[str]:
    """The paper's trends (Tables II-IV), one line each: 'ok' or what broke."""
    lines = []
    for predictor in predictors:
        for trace in traces:
            m = [results[Case(trace, predictor, a)]['metrics'] for a in sweep.ALPHAS]
            trust = [x['final_trust'] for x in m]
            score = [x['mean_explicability'] for x in m]
            rmse = [x['rmse_mps2'] for x in m]
            problems = []
            if any(b < a * 0.99 for a, b in itertools.pairwise(trust)):
                problems.append('final trust decreases')
            if any(b > a * 1.01 for a, b in itertools.pairwise(score)):
                problems.append('mean E increases')
            if any(b > a * 1.01 for a, b in itertools.pairwise(rmse)):
                problems.append('RMSE increases')
            if not (trust[-1] > trust[0] and score[-1] < score[0] and rmse[-1] < rmse[0]):
                problems.append('alpha = 1 not strictly better than alpha = 0')
            status = 'ok' if not problems else '; '.join(problems)
            lines.append(f'TAC-{predictor.upper()} {trace}: {status}')
    if {'gru', 'ca'} <= set(predictors) and 'us06' in traces:
        worse = [a for a in sweep.ALPHAS
                 if not (results[Case('us06', 'gru', a)]['metrics']['final_trust']
                         > results[Case('us06', 'ca', a)]['metrics']['final_trust']
                         and results[Case('us06', 'gru', a)]['metrics']['mean_explicability']
                         < results[Case('us06', 'ca', a)]['metrics']['mean_explicability'])]
        lines.append('TAC-GRU beats TAC-CA on US06 (trust and E) for every alpha: '
                     + ('ok' if not worse else f'no, at alpha = {worse}'))
    return lines


def run(args: argparse.Namespace) -> int:
    """Run ``trust-av reproduce``."""
    unknown = [p for p in args.predictors if p not in KNOWN_PREDICTORS]
    if unknown:
        raise TrustAvPlannerError(f'unknown predictor(s) {unknown}; available: '
                                  f'{list(KNOWN_PREDICTORS)}')
    if args.profile != 'table_i' and args.params_file is not None:
        raise TrustAvPlannerError('--profile and --params-file both choose the parameters: give '
                                  'one of them')
    params_file = args.params_file or PROFILES[args.profile]
    out: Path = args.results_dir or DEFAULT_RESULTS[args.profile]
    if args.lead_preview is not None and args.lead_preview != 'recorded':
        out = args.results_dir or out.with_name(f'{out.name}_{args.lead_preview}')
    # everything is checked before anything is written (the results directory included)
    config = load_run_config(params_file, None if args.lead_preview is None else
                             {'planner': {'lead_preview': args.lead_preview}})
    for trace in args.traces:               # a bad trace is named before any case runs
        load_trace(trace, config.planner.dt_s, config.trace)
    cases = sweep.sweep_cases(args.traces, args.predictors, sweep.ALPHAS)
    if args.drivers:
        cases = sweep.population_cases(cases, args.drivers, args.drivers_seed,
                                       args.driver_fit)
    if args.executor == 'ray':
        sweep.check_ray_address(args.ray_address)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise TrustAvPlannerError(f'--results-dir {out}: cannot create it '
                                  f'({err.strerror})') from err
    if args.lead_preview is not None:
        params_file = with_lead_preview(params_file, args.lead_preview, out)
    executor: sweep.Executor
    if args.executor == 'ray':
        executor = sweep.RayExecutor(args.ray_address, args.workers)
    else:
        executor = sweep.LocalExecutor(args.workers)
    bar = Progress('reproduce', len(cases), shown=not args.no_progress)
    start = time.monotonic()
    runner = 'graph' if args.graph else 'in-process'
    results = sweep.run_sweep(cases, params_file, out, executor,
                              bar.update, runner=runner,
                              max_steps=args.max_steps)
    bar.close()
    elapsed = time.monotonic() - start

    with output_files.replacing(out / 'all_runs.csv') as (table,), \
            table.open('w', newline='') as handle:
        writer = csv.writer(handle)
        driver_names = (*WEIGHT_NAMES, 'time_headway_s')
        writer.writerow(['trace', 'predictor', 'alpha', 'driver', *driver_names,
                         *results[cases[0]]['metrics']])
        for case in cases:
            driver = {**{name: getattr(config.driver, name) for name in driver_names},
                      **dict(case.driver_params)}
            writer.writerow([case.trace, case.predictor, case.alpha, case.driver,
                             *(driver[name] for name in driver_names),
                             *results[case]['metrics'].values()])
    if args.drivers:
        alpha_table, improvement_table = (tables.population_alpha_table,
                                          tables.population_improvement_table)
        summary = sweep.population_mean(results)  # trends and Figure 3 on the means
    else:
        alpha_table, improvement_table = tables.alpha_table, tables.improvement_table
        summary = results
    written = []
    if 'us06' in args.traces:
        for predictor, name, paper in (('gru', 'table_II_tac_gru_us06', TABLE_II_TAC_GRU_US06),
                                       ('ca', 'table_III_tac_ca_us06', TABLE_III_TAC_CA_US06)):
            if predictor in args.predictors:
                us06_steps = load_trace('us06', config.planner.dt_s, config.trace).steps
                tables.write_rows(out / name, *alpha_table(results, 'us06', predictor, paper,
                                                           (us06_steps, config.trust)))
                written.append(f'{name}.md')
    tables.write_rows(out / 'table_IV_max_improvements',
                         *improvement_table(results, args.traces, args.predictors))
    written.append('table_IV_max_improvements.md')
    traces = [load_trace(t, config.planner.dt_s, config.trace) for t in args.traces]
    speed_profiles(traces, out / 'figure_2_speed_profiles.png')
    written.append('figure_2_speed_profiles.png')
    if 'us06' in args.traces:
        series = {f'TAC-{p.upper()}': {a: (summary[Case('us06', p, a)]['time_s'],
                                           summary[Case('us06', p, a)]['trust'])
                                       for a in sweep.ALPHAS}
                  for p in args.predictors}
        trust_over_time(series, 'us06', out / 'figure_3_trust_us06.png',
                        config.trust.trust_growth_rate)
        written.append('figure_3_trust_us06.png')

    for path in written:
        if path.endswith('.md'):
            print(f'\n## {path}\n' + (out / path).read_text())
    print('Trends of Tables II-IV (final trust up, mean E and RMSE down with alpha):')
    if args.drivers:
        print(f'(a population of {args.drivers} drivers, seed {args.drivers_seed}: tables give '
              'mean ± 95 % CI over drivers; trends and Figure 3 use the means)')
    for line in trend_checks(summary, args.traces, args.predictors):
        print(f'  {line}')
    print(f'\nProfile {args.profile} ({params_file}): epsilon_mps2 = '
          f'{config.trust.epsilon_mps2:g}, explicability_scale = '
          f'{config.planner.explicability_scale:g}; TAC-GRU uses {config.planner.gru_model} '
          '(trained behind the default profile)')
    print(f'{len(cases)} cases ({runner}) in {elapsed:.1f} s wall; outputs in {out}/: '
          + ', '.join(written))
    if args.graph:
        print(f'graph recordings (MCAP, one per case): {out / "graph_bags"}/')
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add ``reproduce`` to ``trust-av``."""
    parser = subparsers.add_parser(
        'reproduce', help="the paper's Tables II-IV and Figures 2-3",
        description='Sweep traces x predictors x alpha in {0, 0.25, 0.5, 0.75, 1} with one '
                    'configuration, in parallel, and write Tables II-IV (Markdown and CSV, '
                    "ours beside the paper's) and Figures 2-3 (PNG). Finished cases are cached "
                    'by a hash of case, params file and code, so a rerun only runs what changed.')
    parser.add_argument('--traces', type=csv_list, default=list(sweep.TRACES),
                        help='comma-separated traces (default: %(default)s)')
    parser.add_argument('--predictors', type=csv_list, default=list(sweep.PREDICTORS),
                        help='comma-separated predictors (default: %(default)s)')
    parser.add_argument('--executor', choices=('local', 'ray'), default='local',
                        help='local process pool (default) or a Ray cluster')
    parser.add_argument('--workers', type=positive_int, default=None,
                        help=f'parallel workers, 1..{MAX_WORKERS} (default: one per core)')
    parser.add_argument('--ray-address', default=None,
                        help='Ray cluster address (default: start a local one)')
    parser.add_argument('--graph', action='store_true',
                        help='run every case through the ROS 2 node graph (six processes in '
                             'lock-step, recorded to MCAP under RESULTS_DIR/graph_bags/) '
                             'instead of in-process; same numbers, about 10 s per case')
    parser.add_argument('--max-steps', type=steps_value, default=0,
                        help='stop every case after this many steps, for a quick check '
                             "(default: whole traces; tables then differ from the paper's)")
    parser.add_argument('--drivers', type=bounded_int('--drivers', 0, MAX_DRIVERS),
                        default=0, metavar='K',
                        help='run every case for K human drivers sampled from the fitted '
                             "per-pair weights (seeded) instead of the params file's driver; "
                             'tables then give mean ± 95 %% confidence interval per cell '
                             f"(default: 0, the params file's driver; at most {MAX_DRIVERS})")
    parser.add_argument('--drivers-seed', type=bounded_int('--drivers-seed', 0, MAX_SEED),
                        default=1,
                        help='seed of the driver population (default: %(default)s)')
    parser.add_argument('--driver-fit', type=Path, default=DRIVER_FIT_FILE,
                        help='driver-fit file with per-pair weights (default: the shipped fit, '
                             'human_driver_sim/models/driver_fit.yaml)')
    parser.add_argument('--profile', choices=tuple(PROFILES), default='table_i',
                        help="which parameters: table_i = the paper's Table I (epsilon 6, "
                             "config/trust_av.yaml), as_reported = what the paper's printed "
                             'mean E imply (epsilon 3, config/paper_as_reported.yaml; '
                             'docs/RESULTS.md); default: %(default)s')
    parser.add_argument('--results-dir', type=Path, default=None,
                        help='where tables, figures and the cache go (default: results/paper '
                             'for table_i, results/paper_as_reported for as_reported)')
    parser.add_argument('--params-file', type=Path, default=None,
                        help="ROS 2 params file instead of a profile's (default: the "
                             "profile's)")
    add_lead_preview_option(parser)
    parser.add_argument('--no-progress', action='store_true', help='no progress bar')
    parser.set_defaults(func=run)
