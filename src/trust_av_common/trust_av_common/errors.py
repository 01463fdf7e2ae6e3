"""The one exception base of every trust-av package, and the one-line message helpers.

Every exception the project raises for a reason the user can act on derives from
:class:`TrustAvError` (directly, or through a package's own base:
:class:`~trust_monitor.errors.TrustMonitorError`,
:class:`~preceding_traffic.errors.PrecedingTrafficError`,
:class:`~human_driver_sim.errors.HumanDriverSimError`,
:class:`~trust_av_planner.errors.TrustAvPlannerError`,
:class:`~trust_av.errors.TrustAvAppError`), so a command catches one class and prints one line
(:func:`one_line`).
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable

__all__ = ['TrustAvError', 'did_you_mean', 'one_line', 'with_suggestions']


class TrustAvError(ValueError):
    """Bad input or a run that cannot proceed, for a reason the user can act on (a params
    file, a parameter value, a data file, a node that died); the message names it. Every
    other exception of the project derives from it. A ``ValueError``, as the packages' bases
    always were."""


def one_line(err: BaseException) -> str:
    """``err``'s message as the one line a command prints: the lines of a multi-line message
    (a YAML parser's caret diagram, say, passed on inside ours) joined with single spaces."""
    return ' '.join(' '.join(line.split()) for line in str(err).splitlines() if line.strip()) \
        or type(err).__name__


def did_you_mean(name: object, known: Iterable[object]) -> str:
    """``" (did you mean 'x'?)"`` naming the known names closest to a mistyped ``name``
    (:func:`difflib.get_close_matches`, at most three, best first), or ``''`` when none is
    close. Appended to the one line that refuses an unknown name."""
    close = difflib.get_close_matches(str(name), [str(k) for k in known], n=3, cutoff=0.6)
    if not close:
        return ''
    return f' (did you mean {" or ".join(repr(c) for c in close)}?)'


def with_suggestions(unknown: Iterable[object], known: Iterable[object]) -> str:
    """``unknown`` names, comma-separated, each followed by :func:`did_you_mean` from
    ``known``: ``"predictr (did you mean 'predictor'?), foo"``."""
    known = [str(k) for k in known]
    return ', '.join(f'{name}{did_you_mean(name, known)}' for name in unknown)
