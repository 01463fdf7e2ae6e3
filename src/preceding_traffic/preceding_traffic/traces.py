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
import os
import stat
from collections.abc import Iterator
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from preceding_traffic.errors import PrecedingTrafficError
from trust_av_common.errors import did_you_mean
from trust_av_common.input_files import bounded_lines, not_regular
from trust_av_common.params import MAX_STAMP_S, ParamsError, check_fields, param

__all__ = ['MAX_SPEED_MPS', 'MAX_TRACE_STEPS', 'SHIPPED_TRACES', 'TRAINING_TRACES', 'SpeedTrace',
           'TraceConfig', 'TraceError', 'check_accelerations', 'check_sample', 'read_samples',
           'resample', 'trace_path', 'truncate']

MAX_SPEED_MPS = 100.0
"""Fastest speed a trace may hold, m/s (360 km/h: above any road vehicle; a faster sample is
a unit or column mistake)."""
MAX_TIME_S = MAX_STAMP_S
"""Latest sample time a trace may hold, s: a run stamps its messages with the trace's time
(:data:`trust_av_common.params.MAX_STAMP_S`)."""
MAX_TRACE_STEPS = 200_000
"""Most control steps a trace may have (55 h at 1 s, 5.5 h at 0.1 s): the in-process loop
keeps one record per step (2.9 kB measured on US06), so this bounds it to about 0.6 GB."""
MAX_LINE_CHARS = 4096
"""Longest line of a trace CSV (a binary file has no line ends)."""

TRACE_ACCEL_MAX_MPS2 = 5.0
"""Default ``trace_accel_max_mps2``: the fastest speed-up of a trace, m/s^2. Above every
standard drive cycle (EPA US06, the aggressive-driving cycle, peaks at 3.76 m/s^2 in
``data/us06.csv``; the other shipped and training traces at 1.4-2.7 m/s^2) and a brisk
passenger car at full throttle (0-100 km/h in 6 s is 4.6 m/s^2 on average). A trace in
km/h read as m/s speeds up 3.6 times as fast: every shipped trace so read is above it."""
TRACE_BRAKE_MAX_MPS2 = 9.81
"""Default ``trace_brake_max_mps2``: the hardest braking of a trace, m/s^2: a tyre on dry
asphalt transmits at most about 1 g (friction coefficient up to about 1.0; emergency stops
of passenger cars reach 8-10 m/s^2)."""
TRACE_STOPPING_SPEED_MAX_MPS = 150.0 / 3.6
"""Default ``trace_stopping_speed_max_mps``: the fastest a trace that also comes to a
standstill may drive, m/s (150 km/h, above every posted motorway limit but unrestricted
German Autobahn stretches; WLTC class 3b, the fastest cycle with stops, peaks at
131 km/h, US06 at 129 km/h). Stop-and-go driving above it is mostly speeds in km/h read as
m/s: a gentle urban trace so read keeps its accelerations below ``trace_accel_max_mps2``
(3.6 x 1.4 m/s^2) but not its speeds (3.6 x 50 km/h = 180 "km/h")."""
STANDSTILL_MPS = 0.5
"""A sample this slow is a standstill (for ``trace_stopping_speed_max_mps``), m/s."""
ACCEL_WINDOW_S = 1.0
"""Accelerations of a trace are checked as speed changes over this window (a noisy 10 Hz
odometry is not a hard acceleration), s."""

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
                                    low=0.0, low_inclusive=False, high=3600.0)
    bag_topic: str = param('topic replayed when trace is a bag',
                           default='/preceding_vehicle/odom')
    bag_message_type: str = param('its type: nav_msgs/msg/Odometry or '
                                  'geometry_msgs/msg/TwistStamped',
                                  default='nav_msgs/msg/Odometry')
    trace_accel_max_mps2: float = param(
        'fastest speed-up a trace may hold (over any 1 s); more is a unit mistake (km/h)',
        unit='m/s^2', low=0.0, low_inclusive=False, high=100.0,
        default=TRACE_ACCEL_MAX_MPS2)
    trace_brake_max_mps2: float = param(
        'hardest braking a trace may hold (over any 1 s, a magnitude); more is a unit '
        'mistake (km/h)', unit='m/s^2', low=0.0, low_inclusive=False, high=100.0,
        default=TRACE_BRAKE_MAX_MPS2)
    trace_stopping_speed_max_mps: float = param(
        'fastest speed a trace that also comes to a standstill may reach (stop-and-go above '
        'motorway speeds); more is a unit mistake (km/h)', unit='m/s', low=0.0,
        low_inclusive=False, high=MAX_SPEED_MPS, default=TRACE_STOPPING_SPEED_MAX_MPS)

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
        speeds_mps: preceding-traffic speed at t0 + k*dt_s, m/s (the whole trace).
        t0_s: time of the first sample, s.
        step_limit: run only this many steps (0: all); the preview past it is the
            recorded future, as in the whole run.
        source: the file it was read from ('' if none), for messages.
    """

    name: str
    dt_s: float
    speeds_mps: np.ndarray
    t0_s: float = 0.0
    step_limit: int = 0
    source: str = ''

    @property
    def steps(self) -> int:
        """Number of control steps: one fewer than grid points, at most ``step_limit``."""
        whole = len(self.speeds_mps) - 1
        return min(whole, self.step_limit) if self.step_limit else whole

    @property
    def max_speed_mps(self) -> float:
        """max(v_PT) over the whole trace: Table I's speed limit for both vehicles (the same
        for a run limited to its first steps)."""
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


def check_sample(where: str, t: float, v: float, previous_t: float | None,
                 config: TraceConfig) -> None:
    """The rules every speed sample obeys, CSV or bag.

    Args:
        where: the sample's place for messages (``file:line`` or ``bag: topic message i``).
        t: its time, s.
        v: its speed, m/s.
        previous_t: the time of the sample before it (None for the first), s.
        config: ``max_sample_gap_s``.

    Raises:
        TraceError: NaN or infinite value, a time before 0 or after :data:`MAX_TIME_S`,
            negative speed, a speed above
            :data:`MAX_SPEED_MPS`, time not increasing, or a hole longer than
            ``max_sample_gap_s``.
    """
    if not (math.isfinite(t) and math.isfinite(v)):
        raise TraceError(f'{where}: NaN or infinite value')
    if t < 0.0:
        raise TraceError(f'{where}: time {t:g} s is before 0 (a run stamps its messages with '
                         "the trace's time, and ROS time starts at 0)")
    if t > MAX_TIME_S:
        raise TraceError(f'{where}: time {t:g} s is beyond {MAX_TIME_S} s (a ROS 2 time stamp '
                         'holds int32 seconds; an hour is left for the run)')
    if v < 0.0:
        raise TraceError(f'{where}: negative speed {v:g} m/s')
    if v > MAX_SPEED_MPS:
        raise TraceError(f'{where}: speed {v:g} m/s is above {MAX_SPEED_MPS:g} m/s '
                         f'({MAX_SPEED_MPS * 3.6:g} km/h), faster than any road vehicle '
                         '(wrong unit or column?)')
    if previous_t is not None and t <= previous_t:
        raise TraceError(f'{where}: time {t:g} s does not increase (previous {previous_t:g} s)')
    if previous_t is not None and t - previous_t > config.max_sample_gap_s:
        raise TraceError(f'{where}: gap of {t - previous_t:g} s before t = {t:g} s exceeds '
                         f'max_sample_gap_s = {config.max_sample_gap_s:g} s')


def check_accelerations(where: str, times_s: np.ndarray, speeds_mps: np.ndarray,
                        config: TraceConfig) -> None:
    """Refuse a trace that speeds up or brakes harder than a road vehicle does: the speed
    change over every :data:`ACCEL_WINDOW_S` (over the whole trace when it is shorter),
    against ``trace_accel_max_mps2`` and ``trace_brake_max_mps2``; and one that comes to a
    standstill (below :data:`STANDSTILL_MPS`) yet drives faster than
    ``trace_stopping_speed_max_mps`` (stop-and-go above motorway speeds). The usual cause is
    a trace in km/h read as m/s (3.6 times the speeds and the accelerations).

    Args:
        where: the trace's name for messages (its file, or bag and topic).
        times_s: sample times, increasing, s.
        speeds_mps: speeds at those times, m/s.
        config: the two limits.

    Raises:
        TraceError: an acceleration beyond a limit, or a standstill and a speed above
            ``trace_stopping_speed_max_mps`` (one line naming the trace, the time, the
            likely cause and the parameter that raises the limit).
    """
    span = float(times_s[-1] - times_s[0])
    window = min(ACCEL_WINDOW_S, span)
    if window > 0.0:
        _check_accel(where, times_s, speeds_mps, config, window)
    _check_stop_and_go(where, times_s, speeds_mps, config)


def _check_accel(where: str, times_s: np.ndarray, speeds_mps: np.ndarray,
                 config: TraceConfig, window: float) -> None:
    """The accelerations of :func:`check_accelerations` over ``window`` s."""
    ends = times_s[times_s >= times_s[0] + window]
    if ends.size == 0:       # a span of one window whose end rounds below it
        ends = times_s[-1:]
    accels = (np.interp(ends, times_s, speeds_mps)
              - np.interp(ends - window, times_s, speeds_mps)) / window
    for index, limit, name, verb in (
            (int(np.argmax(accels)), config.trace_accel_max_mps2, 'trace_accel_max_mps2',
             'speeds up'),
            (int(np.argmin(accels)), config.trace_brake_max_mps2, 'trace_brake_max_mps2',
             'brakes')):
        value = abs(float(accels[index]))
        if (verb == 'brakes') == (accels[index] < 0.0) and value > limit:
            raise TraceError(
                f'{where}: {verb} at {value:.3g} m/s^2 before t = {ends[index]:g} s, harder '
                f'than a road vehicle ({name} = {limit:g} m/s^2); are its speeds in km/h '
                '(divide by 3.6 for m/s) or in another unit? If the trace is right, raise '
                f'preceding_traffic.{name} in a --params-file')


def _check_stop_and_go(where: str, times_s: np.ndarray, speeds_mps: np.ndarray,
                       config: TraceConfig) -> None:
    """See :func:`check_accelerations`."""
    top = int(np.argmax(speeds_mps))
    limit = config.trace_stopping_speed_max_mps
    stops = np.flatnonzero(speeds_mps < STANDSTILL_MPS)
    if speeds_mps[top] > limit and stops.size:
        raise TraceError(
            f'{where}: stands still at t = {times_s[stops[0]]:g} s yet reaches '
            f'{speeds_mps[top]:.3g} m/s ({speeds_mps[top] * 3.6:.0f} km/h) at t = '
            f'{times_s[top]:g} s: stop-and-go above motorway speeds '
            f'(trace_stopping_speed_max_mps = {limit:.4g} m/s); are its speeds in km/h '
            '(divide by 3.6 for m/s)? If the trace is right, raise '
            'preceding_traffic.trace_stopping_speed_max_mps in a --params-file')


def read_samples(path: Path, config: TraceConfig) -> tuple[np.ndarray, np.ndarray]:
    """Read and validate raw ``(time_s, speed_mps)`` samples.

    The file must be a regular file of UTF-8 text (a byte-order mark is allowed). Messages
    name the file, the line and the problem, never the file's content (a ``trace:`` path in
    a params file may point anywhere).

    Raises:
        TraceError: missing or unreadable file, not a regular file, not UTF-8 text, not CSV,
            wrong columns, empty, non-numeric, or a sample that breaks :func:`check_sample`.
    """
    kind = not_regular(path)
    if kind is not None:                # checked before opening: a FIFO blocks the open
        raise TraceError(f'{path}: not a regular file ({kind}; expected a time_s,speed_mps '
                         'CSV)')
    try:
        handle = path.open(newline='', encoding='utf-8-sig')
    except OSError as err:
        hint = did_you_mean(path.name, SHIPPED_TRACES) if path.parent == Path() else ''
        raise TraceError(f'{path}: cannot open trace ({err.strerror}){hint}') from err
    with handle:
        if not stat.S_ISREG(os.fstat(handle.fileno()).st_mode):
            raise TraceError(f'{path}: not a regular file (expected a time_s,speed_mps CSV)')
        reader = csv.reader(bounded_lines(handle, path, MAX_LINE_CHARS, TraceError,
                                          ' (not a time_s,speed_mps CSV)'), strict=True)
        try:
            return _parse(path, reader, config)
        except UnicodeDecodeError as err:
            raise TraceError(f'{path}: not UTF-8 text (expected a time_s,speed_mps CSV)') \
                from err
        except csv.Error as err:
            raise TraceError(f'{path}:{reader.line_num}: not CSV text ({err})') from err


def _parse(path: Path, reader: Iterator[list[str]],
           config: TraceConfig) -> tuple[np.ndarray, np.ndarray]:
    header = next(reader, None)
    if header is None:
        raise TraceError(f'{path}: empty file (expected header time_s,speed_mps)')
    if [h.strip() for h in header] != ['time_s', 'speed_mps']:
        raise TraceError(f'{path}:1: expected the header time_s,speed_mps (a CSV with these '
                         'two columns)')
    times: list[float] = []
    speeds: list[float] = []
    for line, row in enumerate(reader, start=2):
        if not row:
            continue
        if len(row) != 2:
            raise TraceError(f'{path}:{line}: expected 2 values, got {len(row)}')
        for column, text in zip(('time_s', 'speed_mps'), row, strict=True):
            try:
                float(text)
            except ValueError as err:
                raise TraceError(f'{path}:{line}: {column} is not a number') from err
        t, v = float(row[0]), float(row[1])
        check_sample(f'{path}:{line}', t, v, times[-1] if times else None, config)
        times.append(t)
        speeds.append(v)
    if len(times) < 2:
        raise TraceError(f'{path}: needs at least 2 samples, got {len(times)}')
    return np.asarray(times), np.asarray(speeds)


def resample(times_s: np.ndarray, speeds_mps: np.ndarray, dt_s: float,
             where: str = 'trace') -> np.ndarray:
    """Linear interpolation onto ``times_s[0] + k*dt_s`` up to the last sample.

    Args:
        times_s: sample times, increasing, s.
        speeds_mps: speeds at those times, m/s.
        dt_s: control step, s.
        where: the source's name for messages.

    Raises:
        TraceError: the trace is shorter than one control step, or longer than
            :data:`MAX_TRACE_STEPS` steps (checked before anything is allocated).
    """
    if not dt_s > 0.0:
        raise TraceError(f'dt_s must be > 0, got {dt_s}')
    span = float(times_s[-1] - times_s[0])
    steps = math.floor(span / dt_s + 1e-9)
    if steps < 1:
        raise TraceError(f'{where}: spans {span:g} s, shorter than one control step '
                         f'(dt_s = {dt_s:g} s)')
    if steps > MAX_TRACE_STEPS:
        raise TraceError(f'{where}: {span:g} s at dt_s = {dt_s:g} s is {steps} steps, more than '
                         f'the {MAX_TRACE_STEPS} a trace may have')
    grid = times_s[0] + dt_s * np.arange(steps + 1)
    speeds: np.ndarray = np.interp(grid, times_s, speeds_mps)
    return speeds


def truncate(trace: SpeedTrace, max_steps: int) -> SpeedTrace:
    """``trace`` limited to its first ``max_steps`` control steps (all of it for 0).

    Only the length changes: the speed limit (:attr:`SpeedTrace.max_speed_mps`) and the
    preview still see the whole trace, so a shortened run equals the start of the full run.

    Raises:
        TraceError: ``max_steps`` is negative.
    """
    if max_steps < 0:
        raise TraceError(f'max_steps must be >= 0, got {max_steps}')
    if not max_steps or max_steps >= trace.steps:
        return trace
    return dataclasses.replace(trace, step_limit=max_steps)
