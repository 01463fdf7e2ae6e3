"""Each package.xml declares what its package imports, so that ``rosdep install`` leaves no
ImportError, and declares nothing it does not use.

The imports come from the code itself (every ``import`` in the AST, at module level or
inside functions), plus the message packages of the topic table for a package that builds
message classes by name (the recorder subscribes to every topic of
``trust_av_common.topics``). Third-party modules map to rosdep keys of rosdistro's
``rosdep/python.yaml`` (ros/rosdistro @ 8468e88, 2026-08-22): ``python3-numpy`` (line 5923),
``python3-yaml`` (9553), ``python3-matplotlib`` (5437), ``python3-tqdm`` (9009),
``python3-torch`` (8957: Ubuntu ``python3-torch`` from noble on), ``python3-scipy``, and
three keys that rosdep
installs with pip: ``casadi-pip`` (149), ``python3-rosbags-pip`` (7996) and
``mcap-ros2-support`` (328; the ``mcap`` module is its dependency). No key exists for
``ray`` (an optional extra, pip only, imported only inside the function that uses it).
"""

from __future__ import annotations

import ast
import hashlib
import os
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
from catkin_pkg.package import parse_package
from support.paths import REPO, tree_packages

from trust_av_common.topics import TOPICS

SRC = REPO / 'src'
PACKAGES = tree_packages()
ROSDEP_KEYS = {
    'numpy': 'python3-numpy',
    'yaml': 'python3-yaml',
    'matplotlib': 'python3-matplotlib',
    'tqdm': 'python3-tqdm',
    'torch': 'python3-torch',
    'scipy': 'python3-scipy',
    'casadi': 'casadi-pip',
    'rosbags': 'python3-rosbags-pip',
    'mcap': 'mcap-ros2-support',
    'pandas': 'python3-pandas',
    'websockets': 'python3-websockets',
}
"""Python module -> rosdep key (rosdistro rosdep/python.yaml; see the module docstring)."""
ROS_PACKAGES = {'rclpy', 'rcl_interfaces', 'builtin_interfaces', 'ament_index_python',
                'std_msgs', 'nav_msgs', 'geometry_msgs', 'trajectory_msgs', 'diagnostic_msgs',
                'rosgraph_msgs', 'tf2_msgs', 'visualization_msgs', 'sensor_msgs', 'lifecycle_msgs',
                'autoware_perception_msgs', 'autoware_control_msgs', *PACKAGES}
"""Modules that are ROS 2 packages: the key is the package name."""
OPTIONAL = {'ray': 'pip install ray==2.60.0 (trust-av reproduce --executor ray)'}
"""Modules with no rosdep key, installed by a documented pip step, imported lazily."""


def imports(package: str) -> tuple[set[str], set[str], bool]:
    """Top-level modules imported anywhere in a package, those imported at module level,
    and whether it builds message classes by name (``message_class``)."""
    anywhere: set[str] = set()
    top: set[str] = set()
    by_name = False
    for path in (SRC / package / package).rglob('*.py'):
        tree = ast.parse(path.read_text(), str(path))
        module_level = {id(node) for node in tree.body}
        for node in ast.walk(tree):
            names: list[str] = []
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                names = [node.module]
                by_name |= any(alias.name == 'message_class' for alias in node.names) and \
                    package != 'trust_av_common'
            roots = {name.split('.')[0] for name in names}
            anywhere |= roots
            if id(node) in module_level:
                top |= roots
    third_party = {m for m in anywhere if m not in sys.stdlib_module_names}
    return third_party, top, by_name


def declared(package: str) -> set[str]:
    root = ET.parse(SRC / package / 'package.xml').getroot()
    return {e.text or '' for e in root if e.tag in ('depend', 'exec_depend')}


def needed(package: str) -> set[str]:
    modules, _, by_name = imports(package)
    keys = set()
    for module in modules - {package} - set(OPTIONAL):
        if module in ROS_PACKAGES:
            keys.add(module)
        else:
            assert module in ROSDEP_KEYS, f'{package} imports {module}: add its rosdep key'
            keys.add(ROSDEP_KEYS[module])
    if by_name:
        keys |= {topic.msgtype.split('/')[0] for topic in TOPICS}
    return keys


@pytest.mark.parametrize('package', PACKAGES)
def test_package_xml_declares_what_the_package_imports(package: str) -> None:
    missing = needed(package) - declared(package)
    unused = declared(package) - needed(package)
    assert not missing, f'{package}/package.xml misses {sorted(missing)}'
    assert not unused, f'{package}/package.xml declares unused {sorted(unused)}'


def test_optional_modules_are_imported_lazily_and_documented() -> None:
    readme = (SRC.parent / 'docs' / 'operations' / 'colcon.md').read_text()
    for package in PACKAGES:
        modules, top, _ = imports(package)
        for module, step in OPTIONAL.items():
            assert module not in top, f'{package} imports {module} at module level'
            if module in modules:
                assert step.split(' (')[0] in readme


def test_the_check_sees_imports_inside_functions() -> None:
    """torch is imported only inside functions of trust_av: still required."""
    modules, top, by_name = imports('trust_av')
    assert 'torch' in modules and 'torch' not in top and by_name
    assert 'python3-torch' in needed('trust_av')


@pytest.mark.parametrize('package', PACKAGES)
def test_package_xml_is_what_rosdep_reads(package: str) -> None:
    """catkin_pkg (the parser of rosdep and colcon-ros) reads it as format 3 with no
    warnings (an unescaped '&' in a description made two of them unreadable)."""
    warnings: list[str] = []
    manifest = parse_package(SRC / package / 'package.xml', warnings=warnings)
    assert (manifest.name, manifest.package_format, warnings) == (package, 3, [])
    assert {d.name for d in manifest.exec_depends} == declared(package)


REPOSITORY_TESTS = {'test_colcon', 'test_suite_groups', 'test_layout', 'test_benchmarks',
                    'test_packages', 'test_docs', 'test_example_plugin',
                    'test_compare_trust_models', 'test_cli_fuzz', 'test_limits', 'test_code_map',
                    'test_first_result', 'test_typing_report', 'test_docs_examples',
                    'test_moved_imports', 'test_public_api', 'test_suite_layout',
                    'test_dead_code', 'test_setup_pins'}
"""Test modules about the repository as a whole (the packages together, the suite, the
benchmarks), which no single package's ``colcon test`` runs."""


def test_each_test_module_is_one_package_s_or_the_repository_s() -> None:
    """``colcon test`` runs pytest in each package's directory; its setup.cfg points pytest at
    that package's modules of tests/ (``testpaths``). Every module is in exactly one list,
    or is one of the repository's own (:data:`REPOSITORY_TESTS`); a new test module missing
    from both is named with the line to add and the package it imports most."""
    problems = ownership_problems(SRC.parent / 'tests')
    assert problems == [], '\n'.join(problems)


def test_a_new_test_module_is_named_with_the_line_to_add(tmp_path: Path) -> None:
    """Not vacuous: a test module in a tier folder and in no list is named, with the
    setup.cfg line and the package it imports most."""
    (tmp_path / 'tests' / 'core').mkdir(parents=True)
    (tmp_path / 'tests' / 'core' / 'test_brand_new.py').write_text(
        'from trust_monitor.paper_trust import TrustConfig\nimport trust_av_common.params\n'
        'from trust_monitor.estimate import main\n')
    planted = 'tests/core/' + 'test_brand_new.py'   # (split: not a cited test file)
    assert ownership_problems(tmp_path / 'tests')[0] == (
        f"{planted} is in no package's setup.cfg testpaths: add the line "
        f'"    ../../{planted}" to src/trust_monitor/setup.cfg (the package '
        'it imports most), or name test_brand_new in REPOSITORY_TESTS '
        '(tests/core/test_packages.py) if it tests the repository as a whole')


def ownership_problems(tests: Path) -> list[str]:
    """Each test module under ``tests`` that no package's ``testpaths`` or
    :data:`REPOSITORY_TESTS` names (or two name), one line each saying what to do."""
    import configparser
    from collections import Counter

    owners: dict[str, list[str]] = {}
    problems = []
    for package in PACKAGES:
        config = configparser.ConfigParser()
        config.read(SRC / package / 'setup.cfg')
        for path in config['tool:pytest']['testpaths'].split():
            module = (SRC / package / path).resolve()
            if not module.is_file():
                problems.append(f'src/{package}/setup.cfg: testpaths names {path}, which does '
                                'not exist: remove the line')
            owners.setdefault(module.stem, []).append(package)
    for path in sorted(tests.rglob('test_*.py')):
        module, where = path.stem, path.relative_to(tests.parent)
        if len(owners.get(module, [])) > 1:
            problems.append(f'{where} is in the testpaths of {" and ".join(owners[module])}: '
                            'keep it in one')
        elif module not in owners and module not in REPOSITORY_TESTS:
            imported = Counter(name.split('.')[0] for node in ast.walk(ast.parse(
                path.read_text(), str(path))) for name in (
                [a.name for a in node.names] if isinstance(node, ast.Import) else
                [node.module] if isinstance(node, ast.ImportFrom) and node.module else [])
                if name.split('.')[0] in PACKAGES)
            most = imported.most_common(1)[0][0] if imported else 'PACKAGE'
            problems.append(f"{where} is in no package's setup.cfg testpaths: add the line "
                            f'"    ../../{where}" to src/{most}/setup.cfg (the package it '
                            f'imports most), or name {module} in REPOSITORY_TESTS '
                            '(tests/core/test_packages.py) if it tests the repository as a whole')
    known = {path.stem for path in tests.rglob('test_*.py')}
    problems += [f'REPOSITORY_TESTS names {m}, which is no test module: remove it'
                 for m in sorted(REPOSITORY_TESTS - known)]
    return problems


@pytest.mark.parametrize('package', PACKAGES)
def test_colcon_test_knows_the_suite_s_markers(package: str) -> None:
    """``colcon test`` runs pytest with the package's setup.cfg and ``--strict-markers``: a
    marker the suite sets (conftest.py marks every test by its tier folder) that the file
    does not declare is an error there, and the package's tests do not run at all."""
    import configparser
    import tomllib

    def names(lines: list[str]) -> set[str]:
        return {line.split(':', 1)[0].strip() for line in lines if line.strip()}

    suite = tomllib.loads((REPO / 'pyproject.toml').read_text())['tool']['pytest']
    cfg = configparser.ConfigParser()
    cfg.read(SRC / package / 'setup.cfg')
    declared = names(cfg['tool:pytest']['markers'].splitlines())
    assert declared == names(suite['ini_options']['markers'])


def test_the_drive_page_s_files_ship_in_the_package_and_are_served_from_it(
        tmp_path: Path) -> None:
    """What ``pip install`` and ``colcon build`` install of trust_av (setup.py ``build_py``:
    its modules and ``package_data``) holds every file of the drive page, the vendored
    library and its licence included, and the drive server serves every page file from that
    copy byte for byte."""
    import subprocess

    built = subprocess.run([sys.executable, 'setup.py', '-q', 'build_py', '--build-lib',
                            str(tmp_path)], cwd=SRC / 'trust_av', capture_output=True,
                           text=True, check=False)
    assert built.returncode == 0, built.stderr
    web = SRC / 'trust_av' / 'trust_av' / 'drive' / 'web'
    shipped = tmp_path / 'trust_av' / 'drive' / 'web'
    files = sorted(str(p.relative_to(web)) for p in web.rglob('*') if p.is_file())
    assert sorted(str(p.relative_to(shipped)) for p in shipped.rglob('*') if p.is_file()) \
        == files
    assert {'vendor/konva/konva.min.js', 'vendor/konva/LICENSE', 'vendor/README.md'} <= \
        set(files)
    served = subprocess.run(
        [sys.executable, '-c', 'import hashlib, trust_av.drive.server as s; '
         'print(s.__file__); [print(p, hashlib.sha256(s.page_file(n)).hexdigest()) '
         'for p, (n, _) in sorted(s.PAGES.items())]'],
        env={**os.environ, 'PYTHONPATH': str(tmp_path)}, capture_output=True, text=True,
        check=False)
    assert served.returncode == 0, served.stderr
    module, *pages = served.stdout.splitlines()
    assert Path(module).is_relative_to(tmp_path)
    from trust_av.drive.server import PAGES
    assert pages == [f'{path} {hashlib.sha256((web / name).read_bytes()).hexdigest()}'
                     for path, (name, _) in sorted(PAGES.items())]
    assert '/vendor/konva/konva.min.js' in PAGES
