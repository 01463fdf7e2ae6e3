"""Where the repository and the suite are, wherever a test module sits in ``tests/``."""

from __future__ import annotations

from pathlib import Path

TESTS = Path(__file__).resolve().parents[1]
"""The suite's directory, ``tests/``."""
REPO = TESTS.parent
"""The repository's root."""
GOLDEN = TESTS / 'golden'
"""Stored results the tests compare with."""
