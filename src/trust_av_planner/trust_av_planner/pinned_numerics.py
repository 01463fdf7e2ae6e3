"""Pinned floating-point numerics for GRU training (issue 14, item 1): skeleton.

The environment of the training child process is built here; see docs/GRU.md.
"""

from __future__ import annotations
