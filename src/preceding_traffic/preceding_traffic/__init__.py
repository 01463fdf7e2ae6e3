"""Preceding-traffic speed source: drive-cycle traces, validation, resampling and preview."""

__all__: list[str] = []

