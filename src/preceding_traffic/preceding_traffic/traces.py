"""Speed traces of the preceding traffic: load, validate, resample onto the control grid, preview.

A trace is a CSV with the header ``time_s,speed_mps``. Shipped traces (``us06``, ``nycc``,
``commute_am``, ``commute_pm``) are selected by name; any other argument is read as a path.
Validation errors name the file, the row (1-based line number, header = line 1) and the
problem.
"""

from __future__ import annotations

import csv
import dataclasses
import math
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from preceding_traffic.errors import PrecedingTrafficError
from trust_monitor.common.params import ParamsError, check_fields, param

SHIPPED_TRACES = ('us06', 'nycc', 'commute_am', 'commute_pm')
"""Evaluation traces shipped in ``data/`` (sources and licences in ``data/SOURCES.md``)."""
TRAINING_TRACES = ('udds', 'hwfet', 'wltc_3b')
"""Traces for training learned models only, in ``data/training/``."""


class TraceError(PrecedingTrafficError):
    """A speed trace is unusable; the message names the file, row and problem."""


@dataclass(frozen=True)
class TraceConfig:
    """How traces are read.

    Attributes:
        trace: shipped trace name (see :data:`SHIPPED_TRACES`), a CSV path, or a rosbag2 bag
            (a directory with ``metadata.yaml``, or a ``.mcap``/``.db3`` file).
        max_sample_gap_s: longest interval between two samples that is still interpolated, s.
        bag_topic: the preceding vehicle's topic when ``trace`` is a bag.
        bag_message_type: its type: ``nav_msgs/msg/Odometry`` or
            ``geometry_msgs/msg/TwistStamped``.
    """

    trace: str = param('shipped trace name, time_s,speed_mps CSV or rosbag2 bag')
    max_sample_gap_s: float = param('longest hole in a trace that is interpolated', unit='s',
                                    low=0.0, low_inclusive=False)
    bag_topic: str = param('topic replayed when trace is a bag',
                           default='/preceding_vehicle/odom')
    bag_message_type: str = param('its type: nav_msgs/msg/Odometry or '
                                  'geometry_msgs/msg/TwistStamped',
                                  default='nav_msgs/msg/Odometry')

    def __post_init__(self) -> None:
        try:
            check_fields(self)
        except ParamsError as err:
            raise TraceError(str(err)) from err


@dataclass(frozen=True)
class SpeedTrace:
    """A validated speed trace on a uniform control grid.

    Attributes:
        name: trace name or file stem.
        dt_s: control step, s.
        speeds_mps: preceding-traffic speed at t0 + k*dt_s, m/s.
        t0_s: time of the first sample, s.
    """

    name: str
    dt_s: float
    speeds_mps: np.ndarray
    t0_s: float = 0.0

    @property
    def steps(self) -> int:
        """Number of control steps (one fewer than grid points)."""
        return len(self.speeds_mps) - 1

    @property
    def max_speed_mps(self) -> float:
        """max(v_PT): Table I's speed limit for both vehicles."""
        return float(np.max(self.speeds_mps))

    def time_s(self, step: int) -> float:
        """Time of grid point ``step``, s."""
        return self.t0_s + step * self.dt_s

    def preview(self, step: int, horizon: int) -> np.ndarray:
        """Speeds at steps ``step .. step+horizon-1``; past the end the last speed is held."""
        idx = np.minimum(np.arange(step, step + horizon), len(self.speeds_mps) - 1)
        return self.speeds_mps[idx]


def trace_path(name_or_path: str) -> Path:
    """Path of a shipped trace (by name) or of a user file."""
    name = name_or_path.lower()
    if name in SHIPPED_TRACES:
        return Path(str(resources.files('preceding_traffic') / 'data' / f'{name}.csv'))
    if name in TRAINING_TRACES:
        return Path(str(resources.files('preceding_traffic') / 'data' / 'training'
                        / f'{name}.csv'))
    return Path(name_or_path)


def read_samples(path: Path, config: TraceConfig) -> tuple[np.ndarray, np.ndarray]:
    """Read and validate raw ``(time_s, speed_mps)`` samples.

    Raises:
        TraceError: missing file, wrong columns, empty, non-numeric, NaN/inf, negative speed,
            non-increasing time, or a sample gap longer than ``config.max_sample_gap_s``.
    """
    try:
        handle = path.open(newline='')
    except OSError as err:
        raise TraceError(f'{path}: cannot open trace ({err.strerror})') from err
    times: list[float] = []
    speeds: list[float] = []
    with handle:
        reader = csv.reader(handle)
        header = next(reader, None)
        if header is None:
            raise TraceError(f'{path}: empty file (expected header time_s,speed_mps)')
        if [h.strip() for h in header] != ['time_s', 'speed_mps']:
            raise TraceError(f'{path}:1: expected columns time_s,speed_mps, '
                             f'got {",".join(header)}')
        for line, row in enumerate(reader, start=2):
            if not row:
                continue
            if len(row) != 2:
                raise TraceError(f'{path}:{line}: expected 2 values, got {len(row)}')
            try:
                t, v = float(row[0]), float(row[1])
            except ValueError as err:
                raise TraceError(f'{path}:{line}: not a number ({err})') from err
            if not (math.isfinite(t) and math.isfinite(v)):
                raise TraceError(f'{path}:{line}: NaN or infinite value ({row[0]}, {row[1]})')
            if v < 0.0:
                raise TraceError(f'{path}:{line}: negative speed {v} m/s')
            if times and t <= times[-1]:
                raise TraceError(f'{path}:{line}: time {t} s does not increase '
                                 f'(previous {times[-1]} s)')
            if times and t - times[-1] > config.max_sample_gap_s:
                raise TraceError(f'{path}:{line}: gap of {t - times[-1]:g} s before t = {t:g} s '
                                 f'exceeds max_sample_gap_s = {config.max_sample_gap_s:g} s')
            times.append(t)
            speeds.append(v)
    if len(times) < 2:
        raise TraceError(f'{path}: needs at least 2 samples, got {len(times)}')
    return np.asarray(times), np.asarray(speeds)


def resample(times_s: np.ndarray, speeds_mps: np.ndarray, dt_s: float) -> np.ndarray:
    """Linear interpolation onto ``times_s[0] + k*dt_s`` up to the last sample."""
    if not dt_s > 0.0:
        raise TraceError(f'dt_s must be > 0, got {dt_s}')
    count = math.floor((times_s[-1] - times_s[0]) / dt_s + 1e-9) + 1
    grid = times_s[0] + dt_s * np.arange(count)
    speeds: np.ndarray = np.interp(grid, times_s, speeds_mps)
    return speeds


def truncate(trace: SpeedTrace, max_steps: int) -> SpeedTrace:
    """The first ``max_steps`` control steps of ``trace`` (all of it for 0)."""
    if max_steps < 0:
        raise ValueError(f'max_steps must be >= 0, got {max_steps}')
    if not max_steps:
        return trace
    return dataclasses.replace(trace, speeds_mps=trace.speeds_mps[:max_steps + 1])
