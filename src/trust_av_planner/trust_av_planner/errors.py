"""The trust_av_planner package's exception class."""

from __future__ import annotations

from trust_av_common.errors import TrustAvError

__all__ = ['TrustAvPlannerError']


class TrustAvPlannerError(TrustAvError):
    """A run cannot proceed for a reason the user can act on (bad input such as a file, a node,
    a parameter or a model file; a graph that did not start or a node that died); the message
    names it. Every other exception of this package derives from it."""
