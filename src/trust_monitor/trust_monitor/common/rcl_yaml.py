"""Pure-Python mirror of rcl's params-file rules (ROS 2 Jazzy), for checking files up front.

A node started with ``--ros-args --params-file F`` gets its parameter overrides from rcl's
C parser (``ros2/rcl``, package ``rcl_yaml_param_parser``, Jazzy tag 9.2.0; the wheels
installed here are 9.2.8) and from rclpy's node-name matching (``ros2/rclpy`` 7.1.x,
``rclpy/src/rclpy/node.cpp``). This module reproduces both, event by event, so that
``trust-av`` can accept exactly the files a node accepts and refuse, with one line, the
files a node would refuse. ``tests/test_rcl_yaml_rules.py`` holds it to the real parser.

What rcl does, with the function each rule comes from:

* ``parse.c: parse_file_events`` walks libyaml events. Alias events are refused ("Will not
  support aliasing"); anchors, tags, document markers and several documents in one file
  are not refused (all documents land in one structure). Keys before ``ros__parameters``
  nest as a node namespace joined with ``/``; a key that *starts with* ``ros__parameters``
  (``strncmp`` on its length) opens the parameters of the node named so far. A scalar
  value anywhere above that level is refused ("Cannot have a value before
  ros__parameters"), so is a sequence above it or a sequence used as a key.
* ``parse.c: parse_key``: an empty key is refused; the node name is checked by
  ``_validate_name`` (``/**`` and ``/*`` allowed whole, ``**``/``*`` as a namespace token
  or as the node name; every other token by rmw's namespace and node-name rules). Nested
  maps under ``ros__parameters`` become dotted names: the entry of the map's key is
  renamed to ``key.child`` and later children get new entries (``find_parameter``).
* ``parse.c: parse_value`` and ``get_value``: an unquoted empty value is refused ("No
  value"); ``!!str`` makes a string; otherwise, unless quoted, the YAML 1.1 words
  ``y/yes/true/on`` (and capitalised forms) are booleans, a whole ``strtoll(.., 0)`` is an
  integer (so ``0x1F`` is 31 and ``010`` is 8), a whole ``strtod`` without ``ERANGE`` is a
  double (``1e3``, ``inf``, ``nan``, ``08``, the ``.nan``/``.inf`` forms), anything else a
  string (``null`` and ``~`` are the strings ``'null'`` and ``'~'``). Items of one sequence
  must share a type ("Sequence should be of same type"). A value written again fills the
  slot of its type in the same ``rcl_variant_t`` and leaves the other slots as they were.
* ``namespace.c: rem_name_from_ns`` strips a parameter namespace at its last ``.``.
* ``rcl/src/rcl/arguments.c: _rcl_parse_param_file``: every ``--params-file`` is parsed
  into the same ``rcl_params_t``, in command-line order.
* rclpy ``node.cpp: _parameter_from_rcl_variant`` reads the first slot set in the order
  bool, integer, double, string, byte array, bool/integer/double/string array (so an
  integer written first survives a later double or string for the same name).
* rclpy ``node.cpp: _populate_node_parameters_from_rcl_params`` visits the node sections
  in order of first appearance, prefixes a ``/``, turns each ``/*`` into ``(/\\w+)`` (so
  ``/**`` becomes ``(/\\w+)*``) and applies every section that ``std::regex_match``-es the
  node's fully qualified name, later sections over earlier ones. A plain ``planner:``
  section therefore applies to ``/planner`` only, never to ``/car1/planner``.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import yaml

from trust_monitor.common.params import ParamsError
from trust_monitor.common.rcl_values import (
    _NODE_LEVEL,
    _PARAMS_LEVEL,
    PARAMS_KEY,
    ParsedParams,
    RclParams,
    _c_string,
    _name,
    _NodeEntry,
    _set_value,
    _validate_name,
    rcl_scalar_value,
)


class _Tracker:
    """``impl/types.h: namespace_tracker_t`` with ``namespace.c``'s three operations."""

    def __init__(self) -> None:
        self.node_ns: str | None = None
        self.num_node_ns = 0
        self.param_ns: str | None = None
        self.num_param_ns = 0

    def add_node(self, name: str) -> None:
        """``add_name_to_ns`` for a node namespace (separator ``/``, not doubled)."""
        if self.num_node_ns == 0 or self.node_ns is None:
            self.node_ns = name
        elif self.node_ns.endswith('/'):
            self.node_ns += name
        else:
            self.node_ns += '/' + name
        self.num_node_ns += 1

    def remove(self, node: bool) -> None:
        """``rem_name_from_ns``: drop the text after the last separator, count one less."""
        count = self.num_node_ns if node else self.num_param_ns
        current = self.node_ns if node else self.param_ns
        if count == 0:
            return
        if count == 1:
            current = None
        elif current is not None:
            separator = '/' if node else '.'
            cut = current.rfind(separator)
            if cut >= 0:
                current = current[:cut]
        if node:
            self.node_ns, self.num_node_ns = current, count - 1
        else:
            self.param_ns, self.num_param_ns = current, count - 1


def _events(text: str) -> Iterable[yaml.Event]:
    """libyaml's events for ``text`` (PyYAML's C binding when built, else its own parser)."""
    loader = getattr(yaml, 'CSafeLoader', yaml.SafeLoader)
    events: Iterable[yaml.Event] = yaml.parse(text, Loader=loader)
    return events


def _yaml_problem(err: yaml.YAMLError) -> str:
    """A YAML syntax error as one line without file content."""
    problem = getattr(err, 'problem', None) or 'syntax error'
    # Keep quoted punctuation (',' or ']'), drop anything that could be file content.
    problem = re.sub(r"'[^']*'|\"[^\"]*\"",
                     lambda m: '(...)' if re.search(r'[A-Za-z0-9\\]', m.group()) else m.group(),
                     str(problem)).replace('\n', ' ')
    mark = getattr(err, 'problem_mark', None)
    line = f'line {mark.line + 1}: ' if mark is not None else ''
    return f'{line}not valid YAML ({problem})'


def parse_params_into(params: RclParams, text: str, where: str) -> None:
    """Parse one params file into ``params`` as ``parser.c: rcl_parse_yaml_file`` does.

    Args:
        params: the structure shared by all files of one command line.
        text: the file's contents.
        where: the file's name, for messages.

    Raises:
        ParamsError: what rcl refuses, in one line naming the file, line and key.
    """
    tracker = _Tracker()
    is_key = True
    is_seq = False
    sequence_type: list[type] = []
    map_level = _NODE_LEVEL
    map_depth = 0
    is_new_map = False
    entry: _NodeEntry | None = None
    parameter_index = 0
    line = 0
    events = iter(_events(text))
    while True:
        try:
            event = next(events)
        except StopIteration:
            break
        except yaml.YAMLError as err:
            raise ParamsError(f'{where}: {_yaml_problem(err)}') from err
        line = event.start_mark.line + 1 if event.start_mark is not None else line
        if isinstance(event, yaml.ScalarEvent):
            if is_key:
                key = event.value
                if len(key) == 0:
                    raise ParamsError(f'{where}: line {line}: empty key')
                key = _c_string(key)
                if map_level == _NODE_LEVEL:
                    if not key.startswith(PARAMS_KEY):
                        tracker.add_node(key)
                    else:
                        if tracker.num_node_ns == 0 or tracker.node_ns is None:
                            raise ParamsError(f'{where}: line {line}: {PARAMS_KEY} without a '
                                              'node name above it')
                        problem = _validate_name(tracker.node_ns)
                        if problem:
                            raise ParamsError(f'{where}: line {line}: node name '
                                              f'{_name(tracker.node_ns)}: {problem}')
                        entry = params.find_node(tracker.node_ns)
                        tracker.remove(node=True)
                        map_level += 1
                else:
                    assert entry is not None
                    if is_new_map:
                        tracker.param_ns = entry.names[parameter_index]
                        tracker.num_param_ns += 1
                        is_new_map = False
                    if tracker.param_ns is None:
                        parameter_index = entry.find(key)
                    else:
                        parameter_index = entry.find(tracker.param_ns)
                        entry.names[parameter_index] = f'{tracker.param_ns}.{key}'
                is_key = False
            else:
                if map_level < _PARAMS_LEVEL or entry is None or not entry.names:
                    above = f' under {_name(tracker.node_ns)}' if tracker.node_ns else ''
                    raise ParamsError(f'{where}: line {line}: a value{above} above '
                                      f'{PARAMS_KEY} (every section needs <node>: '
                                      f'{PARAMS_KEY}: <name>: <value>)')
                parameter = entry.names[parameter_index]
                quoted = event.style in ("'", '"')
                if not quoted and len(event.value) == 0:
                    raise ParamsError(f'{where}: line {line}: parameter {_name(parameter)} has '
                                      'no value')
                value = rcl_scalar_value(event.value, quoted, event.tag)
                _set_value(entry.values[parameter_index], value, is_seq, sequence_type, where,
                           line, parameter)
                if not is_seq:
                    is_key = True
        elif isinstance(event, yaml.SequenceStartEvent):
            if is_key or map_level < _PARAMS_LEVEL:
                raise ParamsError(f'{where}: line {line}: a sequence where rcl needs a key or a '
                                  f'mapping (sequences are values under {PARAMS_KEY} only)')
            is_seq = True
            sequence_type = []
        elif isinstance(event, yaml.SequenceEndEvent):
            is_seq = False
            is_key = True
        elif isinstance(event, yaml.MappingStartEvent):
            map_depth += 1
            is_new_map = True
            is_key = True
            if map_level == _PARAMS_LEVEL and map_depth - (tracker.num_node_ns + 1) == 2:
                is_new_map = False
        elif isinstance(event, yaml.MappingEndEvent):
            if map_level == _PARAMS_LEVEL:
                if tracker.num_param_ns > 0:
                    tracker.remove(node=False)
                else:
                    map_level -= 1
            elif map_level == _NODE_LEVEL and map_depth == tracker.num_node_ns + 1:
                tracker.remove(node=True)
            map_depth -= 1
        elif isinstance(event, yaml.AliasEvent):
            key = ''
            if map_level == _PARAMS_LEVEL and entry is not None and not is_key:
                key = f'parameter {_name(entry.names[parameter_index])}: '
            raise ParamsError(f'{where}: line {line}: {key}YAML alias (*name): rcl will not '
                              'support aliasing; write the value out')
        # Stream and document start/end events: rcl ignores them (parse_file_events).


def parse_params_text(text: str, where: str) -> ParsedParams:
    """Parse one params file as rcl does and type its values as rclpy reads them.

    Args:
        text: the file's contents.
        where: the file's name, for messages.

    Returns:
        Section name (as written, e.g. ``/**``, ``planner``, ``/car1/planner``) to
        ``{parameter: value}``; nested maps are flattened to dotted names; values are
        bool, int, float, str, lists of one of those, or ``None`` for a parameter rcl
        holds without a value (e.g. ``[]``).

    Raises:
        ParamsError: rcl would refuse the file; one line naming the file, line and key.
    """
    params = RclParams()
    parse_params_into(params, text, where)
    return ParsedParams(params.resolved(), text, where)


def section_regex(section: str) -> str:
    """rclpy ``node.cpp``: the regular expression a section name stands for."""
    name = section if section.startswith('/') else '/' + section
    return name.replace('/*', '(/\\w+)')


def node_matches(pattern: str, node_fqn: str) -> bool:
    """Whether a params-file section applies to a node, as rclpy decides.

    Args:
        pattern: the section name as written (``/**``, ``/*``, ``/**/planner``,
            ``/car1/planner``, ``planner``, ...).
        node_fqn: the node's fully qualified name, e.g. ``/car1/planner``.
    """
    if not pattern:
        raise ParamsError('empty node name in a params file section')
    return re.fullmatch(section_regex(pattern), node_fqn, flags=re.ASCII) is not None


def _replay_plain(params: RclParams, sections: Mapping[str, Mapping[str, Any]]) -> None:
    """Merge a plain mapping (not from :func:`parse_params_text`) into ``params``."""
    for node, values in sections.items():
        entry = params.find_node(node)
        for name, value in values.items():
            variant = entry.values[entry.find(name)]
            if isinstance(value, (list, tuple)):
                kinds = {type(item) for item in value}
                if len(kinds) > 1:
                    raise ParamsError(f'parameter {_name(name)}: items of one sequence must '
                                      'have one type')
                for kind in kinds:
                    slot = {bool: 'bool_array', int: 'integer_array', float: 'double_array',
                            str: 'string_array'}[kind]
                    setattr(variant, slot, list(value))
            elif value is not None:
                _set_value(variant, value, False, [], 'params', 0, name)


def params_for_node(files: Sequence[Mapping[str, Mapping[str, Any]]],
                    node_fqn: str) -> dict[str, Any]:
    """The parameter overrides a node gets from ``--params-file`` given once per file.

    The files are parsed, in order, into one structure (``arguments.c``), then every
    section whose name matches ``node_fqn`` is applied in order of first appearance
    (rclpy ``node.cpp``). So a later file wins for a section that first appeared in it or
    later, but a section that first appeared earlier is applied earlier: with file 1
    holding ``/**`` and ``planner`` and file 2 holding ``/**`` alone, file 1's ``planner``
    values still win for ``/planner``. Within one file the later section wins, whatever
    its specificity.

    Args:
        files: results of :func:`parse_params_text` (replayed exactly), or plain mappings
            (merged slot by slot, without rcl's renaming of nested maps across files).
        node_fqn: the node's fully qualified name, e.g. ``/car1/planner``.

    Returns:
        Parameter name to value, as the node's parameter overrides.

    Raises:
        ParamsError: a file is refused by rcl, or a parameter for this node has no value
            (rcl keeps ``a: []`` as a name without a value; rclpy's node refuses it).
    """
    params = RclParams()
    for sections in files:
        if isinstance(sections, ParsedParams):
            parse_params_into(params, sections.text, sections.where)
        else:
            _replay_plain(params, sections)
    merged: dict[str, Any] = {}
    for node, entry in params.nodes.items():
        if node_matches(node, node_fqn):
            for name, variant in zip(entry.names, entry.values, strict=True):
                merged[name] = variant.value()
    for name, value in merged.items():
        if value is None:
            # rclpy node.py declare_parameters: 'Cannot declare a statically typed
            # parameter with default value of type PARAMETER_NOT_SET'.
            raise ParamsError(f'{node_fqn}: parameter {_name(name)} has no value (e.g. [] or '
                              '{}); rclpy refuses to declare it')
    return merged
