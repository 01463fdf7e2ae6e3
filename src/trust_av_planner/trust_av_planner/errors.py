"""The planner package's exception class: bad input that a user can fix."""

from __future__ import annotations


class TrustAvError(RuntimeError):
    """A run cannot proceed; the message names the bad input (file, node, parameter)."""
