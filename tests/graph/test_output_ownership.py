"""Outputs are never someone else's: ``--overwrite`` replaces only what a trust-av command
proves it wrote (its own .trust_av_output marker, never a guess from file names), and the
previous outputs are replaced only once the new ones are complete (moved aside, put back on
any failure or stop)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from support.bags import record

from trust_av.cli.main import main
from trust_av.errors import TrustAvAppError
from trust_av.graph.bag_writer import BagWriter
from trust_av.system.outputs import (
    MARKER,
    RunOutputs,
    marked_outputs,
    prepare_outputs,
    replacing_outputs,
)


def snapshot(directory: Path) -> dict[str, bytes]:
    """Every file under ``directory`` (hidden ones too) and its bytes."""
    return {str(p.relative_to(directory)): p.read_bytes()
            for p in sorted(directory.rglob('*')) if p.is_file()}


def previous_run(bag: Path, plot: bytes = b'old plot') -> RunOutputs:
    """Outputs as an earlier ``trust-av run`` left them: a recorded bag, a plot, logs."""
    with replacing_outputs(bag, overwrite=False, command='run') as outputs:
        record(BagWriter(outputs.bag), 3)
        outputs.plot.write_bytes(plot)
        (outputs.logs / 'planner.log').write_text('old log\n')
    return outputs


@pytest.mark.parametrize('content', [
    {'metadata.yaml': 'rosbag2_bagfile_information: {}\n', 'thesis.tex': 'precious'},
    {'data.mcap': 'not ours', 'notes.txt': 'precious'},
    {},                                                          # an empty directory
])
def test_a_directory_that_looks_like_a_bag_is_refused(tmp_path: Path,
                                                      content: dict[str, str]) -> None:
    project = tmp_path / 'proj'
    project.mkdir()
    for name, text in content.items():
        (project / name).write_text(text)
    before = snapshot(tmp_path)
    with pytest.raises(TrustAvAppError, match=f'proj: not written by trust-av .no {MARKER}'):
        prepare_outputs(project, overwrite=True)
    assert main(['run', '--bag', str(project), '--overwrite', '--max-steps', '3',
                 '--no-progress']) == 2
    assert snapshot(tmp_path) == before and project.is_dir()


def test_a_bag_from_our_recorder_without_the_commands_marker_is_refused(tmp_path: Path) -> None:
    """Not a guess from the contents either: a bag the recorder wrote but no command marked
    (e.g. copied in by the user) is not replaced."""
    bag = tmp_path / 'run'
    record(BagWriter(bag), 2)
    with pytest.raises(TrustAvAppError, match='not written by trust-av'):
        prepare_outputs(bag, overwrite=True)


def test_the_sibling_logs_directory_with_notes_survives(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``--bag d/data --overwrite`` with no d/data deleted d/data.logs/ holding notes."""
    notes = tmp_path / 'd' / 'data.logs' / 'notes.txt'
    notes.parent.mkdir(parents=True)
    notes.write_text('my notes')
    assert main(['run', '--bag', str(tmp_path / 'd' / 'data'), '--overwrite',
                 '--max-steps', '3', '--no-progress']) == 2
    err = capsys.readouterr().err
    assert err == (f'trust-av run: error: {notes.parent}: not written by trust-av (no '
                   f'{MARKER} marker naming it); refusing to replace it, move it away or '
                   'choose another --bag\n')
    assert notes.read_text() == 'my notes'
    assert sorted(p.name for p in (tmp_path / 'd').iterdir()) == ['data.logs']


def test_a_marked_plot_is_ours_an_unnamed_one_is_not(tmp_path: Path) -> None:
    outputs = previous_run(tmp_path / 'run')
    assert marked_outputs(outputs.bag) == ['run', 'run.png', 'run.logs']
    assert prepare_outputs(outputs.bag, overwrite=True) == outputs
    other = tmp_path / 'other'
    (tmp_path / 'other.png').write_bytes(b'a user plot')
    with pytest.raises(TrustAvAppError, match=r'other\.png: not written by trust-av'):
        prepare_outputs(other, overwrite=True)


def test_replacing_puts_the_previous_outputs_back_on_a_failure_or_a_stop(
        tmp_path: Path) -> None:
    bag = tmp_path / 'run'
    previous_run(bag)
    before = snapshot(tmp_path)
    words = (r"^the graph failed; the previous outputs are back in place, this run's were "
             r'moved to \S*/run\.incomplete$')      # logs holding only the marker: removed
    with pytest.raises(TrustAvAppError, match=words), \
            replacing_outputs(bag, overwrite=True, command='run') as outputs:
        assert not outputs.bag.exists() and not outputs.plot.exists()
        assert [p.name for p in tmp_path.iterdir() if p.name.startswith('.')] != []
        record(BagWriter(outputs.bag), 1)
        raise TrustAvAppError('the graph failed')
    incomplete = RunOutputs.beside(tmp_path / 'run.incomplete')
    kept = {name: data for name, data in snapshot(tmp_path).items()
            if not name.startswith('run.incomplete')}
    assert kept == before                                      # byte for byte, markers too
    assert incomplete.bag.is_dir() and (incomplete.bag / MARKER).is_file()
    assert not incomplete.logs.exists()
    with pytest.raises(KeyboardInterrupt), \
            replacing_outputs(bag, overwrite=True, command='run'):
        raise KeyboardInterrupt
    kept = {name: data for name, data in snapshot(tmp_path).items()
            if not name.startswith('run.incomplete')}
    assert kept == before
    assert not (tmp_path / 'run.incomplete-2').exists()        # that one wrote nothing


def test_replacing_deletes_the_previous_outputs_only_after_success(tmp_path: Path) -> None:
    bag = tmp_path / 'run'
    previous_run(bag, plot=b'first')
    previous = prepare_outputs(bag, overwrite=True)
    with replacing_outputs(bag, overwrite=True, command='run') as outputs:
        record(BagWriter(outputs.bag), 5)
        outputs.plot.write_bytes(b'second')
    assert previous == outputs and outputs.plot.read_bytes() == b'second'
    assert sorted(p.name for p in tmp_path.iterdir()) == ['run', 'run.logs', 'run.png']
    assert sorted(p.name for p in bag.iterdir()) == [MARKER, 'metadata.yaml', 'run.mcap']


def test_a_killed_overwrite_is_named_not_lost(tmp_path: Path) -> None:
    """The previous outputs of an --overwrite run killed mid-way (SIGKILL: no clean-up) are
    in hidden siblings; the next run names them instead of starting."""
    bag = tmp_path / 'run'
    previous_run(bag)
    hidden = tmp_path / f'.run.replaced-{os.getpid()}'
    bag.rename(hidden)
    with pytest.raises(TrustAvAppError, match=r'\.run\.replaced-\d+: the previous bag '
                                                   'directory kept by an --overwrite run'):
        prepare_outputs(bag, overwrite=True)


def test_an_overwrite_run_that_fails_at_start_up_keeps_the_previous_bag(
        tmp_path: Path) -> None:
    bag = tmp_path / 'run'
    previous_run(bag)
    before = snapshot(tmp_path)
    proc = subprocess.run([sys.executable, '-m', 'trust_av.cli', 'run', '--trace',
                           'us06', '--max-steps', '3', '--bag', str(bag), '--overwrite',
                           '--no-progress', '--no-plot', '--startup-timeout-s', '0.001'],
                          capture_output=True, text=True, timeout=180)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert proc.stderr.count('\n') == 1, proc.stderr
    # The 1 ms start-up fails before the bag exists (only the logs were written), or (seen
    # once under load) at the lifecycle services, after the bag was created: both moved.
    assert re.search("; the previous outputs are back in place, this run's were moved to "
                     f'({re.escape(str(tmp_path))}/run\\.incomplete, )?'
                     f'{re.escape(str(tmp_path))}/run\\.incomplete\\.logs\n$',
                     proc.stderr), proc.stderr
    kept = {name: data for name, data in snapshot(tmp_path).items()
            if not name.startswith('run.incomplete')}
    assert kept == before
