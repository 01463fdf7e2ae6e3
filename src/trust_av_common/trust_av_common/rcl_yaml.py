"""Params files as a node reads them: rcl's parser (:mod:`~trust_av_common.rcl_parser`)
and rclpy's section matching.

A node started with ``--ros-args --params-file F`` gets its parameter overrides from rcl's
C parser (``ros2/rcl``, package ``rcl_yaml_param_parser``, ``parser.c:
rcl_parse_yaml_file``), which this module calls itself through ctypes, and from rclpy's
node-name matching, which rcl does not expose and which is therefore reproduced here:

* rclpy ``rclpy/src/rclpy/node.cpp: _populate_node_parameters_from_rcl_params`` (7.1.x)
  visits the node sections in rcl's order (first appearance over all files), prefixes a
  ``/`` to a relative name, turns each ``/*`` into ``(/\\w+)`` (so ``/**`` becomes
  ``(/\\w+)*``) and applies every section that ``std::regex_match``-es the node's fully
  qualified name, later sections over earlier ones. A plain ``planner:`` section therefore
  applies to ``/planner`` only, never to ``/car1/planner``.
* rclpy ``rclpy/node.py: declare_parameters`` refuses an override without a value (rcl keeps
  ``a: []`` or ``a: {}`` as a name whose ``rcl_variant_t`` has no slot set).

``tests/graph/test_rcl_yaml_rules.py`` holds both to a node started with the same files.

rcl's refusals are reported in one line with rcl's own reason and line; this module adds
the key or section at that line (found with PyYAML, which reads the text with libyaml as
rcl does) and, for text that is not YAML, libyaml's own problem, never the file's content.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from typing import Any

import yaml

from trust_av_common.params import ParamsError
from trust_av_common.rcl_parser import RclParseError, parse_files
from trust_av_common.rcl_values import PARAMS_KEY, ParsedParams, _name

__all__ = ['node_matches', 'params_for_node', 'parse_params_text']


def _events(text: str) -> tuple[list[tuple[int, yaml.Event]], yaml.YAMLError | None]:
    """libyaml's events for ``text`` with their 1-based lines, up to the first syntax error,
    and that error (None: ``text`` is YAML). Only for messages: rcl has refused the file."""
    loader = getattr(yaml, 'CSafeLoader', yaml.SafeLoader)
    events: list[tuple[int, yaml.Event]] = []
    try:
        for event in yaml.parse(text, Loader=loader):
            line = event.start_mark.line + 1 if event.start_mark is not None else 0
            events.append((line, event))
    except yaml.YAMLError as err:
        return events, err
    return events, None


def _yaml_problem(err: yaml.YAMLError) -> str:
    """libyaml's reason a text is not YAML, without any of its content."""
    problem = str(getattr(err, 'problem', None) or 'syntax error')
    # Keep quoted punctuation (',' or ']'), drop anything that could be file content.
    return re.sub(r"'[^']*'|\"[^\"]*\"",
                  lambda m: '(...)' if re.search(r'[A-Za-z0-9\\]', m.group()) else m.group(),
                  problem).replace('\n', ' ')


def _key_paths(text: str) -> list[tuple[int, list[str]]]:
    """Each mapping key's line and path of keys from the top (``['planner',
    'ros__parameters', 'alpha']``), in file order."""
    paths: list[tuple[int, list[str]]] = []
    stack: list[list[Any]] = []  # per open collection: [is_mapping, expecting_key, key]
    for line, event in _events(text)[0]:
        top = stack[-1] if stack else None
        if isinstance(event, (yaml.ScalarEvent, yaml.AliasEvent,
                              yaml.MappingStartEvent, yaml.SequenceStartEvent)):
            if top is not None and top[0]:
                if top[1]:
                    key = event.value if isinstance(event, yaml.ScalarEvent) else '?'
                    top[2] = key
                    keys = [str(entry[2]) for entry in stack if entry[0]]
                    paths.append((line, keys))
                top[1] = not top[1]
            if isinstance(event, yaml.MappingStartEvent):
                stack.append([True, True, None])
            elif isinstance(event, yaml.SequenceStartEvent):
                stack.append([False, False, None])
        elif isinstance(event, (yaml.MappingEndEvent, yaml.SequenceEndEvent)) and stack:
            stack.pop()
    return paths


def _describe(keys: list[str]) -> str:
    """A key path as one short phrase: the parameter and section, or the key above
    ``ros__parameters``."""
    for index, key in enumerate(keys):
        if key.startswith(PARAMS_KEY) and index > 0:
            section = '/'.join(keys[:index])
            if index + 1 < len(keys):
                return (f'parameter {_name(".".join(keys[index + 1:]))} of section '
                        f'{_name(section)}: ')
            return f'section {_name(section)}: '
    return f'key {_name("/".join(keys))}: '


def _sections(text: str) -> list[str]:
    """The node names of ``text``'s sections in file order, joined as rcl joins them."""
    names = []
    for _, keys in _key_paths(text):
        for index, key in enumerate(keys):
            if key.startswith(PARAMS_KEY) and index > 0 and index == len(keys) - 1:
                name = ''
                for part in keys[:index]:
                    name = part if not name else name + ('' if name.endswith('/') else '/') + part
                names.append(name)
    return names


# Advice added to rcl's reasons (by the start of rcl's text, parse.c).
_HINTS = {
    'Will not support aliasing': 'a YAML alias (*name): write the value out',
    'Cannot have a value before': ('every section needs <node>: ros__parameters: <name>: '
                                   '<value>'),
    'Sequence should be of same type': 'items of one list must have one type',
    'Sequences can only be values': 'a list is a value under ros__parameters only',
    'Sequences cannot be key': 'a list is a value under ros__parameters only',
    'No value': 'write a value, or quote an empty string',
}


def _refusal(err: RclParseError, text: str) -> ParamsError:
    """rcl's refusal in one line: file, rcl's line, the key or section it concerns, rcl's
    reason, advice, and libyaml's problem for text that is not YAML."""
    reason = err.reason
    hint = next((advice for start, advice in _HINTS.items() if reason.startswith(start)), None)
    if hint:
        reason += f' ({hint})'
    if err.line is not None:
        above = [keys for line, keys in _key_paths(text) if line <= err.line]
        context = _describe(above[-1]) if above else ''
        syntax_error = _events(text)[1]
        if syntax_error is not None:
            reason += f' (not valid YAML: {_yaml_problem(syntax_error)})'
        return ParamsError(f'{err.where}: line {err.line}: {context}rcl: {reason}')
    # No line (a section's node name rmw refuses): the first section rcl did not store.
    context = next((f'section {_name(name)}: ' for name in _sections(text)
                    if name not in err.stored), '')
    return ParamsError(f'{err.where}: {context}rcl: {reason}')


def _parse(layers: Sequence[ParsedParams]) -> dict[str, dict[str, Any]]:
    """All layers into one rcl structure, refusals in one line with their context."""
    try:
        return parse_files([(layer.text.encode('utf-8'), layer.where) for layer in layers])
    except RclParseError as err:
        text = next(layer.text for layer in layers if layer.where == err.where)
        raise _refusal(err, text) from err


def parse_params_text(text: str, where: str) -> ParsedParams:
    """Parse one params file with rcl and type its values as rclpy reads them.

    Args:
        text: the file's contents.
        where: the file's name, for messages.

    Returns:
        Section name (as rcl stores it, e.g. ``/**``, ``planner``, ``/car1/planner``) to
        ``{parameter: value}``; nested maps are flattened to dotted names; values are
        bool, int, float, str, lists of one of those, or ``None`` for a parameter rcl
        holds without a value (e.g. ``[]``).

    Raises:
        ParamsError: rcl refuses the file; one line naming the file, rcl's line and reason,
            and the key or section it concerns.
    """
    layer = ParsedParams({}, text, where)
    layer.update(_parse([layer]))
    return layer


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

    Raises:
        ParamsError: ``pattern`` is empty.
    """
    if not pattern:
        raise ParamsError('empty node name in a params file section')
    return re.fullmatch(section_regex(pattern), node_fqn, flags=re.ASCII) is not None


def params_for_node(files: Sequence[ParsedParams], node_fqn: str) -> dict[str, Any]:
    """The parameter overrides a node gets from ``--params-file`` given once per file.

    The files are parsed by rcl, in order, into one structure (``arguments.c``), then every
    section whose name matches ``node_fqn`` is applied in order of first appearance
    (rclpy ``node.cpp``). So a later file wins for a section that first appeared in it or
    later, but a section that first appeared earlier is applied earlier: with file 1
    holding ``/**`` and ``planner`` and file 2 holding ``/**`` alone, file 1's ``planner``
    values still win for ``/planner``. Within one file the later section wins, whatever
    its specificity.

    Args:
        files: results of :func:`parse_params_text` (their text is parsed again, together).
        node_fqn: the node's fully qualified name, e.g. ``/car1/planner``.

    Returns:
        Parameter name to value, as the node's parameter overrides.

    Raises:
        ParamsError: a file is refused by rcl, or a parameter for this node has no value
            (rcl keeps ``a: []`` as a name without a value; rclpy's node refuses it).
    """
    merged: dict[str, Any] = {}
    for node, values in _parse(files).items():
        if node_matches(node, node_fqn):
            merged.update(values)
    for name, value in merged.items():
        if value is None:
            # rclpy node.py declare_parameters: 'Cannot declare a statically typed
            # parameter with default value of type PARAMETER_NOT_SET'.
            raise ParamsError(f'{node_fqn}: parameter {_name(name)} has no value (e.g. [] or '
                              '{}); rclpy refuses to declare it')
    return merged
