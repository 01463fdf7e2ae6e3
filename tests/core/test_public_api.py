"""Each module of every package of the tree (``src/NAME/NAME/``, found, never listed) declares
its public API (``__all__``), every declared name exists, the docs' API reference
(docs/reference/api.md, rendered with mkdocstrings' ``public`` filter, which follows
``__all__``) shows only declared names, and every exception class derives from the one base."""

from __future__ import annotations

import ast
import importlib
import re
from pathlib import Path

import pytest
from support.paths import REPO, tree_packages

PACKAGES = tree_packages()


def declared(path: Path) -> list[str] | None:
    """The names a module's ``__all__`` lists (None: it declares none)."""
    for node in ast.parse(path.read_text()).body:
        targets = node.targets if isinstance(node, ast.Assign) else \
            [node.target] if isinstance(node, ast.AnnAssign) else []
        if any(isinstance(t, ast.Name) and t.id == '__all__' for t in targets):
            assert node.value is not None
            return list(ast.literal_eval(node.value))
    return None


def modules(src: Path = REPO / 'src') -> dict[str, Path]:
    """Every module of every package of the tree under ``src``, by dotted name."""
    found = {}
    for package in tree_packages(src):
        root = src / package
        for path in sorted((root / package).rglob('*.py')):
            parts = list(path.relative_to(root).with_suffix('').parts)
            if parts[-1] == '__init__':
                parts.pop()
            found['.'.join(parts)] = path
    return found


def undeclared(found: dict[str, Path]) -> list[str]:
    """The modules that declare no ``__all__`` (``__main__`` needs none)."""
    return sorted(name for name, path in found.items()
                  if declared(path) is None and not name.endswith('__main__'))


def test_every_module_declares_its_public_api() -> None:
    assert undeclared(modules()) == []


@pytest.mark.parametrize('package', PACKAGES)
def test_every_declared_name_exists(package: str) -> None:
    for name, path in modules().items():
        if name.split('.')[0] != package or name.endswith('__main__'):
            continue
        public = declared(path) or []
        assert public == sorted(set(public), key=public.index), f'{name}: a name twice'
        tree = ast.parse(path.read_text())
        defined = {t.id for node in ast.walk(tree) if isinstance(node, (ast.Assign,
                   ast.AnnAssign)) for target in (node.targets if isinstance(node, ast.Assign)
                   else [node.target]) for t in ast.walk(target) if isinstance(t, ast.Name)}
        defined |= {node.name for node in tree.body
                    if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef))}
        defined |= {(a.asname or a.name).split('.')[0] for node in tree.body
                    if isinstance(node, (ast.Import, ast.ImportFrom)) for a in node.names}
        assert set(public) <= defined, f'{name}: {sorted(set(public) - defined)}'


def test_the_api_reference_shows_only_declared_names() -> None:
    page = (REPO / 'docs' / 'reference' / 'api.md').read_text()
    shown = re.findall(r'^::: ([\w.]+)', page, re.MULTILINE)
    assert len(shown) > 10
    for target in shown:
        try:
            importlib.import_module(target)
            continue  # a whole module: rendered through its __all__
        except ModuleNotFoundError:
            pass
        module_name, _, name = target.rpartition('.')
        module = importlib.import_module(module_name)
        assert name in module.__all__, f'{target} is not in {module_name}.__all__'


NOT_ERRORS = {
    'trust_av_common.ros.raw_inputs.OtherEncodingError':
        'a signal inside the raw decoder: not plain CDR, read with rclpy instead',
    'trust_av.contract._DoesNotApplyError': 'a signal inside the contract: a rule not applying',
}
"""Exception classes that are control flow inside one module, never raised to a caller."""


def test_every_project_exception_derives_from_the_one_base() -> None:
    """So that ``trust-av`` catches one class (TrustAvError) and prints one line; a stop
    (KeyboardInterrupt: Ctrl-C, SIGTERM) is not an error."""
    found = exception_classes(modules())
    assert len(found) > 30
    assert astray(found) == []


def exception_classes(found: dict[str, Path]) -> dict[str, type]:
    """Every exception class the modules define (imported: ``class X(Base)`` as Python sees
    it), by qualified name."""
    classes = {}
    for name in found:
        if name.endswith('__main__'):
            continue
        module = importlib.import_module(name)
        for value in vars(module).values():
            if (isinstance(value, type) and issubclass(value, BaseException)
                    and value.__module__ == name):
                classes[f'{name}.{value.__qualname__}'] = value
    return classes


def astray(classes: dict[str, type]) -> list[str]:
    """The exception classes that derive from neither the one base nor a stop (a warning
    category, such as the old import paths' MovedPathWarning, is not an error)."""
    from trust_av_common.errors import TrustAvError

    return sorted(qualified for qualified, cls in classes.items()
                  if not issubclass(cls, (TrustAvError, KeyboardInterrupt, Warning))
                  and qualified not in NOT_ERRORS)


def test_a_new_package_is_checked_without_an_edit_here(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Not vacuous, and not a list: a package planted in a tree (``src/NAME/NAME/``) is
    found, and its module without ``__all__`` and its ``ValueError`` subclass are named."""
    root = tmp_path / 'src' / 'planted_package'
    (root / 'planted_package').mkdir(parents=True)
    (root / 'planted_package' / '__init__.py').write_text('__all__: list[str] = []\n')
    (root / 'planted_package' / 'oops.py').write_text('class Oops(ValueError):\n    pass\n')
    monkeypatch.syspath_prepend(str(root))
    found = modules(tmp_path / 'src')
    assert undeclared(found) == ['planted_package.oops']
    assert astray(exception_classes(found)) == ['planted_package.oops.Oops']
