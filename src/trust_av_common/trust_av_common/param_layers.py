"""Params files in layers, read by rcl's rules: the one reader behind ``trust-av``,
``trust-monitor-estimate`` and the nodes' defaults.

A run's configuration is an ordered list of ROS 2 params files: the shipped
``config/trust_av.yaml`` first, then every ``--params-file`` in command-line order. The nodes
get exactly that list (``--ros-args --params-file F1 --params-file F2 ...``), so the values
are what rcl and rclpy make of it (:mod:`trust_av_common.rcl_yaml`: all files parsed by
rcl's own parser into one structure, sections matched against the node's fully qualified
name and applied in order of first appearance). Two of rcl's rules would silently drop a
value the user wrote in a later file; :func:`layered_params` refuses both instead, naming
the file and parameter:

- a section that first appeared in an earlier file is applied at its first appearance, so
  ``/**: alpha: 0.3`` in a later file loses against an earlier ``planner: alpha: 0.5``;
- a value fills the slot of its own type and rclpy reads an integer before a double, so
  ``dt_s: 0.5`` in a later file loses against an earlier ``dt_s: 1``.

Sections may name nodes in any namespace (``/**/planner``, ``/*/planner``, ``car1/planner``,
``/**``); a section applies to a node when rclpy would apply it.
"""

from __future__ import annotations

import os
import stat
import sys
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from trust_av_common.input_files import not_regular
from trust_av_common.params import ParamsError
from trust_av_common.rcl_values import ParsedParams
from trust_av_common.rcl_yaml import params_for_node, parse_params_text

__all__ = ['Layered', 'layer_files', 'layered_params', 'node_fqn', 'read_layer', 'read_layers',
           'section_target', 'shipped_params_file', 'text_layer', 'to_params_text']

SHIPPED_PARAMS = 'trust_av.yaml'
"""File name of the shipped params file (every parameter of the graph, the paper's values)."""
SHARE_PACKAGE = 'trust_av_common'
"""The package whose ``share/<package>/config/`` holds the installed params files."""
MAX_PARAMS_BYTES = 1 << 20
"""Largest params file read (1 MiB; the shipped one is 5 kB)."""
WILDCARD_TOKENS = ('*', '**')
_KINDS = {bool: 'boolean', int: 'integer', float: 'double', str: 'string', list: 'list'}
_ARTICLES = {'integer': 'an'}
_DBL_MIN = 2.2250738585072014e-308  # smallest normal double: strtod gives ERANGE below


def shipped_params_file(name: str = SHIPPED_PARAMS) -> Path:
    """A shipped params file: ``share/trust_av_common/config/<name>`` when this package was
    installed by colcon (found through ament_index_python), else the source tree's
    ``config/<name>`` (an editable install), else ``<sys.prefix>/share/trust_av_common/config``
    (a wheel).

    Raises:
        ParamsError: neither place has the file.
    """
    here = Path(__file__).resolve()
    installed_by_colcon = _colcon_share(here)
    if installed_by_colcon is not None:
        return installed_by_colcon / 'config' / name
    source = here.parent / 'config' / name
    if source.exists():
        return source.resolve()
    installed = Path(sys.prefix) / 'share' / SHARE_PACKAGE / 'config' / name  # pip install
    if installed.exists():
        return installed
    raise ParamsError(f'cannot find the shipped params file {name}: neither share/'
                      f'{SHARE_PACKAGE}/config/ of a colcon or pip install nor the source '
                      f'tree ({source.parent}) has it')


def _colcon_share(module: Path) -> Path | None:
    """``share/trust_av_common`` of the colcon install ``module`` belongs to (None: the module
    is not an installed copy, or there is no ament index at all, as in a bare venv)."""
    try:
        from ament_index_python.packages import (
            PackageNotFoundError,
            get_package_prefix,
            get_package_share_directory,
        )
    except ImportError:
        return None
    try:
        prefix = Path(get_package_prefix(SHARE_PACKAGE)).resolve()
    except (PackageNotFoundError, OSError):  # OSError: AMENT_PREFIX_PATH is not set
        return None
    if prefix not in module.parents:  # another install: this module is the source tree
        return None
    return Path(get_package_share_directory(SHARE_PACKAGE))


def layer_files(files: str | Path | Iterable[str | Path] = (),
                base: Path | None = None) -> tuple[Path, ...]:
    """The ordered params files of a run: ``base`` (default: the shipped file), then ``files``.

    A first file that is ``base`` itself is not repeated.
    """
    bottom = base if base is not None else shipped_params_file()
    given = [Path(files)] if isinstance(files, (str, Path)) else [Path(f) for f in files]
    if given and given[0].resolve() == bottom.resolve():
        given = given[1:]
    return (bottom, *given)


def read_layer(path: str | Path) -> ParsedParams:
    """Read one params file with rcl's parser (:func:`rcl_yaml.parse_params_text`).

    Raises:
        ParamsError: the file cannot be read, is not a regular file, is larger than
            :data:`MAX_PARAMS_BYTES`, is not UTF-8, or rcl would refuse it (one line naming
            the file, line and key, never the file's content).
    """
    path = Path(path)
    kind = not_regular(path)
    if kind is not None:                # checked before opening: a FIFO blocks the open
        raise ParamsError(f'{path}: cannot read params file (not a regular file: {kind})')
    try:
        with path.open('rb') as handle:
            if not stat.S_ISREG(os.fstat(handle.fileno()).st_mode):
                raise ParamsError(f'{path}: not a regular file (expected a params file)')
            data = handle.read(MAX_PARAMS_BYTES + 1)
    except OSError as err:
        raise ParamsError(f'{path}: cannot read params file ({err.strerror})') from err
    if len(data) > MAX_PARAMS_BYTES:
        raise ParamsError(f'{path}: larger than {MAX_PARAMS_BYTES} bytes (not a params file)')
    try:
        text = data.decode('utf-8')
    except UnicodeDecodeError as err:
        raise ParamsError(f'{path}: not UTF-8 text (expected a params file)') from err
    return parse_params_text(text, str(path))


def read_layers(paths: Iterable[str | Path]) -> list[ParsedParams]:
    """:func:`read_layer` for each file, in order."""
    return [read_layer(path) for path in paths]


def to_params_text(sections: Mapping[str, Mapping[str, Any]]) -> str:
    """A params file that rcl reads back with exactly these values and types.

    Strings are always quoted (rcl would read an unquoted ``1e3``, ``inf``, ``yes`` or
    ``08`` as a number or a boolean), floats are written so that ``strtod`` and not
    ``strtoll`` reads them, booleans as ``true``/``false``.

    Args:
        sections: section name (``/**``, ``/planner``, ...) to ``{parameter: value}``;
            values are bool, int, float, str or non-empty lists of one of those.
    """
    lines: list[str] = []
    for section, values in sections.items():
        lines.append(f'{_quoted(section)}:')
        lines.append('  ros__parameters:')
        if not values:
            lines[-1] += ' {}'
        for name, value in values.items():
            lines.append(f'    {_quoted(name)}: {_scalar_text(value)}')
    return '\n'.join(lines) + '\n'


def _quoted(text: str) -> str:
    return "'" + text.replace("'", "''") + "'"


def _scalar_text(value: Any) -> str:
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if value != 0.0 and abs(value) < _DBL_MIN:
            raise ParamsError(f'cannot pass {value!r} in a params file: rcl reads a subnormal '
                              'double as a string')
        text = repr(value)
        return text if any(c in text for c in '.en') else text + '.0'
    if isinstance(value, str):
        return _quoted(value)
    if isinstance(value, (list, tuple)) and value:
        return '[' + ', '.join(_scalar_text(item) for item in value) + ']'
    raise ParamsError(f'cannot write {value!r} as a ROS parameter value')


def text_layer(sections: Mapping[str, Mapping[str, Any]], where: str) -> ParsedParams:
    """Values given on a command line as one more layer, read back through rcl's rules."""
    return parse_params_text(to_params_text(sections), where)


def node_fqn(namespace: str, name: str) -> str:
    """A node's fully qualified name: ``node_fqn('/', 'planner') == '/planner'``."""
    namespace = namespace if namespace.startswith('/') else '/' + namespace
    return namespace.rstrip('/') + '/' + name


def section_target(section: str) -> str | None:
    """The node name a section is written for (its last token), or None for a wildcard
    (``/**``, ``/*``, ``/car1/*``)."""
    last = section.rstrip('/').rsplit('/', 1)[-1]
    return None if last in WILDCARD_TOKENS else last


def _same(a: Any, b: Any) -> bool:
    return type(a) is type(b) and repr(a) == repr(b)


class Layered(dict):  # type: ignore[type-arg]
    """A node's parameters (name to value) with the file each came from (:attr:`sources`)."""

    def __init__(self, values: Mapping[str, Any], sources: Mapping[str, str]) -> None:
        super().__init__(values)
        self.sources = dict(sources)


def layered_params(layers: Sequence[ParsedParams], fqn: str) -> Layered:
    """The parameters node ``fqn`` gets from ``--params-file`` once per layer, in order.

    Exactly rcl's and rclpy's result (:func:`rcl_yaml.params_for_node`), refused where that
    result is not the value the last file writing a parameter gave it.

    Args:
        layers: the files (:func:`read_layer`, :func:`text_layer`), bottom first.
        fqn: the node's fully qualified name, e.g. ``/planner`` or ``/car1/planner``.

    Returns:
        Parameter name to value; ``sources`` names the file each value came from.

    Raises:
        ParamsError: a parameter without a value, or a value of a later file that would not
            reach the node (one line naming the file, the parameter and what the node would
            get instead).
    """
    written: dict[str, tuple[Any, str]] = {}
    for layer in layers:
        try:
            values = params_for_node([layer], fqn)
        except ParamsError as err:
            raise ParamsError(f'{layer.where}: {err}') from err
        for name, value in values.items():
            written[name] = (value, layer.where)
    merged = params_for_node(layers, fqn)
    for name, (value, where) in written.items():
        got = merged[name]
        if _same(got, value):
            continue
        if type(got) is not type(value):
            kind = _KINDS.get(type(got), type(got).__name__)
            why = (f'rcl keeps the {kind} written for it in an earlier file; write '
                   f'{_ARTICLES.get(kind, "a")} {kind} here')
        else:
            why = ('a section of an earlier file that applies to this node is applied after '
                   'this one (rcl applies sections in the order they first appear); write it '
                   'in a section that first appears in this file, e.g. '
                   f'/**/{fqn.rsplit("/", 1)[-1]}')
        raise ParamsError(f'{where}: parameter {name} = {value!r} would not reach {fqn}, which '
                          f'would get {got!r}: {why}')
    return Layered(merged, {name: where for name, (_, where) in written.items()})
