"""Each module of the six packages declares its public API (``__all__``), every declared
name exists, and the docs' API reference (docs/reference/api.md, rendered with
mkdocstrings' ``public`` filter, which follows ``__all__``) shows only declared names."""

from __future__ import annotations

import ast
import importlib
import re
from pathlib import Path

import pytest
from support.paths import REPO

PACKAGES = ('trust_av_common', 'trust_monitor', 'preceding_traffic', 'human_driver_sim',
            'trust_av_planner', 'trust_av')


def declared(path: Path) -> list[str] | None:
    """The names a module's ``__all__`` lists (None: it declares none)."""
    for node in ast.parse(path.read_text()).body:
        targets = node.targets if isinstance(node, ast.Assign) else \
            [node.target] if isinstance(node, ast.AnnAssign) else []
        if any(isinstance(t, ast.Name) and t.id == '__all__' for t in targets):
            assert node.value is not None
            return list(ast.literal_eval(node.value))
    return None


def modules() -> dict[str, Path]:
    found = {}
    for package in PACKAGES:
        root = REPO / 'src' / package
        for path in sorted((root / package).rglob('*.py')):
            parts = list(path.relative_to(root).with_suffix('').parts)
            if parts[-1] == '__init__':
                parts.pop()
            found['.'.join(parts)] = path
    return found


def test_every_module_declares_its_public_api() -> None:
    missing = sorted(name for name, path in modules().items()
                     if declared(path) is None and not name.endswith('__main__'))
    assert missing == []


@pytest.mark.parametrize('package', PACKAGES)
def test_every_declared_name_exists(package: str) -> None:
    for name, path in modules().items():
        if not name.startswith(package) or name.endswith('__main__'):
            continue
        public = declared(path) or []
        assert public == sorted(set(public), key=public.index), f'{name}: a name twice'
        tree = ast.parse(path.read_text())
        defined = {t.id for node in ast.walk(tree) if isinstance(node, (ast.Assign,
                   ast.AnnAssign)) for t in (node.targets if isinstance(node, ast.Assign)
                   else [node.target]) if isinstance(t, ast.Name)}
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
    from trust_av_common.errors import TrustAvError

    found = {}
    for name in modules():
        if name.endswith('__main__'):
            continue
        module = importlib.import_module(name)
        for value in vars(module).values():
            if (isinstance(value, type) and issubclass(value, BaseException)
                    and value.__module__ == name):
                found[f'{name}.{value.__qualname__}'] = value
    assert len(found) > 30
    astray = sorted(qualified for qualified, cls in found.items()
                    if not issubclass(cls, (TrustAvError, KeyboardInterrupt))
                    and qualified not in NOT_ERRORS)
    assert astray == []
