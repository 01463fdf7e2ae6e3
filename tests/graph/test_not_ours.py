"""Nothing that is not ours is deleted, rewritten or written through: a participant folder
without the study's marker is never withdrawn, ``repair-bag`` never rewrites a complete
recording nor drops what a file it repairs holds, and no single-file output follows a
symbolic link. Each rule is tried with a foreign folder, a symbolic link and a complete
foreign bag."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from support.paths import REPO

from trust_av.cli.main import main

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
    from trust_av.study.layout_plots import main as layout_main
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


@pytest.mark.parametrize('name', ['all_runs.csv', 'table_IV_max_improvements.md',
                                  'figure_3_trust_us06.png'])
def test_reproduce_refuses_a_link_among_its_results_before_the_sweep(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], name: str) -> None:
    results = tmp_path / 'results'
    results.mkdir()
    victim = tmp_path / 'notes.txt'
    victim.write_text('not ours')
    (results / name).symlink_to(victim)
    before = _tree(tmp_path)
    assert main(['reproduce', '--traces', 'us06', '--predictors', 'ca', '--alphas', '0',
                 '--results-dir', str(results), '--no-progress']) == 2
    err = capsys.readouterr().err
    # a folder holding anything trust-av did not write there (a link too) is not replaced
    assert err.count('\n') == 1 and f'holds files trust-av did not write ({name};' in err, err
    assert _tree(tmp_path) == before


def test_dev_stdout_is_still_an_output(tmp_path: Path) -> None:
    """``/dev/stdout`` is a link (to ``/proc/self/fd/1``): the system's names for open
    files are followed, also when stdout is a regular file."""
    out = tmp_path / 'report.json'
    with out.open('w') as handle:
        done = subprocess.run(
            [sys.executable, '-c', 'from pathlib import Path\n'
             'from trust_av_common.output_files import write_text\n'
             "write_text(Path('/dev/stdout'), '{}')"], stdout=handle, stderr=subprocess.PIPE,
            text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert out.read_text() == '{}'


# --- withdrawal ------------------------------------------------------------------------

def _conditions() -> list:
    from trust_av.drive.sessions import Condition
    return [Condition('a', 0.0, 'ca', 'us06'), Condition('b', 1.0, 'ca', 'us06')]


def _withdraw(study: Path, participant: str, *extra: str) -> int:
    return main(['drive', '--study', str(study), '--participant', participant, '--withdraw',
                 *extra])


def _refused(capsys: pytest.CaptureFixture[str], *words: str) -> None:
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and err.startswith('trust-av drive: error: '), err
    assert 'Traceback' not in err and all(word in err for word in words), err


def _foreign_folders(root: Path) -> dict[str, Path]:
    """Folders trust-av never made, each where a participant folder could be."""
    made: dict[str, Path] = {}
    documents = root / 'Documents'                    # a user's folder with their files
    (documents / 'taxes').mkdir(parents=True)
    (documents / 'taxes' / '2025.pdf').write_bytes(b'%PDF')
    made['a user folder'] = documents
    (root / 'Empty').mkdir()
    made['an empty folder'] = root / 'Empty'
    looks = root / 'Looks'                            # a session.json that is not a session
    looks.mkdir()
    (looks / 'session.json').write_text('{"participant": "Looks"}\n')
    made['a folder with a foreign session.json'] = looks
    other = root / 'Other'                            # another participant's session copied
    other.mkdir()
    (other / 'session.json').write_text(json.dumps(
        {'participant': 'P99', 'row': 0, 'order': ['a', 'b'], 'practice_done': False,
         'drives': []}))
    made["another participant's session"] = other
    forged = root / 'Forged'                          # a marker naming someone else
    forged.mkdir()
    (forged / '.trust_av_participant').write_text(json.dumps(
        {'trust_av': 'participant folder', 'study': 'x', 'participant': 'P01'}))
    made['a marker naming another participant'] = forged
    copied = root / 'Copied'                          # ours, but of another study
    copied.mkdir()
    (copied / '.trust_av_participant').write_text(json.dumps(
        {'trust_av': 'participant folder', 'study': 'another-study', 'participant': 'Copied'}))
    made['a folder of another study'] = copied
    handmade = root / 'Handmade'                      # a marker naming no study
    handmade.mkdir()
    (handmade / 'notes.txt').write_text('not ours')
    (handmade / '.trust_av_participant').write_text(json.dumps(
        {'trust_av': 'participant folder', 'participant': 'Handmade'}))
    made['a hand-made marker naming no study'] = handmade
    (root / 'AFile').write_text('not a folder')
    made['a file'] = root / 'AFile'
    return made


@pytest.mark.parametrize('with_study', [False, True])
def test_withdrawal_never_deletes_a_foreign_folder(tmp_path: Path, with_study: bool,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """`--study home --participant Documents` once deleted home/Documents: a folder that
    does not carry the study's marker (or, from before markers, its session) is refused in
    one line, exit 2, with --yes, and nothing anywhere is changed."""
    from trust_av.drive.sessions import enrol

    if with_study:
        enrol(tmp_path, 'P01', _conditions())
    for name, folder in _foreign_folders(tmp_path).items():
        before = _tree(tmp_path)
        assert _withdraw(tmp_path, folder.name, '--yes') == 2, name
        _refused(capsys, str(folder), 'nothing is deleted')
        assert _tree(tmp_path) == before, name


def test_a_foreign_folder_is_never_enrolled(tmp_path: Path) -> None:
    """Enrolment never adopts a folder it did not make (it would then carry the marker)."""
    from trust_av.drive.sessions import SessionError, enrol

    for folder in _foreign_folders(tmp_path).values():
        before = _tree(tmp_path)
        with pytest.raises(SessionError):
            enrol(tmp_path, folder.name, _conditions())
        assert _tree(tmp_path) == before


@pytest.mark.parametrize('where', ['participant folder', 'study directory', 'inside'])
def test_withdrawal_refuses_a_symbolic_link(tmp_path: Path, where: str,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    from trust_av.drive.sessions import enrol

    real = tmp_path / 'real'
    enrol(real, 'P01', _conditions())
    keep = tmp_path / 'keep'                 # what a link might point at
    keep.mkdir()
    (keep / 'precious').write_text('not ours')
    study, participant = real, 'P01'
    if where == 'participant folder':
        (real / 'P02').symlink_to(real / 'P01')          # a link to a real participant's
        participant = 'P02'
    elif where == 'study directory':
        study = tmp_path / 'linked'
        study.symlink_to(real)
    else:
        (real / 'P01' / 'shortcut').symlink_to(keep)
    before = _tree(tmp_path)
    assert _withdraw(study, participant, '--yes') == 2
    _refused(capsys, 'symbolic link', 'nothing is deleted')
    assert _tree(tmp_path) == before


def test_withdrawal_deletes_our_folder_after_confirmation(
        tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    import io

    from trust_av.drive.sessions import MARKER, enrol

    enrol(tmp_path, 'P01', _conditions())
    marker = json.loads((tmp_path / 'P01' / MARKER).read_text())
    study = json.loads((tmp_path / 'study.json').read_text())
    assert marker['participant'] == 'P01' and marker['study'] == study['study']
    before = _tree(tmp_path)
    assert _withdraw(tmp_path, 'P01') == 2          # no terminal (pytest's stdin), no --yes
    _refused(capsys, '--yes', 'no terminal')
    assert _tree(tmp_path) == before

    class Terminal(io.StringIO):
        def isatty(self) -> bool:
            return True

    for answer, deleted in (('n\n', False), ('', False), ('y\n', True)):
        monkeypatch.setattr(sys, 'stdin', Terminal(answer))
        assert _withdraw(tmp_path, 'P01') == 0
        out = capsys.readouterr().out
        assert (tmp_path / 'P01').exists() != deleted
        assert ('every file trust-av wrote deleted' if deleted else 'nothing deleted') in out
    assert _withdraw(tmp_path, 'P01', '--yes') == 0
    assert 'no data in this study' in capsys.readouterr().out


def test_withdrawal_deletes_only_what_trust_av_wrote(tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """Of a participant folder proven this study's, withdrawal deletes the entries trust-av
    writes there and leaves (and names) a file it did not write, with the folder, and a bag
    the session names outside the folder (an earlier version took condition names as
    paths): it never reports "every file deleted" over what it left."""
    from trust_av.drive.sessions import DriveRecord, enrol, save_session

    session = enrol(tmp_path, 'P01', _conditions())
    folder = tmp_path / 'P01'
    for name in ('drive_01_practice', 'drive_02_a', 'drive_02_a.attempt1', 'drive_02_a.logs'):
        (folder / name).mkdir()
        (folder / name / 'x.mcap').write_bytes(b'x')
    for name in ('summary.csv', 'comparison.csv'):
        (folder / name).write_text('drive\n')
    (folder / 'notes.txt').write_text("the researcher's")
    outside = tmp_path / 'elsewhere'
    outside.mkdir()
    (outside / 'x.mcap').write_bytes(b'x')
    session.drives.append(DriveRecord(3, '../elsewhere', 'P01/../elsewhere', 'done', 3))
    save_session(tmp_path, session)
    assert _withdraw(tmp_path, 'P01', '--yes') == 0
    out = capsys.readouterr().out
    assert sorted(p.name for p in folder.iterdir()) == ['notes.txt']
    assert (outside / 'x.mcap').is_file()
    assert 'every file trust-av wrote deleted (8 files' in out       # 4 bags, 4 files
    assert 'did not write: notes.txt' in out and str(outside.resolve()) in out


def test_a_folder_from_before_markers_is_recognised_by_its_session(tmp_path: Path) -> None:
    """A study made by an earlier version: its participant folders have a session.json of
    the participant and the study a study.json, but no marker. Resuming adds the marker;
    withdrawal deletes such a folder."""
    from trust_av.drive.sessions import MARKER, enrol
    from trust_av.drive.withdrawal import withdraw

    for participant in ('P01', 'P02'):
        enrol(tmp_path, participant, _conditions())
        (tmp_path / participant / MARKER).unlink()
    (tmp_path / 'study.json').write_text('{"enrolled": 2}\n')   # the old counter
    enrol(tmp_path, 'P01', _conditions())                       # resumed
    assert (tmp_path / 'P01' / MARKER).is_file()
    assert 'study' in json.loads((tmp_path / 'study.json').read_text())
    assert withdraw(tmp_path, 'P01') and withdraw(tmp_path, 'P02')
    assert sorted(p.name for p in tmp_path.iterdir()) == ['study.json']


# --- repair-bag ------------------------------------------------------------------------

ATTACHMENT = ('calibration.yaml', 'application/yaml', b'wheelbase_m: 2.7\n')
METADATA = ('recording', {'operator': 'site B', 'weather': 'dry'})
QUIET = '/lead/status'


def foreign_mcap(path: Path, *, finished: bool, messages: int = 40) -> None:
    """An MCAP another tool wrote (profile ros2, CDR, ros2msg schemas, as ``ros2 bag
    record``): an attachment, a metadata record, a channel without messages and a schema
    no channel uses besides /lead/odom's messages; finished, or cut off by a kill (chunks on
    disk, no summary, no footer)."""
    from mcap.writer import CompressionType
    from mcap.writer import Writer as McapWriter
    from support.bags import odometry

    with path.open('wb') as handle:
        writer = McapWriter(handle, compression=CompressionType.ZSTD, chunk_size=512)
        writer.start(profile='ros2', library='mcap-cpp; rosbag2 jazzy')
        writer.add_attachment(11, 12, *ATTACHMENT)
        writer.add_metadata(*METADATA)
        writer.register_schema('my_pkg/msg/Note', 'ros2msg', b'string text')
        odom = writer.register_channel(
            '/lead/odom', 'cdr', writer.register_schema('nav_msgs/msg/Odometry', 'ros2msg', b''),
            {})
        writer.register_channel(QUIET, 'cdr',
                                writer.register_schema('std_msgs/msg/String', 'ros2msg', b''), {})
        for i in range(messages):
            log_time = 5_000_000_000 + 17 * i
            writer.add_message(odom, log_time=log_time, publish_time=log_time,
                               data=odometry(i * 10**9, float(i)))
        if finished:
            writer.finish()
        handle.flush()


@pytest.mark.parametrize('layout', ['lone .mcap', 'directory without metadata.yaml'])
def test_a_complete_foreign_recording_is_never_rewritten(
        tmp_path: Path, layout: str, capsys: pytest.CaptureFixture[str]) -> None:
    """It was rewritten, its attachment and metadata record dropped, the original deleted."""
    if layout == 'lone .mcap':
        path = tmp_path / 'drive.mcap'
        foreign_mcap(path, finished=True)
    else:
        path = tmp_path / 'drive'
        path.mkdir()
        foreign_mcap(path / 'drive_0.mcap', finished=True)
    before = _tree(tmp_path)
    assert main(['repair-bag', str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and 'a complete bag written by mcap-cpp' in err, err
    assert 'never rewrites a complete recording' in err
    assert ('ros2 bag reindex' in err) == (layout != 'lone .mcap')
    assert _tree(tmp_path) == before


def test_a_repair_keeps_attachments_metadata_and_quiet_channels(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from mcap.reader import make_reader
    from rosbags.rosbag2 import Reader
    from support.rosbag2_rules import check_bag_directory

    from trust_av.graph.bag_repair import complete_mcap

    lone = tmp_path / 'drive.mcap'
    foreign_mcap(lone, finished=False)
    assert not complete_mcap(lone)
    assert main(['repair-bag', str(lone)]) == 0
    out = capsys.readouterr().out
    bag = tmp_path / 'drive'
    (mcap,) = bag.glob('*.mcap')
    assert complete_mcap(mcap) and check_bag_directory(bag) == []
    with mcap.open('rb') as handle:
        reader = make_reader(handle)
        attachments = [(a.name, a.media_type, a.data) for a in reader.iter_attachments()]
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
        summary = reader.get_summary()
        assert summary is not None
        topics = {c.topic for c in summary.channels.values()}
        schemas = {s.name for s in summary.schemas.values()}
        kept = sum(1 for _ in reader.iter_messages())
    assert attachments == [ATTACHMENT] and metadata[METADATA[0]] == METADATA[1]
    assert 'rosbag2' in metadata                   # the repaired bag's own description
    assert topics == {'/lead/odom', QUIET} and 'my_pkg/msg/Note' in schemas
    with Reader(bag) as rosbag:
        assert {c.topic: c.msgcount for c in rosbag.connections} == {'/lead/odom': kept,
                                                                    QUIET: 0}
    assert out == (f'{bag}: repaired, {kept} messages kept on 1 topic, 1 topic without '
                   'messages, 1 schema no channel uses, 1 attachment, 1 metadata record; '
                   'the unfinished recording was replaced once the repaired bag read back '
                   'whole (mcap reader and rosbags)\n')
    assert sorted(p.name for p in tmp_path.iterdir()) == ['drive']


def test_repair_bag_refuses_a_symbolic_link(tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    """A link named as the recording (or the MCAP file in a bag directory): the repair would
    move the link, not the recording; refused in one line, nothing changed."""
    elsewhere = tmp_path / 'elsewhere'
    elsewhere.mkdir()
    foreign_mcap(elsewhere / 'real.mcap', finished=False)
    (tmp_path / 'link.mcap').symlink_to(elsewhere / 'real.mcap')
    (tmp_path / 'linked_bag').symlink_to(elsewhere)
    bag = tmp_path / 'bag'
    bag.mkdir()
    (bag / 'bag_0.mcap').symlink_to(elsewhere / 'real.mcap')
    before = _tree(tmp_path)
    for path in ('link.mcap', 'linked_bag', 'bag'):
        assert main(['repair-bag', str(tmp_path / path)]) == 2, path
        err = capsys.readouterr().err
        assert err.count('\n') == 1 and 'a symbolic link' in err, err
        assert _tree(tmp_path) == before
