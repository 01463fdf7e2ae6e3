"""The graph half of the trust-model contract (tests/core/test_trust_model_contract.py has the
rest), for every registered trust model, shipped or a plug-in's: 30 lock-step steps of
``trust-av run`` with the model chosen by ``trust_model`` equal the in-process loop (trust,
E, plans), with T_min set above the model's initial trust so that the NMPC's trust
constraint binds."""

from __future__ import annotations

import pytest

from trust_av.contract import check_component
from trust_av_common import registry
from trust_monitor.model_interface import TRUST_MODELS

NAMES = registry.names(TRUST_MODELS)


@pytest.mark.parametrize('name', NAMES)
def test_graph_equals_in_process(name: str) -> None:
    """``trust-av run`` (the node graph, lock-step) with ``trust_model: NAME`` and T_min above
    its initial trust (so that the NMPC's trust constraint binds) equals the in-process
    loop over 30 steps: every recorded field (trust, E, E_max, the plans) but the solve
    times (the shipped contract's rule)."""
    report = check_component(TRUST_MODELS, name, graph=True)
    assert 'graph == in-process' in report.passed, report
