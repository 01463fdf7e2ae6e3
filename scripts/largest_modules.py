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


def sizes(src: Path = SRC) -> list[Size]:
    """Every module of the tree's packages, largest first."""
    found = []
    for name, path in module_files(src).items():
        text = path.read_text(encoding='utf-8')
        functions = [(node.end_lineno - node.lineno + 1, node.name)
                     for node in ast.walk(ast.parse(text, str(path)))
                     if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
                     and node.end_lineno is not None]
        longest_lines, longest = max(functions, default=(0, ''))
        found.append(Size(name, path, len(text.splitlines()), longest, longest_lines))
    return sorted(found, key=lambda s: (-s.lines, s.name))


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
