"""A drive's bag read back: the series the comparison and the driver fit take.

Reads with rosbags (typestore ``ROS2_JAZZY``); no rclpy. Times are seconds since the
drive's ``/sim/start`` (the bag's ``custom_data`` ``trust_av.drive.start_ns``), on the one
wall clock every message of the drive is stamped with. The plans, the monitor's trust and
the odometry are the drive's: from its start to its end (``trust_av.drive.end_ns``; a bag
without it, to its last message), not what the nodes published before the start or while
they were being stopped.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from human_driver_sim.car_following import FollowingPair
from human_driver_sim.splits import Split
from trust_av.drive.trust_rating import DriveSeries
from trust_av.errors import TrustAvAppError

__all__ = ['DriveBag', 'DriveBagError', 'custom_data', 'demonstration', 'drive_bag_pairs',
           'read_drive', 'split_by_participant']

NS = 1e-9


class DriveBagError(TrustAvAppError):
    """A bag is not a complete drive recording; the message names the bag and what lacks."""


@dataclass
class DriveBag:
    """Everything the analysis takes from one drive."""

    path: Path
    metadata: dict[str, str]
    series: DriveSeries
    rating_times_s: np.ndarray
    ratings: np.ndarray
    questionnaire: list[float]
    odometry: dict[str, np.ndarray]
    """Topic -> rows (t_s, position_m, speed_mps)."""


def custom_data(bag: Path) -> dict[str, str]:
    """The bag's ``custom_data`` (rosbag2 ``metadata.yaml``).

    Raises:
        DriveBagError: no readable ``metadata.yaml``.
    """
    try:
        meta = yaml.safe_load((Path(bag) / 'metadata.yaml').read_text())
        return dict(meta['rosbag2_bagfile_information'].get('custom_data') or {})
    except (OSError, yaml.YAMLError, KeyError, TypeError) as err:
        raise DriveBagError(f'{bag}: no readable metadata.yaml ({err})') from err


def _stamp(msg: Any) -> int:
    return int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)


def read_drive(bag: Path) -> DriveBag:
    """Read one drive's bag.

    Raises:
        DriveBagError: not a drive's bag (no start time in its metadata) or unreadable.
    """
    bag = Path(bag)
    meta = custom_data(bag)
    if 'trust_av.drive.start_ns' not in meta:
        raise DriveBagError(f'{bag}: not a drive recording (no trust_av.drive.start_ns in '
                            'custom_data)')
    start = int(meta['trust_av.drive.start_ns'])
    end = int(meta.get('trust_av.drive.end_ns', 2**63 - 1))
    plans: dict[int, list[float]] = {}
    expected: dict[int, list[float]] = {}
    trust: list[tuple[int, float]] = []
    ratings: list[tuple[int, float]] = []
    questionnaire: list[float] = []
    odometry: dict[str, list[tuple[float, float, float]]] = {
        '/preceding_vehicle/odom': [], '/ego/odom': [], '/human/odom': []}
    wanted = {'/ego/plan', '/ego/expected_plan', '/trust_monitor/trust', '/driver/rating',
              '/driver/questionnaire', *odometry}
    try:
        with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
            connections = [c for c in reader.connections if c.topic in wanted]
            for connection, _, raw in reader.messages(connections=connections):
                msg: Any = reader.deserialize(raw, connection.msgtype)
                topic, ns = connection.topic, _stamp(msg)
                if topic == '/ego/plan':
                    plans[ns] = [float(p.accelerations[0]) for p in msg.points]
                elif topic == '/ego/expected_plan':
                    expected[ns] = [float(p.accelerations[0]) for p in msg.points]
                elif topic == '/trust_monitor/trust':
                    if ns <= end:
                        trust.append((ns, float(msg.vector.z)))
                elif topic == '/driver/rating':
                    ratings.append((ns, float(msg.vector.x)))
                elif topic == '/driver/questionnaire':
                    questionnaire = [float(v) for v in msg.position]
                elif start <= ns <= end:
                    odometry[topic].append(((ns - start) * NS,
                                            float(msg.pose.pose.position.x),
                                            float(msg.twist.twist.linear.x)))
    except Exception as err:  # rosbags raises several unrelated classes; named below
        raise DriveBagError(f'{bag}: cannot read the drive ({type(err).__name__}: '
                            f'{err})') from err
    stamps = sorted(s for s in set(plans) & set(expected) if start <= s <= end)
    trust_t = np.array([(s - start) * NS for s, _ in trust])
    trust_v = np.array([v for _, v in trust])
    times = np.array([(s - start) * NS for s in stamps])
    if len(trust_t):
        index = np.clip(np.searchsorted(trust_t, times, side='right') - 1, 0, len(trust_t) - 1)
        monitor = np.where(times >= trust_t[0], trust_v[index], np.nan)
    else:
        monitor = np.full(len(times), np.nan)
    series = DriveSeries(times, [plans[s] for s in stamps], [expected[s] for s in stamps],
                         monitor)
    return DriveBag(bag, meta, series,
                    np.array([(s - start) * NS for s, _ in ratings]),
                    np.array([v for _, v in ratings]), questionnaire,
                    {k: np.array(v).reshape(-1, 3) for k, v in odometry.items()})


def demonstration(drive: DriveBag, dt_s: float, vehicle_length_m: float) -> FollowingPair:
    """The drive as a car-following demonstration: the AV leads, the person follows,
    resampled to ``dt_s`` (the format ``trust-av fit-driver`` fits to).

    Raises:
        DriveBagError: the drive has less than two samples of either vehicle.
    """
    av, you = drive.odometry['/ego/odom'], drive.odometry['/human/odom']
    if len(av) < 2 or len(you) < 2:
        raise DriveBagError(f'{drive.path}: too few odometry samples for a demonstration')
    end = min(av[-1, 0], you[-1, 0])
    grid = np.arange(max(av[0, 0], you[0, 0]), end + 1e-9, dt_s)
    if len(grid) < 2:
        raise DriveBagError(f'{drive.path}: shorter than two steps of {dt_s:g} s')
    lead_x, lead_v = np.interp(grid, av[:, 0], av[:, 1]), np.interp(grid, av[:, 0], av[:, 2])
    own_x, own_v = np.interp(grid, you[:, 0], you[:, 1]), np.interp(grid, you[:, 0], you[:, 2])
    participant = drive.metadata.get('trust_av.participant', '')
    return FollowingPair(name=f'{drive.path.name}:av->{participant}', dt_s=dt_s,
                         leader_speed_mps=lead_v, follower_speed_mps=own_v,
                         gap_m=lead_x - vehicle_length_m - own_x, dataset='drive',
                         pair_key=str(drive.path), driver=f'drive:{participant}')


def drive_bags(directory: Path) -> list[Path]:
    """Every complete drive bag under ``directory`` (status ``done``, not the practice)."""
    out = []
    for meta in sorted(Path(directory).rglob('metadata.yaml')):
        data = custom_data(meta.parent)
        if data.get('trust_av.drive.status') == 'done' \
                and data.get('trust_av.condition') != 'practice':
            out.append(meta.parent)
    return out


def split_by_participant(pairs: list[FollowingPair]) -> Split:
    """Train / validation / test split of drive demonstrations, as NGSIM's by vehicle:
    participants in name order take the roles in turn (train, validation, test, train, ...),
    so a person is in one split only; with fewer than three participants, their drives in
    name order take the roles in turn instead.

    Raises:
        DriveBagError: fewer than three demonstrations.
    """
    if len(pairs) < 3:
        raise DriveBagError(f'need at least three drives to train, validate and test, got '
                            f'{len(pairs)}')
    out = Split([], [], [])
    people = sorted({p.driver for p in pairs})
    if len(people) >= 3:
        role = {person: out[k % 3] for k, person in enumerate(people)}
        for pair in pairs:
            role[pair.driver].append(pair)
        return out
    for k, pair in enumerate(sorted(pairs, key=lambda p: p.name)):
        out[k % 3].append(pair)
    return out


def drive_bag_pairs(study: Path, dt_s: float, vehicle_length_m: float) -> tuple[
        Split, dict[str, Any]]:
    """``trust-av fit-driver --drives``: the study's complete drives as demonstrations, split
    like the public data (:func:`split_by_participant`), and what was read.

    Raises:
        DriveBagError: no complete drive, fewer than three, or one unreadable (named).
    """
    bags = drive_bags(study)
    if not bags:
        raise DriveBagError(f'{study}: no complete drive (status done) to fit to')
    pairs = [demonstration(read_drive(bag), dt_s, vehicle_length_m) for bag in bags]
    return split_by_participant(pairs), {'bags': [str(b) for b in bags],
                                         'participants': sorted({p.driver for p in pairs})}
