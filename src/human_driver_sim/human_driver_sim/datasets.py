"""Cleaned human car-following pairs from OpenACC and NGSIM-chain CSVs (read, never copied).

Every pair becomes one or more :class:`~human_driver_sim.car_following.FollowingPair`
segments on the control step: the leader's speed, the follower's speed and the
bumper-to-bumper gap, chosen so that the gap and the two speeds agree with each other
(docs/DRIVER_IRL.md, "Data"):

* **OpenACC** (JRC OpenACC database, CC BY 4.0, (c) European Union): the recorded gap
  ``IVS_i`` is the straight-line distance between the two GNSS positions minus a constant
  bumper correction, but the Doppler ``Speed_i`` columns disagree with it by a steady
  0.05-0.27 m/s. Two leader constructions, both consistent with the gap:
  ``along_track`` (default) projects every car's ENU position onto one reference path and
  takes each speed as the time derivative of that arc length; ``gap`` keeps the follower's
  Doppler speed and gives the leader the follower's speed plus the gap's derivative.
  Splice artefacts (spans where the source removed noisy data and spline-interpolated
  across) are found where the gap's rate and the Doppler relative speed disagree by
  more than :data:`SPLICE_RESIDUAL_MPS`, or a Doppler acceleration exceeds
  :data:`SPLICE_ACCEL_MPS2`; the span is cut out and the pair split around it.
* **NGSIM chains**: :mod:`human_driver_sim.ngsim`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from human_driver_sim.car_following import (
    CarFollowingDataError,
    FollowingPair,
    LoadReport,
    Splice,
    numeric_table,
    read_rows,
    resample,
)
from human_driver_sim.ngsim import NGSIM_VEHICLE_LENGTH_M, read_ngsim_pairs

__all__ = ['FORMATS', 'load_directory', 'read_openacc_pairs']

SPLICE_RESIDUAL_MPS = 5.0
"""|d IVS/dt - (v_lead - v_follow)| (1 s mean) above this is a splice artefact, m/s (the
clean parts of the Vicolungo files stay below 3.4 m/s; the part3 splice reaches 11-55)."""
SPLICE_EXTEND_MPS = 1.0
"""A flagged span grows while the residual stays above this, m/s."""
SPLICE_ACCEL_MPS2 = 5.0
"""A Doppler acceleration (1 s mean) above this is an artefact, m/s^2 (clean parts < 3.3)."""
SPLICE_MARGIN_S = 1.0
"""Time cut on either side of a flagged span, s."""
MIN_SEGMENT_S = 20.0
"""Shorter pieces left by a cut are dropped, s."""
FORMATS = ('openacc', 'ngsim')


def _mean_1s(values: np.ndarray, time_s: np.ndarray) -> np.ndarray:
    """Centred moving mean over about one second."""
    step = float(np.median(np.diff(time_s)))
    width = max(1, round(1.0 / step))
    kernel = np.ones(width) / width
    padded = np.pad(values, (width // 2, width - 1 - width // 2), mode='edge')
    return np.convolve(padded, kernel, mode='valid')


def along_track_m(east_m: np.ndarray, north_m: np.ndarray, path_east_m: np.ndarray,
                  path_north_m: np.ndarray) -> np.ndarray:
    """Arc length along a reference polyline of each point's projection onto it, m.

    The points are assumed to move forward along the path (a search window follows the
    previous match), which holds for cars on one road.
    """
    seg = np.column_stack([np.diff(path_east_m), np.diff(path_north_m)])
    length = np.hypot(seg[:, 0], seg[:, 1])
    keep = length > 1e-6
    seg, length = seg[keep], length[keep]
    start = np.column_stack([path_east_m[:-1], path_north_m[:-1]])[keep]
    cumulative = np.concatenate([[0.0], np.cumsum(length)])
    out = np.empty(len(east_m))
    at = 0
    for k, point in enumerate(np.column_stack([east_m, north_m])):
        lo = 0 if k == 0 else max(0, at - 20)
        hi = len(seg) if k == 0 else min(len(seg), at + 200)
        rel = point - start[lo:hi]
        u = np.clip(np.einsum('ij,ij->i', rel, seg[lo:hi]) / length[lo:hi] ** 2, 0.0, 1.0)
        dist = np.hypot(rel[:, 0] - u * seg[lo:hi, 0], rel[:, 1] - u * seg[lo:hi, 1])
        best = int(np.argmin(dist))
        at = lo + best
        out[k] = cumulative[at] + u[best] * length[at]
    return out


def _segments(mask_ok: np.ndarray, time_s: np.ndarray, min_s: float) -> list[slice]:
    """Runs of True in ``mask_ok`` lasting at least ``min_s``."""
    out, k = [], 0
    while k < len(mask_ok):
        if not mask_ok[k]:
            k += 1
            continue
        j = k
        while j + 1 < len(mask_ok) and mask_ok[j + 1]:
            j += 1
        if time_s[j] - time_s[k] >= min_s:
            out.append(slice(k, j + 1))
        k = j + 1
    return out


def splice_mask(time_s: np.ndarray, gap_m: np.ndarray, leader_doppler_mps: np.ndarray,
                follower_doppler_mps: np.ndarray) -> tuple[np.ndarray, list[tuple[float, float,
                                                                                   float]]]:
    """Samples free of splice artefacts, and the spans cut (start, end in s, max residual).

    The residual is the disagreement of two independent relative speeds: the GNSS gap's rate
    and the Doppler speed difference (1 s mean). A sample is an artefact where it exceeds
    :data:`SPLICE_RESIDUAL_MPS` or a Doppler acceleration exceeds :data:`SPLICE_ACCEL_MPS2`;
    each span grows while the residual stays above :data:`SPLICE_EXTEND_MPS`, plus
    :data:`SPLICE_MARGIN_S` on both sides.
    """
    residual = np.abs(_mean_1s(np.gradient(gap_m, time_s)
                               - (leader_doppler_mps - follower_doppler_mps), time_s))
    accel = np.maximum(np.abs(_mean_1s(np.gradient(leader_doppler_mps, time_s), time_s)),
                       np.abs(_mean_1s(np.gradient(follower_doppler_mps, time_s), time_s)))
    bad = (residual > SPLICE_RESIDUAL_MPS) | (accel > SPLICE_ACCEL_MPS2)
    grown = bad.copy()
    for k in np.flatnonzero(bad):
        j = k
        while j > 0 and residual[j - 1] > SPLICE_EXTEND_MPS and not grown[j - 1]:
            j -= 1
            grown[j] = True
        j = k
        while j + 1 < len(bad) and residual[j + 1] > SPLICE_EXTEND_MPS and not grown[j + 1]:
            j += 1
            grown[j] = True
    spans: list[tuple[float, float, float]] = []
    for run in _segments(grown, time_s, 0.0):
        lo = round(float(time_s[run.start] - time_s[0]) - SPLICE_MARGIN_S, 1)
        hi = round(float(time_s[run.stop - 1] - time_s[0]) + SPLICE_MARGIN_S, 1)
        peak = float(residual[run].max())
        if spans and lo <= spans[-1][1]:  # overlapping after the margins: one span
            spans[-1] = (spans[-1][0], hi, max(spans[-1][2], peak))
        else:
            spans.append((lo, hi, peak))
    ok = np.ones(len(time_s), dtype=bool)
    for lo, hi, _ in spans:
        ok &= ~((time_s - time_s[0] >= lo) & (time_s - time_s[0] <= hi))
    return ok, spans


def read_openacc_pairs(path: Path, *, dt_s: float = 1.0, leader: str = 'along_track',
                       report: LoadReport | None = None) -> list[FollowingPair]:
    """Every leader->follower pair of one OpenACC file, cleaned and resampled to ``dt_s``.

    Args:
        path: OpenACC CSV (5 metadata lines, then ``Time, Speed_i, E_i, N_i, ..., IVS_i``).
        dt_s: Output step, s.
        leader: ``along_track`` (speeds from GNSS arc length) or ``gap`` (follower Doppler
            speed; leader = follower speed + gap rate).
        report: Receives the splices cut.

    Returns:
        Segments, platoon order; a pair split by a splice gives several (``name#1``, ...),
        sharing ``pair_key``.

    Raises:
        CarFollowingDataError: Unreadable file, missing columns, bad values.
    """
    if dt_s <= 0.0:
        raise CarFollowingDataError(f'dt_s must be positive, got {dt_s}')
    if leader not in ('along_track', 'gap'):
        raise CarFollowingDataError(f'unknown leader construction {leader!r}')
    rows = read_rows(path)
    header_at = next((i for i, r in enumerate(rows[:20]) if r and r[0].strip() == 'Time'), None)
    if header_at is None:
        raise CarFollowingDataError(f'{path}: no header line starting with "Time" (OpenACC)')
    header = [c.strip() for c in rows[header_at]]
    count = sum(1 for c in header if c.startswith('Speed') and c[5:].isdigit())
    if count < 2:
        raise CarFollowingDataError(f'{path}: fewer than 2 Speed_i columns (OpenACC)')
    needed = ['Time']
    for i in range(1, count + 1):
        needed += [f'Speed{i}', f'E{i}', f'N{i}']
    needed += [f'IVS{i}' for i in range(1, count)]
    col = numeric_table(path, rows, header_at, needed)
    names = next((r[1:count + 1] for r in rows[:header_at] if r and r[0] == 'Vehicle_order'),
                 [str(i) for i in range(1, count + 1)])
    time_s = col['Time']
    speed = {}
    if leader == 'along_track':
        first, last = (np.column_stack([col[f'E{i}'], col[f'N{i}']]) for i in (1, count))
        # Reference path: the last car's track up to the first car's start, then the first's.
        join = int(np.argmin(np.hypot(*(last - first[0]).T)))
        ref = np.vstack([last[:join], first])
        for i in range(1, count + 1):
            arc = along_track_m(col[f'E{i}'], col[f'N{i}'], ref[:, 0], ref[:, 1])
            speed[i] = np.gradient(arc, time_s)
    pairs = []
    for i in range(1, count):
        key = f'{path.stem}:{i}->{i + 1}'
        gap = col[f'IVS{i}']
        if leader == 'along_track':
            lead_v, follow_v = speed[i], speed[i + 1]
        else:
            follow_v = col[f'Speed{i + 1}']
            lead_v = follow_v + np.gradient(gap, time_s)
        ok, spans = splice_mask(time_s, gap, col[f'Speed{i}'], col[f'Speed{i + 1}'])
        if report is not None:
            report.splices += [Splice(key, lo, hi, res) for lo, hi, res in spans]
        pieces = _segments(ok, time_s, MIN_SEGMENT_S)
        for n, piece in enumerate(pieces, start=1):
            t = time_s[piece]
            grid, g = resample(t, gap[piece], dt_s)
            pairs.append(FollowingPair(
                name=key if len(pieces) == 1 else f'{key}#{n}', dt_s=dt_s,
                leader_speed_mps=resample(t, lead_v[piece], dt_s)[1],
                follower_speed_mps=resample(t, follow_v[piece], dt_s)[1], gap_m=g,
                dataset='openacc', pair_key=key,
                driver=f'{path.stem.split("_part")[0]}:{names[i].strip() or i + 1}',
                start_s=round(float(grid[0] - time_s[0]), 3)))
    return pairs


def detect_format(directory: Path) -> str:
    """``openacc`` or ``ngsim``: the layout of the first CSV that has one of them.

    Raises:
        CarFollowingDataError: Not a directory, no CSV, or no file in either format.
    """
    files = csv_files(directory)
    for path in files:
        rows = read_rows(path)
        if rows and rows[0] and rows[0][0].strip() == 't1':
            return 'ngsim'
        if any(r and r[0].strip() == 'Time' for r in rows[:20]):
            return 'openacc'
    raise CarFollowingDataError(f'{files[0]}: neither OpenACC ("Time" header after metadata) '
                                f'nor NGSIM chain ("t1" header)')


def csv_files(directory: Path) -> list[Path]:
    """The directory's ``*.csv`` files, sorted.

    Raises:
        CarFollowingDataError: Not a directory or no CSV in it.
    """
    if not directory.is_dir():
        raise CarFollowingDataError(f'{directory}: not a directory')
    files = sorted(directory.glob('*.csv'))
    if not files:
        raise CarFollowingDataError(f'{directory}: no *.csv files')
    return files


def load_directory(directory: Path, fmt: str | None = None, *, dt_s: float = 1.0,
                   report: LoadReport | None = None, leader: str = 'along_track',
                   vehicle_length_m: float = NGSIM_VEHICLE_LENGTH_M) -> list[FollowingPair]:
    """Every cleaned pair of a directory of OpenACC or NGSIM-chain CSVs.

    Raises:
        CarFollowingDataError: Bad directory, format or file; no pair left after cleaning.
    """
    fmt = fmt or detect_format(directory)
    if fmt not in FORMATS:
        raise CarFollowingDataError(f'unknown format {fmt!r} (known: {", ".join(FORMATS)})')
    files = csv_files(directory)
    if fmt == 'openacc':
        # Only data tables: OpenACC directories also hold a vehicle-specification CSV.
        tables = [f for f in files if any(r and r[0].strip() == 'Time'
                                          for r in read_rows(f)[:20])]
        if not tables:
            raise CarFollowingDataError(f'{directory}: no OpenACC file ("Time" header)')
        pairs = [p for f in tables for p in read_openacc_pairs(f, dt_s=dt_s, leader=leader,
                                                               report=report)]
        files = tables
    else:
        pairs = read_ngsim_pairs(files, dt_s=dt_s, vehicle_length_m=vehicle_length_m,
                                 report=report)
    if report is not None:
        report.files = [str(f) for f in files]
    if not pairs:
        raise CarFollowingDataError(f'{directory}: no pair left after cleaning')
    return pairs
