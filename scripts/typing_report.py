"""How much of the source the strict type check (mypy, scripts/test.sh) sees: the lines of
the modules it checks and of those it excludes, per excluded module.

    python scripts/typing_report.py [--exclude REGEX]

The exclusion is read from scripts/test.sh (its ``mypy --exclude '...'``, none if it has
none) unless given.
Lines are physical lines of the .py files under the four packages' import roots.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
NOTHING = r'(?!)'
"""A pattern that matches no path: no exclusion."""
PACKAGES = tuple(f'src/{p.name}/{p.name}' for p in sorted((ROOT / 'src').iterdir())
                 if (p / p.name / '__init__.py').is_file())
"""Every package's module folder (src/NAME/NAME), as scripts/test.sh gives them to mypy."""


def exclusion_of_test_script(path: Path = ROOT / 'scripts' / 'test.sh') -> str:
    """The regular expression scripts/test.sh gives mypy's ``--exclude`` (:data:`NOTHING`
    when it gives none).

    Raises:
        SystemExit: the script runs no mypy.
    """
    text = path.read_text(encoding='utf-8')
    if re.search(r'^mypy\b', text, re.MULTILINE) is None:
        raise SystemExit(f'{path}: runs no mypy')
    found = re.search(r"^mypy --exclude '([^']*)'", text, re.MULTILINE)
    return NOTHING if found is None else found[1]


def line_counts(exclude: str) -> tuple[dict[str, int], dict[str, int]]:
    """(checked, excluded): lines per module path (relative to the repository)."""
    pattern = re.compile(exclude)
    checked: dict[str, int] = {}
    excluded: dict[str, int] = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob('*.py')):
            name = path.relative_to(ROOT).as_posix()
            lines = len(path.read_text(encoding='utf-8').splitlines())
            # mypy matches --exclude against the path as given on its command line
            (excluded if pattern.search(name) else checked)[name] = lines
    return checked, excluded


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--exclude', default=None,
                        help="mypy's --exclude pattern (default: the one in scripts/test.sh)")
    args = parser.parse_args(argv)
    exclude = args.exclude if args.exclude is not None else exclusion_of_test_script()
    checked, excluded = line_counts(exclude)
    for name, lines in sorted(excluded.items()):
        print(f'{lines:6d}  {name}')
    total_checked, total_excluded = sum(checked.values()), sum(excluded.values())
    share = total_excluded / max(1, total_checked + total_excluded)
    print(f'excluded: {total_excluded} lines in {len(excluded)} modules ({share:.1%})')
    print(f'checked:  {total_checked} lines in {len(checked)} modules')
    return 0


if __name__ == '__main__':
    sys.exit(main())
