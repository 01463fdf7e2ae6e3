"""The reference tables of the documentation, generated from the code at build time.

The site (``mkdocs.yml``, hook ``docs/hooks.py``) replaces a marker line
``<!-- generated: NAME -->`` in a page with :func:`generated` ``(NAME)``, so no table is
copied by hand into a page:

- ``cli``: every ``trust-av`` subcommand and ``trust-monitor-estimate``, from their
  argparse parsers;
- ``parameters``: every parameter of the shipped params file, with the description, unit
  and range of its configuration dataclass field (:func:`trust_av_common.params.param`);
- ``topics``: the topic table of :mod:`trust_av_common.topics`;
- ``vehicle_interface``: the part of it a vehicle connects to (the planner's inputs from
  outside, the planner's and the trust monitor's outputs).
"""

from __future__ import annotations

import argparse
import dataclasses
import re
from collections.abc import Callable

from trust_av.cli.main import build_parser
from trust_av.system.config import DEFAULT_PARAMS_FILE, NODE_COMPONENTS, node_components
from trust_av_common.errors import TrustAvError
from trust_av_common.params import PARAM_METADATA_KEY, ParamSpec, read_params_file
from trust_av_common.topics import TOPICS, WALL_QOS_TEXT, topic_table_markdown
from trust_monitor.estimate import build_parser as estimate_parser

__all__ = ['UnknownTableError', 'fill', 'parameters_markdown']

MARKER = re.compile(r'^<!-- generated: ([a-z_]+) -->$(?:\n> Generated table:[^\n]*$)?',
                    re.MULTILINE)
"""A line a page holds where a generated table goes, and the line after it that tells a
reader of the Markdown source (on GitHub, say) where to find the table (``> Generated
table: ...``); both are replaced by the table."""


REPO = DEFAULT_PARAMS_FILE.resolve().parents[1]
"""The repository (or install prefix) the shipped params file is in."""


class UnknownTableError(TrustAvError, KeyError):
    """A page names a generated table that does not exist."""


def cell(text: object) -> str:
    """``text`` fit for a Markdown table cell (pipes escaped, no line breaks, no raw HTML)."""
    return (str(text).replace('|', r'\|').replace('<', '&lt;').replace('>', '&gt;')
            .replace('\n', ' '))


def _option_rows(parser: argparse.ArgumentParser) -> list[str]:
    """One table row per option and positional of ``parser`` (not ``-h`` or subcommands)."""
    formatter = parser._get_formatter()      # argparse's own %(default)s expansion
    rows = []
    for action in parser._actions:
        if isinstance(action, (argparse._HelpAction, argparse._SubParsersAction)):
            continue
        if action.option_strings:
            metavar = '' if action.nargs == 0 else f' {action.metavar or action.dest.upper()}'
            name = ', '.join(f'`{o}{metavar}`' for o in action.option_strings)
        else:
            name = f'`{action.metavar or action.dest}` (positional)'
        if action.choices is not None and not isinstance(action.choices, dict):
            name += ' ∈ {' + ', '.join(f'`{c}`' for c in action.choices) + '}'
        helped = formatter._expand_help(action) if action.help else ''
        extras = []
        if action.required and action.option_strings:
            extras.append('required')
        if action.default not in (None, False, [], argparse.SUPPRESS) and \
                '(default' not in helped:
            extras.append(f'default `{shown(action.default)}`')
        text = helped + (f' ({"; ".join(extras)})' if extras else '')
        rows.append(f'| {cell(name)} | {cell(text)} |')
    return rows


def shown(value: object) -> str:
    """A default or shipped value as a user writes it: paths in the repository relative to
    it (``config/trust_av.yaml``), YAML's ``true``/``false``, ``''`` for the empty string."""
    if isinstance(value, list):
        return ', '.join(shown(v) for v in value)
    if isinstance(value, bool):
        return str(value).lower()
    if value == '':
        return "''"
    return str(value).replace(f'{REPO}/', '')


def _command_section(title: str, parser: argparse.ArgumentParser, level: int = 3) -> list[str]:
    """A heading of ``level`` for the command ``title``, its description and its options."""
    lines = [f'{"#" * level} `{title}`', '']
    if parser.description:
        lines += [parser.description, '']
    rows = _option_rows(parser)
    if rows:
        lines += ['| option | meaning |', '| --- | --- |', *rows, '']
    return lines


def cli_markdown() -> str:
    """The command-line reference: one section per command, one row per option."""
    top = build_parser()
    lines = ['## `trust-av`', '', top.description or '', '',
             'Every subcommand has `--help`; `-v`/`--verbose` goes before the subcommand.',
             '']
    subparsers = next(a for a in top._actions if isinstance(a, argparse._SubParsersAction))
    summaries = {a.dest: a.help for a in subparsers._choices_actions}
    lines += ['| command | what it does |', '| --- | --- |']
    lines += [f'| [`trust-av {name}`](#trust-av-{name}) | {cell(summaries.get(name) or "")} |'
              for name in subparsers.choices]
    lines.append('')
    for name, parser in subparsers.choices.items():
        lines += _command_section(f'trust-av {name}', parser)
    lines += _command_section('trust-monitor-estimate', estimate_parser(), level=2)
    return '\n'.join(lines)


def field_specs() -> dict[str, tuple[ParamSpec, tuple[str, ...]]]:
    """Parameter name -> its field's :class:`ParamSpec` and the nodes that read it."""
    specs: dict[str, tuple[ParamSpec, tuple[str, ...]]] = {}
    for node in NODE_COMPONENTS:
        for cls in node_components(node):
            for field in dataclasses.fields(cls):
                spec = field.metadata.get(PARAM_METADATA_KEY)
                if isinstance(spec, ParamSpec):
                    old = specs.get(field.name, (spec, ()))
                    specs[field.name] = (old[0], (*old[1], node))
    return specs


def value_range(spec: ParamSpec) -> str:
    """The allowed values of a parameter, e.g. ``[0.01, 10]``, ``> 0`` or ``ca, gru``."""
    if spec.choices:
        return ', '.join(f'`{c}`' for c in spec.choices)
    if spec.low is not None and spec.high is not None:
        return (f'{"[" if spec.low_inclusive else "("}{spec.low:g}, {spec.high:g}'
                f'{"]" if spec.high_inclusive else ")"}')
    if spec.low is not None:
        return f'{">=" if spec.low_inclusive else ">"} {spec.low:g}'
    if spec.high is not None:
        return f'{"<=" if spec.high_inclusive else "<"} {spec.high:g}'
    return ''


def parameters_markdown() -> str:
    """One table per section of the shipped params file: value, unit, range, meaning.

    Raises:
        KeyError: a parameter of the shipped file has no documented field.
    """
    specs = field_specs()
    lines: list[str] = []
    for section, values in read_params_file(DEFAULT_PARAMS_FILE).items():
        if not values:
            continue
        lines += [f'### `{section}`', '',
                  '| parameter | shipped value | unit | allowed | read by | meaning |',
                  '| --- | --- | --- | --- | --- | --- |']
        for name, value in values.items():
            spec, nodes = specs[name]
            writable = '' if spec.read_only else ' (changeable at run time in wall mode)'
            lines.append(f'| `{name}` | `{cell(shown(value))}` | {cell(spec.unit)} | '
                         f'{cell(value_range(spec))} | {", ".join(nodes)} | '
                         f'{cell(spec.description)}{writable} |')
        lines.append('')
    return '\n'.join(lines)


def topics_markdown() -> str:
    """The topic table of :mod:`trust_av_common.topics`."""
    return topic_table_markdown()


VEHICLE_SIDE = ('planner', 'trust_monitor')
"""The nodes a vehicle runs (everything else of the graph is simulation)."""


def vehicle_interface_markdown() -> str:
    """The topics a vehicle connects to: what the planner takes from outside the two
    vehicle-side nodes, and what those two publish, with their wall-mode QoS."""
    lines = ['| direction | topic (default name) | type | fields, units | frames | '
             'QoS (wall mode) |', '| --- | --- | --- | --- | --- | --- |']
    for t in TOPICS:
        outside = not set(t.publishers) & set(VEHICLE_SIDE)
        if outside and 'planner' not in t.subscribers:
            continue
        direction = 'in' if outside else f'out ({", ".join(t.publishers)})'
        lines.append(f'| {direction} | `/{t.name}` | `{t.msgtype}` | {cell(t.units)} | '
                     f'{cell(t.frames)} | {cell(WALL_QOS_TEXT[t.wall_qos])} |')
    return '\n'.join(lines) + '\n'


GENERATORS: dict[str, Callable[[], str]] = {
    'cli': cli_markdown, 'parameters': parameters_markdown, 'topics': topics_markdown,
    'vehicle_interface': vehicle_interface_markdown}
"""The generated tables by marker name."""


def generated(name: str) -> str:
    """The generated Markdown for the marker ``<!-- generated: name -->``.

    Raises:
        UnknownTableError: no table of that name.
    """
    try:
        return GENERATORS[name]()
    except KeyError as err:
        if name not in GENERATORS:
            raise UnknownTableError(f'no generated table {name!r} '
                                    f'(known: {", ".join(GENERATORS)})') from err
        raise


def fill(markdown: str) -> str:
    """``markdown`` with every marker line replaced by its generated table.

    Args:
        markdown: a page's text.

    Raises:
        UnknownTableError: a marker names no generated table.
    """
    return MARKER.sub(lambda match: generated(match.group(1)), markdown)
