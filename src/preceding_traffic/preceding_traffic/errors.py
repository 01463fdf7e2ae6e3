"""The preceding_traffic package's exception class."""

from __future__ import annotations


class PrecedingTrafficError(ValueError):
    """A speed source (trace or bag) is unusable; the message names the file, row or message
    time and the problem. Every other exception of this package derives from it."""
