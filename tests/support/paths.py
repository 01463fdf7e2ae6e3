"""Where the repository and the suite are, wherever a test module sits in ``tests/``."""

from __future__ import annotations

from pathlib import Path

TESTS = Path(__file__).resolve().parents[1]
"""The suite's directory, ``tests/``."""
REPO = TESTS.parent
"""The repository's root."""
GOLDEN = TESTS / 'golden'
"""Stored results the tests compare with."""


def tree_packages(src: Path = REPO / 'src') -> tuple[str, ...]:
    """Every package of the tree, found, never listed: each folder ``src/NAME/`` that holds
    the Python package ``NAME/`` (a ROS 2 package, one setup.py each), by name."""
    return tuple(sorted(p.name for p in src.iterdir() if (p / p.name / '__init__.py').is_file()))
