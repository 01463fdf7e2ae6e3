"""The ``trust-av`` argument parser: a refused command line gets a one-line usage and one
line naming the bad thing, with a "did you mean" from the parser's own choices and options
(exit 2), instead of argparse's page of usage text."""

from __future__ import annotations

import argparse
import re
from collections.abc import Sequence
from typing import NoReturn

from trust_av_common.errors import did_you_mean

__all__ = ['Parser', 'suggest']

_INVALID_CHOICE = re.compile(r"invalid choice: (?P<value>'[^']*'|\"[^\"]*\") "
                             r'\(choose from (?P<choices>.*)\)$')


def _quoted(text: str) -> list[str]:
    """The quoted items of argparse's ``'a', 'b'`` choice list."""
    return [a or b for a, b in re.findall(r"'([^']*)'|\"([^\"]*)\"", text)]


def suggest(message: str, options: Sequence[str] = ()) -> str:
    """argparse's error ``message`` with a "did you mean" for an invalid choice or an
    unrecognized option (from ``options``, the parser's option strings)."""
    choice = _INVALID_CHOICE.search(message)
    if choice is not None:
        value = _quoted(choice['value'])[0]
        return f'{message}{did_you_mean(value, _quoted(choice["choices"]))}'
    if message.startswith('unrecognized arguments: '):
        hints = [f'{token}{did_you_mean(token.split("=")[0], options)}'
                 for token in message.removeprefix('unrecognized arguments: ').split()]
        if any('did you mean' in hint for hint in hints):
            return 'unrecognized arguments: ' + ' '.join(hints)
    return message


class Parser(argparse.ArgumentParser):
    """An :class:`argparse.ArgumentParser` whose errors are two lines: a one-line usage
    (``--help`` shows the whole) and the error with a suggestion; exit 2."""

    def short_usage(self) -> str:
        """``usage: PROG [options] POSITIONALS`` on one line."""
        positionals = [a.metavar or a.dest for a in self._actions
                       if not a.option_strings and a.help != argparse.SUPPRESS]
        words = [self.prog, '[options]', *(str(p) for p in positionals)]
        return f'usage: {" ".join(words)}  ({self.prog} --help for all options)'

    def error(self, message: str) -> NoReturn:
        """Print the one-line usage and the error (with a suggestion); exit 2."""
        options = [o for o, a in self._option_string_actions.items()
                   if not isinstance(a, argparse._HelpAction)]
        text = suggest(message, options)
        self.exit(2, f'{self.short_usage()}\n{self.prog}: error: {text}\n')

    def parse_args(self, args: Sequence[str] | None = None,  # type: ignore[override]
                   namespace: argparse.Namespace | None = None) -> argparse.Namespace:
        """As argparse's, but an unrecognized option is reported by the subcommand's
        parser (its usage, its options to suggest from)."""
        parsed, extras = self.parse_known_args(args, namespace)
        if extras:
            self._owner(parsed).error(f'unrecognized arguments: {" ".join(extras)}')
        return parsed

    def _owner(self, parsed: argparse.Namespace) -> argparse.ArgumentParser:
        """The subcommand's parser that ``parsed`` went to (this parser when none)."""
        for action in self._actions:
            if isinstance(action, argparse._SubParsersAction):
                chosen = getattr(parsed, action.dest or '', None)
                if chosen in action.choices:
                    return action.choices[chosen]  # type: ignore[no-any-return]
        return self
