"""The largest modules of the packages, a report to look at (about 400 lines is a prompt to
look, not a cap: docs/contributing.md): each module of at least ``--lines`` lines, largest
first, with its longest function and the first sentence of its docstring, so that a module
that grew past its subject is seen and its piece put beside what it belongs to.

Usage: python scripts/largest_modules.py [--lines N]   (default 400; always exits 0)
"""

from __future__ import annotations

import argparse
import ast
import sys
from pathlib import Path
from typing import NamedTuple

from code_map import SRC, module_files, summary

LOOK_AT_LINES = 400
"""A module this long is a prompt to look (docs/contributing.md)."""


class Size(NamedTuple):
    """One module's size: its lines and its longest function (name and lines)."""

    name: str
    path: Path
    lines: int
    longest: str
    longest_lines: int


def functions(text: str, path: Path) -> list[tuple[int, ast.FunctionDef | ast.AsyncFunctionDef]]:
    """Every function of a module's source, with its lines (docstring included)."""
    return [(node.end_lineno - node.lineno + 1, node)
            for node in ast.walk(ast.parse(text, str(path)))
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
            and node.end_lineno is not None]


def sizes(src: Path = SRC) -> list[Size]:
    """Every module of the tree's packages, largest first."""
    found = []
    for name, path in module_files(src).items():
        text = path.read_text(encoding='utf-8')
        longest_lines, longest = max(((length, node.name) for length, node
                                      in functions(text, path)), default=(0, ''))
        found.append(Size(name, path, len(text.splitlines()), longest, longest_lines))
    return sorted(found, key=lambda s: (-s.lines, s.name))


FUNCTION_LINES = 100
"""A function longer than this needs a reason written beside it: a comment line
``# over 100 lines: <why>`` right above its ``def`` (or its first decorator)."""
REASON = '# over 100 lines:'


def long_functions(src: Path = SRC, limit: int = FUNCTION_LINES) -> list[str]:
    """Every function of the tree's packages over ``limit`` lines (docstring included) with
    no reason written above it, as ``path:line name() N lines``."""
    found = []
    for path in module_files(src).values():
        text = path.read_text(encoding='utf-8')
        lines = text.splitlines()
        for length, node in functions(text, path):
            first = min([node.lineno, *(d.lineno for d in node.decorator_list)])
            above = lines[first - 2].strip() if first >= 2 else ''
            if length > limit and not above.startswith(REASON):
                found.append(f'{path.relative_to(src).as_posix()}:{node.lineno} '
                             f'{node.name}() {length} lines')
    return sorted(found)


def report(src: Path = SRC, at_least: int = LOOK_AT_LINES) -> str:
    """The report: one line per module of at least ``at_least`` lines."""
    big = [s for s in sizes(src) if s.lines >= at_least]
    lines = [f'{len(big)} modules of {at_least} lines or more (a prompt to look, not a cap):']
    for s in big:
        where = s.path.relative_to(src / s.name.split('.')[0]).as_posix()
        function = f'{s.longest}() {s.longest_lines}' if s.longest else '-'
        lines.append(f'{s.lines:5d}  {where}  [longest: {function}]  {summary(s.path)}')
    return '\n'.join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--lines', type=int, default=LOOK_AT_LINES,
                        help='list modules of at least this many lines (default: %(default)s)')
    args = parser.parse_args(argv)
    print(report(at_least=args.lines))
    return 0


if __name__ == '__main__':
    sys.exit(main())
