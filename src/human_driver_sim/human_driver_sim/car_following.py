"""A recorded leader->follower pair on the control step, and the data error class.

The readers and the cleaning are in :mod:`human_driver_sim.datasets`.
"""

from __future__ import annotations

import csv
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from human_driver_sim.errors import HumanDriverSimError

__all__ = ['CarFollowingDataError', 'FollowingPair', 'LoadReport', 'Splice', 'numeric_table',
           'read_rows', 'resample']


class CarFollowingDataError(HumanDriverSimError):
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


@dataclass(frozen=True)
class Splice:
    """One span cut out of an OpenACC pair (times from the file's first sample, s)."""

    pair: str
    start_s: float
    end_s: float
    max_residual_mps: float


@dataclass
class LoadReport:
    """What loading a directory did: files, pairs kept, splices cut, pairs left out."""

    files: list[str] = field(default_factory=list)
    splices: list[Splice] = field(default_factory=list)
    excluded: dict[str, str] = field(default_factory=dict)
    duplicates_merged: int = 0
    vehicle_length_m: float | None = None


def read_rows(path: Path) -> list[list[str]]:
    try:
        with path.open(newline='') as handle:
            return [row for row in csv.reader(handle)]
    except OSError as err:
        raise CarFollowingDataError(f'cannot read {path}: {err.strerror}') from err
    except (UnicodeDecodeError, csv.Error) as err:
        raise CarFollowingDataError(f'{path}: not a CSV text file ({err})') from err


def numeric_table(path: Path, rows: list[list[str]], header_at: int,
                   needed: Sequence[str]) -> dict[str, np.ndarray]:
    header = [c.strip() for c in rows[header_at]]
    missing = [c for c in needed if c not in header]
    if missing:
        raise CarFollowingDataError(f'{path}: missing columns {missing}')
    index = [header.index(c) for c in needed]
    body = [r for r in rows[header_at + 1:] if r and any(x.strip() for x in r)]
    try:
        data = np.array([[float(r[i]) for i in index] for r in body], dtype=float)
    except (ValueError, IndexError) as err:
        raise CarFollowingDataError(f'{path}: non-numeric or short row ({err})') from err
    if data.shape[0] < 2:
        raise CarFollowingDataError(f'{path}: fewer than 2 data rows')
    if not np.all(np.isfinite(data)):
        raise CarFollowingDataError(f'{path}: a value is not finite')
    if not np.all(np.diff(data[:, 0]) > 0.0):
        raise CarFollowingDataError(f'{path}: time is not increasing')
    return {c: data[:, k] for k, c in enumerate(needed)}


def resample(time_s: np.ndarray, values: np.ndarray, dt_s: float) -> tuple[np.ndarray,
                                                                              np.ndarray]:
    grid = np.arange(time_s[0], time_s[-1] + 1e-9, dt_s)
    return grid, np.interp(grid, time_s, values)
