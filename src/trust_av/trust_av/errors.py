"""The trust_av package's exception class: the application's own failures."""

from __future__ import annotations

from trust_av_common.errors import TrustAvError

__all__ = ['TrustAvAppError']


class TrustAvAppError(TrustAvError):
    """A run of the application cannot proceed for a reason the user can act on (a command's
    option, an output path, a bag, a graph that did not start or a node that died, a drive's
    session); the message names it. Every other exception of this package derives from it."""
