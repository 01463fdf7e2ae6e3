"""Install the example plug-in (examples/trust_av_example_plugin) as a user would, with pip,
but into a temporary directory put on PYTHONPATH, so that a test leaves the project's
environment as it was; node processes started by trust-av inherit the variable."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
PLUGIN = REPO / 'examples' / 'trust_av_example_plugin'


def install_example_plugin(root: Path) -> dict[str, str]:
    """``pip install`` a copy of the example package into ``root/site``; returns the
    environment (``os.environ`` with that directory first on PYTHONPATH)."""
    source = root / 'source'
    shutil.copytree(PLUGIN, source, ignore=shutil.ignore_patterns('build', '*.egg-info'))
    target = root / 'site'
    proc = subprocess.run([sys.executable, '-m', 'pip', 'install', '--quiet', '--no-deps',
                           '--no-build-isolation', '--disable-pip-version-check',
                           '--no-index', '--target', str(target), str(source)],
                          capture_output=True, text=True, timeout=300, stdin=subprocess.DEVNULL)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    env = dict(os.environ)
    env['PYTHONPATH'] = os.pathsep.join(p for p in (str(target), env.get('PYTHONPATH')) if p)
    return env
