"""Declare a configuration dataclass as ROS parameters and build it validated, with the same
validator as ``trust-av`` (:func:`trust_av_common.params.build_config`).

Where a node's values come from, first wins:

1. its command line's ``-p name:=value`` (the last one of a name; a prefixed
   ``-p planner:name:=value`` only for the nodes its prefix names), over every params file;
2. its parameter overrides from ``--ros-args --params-file F ...`` (merged by rcl and rclpy);
2. the shipped params file (``share/trust_av_common/config/trust_av.yaml`` of a colcon
   install, else the source tree's ``config/``), matched against the node's fully qualified
   name: so a node started alone, without a params file, runs on the shipped values, and a
   params file holding one key is enough;
3. the dataclass default.

The values are checked by the dataclass (types, ranges, cross-field rules) before anything
is declared, so a node refuses exactly what ``trust-av`` refuses, with the same one line.
A double field accepts an integer (``dt_s: 1`` in a params file; rcl types it INTEGER):
the value is converted and the parameter declared as DOUBLE 1.0, so ``ros2 param get``
shows the type the field has. Every parameter is declared read-only with its description,
unit and (closed) range from the field's :class:`~trust_av_common.params.ParamSpec`.

:func:`check_overrides` refuses an override the node does not declare when it comes from a
section written for the node (``planner``, ``/**/planner``, ``/car1/planner``) or from
``-p`` on the command line: a typo. A wildcard section (``/**``, ``/*``) feeds every node of
a bring-up, each taking the keys it declares (rclpy ignores undeclared overrides), so an
unknown name there is only a warning in the node's log. The shipped file's names are never
refused (parameters of the graph's other nodes).
"""

from __future__ import annotations

import dataclasses
import functools
import sys
import typing
from collections.abc import Sequence
from typing import Any, TypeVar

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.node import Node
from rclpy.parameter import Parameter

from trust_av_common import registry
from trust_av_common.errors import with_suggestions
from trust_av_common.param_layers import (
    layered_params,
    read_layer,
    section_target,
    shipped_params_file,
)
from trust_av_common.params import (
    PARAM_METADATA_KEY,
    ParamsError,
    ParamSpec,
    build_config,
    check_type,
)
from trust_av_common.rcl_parser import parse_value
from trust_av_common.rcl_yaml import node_matches

__all__ = ['check_overrides', 'command_line_values', 'declare_component_params',
           'declare_config', 'param_rules', 'predeclare', 'predeclare_component',
           'use_command_line']

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
    low, high = spec.low, spec.high
    closed = low is not None and high is not None and spec.low_inclusive and spec.high_inclusive
    if closed and low is not None and high is not None and kind == Parameter.Type.DOUBLE:
        result.floating_point_range = [FloatingPointRange(from_value=float(low),
                                                          to_value=float(high))]
    elif closed and low is not None and high is not None and kind == Parameter.Type.INTEGER:
        result.integer_range = [IntegerRange(from_value=int(low), to_value=int(high), step=1)]
    if spec.choices:
        result.additional_constraints = f'one of: {", ".join(spec.choices)}'
    return result


_COMMAND_LINE: list[str] = []


def use_command_line(args: Sequence[str]) -> None:
    """The command line rclpy was initialised with (:func:`trust_av_common.ros.spin.init_rclpy`
    gives it): its ``-p`` rules win over the params files (module docstring). Not called:
    ``sys.argv``, as ``rclpy.init`` takes by default."""
    _COMMAND_LINE[:] = list(args)


def param_rules(args: Sequence[str]) -> list[tuple[str, str, str]]:
    """The ``-p``/``--param`` rules of a command line's ``--ros-args`` parts, in order.

    Returns:
        (section, name, value text) per rule: the section as rcl stores it (``/**``, or the
        node-name prefix of ``-p planner:alpha:=0.5``; rcl ``arguments.c``:
        ``_rcl_parse_nodename_prefix`` takes one token before ``:``).
    """
    rules: list[tuple[str, str, str]] = []
    for flag, rule in _ros_args(args):
        if flag not in ('-p', '--param') or ':=' not in rule:
            continue
        target, text = rule.split(':=', 1)
        section, _, name = target.rpartition(':')
        rules.append((section or '/**', name, text))
    return rules


@functools.cache
def _rule_value(name: str, text: str) -> Any:
    return parse_value(name, text)


def command_line_values(args: Sequence[str], fqn: str) -> dict[str, Any]:
    """The values the ``-p`` rules of ``args`` give node ``fqn`` (the last rule of a name
    wins), typed as rcl types them.

    Raises:
        ParamsError: rcl refuses a value (it did not: the node would not have started).
    """
    return {name: _rule_value(name, text) for section, name, text in param_rules(args)
            if node_matches(section, fqn)}


def node_overrides(node: Node) -> dict[str, Any]:
    """The parameter overrides of ``node``, name to value: rclpy's (params files and
    ``-p``, merged by rcl's rules), then its command line's ``-p`` values over them (module
    docstring).

    rclpy keeps its own in ``Node._parameter_overrides`` (``rclpy/node.py``, filled in
    ``Node.__init__`` from rcl's merged ``--params-file``/``-p`` values for this node); it
    has no public accessor, and both the coercion and the unknown-name check need them.
    """
    overrides: dict[str, Parameter] = node._parameter_overrides
    values = {name: param.value for name, param in overrides.items()}
    values.update(command_line_values(_COMMAND_LINE or sys.argv,
                                      node.get_fully_qualified_name()))
    return values


@functools.cache
def _shipped(fqn: str) -> tuple[dict[str, Any], str]:
    """The shipped file's values for node ``fqn`` and the file's path ('' if not found)."""
    try:
        path = shipped_params_file()
    except ParamsError:
        return {}, ''
    return layered_params([read_layer(path)], fqn), str(path)


@functools.cache
def shipped_names() -> frozenset[str]:
    """Every parameter name of the shipped params file (any section)."""
    try:
        layer = read_layer(shipped_params_file())
    except ParamsError:
        return frozenset()
    return frozenset(name for values in layer.values() for name in values)


def declare_config(node: Node, cls: type[T], extra: dict[str, Any] | None = None) -> T:
    """Build the validated config ``cls`` for ``node`` and declare its fields as read-only
    parameters (fields already declared by an earlier config of the node are shared).

    Args:
        node: the node.
        cls: a configuration dataclass whose fields are declared with ``param``.
        extra: values for fields that the node computes itself (not declared).

    Raises:
        ParamsError: a value of the wrong type, out of range, or fields with no value in
            the overrides, the shipped file or the dataclass (the message names all of them
            and how to pass them).
    """
    hints = typing.get_type_hints(cls)
    overrides = node_overrides(node)
    shipped, shipped_path = _shipped(node.get_fully_qualified_name())
    values: dict[str, Any] = dict(extra or {})
    missing: list[str] = []
    for field in dataclasses.fields(cls):  # type: ignore[arg-type]
        name = field.name
        if name in values:
            continue
        if node.has_parameter(name):
            values[name] = node.get_parameter(name).value
        elif name in overrides:
            if overrides[name] is None:  # rcl holds the name without a value (e.g. [])
                raise ParamsError(f'parameter {name} has no value (e.g. [] or {{}})')
            values[name] = check_type(name, overrides[name], hints[name])
        elif name in shipped:
            values[name] = check_type(name, shipped[name], hints[name])
        elif field.default is dataclasses.MISSING:
            missing.append(name)
    if missing:   # every value a run must supply, in one line
        them = 'them' if len(missing) > 1 else 'it'
        hint = (f'no params file sets {them}, each run supplies {them} (trust-av does; by '
                'hand: pass --ros-args ' + ' '.join(f'-p {name}:=VALUE' for name in missing)
                + ')' if shipped_path else 'the shipped params file was not found: pass '
                '--ros-args --params-file config/trust_av.yaml of the trust-av sources')
        plural = 's' if len(missing) > 1 else ''
        raise ParamsError(f'parameter{plural} {", ".join(missing)} '
                          f'{"are" if plural else "is"} missing ({cls.__name__}): {hint}')
    config = build_config(cls, values)
    for field in dataclasses.fields(cls):  # type: ignore[arg-type]
        name = field.name
        if (extra and name in extra) or node.has_parameter(name):
            continue
        value = values.get(name, field.default)
        node.declare_parameter(name, value, descriptor(field, hints[name]),
                               ignore_override=True)
    return config


def predeclare(node: Node, cls: type) -> None:
    """Declare the fields of ``cls`` on ``node`` before any validation, so ``ros2 param``
    shows a managed node's parameters while it is still ``unconfigured``: each with the value
    :func:`declare_config` would take (override, shipped file, default) and its descriptor.
    A field whose value is missing, of the wrong type or outside its descriptor's range is
    left undeclared here: ``configure`` refuses it with the one line :func:`declare_config`
    gives, and the process goes on. :func:`declare_config` at ``configure`` reads the
    declared values, so both see one value.
    """
    hints = typing.get_type_hints(cls)
    overrides = node_overrides(node)
    shipped, _ = _shipped(node.get_fully_qualified_name())
    for field in dataclasses.fields(cls):
        name = field.name
        if node.has_parameter(name):
            continue
        try:
            if name in overrides:
                value = check_type(name, overrides[name], hints[name])
            elif name in shipped:
                value = check_type(name, shipped[name], hints[name])
            elif field.default is not dataclasses.MISSING:
                value = field.default
            else:
                continue
            node.declare_parameter(name, value, descriptor(field, hints[name]),
                                   ignore_override=True)
        except (ParamsError, InvalidParameterValueException, InvalidParameterTypeException):
            continue   # refused at configure, with its one line


def predeclare_component(node: Node, group: str, chooser: str) -> None:
    """:func:`predeclare` the parameters of the component of ``group`` that the (declared)
    parameter ``chooser`` names; nothing if it is not declared or names no registered
    component (``configure`` says which)."""
    if not node.has_parameter(chooser):
        return
    try:
        component = registry.get(group, str(node.get_parameter(chooser).value))
    except registry.RegistryError:
        return
    if component.config_type is not None:
        predeclare(node, component.config_type)


def ros_args_sources(args: Sequence[str]) -> tuple[list[str], list[str]]:
    """The params files and the ``-p`` names of a command line's ``--ros-args`` parts.

    rcl reads ``--params-file FILE`` and ``-p``/``--param name:=value`` between
    ``--ros-args`` and ``--`` (or the end), any number of such parts (rcl ``arguments.c``).

    Returns:
        (params files in order, parameter names set with ``-p``).
    """
    files = [value for flag, value in _ros_args(args) if flag == '--params-file']
    return files, [name for _, name, _ in param_rules(args)]


def _ros_args(args: Sequence[str]) -> list[tuple[str, str]]:
    """(flag, its argument) of ``--params-file``, ``-p`` and ``--param`` between
    ``--ros-args`` and ``--`` (or the end), any number of such parts (rcl ``arguments.c``)."""
    found: list[tuple[str, str]] = []
    inside = False
    items = iter(args)
    for item in items:
        if item == '--ros-args':
            inside = True
        elif item == '--':
            inside = False
        elif inside and item in ('--params-file', '-p', '--param'):
            found.append((item, next(items, '')))
    return found


def override_origins(args: Sequence[str], fqn: str) -> tuple[dict[str, str], set[str]]:
    """Where the overrides of node ``fqn`` were written.

    Returns:
        (name -> the place of a section written for this node or ``-p``: refused if
        unknown; the names written in wildcard sections that apply to it).
    """
    files, names = ros_args_sources(args)
    own = {name: 'the command line (-p)' for name in names}
    wildcard: set[str] = set()
    for path in files:
        try:
            layer = read_layer(path)
        except ParamsError:
            continue   # rcl read it (the node is up); the names stay unplaced: refused
        for section, values in layer.items():
            if not node_matches(section, fqn):
                continue
            if section_target(section) is None:
                wildcard.update(values)
            else:
                for name in values:
                    own.setdefault(name, f'{path}: section {section}')
    return own, wildcard


def check_overrides(node: Node, args: Sequence[str] = ()) -> None:
    """Refuse a parameter override that neither ``node`` declares nor the shipped params
    file holds (a name of another node of the graph), unless it comes only from wildcard
    sections (then log a warning).

    Args:
        node: the node, with its parameters declared.
        args: the command line the node was started with (its ``--ros-args``).

    Raises:
        ParamsError: one line naming the parameter(s): from the node's own section, from
            ``-p``, or from nowhere the command line shows.
    """
    declared = set(node.list_parameters([], 0).names)  # depth 0: every declared name
    # the shipped file's names are parameters of the graph's nodes: never a typo
    unknown = set(node_overrides(node)) - declared - shipped_names()
    if not unknown:
        return
    fqn = node.get_fully_qualified_name()
    own, wildcard = override_origins(args, fqn)
    refused = sorted(name for name in unknown if name in own or name not in wildcard)
    if refused:
        places = sorted({own[name] for name in refused if name in own})
        where = f' (from {"; ".join(places)})' if places else ''
        raise ParamsError(f'{fqn}: unknown parameter(s) {with_suggestions(refused, declared)} '
                          '(not a parameter '
                          f'of this node or of any node of the graph){where}')
    node.get_logger().warning(f'ignoring parameter(s) {", ".join(sorted(unknown))} of a '
                              'wildcard section: not parameters of any node of the graph')



def declare_component_params(node: Node, group: str, name: str) -> Any:
    """The parameters of the registered component ``name`` of ``group``
    (:mod:`trust_av_common.registry`), declared on ``node`` like any other; None when
    the component has none.

    Raises:
        RegistryError: ``name`` is not registered (one line listing the registered names).
        ParamsError: a parameter value is refused.
    """
    component = registry.get(group, name)
    return None if component.config_type is None else declare_config(node,
                                                                      component.config_type)
