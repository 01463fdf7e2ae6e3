"""Input files are looked at before they are opened.

Opening a FIFO for reading blocks until something writes to it, and a directory or a device
is no params file, trace or estimator input either: a command that opened first and checked
afterwards (``fstat`` on the open handle) hung on a FIFO. :func:`not_regular` answers from
``os.stat`` without opening. And an open text file is read a bounded line at a time
(:func:`bounded_lines`): a file of one endless line is refused, never read whole.
"""

from __future__ import annotations

import os
import stat
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TextIO

__all__ = ['bounded_lines', 'not_regular']


def not_regular(path: str | Path) -> str | None:
    """What ``path`` is if it exists and is not a regular file (``'a FIFO'``, ``'a
    directory'``, ...), else ``None`` (a regular file, or nothing there: opening it then
    says why). Symbolic links are followed.

    Args:
        path: the input file.
    """
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return None
    if stat.S_ISREG(mode):
        return None
    for test, kind in ((stat.S_ISDIR, 'a directory'), (stat.S_ISFIFO, 'a FIFO'),
                       (stat.S_ISCHR, 'a character device'), (stat.S_ISBLK, 'a block device'),
                       (stat.S_ISSOCK, 'a socket')):
        if test(mode):
            return kind
    return 'not a regular file'


def bounded_lines(handle: TextIO, path: Path, max_chars: int, error: Callable[[str], Exception],
                  what: str = '') -> Iterator[str]:
    """The text lines of an open input file, each at most ``max_chars`` long (a longer one
    is not read on).

    Args:
        handle: the open file.
        path: its name, for the message.
        max_chars: the longest line allowed.
        error: the exception class of the caller's package, raised with one line
            ``PATH:LINE: line longer than N characters`` and ``what``.
        what: what the file is not, appended to the message (``' (not a CSV)'``).
    """
    number = 0
    while True:
        line = handle.readline(max_chars + 1)
        if not line:
            return
        number += 1
        if len(line) > max_chars:
            raise error(f'{path}:{number}: line longer than {max_chars} characters{what}')
        yield line
