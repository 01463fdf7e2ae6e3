"""NGSIM I-80 car-following chains (US DOT FHWA; 6-vehicle chains as published in
Keke-Long/PERL_planning) as cleaned leader->follower pairs: spacing is front to front, so
the gap is ``Y_k - Y_{k+1} - vehicle_length_m`` with one assumed length for every leader
(lengths are not given); the chains are sliding windows, so every pair is kept once and
repeated windows of a pair are merged on their common samples (docs/DRIVER_IRL.md, "Data").
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from human_driver_sim.car_following import (
    CarFollowingDataError,
    FollowingPair,
    LoadReport,
    numeric_table,
    read_rows,
    resample,
)

__all__ = ['NGSIM_VEHICLE_LENGTH_M', 'read_ngsim_pairs']

NGSIM_VEHICLE_LENGTH_M = 4.5
"""Assumed length of every NGSIM leader (front-to-front spacing -> gap), m; the project's
``vehicle_length_m``. Not given in the chains; docs/DRIVER_IRL.md shows what it changes."""
NGSIM_MIN_GAP_M = 0.5
"""An NGSIM pair whose gap (after the assumed length) ever falls below this is not a
same-lane car-following pair of two cars (or the length is wrong); it is left out, m."""


@dataclass
class _NgsimPiece:
    file: str
    time_s: np.ndarray
    spacing_m: np.ndarray
    leader_speed_mps: np.ndarray
    follower_speed_mps: np.ndarray


def _merge_windows(pieces: list[_NgsimPiece]) -> tuple[list[_NgsimPiece], int]:
    """Merge windows of one pair that share samples (equal spacing and speeds at a shift)."""
    merged: list[_NgsimPiece] = []
    dropped = 0
    for piece in sorted(pieces, key=lambda p: p.file):
        for target in merged:
            shift = _common_shift(target, piece)
            if shift is None:
                continue
            step = float(np.median(np.diff(target.time_s)))
            start = min(0, shift)
            stop = max(len(target.time_s), shift + len(piece.time_s))
            out = {}
            for name in ('spacing_m', 'leader_speed_mps', 'follower_speed_mps'):
                values = np.full(stop - start, np.nan)
                values[shift - start:shift - start + len(piece.time_s)] = getattr(piece, name)
                values[-start:-start + len(target.time_s)] = getattr(target, name)
                out[name] = values
            target.time_s = target.time_s[0] + step * np.arange(start, stop)
            target.spacing_m = out['spacing_m']
            target.leader_speed_mps = out['leader_speed_mps']
            target.follower_speed_mps = out['follower_speed_mps']
            target.file += '+' + piece.file
            dropped += 1
            break
        else:
            merged.append(piece)
    return merged, dropped


def _common_shift(a: _NgsimPiece, b: _NgsimPiece) -> int | None:
    """Sample shift s with b[k] == a[k + s] on at least 10 common samples, or None."""
    for shift in range(-len(b.time_s) + 10, len(a.time_s) - 9):
        lo, hi = max(0, -shift), min(len(b.time_s), len(a.time_s) - shift)
        if hi - lo < 10:
            continue
        if (np.allclose(a.spacing_m[lo + shift:hi + shift], b.spacing_m[lo:hi], atol=1e-3)
                and np.allclose(a.follower_speed_mps[lo + shift:hi + shift],
                                b.follower_speed_mps[lo:hi], atol=1e-3)):
            return shift
    return None


def read_ngsim_pairs(paths: Sequence[Path], *, dt_s: float = 1.0,
                     vehicle_length_m: float = NGSIM_VEHICLE_LENGTH_M,
                     report: LoadReport | None = None) -> list[FollowingPair]:
    """Unique leader->follower pairs of NGSIM chain files, resampled to ``dt_s``.

    Args:
        paths: Chain CSVs (``t1, IDk, Yk, vk, ak`` for k = 1..K, vehicle 1 leads).
        dt_s: Output step, s.
        vehicle_length_m: Assumed leader length (spacing is front to front), m.
        report: Receives the merged duplicates and the pairs left out.

    Raises:
        CarFollowingDataError: Unreadable file, missing columns, bad values.
    """
    if dt_s <= 0.0 or vehicle_length_m < 0.0:
        raise CarFollowingDataError('need dt_s > 0 and vehicle_length_m >= 0')
    by_pair: dict[tuple[str, str], list[_NgsimPiece]] = {}
    for path in paths:
        rows = read_rows(path)
        if not rows or not rows[0] or rows[0][0].strip() != 't1':
            raise CarFollowingDataError(f'{path}: no header starting with "t1" (NGSIM chain)')
        header = [c.strip() for c in rows[0]]
        count = sum(1 for c in header if c.startswith('ID') and c[2:].isdigit())
        if count < 2:
            raise CarFollowingDataError(f'{path}: fewer than 2 vehicles (ID1, ID2, ...)')
        needed = ['t1'] + [f'{c}{k}' for k in range(1, count + 1) for c in ('ID', 'Y', 'v')]
        col = numeric_table(path, rows, 0, needed)
        for k in range(1, count):
            ids = (col[f'ID{k}'], col[f'ID{k + 1}'])
            if any(np.ptp(i) != 0.0 for i in ids):
                raise CarFollowingDataError(f'{path}: vehicle ID{k} or ID{k + 1} changes')
            key = (f'{ids[0][0]:.0f}', f'{ids[1][0]:.0f}')
            by_pair.setdefault(key, []).append(_NgsimPiece(
                path.name, col['t1'], col[f'Y{k}'] - col[f'Y{k + 1}'], col[f'v{k}'],
                col[f'v{k + 1}']))
    pairs = []
    for (lead, follow), pieces in sorted(by_pair.items(), key=lambda x: (int(x[0][1]),
                                                                         int(x[0][0]))):
        merged, dropped = _merge_windows(pieces)
        name = f'ngsim:{lead}->{follow}'
        if report is not None:
            report.duplicates_merged += dropped
        gaps = [p.spacing_m - vehicle_length_m for p in merged]
        if min(float(np.nanmin(g)) for g in gaps) < NGSIM_MIN_GAP_M:
            if report is not None:
                closest = min(float(np.nanmin(p.spacing_m)) for p in merged)
                report.excluded[name] = (f'gap below {NGSIM_MIN_GAP_M} m with a '
                                        f'{vehicle_length_m} m leader (closest front-to-front '
                                        f'spacing {closest:.2f} m)')
            continue
        for n, (piece, gap) in enumerate(zip(merged, gaps, strict=True), start=1):
            ok = np.isfinite(gap)
            t = piece.time_s[ok]
            g = resample(t, gap[ok], dt_s)[1]
            pairs.append(FollowingPair(
                name=name if len(merged) == 1 else f'{name}#{n}', dt_s=dt_s,
                leader_speed_mps=resample(t, piece.leader_speed_mps[ok], dt_s)[1],
                follower_speed_mps=resample(t, piece.follower_speed_mps[ok], dt_s)[1],
                gap_m=g, dataset='ngsim', pair_key=name, driver=f'ngsim:{follow}',
                start_s=float(t[0])))
    if report is not None:
        report.vehicle_length_m = vehicle_length_m
    return pairs
