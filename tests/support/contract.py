"""Short runs of the contract tests: ``trust-av`` in a fresh process, a 30-step trace."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import pytest

GRAPH_STEPS = 30
"""Steps of :func:`trace_csv`'s runs through the node graph."""


def cli(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    """``trust-av ARGS`` in a fresh process (which finds the components as a user's does)."""
    return subprocess.run([sys.executable, '-m', 'trust_av.cli', *args], cwd=cwd,
                          capture_output=True, text=True, timeout=300, stdin=subprocess.DEVNULL)


@pytest.fixture(scope='module')
def trace_csv(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 30-step speed trace (1 s steps, a slow and a fast phase)."""
    path = tmp_path_factory.mktemp('contract') / 'contract.csv'
    path.write_text('time_s,speed_mps\n' + ''.join(
        f'{t},{12.0 + 6.0 * math.sin(t / 5.0):.3f}\n' for t in range(GRAPH_STEPS + 1)))
    return path
