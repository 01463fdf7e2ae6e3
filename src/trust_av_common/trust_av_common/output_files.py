"""Output files written whole or not at all.

A command that writes its result straight to the named file leaves a truncated file that
looks finished when it is stopped half-way (SIGINT, SIGTERM, a kill) or the disk fills up,
and it has already destroyed the file it was replacing; ``train-gru`` and ``fit-driver``
replace the shipped model files by default. :func:`replacing` lets the caller write
temporary files beside the targets and renames them over the targets only when every one
is complete and on disk (``os.replace`` is atomic within a file system, POSIX
``rename(2)``).

A symbolic link is never written through (:func:`link_refused`): a link planted in a shared
directory would redirect the write to whatever it names, so it is refused in one line, as
bag, log and plot paths are. Only the system's names for open files and devices
(``/dev/stdout``, ``/dev/fd/1``, ``/proc/self/fd/1``: links under ``/dev`` and ``/proc``)
are followed.
"""

from __future__ import annotations

import contextlib
import os
import stat
import tempfile
from collections.abc import Iterator
from pathlib import Path

from trust_av_common.errors import TrustAvError
from trust_av_common.held_stops import STOP_SIGNALS, held

__all__ = ['HELD_SIGNALS', 'OutputFileError', 'cannot_create_in', 'cannot_write', 'link_refused',
           'odd_path', 'replacing', 'stop_signals_held', 'write_text']

HELD_SIGNALS = set(STOP_SIGNALS)
"""Held back while a set of files is renamed into place, so a stop cannot split the set."""


class OutputFileError(TrustAvError):
    """An output file could not be written (the message names it and the reason); the
    file that was there before is unchanged and no temporary file is left."""


def _mode_for(path: Path) -> int:
    """The replaced file's permissions, or what a new file gets under the umask (a
    temporary file is created 0600)."""
    try:
        return os.stat(path).st_mode & 0o7777
    except FileNotFoundError:
        umask = os.umask(0)
        os.umask(umask)
        return 0o666 & ~umask


@contextlib.contextmanager
def stop_signals_held() -> Iterator[None]:
    """SIGINT, SIGTERM and SIGHUP wait until the block is done, then run their handlers
    (:func:`~trust_av_common.held_stops.held`). For a few renames, not for work.

    Blocking them for the main thread did not hold them: another thread (torch's, rclpy's,
    a worker pool's) took the signal, and Python ran the handler in the main thread at its
    next bytecode."""
    with held(STOP_SIGNALS):
        yield


def _system_name(path: Path) -> bool:
    """A name under ``/dev`` or ``/proc``: the system's names for devices and open files
    (``/dev/stdout`` is a link to ``/proc/self/fd/1``)."""
    parts = Path(os.path.abspath(path)).parts
    return len(parts) > 1 and parts[1] in ('dev', 'proc')


def link_refused(path: Path) -> str | None:
    """Why ``path`` is refused as an output because it is a symbolic link, or ``None``:
    a link (dangling or not) outside ``/dev`` and ``/proc`` would redirect the write to
    what it names. Only the last component counts, as for bag directories (a linked parent
    directory is the user's own choice of where to write)."""
    if not os.path.islink(path) or _system_name(path):
        return None
    return (f'a symbolic link (to {os.readlink(path)}); refusing to write through it, '
            'give the real path')


def _target(path: Path) -> Path:
    """Where writing ``path`` lands: the path itself, or a system name's target
    (``/dev/stdout`` redirected to a regular file is that file)."""
    return Path(os.path.realpath(path)) if path.is_symlink() else path


def _is_special(path: Path) -> bool:
    """An existing file that is not a regular file (``/dev/stdout``, a FIFO, a device):
    written in place, since renaming over it would replace the device itself."""
    try:
        return not stat.S_ISREG(os.stat(path).st_mode)
    except FileNotFoundError:
        return False


@contextlib.contextmanager
def replacing(*paths: Path) -> Iterator[tuple[Path, ...]]:
    """Temporary files beside ``paths`` (same suffixes) for the block to write.

    When the block ends normally, each temporary file is flushed to disk and renamed over
    its path, with the stop signals (:data:`HELD_SIGNALS`) held back from the first rename
    to the last (a stop then acts right after the whole set is in place). When the block
    raises, or writing fails, the temporary files are removed and every path keeps what it
    had. A symbolic link is refused (:func:`link_refused`; only ``/dev/stdout`` and the
    like are followed); a path that exists and is not a regular file (``/dev/stdout``, a
    FIFO) is handed to the block itself.

    Raises:
        OutputFileError: a path is a symbolic link (nothing is written), or a file could not
            be created, written or renamed (a full disk, no permission, a missing directory
            that cannot be made); one line naming it.
    """
    for path in paths:
        refused = link_refused(Path(path))
        if refused is not None:
            raise OutputFileError(f'{path}: {refused}')
    # a special file is written through the name given (/dev/stdout -> a pipe has no path)
    targets = [Path(path) if _is_special(Path(path)) else _target(Path(path)) for path in paths]
    temporaries: dict[Path, Path] = {}      # target -> its temporary file
    try:
        try:
            for target in targets:
                if _is_special(target):
                    continue
                target.parent.mkdir(parents=True, exist_ok=True)
                handle, name = tempfile.mkstemp(dir=target.parent, prefix=f'.{target.name}.',
                                                suffix=f'.tmp{target.suffix}')
                os.close(handle)
                temporaries[target] = Path(name)
                os.chmod(name, _mode_for(target))
            yield tuple(temporaries.get(target, target) for target in targets)
            for temporary in temporaries.values():
                with open(temporary, 'rb+') as handle_:
                    os.fsync(handle_.fileno())
            with stop_signals_held():
                for target, temporary in temporaries.items():
                    os.replace(temporary, target)
        except OSError as err:
            names = ', '.join(str(p) for p in paths)
            raise OutputFileError(f'{names}: cannot write ({err.strerror or err})') from err
    finally:
        for temporary in temporaries.values():
            temporary.unlink(missing_ok=True)


def write_text(path: Path, text: str) -> None:
    """``path.write_text(text)``, whole or not at all (:func:`replacing`)."""
    with replacing(path) as (temporary,):
        temporary.write_text(text)


def odd_path(path: str | Path) -> str | None:
    """Why ``path`` is no name for an output, or ``None``: a NUL (no system call takes it),
    a newline or another control character (a file name that breaks every listing and log
    line), or no name at all (``.``, ``..``, ``/``, empty).

    Args:
        path: an output path as the user gave it.
    """
    text = str(path)
    if '\x00' in text:
        return 'the path holds a NUL character'
    if any(ord(char) < 32 or ord(char) == 127 for char in text):
        return 'the path holds a newline or another control character'
    if Path(text).name in ('', '.', '..'):
        return 'names no file or directory of its own (., .., / or empty)'
    return None


def cannot_write(path: Path, directory: Path) -> str | None:
    """Why the output file ``path`` cannot be written, or ``None`` if it can. ``directory`` is
    where it goes (its nearest existing ancestor): a regular file (new or replaced) is
    created there (:func:`replacing`), while a device or FIFO is written in place; a
    symbolic link is refused (:func:`link_refused`)."""
    refused = link_refused(path)
    if refused is not None:
        return refused
    if path.exists() and not path.is_file():
        return None if os.access(path, os.W_OK) else 'not writable'
    reason = cannot_create_in(directory)
    return None if reason is None else f'cannot write in directory {directory} ({reason})'


def cannot_create_in(directory: Path) -> str | None:
    """Why nothing can be created in the existing ``directory``, or ``None`` if it can:
    tried by creating and removing an empty directory there. ``os.access`` answers for
    permission bits only: root passes it everywhere, and a file system such as /proc
    refuses the entry itself."""
    try:
        os.rmdir(tempfile.mkdtemp(prefix='.writable-', dir=directory))
    except OSError as err:
        return err.strerror or type(err).__name__
    return None
