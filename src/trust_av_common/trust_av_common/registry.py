"""Registries of interchangeable components (the project's: plan estimators, trust models,
human drivers).

A component is found by name in a Python entry-point group, so a package installed with
pip adds one without an edit to this repository. The shipped components are registered the
same way (in the ``setup.py`` of the package that holds them). An entry point names a
:class:`Component` object::

    entry_points={'trust_av.predictors': ['cv = my_pkg.cv:COMPONENT']}

The registry is generic: it knows no group. The package that owns a group's interface
declares it (:func:`declare`: how the group's ``factory`` is called and what the object it
returns must have), beside that interface: ``trust_av_planner.predictors.PREDICTORS``,
``trust_monitor.model_interface.TRUST_MODELS``, ``human_driver_sim.followers.DRIVERS``.
The registry only finds, checks and lists components. Callers decide from a component's
declaration (``config_type``, ``needs``), never from its name.
"""

from __future__ import annotations

import dataclasses
import functools
import inspect
import logging
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from importlib.metadata import EntryPoint, entry_points
from typing import Any

from trust_av_common.errors import TrustAvError, did_you_mean, one_line

__all__ = ['FOLLOWER_STATE', 'KNOWN_NEEDS', 'Component', 'Group', 'RegistryError', 'build',
           'components', 'config_of', 'config_types', 'declare', 'describe', 'get', 'groups',
           'names', 'not_one_of']

LOG = logging.getLogger(__name__)

FOLLOWER_STATE = 'follower_state'
"""A need: the component uses the human follower's odometry (not only the AV's)."""
KNOWN_NEEDS = frozenset({FOLLOWER_STATE})


class RegistryError(TrustAvError):
    """A component name is not registered, or a registered entry point is not a valid
    :class:`Component`; the message names the group and the name."""


@dataclass(frozen=True)
class Group:
    """An entry-point group, as the package that owns its interface declares it.

    Attributes:
        name: the entry-point group (``trust_av.predictors``).
        factory_arguments: how a component's ``factory`` is called: the names of its
            positional arguments (the group's shared configuration, the component's own
            parameters).
        interface: what the object the factory returns must have (attribute names).
    """

    name: str
    factory_arguments: tuple[str, ...]
    interface: tuple[str, ...]


_DECLARED: dict[str, Group] = {}


def declare(name: str, factory_arguments: Sequence[str], interface: Sequence[str]) -> str:
    """Declare the group ``name`` (from the module that defines its interface) and return
    the name, the key every function here takes. Declaring it again the same way is a no-op.

    Raises:
        RegistryError: it is declared already, differently.
    """
    group = Group(name, tuple(factory_arguments), tuple(interface))
    known = _DECLARED.setdefault(name, group)
    if known != group:
        raise RegistryError(f'component group {name!r} is declared twice, differently: '
                            f'{known} and {group}')
    return name


def groups() -> tuple[str, ...]:
    """The declared groups, sorted (those whose owning modules are imported)."""
    return tuple(sorted(_DECLARED))


def _declared(group: str) -> Group:
    try:
        return _DECLARED[group]
    except KeyError:
        raise RegistryError(f'unknown component group {group!r} (known: '
                            f'{list(groups())})') from None


@dataclass(frozen=True)
class Component:
    """One registered model.

    Attributes:
        name: the name it is chosen by (params files, command line); equals the entry
            point's name.
        factory: builds the model; its arguments are fixed by the group's interface.
        config_type: frozen dataclass of its parameters (declared with
            :func:`trust_av_common.params.param`), or None when it has none. Its
            fields are the component's parameters, declared as ROS parameters under the
            component's name.
        needs: what it needs beyond the AV's own state (:data:`KNOWN_NEEDS`).
        description: one line for ``--help``.
    """

    name: str
    factory: Callable[..., Any]
    config_type: type | None = None
    needs: frozenset[str] = field(default_factory=frozenset)
    description: str = ''

    def __post_init__(self) -> None:
        if not re.fullmatch(r'[a-z][a-z0-9_]*', self.name):
            raise RegistryError(f'component name {self.name!r} is not a lower-case '
                                'identifier')
        if self.config_type is not None and not dataclasses.is_dataclass(self.config_type):
            raise RegistryError(f'component {self.name!r}: config_type must be a dataclass')
        unknown = set(self.needs) - KNOWN_NEEDS
        if unknown:
            raise RegistryError(f'component {self.name!r} needs unknown {sorted(unknown)} '
                                f'(known: {sorted(KNOWN_NEEDS)})')


def not_one_of(what: str, name: str, known: Sequence[str]) -> str:
    """The one line refusing ``name`` for ``what`` (a parameter that names a registered
    component), with a "did you mean" from ``known``."""
    return f'{what} must be one of {list(known)}, got {name!r}{did_you_mean(name, known)}'


def _group_name(group: str) -> str:
    return group.rsplit('.', 1)[-1].rstrip('s').replace('_', ' ')


def describe(group: str, name: str) -> str:
    """How a message names a component: ``predictor 'ses' (trust_av.predictors)``."""
    return f'{_group_name(group)} {name!r} ({group})'


@functools.cache
def _entry_points(group: str) -> tuple[EntryPoint, ...]:
    """The entry points of ``group``, scanned once per process (a scan of every installed
    distribution takes 0.1-0.3 s; a plug-in installed later is seen by the next process)."""
    return tuple(entry_points(group=group))


def names(group: str) -> tuple[str, ...]:
    """The registered names of ``group``, sorted (for ``--help`` and choices)."""
    _declared(group)
    return tuple(sorted({ep.name for ep in _entry_points(group)}))


def get(group: str, name: str) -> Component:
    """The component registered as ``name`` in ``group``.

    Raises:
        RegistryError: ``name`` is not registered (the message lists the registered names),
            two distributions register it, or its entry point fails to load (any exception
            or ``SystemExit`` while importing it; ``KeyboardInterrupt`` passes), is not a
            :class:`Component` of that name, or its factory cannot be called as the group
            calls it (its :class:`Group`'s ``factory_arguments``).
    """
    _declared(group)
    found = [ep for ep in _entry_points(group) if ep.name == name]
    if not found:
        raise RegistryError(f'unknown {_group_name(group)} {name!r} (registered: '
                            f'{", ".join(names(group)) or "none"})'
                            f'{did_you_mean(name, names(group))}')
    if len({ep.value for ep in found}) > 1:
        raise RegistryError(f'{_group_name(group)} {name!r} is registered twice: '
                            f'{", ".join(sorted(ep.value for ep in found))}')
    loaded = _load(group, found[0])
    if isinstance(loaded, RegistryError):   # a fresh one each time, with the original cause
        raise RegistryError(str(loaded)) from loaded.__cause__
    return loaded


@functools.cache
def _load(group: str, entry: EntryPoint) -> Component | RegistryError:
    """The checked component of ``entry``, or the error that says why it is none (kept, so
    that a module failing at import is imported once per process)."""
    where = f'{_group_name(group)} {entry.name!r} ({entry.value})'
    try:
        obj = entry.load()
    except KeyboardInterrupt:
        raise
    except BaseException as err:   # SystemExit at import too: a plug-in never ends a command
        failed = RegistryError(f'{where} failed to load: {type(err).__name__}: '
                               f'{one_line(err)}')
        failed.__cause__ = err
        return failed
    if not isinstance(obj, Component):
        return RegistryError(f'{where} is a {type(obj).__name__}, not a Component')
    if obj.name != entry.name:
        return RegistryError(f'{where} is named {obj.name!r} inside')
    wanted = _declared(group).factory_arguments
    try:
        inspect.signature(obj.factory).bind(*wanted)
    except TypeError as err:
        return RegistryError(f'{where}: its factory{_signature(obj.factory)} cannot be called '
                             f'as factory({", ".join(wanted)}) ({one_line(err)})')
    return obj


def _signature(factory: Callable[..., Any]) -> str:
    try:
        return str(inspect.signature(factory))
    except (TypeError, ValueError):
        return ''


def _short(value: Any) -> str:
    text = ' '.join(repr(value).split())
    return text if len(text) <= 60 else text[:57] + '...'


def build(group: str, component: Component, shared: Any, params: Any) -> Any:
    """``component.factory(shared, params)``, checked: whatever the factory raises (any
    exception or ``SystemExit``; ``KeyboardInterrupt`` passes) and an object without the
    group's interface (its :class:`Group`'s ``interface``) are one line naming the
    component.

    Args:
        group: the component's group.
        component: the component (:func:`get`).
        shared: the group's shared configuration (the factory's first argument).
        params: the component's own parameters (:func:`config_of`).

    Raises:
        RegistryError: the factory failed or returned something else.
    """
    where = describe(group, component.name)
    try:
        built = component.factory(shared, params)
    except (KeyboardInterrupt, RegistryError):
        raise
    except BaseException as err:
        raise RegistryError(f'{where}: its factory raised {type(err).__name__}: '
                            f'{one_line(err)}') from err
    missing = [a for a in _declared(group).interface if not hasattr(built, a)]
    if missing:
        raise RegistryError(f'{where}: its factory returned {_short(built)} '
                            f'({type(built).__name__}), not a {_group_name(group)}: it lacks '
                            f'{", ".join(missing)}')
    return built


def components(group: str) -> tuple[Component, ...]:
    """Every registered component of ``group`` that loads, in name order.

    One that fails to load is left out (logged at debug level: ``trust-av -v``), so that a
    broken plug-in stops only a command that chooses it (:func:`get` then raises)."""
    found = []
    for n in names(group):
        try:
            found.append(get(group, n))
        except RegistryError as err:
            LOG.debug('left out: %s', err)
    return tuple(found)


def config_types(group: str) -> tuple[type, ...]:
    """The ``config_type`` of every registered component of ``group`` that has parameters,
    in name order (their fields are parameters of the node that runs the group)."""
    return tuple(c.config_type for c in components(group) if c.config_type is not None)


def config_of(component: Component, params: Any = None) -> Any:
    """The parameters to build ``component`` with: ``params``, or its defaults
    (``config_type()``); None when it has no parameters.

    Raises:
        RegistryError: ``params`` is given but is not a ``config_type`` instance, or the
            component has no parameters yet ``params`` is given.
    """
    if component.config_type is None:
        if params is not None:
            raise RegistryError(f'component {component.name!r} has no parameters, got a '
                                f'{type(params).__name__}')
        return None
    if params is None:
        return component.config_type()
    if not isinstance(params, component.config_type):
        raise RegistryError(f'component {component.name!r}: parameters must be a '
                            f'{component.config_type.__name__}, got a '
                            f'{type(params).__name__}')
    return params
