"""The trust_monitor package's exception class."""

from __future__ import annotations


class TrustMonitorError(ValueError):
    """Bad input to the trust monitor or the shared floor (a params file, a parameter value,
    a plans CSV); the message names the file, parameter or row. Every other exception of
    this package derives from it."""


def one_line(err: BaseException) -> str:
    """``err``'s message as the one line a command prints: the lines of a multi-line message
    (a YAML parser's caret diagram, say, passed on inside ours) joined with single spaces."""
    return ' '.join(' '.join(line.split()) for line in str(err).splitlines() if line.strip()) \
        or type(err).__name__
