"""Old import paths of moved modules, kept working for one release with a warning.

A package whose modules moved installs a :class:`MovedModules` finder from its
``__init__``: importing an old name (``trust_monitor.common.params``) then warns with a
:class:`MovedPathWarning` naming the new one and gives the new module itself
(``trust_av_common.params``: the same module object, so classes, registries and module
state are shared, never copied). A moved package's old name covers its submodules, also
one added after the move. ``python -m`` with an old name runs the new module (its file is
the program's ``sys.argv[0]``, as ``rclpy.init`` needs); an old name whose new module does
not exist (``old_package.never_was``, an old package's ``__main__``) is a
``ModuleNotFoundError`` that names the package's new place.

The warning is a :class:`FutureWarning`, not a :class:`DeprecationWarning`: Python's default
filters hide a DeprecationWarning unless the code that triggers it is ``__main__`` (PEP 565),
and an old import is in a plug-in's module, imported by ``trust-av``, so its author would
never see it. A FutureWarning is shown by default, once per importing line, in every
command's output (stderr), pointed at the plug-in's file and line.
"""

# import-rewrite: keep (the docstring's example names an old path on purpose)

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
import warnings
from collections.abc import Mapping
from importlib.machinery import ModuleSpec
from types import CodeType, ModuleType

__all__ = ['MovedModules', 'MovedPathWarning', 'install']

RELEASE_NOTE = 'the old path goes in the next release'


class MovedPathWarning(FutureWarning):
    """An old import path or name was used (the message names the new one); shown by
    default wherever the import is, a plug-in's module included (see the module notes)."""


class MovedModules(importlib.abc.MetaPathFinder, importlib.abc.InspectLoader):
    """A meta-path finder and loader that answers only for the old names it maps.

    Args:
        moves: old module or package name -> new name. A package's entry covers its
            submodules (``old.sub`` -> ``new.sub``); an entry for a submodule wins over its
            package's.
    """

    def __init__(self, moves: Mapping[str, str]) -> None:
        self.moves = dict(moves)
        self._longest_first = sorted(self.moves, key=len, reverse=True)

    def new_name(self, fullname: str) -> str | None:
        """The new name of an old module name (None: not a moved name)."""
        if fullname in self.moves:
            return self.moves[fullname]
        for old in self._longest_first:
            if fullname.startswith(old + '.'):
                return self.moves[old] + fullname[len(old):]
        return None

    def find_spec(self, fullname: str, path: object = None,
                  target: ModuleType | None = None) -> ModuleSpec | None:
        new = self.new_name(fullname)
        if new is None:
            return None
        found = importlib.util.find_spec(new)
        if found is None:   # the old package moved, but this module is not in its new place
            old_package = max((old for old in self.moves if fullname.startswith(old + '.')),
                              key=len)
            raise ModuleNotFoundError(
                f'No module named {fullname!r}: {old_package} moved to '
                f'{self.moves[old_package]}, which has no {fullname[len(old_package) + 1:]}',
                name=fullname)
        # the new module's file as the origin: ``python -m`` puts it in sys.argv[0]
        return importlib.util.spec_from_loader(fullname, self, origin=found.origin)

    def create_module(self, spec: ModuleSpec) -> ModuleType | None:
        return None  # the default module, replaced by the new one in exec_module

    def exec_module(self, module: ModuleType) -> None:
        old = module.__name__
        new = self._warned(old)
        moved = importlib.import_module(new)
        renamed = {name[len(old) + 1:] for name in self.moves
                   if name.startswith(old + '.') and '.' not in name[len(old) + 1:]}
        if renamed and hasattr(moved, '__path__'):
            _answer_old_children(moved, old, renamed)
        # the import system returns what sys.modules holds under the old name after this
        sys.modules[old] = moved

    def is_package(self, fullname: str) -> bool:
        spec = importlib.util.find_spec(self._new(fullname))
        return spec is not None and spec.submodule_search_locations is not None

    def get_code(self, fullname: str) -> CodeType | None:
        """The new module's code (``python -m old.name``)."""
        new = self._warned(fullname)
        spec = importlib.util.find_spec(new)
        if spec is None or not isinstance(spec.loader, importlib.abc.InspectLoader):
            raise ImportError(f'{fullname} moved to {new}, which has no code', name=fullname)
        return spec.loader.get_code(new)

    def get_source(self, fullname: str) -> str | None:
        new = self._new(fullname)
        spec = importlib.util.find_spec(new)
        if spec is None or not isinstance(spec.loader, importlib.abc.InspectLoader):
            return None
        return spec.loader.get_source(new)

    def _new(self, fullname: str) -> str:
        new = self.new_name(fullname)
        if new is None:
            raise ImportError(f'{fullname} is not a moved module', name=fullname)
        return new

    def _warned(self, fullname: str) -> str:
        new = self._new(fullname)
        warnings.warn(f'{fullname} moved to {new}: import {new}; {RELEASE_NOTE}',
                      MovedPathWarning, stacklevel=_importer_level())
        return new


def _answer_old_children(package: ModuleType, old: str, children: set[str]) -> None:
    """``from old import child`` for a child that moved apart from its package (looked up
    as an attribute of the new package): the package answers those names through the old
    full name, which warns and gives the child's new module."""
    before = package.__dict__.get('__getattr__')

    def answer(name: str) -> object:
        if name in children:
            return importlib.import_module(f'{old}.{name}')
        if before is not None:
            return before(name)
        raise AttributeError(f'module {package.__name__!r} has no attribute {name!r}')

    package.__getattr__ = answer  # type: ignore[method-assign]


def _importer_level() -> int:
    """The ``stacklevel`` that points a warning issued in this module at the code whose
    import started it (past the import system's frames, which :func:`warnings.warn` itself
    skips without counting them)."""
    frame = sys._getframe(1)  # the frame that calls warnings.warn: stacklevel 1
    level = 1
    while frame.f_back is not None and (frame.f_code.co_filename == __file__
                                        or _is_import_system(frame.f_code.co_filename)
                                        or frame.f_code.co_filename.endswith(_PASSED)
                                        or frame.f_code.co_filename == '<frozen runpy>'):
        frame = frame.f_back
        if not _is_import_system(frame.f_code.co_filename):
            level += 1
    return level


_PASSED = ('runpy.py', 'importlib/__init__.py')
"""Files between an import statement (or ``python -m``) and this module, besides the import
system's own frames."""


def _is_import_system(filename: str) -> bool:
    """The frames warnings.warn skips (its own rule: importlib's _bootstrap modules)."""
    return 'importlib' in filename and '_bootstrap' in filename


def install(moves: Mapping[str, str]) -> MovedModules:
    """Put a :class:`MovedModules` for ``moves`` first on :data:`sys.meta_path` (first, so
    that a stale folder of an old package cannot be found as a namespace package)."""
    finder = MovedModules(moves)
    sys.meta_path.insert(0, finder)
    return finder
