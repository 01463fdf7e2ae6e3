"""The preceding_traffic package's exception class."""

from __future__ import annotations

from trust_av_common.errors import TrustAvError

__all__ = ['PrecedingTrafficError']


class PrecedingTrafficError(TrustAvError):
    """A speed source (trace or bag) is unusable; the message names the file, row or message
    time and the problem. Every other exception of this package derives from it."""
