"""The human follower model, chosen by name from the ``trust_av.drivers`` registry.

A follower (driver) model is a :class:`~trust_av_common.registry.Component` of the
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
from trust_av_common import registry
from trust_av_common.component_checks import (
    PASSING,
    call,
    check_number,
    check_plan,
    check_type,
    raised,
)
from trust_av_common.params import check_fields, param, require

__all__ = ['DRIVERS', 'CheckedFollower', 'Follower', 'FollowerConfig', 'make_follower']

DRIVERS = registry.declare('trust_av.drivers', factory_arguments=('driver', 'params'),
                           interface=('reset', 'step'))
"""Entry-point group of the human follower (driver) models, declared here beside their
interface: ``factory(driver, params)`` returns a :class:`Follower`."""


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
        drivers = registry.names(DRIVERS)
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
    component = registry.get(DRIVERS, (follower or FollowerConfig()).driver_model)
    model: Follower = registry.build(DRIVERS, component, driver,
                                     registry.config_of(component, params))
    return CheckedFollower(model, component.name, driver)


class CheckedFollower:
    """A follower whose every step is checked where it enters the loop
    (:mod:`trust_av_common.component_checks`): the result must have a plan of
    ``horizon_steps`` finite accelerations within the driver's bounds, a ``str`` status, a
    ``bool`` success, an ``int`` iteration count and a finite solve time >= 0; anything the
    model raises names it. The in-process loop and the ``driver`` node both get one from
    :func:`make_follower`.

    Args:
        model: the follower the registry built.
        name: its registered name.
        driver: the ``human_driver`` section (horizon and acceleration bounds).
    """

    def __init__(self, model: Follower, name: str, driver: DriverConfig) -> None:
        self.model = model
        self.name = name
        self.driver = driver
        self.steps_done = 0

    def reset(self) -> None:
        """Reset the model's state (the step count goes on)."""
        call(DRIVERS, self.name, self.steps_done, 'reset()', self.model.reset)

    def step(self, gap_m: float, speed_mps: float, av_speed_mps: float,
             expected_mps2: np.ndarray) -> DriverResult:
        """:meth:`Follower.step` of the model, checked.

        Raises:
            ComponentError: it raised, or its result breaks the interface.
        """
        group, name, k = DRIVERS, self.name, self.steps_done
        try:
            result = self.model.step(gap_m, speed_mps, av_speed_mps, expected_mps2)
        except PASSING:
            raise
        except BaseException as err:
            raise raised(group, name, k, 'step()', err) from err
        if not (type(result) is DriverResult and type(result.status) is str
                and type(result.success) is bool and type(result.iterations) is int):
            check_type(result, DriverResult, group=group, name=name, step=k, what='result')
            check_type(result.status, str, group=group, name=name, step=k, what='status')
            check_type(result.success, (bool, np.bool_), group=group, name=name, step=k,
                       what='success')
            check_type(result.iterations, (int, np.integer), group=group, name=name, step=k,
                       what='iterations')
        plan = check_plan(result.plan_mps2, group=group, name=name, step=k,
                          steps=self.driver.horizon_steps, low=self.driver.accel_min_mps2,
                          high=self.driver.accel_max_mps2, what='plan_mps2')
        check_number(result.solve_time_s, group=group, name=name, step=k, what='solve_time_s',
                     low=0.0)
        self.steps_done += 1
        return result if plan is result.plan_mps2 else DriverResult(
            plan, result.status, result.success, result.iterations, result.solve_time_s)
