"""Typed options of the ``trust-av`` commands: each command declares a frozen dataclass of the
options it reads, built once from argparse's namespace where the command line enters
(:func:`options_from`), so the type checker sees every option a command uses and a command
reads nothing else.

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

__all__ = ['ParamsFileOptions', 'RunOptions', 'command', 'options_from']

Options = TypeVar('Options')


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


def command(kind: type[Options],
            run: Callable[[Options], int]) -> Callable[[argparse.Namespace], int]:
    """A subcommand's ``func``: builds ``kind`` from the parsed namespace, then runs."""
    def from_namespace(namespace: argparse.Namespace) -> int:
        return run(options_from(kind, namespace))
    from_namespace.__doc__ = run.__doc__
    return from_namespace


@dataclasses.dataclass(frozen=True)
class ParamsFileOptions:
    """``--params-file``, repeatable
    (:func:`~trust_av.cli.options.add_params_file_option`): every file in order,
    later over earlier."""

    params_files: tuple[Path, ...]


@dataclasses.dataclass(frozen=True)
class RunOptions(ParamsFileOptions):
    """The options of the commands that run one closed loop
    (:func:`~trust_av.cli.options.add_run_options`): each one None where the params
    file's value holds."""

    trace: str | None
    bag_in: Path | None
    bag_topic: str | None
    bag_type: str | None
    alpha: float | None
    predictor: str | None
    driver_model: str | None
    lead_preview: str | None
    no_progress: bool

    def overrides(self) -> dict[str, dict[str, object]]:
        """Params-file overrides from the options given."""
        planner: dict[str, object] = {}
        if self.lead_preview is not None:
            planner['lead_preview'] = self.lead_preview
        if self.alpha is not None:
            planner['alpha'] = self.alpha
        if self.predictor is not None:
            planner['predictor'] = self.predictor
        traffic: dict[str, object] = {}
        if self.trace is not None:
            traffic['trace'] = self.trace
        if self.bag_in is not None:
            traffic['trace'] = str(self.bag_in)
        if self.bag_topic is not None:
            traffic['bag_topic'] = self.bag_topic
        if self.bag_type is not None:
            traffic['bag_message_type'] = self.bag_type
        driver: dict[str, object] = {}
        if self.driver_model is not None:
            driver['driver_model'] = self.driver_model
        return {'planner': planner, 'preceding_traffic': traffic, 'human_driver': driver}
