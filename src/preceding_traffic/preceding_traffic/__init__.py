"""Preceding-traffic speed source: drive-cycle traces, validation, resampling and preview."""
