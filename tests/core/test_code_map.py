"""The code map (docs/reference/code-map.md) is the tree's: scripts/code_map.py writes its
tables from the packages' folders and module docstrings, and this fails when they differ."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from support.paths import REPO

ROOT = REPO


def test_the_code_map_is_generated_from_the_tree() -> None:
    done = subprocess.run([sys.executable, str(ROOT / 'scripts' / 'code_map.py'), '--check'],
                          capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr


def test_the_check_sees_a_module_the_page_does_not_name(tmp_path: Path) -> None:
    """Not vacuous: a new module makes the check fail until the page is written again."""
    spec = [sys.executable, '-c',
            'import sys; sys.path.insert(0, sys.argv[1]); import code_map; '
            'from pathlib import Path; src = Path(sys.argv[2]); '
            'print(int(code_map.page_with(code_map.render(src), code_map.PAGE.read_text()) '
            '== code_map.PAGE.read_text()))', str(ROOT / 'scripts'), str(tmp_path / 'src')]
    subprocess.run(['cp', '-r', str(ROOT / 'src'), str(tmp_path / 'src')], check=True)
    assert subprocess.run(spec, capture_output=True, text=True, check=True).stdout == '1\n'
    planted = tmp_path / 'src' / 'preceding_traffic' / 'preceding_traffic' / 'planted.py'
    planted.write_text('"""A module the code map does not name yet."""\n')
    assert subprocess.run(spec, capture_output=True, text=True, check=True).stdout == '0\n'
