"""Read ROS 2 params files and build validated, frozen configuration dataclasses.

A ROS 2 params file maps node names to ``ros__parameters``; the wildcard section ``/**``
applies to every node. This module is the one reader the project's CLIs use, so that a
parameter means the same thing in the in-process simulator and in the node graph (where
rclpy itself parses the same file from ``--ros-args --params-file``).

One place per parameter: a configuration dataclass declares each parameter with
:func:`param`, which stores its description, unit and allowed range in the field's metadata.
:func:`check_fields` validates an instance against them (called from ``__post_init__``),
:mod:`trust_av_common.ros.parameters` turns them into ROS parameter descriptors, and the CLI
reads the same ranges for its options.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import typing
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

import yaml

from trust_av_common.errors import TrustAvError, did_you_mean, with_suggestions
from trust_av_common.input_files import not_regular

__all__ = ['CONTROL_STEP_RANGE_S', 'MAX_POSITION_M', 'MAX_STAMP_S', 'MAX_VEHICLE_LENGTH_M',
           'PARAM_METADATA_KEY', 'ParamSpec', 'ParamsError', 'build_config', 'check_fields',
           'check_known', 'check_type', 'control_step_param', 'field_spec', 'param',
           'read_params_file', 'require']

WILDCARD = '/**'
T = TypeVar('T')
PARAM_METADATA_KEY = 'trust_av_param'
"""Key of a field's :class:`ParamSpec` in ``dataclasses.Field.metadata``."""


class ParamsError(TrustAvError):
    """A params file or a parameter value is invalid; the message names the culprit."""


@dataclass(frozen=True)
class ParamSpec:
    """What a configuration field means and which values it accepts.

    Attributes:
        description: one line, what the parameter does.
        unit: SI unit ('' for dimensionless or text).
        low: smallest allowed value (None: unbounded).
        high: largest allowed value (None: unbounded).
        low_inclusive: ``low`` itself is allowed.
        high_inclusive: ``high`` itself is allowed.
        choices: the allowed strings (empty: any).
        read_only: the parameter cannot change while a node runs.
        reason: why it is read-only (shown in its ROS descriptor), '' if not said.
    """

    description: str
    unit: str = ''
    low: float | None = None
    high: float | None = None
    low_inclusive: bool = True
    high_inclusive: bool = True
    choices: tuple[str, ...] = ()
    read_only: bool = True
    reason: str = ''

    def text(self) -> str:
        """Description with its unit, e.g. ``control step (s)``, and why it is read-only."""
        text = f'{self.description} ({self.unit})' if self.unit else self.description
        return f'{text}; read-only: {self.reason}' if self.read_only and self.reason else text

    def problem(self, name: str, value: Any) -> str:
        """Why ``value`` is not allowed for parameter ``name`` ('' when it is)."""
        if self.choices and value not in self.choices:
            return (f'{name} must be one of {list(self.choices)}, got {value!r}'
                    f'{did_you_mean(value, self.choices)}')
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            return ''
        too_low = self.low is not None and (value < self.low or
                                            (value == self.low and not self.low_inclusive))
        too_high = self.high is not None and (value > self.high or
                                              (value == self.high and not self.high_inclusive))
        if not (too_low or too_high):
            return ''
        if self.low is not None and self.high is not None:
            left = '[' if self.low_inclusive else '('
            right = ']' if self.high_inclusive else ')'
            return f'{name} must be in {left}{self.low:g}, {self.high:g}{right}, got {value!r}'
        if self.low is not None:
            return f'{name} must be {">=" if self.low_inclusive else ">"} {self.low:g}, ' \
                   f'got {value!r}'
        assert self.high is not None
        return f'{name} must be {"<=" if self.high_inclusive else "<"} {self.high:g}, ' \
               f'got {value!r}'


def param(description: str, *, unit: str = '', low: float | None = None,
          high: float | None = None, low_inclusive: bool = True, high_inclusive: bool = True,
          choices: tuple[str, ...] = (), read_only: bool = True, reason: str = '',
          default: Any = dataclasses.MISSING) -> Any:
    """A configuration dataclass field that carries its :class:`ParamSpec`.

    Args:
        description: what the parameter does (one line).
        unit: its SI unit, '' if none.
        low: smallest allowed value, or None.
        high: largest allowed value, or None.
        low_inclusive: whether ``low`` itself is allowed.
        high_inclusive: whether ``high`` itself is allowed.
        choices: allowed strings, or () for any.
        read_only: whether a running node refuses to change it.
        reason: why it is read-only (for the ROS descriptor).
        default: the default value (none: the parameter is required).

    Returns:
        A ``dataclasses.field`` to assign to the annotated attribute.
    """
    spec = ParamSpec(description, unit, low, high, low_inclusive, high_inclusive, choices,
                     read_only, reason)
    return dataclasses.field(default=default, metadata={PARAM_METADATA_KEY: spec})


MAX_STAMP_S = 2**31 - 3600
"""Latest time a run may stamp, s: a ROS 2 ``builtin_interfaces/Time`` holds int32 seconds
(below 2^31 s); an hour is left for a horizon and the end of a run. Start times and trace
times are refused beyond it, and before 0."""
MAX_POSITION_M = 1e7
"""Largest initial position along the road, m (10,000 km)."""
MAX_VEHICLE_LENGTH_M = 100.0
"""Longest vehicle, m."""

CONTROL_STEP_RANGE_S = (0.01, 10.0)
"""Allowed control step dt_s, s: 100 Hz to one step per 10 s (the paper's is 1 s). Together
with ``preceding_traffic.traces.MAX_TRACE_STEPS`` it bounds a run's length in steps."""


def control_step_param(description: str = 'control step', reason: str = '') -> Any:
    """The ``dt_s`` field every component that steps declares (one range for all).

    Args:
        description: what the step is in this component.
        reason: why it is read-only in a running node ('' if not said).
    """
    low, high = CONTROL_STEP_RANGE_S
    return param(description, unit='s', low=low, high=high, reason=reason)


def field_spec(cls: type, name: str) -> ParamSpec | None:
    """The :class:`ParamSpec` of field ``name`` of dataclass ``cls`` (None if it has none).

    Raises:
        KeyError: ``cls`` has no field ``name``.
    """
    for field in dataclasses.fields(cls):
        if field.name == name:
            spec = field.metadata.get(PARAM_METADATA_KEY)
            return spec if isinstance(spec, ParamSpec) else None
    raise KeyError(f'{cls.__name__} has no field {name!r}')


def check_fields(config: object) -> None:
    """Check every field of a configuration dataclass against its :class:`ParamSpec`.

    Raises:
        ParamsError: a value out of range or not among the choices (the first one found);
            a float that is NaN or infinite.
    """
    for field in dataclasses.fields(config):  # type: ignore[arg-type]
        value = getattr(config, field.name)
        if isinstance(value, float) and not math.isfinite(value):
            raise ParamsError(f'{field.name} must be finite, got {value!r}')
        spec = field.metadata.get(PARAM_METADATA_KEY)
        if isinstance(spec, ParamSpec):
            problem = spec.problem(field.name, value)
            if problem:
                raise ParamsError(problem)


def read_params_file(path: str | Path) -> dict[str, dict[str, Any]]:
    """Read a ROS 2 params file with PyYAML (plain sections by exact name).

    Not rcl's rules: runs read their params files with
    :func:`trust_av_common.param_layers.read_layer` and
    :func:`~trust_av_common.param_layers.layered_params`.

    Args:
        path: YAML file in ROS 2 params-file format.

    Returns:
        Node name (or ``/**``) to its ``ros__parameters`` mapping.

    Raises:
        ParamsError: the file is missing, not YAML, or not in params-file format.
    """
    path = Path(path)
    kind = not_regular(path)
    if kind is not None:                # a FIFO would block the read
        raise ParamsError(f'{path}: cannot read params file (not a regular file: {kind})')
    try:
        text = path.read_text()
    except OSError as err:
        raise ParamsError(f'{path}: cannot read params file ({err.strerror})') from err
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as err:
        raise ParamsError(f'{path}: not valid YAML ({err})') from err
    if not isinstance(data, dict):
        raise ParamsError(f'{path}: expected a mapping of node names to ros__parameters')
    sections: dict[str, dict[str, Any]] = {}
    for node, body in data.items():
        if not isinstance(body, dict) or set(body) != {'ros__parameters'}:
            raise ParamsError(f'{path}: section {node!r} must hold exactly one key, '
                              'ros__parameters')
        params = body['ros__parameters']
        if not isinstance(params, dict):
            raise ParamsError(f'{path}: {node}.ros__parameters must be a mapping')
        sections[str(node)] = dict(params)
    return sections


def node_params(sections: Mapping[str, Mapping[str, Any]], node: str) -> dict[str, Any]:
    """Merge the wildcard section with one node's section (the node's values win)."""
    merged = dict(sections.get(WILDCARD, {}))
    merged.update(sections.get(node, {}))
    return merged


def check_type(name: str, value: Any, hint: Any) -> Any:
    """``value`` as the type ``hint`` of field ``name`` (an integer is a valid double).

    Raises:
        ParamsError: another type, or a non-finite number.
    """
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ParamsError(f'parameter {name}: expected a number, got {value!r}')
        value = float(value)
        if not math.isfinite(value):
            raise ParamsError(f'parameter {name}: must be finite, got {value!r}')
        return value
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ParamsError(f'parameter {name}: expected an integer, got {value!r}')
        return value
    if hint is bool:
        if not isinstance(value, bool):
            raise ParamsError(f'parameter {name}: expected true or false, got {value!r}')
        return value
    if hint is str:
        if not isinstance(value, str):
            raise ParamsError(f'parameter {name}: expected a string, got {value!r}')
        return value
    raise TypeError(f'unsupported parameter type {hint!r} for {name}')


@functools.cache
def _field_types(cls: type) -> dict[str, Any]:
    """``typing.get_type_hints(cls)``, once per class (a fit builds a model, and so its
    config, at every evaluation of its objective: tens of thousands of times)."""
    return typing.get_type_hints(cls)


def build_config(cls: type[T], params: Mapping[str, Any]) -> T:
    """Build the frozen dataclass ``cls`` from the parameters whose names are its fields.

    Keys that are not fields of ``cls`` are ignored here (a params section feeds several
    components); :func:`check_known` rejects keys that no component knows.

    Raises:
        ParamsError: a field is missing or has the wrong type, or ``cls`` rejects a value.
    """
    if not dataclasses.is_dataclass(cls):
        raise TypeError(f'{cls!r} is not a dataclass')
    hints = _field_types(cls)
    kwargs: dict[str, Any] = {}
    for field in dataclasses.fields(cls):
        if field.name not in params:
            if field.default is not dataclasses.MISSING:
                continue
            raise ParamsError(f'parameter {field.name} is missing ({cls.__name__})')
        kwargs[field.name] = check_type(field.name, params[field.name], hints[field.name])
    try:
        return cls(**kwargs)
    except ParamsError:
        raise
    except ValueError as err:
        raise ParamsError(str(err)) from err


def check_known(params: Mapping[str, Any], *classes: type, where: str) -> None:
    """Reject parameters that none of ``classes`` declares (typos must not pass silently)."""
    known = {f.name for c in classes for f in dataclasses.fields(c)}
    unknown = sorted(set(params) - known)
    if unknown:
        raise ParamsError(f'{where}: unknown parameter(s) {with_suggestions(unknown, known)}')


def require(condition: bool, message: str) -> None:
    """Raise :class:`ParamsError` with ``message`` when ``condition`` is false."""
    if not condition:
        raise ParamsError(message)
