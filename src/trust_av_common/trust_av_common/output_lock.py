"""One command at a time per output: a lock on an output path, taken before anything of it
is created or replaced (:func:`hold_output_lock`).

The lock is ``fcntl.flock`` on an empty lock file beside the output, ``<output>.lock`` (empty:
it takes no block of a nearly full disk); the holder's pid is the kernel's (``/proc/locks``).
The kernel releases it when the holder exits, however it exits (SIGKILL included), so a lock
file left behind never blocks anyone; the holder removes the file on a normal exit. A second
command aimed at the same output, even one started at the same instant, fails to take it at
once and is refused with one line naming the path and the holder's pid.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import time
from collections.abc import Iterator
from pathlib import Path

from trust_av_common.errors import TrustAvError
from trust_av_common.output_files import odd_path

__all__ = ['OutputLockedError', 'hold_output_lock', 'lock_path']

PID_WAIT_S = 0.2
"""How long a refused command looks for the holder's entry in the kernel's lock table."""


class OutputLockedError(TrustAvError):
    """Another process holds the lock on an output (the message names it and the pid)."""


def lock_path(output: Path) -> Path:
    """The lock file of an output: ``<output>.lock`` beside it.

    Args:
        output: the path a command writes.
    """
    return output.with_name(output.name + '.lock')


@contextlib.contextmanager
def hold_output_lock(output: Path, *,
                     in_use: str = 'another run is writing it') -> Iterator[Path | None]:
    """Hold the lock on ``output`` for the block; yields the lock file.

    Missing parent directories of ``output`` are created (and removed again on exit if they
    are still empty, so a refused command leaves nothing behind). Where the file system
    refuses them or the lock file itself (:data:`REFUSING`: not a directory, no permission,
    read-only), or where ``output`` is no name for an output (``odd_path``: a NUL, ``.``),
    no output can be written there either: the block runs without a lock (yields None) and
    the command's own output checks name the reason, as they would have without the lock.

    Args:
        output: the path a command is about to write (a bag directory, an output file).
        in_use: what the refusal says the holder does with ``output``.

    Raises:
        OutputLockedError: another process holds the lock (the line names the path and
            the holder's pid).
        TrustAvError: the lock file cannot be created for another reason (a symbolic
            link or a directory in its place, a full disk: the line names it and why).
    """
    if odd_path(output) is not None:    # no name to put a lock beside: the command's own
        yield None                      # output check refuses it in one line
        return
    path = lock_path(Path(output))
    created: list[Path] = []
    try:
        fd = _take(path, created, in_use)
        if fd is None:
            yield None
            return
        try:
            yield path
        finally:
            with contextlib.suppress(FileNotFoundError):
                path.unlink()       # still holding it: no one can take this file meanwhile
            os.close(fd)
    finally:
        for directory in reversed(created):
            with contextlib.suppress(OSError):
                directory.rmdir()   # only if empty


REFUSING = frozenset({errno.ENOTDIR, errno.ENOENT, errno.EACCES, errno.EPERM, errno.EROFS})
"""Errors of creating an entry that any output in that place would meet too."""


def _make_parents(directory: Path, created: list[Path]) -> bool:
    """Create ``directory`` and its missing parents, appending each one made to ``created``
    (outermost first); False where the file system refuses them (:data:`REFUSING`).

    Raises:
        TrustAvError: a directory cannot be created for another reason.
    """
    missing = []
    while not os.path.lexists(directory) and directory != directory.parent:
        missing.append(directory)
        directory = directory.parent
    for path in reversed(missing):
        try:
            path.mkdir()
        except FileExistsError:
            continue
        except OSError as err:
            if err.errno in REFUSING:
                return False
            raise TrustAvError(f'{path}: cannot create it ({err.strerror})') from err
        created.append(path)
    return True


def _take(path: Path, created: list[Path], in_use: str) -> int | None:
    """Create the missing parents of ``path`` (into ``created``), open and lock ``path``
    (not through a symbolic link); the open descriptor, None where the file system refuses
    them (:data:`REFUSING`).

    A lock file removed by its holder between our open and our lock is a stale name: we
    would hold a lock on a file no one else opens. So the lock counts only if ``path``
    still names the file we locked; otherwise we try again.
    """
    if not _make_parents(path.parent, created):
        return None
    while True:
        try:
            fd = os.open(path, os.O_RDONLY | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, 0o644)
        except OSError as err:
            if err.errno in REFUSING:
                return None
            reason = ('a symbolic link' if err.errno == errno.ELOOP else err.strerror)
            raise TrustAvError(f'{path}: cannot create the lock file ({reason})') \
                from err
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _holder(fd)
            os.close(fd)
            output = path.with_name(path.name[:-len('.lock')])
            raise OutputLockedError(
                f'{output}: {in_use} ({holder}; lock {path})') from None
        except OSError as err:
            os.close(fd)
            raise TrustAvError(f'{path}: cannot lock it ({err.strerror})') from err
        try:
            same = os.stat(path, follow_symlinks=False).st_ino == os.fstat(fd).st_ino
        except FileNotFoundError:
            same = False
        if same:
            return fd
        os.close(fd)


def _holder(fd: int, locks: Path = Path('/proc/locks')) -> str:
    """'pid N' of the process holding the flock on the open file ``fd``, from the kernel's
    table of locks (``/proc/locks``: ``1: FLOCK ADVISORY WRITE <pid> <major>:<minor>:<inode>
    0 EOF``, device numbers in hex); 'pid unknown' if it is not there (gone meanwhile)."""
    info = os.fstat(fd)
    key = f'{os.major(info.st_dev):02x}:{os.minor(info.st_dev):02x}:{info.st_ino}'
    deadline = time.monotonic() + PID_WAIT_S
    while True:
        try:
            table = locks.read_text()
        except OSError:
            return 'pid unknown'
        for line in table.splitlines():
            fields = line.split()
            if len(fields) >= 6 and fields[1] == 'FLOCK' and fields[5] == key:
                return f'pid {fields[4]}'
        if time.monotonic() >= deadline:
            return 'pid unknown'
        time.sleep(0.02)
