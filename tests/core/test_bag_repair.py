"""repair-bag keeps what was recorded or refuses: this project's recordings are re-cut by step
(log time = header stamp), another tool's keep their log times, a repair that keeps nothing
or cannot read its copy back changes nothing. Foreign bags are built here the way
``ros2 bag record`` writes MCAP (profile ``ros2``, CDR channels with ``ros2msg`` schemas,
zstd or lz4 chunks: rosbag2_storage_mcap's defaults, see ros2/rosbag2
rosbag2_storage_mcap/src/mcap_storage.cpp), with the mcap package's writer."""

from __future__ import annotations

import contextlib
import shutil
from pathlib import Path

import pytest
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Message
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter
from rosbags.rosbag2 import StoragePlugin, Writer
from support.bags import QOS, TYPESTORE, odometry, record
from support.rosbag2_rules import check_bag_directory

from trust_av.cli.main import main
from trust_av.graph import bag_repair
from trust_av.graph.bag_repair import repair_bag, written_here
from trust_av.graph.bag_writer import BagWriteError, BagWriter
from trust_av.graph.mcap_steps import RECORDER_LIBRARY

FOREIGN_LIBRARY = 'mcap-cpp; rosbag2 jazzy'


def foreign_unfinished(bag: Path, compression: CompressionType, messages: int = 12, *,
                       msgtype: str = 'nav_msgs/msg/Odometry') -> list[int]:
    """A bag directory another tool was recording when it died: chunks on disk, no summary,
    no metadata.yaml. Log times are not the header stamps. Returns them."""
    bag.mkdir()
    log_times = [7_000_000_000 + 13 * i for i in range(messages)]
    with (bag / f'{bag.name}_0.mcap').open('wb') as handle:
        writer = McapWriter(handle, compression=compression, chunk_size=256)
        writer.start(profile='ros2', library=FOREIGN_LIBRARY)
        schema = writer.register_schema(msgtype, 'ros2msg', b'')
        channel = writer.register_channel('/lead/odom', 'cdr', schema, {})
        for i, log_time in enumerate(log_times):
            writer.add_message(channel, log_time=log_time, publish_time=log_time - 5,
                               data=odometry(i * 10**9, float(i)))
        handle.flush()                               # killed: never finished
    return log_times


def log_times(bag: Path) -> list[int]:
    """The log times of every message read linearly up to the first unreadable byte."""
    (mcap,) = bag.glob('*.mcap')
    times: list[int] = []
    with mcap.open('rb') as handle, contextlib.suppress(McapError):
        times.extend(record.log_time for record in StreamReader(handle).records
                     if isinstance(record, Message))
    return times


def snapshot(directory: Path) -> dict[str, bytes]:
    return {str(p.relative_to(directory)): p.read_bytes()
            for p in sorted(directory.rglob('*')) if p.is_file()}


@pytest.mark.parametrize('compression', [CompressionType.ZSTD, CompressionType.LZ4])
def test_a_foreign_bag_keeps_its_log_times(tmp_path: Path, compression: CompressionType,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    bag = tmp_path / 'foreign'
    written = foreign_unfinished(bag, compression)
    kept = log_times(bag)
    assert kept and kept == written[:len(kept)]     # the chunks that reached the disk
    assert main(['repair-bag', str(bag)]) == 0
    assert capsys.readouterr().out == (
        f'{bag}: repaired, {len(kept)} messages kept on 1 topic; the unfinished recording was '
        'replaced once the repaired bag read back whole (mcap reader and rosbags)\n')
    assert log_times(bag) == kept                   # not the header stamps (0, 1, 2 s ...)
    assert check_bag_directory(bag) == []
    assert not written_here(bag, '')                # the copy is not taken for ours later
    assert main(['repair-bag', str(bag)]) == 2      # complete now: nothing to repair
    assert 'nothing to repair' in capsys.readouterr().err


def test_our_recordings_are_recognised_and_retimed_by_step(tmp_path: Path) -> None:
    bag = tmp_path / 'ours'
    record(BagWriter(bag), 4, finish=False)
    with (bag / 'ours.mcap').open('rb') as handle:
        assert make_reader(handle).get_header().library.startswith(RECORDER_LIBRARY)
    assert written_here(bag, '') is False         # no metadata.yaml yet: the header says
    assert repair_bag(bag) == 8
    assert written_here(bag, '')                    # metadata.yaml's trust_av.recorder
    assert log_times(bag) == sorted([(100 + s) * 10**9 for s in range(4)] * 2)
    assert check_bag_directory(bag) == []


def test_a_complete_foreign_bag_is_refused_unchanged(tmp_path: Path) -> None:
    bag = tmp_path / 'complete'
    with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        connection = writer.add_connection('/lead/odom', 'nav_msgs/msg/Odometry',
                                           typestore=TYPESTORE, offered_qos_profiles=[QOS])
        writer.write(connection, 42, odometry(0, 1.0))
    before = snapshot(tmp_path)
    with pytest.raises(BagWriteError, match=r'a complete bag written by rosbags-.*nothing to '
                                            'repair'):
        repair_bag(bag)
    assert snapshot(tmp_path) == before


def test_a_repair_that_keeps_nothing_exits_2_and_deletes_nothing(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Channels readable, every chunk after them corrupt: it was 'repaired, 0 messages kept',
    exit 0, original deleted."""
    bag = tmp_path / 'corrupt'
    bag.mkdir()
    mcap = bag / 'corrupt.mcap'
    with mcap.open('wb') as handle:                  # unchunked: channels, then messages
        writer = McapWriter(handle, use_chunking=False)
        writer.start(profile='ros2', library=FOREIGN_LIBRARY)
        channel = writer.register_channel(
            '/lead/odom', 'cdr', writer.register_schema('nav_msgs/msg/Odometry', 'ros2msg', b''),
            {})
        for i in range(3):
            writer.add_message(channel, log_time=i, publish_time=i, data=odometry(i, 1.0))
        handle.flush()
    data = bytearray(mcap.read_bytes())
    offset = 8                                       # after the magic: opcode, length, body
    while data[offset] != 0x05:                      # to the first Message record
        offset += 9 + int.from_bytes(data[offset + 1:offset + 9], 'little')
    data[offset + 1:offset + 9] = b'\xff' * 8        # its length: past the end of the file
    mcap.write_bytes(bytes(data))
    before = snapshot(tmp_path)
    assert main(['repair-bag', str(bag)]) == 2
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and 'nothing was changed' in err, err
    assert snapshot(tmp_path) == before


def test_an_unwritable_topic_is_refused_not_dropped(tmp_path: Path) -> None:
    bag = tmp_path / 'custom'
    foreign_unfinished(bag, CompressionType.ZSTD, msgtype='my_pkg/msg/Thing')
    before = snapshot(tmp_path)
    with pytest.raises(BagWriteError, match=r"topic '/lead/odom' .*my_pkg/msg/Thing is not a "
                                            'ROS 2 Jazzy type'):
        repair_bag(bag)
    assert snapshot(tmp_path) == before


def test_the_original_stays_until_the_copy_reads_back(tmp_path: Path,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """A repaired copy that does not read back whole (here: cut after it was finished) is
    not put in place; the recording is as it was and no workspace is left."""
    bag = tmp_path / 'rec'
    record(BagWriter(bag), 5, finish=False)
    before = snapshot(tmp_path)
    finish = BagWriter.finish

    def finish_then_cut(self: BagWriter) -> None:
        finish(self)
        (mcap,) = self.path.glob('*.mcap')
        with mcap.open('r+b') as handle:
            handle.truncate(handle.seek(0, 2) - 40)

    monkeypatch.setattr(bag_repair.BagWriter, 'finish', finish_then_cut)
    with pytest.raises(BagWriteError, match='does not read back whole'):
        repair_bag(bag)
    assert snapshot(tmp_path) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ['rec']
    shutil.rmtree(bag)


def _refused_in_use(capsys: pytest.CaptureFixture[str], *words: str) -> None:
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and err.startswith('trust-av repair-bag: error: '), err
    assert 'Traceback' not in err and all(word in err for word in words), err


def test_a_bag_being_written_or_repaired_is_refused_unchanged(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A run holds its bag's lock while it records (and a repair-bag while it repairs):
    repair-bag takes the same lock, so it never rewrites a recording under its writer (a
    live run once finished with half its messages in the MCAP) nor races another repair
    on one work folder. A lone .mcap in a bag directory being written is refused too."""
    from trust_av_common.output_lock import hold_output_lock

    bag = tmp_path / 'live'
    foreign_unfinished(bag, CompressionType.ZSTD)
    before = snapshot(tmp_path)
    with hold_output_lock(bag):                     # as `trust-av run --bag live` holds it
        assert main(['repair-bag', str(bag)]) == 2
        _refused_in_use(capsys, str(bag), 'a run is writing it or another repair-bag',
                        'pid ', f'{bag}.lock')
        assert main(['repair-bag', str(bag / 'live_0.mcap')]) == 2
        _refused_in_use(capsys, str(bag), 'a run is writing it')
    assert snapshot(tmp_path) == before and sorted(tmp_path.iterdir()) == [bag]
    assert main(['repair-bag', str(bag)]) == 0      # free again


def test_a_drive_bag_is_not_repaired_while_its_participant_s_session_lives(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A drive records into its bag without a lock of its own: the participant's lock
    (held by their live session) covers it."""
    from trust_av.drive.sessions import Condition, enrol, participant_lock

    enrol(tmp_path, 'P01', [Condition('a', 0.0, 'ca', 'us06')])
    bag = tmp_path / 'P01' / 'drive_01_practice'
    foreign_unfinished(bag, CompressionType.ZSTD)
    before = snapshot(tmp_path)
    with participant_lock(tmp_path, 'P01'):
        assert main(['repair-bag', str(bag)]) == 2
        _refused_in_use(capsys, 'participant P01 already has a live session', 'pid ')
    assert snapshot(tmp_path) == before
    assert main(['repair-bag', str(bag)]) == 0


def test_a_bag_is_finished_only_with_every_file_whole_and_listed(tmp_path: Path) -> None:
    """``finished``: metadata.yaml listing exactly the MCAP files, each complete; a bag cut
    anywhere before that is not (its repair keeps what it can)."""
    whole = tmp_path / 'whole'
    record(BagWriter(whole), 3)
    assert bag_repair.finished(whole)
    split = tmp_path / 'split'
    record(BagWriter(split, max_chunks_per_file=2), 5)
    assert len(list(split.glob('*.mcap'))) == 3 and bag_repair.finished(split)
    cut = tmp_path / 'cut'                          # killed before it finished
    record(BagWriter(cut), 3, finish=False)
    assert not bag_repair.finished(cut)
    cut_after_split = tmp_path / 'cut_after_split'  # files 0 and 1 whole, file 2 open
    record(BagWriter(cut_after_split, max_chunks_per_file=2), 5, finish=False)
    assert not bag_repair.finished(cut_after_split)
    unlisted = tmp_path / 'copy' / 'split'          # a whole file metadata.yaml does not list
    shutil.copytree(split, unlisted)
    assert bag_repair.finished(unlisted)
    shutil.copy(unlisted / 'split_2.mcap', unlisted / 'split_3.mcap')
    assert not bag_repair.finished(unlisted)
    no_metadata = tmp_path / 'no_metadata'          # killed between the MCAP and metadata.yaml
    shutil.copytree(whole, no_metadata)
    (no_metadata / 'whole.mcap').rename(no_metadata / 'no_metadata.mcap')
    (no_metadata / 'metadata.yaml').unlink()
    assert not bag_repair.finished(no_metadata)
    truncated = tmp_path / 'truncated'
    shutil.copytree(whole, truncated)
    mcap = truncated / 'whole.mcap'
    mcap.write_bytes(mcap.read_bytes()[:-9])        # the closing magic lost
    assert not bag_repair.finished(truncated)
    assert not bag_repair.finished(tmp_path / 'nothing')


@pytest.mark.parametrize('code', [-9, 130, 1])
def test_a_recorder_stopped_after_it_finished_its_bag_leaves_it_as_it_is(
        tmp_path: Path, code: int) -> None:
    """A stop signal can reach the recorder after its bag is whole (SIGINT, SIGTERM, SIGINT in
    quick succession: the last kills it on its way out): the run's stop keeps that bag as it
    is and does not try to repair a complete recording, which repair refuses."""
    from types import SimpleNamespace

    from trust_av.graph.orchestrator import _finish_recording
    from trust_av.graph.processes import RECORDER

    bag = tmp_path / 'run'
    record(BagWriter(bag), 3)
    recorder = SimpleNamespace(spec=SimpleNamespace(name=RECORDER),
                               popen=SimpleNamespace(returncode=code), error_line=lambda: '')
    graph = SimpleNamespace(processes=[recorder], by_name=lambda _name: recorder)
    before = snapshot(tmp_path)
    _finish_recording(graph, bag)  # type: ignore[arg-type]
    assert snapshot(tmp_path) == before
    with pytest.raises(BagWriteError, match='nothing to repair'):
        repair_bag(bag)                              # what the stop used to call
    cut = tmp_path / 'cut'                           # and one it did not finish is repaired
    record(BagWriter(cut), 3, finish=False)
    _finish_recording(graph, cut)  # type: ignore[arg-type]
    assert bag_repair.finished(cut) and check_bag_directory(cut) == []
