"""The human_driver_sim package's exception class."""

from __future__ import annotations

from trust_av_common.errors import TrustAvError

__all__ = ['HumanDriverSimError']


class HumanDriverSimError(TrustAvError):
    """Bad input to the human driver model (car-following data, a driver-fit file, driver
    parameters); the message names the file or parameter. Every other exception of this
    package derives from it."""
