"""A folder of results written as one set: all of its files or none, never over anyone
else's.

``trust-av fit-trust --out DIR`` and ``trust-av reproduce --results-dir DIR`` write many
files into one folder. :func:`writing_set` gives the command a new, hidden sibling folder
(``.DIR.new-PID``) to write into; when the command ends normally the folder gets its
marker (:data:`~trust_av.system.outputs.MARKER`: the command line, its pid, the time and
every name in the set) and takes DIR's place (the previous set, if any, is renamed aside
first and deleted after; the stop signals are held over the renames). When it fails or is
stopped, the new folder is deleted and DIR keeps the previous complete set (or stays absent).

Before anything is written, DIR is checked: not a symbolic link, a folder, and either empty
or holding exactly what a marker of a trust-av command names (a folder with any other file
in it is the user's and is refused, its files named). A command's work folders (``keep``:
reproduce's resumable ``cache/`` and ``graph_bags/``) live in DIR itself, are named in its
marker and are carried into the new set. Two commands aimed at one DIR at once: the second
is refused (:func:`~trust_av_common.output_lock.hold_output_lock`).
"""

from __future__ import annotations

import contextlib
import os
import shutil
import stat
import sys
from collections.abc import Iterator, Sequence
from pathlib import Path

from trust_av.errors import TrustAvAppError
from trust_av.system.outputs import MARKER, marked_outputs, write_marker
from trust_av_common import output_files
from trust_av_common.output_files import cannot_create_in, odd_path, stop_signals_held
from trust_av_common.output_lock import hold_output_lock

__all__ = ['check_set_folder', 'writing_set']


def _shown(names: Sequence[str]) -> str:
    listed = ', '.join(sorted(names)[:3])
    return listed + (f' and {len(names) - 3} more' if len(names) > 3 else '')


def check_set_folder(out: Path, *, option: str = '--out',
                     keep: Sequence[str] = ()) -> bool:
    """Check ``out`` before a command writes a set there; nothing is changed.

    Args:
        out: the results folder.
        option: the option that named it, for messages.
        keep: the command's work folders allowed in it unnamed by a marker.

    Returns:
        Whether ``out`` exists (empty, or holding a set proven ours).

    Raises:
        TrustAvAppError: an odd path, a symbolic link, not a folder, a folder with files
            no trust-av marker names (or without a marker), a previous set left aside by a
            stopped run, or a parent that cannot be written.
    """
    odd = odd_path(out)
    if odd is not None:
        raise TrustAvAppError(f'{option} {str(out)!r}: {odd}')
    for leftover in sorted(out.parent.glob(f'.{out.name}.replaced-*')) \
            if out.parent.is_dir() else []:
        raise TrustAvAppError(f'{leftover}: the previous results of a run that was stopped '
                                  f'while replacing them; move it back to {out} (or away) '
                                  'first')
    try:
        info = os.lstat(out)
    except (FileNotFoundError, NotADirectoryError):
        ancestor = out.parent
        while not ancestor.exists() and ancestor != ancestor.parent:
            ancestor = ancestor.parent
        if not ancestor.is_dir():
            raise TrustAvAppError(f'{option} {out}: cannot create it (Not a directory)') \
                from None
        reason = cannot_create_in(ancestor)
        if reason is not None:
            raise TrustAvAppError(f'{option} {out}: cannot write in {ancestor} ({reason})') \
                from None
        return False
    if stat.S_ISLNK(info.st_mode):
        raise TrustAvAppError(f'{option} {out}: a symbolic link (to {os.readlink(out)}); '
                                  'refusing to write through it, give the real path')
    if not stat.S_ISDIR(info.st_mode):
        raise TrustAvAppError(f'{option} {out}: exists and is not a directory')
    present = sorted(p.name for p in out.iterdir())
    if not present:
        return True
    named = marked_outputs(out)
    if named is None:
        raise TrustAvAppError(
            f'{option} {out}: holds files trust-av did not write ({_shown(present)}; no '
            f'{MARKER} marker); refusing to replace them, choose another {option}')
    foreign = [n for n in present if n not in (*named, MARKER, *keep)]
    if foreign:
        raise TrustAvAppError(
            f'{option} {out}: holds files its {MARKER} marker does not name '
            f'({_shown(foreign)}); refusing to replace them, move them away or choose '
            f'another {option}')
    reason = cannot_create_in(out.parent)
    if reason is not None:
        raise TrustAvAppError(f'{option} {out}: cannot write in {out.parent} ({reason})')
    return True


def _command_line(command: str) -> str:
    """The command as run (for the marker), e.g. ``fit-trust --ratings r.csv --out o``."""
    argv = sys.argv[1:]
    return ' '.join(argv) if argv and command in argv else command


@contextlib.contextmanager
def writing_set(out: Path, *, command: str, option: str = '--out',
                keep: Sequence[str] = ()) -> Iterator[Path]:
    """A new folder for the block to write the set into; it becomes ``out`` when the block
    ends normally, and is deleted when it raises (module docstring).

    Args:
        out: the results folder.
        command: the subcommand, for the marker.
        option: the option that named ``out``, for messages.
        keep: work folders of the command inside ``out`` (created if missing, with a
            marker, before the block), carried over into the new set.

    Raises:
        TrustAvAppError: as :func:`check_set_folder`; the new set cannot be written or
            put in place (one line; the previous set is then kept).
        OutputLockedError: another command writes ``out`` now.
    """
    with hold_output_lock(out):
        exists = check_set_folder(out, option=option, keep=keep)
        if keep and not (exists and any(out.iterdir())):  # the work folders' home, marked
            _make(out, command, option)                   # ours (a stopped run resumes)
            exists = True
        new = out.with_name(f'.{out.name}.new-{os.getpid()}')
        try:
            shutil.rmtree(new, ignore_errors=True)
            new.mkdir(parents=True)
        except OSError as err:
            raise TrustAvAppError(f'{option} {out}: cannot create {new} '
                                      f'({err.strerror})') from err
        try:
            yield new
            names = sorted({p.name for p in new.iterdir()} | set(keep))
            write_marker(new, _command_line(command), names)
        except BaseException:
            shutil.rmtree(new, ignore_errors=True)
            raise
        _publish(out, new, exists, keep, option)


def _make(out: Path, command: str, option: str) -> None:
    try:
        out.mkdir(parents=True, exist_ok=True)
        write_marker(out, _command_line(command), [])
    except (OSError, output_files.OutputFileError) as err:
        raise TrustAvAppError(f'{option} {out}: cannot create it ({err})') from err


def _publish(out: Path, new: Path, exists: bool, keep: Sequence[str], option: str) -> None:
    """``new`` in the place of ``out``: the work folders moved in, the previous set aside
    and deleted, all with the stop signals held."""
    old = out.with_name(f'.{out.name}.replaced-{os.getpid()}')
    try:
        with stop_signals_held():
            for name in keep:
                if (out / name).is_dir() and not (out / name).is_symlink():
                    os.rename(out / name, new / name)
            if exists and any(out.iterdir()):
                os.rename(out, old)
            os.replace(new, out)            # an empty folder in its place is replaced
    except OSError as err:
        for name in keep:                   # put the work folders back
            if (new / name).is_dir() and os.path.isdir(out):
                os.rename(new / name, out / name)
        if old.exists() and not out.exists():
            os.rename(old, out)
        shutil.rmtree(new, ignore_errors=True)
        raise TrustAvAppError(f'{option} {out}: cannot put the new results in place '
                                  f'({err.strerror}); the previous ones are kept') from err
    shutil.rmtree(old, ignore_errors=True)
