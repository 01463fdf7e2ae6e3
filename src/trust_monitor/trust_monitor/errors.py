"""The trust_monitor package's exception class.

The message helpers that lived here (``one_line``, ``did_you_mean``, ``with_suggestions``)
are :mod:`trust_av_common.errors`'s; importing them from here still works for one release
and warns.
"""

from __future__ import annotations

import warnings
from typing import Any

from trust_av_common import errors as _common
from trust_av_common.errors import TrustAvError
from trust_av_common.moved import MovedPathWarning

__all__ = ['TrustMonitorError']

_MOVED = ('one_line', 'did_you_mean', 'with_suggestions')


class TrustMonitorError(TrustAvError):
    """Bad input to the trust monitor (a plans CSV, a trust model's parameters, a ratings
    table); the message names the file, parameter or row. Every other exception of this
    package derives from it."""


def __getattr__(name: str) -> Any:
    if name in _MOVED:
        warnings.warn(f'trust_monitor.errors.{name} moved to trust_av_common.errors.{name}; '
                      'the old name goes in the next release', MovedPathWarning, stacklevel=2)
        return getattr(_common, name)
    raise AttributeError(f'module {__name__!r} has no attribute {name!r}')
