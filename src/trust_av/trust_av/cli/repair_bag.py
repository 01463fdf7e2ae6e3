"""``trust-av repair-bag``: finish a recording left unfinished (a machine crash, a killed
recorder): every message of every complete chunk is kept, metadata.yaml is written."""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

from trust_av.cli.typed_options import command
from trust_av.errors import TrustAvAppError

__all__: list[str] = []


@dataclasses.dataclass(frozen=True)
class RepairBagOptions:
    """``trust-av repair-bag``'s options."""

    path: str


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
    kept = repair(path)
    target = path if path.is_dir() else path.with_suffix('')
    print(f'{target}: repaired, {kept}; the unfinished recording was replaced once the '
          'repaired bag read back whole (mcap reader and rosbags)')
    return 0


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
                    "printed. Exit codes: 0 repaired, 2 nothing readable, no complete "
                    "message, a complete recording, or the copy failed (nothing is changed "
                    "then).")
    parser.add_argument('path', metavar='PATH', help='bag directory or .mcap file')
    parser.set_defaults(func=command(RepairBagOptions, run))
