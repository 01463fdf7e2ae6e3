"""``trust-av reproduce``: a study of any registered parts (traces x plan estimators x trust
models x followers x alpha) as one tidy table, and the paper's Tables II-IV and Figures 2-3
for the cases that are the paper's, from one command."""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import yaml

from human_driver_sim.followers import DRIVERS
from human_driver_sim.population import CAUTIOUS_FIT_FILE, DRIVER_FIT_FILE
from preceding_traffic.sources import load_trace
from trust_av.cli.options import (
    MAX_DRIVERS,
    MAX_SEED,
    MAX_WORKERS,
    Progress,
    alpha_value,
    bounded_int,
    lead_preview_option,
    params_files_option,
    positive_int,
    steps_value,
)
from trust_av.cli.typed_options import add_command, option
from trust_av.errors import TrustAvAppError
from trust_av.study import population, sweep, tables, trace_reports
from trust_av.study.frame import (
    TRUST_MODEL_PARAMETER,
    check_axes,
    tidy_rows,
    write_tidy_csv,
)
from trust_av.study.paper_results import TABLE_II_TAC_GRU_US06, TABLE_III_TAC_CA_US06
from trust_av.study.plots import speed_profiles, trust_over_time
from trust_av.study.sweep import Case
from trust_av.system.config import (
    DEFAULT_PARAMS_FILE,
    HUMAN_CAUTIOUS_PARAMS_FILE,
    RunConfig,
    load_run_config,
)
from trust_av.system.output_sets import writing_set
from trust_av_common import output_files, registry
from trust_av_planner.predictors import PREDICTORS
from trust_monitor.model_interface import TRUST_MODELS, paper_bound_holds, trust_ceiling

__all__ = ['lead_preview_layer', 'truncation_note', 'unsafe_cases']

PROFILES = {'table_i': DEFAULT_PARAMS_FILE,
            'as_reported': DEFAULT_PARAMS_FILE.with_name('paper_as_reported.yaml'),
            'paper_fitted': DEFAULT_PARAMS_FILE.with_name('paper_fitted_threshold.yaml'),
            'human_cautious': HUMAN_CAUTIOUS_PARAMS_FILE}
"""Parameter profiles: the paper's Table I, the reading its printed mean E imply, that
reading with P_thre fitted to its final trusts (a hypothesis: docs/concepts/trust-models.md),
and Table I with the cautious human follower, who never breaks d_s (docs/DRIVER_IRL.md)."""
DEFAULT_RESULTS = {'table_i': Path('results/paper'),
                   'as_reported': Path('results/paper_as_reported'),
                   'paper_fitted': Path('results/paper_fitted'),
                   'human_cautious': Path('results/human_cautious')}
SWEEP_FOLDERS = ('cache', 'graph_bags')
"""The sweep's work folders in the results directory, kept from run to run (resumable)."""
DRIVER_FITS = {'human_cautious': CAUTIOUS_FIT_FILE}
"""The driver-fit file a profile's population (``--drivers K``) draws from; the shipped fit
for the others."""


def lead_preview_layer(lead_preview: str, out: Path) -> Path:
    """A params-file layer in ``out`` that sets the planner's ``lead_preview`` (the sweep's
    cache keys on the params text, so each preview has its own cases)."""
    path = out / f'params_lead_preview_{lead_preview}.yaml'
    output_files.write_text(path, yaml.safe_dump(
        {'/**/planner': {'ros__parameters': {'lead_preview': lead_preview}}}))
    return path


def csv_list(text: str) -> list[str]:
    """argparse type: comma-separated names."""
    return [t.strip() for t in text.split(',') if t.strip()]


def alpha_list(text: str) -> list[float]:
    """argparse type: comma-separated alphas, each in [0, 1]."""
    return [alpha_value(t) for t in csv_list(text)]


def paper_cases(results: dict[Case, dict[str, Any]], cases: list[Case],
                defaults: tuple[str, str]) -> dict[Case, dict[str, Any]]:
    """The results of the cases that run the params file's follower and trust model (the
    configuration the paper's tables describe), keyed without those two axes.

    Args:
        results: every result.
        cases: the cases to take them from.
        defaults: the params file's (driver_model, trust_model).
    """
    out = {}
    for case in cases:
        if case.driver_model in ('', defaults[0]) and case.trust_model in ('', defaults[1]):
            out[dataclasses.replace(case, driver_model='', trust_model='')] = results[case]
    return out


def trend_checks(results: dict[Case, dict[str, Any]], traces: Sequence[str],
                 predictors: Sequence[str], alphas: Sequence[float]) -> list[str]:
    """The paper's trends (Tables II-IV), one line each: 'ok' or what broke (none with fewer
    than two alphas)."""
    lines: list[str] = []
    alphas = sorted(alphas)
    if len(alphas) < 2:
        return lines
    for predictor in predictors:
        for trace in traces:
            m = [results[Case(trace, predictor, a)]['metrics'] for a in alphas]
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
                problems.append(f'alpha = {alphas[-1]:g} not strictly better than alpha = '
                                f'{alphas[0]:g}')
            status = 'ok' if not problems else '; '.join(problems)
            lines.append(f'TAC-{predictor.upper()} {trace}: {status}')
    if {'gru', 'ca'} <= set(predictors) and 'us06' in traces:
        worse = [a for a in alphas
                 if not (results[Case('us06', 'gru', a)]['metrics']['final_trust']
                         > results[Case('us06', 'ca', a)]['metrics']['final_trust']
                         and results[Case('us06', 'gru', a)]['metrics']['mean_explicability']
                         < results[Case('us06', 'ca', a)]['metrics']['mean_explicability'])]
        lines.append('TAC-GRU beats TAC-CA on US06 (trust and E) for every alpha: '
                     + ('ok' if not worse else f'no, at alpha = {worse}'))
    return lines


def unsafe_cases(every: dict[Case, dict[str, Any]]) -> str:
    """One line naming the cases whose gaps went below the safety minimum (the study's
    warnings, summarised once; '' when none did)."""
    unsafe = {case: result['metrics']['unsafe_steps'] for case, result in every.items()
              if result['metrics']['unsafe_steps']}
    if not unsafe:
        return ''
    names = ', '.join(f'{c.trace} {c.predictor} alpha {c.alpha:g}'
                      f'{"".join(" " + m for m in (c.driver_model, c.trust_model) if m)}'
                      f'{f" driver {c.driver}" if c.driver else ""}'
                      f' ({steps} steps)' for c, steps in sorted(
                          unsafe.items(), key=lambda item: -item[1]))
    return (f'gap below the safety minimum in {len(unsafe)} of {len(every)} cases '
            f'(unsafe steps in all_runs.csv): {names}')


def truncation_note(max_steps: int, dt_s: float, trace_steps: list[int]) -> str:
    """The line every comparison with the paper carries when ``--max-steps`` cut a run short
    ('' when every run is whole)."""
    cut = [steps for steps in trace_steps if 0 < max_steps < steps]
    if not cut:
        return ''
    return (f'TRUNCATED: --max-steps {max_steps} stopped each run after {max_steps * dt_s:g} s '
            f"of {max(cut) * dt_s:g} s; the paper's values are for the whole drive, so no "
            'column or ratio here is comparable with them')


@dataclasses.dataclass(frozen=True)
class ReproduceOptions:
    """``trust-av reproduce``'s options (the axes each a tuple of values, in the order
    given)."""

    traces: tuple[str, ...] = option(
        '--traces', type=csv_list, default=list(sweep.TRACES),
        help='comma-separated traces: shipped names, CSV files or rosbag2 bags '
             '(default: %(default)s)')
    predictors: tuple[str, ...] = option(
        '--predictors', type=csv_list, default=list(sweep.PAPER_PREDICTORS),
        help=lambda: 'comma-separated registered plan estimators '
                     f'({", ".join(registry.names(PREDICTORS))}; default: %(default)s)')
    alphas: tuple[float, ...] = option(
        '--alphas', type=alpha_list, default=list(sweep.ALPHAS),
        help='comma-separated explicability weights in [0, 1] (default: %(default)s)')
    driver_models: tuple[str, ...] = option(
        '--driver-models', type=csv_list, default=[''],
        help=lambda: 'comma-separated registered follower models '
                     f'({", ".join(registry.names(DRIVERS))}; '
                     "default: the params file's driver_model)")
    trust_models: tuple[str, ...] = option(
        '--trust-models', type=csv_list, default=[''],
        help=lambda: 'comma-separated registered trust models '
                     f'({", ".join(registry.names(TRUST_MODELS)) or "none yet"}), set '
                     "as the trust_model parameter (default: the params file's)")
    executor: str = option('--executor', choices=('local', 'ray'), default='local',
                           help='local process pool (default) or a Ray cluster')
    workers: int | None = option(
        '--workers', type=positive_int, default=None,
        help=f'parallel workers, 1..{MAX_WORKERS} (default: one per core)')
    ray_address: str | None = option('--ray-address', default=None,
                                     help='Ray cluster address (default: start a local one)')
    graph: bool = option(
        '--graph',
        help='run every case through the ROS 2 node graph (six processes in '
             'lock-step, recorded to MCAP under RESULTS_DIR/graph_bags/) '
             'instead of in-process; same numbers, about 10 s per case')
    max_steps: int = option(
        '--max-steps', type=steps_value, default=0,
        help='stop every case after this many steps, for a quick check '
             "(default: whole traces; tables then differ from the paper's)")
    drivers: int = option(
        '--drivers', type=bounded_int('--drivers', 0, MAX_DRIVERS), default=0, metavar='K',
        help='run every case for K human drivers sampled (seeded) from the '
             "driver fit's per-driver fits instead of the params file's driver; "
             'tables then give mean ± 95 %% confidence interval per cell '
             f"(default: 0, the params file's driver; at most {MAX_DRIVERS})")
    drivers_seed: int = option(
        '--drivers-seed', type=bounded_int('--drivers-seed', 0, MAX_SEED), default=1,
        help='seed of the driver population (default: %(default)s)')
    driver_fit: Path | None = option(
        '--driver-fit', default=None,
        help='driver-fit file: its per-driver fits, or else its per-pair '
             'weights, are the population source (default: '
             'human_driver_sim/models/driver_fit.yaml for the '
             'human_cautious profile, the shipped driver_fit_caution.yaml '
             'otherwise)')
    profile: str = option(
        '--profile', choices=tuple(PROFILES), default='table_i',
        help="which parameters: table_i = the paper's Table I (epsilon 6, "
             "config/trust_av.yaml), as_reported = what the paper's printed "
             'mean E imply (epsilon 3, config/paper_as_reported.yaml; '
             'docs/RESULTS.md), paper_fitted = as_reported with P_thre 0.97 '
             "FITTED to the paper's final trusts (a hypothesis; "
             'config/paper_fitted_threshold.yaml), human_cautious = Table I with '
             'the cautious human driver, who never breaks d_s '
             '(config/human_cautious.yaml; '
             'docs/DRIVER_IRL.md); default: %(default)s')
    results_dir: Path | None = option(
        '--results-dir', default=None,
        help='where tables, figures and the cache go (default: results/paper '
             'for table_i, results/paper_<profile> for as_reported and '
             'paper_fitted, results/human_cautious for human_cautious)')
    params_files: tuple[Path, ...] = params_files_option()  # layered as in run and simulate
    lead_preview: str | None = lead_preview_option()
    no_progress: bool = option('--no-progress', help='no progress bar')


def run(args: ReproduceOptions) -> int:
    """Run ``trust-av reproduce``."""
    sweep.check_axis('--traces', args.traces)
    sweep.check_axis('--predictors', args.predictors)
    sweep.check_axis('--alphas', args.alphas)
    sweep.check_axis('--driver-models', args.driver_models)
    sweep.check_axis('--trust-models', args.trust_models)
    check_axes(args.predictors, args.driver_models, args.trust_models, args.alphas)
    if args.profile != 'table_i' and args.params_files:
        raise TrustAvAppError('--profile and --params-file both choose the parameters: give '
                              'one of them')
    files: list[Path] = list(args.params_files) or [PROFILES[args.profile]]
    out: Path = args.results_dir or DEFAULT_RESULTS[args.profile]
    if args.lead_preview is not None and args.lead_preview != 'recorded':
        out = args.results_dir or out.with_name(f'{out.name}_{args.lead_preview}')
    # everything is checked before anything is written (the results directory included)
    config = load_run_config(files, None if args.lead_preview is None else
                             {'planner': {'lead_preview': args.lead_preview}})
    for trace in args.traces:               # a bad trace is named before any case runs
        load_trace(trace, config.planner.dt_s, config.trace)
    cases = sweep.sweep_cases(args.traces, args.predictors, args.alphas, args.driver_models,
                              args.trust_models)
    if args.drivers:
        cases = population.population_cases(cases, args.drivers, args.drivers_seed,
                                       args.driver_fit or DRIVER_FITS.get(args.profile,
                                                                          DRIVER_FIT_FILE))
    if args.executor == 'ray':
        sweep.check_ray_address(args.ray_address)
    # one set: every table and figure, or (failed, stopped) the previous set as it was;
    # the sweep's cache and graph bags stay in the folder (resumable)
    with writing_set(out, command='reproduce', option='--results-dir',
                     keep=SWEEP_FOLDERS) as new:
        if args.lead_preview is not None:
            files.append(lead_preview_layer(args.lead_preview, new))
        executor: sweep.Executor
        if args.executor == 'ray':
            executor = sweep.RayExecutor(args.ray_address, args.workers)
        else:
            executor = sweep.LocalExecutor(args.workers)
        note = truncation_note(args.max_steps, config.planner.dt_s,
                               [load_trace(t, config.planner.dt_s, config.trace).steps
                                for t in args.traces])
        bar = Progress('reproduce', len(cases), shown=not args.no_progress)
        start = time.monotonic()
        runner = 'graph' if args.graph else 'in-process'
        every = sweep.run_sweep(cases, [str(f) for f in files], out, executor,
                                bar.update, runner=runner, max_steps=args.max_steps)
        bar.close()
        elapsed = time.monotonic() - start
        write_tidy_csv(new / 'all_runs.csv', tidy_rows(cases, every))
        # every trace's per-alpha table and trust figure, every axis kept (any traces)
        trace_reports.write_trace_reports(new, cases, every, files, note)
        print(f'per trace (every metric per alpha, every trust model and follower; trust over '
              f'time): {out / "by_trace"}/<trace>/ ({", ".join(trace_reports.FILES)})')
        crashed = [f'{case.label}: {every[case]["collision"]}' for case in cases
                   if every[case].get('collision')]
        if crashed:     # their metrics end at the collision (all_runs.csv, column collision)
            print(f'{len(crashed)} of {len(cases)} cases collided: ' + '; '.join(crashed))
        trust_model = sweep.parameter_value(config, TRUST_MODEL_PARAMETER)
        results = paper_cases(every, cases, (config.follower.driver_model, trust_model or ''))
        if results and len(results) < len(cases):
            print(f"Tables II-IV and Figure 3 are the paper's: {len(results)} of {len(cases)} "
                  f"cases, the params file's follower {config.follower.driver_model} and trust "
                  f'model {trust_model}; every trust model and follower is in by_trace/<trace>/')
        if not results:
            return _no_paper_table(cases, runner, elapsed, out)
        written, summary = _paper_outputs(args, config, new, results, note)
        for path in written:
            if path.endswith('.md'):
                print(f'\n## {path}\n' + (new / path).read_text())
    files = [out / f.name if f.parent == new else f for f in files]   # where they are now
    print('Trends of Tables II-IV (final trust up, mean E and RMSE down with alpha):')
    if args.drivers:
        print(f'(a population of {args.drivers} drivers, seed {args.drivers_seed}: tables give '
              'mean ± 95 % CI over drivers; trends and Figure 3 use the means)')
    for line in trend_checks(summary, args.traces, args.predictors, args.alphas):
        print(f'  {line}')
    components = '; '.join(f'{name}: {params}' for name, params in config.predictor_configs)
    print(f'\nProfile {args.profile} ({", ".join(str(f) for f in files)}): epsilon_mps2 = '
          f'{config.trust.epsilon_mps2:g}, performance_threshold = '
          f'{config.trust.performance_threshold:g}, explicability_scale = '
          f'{config.planner.explicability_scale:g}; plan estimator parameters: '
          f'{components or "none"} (the GRU was trained behind the default profile)')
    print(f'{len(cases)} cases ({runner}) in {elapsed:.1f} s wall; outputs in {out}/: '
          + ', '.join(written))
    unsafe = unsafe_cases(every)
    if unsafe:
        print(unsafe)
    if note:
        print(note)
    if args.graph:
        print(f'graph recordings (MCAP, one per case): {out / "graph_bags"}/')
    return 0


def _paper_outputs(args: ReproduceOptions, config: RunConfig, new: Path,
                   results: dict[Case, dict[str, Any]], note: str
                   ) -> tuple[list[str], dict[Case, dict[str, Any]]]:
    """The paper's Tables II-IV and Figures 2-3 written into ``new``: the names written
    (``all_runs.csv`` first) and the results their trends are read from (a population's
    means, or the cases themselves)."""
    written = ['all_runs.csv']
    if args.drivers:
        alpha_table, improvement_table = (tables.population_alpha_table,
                                          tables.population_improvement_table)
        summary = population.population_mean(results)  # trends and Figure 3 on the means
    else:
        alpha_table, improvement_table = tables.alpha_table, tables.improvement_table
        summary = results
    if 'us06' in args.traces:
        for predictor, name, paper in (
                ('gru', 'table_II_tac_gru_us06', TABLE_II_TAC_GRU_US06),
                ('ca', 'table_III_tac_ca_us06', TABLE_III_TAC_CA_US06)):
            if predictor in args.predictors:
                us06_steps = load_trace('us06', config.planner.dt_s, config.trace).steps
                # The bound column is derived from the paper's update: only for a model
                # that declares it runs that update (model_interface.paper_bound_holds).
                bound = ((us06_steps, config.trust)
                         if paper_bound_holds(config.trust_model()) else None)
                tables.write_rows(new / name, *alpha_table(results, 'us06', predictor,
                                                           paper, bound), note=note)
                written.append(f'{name}.md')
    tables.write_rows(new / 'table_IV_max_improvements',
                      *improvement_table(results, args.traces, args.predictors), note=note)
    written.append('table_IV_max_improvements.md')
    traces = [load_trace(t, config.planner.dt_s, config.trace) for t in args.traces]
    speed_profiles(traces, new / 'figure_2_speed_profiles.png')
    written.append('figure_2_speed_profiles.png')
    if 'us06' in args.traces:
        series = {f'TAC-{p.upper()}': {a: (summary[Case('us06', p, a)]['time_s'],
                                           summary[Case('us06', p, a)]['trust'])
                                       for a in args.alphas}
                  for p in args.predictors}
        trust_over_time(series, 'us06', new / 'figure_3_trust_us06.png',
                        trust_ceiling(config.trust_model()), note=note)
        written.append('figure_3_trust_us06.png')
    return written, summary


def _no_paper_table(cases: Sequence[Case], runner: str, elapsed: float, out: Path) -> int:
    print(f'{len(cases)} cases ({runner}) in {elapsed:.1f} s wall; no case runs the '
          "params file's follower and trust model, so no paper table: every run is in "
          f'{out / "all_runs.csv"}')
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add ``reproduce`` to ``trust-av``."""
    parser = subparsers.add_parser(
        'reproduce', help="a study of any registered parts; the paper's Tables II-IV and "
                          'Figures 2-3',
        description='Run every combination of traces x predictors x trust models x driver '
                    'models x alphas with one configuration, in parallel, and write '
                    'all_runs.csv (one row per run, every setting and metric a column); for '
                    "the cases with the params file's follower and trust model also Tables "
                    "II-IV (Markdown and CSV, ours beside the paper's where it printed the "
                    'case) and Figures 2-3 (PNG). Finished cases are cached by a hash of case, '
                    'params files and code, so a rerun only runs what changed. Every axis '
                    'needs a value and holds each value once (an empty axis or a duplicate is '
                    'refused, exit 2): one row per distinct case.')
    add_command(parser, ReproduceOptions, run)
