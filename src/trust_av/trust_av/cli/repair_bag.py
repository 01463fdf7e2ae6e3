"""``trust-av repair-bag``: finish a recording left unfinished (a machine crash, a killed
recorder): every message of every complete chunk is kept, metadata.yaml is written."""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import fcntl
import os
from pathlib import Path

from trust_av.cli.typed_options import add_command, positional
from trust_av.drive.sessions import MARKER, PARTICIPANT_ID, participant_lock
from trust_av.errors import TrustAvAppError
from trust_av_common.output_lock import hold_output_lock, lock_path

__all__: list[str] = []


@dataclasses.dataclass(frozen=True)
class RepairBagOptions:
    """``trust-av repair-bag``'s options."""

    path: str = positional(metavar='PATH', help='bag directory or .mcap file')


def run(args: RepairBagOptions) -> int:
    """Run ``trust-av repair-bag``."""
    from trust_av.graph.bag_repair import repair  # rosbags: only when repairing

    raw = args.path
    if raw == '' or '\x00' in raw:
        raise TrustAvAppError(f'{raw!r}: names no bag directory or .mcap file')
    path = Path(raw)
    if path.name in ('', '.', '..'):    # `repair-bag .` inside the bag directory
        path = path.resolve()
        if path.name == '':
            raise TrustAvAppError(f'{raw}: the root directory is not a bag directory')
    if not path.exists():
        raise TrustAvAppError(f'{path}: no such bag directory or .mcap file')
    if not (path.is_dir() or path.is_file()):       # a FIFO or a device: reading would block
        raise TrustAvAppError(f'{path}: not a bag directory or a regular .mcap file')
    target = path if path.is_dir() else path.with_suffix('')
    if not path.is_dir():                # a lone .mcap: in a bag directory a run writes?
        _refuse_if_written(path.parent)
    with contextlib.ExitStack() as held:     # the locks of the run that writes the bag
        held.enter_context(hold_output_lock(target, in_use=IN_USE))
        for folder in (target.parent, target.parent.parent):
            if (folder / MARKER).is_file() and PARTICIPANT_ID.fullmatch(folder.name):
                # a drive's bag: its participant's live session records into it
                held.enter_context(participant_lock(folder.parent, folder.name))
                break
        kept = repair(path)
    print(f'{target}: repaired, {kept}; the unfinished recording was replaced once the '
          'repaired bag read back whole (mcap reader and rosbags)')
    return 0


IN_USE = ('a run is writing it or another repair-bag is repairing it; repair it once that '
          'has ended')
"""Why a recording whose lock is held is not repaired (:func:`run`)."""


def _refuse_if_written(directory: Path) -> None:
    """Refuse when a command holds the lock of ``directory`` (a bag directory a run writes;
    looked at, never created).

    Raises:
        TrustAvAppError: it does.
    """
    lock = lock_path(directory)
    try:
        fd = os.open(lock, os.O_RDONLY | os.O_NOFOLLOW | os.O_CLOEXEC)
    except OSError:          # no lock file: nobody holds it
        return
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        raise TrustAvAppError(f'{directory}: {IN_USE} (lock {lock})') from None
    finally:
        os.close(fd)


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add ``repair-bag`` to ``trust-av``."""
    parser = subparsers.add_parser(
        'repair-bag', help='finish a recording left unfinished by a crash',
        description='Rewrite a recording whose writer did not finish (a machine crash, a '
                    'killed recorder) into a complete rosbag2 bag directory, in place: every '
                    'message of every complete MCAP chunk is kept (the graph writes one chunk '
                    'per step) and metadata.yaml is written. PATH is a bag directory, or a '
                    'lone .mcap file (it becomes a bag directory of the same stem). A '
                    "recording this project wrote is cut into one chunk per step again (log "
                    "time = header stamp); another tool's keeps its log times (publish time "
                    'becomes the log time); a topic that cannot be written again (no schema, '
                    'not CDR, not a ROS 2 Jazzy type) is refused, not dropped. Attachments, '
                    'metadata records, channels without messages and unused schemas are '
                    'kept. A complete MCAP file (footer, summary and closing magic read, '
                    "every CRC valid: MCAP's own rule) is never rewritten, whoever wrote it. "
                    'The recording is replaced only once the repaired bag reads back whole '
                    'with the mcap reader and rosbags (the same messages); what was kept is '
                    'printed. A recording a run is writing, or another repair-bag is '
                    "repairing (its lock, PATH.lock, is held), or a drive's bag whose "
                    "participant has a live session, is refused. Exit codes: 0 repaired, 2 "
                    'nothing readable, no complete message, a complete recording, a recording '
                    'in use, or the copy failed (nothing is changed then).')
    add_command(parser, RepairBagOptions, run)
