"""Read ROS 2 params files and build validated, frozen configuration dataclasses.

A ROS 2 params file maps node names to ``ros__parameters``; the wildcard section ``/**``
applies to every node. This module is the one reader the project's CLIs use, so that a
parameter means the same thing in the in-process simulator and in the node graph (where
rclpy itself parses the same file from ``--ros-args --params-file``).
"""

from __future__ import annotations

import dataclasses
import math
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any, TypeVar

import yaml

WILDCARD = '/**'
T = TypeVar('T')


class ParamsError(ValueError):
    """A params file or a parameter value is invalid; the message names the culprit."""


def read_params_file(path: str | Path) -> dict[str, dict[str, Any]]:
    """Read a ROS 2 params file.

    Args:
        path: YAML file in ROS 2 params-file format.

    Returns:
        Node name (or ``/**``) to its ``ros__parameters`` mapping.

    Raises:
        ParamsError: the file is missing, not YAML, or not in params-file format.
    """
    path = Path(path)
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


def _check_type(name: str, value: Any, hint: Any) -> Any:
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


def build_config(cls: type[T], params: Mapping[str, Any]) -> T:
    """Build the frozen dataclass ``cls`` from the parameters whose names are its fields.

    Keys that are not fields of ``cls`` are ignored here (a params section feeds several
    components); :func:`check_known` rejects keys that no component knows.

    Raises:
        ParamsError: a field is missing or has the wrong type, or ``cls`` rejects a value.
    """
    if not dataclasses.is_dataclass(cls):
        raise TypeError(f'{cls!r} is not a dataclass')
    hints = typing.get_type_hints(cls)
    kwargs: dict[str, Any] = {}
    for field in dataclasses.fields(cls):
        if field.name not in params:
            if field.default is not dataclasses.MISSING:
                continue
            raise ParamsError(f'parameter {field.name} is missing ({cls.__name__})')
        kwargs[field.name] = _check_type(field.name, params[field.name], hints[field.name])
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
        raise ParamsError(f'{where}: unknown parameter(s) {", ".join(unknown)}')


def require(condition: bool, message: str) -> None:
    """Raise :class:`ParamsError` with ``message`` when ``condition`` is false."""
    if not condition:
        raise ParamsError(message)
