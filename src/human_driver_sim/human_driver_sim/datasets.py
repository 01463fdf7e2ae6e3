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
* **NGSIM chains** (US DOT FHWA I-80; 6-vehicle chains as published in Keke-Long/PERL_planning):
  spacing is front to front, so the gap is ``Y_k - Y_{k+1} - vehicle_length_m`` with one
  assumed length for every leader (lengths are not given). The chains are sliding windows:
  every leader->follower pair is kept once, and repeated windows of a pair are merged
  on their common samples.
"""

from __future__ import annotations

import csv
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from human_driver_sim.car_following import CarFollowingDataError, FollowingPair

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
NGSIM_VEHICLE_LENGTH_M = 4.5
"""Assumed length of every NGSIM leader (front-to-front spacing -> gap), m; the project's
``vehicle_length_m``. Not given in the chains; docs/DRIVER_IRL.md shows what it changes."""
NGSIM_MIN_GAP_M = 0.5
"""An NGSIM pair whose gap (after the assumed length) ever falls below this is not a
same-lane car-following pair of two cars (or the length is wrong); it is left out, m."""
FORMATS = ('openacc', 'ngsim')


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


def _read_rows(path: Path) -> list[list[str]]:
    try:
        with path.open(newline='') as handle:
            return [row for row in csv.reader(handle)]
    except OSError as err:
        raise CarFollowingDataError(f'cannot read {path}: {err.strerror}') from err
    except (UnicodeDecodeError, csv.Error) as err:
        raise CarFollowingDataError(f'{path}: not a CSV text file ({err})') from err


def _numeric_table(path: Path, rows: list[list[str]], header_at: int,
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


def _resample(time_s: np.ndarray, values: np.ndarray, dt_s: float) -> tuple[np.ndarray,
                                                                              np.ndarray]:
    grid = np.arange(time_s[0], time_s[-1] + 1e-9, dt_s)
    return grid, np.interp(grid, time_s, values)


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
    rows = _read_rows(path)
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
    col = _numeric_table(path, rows, header_at, needed)
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
            grid, g = _resample(t, gap[piece], dt_s)
            pairs.append(FollowingPair(
                name=key if len(pieces) == 1 else f'{key}#{n}', dt_s=dt_s,
                leader_speed_mps=_resample(t, lead_v[piece], dt_s)[1],
                follower_speed_mps=_resample(t, follow_v[piece], dt_s)[1], gap_m=g,
                dataset='openacc', pair_key=key,
                driver=f'{path.stem.split("_part")[0]}:{names[i].strip() or i + 1}',
                start_s=round(float(grid[0] - time_s[0]), 3)))
    return pairs


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
        rows = _read_rows(path)
        if not rows or not rows[0] or rows[0][0].strip() != 't1':
            raise CarFollowingDataError(f'{path}: no header starting with "t1" (NGSIM chain)')
        header = [c.strip() for c in rows[0]]
        count = sum(1 for c in header if c.startswith('ID') and c[2:].isdigit())
        if count < 2:
            raise CarFollowingDataError(f'{path}: fewer than 2 vehicles (ID1, ID2, ...)')
        needed = ['t1'] + [f'{c}{k}' for k in range(1, count + 1) for c in ('ID', 'Y', 'v')]
        col = _numeric_table(path, rows, 0, needed)
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
            g = _resample(t, gap[ok], dt_s)[1]
            pairs.append(FollowingPair(
                name=name if len(merged) == 1 else f'{name}#{n}', dt_s=dt_s,
                leader_speed_mps=_resample(t, piece.leader_speed_mps[ok], dt_s)[1],
                follower_speed_mps=_resample(t, piece.follower_speed_mps[ok], dt_s)[1],
                gap_m=g, dataset='ngsim', pair_key=name, driver=f'ngsim:{follow}',
                start_s=float(t[0])))
    if report is not None:
        report.vehicle_length_m = vehicle_length_m
    return pairs


def detect_format(directory: Path) -> str:
    """``openacc`` or ``ngsim``: the layout of the first CSV that has one of them.

    Raises:
        CarFollowingDataError: Not a directory, no CSV, or no file in either format.
    """
    files = csv_files(directory)
    for path in files:
        rows = _read_rows(path)
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
                                          for r in _read_rows(f)[:20])]
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


def split_by_follower(pairs: Sequence[FollowingPair]) -> tuple[list[FollowingPair],
                                                               list[FollowingPair]]:
    """NGSIM fit / held-out split by vehicle: odd follower IDs are held out.

    Every pair is kept whole (all its segments on one side), and a held-out driver is never
    a follower in the fit set (NGSIM IDs are assigned in order of entry, so the parity is
    unrelated to driving).

    Raises:
        CarFollowingDataError: A driver that is not ``ngsim:<integer ID>``.
    """
    fit: list[FollowingPair] = []
    held_out: list[FollowingPair] = []
    for pair in pairs:
        ident = pair.driver.removeprefix('ngsim:')
        if not ident.isdigit():
            raise CarFollowingDataError(f'{pair.name}: driver {pair.driver!r} is not an '
                                        f'NGSIM vehicle ID')
        (held_out if int(ident) % 2 else fit).append(pair)
    return fit, held_out
