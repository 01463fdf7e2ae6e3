"""Readers for human car-following recordings (JRC OpenACC; data is read, never copied).

The OpenACC Ispra-Vicolungo files (CC BY 4.0, (c) European Union, JRC OpenACC database)
hold 5 metadata lines, then a header with ``Time``, ``Speed1..5`` (m/s) and ``IVS1..4``
(bumper-to-bumper gap between car i and i+1, m) at 10 Hz.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np


class CarFollowingDataError(ValueError):
    """A car-following data file is missing or malformed."""


@dataclass(frozen=True)
class FollowingPair:
    """One leader->follower pair resampled to a fixed step.

    Attributes:
        name: ``<file stem>:<leader>-><follower>``.
        dt_s: Sample step, s.
        leader_speed_mps: Leader speed per sample, m/s.
        follower_speed_mps: Follower speed per sample, m/s.
        gap_m: Bumper-to-bumper gap per sample, m.
        dataset: ``openacc``, ``ngsim`` or '' (unknown).
        pair_key: The leader->follower pair this segment belongs to (several segments when
            a pair was split around an artefact); '' means ``name``.
        driver: The follower's identity (hold-out by driver); '' means unknown.
        start_s: Time of the first sample from the start of the recording, s.
    """

    name: str
    dt_s: float
    leader_speed_mps: np.ndarray
    follower_speed_mps: np.ndarray
    gap_m: np.ndarray
    dataset: str = ''
    pair_key: str = ''
    driver: str = ''
    start_s: float = 0.0

    @property
    def key(self) -> str:
        """The pair's identity (``pair_key`` or ``name``)."""
        return self.pair_key or self.name


def read_openacc(path: Path, *, dt_s: float = 1.0) -> list[FollowingPair]:
    """Read every leader->follower pair of one OpenACC file, resampled to ``dt_s``.

    Args:
        path: The CSV file.
        dt_s: Output sample step, s (the control step).

    Returns:
        The pairs, leader first in platoon order.

    Raises:
        CarFollowingDataError: Missing file, missing columns or non-numeric values.
    """
    if dt_s <= 0.0:
        raise CarFollowingDataError(f'dt_s must be positive, got {dt_s}')
    try:
        with path.open(newline='') as handle:
            rows = list(csv.reader(handle))
    except OSError as err:
        raise CarFollowingDataError(f'cannot read {path}: {err.strerror}') from err
    header_at = next((i for i, r in enumerate(rows[:20]) if r and r[0] == 'Time'), None)
    if header_at is None:
        raise CarFollowingDataError(f'{path}: no header line starting with "Time"')
    header = rows[header_at]
    speeds = sorted(c for c in header if c.startswith('Speed') and c[5:].isdigit())
    count = len(speeds)
    needed = ['Time'] + [f'Speed{i}' for i in range(1, count + 1)]
    needed += [f'IVS{i}' for i in range(1, count)]
    missing = [c for c in needed if c not in header]
    if count < 2 or missing:
        raise CarFollowingDataError(f'{path}: missing columns {missing or ["Speed1", "Speed2"]}')
    index = {c: header.index(c) for c in needed}
    try:
        data = np.array([[float(r[index[c]]) for c in needed]
                         for r in rows[header_at + 1:] if r and r[0].strip()])
    except (ValueError, IndexError) as err:
        raise CarFollowingDataError(f'{path}: non-numeric or short row ({err})') from err
    if data.shape[0] < 2 or not np.all(np.diff(data[:, 0]) > 0.0):
        raise CarFollowingDataError(f'{path}: fewer than 2 rows or time not increasing')
    time = data[:, 0]
    grid = np.arange(time[0], time[-1] + 1e-9, dt_s)
    column = {c: np.interp(grid, time, data[:, k]) for k, c in enumerate(needed)}
    return [FollowingPair(name=f'{path.stem}:{i}->{i + 1}', dt_s=dt_s,
                          leader_speed_mps=column[f'Speed{i}'],
                          follower_speed_mps=column[f'Speed{i + 1}'],
                          gap_m=column[f'IVS{i}'])
            for i in range(1, count)]
