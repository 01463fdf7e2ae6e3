"""A recorded leader->follower pair on the control step, and the data error class.

The readers and the cleaning are in :mod:`human_driver_sim.datasets`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from human_driver_sim.errors import HumanDriverSimError


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
