"""The plug-in's own CI: trust-av's shipped contract for every component it registers.

Run it with the plug-in installed into trust-av's environment::

    pip install --no-deps --no-build-isolation -e .
    python -m pytest tests/test_contract.py
"""

from __future__ import annotations

import pytest

from trust_av.contract import check_component

COMPONENTS = [('trust_av.predictors', 'ses'), ('trust_av.trust_models', 'leaky')]


@pytest.mark.parametrize(('group', 'name'), COMPONENTS)
def test_keeps_the_contract(group: str, name: str) -> None:
    """Declaration, build, output shapes and bounds, determinism, bad parameters (and for a
    trust model its time consistency and its bound); raises naming each broken rule."""
    check_component(group, name)


@pytest.mark.parametrize(('group', 'name'), COMPONENTS)
def test_the_node_graph_runs_it_as_the_loop_does(group: str, name: str) -> None:
    """30 steps of the node graph (one process per node) record what the in-process loop
    computes with it (10-30 s each)."""
    report = check_component(group, name, graph=True)
    assert 'graph == in-process' in report.passed
