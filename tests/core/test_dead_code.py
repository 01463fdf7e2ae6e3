"""No production function only tests use: every public top-level function of the packages
in src/, and every public method of a class that derives only from the project's classes (a
method of a library's subclass may be a hook the library calls: an importlib finder's, a
lifecycle node's), is referenced from src/ itself, from an entry point (setup.py: a console
script, a plug-in factory) or from the docs' API reference (docs/reference/api.md), or is in
:data:`ALLOWED` with the reason it stays. A function only tests or benchmarks call belongs
in tests/support/ or benchmarks/; one nothing calls is deleted.

A small AST scan (vulture's idea, without the dependency): a function counts as referenced
when its name appears as a name, an attribute or a ``getattr`` string anywhere in src/
outside its own ``def``
(so a name shared with a method used elsewhere counts, and nothing is reported wrongly)."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest
from support.paths import REPO

ALLOWED: dict[str, str] = {
    'trust_av.study.trust_design.Recovery.confusion_best':
        'the recovery benchmark reports the confusion without the parsimony rule '
        '(benchmarks/bench_trust_recovery.py)',
    # documented for users: a tutorial's code imports them
    'trust_av.study.trust_recovery.synthetic_study':
        'the fit tutorial (docs/tutorials/fit-trust-models.md) makes its ratings table with it',
    'trust_av.study.trust_recovery.write_ratings_table':
        'the fit tutorial (docs/tutorials/fit-trust-models.md) writes its ratings table with it',
    # metrics and bounds of the project's own tools, which write tables the docs print
    'trust_av.system.metrics.explicability_by_age':
        'the control-rate table (scripts/rate_table.py) reports E by the age of the plan',
    'trust_av.system.metrics.step_change_rms_mps2':
        'the control-rate table (scripts/rate_table.py) reports the command steps',
    'trust_monitor.final_trust_bound.warmup_bounds':
        "the paper's bound table (scripts/paper_bound_table.py) reads the warm-up variants",
}
"""Public functions nothing in src/ references that stay, each with why and the file that
uses it (checked). Listed by module and name; an entry that no longer applies fails the
test as well, so the list stays true."""

ENTRY_POINT = re.compile(r'[\w.]+:(\w+)')
"""``module:attribute`` in a setup.py: a console script or a plug-in factory."""
API_ENTRY = re.compile(r'^::: ([\w.]+)', re.MULTILINE)


def module_name(root: Path, path: Path) -> str:
    parts = list(path.relative_to(root).with_suffix('').parts)
    if parts[-1] == '__init__':
        parts.pop()
    return '.'.join(parts)


def declared(tree: ast.Module) -> list[str]:
    """The names a module's ``__all__`` lists (empty: none)."""
    for node in tree.body:
        targets = node.targets if isinstance(node, ast.Assign) else \
            [node.target] if isinstance(node, ast.AnnAssign) else []
        if any(isinstance(t, ast.Name) and t.id == '__all__' for t in targets):
            assert node.value is not None
            return list(ast.literal_eval(node.value))
    return []


def unreferenced(src: Path, api_page: Path | None = None) -> list[str]:
    """``module.function`` of every public top-level function under ``src`` (one folder per
    package, as src/ holds them) that nothing references: no name or attribute of that name
    in src/ outside its own definition, no entry point in a setup.py, no entry of the API
    reference page (a function, or a whole module: its ``__all__``)."""
    trees: dict[str, ast.Module] = {}
    for setup_dir in sorted(p for p in src.iterdir() if p.is_dir()):
        for package in sorted(p for p in setup_dir.iterdir() if (p / '__init__.py').exists()):
            for path in sorted(package.rglob('*.py')):
                trees[module_name(setup_dir, path)] = ast.parse(path.read_text(), str(path))
    used: set[str] = set()
    for tree in trees.values():
        for node in ast.walk(tree):
            if isinstance(node, ast.Name):
                used.add(node.id)
            elif isinstance(node, ast.Attribute):
                used.add(node.attr)
            elif isinstance(node, ast.alias):
                used.add((node.asname or node.name).rpartition('.')[2])
            elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
                    and node.func.id in ('getattr', 'hasattr') and len(node.args) >= 2
                    and isinstance(node.args[1], ast.Constant)):
                used.add(str(node.args[1].value))  # getattr(model, 'trust_range', ...)
    for setup in sorted(src.glob('*/setup.py')):
        used |= set(ENTRY_POINT.findall(setup.read_text()))
    documented: set[str] = set()
    if api_page is not None:
        for target in API_ENTRY.findall(api_page.read_text()):
            if target in trees:
                documented |= {f'{target}.{name}' for name in declared(trees[target])}
            documented.add(target)
    ours = {node.name for tree in trees.values() for node in ast.walk(tree)
            if isinstance(node, ast.ClassDef)}
    found = []
    for name, tree in trees.items():
        for node, where in _functions(tree, ours):
            if (not node.name.startswith('_') and node.name not in used
                    and f'{name}.{node.name}' not in documented):
                found.append(f'{name}.{where}{node.name}')
    return sorted(found)


def _functions(tree: ast.Module, ours: set[str]) -> list[tuple[ast.AST, str]]:
    """The top-level functions of a module, and the methods of its top-level classes that
    derive only from classes defined in src/ (or from none), each with its class's prefix."""
    found: list[tuple[ast.AST, str]] = []
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            found.append((node, ''))
        elif isinstance(node, ast.ClassDef) and all(
                isinstance(base, ast.Name) and base.id in ours for base in node.bases):
            found += [(item, f'{node.name}.') for item in node.body
                      if isinstance(item, (ast.FunctionDef, ast.AsyncFunctionDef))]
    return found


def test_every_public_function_in_src_has_a_caller_in_src_or_is_allowed() -> None:
    found = unreferenced(REPO / 'src', REPO / 'docs' / 'reference' / 'api.md')
    assert sorted(set(found) - set(ALLOWED)) == [], (
        'only tests or benchmarks call these: move them to tests/support/ or benchmarks/, '
        'delete them, or list them in ALLOWED with the reason they stay')
    assert sorted(set(ALLOWED) - set(found)) == [], 'ALLOWED names a function now referenced'


def _package(src: Path, files: dict[str, str], setup: str = '') -> None:
    root = src / 'pkg'
    (root / 'pkg').mkdir(parents=True)
    (root / 'setup.py').write_text(setup)
    (root / 'pkg' / '__init__.py').write_text('')
    for name, text in files.items():
        (root / 'pkg' / name).write_text(text)


def test_the_scan_finds_a_planted_unused_function(tmp_path: Path) -> None:
    src = tmp_path / 'src'
    _package(src, {
        'core.py': ('def used() -> int:\n    return 1\n\n\n'
                    'def only_tests_call_me() -> int:\n    return 2\n\n\n'
                    'def _private() -> int:\n    return 3\n\n\n'
                    'def main() -> None:\n    pass\n\n\n'
                    'def shown() -> None:\n    pass\n'),
        'user.py': 'from pkg.core import used\n\nVALUE = used()\n',
        'shapes.py': ('class Base:\n    def area(self) -> float:\n        return 0.0\n\n\n'
                      'class Square(Base):\n    def only_tests_measure_me(self) -> float:\n'
                      '        return 1.0\n\n    def __len__(self) -> int:\n        return 4\n'
                      '\n\nclass Hook(dict):\n    def a_library_calls_me(self) -> None:\n'
                      '        pass\n\n\nAREA = Square().area()\n'),
        'other.py': ("__all__ = ['whole']\n\n\ndef whole() -> None:\n    pass\n\n\n"
                     'def hidden() -> None:\n    pass\n'),
    }, setup="entry_points={'console_scripts': ['tool = pkg.core:main']}\n")
    page = tmp_path / 'api.md'
    page.write_text('::: pkg.core.shown\n\n::: pkg.other\n')
    assert unreferenced(src, page) == ['pkg.core.only_tests_call_me', 'pkg.other.hidden',
                                       'pkg.shapes.Square.only_tests_measure_me']
    assert unreferenced(src) == ['pkg.core.only_tests_call_me', 'pkg.core.shown',
                                 'pkg.other.hidden', 'pkg.other.whole',
                                 'pkg.shapes.Square.only_tests_measure_me']


@pytest.mark.parametrize('name', sorted(ALLOWED))
def test_each_allowed_function_is_used_where_its_reason_says(name: str) -> None:
    """An allow-list entry names the file that uses it; that file does."""
    where = re.search(r'\(([\w/.-]+\.(?:md|py))\)', ALLOWED[name])
    assert where is not None, f'{name}: the reason names no file'
    assert name.rpartition('.')[2] in (REPO / where.group(1)).read_text()
