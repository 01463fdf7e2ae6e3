"""The import paths from before the packages were cut by role keep working for one release:
an old name warns (a FutureWarning naming the new one, shown by default: a DeprecationWarning
in a plug-in's module would be hidden) and gives the new module itself, and a plug-in written
against the old documented imports still loads, keeps the contract and shows its author the
warnings in a command's output.

import-rewrite: keep (this module names the old paths on purpose)
"""

from __future__ import annotations

import importlib.util
import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from support.example_plugin import PLUGIN

import trust_av_planner
import trust_monitor
from trust_av_common.moved import MovedPathWarning

OLD_AND_NEW = {
    'trust_monitor.common.params': 'trust_av_common.params',
    'trust_monitor.common.registry': 'trust_av_common.registry',
    'trust_monitor.ros.qos': 'trust_av_common.ros.qos',
    'trust_monitor.common.contract': 'trust_av.contract',
    'trust_monitor.trust_model': 'trust_monitor.paper_trust',
    'trust_monitor.trust_interface': 'trust_monitor.model_interface',
    'trust_av_planner.system.config': 'trust_av.system.config',
    'trust_av_planner.cli.main': 'trust_av.cli.main',
    'trust_av_planner.drive.follower': 'human_driver_sim.follower_plant',
    'trust_av_planner.drive.trust_fit': 'trust_monitor.trust_fit',
    'trust_av_planner.study.drive_session': 'trust_av.drive.run_session',
}

TODAYS_IMPORTS = {
    'from trust_av_common.params import': 'from trust_monitor.common.params import',
    'from trust_av_common.registry import': 'from trust_monitor.common.registry import',
    'from trust_monitor.paper_trust import': 'from trust_monitor.trust_model import',
    'from trust_av.contract import': 'from trust_monitor.common.contract import',
}
"""The plug-in's imports now -> as the plug-in tutorial documented them before the cut."""


def run(code: str, env: dict[str, str] | None = None) -> dict[str, object]:
    proc = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                          timeout=300, env=env, stdin=subprocess.DEVNULL)
    assert proc.returncode == 0, proc.stderr
    result: dict[str, object] = json.loads(proc.stdout.strip().splitlines()[-1])
    return result


def test_an_old_module_path_warns_and_is_the_new_module() -> None:
    code = f"""
import importlib, json, sys, warnings
from trust_av_common.moved import MovedPathWarning
out = {{}}
for old, new in {OLD_AND_NEW!r}.items():
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter('always')
        module = importlib.import_module(old)
    named = [str(w.message) for w in caught if w.category is MovedPathWarning
             and f'{{old}} moved to {{new}}' in str(w.message)]
    here = [w.filename for w in caught if w.category is MovedPathWarning]
    out[old] = [module is importlib.import_module(new), module.__name__, len(named),
                sys.modules[old] is module, all(f == '<string>' for f in here)]
print(json.dumps(out))
"""
    result = run(code)
    for old, new in OLD_AND_NEW.items():
        # the same object, one warning naming the new path, pointed at the importing line
        assert result[old] == [True, new, 1, True, True], old


def test_from_an_old_package_import_a_child_that_moved_apart() -> None:
    """``from trust_av_planner.graph import drive`` (now trust_av.drive.graph_run): the old
    package's child answers by its old name."""
    code = """
import json, warnings
warnings.simplefilter('always')
from trust_av_planner.graph import drive, stop_signals
from trust_av_planner.drive import follower
import trust_av.drive.graph_run, trust_av.graph.stop_signals, human_driver_sim.follower_plant
print(json.dumps([drive is trust_av.drive.graph_run,
                  stop_signals is trust_av.graph.stop_signals,
                  follower is human_driver_sim.follower_plant]))
"""
    assert run(code) == [True, True, True]


def test_names_that_moved_out_of_a_module_warn() -> None:
    with pytest.warns(MovedPathWarning, match=r'trust_av_common\.errors\.one_line'):
        from trust_monitor.errors import one_line
    with pytest.warns(MovedPathWarning, match='paper_explicability_bound'):
        from trust_monitor.paper_trust import explicability_bound
    from trust_av_common.errors import one_line as new_one_line
    from trust_monitor.paper_trust import paper_explicability_bound
    assert (one_line, explicability_bound) == (new_one_line, paper_explicability_bound)
    with pytest.raises(AttributeError):
        trust_monitor.errors.nothing_here  # noqa: B018


def test_every_old_path_names_an_existing_module() -> None:
    for old, new in {**trust_monitor.MOVED, **trust_av_planner.MOVED}.items():
        assert importlib.util.find_spec(new) is not None, f'{old} -> {new}'


def test_python_m_with_an_old_name_runs_the_new_module() -> None:
    proc = subprocess.run([sys.executable, '-m',       # the default warning filters
                           'trust_av_planner.cli', '--help'], capture_output=True, text=True,
                          timeout=120, stdin=subprocess.DEVNULL)
    assert proc.returncode == 0 and proc.stdout.startswith('usage: trust-av')
    assert 'trust_av_planner.cli moved to trust_av.cli' in proc.stderr


def test_a_plugin_written_with_the_old_imports_keeps_the_contract(tmp_path: Path) -> None:
    """The example plug-in with the imports the tutorial documented before the cut,
    installed with pip: its components load and pass the contract (called by its old
    path), and each old import warns."""
    source = tmp_path / 'source'
    shutil.copytree(PLUGIN, source, ignore=shutil.ignore_patterns('build', '*.egg-info'))
    rewritten = 0
    for path in [*source.rglob('*.py')]:
        text = path.read_text()
        old = text
        for new_import, old_import in TODAYS_IMPORTS.items():
            text = text.replace(new_import, old_import)
        path.write_text(text)
        rewritten += text != old
    assert rewritten >= 3  # both components and the plug-in's own contract test
    target = tmp_path / 'site'
    proc = subprocess.run([sys.executable, '-m', 'pip', 'install', '--quiet', '--no-deps',
                           '--no-build-isolation', '--disable-pip-version-check',
                           '--no-index', '--target', str(target), str(source)],
                          capture_output=True, text=True, timeout=300, stdin=subprocess.DEVNULL)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    env = {**__import__('os').environ, 'PYTHONPATH': str(target)}
    code = """
import json, warnings
from trust_av_common.moved import MovedPathWarning
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter('always')
    from trust_monitor.common.contract import check_component
    passed = [check_component(group, name).passed
              for group, name in (('trust_av.predictors', 'ses'),
                                  ('trust_av.trust_models', 'leaky'))]
moved = sorted({str(w.message).split(' moved')[0] for w in caught
                if w.category is MovedPathWarning and ' moved to ' in str(w.message)})
print(json.dumps([all(passed), moved]))
"""
    ok, moved = run(code, env)
    assert ok is True
    assert {'trust_monitor.common.contract', 'trust_monitor.common.params',
            'trust_monitor.common.registry', 'trust_monitor.trust_model'} <= set(moved)
    # the author sees them in a command's output, with Python's default warning filters
    # (a DeprecationWarning raised in a plug-in's module, not __main__, would be hidden)
    trace = tmp_path / 'ramp.csv'
    trace.write_text('time_s,speed_mps\n' + ''.join(f'{t},{8 + 0.5 * t}\n' for t in range(9)))
    env.pop('PYTHONWARNINGS', None)
    proc = subprocess.run([sys.executable, '-m', 'trust_av.cli', 'simulate', '--trace',
                           str(trace), '--predictor', 'ses', '--no-progress'], env=env,
                          capture_output=True, text=True, timeout=300, stdin=subprocess.DEVNULL)
    assert proc.returncode == 0, proc.stderr
    shown = [line for line in proc.stderr.splitlines() if 'MovedPathWarning' in line]
    assert any(line.startswith(str(target)) and 'trust_monitor.common.params moved to '
               'trust_av_common.params' in line for line in shown), proc.stderr


def test_python_m_with_every_old_path_runs_its_new_module_or_names_its_place() -> None:
    """What ``python -m OLD`` finds (runpy: the spec, then its code), for every old path the
    shims declare: the new module's file as the spec's origin (``sys.argv[0]``: with none,
    ``rclpy.init`` in a node's ``main`` failed with ``TypeError: bad argument type``) and
    the new module's code; an old package's ``__main__`` is its new one's; a module that is
    not in the package's new place is not found, in one line naming that place (it was said
    to have moved to a module that never existed)."""
    import warnings
    from importlib.abc import InspectLoader

    moved = {**trust_monitor.MOVED, **trust_av_planner.MOVED}
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', FutureWarning)   # MovedPathWarning
        for old, new in moved.items():
            spec, new_spec = importlib.util.find_spec(old), importlib.util.find_spec(new)
            assert spec is not None and new_spec is not None, old
            assert spec.origin == new_spec.origin and spec.origin is not None, old
            if spec.submodule_search_locations is None:
                loader, new_loader = spec.loader, new_spec.loader
                assert isinstance(loader, InspectLoader) and isinstance(new_loader, InspectLoader)
                assert loader.get_code(old) == new_loader.get_code(new), old
                continue
            new_main = importlib.util.find_spec(f'{new}.__main__')
            if new_main is not None:
                main = importlib.util.find_spec(f'{old}.__main__')
                assert main is not None and main.origin == new_main.origin, old
            with pytest.raises(ModuleNotFoundError, match=f'^No module named .{old}.never_was.'
                               f': {old} moved to {new}, which has no never_was$'):
                importlib.util.find_spec(f'{old}.never_was')


def test_python_m_with_an_old_path_that_never_was_names_the_new_place() -> None:
    proc = subprocess.run([sys.executable, '-m', 'trust_av_planner.study.nmpc_reference'],
                          capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL)
    # the old package's MovedPathWarning, then one line naming the new place
    lines = [line for line in proc.stderr.splitlines() if 'MovedPathWarning' not in line]
    assert proc.returncode == 1 and len(lines) == 1, proc.stderr
    assert ("No module named 'trust_av_planner.study.nmpc_reference': trust_av_planner.study "
            'moved to trust_av.study, which has no nmpc_reference') in proc.stderr
