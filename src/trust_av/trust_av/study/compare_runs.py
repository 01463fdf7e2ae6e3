"""Two runs side by side: speeds, gaps, accelerations, explicability and every trust model's
trust over time, one column per run (``trust-av compare``, :func:`compare_runs`).

A run is what the project records:

- a rosbag2 recording of the node graph (``trust-av run --bag``, ``reproduce --graph``'s
  ``graph_bags/<case>/``): its directory, or the ``.mcap`` file in it;
- a drive of the driver-in-the-loop study (``trust-av drive``: a bag of its study
  directory), read as the analysis reads it (:func:`~trust_av.drive.bag_data.read_drive`):
  at each plan's time, the vehicles' odometry (gaps bumper to bumper, the person's
  acceleration from their speed), the plan's first acceleration and its E;
- the per-step CSV of the in-process simulator (``trust-av simulate --out``).

Trust per model is every chosen trust model run over the run's explicability E (the same
update the trust monitor makes, step by step with each step's length) and read on the common
scale [0, 1] (:func:`~trust_monitor.model_interface.common_trust`), so runs recorded with any
model are compared under every model. The model the run itself ran is one of them; with the
params file it ran with, its line is the run's recorded trust on the common scale.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from trust_av.errors import TrustAvAppError
from trust_av.study.plots import pyplot, save_figure
from trust_av.system.config import load_run_config
from trust_av.system.metrics import StepRecord
from trust_av_common.errors import with_suggestions
from trust_av_common.registry import names
from trust_monitor.model_interface import TRUST_MODELS, common_trust, make_trust_model
from trust_monitor.paper_trust import explicability
from trust_monitor.trust_fit import FitError

__all__ = ['compare_runs', 'read_run', 'trust_per_model']

SERIES = ('traffic_speed_mps', 'av_speed_mps', 'human_speed_mps', 'av_gap_m', 'human_gap_m',
          'av_accel_mps2', 'human_accel_mps2', 'explicability')
"""The per-step values a run must hold besides its time ``t_s`` (a simulate CSV's columns)."""
FIGURE_SUFFIXES = ('.png', '.pdf', '.svg')


@dataclass(frozen=True)
class RunSeries:
    """One run's per-step series (time from the run's first step, s).

    Attributes:
        name: how the figure names the run.
        t_s: each step's time since the first, s.
        values: each of :data:`SERIES` per step.
    """

    name: str
    t_s: np.ndarray
    values: dict[str, np.ndarray]

    def __post_init__(self) -> None:
        if len(self.t_s) < 2:
            raise TrustAvAppError(f'{self.name}: {len(self.t_s)} step(s); a run to compare '
                                  'needs at least two')
        if not np.all(np.diff(self.t_s) > 0):
            raise TrustAvAppError(f'{self.name}: step times do not increase')
        for key, series in self.values.items():
            if len(series) != len(self.t_s) or not np.all(np.isfinite(series)):
                raise TrustAvAppError(f'{self.name}: {key} is not one finite number per '
                                      'step')


def from_records(name: str, records: Sequence[StepRecord]) -> RunSeries:
    """A run's series from its :class:`~trust_av.system.metrics.StepRecord`."""
    if not records:
        raise TrustAvAppError(f'{name}: no complete step recorded')
    t = np.array([r.t_s for r in records], float)
    return RunSeries(name, t - t[0], {key: np.array([getattr(r, key) for r in records], float)
                                      for key in SERIES})


def read_csv_run(path: Path) -> RunSeries:
    """A ``trust-av simulate --out`` table (or one made like it), read as every input table
    is (:func:`~trust_av.drive.table_input.table_rows`: a size limit, UTF-8 with or without a
    byte-order mark or UTF-16, comma, semicolon or tab): every value of the columns it needs
    a finite number, ``t_s`` increasing from row to row, at least two rows.

    Raises:
        FitError: one line naming the file, the line and the column.
    """
    from trust_av.drive.table_input import cell_number, table_rows

    needed = ('t_s', *SERIES)
    values: dict[str, list[float]] = {column: [] for column in needed}
    for line, row, decimal in table_rows(path, needed):
        for column in needed:
            value = cell_number(row[column], f'{path}:{line}: column {column}', decimal)
            if value is None:
                raise FitError(f'{path}:{line}: column {column} is empty')
            values[column].append(value)
        times = values['t_s']
        if len(times) > 1 and times[-1] <= times[-2]:
            raise FitError(f'{path}:{line}: column t_s: {times[-1]:g} s is not after the row '
                           f'before ({times[-2]:g} s): rows out of order, or one given twice?')
    if len(values['t_s']) < 2:
        raise FitError(f'{path}: one row; a run to compare needs at least two')
    t = np.array(values.pop('t_s'))
    return RunSeries(path.name, t - t[0],
                     {column: np.array(series) for column, series in values.items()})


def read_drive_run(bag: Path, params_files: Sequence[str | Path] = ()) -> RunSeries:
    """A ``trust-av drive`` recording as a run: every series at the AV's plan times.

    Raises:
        TrustAvAppError: not a complete drive (no plans, a vehicle without odometry).
    """
    from trust_av.drive.bag_data import read_drive  # rosbags: only for a bag

    config = load_run_config(list(params_files))
    drive = read_drive(bag)
    t = np.asarray(drive.series.times_s, float)
    if len(t) < 2:
        raise TrustAvAppError(f'{bag}: {len(t)} plan(s) recorded; a run to compare needs '
                              'at least two')
    at: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for vehicle, topic in (('traffic', '/preceding_vehicle/odom'), ('av', '/ego/odom'),
                           ('human', '/human/odom')):
        rows = drive.odometry[topic]
        if len(rows) < 2:
            raise TrustAvAppError(f'{bag}: no odometry on {topic}')
        at[vehicle] = (np.interp(t, rows[:, 0], rows[:, 1]), np.interp(t, rows[:, 0], rows[:, 2]))
    length = config.shared.vehicle_length_m
    scores = [explicability(p, e, config.trust.epsilon_mps2)
              for p, e in zip(drive.series.plans, drive.series.expected, strict=True)]
    values = {'traffic_speed_mps': at['traffic'][1], 'av_speed_mps': at['av'][1],
              'human_speed_mps': at['human'][1],
              'av_gap_m': at['traffic'][0] - at['av'][0] - length,
              'human_gap_m': at['av'][0] - at['human'][0] - length,
              'av_accel_mps2': np.array([p[0] for p in drive.series.plans], float),
              'human_accel_mps2': np.gradient(at['human'][1], t),
              'explicability': np.asarray(scores, float)}
    return RunSeries(bag.name, t - t[0], values)


def read_run(path: str | Path, params_files: Sequence[str | Path] = ()) -> RunSeries:
    """A run from its recording (a bag directory or its ``.mcap``: the graph's or a
    drive's) or its simulate CSV.

    Args:
        path: the run.
        params_files: params files layered over the shipped one (a drive's E and gaps take
            its epsilon and vehicle length).

    Raises:
        TrustAvAppError: no such file, not a run, or a run without two complete steps.
    """
    path = Path(path)
    if not path.exists():
        raise TrustAvAppError(f'{path}: no such file or directory (give a bag directory, '
                              'its .mcap, or a trust-av simulate --out CSV)')
    if path.is_file() and path.suffix == '.csv':
        return read_csv_run(path)
    bag = path.parent if path.is_file() and path.suffix == '.mcap' else path
    if not (bag / 'metadata.yaml').is_file():
        raise TrustAvAppError(f'{path}: not a run (neither a rosbag2 directory with '
                              'metadata.yaml, its .mcap, nor a .csv)')
    # Imported here: reading a CSV needs no rosbags.
    from trust_av.drive.bag_data import custom_data
    from trust_av.graph.bag_records import records_from_bag
    if 'trust_av.drive.start_ns' in custom_data(bag):
        return read_drive_run(bag, params_files)
    return from_records(bag.name, records_from_bag(bag))


def model_names(models: Sequence[str] | None) -> list[str]:
    """The chosen trust models (None or empty: every registered one).

    Raises:
        TrustAvAppError: a name that is not registered (one line, with suggestions).
    """
    registered = list(names(TRUST_MODELS))
    chosen = [m for m in (models or []) if m] or registered
    unknown = [m for m in chosen if m not in registered]
    if unknown:
        raise TrustAvAppError(f'trust model(s) {with_suggestions(unknown, registered)} '
                              f'not registered; registered: {registered}')
    return list(dict.fromkeys(chosen))


def trust_per_model(run: RunSeries, models: Sequence[str],
                    params_files: Sequence[str | Path] = ()) -> dict[str, np.ndarray]:
    """Each model's trust after each step of ``run`` on the common scale [0, 1], from the
    run's E (each step lasts until the next; the last as long as the median step).

    Args:
        run: the run.
        models: registered trust models.
        params_files: params files (layered over the shipped one) for the models' values.
    """
    config = load_run_config(list(params_files))
    steps = np.diff(run.t_s)
    durations = np.append(steps, np.median(steps))
    scores = np.clip(run.values['explicability'], 0.0, 1.0)
    out = {}
    for name in models:
        model = make_trust_model(dataclasses.replace(config.trust, trust_model=name),
                                 dict(config.trust_model_params))
        state = model.initial_state()
        trust = []
        for score, dt_s in zip(scores, durations, strict=True):
            state = model.step(state, float(score), float(dt_s))
            trust.append(common_trust(model, state))
        out[name] = np.array(trust)
    return out


def _summary(run: RunSeries) -> str:
    values = run.values
    return (f'{run.t_s[-1]:g} s, mean E {float(np.mean(values["explicability"])):.4f}, '
            f'min gaps AV {float(np.min(values["av_gap_m"])):.1f} m, '
            f'human {float(np.min(values["human_gap_m"])):.1f} m')


def draw(runs: Sequence[RunSeries], trust: Sequence[dict[str, np.ndarray]], path: Path) -> None:
    """The side-by-side figure: a column per run, a row per quantity, each row on one
    y scale so the columns compare by eye."""
    plt = pyplot()
    rows = 5
    fig, axes = plt.subplots(rows, len(runs), figsize=(6.0 * len(runs), 12.0), sharex='col',
                             sharey='row', squeeze=False)
    for col, (run, models) in enumerate(zip(runs, trust, strict=True)):
        t, v = run.t_s, run.values
        ax = axes[:, col]
        ax[0].plot(t, v['traffic_speed_mps'], label='preceding traffic', color='tab:grey')
        ax[0].plot(t, v['av_speed_mps'], label='AV', color='tab:blue')
        ax[0].plot(t, v['human_speed_mps'], label='human', color='tab:orange', linestyle='--')
        ax[1].plot(t, v['av_gap_m'], label='AV to traffic', color='tab:blue')
        ax[1].plot(t, v['human_gap_m'], label='human to AV', color='tab:orange',
                   linestyle='--')
        ax[2].plot(t, v['av_accel_mps2'], label='AV', color='tab:blue')
        ax[2].plot(t, v['human_accel_mps2'], label='human', color='tab:orange', linestyle='--')
        ax[3].plot(t, v['explicability'], color='tab:red', label='E')
        for name, series in models.items():
            ax[4].plot(t, series, label=name, linewidth=1.2)
        ax[0].set_title(f'{run.name}\n{_summary(run)}', fontsize=9)
        ax[-1].set_xlabel('time since the start of the run (s)')
        for a in ax:
            a.grid(alpha=0.3)
            a.legend(fontsize=7, loc='best')
    for a, label in zip(axes[:, 0], ('speed (m/s)', 'gap (m)', 'acceleration (m/s²)',
                                     'explicability E', 'trust (common scale)'), strict=True):
        a.set_ylabel(label)
    fig.suptitle("Two runs side by side (trust: every model over each run's E, common scale "
                 '[0, 1])', fontsize=10)
    fig.tight_layout()
    save_figure(fig, path, dpi=100)
    plt.close(fig)


def compare_runs(run_a: str | Path, run_b: str | Path, out: str | Path, *,
                 models: Sequence[str] | None = None,
                 params_files: Sequence[str | Path] = (),
                 labels: Sequence[str] | None = None) -> dict[str, dict[str, float]]:
    """Draw two runs side by side into ``out`` (PNG, PDF or SVG, by its suffix).

    Args:
        run_a: a bag directory, its ``.mcap``, or a ``trust-av simulate --out`` CSV.
        run_b: the same for the other run.
        out: the figure to write (whole or not at all).
        models: registered trust models to draw (None: every registered one).
        params_files: params files layered over the shipped one, for the models' values.
        labels: the two runs' names in the figure (default: their file names).

    Returns:
        Per run label, each model's final trust on the common scale.

    Raises:
        TrustAvAppError: a run that cannot be read, an unknown model, an output
            suffix that is not a figure's (one line naming it).
    """
    out = Path(out)
    if out.suffix.lower() not in FIGURE_SUFFIXES:
        raise TrustAvAppError(f'{out}: the figure must end in one of '
                              f'{", ".join(FIGURE_SUFFIXES)}')
    chosen = model_names(models)
    if labels is not None and (len(labels) != 2 or not all(labels)):
        raise TrustAvAppError(f'labels: need two names, got {list(labels)}')
    runs = [read_run(run_a, params_files), read_run(run_b, params_files)]
    if labels is not None:
        runs = [dataclasses.replace(run, name=label) for run, label in zip(runs, labels,
                                                                            strict=True)]
    elif runs[0].name == runs[1].name:
        runs = [dataclasses.replace(run, name=f'{run.name} ({side})')
                for run, side in zip(runs, ('A', 'B'), strict=True)]
    trust = [trust_per_model(run, chosen, params_files) for run in runs]
    draw(runs, trust, out)
    return {run.name: {m: float(series[-1]) if len(series) else math.nan
                       for m, series in models_trust.items()}
            for run, models_trust in zip(runs, trust, strict=True)}
