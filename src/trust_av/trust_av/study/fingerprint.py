"""What a study's cached results depend on: the source and data files of the packages that
compute a run, and of the installed plug-ins' component modules (:func:`code_fingerprint`,
part of every cached case's key in :mod:`trust_av.study.sweep`)."""

from __future__ import annotations

import hashlib
import sys
from pathlib import Path

from trust_av_common import registry

__all__ = ['PACKAGES', 'PRESENTATION_MODULES', 'code_fingerprint', 'plugin_sources']

PACKAGES = ('trust_av_common', 'preceding_traffic', 'trust_monitor', 'human_driver_sim',
            'trust_av_planner', 'trust_av')
PRESENTATION_MODULES = ('plots.py', 'paper_results.py', 'tables.py', 'frame.py',
                        'trace_reports.py', 'compare_runs.py')
"""Files that cannot change a run's numbers: left out of the cache key (so is ``cli/``)."""


def plugin_sources() -> list[Path]:
    """The source files of the registered components from outside the six packages (the
    installed plug-ins' modules), in name order."""
    from trust_av.system.config import GROUPS

    files = set()
    for group in GROUPS:
        for component in registry.components(group):
            module = sys.modules[component.factory.__module__]
            if module.__name__.split('.')[0] not in PACKAGES and module.__file__:
                files.add(Path(module.__file__))
    return sorted(files)


def code_fingerprint() -> str:
    """Hash of the source and data files of the six packages that results depend on, and
    of the installed plug-ins' component modules."""
    digest = hashlib.sha256()
    for path in plugin_sources():
        digest.update(path.name.encode())
        digest.update(path.read_bytes())
    for package in PACKAGES:
        module = __import__(package)
        root = Path(next(iter(module.__path__)))
        for path in sorted(root.rglob('*')):
            relative = path.relative_to(root)
            if path.name in PRESENTATION_MODULES or relative.parts[0] == 'cli':
                continue
            if path.is_file() and path.suffix in {'.py', '.csv', '.npz', '.json', '.pt'}:
                digest.update(str(path.relative_to(root)).encode())
                digest.update(path.read_bytes())
    return digest.hexdigest()
