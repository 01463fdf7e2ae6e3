"""What a recording command writes, checked before anything runs.

A graph run writes three things: the bag directory ``BAG/`` (rosbag2: metadata.yaml + MCAP),
the plot ``BAG.png`` and the node logs ``BAG.logs/`` beside it. None of them may be a
symbolic link (a dangling one would be written through); an existing one is replaced only
with ``--overwrite``, and then only if it is what this command writes (a bag directory, a
file, a logs directory): an unrelated directory is never deleted.
"""

from __future__ import annotations

import os
import shutil
import stat
from dataclasses import dataclass
from pathlib import Path

from trust_av_planner.errors import TrustAvPlannerError
from trust_monitor.common.output_files import cannot_create_in


@dataclass(frozen=True)
class RunOutputs:
    """The paths a recording command writes."""

    bag: Path
    plot: Path
    logs: Path

    @classmethod
    def beside(cls, bag: Path) -> RunOutputs:
        """``BAG/``, ``BAG.png`` and ``BAG.logs/``."""
        return cls(bag, bag.with_name(bag.name + '.png'), bag.with_name(bag.name + '.logs'))


def _is_bag_directory(path: Path) -> bool:
    entries = {p.name for p in path.iterdir()}
    return not entries or 'metadata.yaml' in entries or any(
        name.endswith('.mcap') for name in entries)


def prepare_outputs(bag: Path, *, overwrite: bool, option: str = '--bag') -> RunOutputs:
    """Check (and with ``overwrite`` clear) the outputs of a recording before a run.

    Args:
        bag: the bag directory the user named.
        overwrite: whether existing outputs may be replaced.
        option: the command-line option that named ``bag``, for messages.

    Returns:
        The outputs, none of which exists any more.

    Raises:
        TrustAvPlannerError: a path is a link, exists without ``overwrite``, is something
            this command does not write, or its parent cannot be written.
    """
    if bag.suffix == '.mcap':
        raise TrustAvPlannerError(f'{option} {bag}: a recording is a rosbag2 bag directory, '
                                  f'not an .mcap file; name the directory (e.g. '
                                  f'{bag.with_suffix("")})')
    outputs = RunOutputs.beside(bag)
    for path, kind in ((outputs.bag, 'bag directory'), (outputs.plot, 'plot'),
                       (outputs.logs, 'logs directory')):
        try:
            info = os.lstat(path)
        except (FileNotFoundError, NotADirectoryError):   # checked below, with the parent
            continue
        if stat.S_ISLNK(info.st_mode):
            raise TrustAvPlannerError(f'{path}: the {kind} is a symbolic link; give a real '
                                      f'path in {option}')
        if not overwrite:
            raise TrustAvPlannerError(f'{path} exists already; pass --overwrite or choose '
                                      f'another {option}')
        is_dir = stat.S_ISDIR(info.st_mode)
        if (kind == 'plot' and is_dir) or (kind != 'plot' and not is_dir):
            raise TrustAvPlannerError(f'{path}: not a {kind}; refusing to replace it')
        if kind == 'bag directory' and not _is_bag_directory(path):
            raise TrustAvPlannerError(f'{path}: not a bag directory (no metadata.yaml or '
                                      '.mcap); refusing to replace it')
    parent = bag.parent
    ancestor = parent                        # the nearest directory that exists
    while not ancestor.exists() and ancestor != ancestor.parent:
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise TrustAvPlannerError(f'{ancestor}: not a directory ({option} {bag})')
    reason = cannot_create_in(ancestor)
    if reason is not None:
        raise TrustAvPlannerError(f'{ancestor}: cannot write there ({option} {bag}: {reason})')
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise TrustAvPlannerError(f'{parent}: cannot create it ({option} {bag}: '
                                  f'{err.strerror})') from err
    for path in (outputs.bag, outputs.logs):
        if path.is_dir():
            shutil.rmtree(path)
    outputs.plot.unlink(missing_ok=True)
    return outputs
