"""scripts/typing_report.py: the lines strict typing checks and excludes, from the exclusion
scripts/test.sh gives mypy (or one given)."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest
from support.paths import REPO

SCRIPT = REPO / 'scripts' / 'typing_report.py'
_spec = importlib.util.spec_from_file_location('typing_report', SCRIPT)
assert _spec is not None and _spec.loader is not None
typing_report = importlib.util.module_from_spec(_spec)
sys.modules['typing_report'] = typing_report
_spec.loader.exec_module(typing_report)


def test_an_exclusion_moves_lines_from_checked_to_excluded() -> None:
    checked, excluded = typing_report.line_counts(typing_report.NOTHING)
    assert not excluded and len(checked) > 100
    total = sum(checked.values())
    checked_ros, excluded_ros = typing_report.line_counts('/ros/')
    assert set(excluded_ros) == {n for n in checked if '/ros/' in n} != set()
    assert sum(checked_ros.values()) + sum(excluded_ros.values()) == total
    spin = 'src/trust_av_common/trust_av_common/ros/spin.py'
    assert excluded_ros[spin] == len((REPO / spin).read_text().splitlines())


def test_the_report_reads_the_test_script(tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    script = tmp_path / 'test.sh'
    script.write_text("mypy --exclude '(_node)\\.py$' \\\n  src\n")
    assert typing_report.exclusion_of_test_script(script) == r'(_node)\.py$'
    script.write_text('mypy \\\n  src\n')
    assert typing_report.exclusion_of_test_script(script) == typing_report.NOTHING
    script.write_text('ruff check src\n')
    with pytest.raises(SystemExit, match='runs no mypy'):
        typing_report.exclusion_of_test_script(script)
    assert typing_report.main(['--exclude', '_node\\.py$']) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[-2].startswith('excluded: ') and lines[-1].startswith('checked:  ')
    assert any(line.endswith('planner_node.py') for line in lines[:-2])
