"""The suite's own layout: every test module in one tier folder (tests/conftest.py marks its
tests with the tier), and helpers shared through ``tests/support/``: no test module imports
another test module or the conftest (a test module imported by another ran its tests twice
when collected from both, and tied modules of different tiers together)."""

from __future__ import annotations

import ast
import contextlib
from pathlib import Path

from support.paths import REPO, TESTS

TIERS = ('core', 'graph', 'browser')


def imported_names(path: Path) -> set[str]:
    """Every module name ``path`` imports, at module level or inside functions, and the
    module names in code strings it runs (``-c`` programs are parsed too)."""
    names: set[str] = set()

    def walk(tree: ast.AST) -> None:
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                names.update(alias.name for alias in node.names)
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names.add(node.module)
            elif isinstance(node, ast.Constant) and isinstance(node.value, str) \
                    and 'import ' in node.value:
                with contextlib.suppress(SyntaxError):  # prose naming an import
                    walk(ast.parse(node.value))

    walk(ast.parse(path.read_text(encoding='utf-8')))
    return names


def cross_imports(tests: Path) -> dict[str, list[str]]:
    """Python file under ``tests`` -> the test modules and conftests it imports."""
    found = {}
    for path in sorted(tests.rglob('*.py')):
        bad = sorted(name for name in imported_names(path)
                     if name.split('.')[-1].startswith('test_')
                     or name.split('.')[-1] == 'conftest')
        if bad:
            found[str(path.relative_to(tests))] = bad
    return found


def test_no_test_module_imports_another() -> None:
    assert cross_imports(TESTS) == {}


def test_an_import_of_a_test_module_is_found(tmp_path: Path) -> None:
    (tmp_path / 'core').mkdir()
    (tmp_path / 'core' / 'test_a.py').write_text('from support.graph import run_command\n')
    # (the planted imports are split so that this module does not hold them itself)
    (tmp_path / 'core' / 'test_b.py').write_text(
        'def test_x():\n    from ' + 'test_a import helper\n')
    (tmp_path / 'core' / 'test_c.py').write_text(
        "CHILD = '''\\nimport sys\\nfrom " + "conftest import closed_loop\\n'''\n")
    assert cross_imports(tmp_path) == {'core/test_b.py': ['test_a'],
                                       'core/test_c.py': ['conftest']}


def test_every_test_module_is_in_a_tier_folder() -> None:
    """tests/core, tests/graph, tests/browser; nothing else holds a test module (the
    fixtures' plug-ins, golden files and helpers are in plugins/, golden/, support/)."""
    outside = [str(path.relative_to(TESTS)) for path in TESTS.rglob('test_*.py')
               if path.relative_to(TESTS).parts[0] not in TIERS]
    assert outside == []
    assert all(any((TESTS / tier).glob('test_*.py')) for tier in TIERS)


def test_every_cited_test_file_exists() -> None:
    """Every ``tests/...py`` the docs, the code and the configuration name is there: the
    suite's, or an example package's own (the plug-in tutorial runs its tests from the
    package's folder); the changelog keeps the paths of its day."""
    import re

    cited = re.compile(r'(?<![\w/.])tests/[\w/]+\.py\b')  # a path's start
    roots = [REPO / 'README.md', *(REPO / 'docs').rglob('*.md'), *(REPO / 'src').rglob('*.py'),
             *(REPO / 'src').rglob('setup.cfg'), *(REPO / 'scripts').rglob('*'),
             *(REPO / 'benchmarks').rglob('*.py'), *TESTS.rglob('*.py'), REPO / 'pyproject.toml']
    missing = {}
    for path in roots:
        if path.is_file() and path.name != 'CHANGELOG.md':
            for name in cited.findall(path.read_text(encoding='utf-8', errors='replace')):
                if not (REPO / name).is_file() and not any((REPO / 'examples').glob(f'*/{name}')):
                    missing.setdefault(str(path.relative_to(REPO)), []).append(name)
    assert missing == {}
