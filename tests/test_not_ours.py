"""Nothing that is not ours is deleted, rewritten or written through: a participant folder
without the study's marker is never withdrawn, ``repair-bag`` never rewrites a complete
recording nor drops what a file it repairs holds, and no single-file output follows a
symbolic link. Each rule is tried with a foreign folder, a symbolic link and a complete
foreign bag."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from trust_av_planner.cli.main import main

REPO = Path(__file__).resolve().parents[1]
BAG = REPO / 'bags' / 'commute_am'


def _tree(path: Path) -> dict[str, bytes | str]:
    """Every entry under ``path`` (links by their target, files by their bytes)."""
    out: dict[str, bytes | str] = {}
    for entry in sorted(path.rglob('*')):
        key = str(entry.relative_to(path))
        out[key] = (f'-> {os.readlink(entry)}' if entry.is_symlink()
                    else entry.read_bytes() if entry.is_file() else 'dir')
    return out


# --- single-file outputs ---------------------------------------------------------------

def _estimate(args: list[str]) -> int:
    from trust_monitor.estimate import main as estimate_main
    return estimate_main(args)


def _layout_plots(args: list[str]) -> int:
    from trust_av_planner.study.layout_plots import main as layout_main
    return layout_main(args)


OUTPUT_OPTIONS = {
    'simulate --out': (main, ['simulate', '--trace', 'us06', '--no-progress', '--out']),
    'eval-driver --json': (main, ['eval-driver', '--data', '{tmp}', '--json']),
    'shadow --json': (main, ['shadow', '--bag', str(BAG), '--out', '{tmp}/shadow', '--json']),
    'train-gru --out': (main, ['train-gru', '--out']),
    'fit-driver --out': (main, ['fit-driver', '--data', '{tmp}', '--out']),
    'trace-to-bag OUT': (main, ['trace-to-bag', 'us06']),
    'trust-monitor-estimate -o': (_estimate, ['{tmp}/plans.csv', '-o']),
    'layout_plots PNG': (_layout_plots, [str(BAG)]),
}
"""Every option that names one output (a file, or trace-to-bag's bag directory)."""


@pytest.mark.parametrize('target', ['a file', 'nothing', 'a directory'])
@pytest.mark.parametrize('option', list(OUTPUT_OPTIONS))
def test_no_output_is_written_through_a_link(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                             option: str, target: str) -> None:
    """A link planted where the output goes would redirect the write to what it names:
    refused in one line, exit 2, before any work, and nothing changed anywhere."""
    elsewhere = tmp_path / 'elsewhere'
    elsewhere.mkdir()
    victim = elsewhere / 'notes.txt'
    if target == 'a file':
        victim.write_text('not ours')
    elif target == 'a directory':
        victim.mkdir()
        (victim / 'kept').write_text('not ours')
    (tmp_path / 'plans.csv').write_text('t,a\n')
    link = tmp_path / 'out'
    link.symlink_to(victim)
    before = _tree(tmp_path)
    command, args = OUTPUT_OPTIONS[option]
    code = command([a.replace('{tmp}', str(tmp_path)) for a in args] + [str(link)])
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.count('\n') == 1 and 'symbolic link' in err and str(link) in err, err
    assert _tree(tmp_path) == before


def test_dev_stdout_is_still_an_output(tmp_path: Path) -> None:
    """``/dev/stdout`` is a link (to ``/proc/self/fd/1``): the system's names for open
    files are followed, also when stdout is a regular file."""
    out = tmp_path / 'report.json'
    with out.open('w') as handle:
        done = subprocess.run(
            [sys.executable, '-c', 'from pathlib import Path\n'
             'from trust_monitor.common.output_files import write_text\n'
             "write_text(Path('/dev/stdout'), '{}')"], stdout=handle, stderr=subprocess.PIPE,
            text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert out.read_text() == '{}'
