"""Every dotted module name written in the tree names a module or an object that exists.

Docs (``docs/**/*.md``, ``README.md``), docstrings, comments and strings of the Python files
(``src``, ``benchmarks``, ``scripts``, ``tests``, ``examples``) and the params files'
comments name modules of this project (``trust_monitor.paper_trust``,
``trust_av_common.ros.messages.diagnostics``). A module that moves or is renamed leaves such
names behind, and nothing imports them, so nothing fails: this check does. A name resolves
when its longest prefix that is a module of ``src/<package>/<package>/`` exists and the rest
starts with a name that module defines or imports at its top level (a class's members are
then looked up in its body, ``self.<attribute>`` assignments included).

An old import path that still works for one release (a package's ``MOVED`` table,
:mod:`trust_av_common.moved`) is not a current name: it is accepted only where a file says
it names old paths on purpose (``import-rewrite: keep`` anywhere in the file, or between
``import-rewrite: off`` and ``import-rewrite: on``). The changelog is history and is not
checked. Resolution reads the source (ast), it imports nothing.

Usage: ``python scripts/doc_names.py`` prints each unresolved name as ``file:line: name
(why)`` and exits 1 when there is one, 0 otherwise.
"""

from __future__ import annotations

import ast
import re
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parent.parent
SCANNED = ('README.md', 'docs', 'src', 'benchmarks', 'scripts', 'tests', 'examples', 'config')
SUFFIXES = ('.md', '.py', '.yaml')
SKIPPED = ('docs/CHANGELOG.md',)
# the last part of a file name, not an attribute (``config/trust_av.yaml``)
FILE_SUFFIXES = {'py', 'md', 'yaml', 'yml', 'json', 'csv', 'png', 'mcap', 'db3', 'sh', 'txt',
                 'toml', 'cfg', 'xml', 'egg', 'html', 'js', 'npz', 'pt', 'log', 'svg'}


def packages(root: Path = ROOT) -> list[str]:
    """The project's Python packages: ``src/<name>/<name>/__init__.py``."""
    return sorted(p.parent.name for p in (root / 'src').glob('*/*/__init__.py')
                  if p.parent.name == p.parent.parent.name)


@dataclass(frozen=True)
class Unresolved:
    """A dotted name that names nothing (or only an old path) at ``path:line``."""

    path: str
    line: int
    name: str
    why: str

    def __str__(self) -> str:
        return f'{self.path}:{self.line}: {self.name} ({self.why})'


@cache
def _tree(path: Path) -> ast.Module:
    return ast.parse(path.read_text(encoding='utf-8'), str(path))


def _assigned(targets: list[ast.expr]) -> Iterator[str]:
    for target in targets:
        for node in ast.walk(target):
            if isinstance(node, ast.Name):
                yield node.id


def _defined(body: list[ast.stmt]) -> dict[str, ast.stmt]:
    """Names a module or class body defines or imports, with their statement."""
    names: dict[str, ast.stmt] = {}
    for stmt in body:
        if isinstance(stmt, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names[stmt.name] = stmt
        elif isinstance(stmt, ast.Assign):
            names.update((n, stmt) for n in _assigned(stmt.targets))
        elif isinstance(stmt, (ast.AnnAssign, ast.AugAssign)):
            names.update((n, stmt) for n in _assigned([stmt.target]))
        elif isinstance(stmt, (ast.Import, ast.ImportFrom)):
            names.update(((a.asname or a.name).split('.')[0], stmt) for a in stmt.names)
        elif isinstance(stmt, (ast.If, ast.Try)):   # `if TYPE_CHECKING:`, `try: import`
            inner = [*stmt.body, *stmt.orelse,
                     *(s for h in getattr(stmt, 'handlers', []) for s in h.body)]
            names.update(_defined(inner))
    return names


def _members(cls: ast.ClassDef) -> set[str]:
    """A class's members: its body's names and the ``self.<name>`` its methods assign."""
    members = set(_defined(cls.body))
    for node in ast.walk(cls):
        if isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store) and \
                isinstance(node.value, ast.Name) and node.value.id == 'self':
            members.add(node.attr)
    return members


def _module_file(root: Path, parts: list[str]) -> tuple[Path | None, int]:
    """The file of the longest module prefix of ``parts`` and how many parts it takes."""
    package = root / 'src' / parts[0] / parts[0]
    found: tuple[Path | None, int] = (package / '__init__.py', 1)
    here = package
    for i, part in enumerate(parts[1:], start=2):
        if (here / part / '__init__.py').is_file():
            here = here / part
            found = (here / '__init__.py', i)
        elif (here / f'{part}.py').is_file():
            return here / f'{part}.py', i
        else:
            break
    return found


def resolve(name: str, root: Path = ROOT) -> str:
    """'' when ``name`` names a module or an object of this tree, else why not."""
    parts = name.split('.')
    module, used = _module_file(root, parts)
    if module is None or not module.is_file():
        return 'no such package'
    rest = parts[used:]
    if not rest:
        return ''
    defined = _defined(_tree(module).body)
    module_name = '.'.join(parts[:used])
    if rest[0] not in defined:
        if module.name == '__init__.py' and (module.parent / rest[0]).exists():
            return f'{module_name}.{rest[0]} is a folder that is not a package'
        return f'{module_name} has no {rest[0]!r}'
    stmt = defined[rest[0]]
    if len(rest) > 1 and isinstance(stmt, ast.ClassDef) and rest[1] not in _members(stmt):
        return f'{module_name}.{rest[0]} has no member {rest[1]!r}'
    return ''


def _moved(root: Path) -> dict[str, str]:
    """Every package's MOVED table: old path -> new path."""
    moved: dict[str, str] = {}
    for package in packages(root):
        init = root / 'src' / package / package / '__init__.py'
        stmt = _defined(_tree(init).body).get('MOVED')
        if isinstance(stmt, (ast.Assign, ast.AnnAssign)) and stmt.value is not None:
            moved.update(ast.literal_eval(stmt.value))
    return moved


def _old_path(name: str, moved: dict[str, str]) -> str | None:
    for old in sorted(moved, key=len, reverse=True):
        if name == old or name.startswith(old + '.'):
            return moved[old] + name[len(old):]
    return None


def _kept_lines(text: str) -> set[int]:
    """Lines (1-based) that name old paths or made-up names on purpose: the whole file
    after ``import-rewrite: keep``, the lines between ``import-rewrite: off`` (or
    ``doc-names: off``, for a test's planted names) and the next ``... on``."""
    lines = text.splitlines()
    if any('import-rewrite: keep' in line for line in lines):
        return set(range(1, len(lines) + 1))
    kept: set[int] = set()
    off = False
    for number, line in enumerate(lines, start=1):
        if 'import-rewrite: off' in line or 'doc-names: off' in line:
            off = True
        elif 'import-rewrite: on' in line or 'doc-names: on' in line:
            off = False
        if off:
            kept.add(number)
    return kept


def files(root: Path = ROOT) -> Iterator[Path]:
    """The scanned files."""
    for entry in SCANNED:
        path = root / entry
        candidates = [path] if path.is_file() else sorted(path.rglob('*')) if path.is_dir() \
            else []
        for file in candidates:
            relative = _shown(file, root)
            if file.suffix in SUFFIXES and file.is_file() and relative not in SKIPPED and \
                    not any(part.startswith('.') or part in ('__pycache__', 'build', 'install')
                            for part in file.relative_to(root).parts):
                yield file


def _pattern(root: Path) -> re.Pattern[str]:
    names = '|'.join(re.escape(p) for p in packages(root))
    return re.compile(rf'(?<![\w./-])(?:{names})(?:\.[A-Za-z_]\w*)+')


def _strings(tree: ast.Module) -> Iterator[str]:
    """The string constants of a module that are not docstrings (an f-string's parts)."""
    docstrings = {id(node.body[0].value) for node in ast.walk(tree)
                  if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef,
                                       ast.AsyncFunctionDef))
                  and node.body and isinstance(node.body[0], ast.Expr)
                  and isinstance(node.body[0].value, ast.Constant)}
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and \
                id(node) not in docstrings:
            yield node.value


def keys(root: Path = ROOT) -> set[str]:
    """Dotted names the code uses as keys, not as modules: entry-point groups
    (``trust_av.predictors``), bag metadata keys (``trust_av.drive.start_ns``, and the
    prefix ``trust_av.component.`` of an f-string's key). A string constant of the code
    (not a docstring) that starts with a package name and names no module is a key."""
    pattern = _pattern(root)
    found: set[str] = set()
    for file in sorted((root / 'src').rglob('*.py')):
        for text in _strings(_tree(file)):
            match = pattern.match(text)
            if match and match.group(0) == text.rstrip('.') and resolve(match.group(0), root):
                found.add(text)
    return found


def _used(code: list[Path]) -> set[str]:
    """Every name the code uses for a variable, an argument or an attribute."""
    used: set[str] = set()
    for path in code:
        for node in ast.walk(_tree(path)):
            if isinstance(node, ast.Name):
                used.add(node.id)
            elif isinstance(node, ast.arg):
                used.add(node.arg)
            elif isinstance(node, ast.Attribute):
                used.add(node.attr)
    return used


def _code(root: Path) -> list[Path]:
    return [p for d in ('src', 'tests', 'benchmarks', 'scripts', 'examples')
            for p in (root / d).rglob('*.py')]


def short_names(root: Path = ROOT) -> dict[str, str]:
    """A module's last name -> its full name, for the modules of ``src`` whose last name
    is unique and never a variable's (``paper_trust.TrustEstimator`` is checked as
    ``trust_monitor.paper_trust.TrustEstimator``; ``planner.step`` is not checked)."""
    modules: dict[str, list[str]] = {}
    for package in packages(root):
        base = root / 'src' / package
        for path in (base / package).rglob('*.py'):
            dotted = '.'.join(path.relative_to(base).with_suffix('').parts)
            if path.stem != '__init__':
                modules.setdefault(path.stem, []).append(dotted)
    used = _used(_code(root))
    return {stem: full[0] for stem, full in modules.items()
            if len(full) == 1 and stem not in used and '_' in stem}


def former_modules(root: Path = ROOT) -> set[str]:
    """Module names (a file's stem) that a package of ``src`` had and has no more: the
    last part of every old path in a ``MOVED`` table, and every module file in the git
    history of ``src`` (when the tree is a git checkout)."""
    former = {old.rsplit('.', 1)[-1] for old in _moved(root)}   # trust_interface
    history = subprocess.run(['git', 'log', '--all', '--name-only', '--pretty=format:', '--',
                              'src'], cwd=root, capture_output=True, text=True, check=False)
    former |= {Path(line).stem for line in history.stdout.splitlines()
               if line.endswith('.py') and not Path(line).stem.startswith('_')}
    code = _code(root)
    current = {p.stem for p in code} | {p.parent.name for p in code if p.stem == '__init__'}
    # a name the code uses for a variable, an argument or an attribute (``drive.ratings``,
    # ``graph.specs``) says nothing of a module
    return former - current - _used(code)


def parameters(root: Path = ROOT) -> set[str]:
    """``node.parameter`` for every parameter of a node section of ``config/*.yaml``
    (``preceding_traffic.trace``: the params-file notation, not a module)."""
    found: set[str] = set()
    for path in sorted((root / 'config').glob('*.yaml')):
        for section, body in (yaml.safe_load(path.read_text(encoding='utf-8')) or {}).items():
            node = str(section).rsplit('/', 1)[-1]
            params = (body or {}).get('ros__parameters') or {}
            found.update(f'{node}.{name}' for name in params)
    return found


def _is_key(name: str, declared: set[str]) -> bool:
    return name in declared or any((key.endswith('.') and name.startswith(key)) or
                                   key.startswith(name + '.') for key in declared)


def _shown(file: Path, root: Path) -> str:
    return file.relative_to(root).as_posix() if file.is_relative_to(root) else str(file)


def check(root: Path = ROOT, scanned: list[Path] | None = None) -> list[Unresolved]:
    """Every unresolved dotted name in ``scanned`` (default: :func:`files`)."""
    pattern = _pattern(root)
    moved = _moved(root)
    declared = keys(root) | parameters(root)
    former = former_modules(root)
    short = short_names(root)
    bare_current = re.compile(rf'(?<![\w./-])({"|".join(sorted(short)) or "(?!)"})'
                              r'((?:\.[A-Za-z_]\w*)+)')
    bare = re.compile(rf'(?<![\w./-])({"|".join(sorted(former)) or "(?!)"})\.([A-Za-z_]\w*)')
    found: list[Unresolved] = []
    for file in scanned if scanned is not None else list(files(root)):
        text = file.read_text(encoding='utf-8')
        kept = _kept_lines(text)
        for number, line in enumerate(text.splitlines(), start=1):
            if number in kept:
                continue
            for match in pattern.finditer(line):
                name = match.group(0)
                if name.rsplit('.', 1)[1] in FILE_SUFFIXES:
                    continue
                new = _old_path(name, moved)
                if new is not None:
                    found.append(Unresolved(_shown(file, root), number,
                                            name, f'an old path: now {new}'))
                    continue
                why = resolve(name, root)
                if why and not _is_key(name, declared):
                    found.append(Unresolved(_shown(file, root), number, name,
                                            why))
            for match in bare_current.finditer(line):
                full = short[match.group(1)] + match.group(2)
                if match.group(2).rsplit('.', 1)[1] not in FILE_SUFFIXES and \
                        resolve(full, root):
                    found.append(Unresolved(_shown(file, root), number,
                                            match.group(0), resolve(full, root)))
            for match in bare.finditer(line):
                if match.group(2) not in FILE_SUFFIXES:
                    found.append(Unresolved(_shown(file, root), number,
                                            match.group(0),
                                            f'module {match.group(1)} is gone'))
    return found


def main() -> int:
    """Print the unresolved names; exit 1 if there is one."""
    found = check()
    for item in found:
        print(item)
    print(f'{len(found)} unresolved dotted module names', file=sys.stderr)
    return 1 if found else 0


if __name__ == '__main__':
    sys.exit(main())
