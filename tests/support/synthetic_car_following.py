"""Small synthetic car-following CSVs in the OpenACC and NGSIM-chain layouts (built in
tmp_path by the tests; no recorded data is committed)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

RADIUS_M = 800.0
"""The synthetic road is an arc of this radius (so the chord gap differs from the arc)."""


def leader_speed(time_s: np.ndarray) -> np.ndarray:
    """A leader that speeds up and slows down, m/s."""
    return 25.0 + 3.0 * np.sin(time_s / 15.0) + 1.5 * np.sin(time_s / 5.0)


def write_openacc(path: Path, *, duration_s: float = 120.0, cars: int = 3,
                  doppler_scale: float = 1.0, splice_at_s: float | None = None) -> dict:
    """An OpenACC-layout file: ``cars`` cars on an arc, 10 Hz; returns the truth.

    Car i + 1 follows car i at a gap 30 + 5 sin(t / 12) m (bumper to bumper; the GNSS
    antennas are 4 m apart more). ``doppler_scale`` biases every Doppler speed (the data's
    drift); ``splice_at_s`` adds a 3 s spliced span to the last car (positions jump 20 m and
    back, Doppler speed +10 m/s), like the Vicolungo part3 artefact.
    """
    time_s = np.round(np.arange(0.0, duration_s + 1e-9, 0.1), 1)
    lead_v = leader_speed(time_s)
    arc = {1: 200.0 + np.concatenate([[0.0], np.cumsum(0.5 * (lead_v[1:] + lead_v[:-1])
                                                        * 0.1)])}
    speed = {1: lead_v}
    gaps = {}
    for i in range(1, cars):
        gap = 30.0 + 5.0 * np.sin(time_s / 12.0 + i)
        gaps[i] = gap
        arc[i + 1] = arc[i] - gap - 4.0
        speed[i + 1] = speed[i] - 5.0 / 12.0 * np.cos(time_s / 12.0 + i)
    doppler = {i: speed[i] * doppler_scale for i in speed}
    east = {i: RADIUS_M * np.sin(arc[i] / RADIUS_M) for i in arc}
    north = {i: RADIUS_M * (1.0 - np.cos(arc[i] / RADIUS_M)) for i in arc}
    if splice_at_s is not None:
        span = (time_s >= splice_at_s) & (time_s < splice_at_s + 3.0)
        bump = 20.0 * np.sin(np.pi * (time_s[span] - splice_at_s) / 3.0)
        heading = arc[cars][span] / RADIUS_M
        east[cars][span] += bump * np.cos(heading)
        north[cars][span] += bump * np.sin(heading)
        doppler[cars][span] += 10.0
    ivs = {i: np.hypot(east[i] - east[i + 1], north[i] - north[i + 1]) - 4.0
           for i in range(1, cars)}
    header = ['Time']
    for i in range(1, cars + 1):
        header += [f'Speed{i}', f'E{i}', f'N{i}']
    header += [f'IVS{i}' for i in range(1, cars)] + [f'Driver{i}' for i in range(1, cars + 1)]
    lines = ['Date,28,2,2019', 'Vehicle_order,' + ','.join(f'Car{i}' for i in range(1, cars + 1)),
             f'Number_of_vehicles,{cars}', 'ACC,0', 'Distance_setting,min', ','.join(header)]
    for k, t in enumerate(time_s):
        row = [f'{380000.0 + t:.1f}']
        for i in range(1, cars + 1):
            row += [f'{doppler[i][k]:.6f}', f'{east[i][k]:.6f}', f'{north[i][k]:.6f}']
        row += [f'{ivs[i][k]:.6f}' for i in range(1, cars)] + ['Human'] * cars
        lines.append(','.join(row))
    path.write_text('\n'.join(lines) + '\n')
    return {'time_s': time_s, 'speed': speed, 'gap': gaps}


def write_ngsim_chain(path: Path, ids: list[int], *, start_s: float = 0.0,
                      duration_s: float = 20.0, spacing_m: float = 15.0) -> None:
    """An NGSIM chain file of vehicles ``ids`` (1 leads) cut from one shared synthetic
    platoon from ``start_s``: files with overlapping ids and times share their samples."""
    time_s = np.round(np.arange(0.0, duration_s + 1e-9, 0.1), 1)
    absolute = time_s + start_s
    header = ['t1']
    for k in range(1, len(ids) + 1):
        header += [f'ID{k}', f'Y{k}', f'v{k}', f'a{k}']
    columns = []
    for vehicle in ids:
        # Vehicle n's trajectory depends only on its ID (and time), so every window that
        # holds it holds the same samples.
        speed = 8.0 + 2.0 * np.sin(absolute / 6.0 + 0.3 * vehicle)
        position = (1000.0 - spacing_m * vehicle + 8.0 * absolute
                    - 12.0 * np.cos(absolute / 6.0 + 0.3 * vehicle))
        columns.append((vehicle, position, speed))
    origin = columns[-1][1][0]
    lines = [','.join(header)]
    for k, t in enumerate(time_s):
        row = [f'{t:.1f}']
        for vehicle, position, speed in columns:
            row += [str(vehicle), f'{position[k] - origin:.4f}', f'{speed[k]:.4f}', '0.0']
        lines.append(','.join(row))
    path.write_text('\n'.join(lines) + '\n')
