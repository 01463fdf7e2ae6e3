"""Train / validation / test splits of the recorded car following (docs/DRIVER_IRL.md, "Split").

Model selection (which model, its bounds and floors) looks at the validation split only; the
test split is scored once, for the reported figures.

* OpenACC Vicolungo: part3 is the test set (the same four drivers, another stretch of the
  trip). Part2 is cut in time: the first :data:`TRAIN_SHARE` of every segment trains, the
  rest validates (one trip; the validation stretch follows its training stretch).
* NGSIM I-80: split by vehicle (the follower's ID): odd IDs test, IDs divisible by 4 train,
  the other even IDs (2 mod 4) validate. No follower is in two splits and no pair is cut
  (NGSIM IDs are assigned in order of entry, so the residue is unrelated to driving).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import NamedTuple

from human_driver_sim.car_following import CarFollowingDataError, FollowingPair

__all__ = ['Split', 'cut_in_time', 'ngsim_role', 'split_ngsim', 'split_openacc']

OPENACC_FIT_PART = 'JRC-VC_280219_part2'
OPENACC_TEST_PART = 'JRC-VC_280219_part3'
TRAIN_SHARE = 0.7
"""Share of each OpenACC part2 segment (from its start) that trains; the rest validates."""


class Split(NamedTuple):
    """Pairs of one data set in the three roles."""

    train: list[FollowingPair]
    validation: list[FollowingPair]
    test: list[FollowingPair]


def cut_in_time(pair: FollowingPair, share: float) -> tuple[FollowingPair, FollowingPair]:
    """The first ``share`` of a segment and the rest (one sample shared, the rest's start).

    Raises:
        ValueError: ``share`` outside (0, 1) or a segment too short to cut.
    """
    if not 0.0 < share < 1.0:
        raise ValueError(f'share must be in (0, 1), got {share}')
    count = len(pair.gap_m)
    cut = round(share * (count - 1))
    if cut < 1 or cut > count - 2:
        raise ValueError(f'{pair.name}: {count} samples cannot be cut at {share}')

    def part(lo: int, hi: int) -> FollowingPair:
        return dataclasses.replace(pair, leader_speed_mps=pair.leader_speed_mps[lo:hi],
                                   follower_speed_mps=pair.follower_speed_mps[lo:hi],
                                   gap_m=pair.gap_m[lo:hi],
                                   start_s=pair.start_s + lo * pair.dt_s)

    return part(0, cut + 1), part(cut, count)


def split_openacc(pairs: Sequence[FollowingPair], share: float = TRAIN_SHARE) -> Split:
    """OpenACC: part2 cut in time (train, validation), part3 the test set.

    Raises:
        CarFollowingDataError: part2 or part3 missing.
    """
    fit = [p for p in pairs if p.key.startswith(OPENACC_FIT_PART + ':')]
    test = [p for p in pairs if p.key.startswith(OPENACC_TEST_PART + ':')]
    if not fit or not test:
        raise CarFollowingDataError(f'needs {OPENACC_FIT_PART}.csv and {OPENACC_TEST_PART}.csv')
    cuts = [cut_in_time(p, share) for p in fit]
    return Split([c[0] for c in cuts], [c[1] for c in cuts], test)


def ngsim_role(driver: str) -> str:
    """``train``, ``validation`` or ``test`` for an NGSIM follower ``ngsim:<ID>``.

    Raises:
        CarFollowingDataError: A driver that is not ``ngsim:<integer ID>``.
    """
    ident = driver.removeprefix('ngsim:')
    if not ident.isdigit():
        raise CarFollowingDataError(f'driver {driver!r} is not an NGSIM vehicle ID')
    number = int(ident)
    if number % 2:
        return 'test'
    return 'train' if number % 4 == 0 else 'validation'


def split_ngsim(pairs: Sequence[FollowingPair]) -> Split:
    """NGSIM by follower ID: odd test, 0 mod 4 train, 2 mod 4 validation.

    Raises:
        CarFollowingDataError: A driver that is not an NGSIM vehicle ID.
    """
    out = Split([], [], [])
    for pair in pairs:
        try:
            role = ngsim_role(pair.driver)
        except CarFollowingDataError as err:
            raise CarFollowingDataError(f'{pair.name}: {err}') from err
        getattr(out, role).append(pair)
    return out
