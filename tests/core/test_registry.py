"""The component registry: names, lookups and one-line refusals (pure, no rclpy)."""

from __future__ import annotations

import pytest

from trust_av_common import registry
from trust_av_common.registry import Component, RegistryError


def test_unknown_name_lists_the_registered_ones() -> None:
    with pytest.raises(RegistryError, match=r"unknown predictor 'nope' \(registered: "):
        registry.get(registry.PREDICTORS, 'nope')


def test_unknown_group_is_refused() -> None:
    with pytest.raises(RegistryError, match='unknown component group'):
        registry.names('trust_av.nothing')   # doc-names: off (a made-up group)
    # doc-names: on


@pytest.mark.parametrize('name', ['', 'CV', '1cv', 'c-v', 'cv '])
def test_component_names_are_identifiers(name: str) -> None:
    with pytest.raises(RegistryError, match='lower-case identifier'):
        Component(name=name, factory=object)


def test_unknown_need_is_refused() -> None:
    with pytest.raises(RegistryError, match='needs unknown'):
        Component(name='x', factory=object, needs=frozenset({'telepathy'}))
