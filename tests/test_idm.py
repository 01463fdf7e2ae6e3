"""IDM baseline and OpenACC reader: physical behaviour and clear errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from human_driver_sim.car_following import CarFollowingDataError, read_openacc
from human_driver_sim.idm import IdmParams, replay


def test_idm_no_collision_behind_braking_leader() -> None:
    leader = np.concatenate([np.full(20, 25.0), np.linspace(25.0, 0.0, 9), np.zeros(40)])
    gap, speed = replay(IdmParams(), leader, 40.0, 25.0, 1.0)
    assert gap.min() > 0.0
    assert speed[-1] < 0.5


def test_reader_rejects_missing_and_malformed(tmp_path: Path) -> None:
    with pytest.raises(CarFollowingDataError, match='cannot read'):
        read_openacc(tmp_path / 'absent.csv')
    bad = tmp_path / 'bad.csv'
    bad.write_text('a\nb\nc\nd\ne\nTime,Speed1,Speed2,IVS1\n0,1,x,3\n')
    with pytest.raises(CarFollowingDataError, match='non-numeric'):
        read_openacc(bad)


def test_reader_resamples(tmp_path: Path) -> None:
    good = tmp_path / 'good.csv'
    lines = ['m'] * 5 + ['Time,Speed1,Speed2,IVS1']
    lines += [f'{k / 10},{20 + k / 10},20,30' for k in range(31)]
    good.write_text('\n'.join(lines) + '\n')
    (pair,) = read_openacc(good, dt_s=1.0)
    assert len(pair.gap_m) == 4
    assert pair.leader_speed_mps[1] == pytest.approx(21.0)
