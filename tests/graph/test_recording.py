"""Recordings that survive every way a run can end: the bag writer (one chunk per step, a full
disk, repair), the outputs a run writes, the per-user domain leases. Every bag is held to
rosbag2 Jazzy's reader rules (tests/support/rosbag2_rules.py). The graph-level cases (SIGTERM, a
killed orchestrator, a foreign publisher, a full disk under a real run) are at the end."""

from __future__ import annotations

import ast
import contextlib
import errno
import importlib
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from mcap.reader import make_reader
from rosbags.rosbag2 import Reader
from support.bags import QOS, fail_commit, odometry, record
from support.graph import stoppable_run
from support.processes import (
    INTERRUPTED_RUN_STEPS,
    assert_every_topic_complete,
    long_trace,
    wait_for_steps,
    wait_ready,
)
from support.rosbag2_rules import check_bag_directory  # the test-side oracle module

from trust_av.errors import TrustAvAppError
from trust_av.graph import bag_writer, mcap_steps
from trust_av.graph.bag_repair import _swap_into_place, mcap_files, repair_bag
from trust_av.graph.bag_writer import BagWriteError, BagWriter
from trust_av.graph.domains import lease_domain
from trust_av.graph.processes import GraphError
from trust_av.system.outputs import MARKER, prepare_outputs


def counts(bag: Path) -> dict[str, int]:
    with Reader(bag) as reader:
        return {c.topic: c.msgcount for c in reader.connections}


def test_bag_writer_writes_a_rosbag2_bag_directory(tmp_path: Path) -> None:
    bag = tmp_path / 'run'
    record(BagWriter(bag), 20)
    assert sorted(p.name for p in bag.iterdir()) == ['metadata.yaml', 'run.mcap']
    assert check_bag_directory(bag) == []
    assert counts(bag) == {'/a/odom': 20, '/b/odom': 20}
    with pytest.raises(bag_writer.BagWriteError, match='exists already'):
        BagWriter(bag)


@pytest.mark.parametrize('where', ['new_writer', '_grow_reserve'])
def test_a_stop_while_the_bag_is_created_leaves_no_directory(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, where: str) -> None:
    """A stop signal (raised as KeyboardInterrupt, like trust_av.graph.stop_signals.Stopped)
    while the bag is being created, after its directory and MCAP file exist, before or after
    the MCAP header: no half-made bag is left (a stopped ``trust-av shadow`` left an empty
    .mcap and no metadata.yaml, and said its recordings were finished)."""
    def stop(*_args: object) -> None:
        raise KeyboardInterrupt
    target = bag_writer if where == 'new_writer' else BagWriter
    monkeypatch.setattr(target, where, stop)
    with pytest.raises(KeyboardInterrupt):
        BagWriter(tmp_path / 'run')
    assert list(tmp_path.iterdir()) == []
    monkeypatch.undo()
    record(BagWriter(tmp_path / 'run'), 2)        # the name is free again
    assert check_bag_directory(tmp_path / 'run') == []


def test_wall_mode_log_time_is_the_receive_time_and_publish_time_the_stamp(
        tmp_path: Path) -> None:
    """``receive_time_ns`` (wall mode, as ``ros2 bag record``): log time = receive time,
    publish time = the header stamp; without it both are the stamp (lock-step). The bag
    still follows rosbag2's rules (its start and duration are the log times')."""
    from mcap.reader import make_reader
    bag = tmp_path / 'wall'
    with BagWriter(bag) as writer:
        writer.add_topic('/a/odom', 'nav_msgs/msg/Odometry', QOS)
        for step in range(3):
            stamp = (100 + step) * 10**9
            assert writer.write('/a/odom', odometry(stamp, 0.0),
                                receive_time_ns=stamp + 2_000_000) == stamp + 2_000_000
            writer.end_step()
        writer.write('/a/odom', odometry(200 * 10**9, 0.0))
        writer.finish()
    assert check_bag_directory(bag) == []
    with (bag / 'wall.mcap').open('rb') as stream:
        times = [(m.log_time, m.publish_time) for _, _, m in make_reader(stream).iter_messages()]
    assert times == [((100 + k) * 10**9 + 2_000_000, (100 + k) * 10**9) for k in range(3)] + [
        (200 * 10**9, 200 * 10**9)]


def test_every_step_is_on_disk_before_the_bag_is_finished(tmp_path: Path) -> None:
    """A writer that never finishes (SIGKILL) leaves every closed step in the file; repair
    turns it into a complete bag, and a chunk cut in the middle is dropped whole."""
    bag = tmp_path / 'killed'
    record(BagWriter(bag), 10, finish=False)          # no summary, no metadata.yaml
    assert not (bag / 'metadata.yaml').exists()
    assert check_bag_directory(bag)                    # not readable as it is
    cut = tmp_path / 'cut'
    shutil.copytree(bag, cut)
    mcap = cut / 'killed.mcap'
    mcap.rename(cut / 'cut.mcap')
    with (cut / 'cut.mcap').open('r+b') as handle:
        handle.truncate(handle.seek(0, 2) - 200)       # inside the last step's chunk
    proc = subprocess.run([sys.executable, '-m', 'trust_av.cli', 'repair-bag',
                           str(bag)], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert check_bag_directory(bag) == []
    assert counts(bag) == {'/a/odom': 10, '/b/odom': 10}
    assert sorted(p.name for p in bag.iterdir()) == ['killed.mcap', 'metadata.yaml']
    assert repair_bag(cut) == 18                       # 9 whole steps of 2 messages
    assert check_bag_directory(cut) == []


def test_repair_bag_on_nothing_readable_is_one_line(tmp_path: Path) -> None:
    junk = tmp_path / 'junk.mcap'
    junk.write_bytes(b'\x89MCAP0\r\n' + b'\x00' * 7)
    proc = subprocess.run([sys.executable, '-m', 'trust_av.cli', 'repair-bag',
                           str(junk)], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2 and proc.stderr.count('\n') == 1
    assert 'no readable MCAP channels' in proc.stderr


def unfinished_recording(directory: Path) -> tuple[Path, bytes]:
    """A lone .mcap of a killed recorder, and its bytes."""
    bag = directory / 'rec'
    record(BagWriter(bag), 5, finish=False)
    lone = directory / 'lone.mcap'
    (bag / 'rec.mcap').rename(lone)
    shutil.rmtree(bag)
    return lone, lone.read_bytes()


def test_repair_never_loses_the_recording(tmp_path: Path) -> None:
    """The recording is deleted only once its repaired bag is in place: a lone .mcap whose
    bag directory name is taken is refused; a rename that fails puts the recording back; a
    repair killed between its renames leaves it where the next repair names it."""
    lone, content = unfinished_recording(tmp_path)
    taken = tmp_path / 'lone'
    taken.mkdir()
    (taken / 'notes.txt').write_text('not a bag')
    proc = subprocess.run([sys.executable, '-m', 'trust_av.cli', 'repair-bag',
                           str(lone)], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    assert proc.stderr == (f'trust-av repair-bag: error: {taken} exists already and the '
                           f'repaired bag of {lone} would replace it; move it away first\n')
    assert lone.read_bytes() == content and (taken / 'notes.txt').read_text() == 'not a bag'

    staging = tmp_path / 'staging'
    staging.mkdir()                                   # renaming it onto `taken` fails
    with pytest.raises(BagWriteError, match='cannot put the repaired bag there'):
        _swap_into_place(lone, staging, taken, tmp_path / 'old')
    assert lone.read_bytes() == content and not (tmp_path / 'old').exists()

    shutil.rmtree(taken)
    workspace = tmp_path / '.lone.repairing'         # as a repair killed between renames
    workspace.mkdir()
    lone.rename(workspace / 'old')
    with pytest.raises(BagWriteError, match='an earlier repair that did not finish'):
        repair_bag(lone)
    assert (workspace / 'old').read_bytes() == content


def test_a_full_disk_keeps_every_complete_step(tmp_path: Path,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    """The write of a step fails half-way: the partial step is cut off, the reserve pays for
    the summary and metadata.yaml, the bag holds every complete step, nothing else is left."""
    original = mcap_steps.WholeWrites.write
    bag = tmp_path / 'full'
    capacity = 120_000                                 # the disk: the MCAP plus the reserve

    def quota(handle: mcap_steps.WholeWrites, data: bytes) -> int:
        reserve = bag / bag_writer.RESERVE_NAME
        used = handle.position + (reserve.stat().st_size if reserve.exists() else 0)
        if used + len(data) > capacity:
            original(handle, bytes(data)[:max(capacity - used, 0)])   # a short write first
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return original(handle, data)

    monkeypatch.setattr(mcap_steps.WholeWrites, 'write', quota)
    writer = BagWriter(bag)
    record(writer, 200, finish=False)
    assert writer.finished and 'disk full' in writer.disk_full
    assert 0 < writer.steps < 200
    assert check_bag_directory(bag) == []
    assert counts(bag) == {'/a/odom': writer.steps, '/b/odom': writer.steps}
    assert sorted(p.name for p in bag.iterdir()) == ['full.mcap', 'metadata.yaml']
    writer.finish()                                    # idempotent


def test_a_real_full_disk(small_disk: Path) -> None:
    bag = small_disk / 'run'
    writer = BagWriter(bag)
    record(writer, 10_000, finish=False)
    assert 'disk full' in writer.disk_full and writer.steps > 10
    assert check_bag_directory(bag) == []
    assert sorted(p.name for p in bag.iterdir()) == ['metadata.yaml', 'run.mcap']


def test_a_long_recording_goes_on_in_numbered_files_rosbag2_reads_in_order(
        tmp_path: Path) -> None:
    """After max_chunks_per_file steps the file is finished and the next begins: rosbag2's
    split, every file complete with its own summary, metadata.yaml listing them in order
    with each one's messages and span (rosbag2's reader rules, tests/support/rosbag2_rules.py)."""
    bag = tmp_path / 'long'
    writer = BagWriter(bag, max_chunks_per_file=4)
    record(writer, 10)
    assert writer.files == ['long.mcap', 'long_1.mcap', 'long_2.mcap']
    assert sorted(p.name for p in bag.iterdir()) == sorted([*writer.files, 'metadata.yaml'])
    assert check_bag_directory(bag) == []
    assert counts(bag) == {'/a/odom': 10, '/b/odom': 10}
    chunks = []
    for name in writer.files:
        with (bag / name).open('rb') as handle:
            summary = make_reader(handle).get_summary()
        assert summary is not None and summary.statistics is not None
        chunks.append(summary.statistics.chunk_count)
        assert sorted(c.topic for c in summary.channels.values()) == ['/a/odom', '/b/odom']
    assert chunks == [4, 4, 2]
    even = BagWriter(tmp_path / 'even', max_chunks_per_file=5)
    record(even, 10)              # the file begun at the last split is empty: not kept
    assert even.files == ['even.mcap', 'even_1.mcap']
    assert sorted(p.name for p in (tmp_path / 'even').iterdir()) == [
        'even.mcap', 'even_1.mcap', 'metadata.yaml']
    assert check_bag_directory(tmp_path / 'even') == []
    with Reader(bag) as reader:          # rosbags: the files one after the other, in order
        stamps = [stamp for _, stamp, _ in reader.messages()]
    assert stamps == sorted(stamps) and len(stamps) == 20
    info = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert [(f['path'], f['message_count'], f['starting_time']['nanoseconds_since_epoch'])
            for f in info['files']] == [('long.mcap', 8, 100 * 10**9),
                                        ('long_1.mcap', 8, 104 * 10**9),
                                        ('long_2.mcap', 4, 108 * 10**9)]


def test_a_killed_split_recording_is_repaired_whole(tmp_path: Path) -> None:
    """Killed in its twelfth file (no metadata.yaml, the last file without a summary): the
    repair reads the files by their numbers (long_10 after long_9, not after long_1) and
    keeps every complete step of every file."""
    bag = tmp_path / 'killed'
    writer = BagWriter(bag, max_chunks_per_file=1)
    record(writer, 12, finish=False)
    writer.write('/a/odom', odometry(112 * 10**9, 12.0))   # a step not yet ended: lost
    assert not (bag / 'metadata.yaml').exists()
    assert [file.name for file in mcap_files(bag)] == [
        'killed.mcap', *(f'killed_{n}.mcap' for n in range(1, 13))]
    assert repair_bag(bag) == 24
    assert check_bag_directory(bag) == []
    assert counts(bag) == {'/a/odom': 12, '/b/odom': 12}
    other = tmp_path / 'other'                 # files of no known order, and no metadata.yaml
    other.mkdir()
    for name in ('a.mcap', 'b.mcap'):
        shutil.copy(bag / 'killed.mcap', other / name)
    with pytest.raises(BagWriteError, match='cannot tell the order of its 2 MCAP files'):
        repair_bag(other)


def test_a_full_disk_at_the_next_file_finishes_the_bag_with_the_files_before(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The next file cannot be created (a full disk): it is not left behind, and the bag is
    finished with every step of the files before it."""
    create = mcap_steps.WholeWrites.__init__

    def full(handle: mcap_steps.WholeWrites, path: Path) -> None:
        if path.name != 'full.mcap':
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        create(handle, path)

    monkeypatch.setattr(mcap_steps.WholeWrites, '__init__', full)
    writer = BagWriter(tmp_path / 'full', max_chunks_per_file=3)
    record(writer, 5, finish=False)
    assert writer.finished and writer.steps == 3
    assert 'cannot start its next file full_1.mcap (No space left on device)' in writer.disk_full
    assert sorted(p.name for p in (tmp_path / 'full').iterdir()) == ['full.mcap',
                                                                     'metadata.yaml']
    assert check_bag_directory(tmp_path / 'full') == []
    assert counts(tmp_path / 'full') == {'/a/odom': 3, '/b/odom': 3}


def test_the_reserve_always_pays_for_the_summary_and_grows_every_64_steps(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """After every step the reserve holds the summary of every chunk written; it is grown
    (one fallocate) once per RESERVE_STEP_CHUNKS steps, not at every step."""
    grown = []
    fallocate = os.posix_fallocate

    def counted(fd: int, offset: int, length: int) -> None:
        grown.append(length)
        fallocate(fd, offset, length)

    monkeypatch.setattr(os, 'posix_fallocate', counted)
    bag = tmp_path / 'reserve'
    writer = BagWriter(bag)
    writer.add_topic('/a/odom', 'nav_msgs/msg/Odometry', QOS)
    for step in range(200):
        writer.write('/a/odom', odometry((100 + step) * 10**9, 1.0))
        assert writer.end_step()
        assert (bag / bag_writer.RESERVE_NAME).stat().st_size >= (
            bag_writer.RESERVE_BASE_BYTES + bag_writer.RESERVE_PER_CHUNK_BYTES * (step + 1))
    assert len(grown) == 1 + 200 // (bag_writer.RESERVE_STEP_CHUNKS + 1)
    writer.finish()
    assert not (bag / bag_writer.RESERVE_NAME).exists() and check_bag_directory(bag) == []


def test_a_failed_step_with_a_new_topic_keeps_every_complete_step(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The step that fails is the first of a topic added late, and another topic was added
    with it: the writer that finishes the bag is rebuilt from the file's complete steps
    (the failed step's messages never reach the summary), and both late topics are in it
    with no messages."""
    fail_commit(monkeypatch, 4)
    bag = tmp_path / 'late'
    writer = BagWriter(bag)
    record(writer, 3, ('/a/odom',), finish=False)
    writer.add_topic('/late/odom', 'nav_msgs/msg/Odometry', QOS)
    writer.add_topic('/late/text', 'std_msgs/msg/String', [QOS, QOS])
    writer.write('/a/odom', odometry(103 * 10**9, 3.0))
    writer.write('/late/odom', odometry(103 * 10**9, 3.0))
    assert writer.counts == {'/a/odom': 4, '/late/odom': 1, '/late/text': 0}
    assert not writer.end_step()
    assert writer.steps == 3 and 'cannot write (Input/output error)' in writer.disk_full
    assert check_bag_directory(bag) == []
    assert counts(bag) == {'/a/odom': 3, '/late/odom': 0, '/late/text': 0}
    with (bag / 'late.mcap').open('rb') as handle:
        summary = make_reader(handle).get_summary()
    assert summary is not None and summary.statistics is not None
    assert summary.statistics.message_count == 3 and summary.statistics.chunk_count == 3
    assert summary.statistics.message_end_time == 102 * 10**9
    assert sorted(c.topic for c in summary.channels.values()) == ['/a/odom', '/late/odom',
                                                                   '/late/text']
    assert sorted(p.name for p in bag.iterdir()) == ['late.mcap', 'metadata.yaml']


def test_the_rebuilt_writer_must_end_where_the_complete_steps_end(tmp_path: Path) -> None:
    """The writer rebuilt from a file (after a failed step) writes the same bytes as the one
    that wrote it, checked: it refuses a file cut inside a step, a size that is not the
    file's, or a header naming another writer."""
    bag = tmp_path / 'cut'
    record(BagWriter(bag), 3, finish=False)
    mcap = bag / 'cut.mcap'
    size = mcap.stat().st_size
    rebuilt = mcap_steps.replay(mcap, size, mcap_steps.RECORDER_LIBRARY)
    assert (rebuilt.stream.position, rebuilt.schemas, rebuilt.channels) == (size, 1, 2)
    with pytest.raises(ValueError, match=f'ends at byte {size}, not {size + 1}'):
        mcap_steps.replay(mcap, size + 1, mcap_steps.RECORDER_LIBRARY)
    with pytest.raises(ValueError, match='its header names'):
        mcap_steps.replay(mcap, size, 'another.writer')
    with mcap.open('ab') as handle:                     # a record longer than the file
        handle.write(b'\x05' + b'\xff' * 8)
    with pytest.raises(ValueError, match=f'cannot be read to byte {size + 9}'):
        mcap_steps.replay(mcap, size + 9, mcap_steps.RECORDER_LIBRARY)
    with mcap.open('r+b') as handle:
        handle.truncate(size - 100)                     # in the last step's message indexes
    with pytest.raises(ValueError, match=rf'replay to \d+ bytes, not {size - 100}'):
        mcap_steps.replay(mcap, size - 100, mcap_steps.RECORDER_LIBRARY)


PUBLIC_ONLY = ('bag_writer', 'bag_metadata', 'mcap_steps')
"""The bag writer's modules: public library API only."""


def _internal(module: str) -> str:
    """Why ``module`` is not public API of its library ('' if it is): a part starting with
    ``_``, or a package whose ``__all__`` does not name the next part."""
    parts = module.split('.')
    for number, part in enumerate(parts):
        if part.startswith('_'):
            return f'{module}: {part} is private'
        if number:
            package = importlib.import_module('.'.join(parts[:number]))
            names = getattr(package, '__all__', None)
            if names is not None and part not in names:
                return f'{module}: {package.__name__}.__all__ does not name {part}'
    return ''


@pytest.mark.parametrize('name', PUBLIC_ONLY)
def test_the_bag_writer_uses_public_library_api_only(name: str) -> None:
    """No attribute starting with ``_`` of anything but the writer's own objects, no
    internal module, no name a module's ``__all__`` leaves out (rosbags, mcap, yaml)."""
    source = Path(bag_writer.__file__).with_name(f'{name}.py')
    problems = []
    for node in ast.walk(ast.parse(source.read_text())):
        if isinstance(node, ast.Attribute) and node.attr.startswith('_') \
                and not node.attr.startswith('__') \
                and not (isinstance(node.value, ast.Name) and node.value.id == 'self'):
            problems.append(f'line {node.lineno}: .{node.attr}')
        elif isinstance(node, ast.ImportFrom) and node.module \
                and node.module.split('.')[0] in ('rosbags', 'mcap', 'yaml'):
            why = _internal(node.module)
            names = getattr(importlib.import_module(node.module), '__all__', None)
            for alias in node.names:
                if alias.name.startswith('_') or (names is not None
                                                  and alias.name not in names):
                    why = why or f'{node.module}.{alias.name} is not in its __all__'
            if why:
                problems.append(f'line {node.lineno}: {why}')
    assert problems == []
    assert _internal('rosbags.rosbag2.storage_mcap')     # what it used before is caught
    assert _internal('mcap._chunk_builder')


def test_outputs_are_checked_before_a_run(tmp_path: Path) -> None:
    with pytest.raises(TrustAvAppError, match=r'not an \.mcap file'):
        prepare_outputs(tmp_path / 'x.mcap', overwrite=True)
    bag = tmp_path / 'run'
    (tmp_path / 'run.png').write_bytes(b'old plot')
    with pytest.raises(TrustAvAppError, match=r'run\.png exists already'):
        prepare_outputs(bag, overwrite=False)
    (tmp_path / 'run.png').unlink()
    (tmp_path / 'run.logs').symlink_to(tmp_path / 'nowhere')      # dangling
    with pytest.raises(TrustAvAppError, match='is a symbolic link'):
        prepare_outputs(bag, overwrite=True)
    (tmp_path / 'run.logs').unlink()
    bag.mkdir()
    (bag / 'thesis.tex').write_text('precious')
    with pytest.raises(TrustAvAppError, match='not written by trust-av'):
        prepare_outputs(bag, overwrite=True)
    assert (bag / 'thesis.tex').read_text() == 'precious'
    # what --overwrite may replace: tests/graph/test_output_ownership.py


def test_leases_never_write_through_a_planted_link(tmp_path: Path,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv('TRUST_AV_DOMAIN_RANGE', '1-1')
    leases = tmp_path / 'leases'
    target = tmp_path / 'precious.txt'
    target.write_text('keep me')
    with lease_domain(directory=leases) as domain:
        assert (leases / f'{domain}.lock').exists()
    assert oct(os.stat(leases).st_mode & 0o777) == '0o700'
    (leases / '1.lock').unlink()
    (leases / '1.lock').symlink_to(target)
    with pytest.raises(GraphError, match=r'1\.lock: a lease file is a symbolic link'), \
            lease_domain(directory=leases):
        pass
    assert target.read_text() == 'keep me'


def test_a_lease_directory_that_is_not_ours_is_refused(tmp_path: Path) -> None:
    link = tmp_path / 'link'
    link.symlink_to(tmp_path)
    with pytest.raises(GraphError, match='not a directory'), lease_domain(directory=link):
        pass
    loose = tmp_path / 'loose'
    loose.mkdir(mode=0o777)
    os.chmod(loose, 0o777)
    with lease_domain(directory=loose):
        assert oct(os.stat(loose).st_mode & 0o777) == '0o700'
    if os.getuid() != 0:
        pytest.skip('changing the owner of the directory needs root')
    other = tmp_path / 'other'
    other.mkdir(mode=0o700)
    os.chown(other, 12345, 12345)
    with pytest.raises(GraphError, match='belongs to uid 12345'), lease_domain(directory=other):
        pass


def test_a_domain_with_someone_else_on_it_is_skipped(tmp_path: Path) -> None:
    seen = []

    def foreign(domain: int) -> str:
        seen.append(domain)
        return 'nodes /intruder' if len(seen) == 1 else ''

    with lease_domain(foreign, directory=tmp_path / 'leases') as domain:
        assert domain == seen[1] != seen[0]
    with pytest.raises(GraphError, match=r'no free ROS domain id .*not private: '), \
            lease_domain(lambda _domain: 'nodes /x', directory=tmp_path / 'leases2'):
        pass


def test_a_domain_whose_rtps_ports_are_bound_is_not_private(tmp_path: Path) -> None:
    """A socket on one of a domain's RTPS ports (what any DDS participant binds) makes it
    not private at once; the ports of other domains do not; a socket table in the kernel's
    format is read for both address families."""
    import socket

    from trust_av.graph.domains import domain_ports_in_use
    from trust_av.graph.session import foreign_participants

    with lease_domain() as domain:        # the lease every run takes: no run of ours is on it
        assert foreign_participants(domain) == ''
        port = 7400 + 250 * domain + 10 + 2 * 7          # participant 7's discovery port
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
            sock.bind(('127.0.0.1', port))
            assert f'UDP ports {port} in use' in foreign_participants(domain)
            other = domain - 1 if domain > 0 else domain + 1
            assert port not in (domain_ports_in_use(other) or [])
        assert foreign_participants(domain) == ''
    table = tmp_path / 'udp6'
    table.write_text('  sl  local_address                         remote_address  st\n'
                     '   0: 00000000000000000000000001000000:FC96 '
                     '00000000000000000000000000000000:0000 07\n')
    assert domain_ports_in_use(229, (table,)) == [64662]      # 7400 + 250 * 229 + 12
    assert domain_ports_in_use(229, (tmp_path / 'none',)) is None


# --- the whole graph ------------------------------------------------------------------------

def run_command(bag: Path, steps: int = 600, *extra: str, trace: str = 'us06') -> list[str]:
    return [sys.executable, '-m', 'trust_av.cli', 'run', '--trace', trace,
            '--max-steps', str(steps), '--bag', str(bag), '--no-progress', '--no-plot', *extra]


@pytest.mark.parametrize('signum', [signal.SIGTERM, signal.SIGHUP], ids=['SIGTERM', 'SIGHUP'])
def test_a_stop_signal_finishes_the_bag_like_sigint(tmp_path: Path, signum: int) -> None:
    """SIGTERM to trust-av (``timeout``, ``docker stop``); SIGHUP to its process group (the
    terminal closed)."""
    bag = tmp_path / 'term'
    proc = stoppable_run(bag)
    wait_for_steps(bag, 8, proc=proc)
    if signum == signal.SIGTERM:
        proc.send_signal(signum)
    else:
        os.killpg(proc.pid, signum)
    _out, err = proc.communicate(timeout=120)
    assert proc.returncode == 128 + signum, err
    assert err.count('\n') == 1 and f'stopped by {signal.Signals(signum).name}' in err
    assert check_bag_directory(bag) == []
    assert 0 < assert_every_topic_complete(bag) < INTERRUPTED_RUN_STEPS


def intruder(domain: int) -> subprocess.Popen[str]:
    """Another user's process on ``domain``: publishes trust -999 on the graph's topic."""
    code = ('import rclpy, time\n'
            'from geometry_msgs.msg import Vector3Stamped\n'
            'from trust_av_common.ros.qos import QOS\n'
            'rclpy.init()\n'
            "node = rclpy.create_node('intruder')\n"
            "pub = node.create_publisher(Vector3Stamped, '/trust_monitor/trust', QOS['STEP'])\n"
            'msg = Vector3Stamped(); msg.vector.z = -999.0\n'
            "print('ready', flush=True)\n"
            'while True:\n'
            '    pub.publish(msg); time.sleep(0.2)\n')
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    process = subprocess.Popen([sys.executable, '-c', code], env=env, text=True,
                               stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
    wait_ready(process)
    return process


def test_a_foreign_publisher_stops_the_run_and_a_foreign_domain_is_skipped(
        tmp_path: Path) -> None:
    """Domain 230 has someone on it: a run limited to 230-231 takes 231. Then the intruder
    moves onto 231 while the run records: the run stops with one line naming the topic and
    the node, exit 2, and the bag is finished."""
    # The run must outlast the intruder's start and its discovery (a Python process, then
    # up to one periodic participant announcement plus the watch period): a long trace,
    # recorded at least 20 ms a step (the test-only slow disk; the graph waits for it), so
    # 3000 steps take at least 60 s. Unpaced, they took 10.7 s, and on a loaded host the
    # run finished before the intruder was heard.
    env = dict(os.environ, TRUST_AV_DOMAIN_RANGE='230-231', TRUST_AV_TEST_WRITE_DELAY_S='0.02')
    trace = long_trace(tmp_path)
    first = intruder(230)
    second = None
    try:
        bag = tmp_path / 'intruded'
        proc = subprocess.Popen(run_command(bag, INTERRUPTED_RUN_STEPS, trace=str(trace)),
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                env=env)
        wait_for_steps(bag, 8, proc=proc)
        second = intruder(231)
        out, err = proc.communicate(timeout=120)
    finally:
        for process in (first, second):
            if process is not None:
                process.kill()
                process.wait()
    assert proc.returncode == 2, out + err
    assert err.count('\n') == 1, err
    assert 'foreign publisher on /trust_monitor/trust: node /intruder' in err
    assert 'domain 231' in err
    assert check_bag_directory(bag) == []              # finished (it may hold the intruder's
                                                        # messages of the last second)


def test_a_full_disk_under_a_real_run_is_one_line(small_disk: Path) -> None:
    bag = small_disk / 'run'
    proc = subprocess.run(run_command(bag), capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert proc.stderr.count('\n') == 1 and 'disk full' in proc.stderr, proc.stderr
    assert check_bag_directory(bag) == []
    # the command's marker: there unless the line says a marker did not fit (the bag's may
    # fit where the logs directory's did not)
    names = sorted(p.name for p in bag.iterdir())
    assert [n for n in names if n != MARKER] == ['metadata.yaml', 'run.mcap']
    assert MARKER in names or 'not marked' in proc.stderr, proc.stderr


@pytest.mark.parametrize('free_kb', [0, 4, 24])
def test_a_disk_full_before_the_run_is_one_line_naming_it(small_disk: Path,
                                                          free_kb: int) -> None:
    """With no room for the node logs (0 kB), or for the recorder's first bytes (4, 24 kB;
    perhaps not even for its log line): one line, exit 2, that says the disk is full, and no
    empty recording left (it was an OSError traceback, or the repair of the empty recording
    hid why)."""
    # 0 kB: until the disk refuses
    with (small_disk / 'filler').open('wb', buffering=0) as handle, \
            contextlib.suppress(OSError):
        while shutil.disk_usage(small_disk).free > free_kb * 1024:
            handle.write(b'\0' * 1024)
    bag = small_disk / 'run'
    proc = subprocess.run(run_command(bag, 20), capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    full = 'No space left on device'
    expected = ((f'{bag}.logs: cannot write the node logs and per-run parameters there '
                 f'({full}); the disk holding {bag} has only 0 kB free',
                 f'{bag}.logs: cannot write the node logs there ({full})',   # or its marker
                 # where a new directory needs a block too, the check before the run says it
                 f'{small_disk}: cannot write there (--bag {bag}: {full})') if free_kb == 0 else
                # the recorder's own line if it fitted on the disk, else its exit code's; or
                # the logs' if the command's marker in BAG.logs took the last blocks
                (f'{bag}: no room to start a recording ({full})', f'{bag}: the disk filled up',
                 f'{bag}.logs: cannot write the node logs and per-run parameters there '
                 f'({full}); the disk holding {bag} has only 0 kB free'))
    assert proc.stderr in {f'trust-av run: error: {line}\n' for line in expected}, proc.stderr
    assert not bag.exists()


def test_a_plan_without_points_in_a_recording_is_one_line(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A recorded plan that no node of the graph would publish (an empty JointTrajectory,
    e.g. from a foreign publisher the run did not catch in time) is named, not an
    IndexError; an empty expected plan stays allowed."""
    from types import SimpleNamespace as M

    from trust_av.errors import TrustAvAppError
    from trust_av.graph import bag_records

    def diagnostics(**values: str) -> M:
        return M(status=[M(values=[M(key=k, value=v) for k, v in values.items()])])

    odom = M(pose=M(pose=M(position=M(x=0.0))), twist=M(twist=M(linear=M(x=1.0))))
    plan = M(points=[M(accelerations=[0.5]), M(accelerations=[0.25])])
    step = {'preceding_vehicle/odom': odom, 'ego/odom': odom, 'human/odom': odom,
            'ego/plan': plan, 'ego/expected_plan': M(points=[]), 'human/plan': plan,
            'trust_monitor/trust': M(vector=M(x=0.1, y=0.9, z=0.2)),
            'ego/planner_status': diagnostics(gap_m='20', explicability_max='1',
                                              status='ok', success='True', iterations='3',
                                              solve_time_s='0.001'),
            'human/driver_status': diagnostics(gap_m='25', status='ok', success='True',
                                               solve_time_s='0.001')}

    def recording(human_plan: M) -> None:
        topics = {f'/car1/{name}': {2_000_000_000: msg} for name, msg in step.items()}
        topics['/car1/human/plan'] = {2_000_000_000: human_plan}
        monkeypatch.setattr(bag_records, 'read_topics', lambda _path: topics)

    recording(plan)
    [record] = bag_records.records_from_bag(tmp_path, '/car1')
    assert record.human_plan_mps2 == (0.5, 0.25) and record.expected_plan_mps2 == ()
    recording(M(points=[]))
    with pytest.raises(TrustAvAppError) as error:
        bag_records.records_from_bag(tmp_path, '/car1')
    assert str(error.value) == (f'{tmp_path}: /car1/human/plan at t = 2 s: a plan without '
                                'accelerations (not one the graph publishes: another '
                                'publisher on the topic?)')
