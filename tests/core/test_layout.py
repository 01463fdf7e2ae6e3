"""The import rule of the layout (docs/reference/code-map.md), checked on every module of every
package of the tree (each ``src/NAME/NAME/``, found, never listed) by walking their imports
(module level and inside functions), and the pure core's promise that importing it never loads
rclpy or a message package (HOUSE_STYLE rule 1).

The layers are declared once, in ``scripts/code_map.py`` (``LAYERS``), which also writes the
code map. The rule:
- every package of the tree is declared (its layers and the packages it may import); every
  module is in a folder its package's layers declare: an unlisted package or folder fails;
- packages: ``trust_av_common`` (the floor) imports none of the others; ``trust_monitor``,
  ``preceding_traffic`` and ``human_driver_sim`` import only the floor (and not each other);
  ``trust_av_planner`` imports those but not ``trust_av`` (the application), which nothing
  imports;
- inside a package, a module imports only folders of the same or a lower rank; node modules
  (``*_node.py``) are started by name and imported by nobody;
- pure folders' modules (except node modules and ``__main__``) never import rclpy, a message
  package, or a module that is not pure;
- no import cycles between project modules.
"""

from __future__ import annotations

import ast
import importlib.util
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

from support.paths import REPO

SRC = REPO / 'src'
_spec = importlib.util.spec_from_file_location(
    'code_map', REPO / 'scripts' / 'code_map.py')
assert _spec is not None and _spec.loader is not None
code_map = importlib.util.module_from_spec(_spec)
sys.modules['code_map'] = code_map      # dataclass-like NamedTuples need their module
_spec.loader.exec_module(code_map)
ALLOWED_PACKAGES: dict[str, set[str]] = code_map.ALLOWED_PACKAGES
LAYERS = code_map.LAYERS
ROS_ROOTS = ('rclpy', 'rcl_interfaces', 'builtin_interfaces', 'rosgraph_msgs', 'rosidl_runtime_py')


@dataclass(frozen=True)
class Module:
    """One module of the tree and every import it makes (resolved names)."""

    name: str
    path: Path
    imports: tuple[str, ...]


def module_name(root: Path, path: Path) -> str:
    parts = list(path.relative_to(root).with_suffix('').parts)
    if parts[-1] == '__init__':
        parts.pop()
    return '.'.join(parts)


def scan(src: Path) -> dict[str, Module]:
    """Every module under ``src/<package>/<package>/`` of every package of the tree, with its
    imports."""
    files = {}
    for package in code_map.tree_packages(src):
        root = src / package
        for path in sorted((root / package).rglob('*.py')):
            files[module_name(root, path)] = path
    modules = {}
    for name, path in files.items():
        found: list[str] = []
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                found += [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                for alias in node.names:
                    candidate = f'{node.module}.{alias.name}'
                    found.append(candidate if candidate in files else node.module)
        modules[name] = Module(name, path, tuple(sorted(set(found))))
    return modules


def is_node(name: str) -> bool:
    return name.rsplit('.', 1)[-1].endswith('_node')


def layer_of(module: Module) -> object | None:
    """The declared layer of a module's folder (None: the folder is not declared)."""
    return code_map.layer(module.name, module.path)


def is_pure(module: Module) -> bool:
    layer = layer_of(module)
    return not (layer is None or not layer.pure or is_node(module.name)
                or module.name.endswith('__main__'))


def rank(module: Module) -> int:
    """Rank inside its package; a node module (an adapter started by name) ranks above
    everything of its package that it may use."""
    layer = layer_of(module)
    assert layer is not None
    return 99 if is_node(module.name) else int(layer.rank)


def is_ros(imported: str) -> bool:
    root = imported.split('.')[0]
    return root in ROS_ROOTS or root.endswith('_msgs')


def violations(modules: dict[str, Module]) -> list[str]:
    """Every break of the rule, one line each."""
    problems = []
    packages = {name.split('.')[0] for name in modules}
    for package in sorted(p for p in packages if p not in LAYERS or p not in ALLOWED_PACKAGES):
        problems.append(f'package {package} (src/{package}/) is declared nowhere: give it its '
                        'layers (LAYERS) and the packages it may import (ALLOWED_PACKAGES) in '
                        'scripts/code_map.py')
    for module in modules.values():
        package = module.name.split('.')[0]
        if package not in LAYERS or package not in ALLOWED_PACKAGES:
            continue  # reported once above
        if layer_of(module) is None:
            folder = code_map.folder_of(module.name, module.path)
            problems.append(f'{module.name}: folder {package}/{folder}/ is in no declared '
                            'layer (scripts/code_map.py LAYERS)')
            continue
        for imported in module.imports:
            target = imported.split('.')[0]
            where = f'{module.name} imports {imported}'
            if is_pure(module) and is_ros(imported):
                problems.append(f'{where}: a pure module imports ROS')
            if target not in packages:
                continue
            if imported not in modules and imported != target:
                continue  # a name inside a module; the module itself is listed too
            if target not in ALLOWED_PACKAGES[package]:
                problems.append(f'{where}: package {package} may not import {target}')
            other = modules.get(imported)
            if other is None or layer_of(other) is None:
                continue
            if is_node(imported):
                problems.append(f'{where}: node modules are started by name, never imported')
            if is_pure(module) and not is_pure(other):
                problems.append(f'{where}: a pure module imports a non-pure one')
            if package == target and rank(other) > rank(module):
                problems.append(f'{where}: layer {rank(module)} may not import layer '
                                f'{rank(other)}')
    problems += [f'import cycle: {" -> ".join(c)}' for c in cycles(modules)]
    return problems


def cycles(modules: dict[str, Module]) -> list[list[str]]:
    """Import cycles between project modules (depth-first search)."""
    found: list[list[str]] = []
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(name: str) -> None:
        state[name] = 1
        stack.append(name)
        for imported in modules[name].imports:
            if imported not in modules or imported == name:
                continue
            if state.get(imported) == 1:
                found.append([*stack[stack.index(imported):], imported])
            elif imported not in state:
                visit(imported)
        stack.pop()
        state[name] = 2

    for name in sorted(modules):
        if name not in state:
            visit(name)
    return found


def test_every_module_follows_the_import_rule() -> None:
    modules = scan(SRC)
    assert len(modules) > 50
    assert violations(modules) == []


def plant(tmp_path: Path, files: dict[str, str]) -> dict[str, Module]:
    """A copy of the tree with extra or replaced modules."""
    for package in code_map.tree_packages(SRC):
        for path in (SRC / package / package).rglob('*.py'):
            target = tmp_path / path.relative_to(SRC)
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_text(path.read_text())
    for relative, text in files.items():
        (tmp_path / relative).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / relative).write_text(text)
    return scan(tmp_path)


def test_planted_violations_are_found(tmp_path: Path) -> None:
    """The checker is not vacuous: each kind of violation, planted once, is reported."""
    # doc-names: off (the modules planted here exist only in the test's tree)
    planted = {
        'trust_av_common/trust_av_common/bad_ros.py': 'import rclpy\n',
        'trust_av_common/trust_av_common/bad_up.py':
            'from trust_monitor.paper_trust import TrustConfig\n',
        'human_driver_sim/human_driver_sim/bad_planner.py':
            'from trust_av_planner.nmpc import PlannerConfig\n',
        'trust_av_planner/trust_av_planner/bad_app.py':
            'from trust_av.system.config import RunConfig\n',
        'trust_av/trust_av/system/bad_graph.py':
            'def f():\n    from trust_av.graph.orchestrator import run_graph\n',
        'trust_av_planner/trust_av_planner/bad_msgs.py': 'from nav_msgs.msg import Odometry\n',
        'preceding_traffic/preceding_traffic/cycle_a.py': 'import preceding_traffic.cycle_b\n',
        'preceding_traffic/preceding_traffic/cycle_b.py': 'import preceding_traffic.cycle_a\n',
        'trust_av/trust_av/webapp/server.py': 'import asyncio\n',
        'trust_av/trust_av/study/bad_node.py':
            'from trust_av_planner.planner_node import PlannerNode\n',
        'trust_av/trust_av/study/uses_cli.py': 'from trust_av.cli.main import main\n',
        'newest_package/newest_package/__init__.py': '',
    }
    found = '\n'.join(violations(plant(tmp_path, planted)))
    assert 'trust_av_common.bad_ros imports rclpy: a pure module imports ROS' in found
    assert ('trust_av_common.bad_up imports trust_monitor.paper_trust: package trust_av_common '
            'may not import trust_monitor') in found
    assert 'bad_planner imports trust_av_planner.nmpc: package human_driver_sim may not' in found
    assert ('bad_app imports trust_av.system.config: package trust_av_planner may not import '
            'trust_av') in found
    assert ('system.bad_graph imports trust_av.graph.orchestrator: layer 1 may not '
            'import layer 2') in found
    assert 'trust_av.webapp.server: folder trust_av/webapp/ is in no declared layer' in found
    assert 'bad_msgs imports nav_msgs.msg: a pure module imports ROS' in found
    assert 'import cycle: preceding_traffic.cycle_a -> preceding_traffic.cycle_b' in found
    assert 'bad_node imports trust_av_planner.planner_node: node modules' in found
    assert 'study.uses_cli imports trust_av.cli.main: layer 4 may not import layer 5' in found
    assert 'package newest_package (src/newest_package/) is declared nowhere' in found
    # doc-names: on


def test_importing_the_pure_core_loads_no_ros() -> None:
    """At run time too (third-party imports included): every pure module, imported in a
    fresh interpreter, leaves rclpy and every message package unloaded."""
    pure = sorted(name for name, module in scan(SRC).items() if is_pure(module))
    assert 'trust_av.system.closed_loop' in pure and 'trust_av_common.ros.qos' not in pure
    code = ('import sys\n'
            f'for m in {pure!r}: __import__(m)\n'
            f'roots = {ROS_ROOTS!r}\n'
            "bad = sorted(m for m in sys.modules if m.split('.')[0] in roots "
            "or m.split('.')[0].endswith('_msgs'))\n"
            'print(bad)\n')
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == '[]', out.stdout


def test_the_largest_modules_are_reported_not_refused(tmp_path: Path) -> None:
    """Module size follows content: about 400 lines is a prompt to look, not a cap, so no
    length fails; scripts/largest_modules.py reports the modules of 400 lines or more,
    largest first, with their longest function (a planted long module heads it)."""
    spec = importlib.util.spec_from_file_location(
        'largest_modules', REPO / 'scripts' / 'largest_modules.py')
    assert spec is not None and spec.loader is not None
    largest = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(largest)
    plant(tmp_path, {'preceding_traffic/preceding_traffic/planted_long.py':
                     '"""A long one."""\n\n\ndef long() -> None:\n' + '    pass\n' * 600})
    report = largest.report(tmp_path).splitlines()
    assert report[1].split() == ['604', 'preceding_traffic/planted_long.py',
                                 '[longest:', 'long()', '601]', 'A', 'long', 'one']
    listed = [int(line.split()[0]) for line in report[1:]]
    assert listed == sorted(listed, reverse=True) and min(listed) >= 400
    assert report[0].startswith(f'{len(listed)} modules of 400 lines or more')


def test_no_function_over_100_lines_without_a_reason_beside_it(tmp_path: Path) -> None:
    """A function of more than 100 lines (docstring included) in any package of the tree has
    its reason written above its ``def`` (``# over 100 lines: ...``), or it is cut: none is
    today. Planted: a long function is named with its length; the same with a reason is not."""
    spec = importlib.util.spec_from_file_location(
        'largest_modules', REPO / 'scripts' / 'largest_modules.py')
    assert spec is not None and spec.loader is not None
    largest = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(largest)
    assert largest.long_functions() == []
    body = '    pass\n' * 100
    plant(tmp_path, {'preceding_traffic/preceding_traffic/planted_long.py':
                     f'"""Two long ones."""\n\n\ndef long() -> None:\n{body}\n\n'
                     f'# over 100 lines: one table, read top to bottom\n'
                     f'def explained() -> None:\n{body}'})
    assert largest.long_functions(tmp_path) == [
        'preceding_traffic/preceding_traffic/planted_long.py:4 long() 101 lines']
