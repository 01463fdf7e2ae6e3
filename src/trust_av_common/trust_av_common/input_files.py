"""Input files are looked at before they are opened.

Opening a FIFO for reading blocks until something writes to it, and a directory or a device
is no params file, trace or estimator input either: a command that opened first and checked
afterwards (``fstat`` on the open handle) hung on a FIFO. :func:`not_regular` answers from
``os.stat`` without opening.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

__all__ = ['not_regular']


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
