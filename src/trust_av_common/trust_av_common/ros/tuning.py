"""Run-time parameter changes (``ros2 param set``): validated like start-up, applied from the
next tick, wall mode only.

A node lists the configurations it holds (:class:`Tunable`); a ``set_parameters`` request is
accepted only when every parameter is one whose field says ``read_only=False`` (the others
are read-only in their descriptor, with the reason), the node runs in wall mode (lock-step
runs are deterministic: nothing changes under them), and the new configuration builds
(:func:`trust_av_common.params.build_config`: the field's type and range and the
dataclass's own checks, exactly as at start-up). The node then gets the new configuration
and the change is logged.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter

from trust_av_common.params import ParamsError, build_config, field_spec

__all__ = ['Tunable', 'check_request', 'enable_tuning']


@dataclass
class Tunable:
    """A configuration a node holds: how to read it and how to install a new one.

    Attributes:
        cls: the configuration dataclass.
        get: returns the node's current instance.
        apply: installs a validated new instance (effective at the node's next tick).
    """

    cls: type
    get: Callable[[], Any]
    apply: Callable[[Any], None]


def check_request(tunables: list[Tunable], changes: dict[str, Any],
                  wall: bool) -> tuple[str, dict[int, Any]]:
    """Validate a set of parameter changes; pure (no ROS).

    Args:
        tunables: the node's configurations.
        changes: parameter name -> new value.
        wall: the node runs in wall mode.

    Returns:
        ('', new configurations by index in ``tunables``) when every change is allowed, else
        (the reason, {}).
    """
    if not wall:
        return ('parameters are fixed in lock-step mode (its runs are deterministic); run '
                'with clock_mode wall to change them at run time'), {}
    new: dict[int, Any] = {}
    for name in changes:
        owners = [i for i, t in enumerate(tunables)
                  if name in {f.name for f in dataclasses.fields(t.cls)}]
        if not owners:
            return f'{name} is not a parameter of this node', {}
        for i in owners:
            spec = field_spec(tunables[i].cls, name)
            if spec is None or spec.read_only:
                reason = spec.reason if spec is not None and spec.reason else 'fixed'
                return f'{name} is read-only: {reason}', {}
    for i, tunable in enumerate(tunables):
        mine = {k: v for k, v in changes.items()
                if k in {f.name for f in dataclasses.fields(tunable.cls)}}
        if not mine:
            continue
        values = {**dataclasses.asdict(tunable.get()), **mine}
        try:
            new[i] = build_config(tunable.cls, values)
        except ParamsError as err:
            return str(err), {}
    return '', new


def enable_tuning(node: Node, tunables: list[Tunable], wall: bool) -> None:
    """Install the set-parameters callback on ``node`` (after its parameters are declared).

    Args:
        node: the node.
        tunables: the configurations it holds.
        wall: the node runs in wall mode (otherwise every change is refused).
    """
    def on_set(parameters: list[Parameter]) -> SetParametersResult:
        changes = {p.name: p.value for p in parameters}
        reason, new = check_request(tunables, changes, wall)
        if reason:
            node.get_logger().warning(f'parameter change refused: {reason}')
            return SetParametersResult(successful=False, reason=reason)
        for i, config in new.items():
            old = tunables[i].get()
            tunables[i].apply(config)
            for name in changes:
                if hasattr(old, name):
                    node.get_logger().info(f'parameter {name}: {getattr(old, name)!r} -> '
                                           f'{getattr(config, name)!r} (from the next tick)')
        return SetParametersResult(successful=True)

    node.add_on_set_parameters_callback(on_set)
