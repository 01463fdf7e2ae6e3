"""The run plot (``trust-av run``'s PNG): P with its threshold, trust with its ceiling, and
time from the start of the drive even when the records carry a bag's epoch stamps."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from preceding_traffic.sources import load_trace
from preceding_traffic.traces import truncate
from trust_av.study import plots
from trust_av.system.closed_loop import simulate
from trust_av.system.config import load_run_config

STEPS = 12
EPOCH_S = 1_700_000_000.0


def drawn_figure(records: list[Any], tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                 **trust: Any) -> Any:
    """Draw the run plot and keep the figure (the PNG is written too)."""
    kept: list[Any] = []
    save = plots.save_figure

    def keep(fig: Any, path: Path, dpi: int) -> None:
        kept.append(fig)
        save(fig, path, dpi)

    monkeypatch.setattr(plots, 'save_figure', keep)
    png = tmp_path / 'run.png'
    plots.run_overview(records, 'test', png, **trust)
    assert png.stat().st_size > 10_000
    return kept[0]


@pytest.fixture(scope='module')
def us06_records() -> list[Any]:
    config = load_run_config()
    trace = truncate(load_trace('us06', config.planner.dt_s, config.trace), STEPS)
    return simulate(config.for_trace(trace), trace).records


def test_p_threshold_and_trust_ceiling_are_drawn(us06_records: list[Any], tmp_path: Path,
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    fig = drawn_figure(us06_records, tmp_path, monkeypatch, performance_threshold=0.8,
                       ceiling=(0.5, 0.1))
    p_axis, trust_axis = fig.axes[4], fig.axes[5]
    p_lines = {line.get_label(): line for line in p_axis.get_lines()}
    assert list(p_lines['P'].get_ydata()) == [r.performance for r in us06_records]
    threshold = p_lines['threshold P_thre = 0.8']
    assert set(threshold.get_ydata()) == {0.8}
    trust_lines = {line.get_label(): line for line in trust_axis.get_lines()}
    assert list(trust_lines['trust T'].get_ydata()) == [r.trust for r in us06_records]
    ceiling = np.asarray(trust_lines['ceiling T(0) + δ·t (δ = 0.1/s)'].get_ydata())
    # trust after step k (1 s steps) can be at most T(0) + delta * (k + 1)
    assert ceiling == pytest.approx(0.5 + 0.1 * np.arange(1, STEPS + 1))
    assert all(r.trust <= c + 1e-12 for r, c in zip(us06_records, ceiling, strict=True))


def test_bag_timed_records_get_time_from_the_start(us06_records: list[Any], tmp_path: Path,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    stamped = [dataclasses.replace(r, t_s=EPOCH_S + r.t_s) for r in us06_records]
    fig = drawn_figure(stamped, tmp_path, monkeypatch, performance_threshold=0.8,
                       ceiling=(0.0, 0.1))
    fig.canvas.draw()
    for axis in fig.axes:
        for line in axis.get_lines()[:1]:
            assert list(line.get_xdata()) == [float(k) for k in range(STEPS)]
        assert axis.xaxis.get_offset_text().get_text() == ''      # no "+1.7e9"
    assert fig.axes[-1].get_xlabel() == 'time since the start of the drive (s)'


def test_a_ceiling_is_drawn_only_for_a_model_that_declares_one(
        us06_records: list[Any], tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The ceiling is the trust model's declared property (``ceiling``), not a guess from
    its name: the paper's and asymmetric models declare T(0) + delta t, beta_bernoulli and
    optimo none, and their plots have no ceiling line."""
    from trust_monitor.model_interface import make_trust_model, trust_ceiling

    config = load_run_config()
    declared = {name: trust_ceiling(make_trust_model(
        dataclasses.replace(config.trust, trust_model=name), dict(config.trust_model_params)))
        for name in ('paper', 'asymmetric', 'beta_bernoulli', 'optimo')}
    assert declared == {'paper': (0.0, 0.1), 'asymmetric': (0.0, 0.1),
                        'beta_bernoulli': None, 'optimo': None}
    fig = drawn_figure(us06_records, tmp_path, monkeypatch, performance_threshold=0.8,
                       ceiling=None)
    assert [line.get_label() for line in fig.axes[5].get_lines()] == ['trust T']


def test_the_trust_unaware_av_is_drawn_beside_with_e_labelled(
        us06_records: list[Any], tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The main job's figure: the alpha = 0 run of the same drive beside the trust-aware one
    (speed, E, P, trust and trust lost against the ceiling), E's direction said."""
    config = load_run_config(overrides={'planner': {'alpha': 0.0}})
    trace = truncate(load_trace('us06', config.planner.dt_s, config.trace), STEPS)
    unaware = simulate(config.for_trace(trace), trace).records
    fig = drawn_figure(us06_records, tmp_path, monkeypatch, performance_threshold=0.8,
                       ceiling=(0.0, 0.1), baseline=unaware)
    e_axis, lost_axis = fig.axes[3], fig.axes[6]
    assert 'higher = less explicable' in e_axis.get_title(loc='left')
    e_lines = {line.get_label(): line for line in e_axis.get_lines()}
    assert list(e_lines['trust-unaware AV (α = 0)'].get_ydata()) == \
        [r.explicability for r in unaware]
    assert list(e_lines['trust-aware AV'].get_ydata()) == \
        [r.explicability for r in us06_records]
    lost = {line.get_label(): line for line in lost_axis.get_lines()}
    ceiling = 0.1 * np.arange(1, STEPS + 1)
    assert np.allclose(lost['trust-unaware AV (α = 0)'].get_ydata(),
                       ceiling - np.asarray([r.trust for r in unaware]))
