"""The suite's own scheduling holds: under ``pytest -n 6 --dist loadgroup`` (scripts/test.sh)
the groups tests/conftest.py marks keep their tests on one worker, the wall-clock tests start
on the wall lanes and the others beside them, and nothing else is tied to one worker.

The suite's 5-minute budget rests on it: a module-scoped fixture (a colcon build, a recorded
graph run) is built once, not once per worker, and the long wall-clock tests wait side by
side on half of the workers while the others keep the CPU busy. pytest-xdist puts a group
into the test's id by renaming ``Item._nodeid``; pytest 9.2 keeps the id elsewhere, so
there every group silently dissolved (requirements.txt pins a pytest where it holds). This
runs the real hook of tests/conftest.py in a small pytest run and checks where each test
ran.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from support.paths import REPO, TESTS

ROOT = REPO
CONFTEST = TESTS / 'conftest.py'


@pytest.mark.slow
def test_groups_stay_on_one_worker(tmp_path: Path) -> None:
    (tmp_path / 'conftest.py').write_text(textwrap.dedent(f"""
        import importlib.util

        spec = importlib.util.spec_from_file_location('project_conftest', {str(CONFTEST)!r})
        project = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(project)
        pytest_collection_modifyitems = project.pytest_collection_modifyitems
        pytest_xdist_make_scheduler = project.pytest_xdist_make_scheduler


        def pytest_configure(config):
            config.addinivalue_line('markers', 'wall_clock: waits')
            config.addinivalue_line('markers', 'slow: slow')
        """))
    (tmp_path / 'test_probe.py').write_text(textwrap.dedent("""
        import json, os, time
        from pathlib import Path

        import pytest

        OUT = Path(os.environ['GROUPS_OUT'])


        def note(kind):
            with OUT.open('a') as out:
                out.write(json.dumps([kind, os.environ['PYTEST_XDIST_WORKER']]) + '\\n')


        @pytest.fixture(scope='module')
        def shared():
            note('fixture built')


        @pytest.mark.parametrize('i', range(6))
        def test_with_module_fixture(shared, i):
            note('module fixture')
            time.sleep(0.05)


        @pytest.mark.wall_clock
        @pytest.mark.parametrize('i', range(4))
        def test_wall(i):
            note('wall clock')
            time.sleep(0.5)


        @pytest.mark.parametrize('i', range(8))
        def test_free(i):
            note('free')
            time.sleep(0.05)
        """))
    out = tmp_path / 'where.jsonl'
    proc = subprocess.run(
        [sys.executable, '-m', 'pytest', '-n', '2', '--dist', 'loadgroup',
         '--no-loadscope-reorder', '-q', '-p', 'no:cacheprovider',
         str(tmp_path / 'test_probe.py')],
        cwd=tmp_path, capture_output=True, text=True, timeout=120,
        env={**os.environ, 'GROUPS_OUT': str(out)})
    assert proc.returncode == 0, proc.stdout + proc.stderr
    rows = [json.loads(line) for line in out.read_text().splitlines()]
    workers: dict[str, set[str]] = {}
    for kind, worker in rows:
        workers.setdefault(kind, set()).add(worker)
    assert sum(kind == 'fixture built' for kind, _ in rows) == 1, rows
    assert len(workers['module fixture']) == 1, rows
    # the wall-clock tests come first (tests/conftest.py orders them), one unit each: the
    # wall lane (gw0) starts with one, the other worker with a CPU test beside it (when every
    # worker took a waiting test first, the CPU idled at the start of the suite)
    first = {}
    for kind, worker in rows:
        first.setdefault(worker, kind)
    assert first['gw0'] == 'wall clock' and first['gw1'] != 'wall clock', rows


@pytest.mark.slow
def test_a_test_that_times_out_fails_alone_and_the_run_goes_on(tmp_path: Path) -> None:
    """Under the suite's own settings (pyproject.toml: pytest-timeout's thread method; the
    scheduler of tests/conftest.py) and ``-n 2 --dist loadgroup``, a hung test is reported
    failed once, and every other test still runs and passes, those of its own group too: no
    INTERNALERROR ends the run, and the hung test does not run again on each new worker."""
    (tmp_path / 'conftest.py').write_text(textwrap.dedent(f"""
        import importlib.util

        spec = importlib.util.spec_from_file_location('project_conftest', {str(CONFTEST)!r})
        project = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(project)
        pytest_collection_modifyitems = project.pytest_collection_modifyitems
        pytest_xdist_make_scheduler = project.pytest_xdist_make_scheduler
        """))
    (tmp_path / 'test_probe.py').write_text(textwrap.dedent("""
        import time

        import pytest


        @pytest.fixture(scope='module')
        def shared():
            return 1


        @pytest.mark.timeout(10)
        def test_hangs_beside_its_group(shared):
            time.sleep(120)


        @pytest.mark.parametrize('i', range(3))
        def test_in_the_group(shared, i):
            time.sleep(0.2)


        @pytest.mark.timeout(10)
        def test_hangs():
            time.sleep(120)


        @pytest.mark.parametrize('i', range(6))
        def test_fine(i):
            time.sleep(0.2)
        """))
    proc = subprocess.run(
        [sys.executable, '-m', 'pytest', '-n', '2', '--dist', 'loadgroup', '-q',
         '-p', 'no:cacheprovider', '-c', str(ROOT / 'pyproject.toml'), '--rootdir',
         str(tmp_path), str(tmp_path / 'test_probe.py')],
        cwd=tmp_path, capture_output=True, text=True, timeout=600)  # a hang guard only
    out = proc.stdout + proc.stderr
    # (the hung tests' 10 s: a worker killed while xdist still brings the workers up, as a
    # 2 s timeout on a loaded machine did, is xdist's own INTERNALERROR; the suite's tests
    # time out after 300 s, long after every worker is up)
    assert proc.returncode == 1, out
    assert 'INTERNALERROR' not in out, out
    # each hung test once, and every other test of its group (module fixture) still ran
    assert re.search(r'\b2 failed, 9 passed\b', out), out
    # one crash each (the FAILURES section's line per crash; the short summary repeats it
    # in full where CI is set, cut to the terminal's width elsewhere)
    crashes = re.findall(r"^worker '\w+' crashed while running '(test_probe\.py::[\w@.]+)'$",
                         out, re.MULTILINE)
    assert crashes.count('test_probe.py::test_hangs') == 1, out
    # (its id carries its xdist group: test_probe.py::test_hangs_beside_its_group@...)
    assert sum(c.startswith('test_probe.py::test_hangs_beside_its_group')
               for c in crashes) == 1, out


def test_each_test_is_marked_with_its_tier_folder() -> None:
    """tests/conftest.py's tier of a module: its folder under tests/ (core, graph, browser)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location('project_conftest', CONFTEST)
    assert spec is not None and spec.loader is not None
    project = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(project)
    assert project.tier(TESTS / 'core' / 'test_nmpc.py') == 'core'
    assert project.tier(TESTS / 'graph' / 'test_graph.py') == 'graph'
    assert project.tier(TESTS / 'browser' / 'test_drive_page.py') == 'browser'
    assert project.tier(TESTS / 'support' / 'graph.py') is None
    assert project.tier(TESTS / 'test_flat.py') is None
    assert project.tier(REPO / 'examples' / 'core' / 'test_x.py') is None
