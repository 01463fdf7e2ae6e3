"""A study from any registered parts, as one tidy table: one row per run, every setting and
every metric a column.

The axes are traces (shipped names, CSVs, bags) x plan estimators x trust models x follower
models x alpha (x a sampled driver population); each case runs once, on the sweep's
executors and cache (:mod:`trust_av.study.sweep`). ``trust-av reproduce`` writes the
table as ``all_runs.csv``; from Python :func:`study` returns it as a pandas DataFrame and
writes each trace's tables and trust figure (:mod:`trust_av.study.trace_reports`)::

    from trust_av.study.frame import study

    if __name__ == '__main__':    # study() starts worker processes: run it as a script
        runs = study(['us06'], ['ca', 'cv'], [0.0, 1.0], driver_models=['mpc', 'idm'],
                     results_dir='results/mine')
        print(runs.groupby(['predictor', 'driver_model']).final_trust.mean())
"""

from __future__ import annotations

import csv
import dataclasses
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from human_driver_sim.followers import DRIVERS
from trust_av.errors import TrustAvAppError
from trust_av.study import sweep
from trust_av.study.sweep import Case
from trust_av.study.trace_reports import write_trace_reports
from trust_av.system.config import DEFAULT_PARAMS_FILE, all_components
from trust_av_common import output_files, registry
from trust_av_common.errors import with_suggestions
from trust_av_planner.predictors import PREDICTORS
from trust_monitor.model_interface import TRUST_MODELS

if TYPE_CHECKING:
    import pandas as pd

__all__ = ['TRUST_MODEL_PARAMETER', 'check_axes', 'study', 'tidy_rows', 'write_tidy_csv']

TRUST_MODEL_PARAMETER = 'trust_model'
"""The parameter (``/**`` section) that names the registered trust model a run uses."""


def check_axes(predictors: Iterable[str], driver_models: Iterable[str],
               trust_models: Iterable[str], alphas: Iterable[float]) -> None:
    """Refuse names that are not registered, and alphas outside [0, 1] ('' in a model axis
    is the params file's choice).

    Raises:
        TrustAvAppError: one line naming the bad value and what is registered.
    """
    for what, group, values in (('predictor', PREDICTORS, predictors),
                                ('driver model', DRIVERS, driver_models),
                                ('trust model', TRUST_MODELS, trust_models)):
        known = registry.names(group)
        unknown = [v for v in values if v and v not in known]
        if unknown:
            raise TrustAvAppError(f'unknown {what}(s) {with_suggestions(unknown, known)}; '
                                  f'registered: {list(known)}')
    if any(trust_models) and not any(f.name == TRUST_MODEL_PARAMETER for c in all_components()
                                     for f in dataclasses.fields(c)):
        raise TrustAvAppError(f'trust models {[m for m in trust_models if m]}: no component '
                              f'declares the {TRUST_MODEL_PARAMETER} parameter yet, so '
                              "only the params file's trust model can run")
    bad = [a for a in alphas if not 0.0 <= a <= 1.0]
    if bad:
        raise TrustAvAppError(f'alpha must be in [0, 1], got {bad}')


def tidy_rows(cases: Sequence[Case], results: dict[Case, dict[str, Any]]
              ) -> list[dict[str, Any]]:
    """One row per case, in case order: its settings as it ran, then its metrics, then
    ``collision``: ``none``, or the line naming the step and the vehicles (the metrics then
    end with that step)."""
    return [{**results[case]['settings'], **results[case]['metrics'],
             'collision': results[case].get('collision') or 'none'} for case in cases]


def write_tidy_csv(path: Path, rows: Sequence[dict[str, Any]]) -> None:
    """The rows as CSV; the columns are every key in first-seen order (a component's own
    parameters are empty in the rows of other components)."""
    columns = list(dict.fromkeys(key for row in rows for key in row))
    with output_files.replacing(path) as (target,), target.open('w', newline='') as handle:
        writer = csv.DictWriter(handle, fieldnames=columns, restval='')
        writer.writeheader()
        writer.writerows(rows)


def study(traces: Iterable[str] = sweep.TRACES,
          predictors: Iterable[str] = sweep.PAPER_PREDICTORS,
          alphas: Iterable[float] = sweep.ALPHAS, *,
          driver_models: Iterable[str] = ('',), trust_models: Iterable[str] = ('',),
          params_files: str | Path | Sequence[str | Path] = DEFAULT_PARAMS_FILE,
          results_dir: str | Path = 'results/study', executor: sweep.Executor | None = None,
          runner: str = 'in-process', max_steps: int = 0,
          trace_reports: bool = True) -> pd.DataFrame:
    """Run every combination (cached in ``results_dir/cache`` as ``trust-av reproduce``)
    and return the tidy table as a DataFrame, the rows of ``reproduce``'s ``all_runs.csv``;
    write each trace's per-alpha tables and trust figure into
    ``results_dir/by_trace/<trace>/`` as ``reproduce`` does
    (:mod:`~trust_av.study.trace_reports`).

    Call it from a script's ``if __name__ == '__main__':`` block: the local executor starts
    worker processes, which import the script again.

    Args:
        traces: shipped trace names, CSV files or rosbag2 bags.
        predictors: registered plan estimators.
        alphas: explicability weights in [0, 1].
        driver_models: registered follower models ('' = the params file's).
        trust_models: registered trust models ('' = the params file's), set as the
            ``trust_model`` parameter.
        params_files: params file(s), layered in order over the shipped one.
        results_dir: where the cache (and graph recordings) go.
        executor: where cases run (default: a local process pool, one per core).
        runner: ``in-process`` or ``graph``.
        max_steps: stop each run after this many steps (0: the whole trace).
        trace_reports: write the per-trace tables and figures (False: the table only).

    Raises:
        TrustAvAppError: an unregistered name, an alpha outside [0, 1], a case that
            failed (named).
    """
    import pandas as pd

    predictors, driver_models = list(predictors), list(driver_models)
    trust_models, alphas = list(trust_models), list(alphas)
    check_axes(predictors, driver_models, trust_models, alphas)
    cases = sweep.sweep_cases(list(traces), predictors, alphas, driver_models, trust_models)
    results = sweep.run_sweep(cases, params_files, Path(results_dir),
                              executor or sweep.LocalExecutor(), runner=runner,
                              max_steps=max_steps)
    if trace_reports:
        write_trace_reports(Path(results_dir), cases, results, params_files)
    return pd.DataFrame(tidy_rows(cases, results))
