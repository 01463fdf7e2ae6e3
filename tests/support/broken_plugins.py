"""Install the deliberately broken plug-ins of ``tests/plugins/`` with real entry points: a
``*.dist-info`` directory (what pip writes) beside the modules, in a directory put first on
the import path (this process, through pytest's ``monkeypatch``) or PYTHONPATH (a command
and the node processes it starts), so the project's environment stays as it was."""

from __future__ import annotations

import importlib.util
import os
import shutil
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from types import ModuleType

import pytest

PLUGINS = Path(__file__).resolve().parents[1] / 'plugins'


def _table() -> ModuleType:
    """The plug-ins' module read from its file (what it registers), under another name than
    the installed one's."""
    spec = importlib.util.spec_from_file_location('broken_plugins_table',
                                                  PLUGINS / 'trust_av_broken_plugins.py')
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


broken = _table()
AT_IMPORT = 'broken_at_import'
"""The predictor whose module exits at import."""


def install(root: Path) -> Path:
    """The broken plug-ins as an installed distribution in ``root/site``; returns it."""
    site = root / 'site'
    info = site / 'trust_av_broken_plugins-0.0.0.dist-info'
    info.mkdir(parents=True, exist_ok=True)
    for module in ('trust_av_broken_plugins.py', 'trust_av_broken_at_import.py'):
        shutil.copy(PLUGINS / module, site / module)
    (info / 'METADATA').write_text('Metadata-Version: 2.1\nName: trust-av-broken-plugins\n'
                                   'Version: 0.0.0\n')
    lines = []
    for group, table in broken.ENTRY_POINTS.items():
        lines.append(f'[{group}]')
        prefix = group.rsplit('.', 1)[-1].upper()
        lines += [f'{name} = trust_av_broken_plugins:{prefix}_{name}' for name in table]
        if group == 'trust_av.predictors':
            lines.append(f'{AT_IMPORT} = trust_av_broken_at_import:COMPONENT')
        lines.append('')
    (info / 'entry_points.txt').write_text('\n'.join(lines))
    return site


def environment(site: Path) -> dict[str, str]:
    """``os.environ`` with ``site`` first on PYTHONPATH."""
    env = dict(os.environ)
    env['PYTHONPATH'] = os.pathsep.join(p for p in (str(site), env.get('PYTHONPATH')) if p)
    return env


@contextmanager
def installed_here(site: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """The plug-ins in ``site`` registered in this process too, while the context lasts
    (``site`` on the import path through ``monkeypatch``; the registry's scans are redone
    on entry and on exit)."""
    from trust_av_common import registry

    monkeypatch.syspath_prepend(str(site))
    registry._entry_points.cache_clear()
    registry._load.cache_clear()
    try:
        yield
    finally:
        monkeypatch.undo()
        registry._entry_points.cache_clear()
        registry._load.cache_clear()
        for module in ('trust_av_broken_plugins', 'trust_av_broken_at_import'):
            sys.modules.pop(module, None)
