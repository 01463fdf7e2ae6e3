"""The human follower model, chosen by name from the ``trust_av.drivers`` registry.

A follower (driver) model is a :class:`~trust_monitor.common.registry.Component` of the
entry-point group ``trust_av.drivers``: its ``factory(driver, params)`` takes the
``human_driver`` section's :class:`~human_driver_sim.driver_mpc.DriverConfig` (step,
horizon, speed and acceleration bounds, standstill gap; the fitted MPC's weights) and an
instance of its ``config_type`` (None when it has none), and returns a :class:`Follower`.
The in-process loop and the ``driver`` node build it with :func:`make_follower`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from human_driver_sim.driver_mpc import DriverConfig, DriverResult
from trust_monitor.common import registry
from trust_monitor.common.params import check_fields, param, require


class Follower(Protocol):
    """Interface of a follower model (the human driving behind the AV)."""

    def reset(self) -> None:
        """Forget any state carried between steps (warm starts, filters)."""

    def step(self, gap_m: float, speed_mps: float, av_speed_mps: float,
             expected_mps2: np.ndarray) -> DriverResult:
        """The human's plan for the next ``horizon_steps`` steps (``plan_mps2``, m/s^2; its
        first value is applied) from its gap to the AV (m), its speed and the AV's (m/s) and
        the AV plan it expects (``horizon_steps`` values on the model grid, m/s^2)."""


@dataclass(frozen=True)
class FollowerConfig:
    """Which follower model drives behind the AV (the ``human_driver`` section)."""

    driver_model: str = param('the human follower model: a registered driver (entry-point '
                              'group trust_av.drivers)', default='mpc',
                              reason='the follower model is built at start-up')

    def __post_init__(self) -> None:
        check_fields(self)
        drivers = registry.names(registry.DRIVERS)
        require(self.driver_model in drivers,
                registry.not_one_of('driver_model', self.driver_model, drivers))


def make_follower(driver: DriverConfig, follower: FollowerConfig | None = None,
                  params: Any = None) -> Follower:
    """The follower model registered under ``follower.driver_model``.

    Args:
        driver: the ``human_driver`` section's parameters.
        follower: the choice (None: the default, ``mpc``).
        params: the model's own parameters (its ``config_type``; None: its defaults).

    Raises:
        RegistryError: the name is not registered, or ``params`` does not fit it.
    """
    component = registry.get(registry.DRIVERS, (follower or FollowerConfig()).driver_model)
    model: Follower = component.factory(driver, registry.config_of(component, params))
    return model
