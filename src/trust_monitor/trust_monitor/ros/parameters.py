"""Declare a configuration dataclass as ROS parameters and build it validated.

Each field's description, unit and range come from its
:class:`~trust_monitor.common.params.ParamSpec` (one place per parameter); the values from
``--ros-args --params-file`` / ``-p``; the dataclass validates them exactly as the CLI does
(:func:`trust_monitor.common.params.build_config`).
"""

from __future__ import annotations

import dataclasses
import typing
from typing import Any, TypeVar

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.node import Node
from rclpy.parameter import Parameter

from trust_monitor.common.params import PARAM_METADATA_KEY, ParamsError, ParamSpec, build_config

T = TypeVar('T')


def descriptor(field: dataclasses.Field[Any], hint: Any) -> ParameterDescriptor:
    """The ROS parameter descriptor of a configuration field: type, description with unit,
    read-only flag and, for a closed interval, the range (ROS ranges are closed; open bounds
    are checked by the dataclass itself)."""
    kind = {float: Parameter.Type.DOUBLE, int: Parameter.Type.INTEGER,
            bool: Parameter.Type.BOOL, str: Parameter.Type.STRING}[hint]
    spec = field.metadata.get(PARAM_METADATA_KEY)
    if not isinstance(spec, ParamSpec):
        spec = ParamSpec(field.name)
    result = ParameterDescriptor(name=field.name, description=spec.text(), type=kind.value,
                                 read_only=spec.read_only)
    closed = (spec.low is not None and spec.high is not None and spec.low_inclusive
              and spec.high_inclusive)
    if closed and kind == Parameter.Type.DOUBLE:
        result.floating_point_range = [FloatingPointRange(from_value=float(spec.low),
                                                          to_value=float(spec.high))]
    elif closed and kind == Parameter.Type.INTEGER:
        result.integer_range = [IntegerRange(from_value=int(spec.low),  # type: ignore[arg-type]
                                             to_value=int(spec.high),  # type: ignore[arg-type]
                                             step=1)]
    if spec.choices:
        result.additional_constraints = f'one of: {", ".join(spec.choices)}'
    return result


def declare_config(node: Node, cls: type[T], extra: dict[str, Any] | None = None) -> T:
    """Declare every field of ``cls`` as a read-only parameter and build the validated config.

    Values come from ``--ros-args --params-file`` / ``-p``; a field without a value and
    without a dataclass default makes start-up fail naming it.

    Raises:
        ParamsError: missing parameter or a value the dataclass rejects.
    """
    hints = typing.get_type_hints(cls)
    values: dict[str, Any] = dict(extra or {})
    for field in dataclasses.fields(cls):  # type: ignore[arg-type]
        if field.name in values:
            continue
        described = descriptor(field, hints[field.name])
        if not node.has_parameter(field.name):
            if field.default is not dataclasses.MISSING:
                node.declare_parameter(field.name, field.default, described)
            else:
                node.declare_parameter(field.name, Parameter.Type(described.type), described)
        param = node.get_parameter(field.name)
        if param.type_ == Parameter.Type.NOT_SET:
            raise ParamsError(f'parameter {field.name} is missing ({cls.__name__})')
        values[field.name] = param.value
    return build_config(cls, values)
