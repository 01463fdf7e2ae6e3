"""What a recording command writes, checked before anything runs, replaced only when proven
its own and only once the new outputs are complete.

A graph run writes three things: the bag directory ``BAG/`` (rosbag2: metadata.yaml + MCAP),
the plot ``BAG.png`` and the node logs ``BAG.logs/`` beside it. None of them may be a
symbolic link (a dangling one would be written through). Each directory the command writes
gets a marker file, :data:`MARKER` (the command, its pid, the time and the names of the
outputs it wrote), written by the command itself; the plot is named in the markers of its
bag and logs. An existing output is replaced only with ``--overwrite`` and only if such a
marker proves it was written here: a directory that merely looks like a bag (a
``metadata.yaml``, an ``.mcap``, nothing at all) is a user's and is refused.

Replacing is in three moves (:func:`replacing_outputs`): the previous outputs are renamed
to hidden siblings (``.NAME.replaced-PID``) before the run; on success they are deleted; on
any failure or stop they are renamed back, and what the failed run wrote is kept beside
them as ``BAG.incomplete`` (``.png``, ``.logs``) rather than lost.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import stat
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import yaml

from trust_av.errors import TrustAvAppError
from trust_av_common import output_files
from trust_av_common.errors import TrustAvError
from trust_av_common.output_files import cannot_create_in, odd_path, stop_signals_held
from trust_av_common.output_lock import hold_output_lock

__all__ = ['MARKER', 'RunOutputs', 'marked_outputs', 'prepare_outputs', 'replacing_outputs']

MARKER = '.trust_av_output'
"""The marker file a command writes into each output directory it creates."""


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

    def paths(self) -> tuple[Path, Path, Path]:
        """The bag, the plot and the logs."""
        return self.bag, self.plot, self.logs


def write_marker(directory: Path, command: str, names: list[str]) -> None:
    """Mark ``directory`` as written by ``trust-av COMMAND`` (whole or not at all).

    Args:
        directory: an output directory the command created.
        command: the subcommand, e.g. ``run``.
        names: the outputs it wrote (file names beside ``directory``, itself included).

    Raises:
        OutputFileError: the marker cannot be written (one line naming it).
    """
    output_files.write_text(directory / MARKER, yaml.safe_dump({
        'command': f'trust-av {command}', 'pid': os.getpid(),
        'time': time.strftime('%Y-%m-%dT%H:%M:%SZ', time.gmtime()), 'outputs': names},
        sort_keys=False))


def marked_outputs(directory: Path) -> list[str] | None:
    """The outputs the marker in ``directory`` names, or ``None`` without a marker (none,
    not a regular file, unreadable or not ours)."""
    marker = directory / MARKER
    try:
        if not stat.S_ISREG(os.lstat(marker).st_mode):
            return None
        document = yaml.safe_load(marker.read_text(errors='replace'))
    except (OSError, yaml.YAMLError):
        return None
    if not (isinstance(document, dict) and str(document.get('command', '')).startswith(
            'trust-av ') and isinstance(document.get('outputs'), list)):
        return None
    return [str(name) for name in document['outputs']]


def _ours(path: Path, kind: str, outputs: RunOutputs) -> bool:
    """Whether the existing ``path`` is proven this project's output by a marker."""
    if kind == 'plot':
        return any(path.name in (marked_outputs(directory) or [])
                   for directory in (outputs.bag, outputs.logs)
                   if directory.is_dir() and not directory.is_symlink())
    return path.name in (marked_outputs(path) or [])


def hidden_leftovers(path: Path) -> list[Path]:
    """Previous outputs of ``path`` an earlier ``--overwrite`` run moved aside and, killed,
    never put back or deleted."""
    return sorted(path.parent.glob(f'.{path.name}.replaced-*')) if path.parent.is_dir() else []


def prepare_outputs(bag: Path, *, overwrite: bool, option: str = '--bag') -> RunOutputs:
    """Check the outputs of a recording before a run; nothing is changed.

    Args:
        bag: the bag directory the user named.
        overwrite: whether existing outputs may be replaced.
        option: the command-line option that named ``bag``, for messages.

    Returns:
        The outputs (some may exist: only with ``overwrite`` and proven ours).

    Raises:
        TrustAvAppError: an odd path (:func:`~trust_av_common.output_files.odd_path`:
            a NUL or newline in it, ``.``), a path is a link, exists without ``overwrite``, is
            not proven
            written by this project (no marker), is left over from a killed ``--overwrite``
            run, or its parent cannot be written.
    """
    odd = odd_path(bag)
    if odd is not None:
        raise TrustAvAppError(f'{option} {str(bag)!r}: {odd}')
    if bag.suffix == '.mcap':
        raise TrustAvAppError(f'{option} {bag}: a recording is a rosbag2 bag directory, '
                              f'not an .mcap file; name the directory (e.g. '
                              f'{bag.with_suffix("")})')
    outputs = RunOutputs.beside(bag)
    for path, kind in zip(outputs.paths(), ('bag directory', 'plot', 'logs directory'),
                          strict=True):
        for leftover in hidden_leftovers(path):
            raise TrustAvAppError(f'{leftover}: the previous {kind} kept by an '
                                  f'--overwrite run that did not finish; move it back to '
                                  f'{path} (or away) first')
        try:
            info = os.lstat(path)
        except (FileNotFoundError, NotADirectoryError):   # checked below, with the parent
            continue
        if stat.S_ISLNK(info.st_mode):
            raise TrustAvAppError(f'{path}: the {kind} is a symbolic link; give a real '
                                  f'path in {option}')
        if not overwrite:
            raise TrustAvAppError(f'{path} exists already; pass --overwrite or choose '
                                  f'another {option}')
        is_dir = stat.S_ISDIR(info.st_mode)
        if (kind == 'plot' and not stat.S_ISREG(info.st_mode)) or (kind != 'plot'
                                                                  and not is_dir):
            raise TrustAvAppError(f'{path}: not a {kind}; refusing to replace it')
        if not _ours(path, kind, outputs):
            raise TrustAvAppError(
                f'{path}: not written by trust-av (no {MARKER} marker naming it); '
                'refusing to replace it, move it away or choose another ' + option)
    parent = bag.parent
    ancestor = parent                        # the nearest directory that exists
    while not ancestor.exists() and ancestor != ancestor.parent:
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise TrustAvAppError(f'{ancestor}: not a directory ({option} {bag})')
    reason = cannot_create_in(ancestor)
    if reason is not None:
        raise TrustAvAppError(f'{ancestor}: cannot write there ({option} {bag}: {reason})')
    return outputs


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    else:
        path.unlink(missing_ok=True)


def _mark(outputs: RunOutputs, command: str) -> None:
    """Markers in the bag and logs directories naming every output that exists.

    Raises:
        OutputFileError: a marker cannot be written.
    """
    names = [p.name for p in outputs.paths() if os.path.lexists(p)]
    for directory in (outputs.bag, outputs.logs):
        if directory.is_dir() and marked_outputs(directory) != names:
            write_marker(directory, command, names)


def _remove_if_unused(logs: Path) -> None:
    """Remove the logs directory this command created if nothing but its marker is in it
    (a run refused before any node started leaves nothing behind)."""
    if logs.is_dir() and not logs.is_symlink() and [p.name for p in logs.iterdir()] == [MARKER]:
        shutil.rmtree(logs)


def _mark_after_failure(outputs: RunOutputs, command: str) -> str:
    """:func:`_mark` after a failed run: ``''``, or why the markers could not be written
    (``'; ...'``, for its error line; a full disk is the usual reason)."""
    try:
        _mark(outputs, command)
    except output_files.OutputFileError as err:
        return f"; the outputs are not marked as trust-av's ({err})"
    return ''


def _free_name(path: Path) -> Path:
    """``path``, or ``path`` with ``-2``, ``-3``, ... if that (or one of its siblings) is
    taken."""
    candidate, number = path, 1
    while any(os.path.lexists(p) for p in RunOutputs.beside(candidate).paths()):
        number += 1
        candidate = path.with_name(f'{path.name}-{number}')
    return candidate


@contextlib.contextmanager
def replacing_outputs(bag: Path, *, overwrite: bool, command: str,
                      option: str = '--bag') -> Iterator[RunOutputs]:
    """The outputs for the block to write (:func:`_replacing_outputs`), with the lock on
    ``bag`` held throughout (:func:`~trust_av_common.output_lock.hold_output_lock`): a
    second command aimed at the same outputs is refused before either writes.

    Raises:
        TrustAvAppError: as :func:`_replacing_outputs`.
        OutputLockedError: another command holds the lock (the line names it).
    """
    with hold_output_lock(bag), _replacing_outputs(bag, overwrite=overwrite, command=command,
                                                   option=option) as outputs:
        yield outputs


@contextlib.contextmanager
def _replacing_outputs(bag: Path, *, overwrite: bool, command: str,
                       option: str = '--bag') -> Iterator[RunOutputs]:
    """:func:`prepare_outputs`, then the outputs for the block to write, with the previous
    ones put back unless it ends normally.

    The logs directory is created (with its marker) before the block; after it, the bag
    and logs directories get markers naming every output written. Previous outputs (only
    with ``overwrite``, only proven ours) are renamed to hidden siblings first; when the
    block ends normally they are deleted; when it raises (a failure, a stop) they are
    renamed back and what the block wrote is moved to ``BAG.incomplete`` (``.png``,
    ``.logs``; ``-2``, ... if taken), named in the error line of a failure.

    Args:
        bag: the bag directory the user named.
        overwrite: whether existing outputs may be replaced.
        command: the subcommand, for the markers.
        option: the option that named ``bag``, for messages.

    Raises:
        TrustAvAppError: as :func:`prepare_outputs`; an output cannot be moved aside
            or the logs directory cannot be created (nothing is changed then).
    """
    outputs = prepare_outputs(bag, overwrite=overwrite, option=option)
    aside: list[tuple[Path, Path]] = []
    try:
        outputs.bag.parent.mkdir(parents=True, exist_ok=True)
        with stop_signals_held():
            for path in outputs.paths():
                if os.path.lexists(path):
                    hidden = path.with_name(f'.{path.name}.replaced-{os.getpid()}')
                    os.rename(path, hidden)
                    aside.append((path, hidden))
        outputs.logs.mkdir()
        write_marker(outputs.logs, command, [outputs.logs.name])
    except (OSError, output_files.OutputFileError) as err:
        if outputs.logs.is_dir():
            shutil.rmtree(outputs.logs)
        _put_back(outputs, aside)
        cause = err.__cause__ if isinstance(err, output_files.OutputFileError) else err
        reason = cause.strerror if isinstance(cause, OSError) else str(err)
        raise TrustAvAppError(f'{outputs.logs}: cannot write the node logs there '
                              f'({reason})') from err
    try:
        yield outputs
    except TrustAvError as err:
        _remove_if_unused(outputs.logs)
        unmarked = _mark_after_failure(outputs, command)
        moved = _put_back(outputs, aside)
        if not moved and not unmarked:
            raise
        raise TrustAvAppError(
            f'{err}' + ("; the previous outputs are back in place, this run's were moved to "
                        + ', '.join(str(p) for p in moved) if moved else '') + unmarked) from err
    except BaseException:
        # A stop (or a bug): its own line or traceback is what is printed; a bag the
        # marker could not be written into is left unmarked (never replaced by --overwrite).
        _remove_if_unused(outputs.logs)
        _mark_after_failure(outputs, command)
        _put_back(outputs, aside)
        raise
    with stop_signals_held():           # a stop here would leave both sets behind
        try:
            _mark(outputs, command)
        finally:                        # the new outputs are complete either way
            for _, hidden in aside:
                _remove(hidden)


def _put_back(outputs: RunOutputs, aside: list[tuple[Path, Path]]) -> list[Path]:
    """Rename the previous outputs back; what the run wrote goes to ``BAG.incomplete``
    (``.png``, ``.logs``) first. Returns where it went (empty when nothing was aside)."""
    moved: list[Path] = []
    if not aside:
        return moved
    with stop_signals_held():
        kept = _free_name(outputs.bag.with_name(outputs.bag.name + '.incomplete'))
        for path, new in zip(outputs.paths(), RunOutputs.beside(kept).paths(), strict=True):
            if os.path.lexists(path):
                os.rename(path, new)
                moved.append(new)
        for path, hidden in aside:
            os.rename(hidden, path)
    return moved
