"""The trust_monitor package's exception class."""

from __future__ import annotations


class TrustMonitorError(ValueError):
    """Bad input to the trust monitor or the shared floor (a params file, a parameter value,
    a plans CSV); the message names the file, parameter or row. Every other exception of
    this package derives from it."""
