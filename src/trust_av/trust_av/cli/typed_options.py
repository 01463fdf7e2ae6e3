"""Typed options of the ``trust-av`` commands, each declared once: a command's frozen options
dataclass is the declaration its parser is built from (:func:`add_options`), and the command
reads a value of it built from argparse's namespace (:func:`options_from`), so the type
checker sees every option a command uses and a command reads nothing else.

A field is an option by its declaration, :func:`option` (``--flag``) or :func:`positional`,
which holds argparse's keywords; :func:`add_options` adds the fields in field order (a base
class's fields first), each with its ``dest`` the field's name. An option that a command's
help lists after its own (``--params-file``) is a field the command declares last with the
shared declaration (:func:`trust_av.cli.options.params_files_option`). A field declared
without either is refused (:class:`TypeError`), and :func:`check_parser` refuses a parser
with an option that is no field (an ``add_argument`` outside the builder). The namespace
entries that are no option of a command are argparse's ``help``, ``trust-av``'s own
(``command``, ``verbose``: a command that reads one declares it with
:func:`trust_avs_option`), the command's ``func`` (:func:`command`) and the extra defaults
an option declares (``params_file``, the last of ``--params-file``). A mutually exclusive
group is the fields that name the same :class:`Exclusive`.

The values' ranges and formats are checked by the parser's ``type=`` functions
(:mod:`trust_av.cli.options`), one line and exit 2 for bad input; what
:func:`options_from` checks is that the parser gave every field a value of the declared type
(a mismatch is a defect of the parser, not of the input, and raises :class:`TypeError`).
"""

from __future__ import annotations

import argparse
import dataclasses
import types
import typing
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

__all__ = ['Command', 'Exclusive', 'add_command', 'add_options', 'check_parser', 'command',
           'option', 'options_from', 'positional', 'trust_avs_option']

Options = TypeVar('Options')

DECLARATION = 'trust_av.cli.option'
"""The key of a field's metadata that holds its :class:`Declaration`."""


@dataclasses.dataclass(frozen=True)
class Exclusive:
    """An argparse mutually exclusive group: the fields that name the same one are added to
    it, the group where the first of them is."""

    name: str
    required: bool = False


@dataclasses.dataclass(frozen=True)
class Declaration:
    """A field's command-line option: its flags (none for a positional), argparse's keywords
    (``help`` and ``choices`` may be zero-argument callables, called when the parser is built:
    registries are read then), its exclusive group, and other namespace entries it sets
    (``parser.set_defaults``)."""

    flags: tuple[str, ...]
    keywords: dict[str, Any]
    exclusive: Exclusive | None = None
    also_sets: dict[str, object] = dataclasses.field(default_factory=dict)
    trust_avs: bool = False


def option(*flags: str, exclusive: Exclusive | None = None,
           also_sets: dict[str, object] | None = None, **keywords: Any) -> Any:
    """A field that is the option ``flags`` (``--out``) with argparse's ``keywords``; its
    ``dest`` is the field's name (or the field is one of the namespace entries it
    ``also_sets``: an action that sets several, as ``--params-file``). ``type=`` may be left
    out for a field of type ``Path``, ``int`` or ``float`` (or ``X | None``: ``type=X``),
    ``action=`` for a ``bool`` field (``store_true``). ``default=`` is argparse's: the
    dataclass field has no default."""
    if not flags or not all(flag.startswith('-') for flag in flags):
        raise TypeError(f'option{flags!r}: an option needs flags starting with -')
    return dataclasses.field(metadata={DECLARATION: Declaration(
        flags, keywords, exclusive, dict(also_sets or {}))})


def trust_avs_option() -> Any:
    """A field that is ``trust-av``'s own option of its name (``verbose``: ``-v``, before
    the command), not one of the command's: its parser adds nothing for it."""
    return dataclasses.field(metadata={DECLARATION: Declaration((), {}, trust_avs=True)})


def positional(**keywords: Any) -> Any:
    """A field that is a positional argument named by the field, with argparse's
    ``keywords`` (``type=`` implied as for :func:`option`)."""
    return dataclasses.field(metadata={DECLARATION: Declaration((), keywords)})


_IMPLIED_TYPES = (Path, int, float)
"""The annotations whose class is argparse's ``type=`` when a declaration gives none."""


def _implied(hint: Any) -> dict[str, Any]:
    """argparse keywords a field's type implies: ``type=`` for ``Path``, ``int`` and
    ``float`` (``X | None`` too), ``action='store_true'`` for ``bool``."""
    arms = [hint]
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        arms = [arm for arm in typing.get_args(hint) if arm is not type(None)]
    if len(arms) == 1 and arms[0] is bool:
        return {'action': 'store_true'}
    if len(arms) == 1 and arms[0] in _IMPLIED_TYPES:
        return {'type': arms[0]}
    return {}


def add_options(parser: argparse.ArgumentParser, kind: type) -> None:
    """Add the options dataclass ``kind``'s fields to ``parser``, in field order.

    Raises:
        TypeError: a field has no declaration (:func:`option`, :func:`positional`), or an
            option's flags give argparse another ``dest`` than the field's name.
    """
    hints = typing.get_type_hints(kind)
    groups: dict[str, argparse._MutuallyExclusiveGroup] = {}
    for field in dataclasses.fields(kind):
        declared = field.metadata.get(DECLARATION)
        if not isinstance(declared, Declaration):
            raise TypeError(f'{kind.__name__}.{field.name}: no option declared; declare it '
                            'with option(...) or positional(...)')
        if declared.trust_avs:
            continue
        keywords = {key: value() if key in ('help', 'choices') and callable(value) else value
                    for key, value in declared.keywords.items()}
        if 'type' not in keywords and 'action' not in keywords:
            keywords.update(_implied(hints[field.name]))
        target: argparse._ActionsContainer = parser
        if declared.exclusive is not None:
            name = declared.exclusive.name
            if name not in groups:
                groups[name] = parser.add_mutually_exclusive_group(
                    required=declared.exclusive.required)
            target = groups[name]
        if declared.flags:
            action = target.add_argument(*declared.flags, **keywords)
            if action.dest != field.name and field.name not in declared.also_sets:
                raise TypeError(f'{kind.__name__}.{field.name}: {declared.flags[0]} sets '
                                f'{action.dest!r}, not the field')
        else:
            target.add_argument(field.name, **keywords)
        if declared.also_sets:
            parser.set_defaults(**declared.also_sets)


def _declared(field: dataclasses.Field[Any]) -> Declaration:
    declared = field.metadata.get(DECLARATION)
    return declared if isinstance(declared, Declaration) else Declaration((), {})


def check_parser(parser: argparse.ArgumentParser) -> None:
    """Refuse a command's parser with an option that is no field of its options (an
    ``add_argument`` outside :func:`add_options`).

    Raises:
        TypeError: it has one, or its ``func`` is not a :class:`Command`.
    """
    func = parser.get_default('func')
    if not isinstance(func, Command):
        raise TypeError(f'{parser.prog}: its func is not a typed command')
    fields = {name for field in dataclasses.fields(func.options)
              for name in (field.name, *_declared(field).also_sets)}
    for action in parser._actions:
        if not isinstance(action, argparse._HelpAction) and action.dest not in fields:
            raise TypeError(f'{parser.prog}: {"/".join(action.option_strings) or action.dest} '
                            f'is no field of {func.options.__name__}')


def _matches(value: object, hint: Any) -> bool:
    """True when ``value`` is of the type ``hint`` (classes, ``X | None``, ``Literal``,
    ``tuple[X, ...]``; an int is a float, a bool is not a number)."""
    origin = typing.get_origin(hint)
    if origin in (typing.Union, types.UnionType):
        return any(_matches(value, arm) for arm in typing.get_args(hint))
    if origin is typing.Literal:
        return value in typing.get_args(hint)
    if origin is tuple:
        element = typing.get_args(hint)[0]
        return isinstance(value, tuple) and all(_matches(v, element) for v in value)
    if hint is type(None):
        return value is None
    if hint in (int, float) and isinstance(value, bool):
        return False
    if hint is float:
        return isinstance(value, (int, float))
    return isinstance(value, hint)


def options_from(kind: type[Options], namespace: argparse.Namespace) -> Options:
    """The options dataclass ``kind`` with each field's value from ``namespace`` (a list
    becomes a tuple, an int a float where the field says so).

    Raises:
        TypeError: the parser gave no value, or one of another type, for a field (a
            defect of the command's parser).
    """
    hints = typing.get_type_hints(kind)
    values: dict[str, object] = {}
    for field in dataclasses.fields(kind):  # type: ignore[arg-type]
        if not hasattr(namespace, field.name):
            raise TypeError(f'{kind.__name__}.{field.name}: the parser sets no such option')
        value = getattr(namespace, field.name)
        if isinstance(value, list):
            value = tuple(value)
        hint = hints[field.name]
        if hint is float and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if not _matches(value, hint):
            raise TypeError(f'{kind.__name__}.{field.name}: {value!r} is not {hint}')
        values[field.name] = value
    return kind(**values)


class Command:
    """A subcommand's ``func``: builds its options dataclass ``options`` from the parsed
    namespace (:func:`options_from`), then runs."""

    def __init__(self, options: type[Any], run: Callable[[Any], int]) -> None:
        self.options = options
        self.run = run
        self.__doc__ = run.__doc__

    def __call__(self, namespace: argparse.Namespace) -> int:
        return self.run(options_from(self.options, namespace))


def command(kind: type[Options], run: Callable[[Options], int]) -> Command:
    """A subcommand's ``func``: builds ``kind`` from the parsed namespace, then runs."""
    return Command(kind, run)


def add_command(parser: argparse.ArgumentParser, kind: type[Options],
                run: Callable[[Options], int]) -> None:
    """Add ``kind``'s options to a command's ``parser`` (:func:`add_options`) and make
    ``run`` its ``func``."""
    add_options(parser, kind)
    parser.set_defaults(func=command(kind, run))

