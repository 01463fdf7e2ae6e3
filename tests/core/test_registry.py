"""The component registry: names, lookups and one-line refusals (pure, no rclpy)."""

from __future__ import annotations

import pytest

from trust_av_common import registry
from trust_av_common.registry import Component, RegistryError
from trust_av_planner.predictors import PREDICTORS


def test_unknown_name_lists_the_registered_ones() -> None:
    with pytest.raises(RegistryError, match=r"unknown predictor 'nope' \(registered: "):
        registry.get(PREDICTORS, 'nope')


def test_unknown_group_is_refused() -> None:
    with pytest.raises(RegistryError, match='unknown component group'):
        registry.names('trust_av.nothing')   # doc-names: off (a made-up group)
    # doc-names: on


def test_a_group_is_declared_by_the_package_that_owns_it() -> None:
    """The registry knows no group of its own: each is declared beside its interface (how its
    factory is called, what it returns), once; a new one works as the shipped ones do."""
    from human_driver_sim.followers import DRIVERS
    from trust_monitor.model_interface import TRUST_MODELS

    assert {PREDICTORS, TRUST_MODELS, DRIVERS} <= set(registry.groups())
    group = registry.declare('test_registry.widgets', ('shared', 'params'), ('spin',))
    assert registry.declare('test_registry.widgets', ['shared', 'params'], ['spin']) == group
    assert registry.names(group) == ()
    with pytest.raises(RegistryError, match=r"unknown widget 'gear' \(registered: none\)"):
        registry.get(group, 'gear')
    widget = Component(name='gear', factory=lambda shared, params: object())
    with pytest.raises(RegistryError, match=r"widget 'gear' \(test_registry.widgets\): its "
                                            r'factory returned .* it lacks spin'):
        registry.build(group, widget, None, None)
    with pytest.raises(RegistryError, match='declared twice, differently'):
        registry.declare('test_registry.widgets', ('shared', 'params'), ('spin', 'stop'))


@pytest.mark.parametrize('name', ['', 'CV', '1cv', 'c-v', 'cv '])
def test_component_names_are_identifiers(name: str) -> None:
    with pytest.raises(RegistryError, match='lower-case identifier'):
        Component(name=name, factory=object)


def test_unknown_need_is_refused() -> None:
    with pytest.raises(RegistryError, match='needs unknown'):
        Component(name='x', factory=object, needs=frozenset({'telepathy'}))
