"""The suite's own scheduling holds: under ``pytest -n 4 --dist loadgroup`` (scripts/test.sh)
the groups tests/conftest.py marks keep their tests on one worker.

The suite's 5-minute budget rests on it: the wall-clock tests wait on one worker while the
others compute, and a module-scoped fixture (a colcon build, a recorded graph run) is built
once, not once per worker. pytest-xdist puts a group into the test's id by renaming
``Item._nodeid``; pytest 9.2 keeps the id elsewhere, so there every group silently
dissolved (requirements.txt pins a pytest where it holds). This runs the real hook of
tests/conftest.py in a small pytest run and checks where each test ran.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

CONFTEST = Path(__file__).with_name('conftest.py')


def test_groups_stay_on_one_worker(tmp_path: Path) -> None:
    (tmp_path / 'conftest.py').write_text(textwrap.dedent(f"""
        import importlib.util

        spec = importlib.util.spec_from_file_location('project_conftest', {str(CONFTEST)!r})
        project = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(project)
        pytest_collection_modifyitems = project.pytest_collection_modifyitems


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
            time.sleep(0.05)


        @pytest.mark.parametrize('i', range(8))
        def test_free(i):
            time.sleep(0.05)
        """))
    out = tmp_path / 'where.jsonl'
    proc = subprocess.run(
        [sys.executable, '-m', 'pytest', '-n', '2', '--dist', 'loadgroup', '-q',
         '-p', 'no:cacheprovider', str(tmp_path / 'test_probe.py')],
        cwd=tmp_path, capture_output=True, text=True, timeout=120,
        env={**os.environ, 'GROUPS_OUT': str(out)})
    assert proc.returncode == 0, proc.stdout + proc.stderr
    rows = [json.loads(line) for line in out.read_text().splitlines()]
    workers: dict[str, set[str]] = {}
    for kind, worker in rows:
        workers.setdefault(kind, set()).add(worker)
    assert sum(kind == 'fixture built' for kind, _ in rows) == 1, rows
    assert len(workers['module fixture']) == 1, rows
    assert len(workers['wall clock']) == 1, rows
