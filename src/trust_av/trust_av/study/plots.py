"""Figures (matplotlib, Agg backend, PNG): the paper's Figures 2 and 3, and one run's traces."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from preceding_traffic.traces import SpeedTrace
from trust_av.study.paper_results import TRACE_LABELS
from trust_av_common.output_files import replacing

__all__ = ['pyplot', 'run_overview', 'save_figure', 'speed_profiles', 'trust_over_time']


def pyplot() -> Any:
    """``matplotlib.pyplot`` on the Agg backend, imported when a figure is drawn (about
    1 CPU-s: commands that draw nothing, ``--help`` and bad input, do not pay it)."""
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig: Any, path: Path, dpi: int) -> None:
    """``fig.savefig(path)``, whole or not at all (``trust_av_common.output_files``;
    the format follows the suffix)."""
    with replacing(path) as (temporary,):
        fig.savefig(temporary, dpi=dpi)


def speed_profiles(traces: Sequence[SpeedTrace], path: Path) -> None:
    """Figure 2: the preceding traffic's speed profile of each trace."""
    plt = pyplot()
    fig, axes = plt.subplots(len(traces), 1, figsize=(8, 2.2 * len(traces)), squeeze=False)
    for ax, trace in zip(axes[:, 0], traces, strict=True):
        t = trace.t0_s + trace.dt_s * np.arange(len(trace.speeds_mps))
        ax.plot(t, trace.speeds_mps, color='tab:blue', linewidth=1.0)
        ax.set_title(TRACE_LABELS.get(trace.name, trace.name), fontsize=10)
        ax.set_ylabel('speed (m/s)')
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel('time (s)')
    fig.suptitle('Figure 2: speed profiles of the preceding traffic')
    fig.tight_layout()
    save_figure(fig, path, dpi=120)
    plt.close(fig)


def trust_over_time(series: Mapping[str, Mapping[float, tuple[Sequence[float],
                                                                Sequence[float]]]],
                    trace: str, path: Path, ceiling: tuple[float, float] | None,
                    note: str = '') -> None:
    """Figure 3: trust over time for every alpha, one column per predictor.

    The top row is the trust level itself (the paper's figure). When the trust model
    declares a ceiling (:func:`~trust_monitor.model_interface.trust_ceiling`), a bottom row
    shows the trust lost against it, ``T(0) + delta * t`` (what a perfectly explicable AV
    would earn, P = 1 every step), which makes small differences between alphas visible.

    Args:
        series: predictor label -> alpha -> (time_s, trust after each step).
        trace: trace name for the title.
        path: PNG to write.
        ceiling: the trust model's (T(0), delta per second), or None (no bottom row).
        note: a line under the title (a truncated run says so).
    """
    plt = pyplot()
    rows = 1 if ceiling is None else 2
    fig, axes = plt.subplots(rows, len(series), figsize=(6 * len(series), 7 if rows == 2 else 5),
                             squeeze=False, sharex=True, sharey='row',
                             height_ratios=[2, 1][:rows])
    colors = plt.get_cmap('viridis')
    for col, (label, by_alpha) in enumerate(series.items()):
        top = axes[0, col]
        for i, (alpha, (time_s, trust)) in enumerate(sorted(by_alpha.items())):
            color = colors(i / max(len(by_alpha) - 1, 1))
            top.plot(time_s, trust, color=color, label=f'alpha = {alpha:g}', linewidth=1.2)
            if ceiling is not None:
                # trust is recorded after each step: after k steps, at most T(0) + delta*k*step
                step_s = time_s[1] - time_s[0] if len(time_s) > 1 else 1.0
                level = ceiling[0] + ceiling[1] * (np.asarray(time_s) - time_s[0] + step_s)
                axes[1, col].plot(time_s, level - np.asarray(trust), color=color,
                                  linewidth=1.2)
        top.set_title(f'{label} on {TRACE_LABELS.get(trace, trace)}')
        top.legend(loc='upper left', fontsize=8)
        axes[-1, col].set_xlabel('time (s)')
        for ax in axes[:, col]:
            ax.grid(alpha=0.3)
    axes[0, 0].set_ylabel('trust level T')
    if ceiling is not None:
        axes[1, 0].set_ylabel('trust lost vs. ceiling T(0) + δ·t')
    fig.suptitle('Figure 3: trust level of the human driver during the trip'
                 + (f'\n{note}' if note else ''))
    fig.tight_layout()
    save_figure(fig, path, dpi=120)
    plt.close(fig)


def run_overview(records: Sequence[Any], title: str, path: Path, *,
                 performance_threshold: float, ceiling: tuple[float, float] | None,
                 baseline: Sequence[Any] | None = None) -> None:
    """One run: speeds, gaps, accelerations, E and P, trust, and (when the trust model
    declares a ceiling) the trust lost against it, against time; beside it (thin dashed
    lines) the trust-unaware AV (alpha = 0) on the same drive when ``baseline`` is given.

    Time runs from the start of the drive (the first record's stamp is 0 s), so a run timed
    by a bag's epoch stamps reads like a simulated one. The P panel draws the threshold
    P_thre (trust grows where P is above it), the trust panels the ceiling
    ``T(0) + delta * t`` that a perfectly explicable AV (P = 1 every step) would reach and
    how far below it each AV's trust is (what alpha changes when trust stays near it), when
    the trust model declares one (:func:`~trust_monitor.model_interface.trust_ceiling`).

    Args:
        records: :class:`trust_av.system.metrics.StepRecord` (or objects with the
            same attributes), one per control step, in time order.
        title: the figure's title.
        path: PNG to write (whole or not at all).
        performance_threshold: P_thre of eq. (11), dimensionless.
        ceiling: the trust model's ceiling (T(0), trust units; delta, trust units per
            second), or None: it has none, and neither it nor the lost-trust panel is drawn.
        baseline: the same drive's records with alpha = 0 (the trust-unaware AV), or None.
    """
    plt = pyplot()
    t = drive_time_s(records)
    step_s = t[1] - t[0] if len(t) > 1 else 1.0
    panels = 6 if ceiling is None else 7
    fig, axes = plt.subplots(panels, 1, figsize=(9, 12.5 if ceiling is None else 14.5),
                             sharex=True)
    aware = 'trust-aware AV' if baseline is not None else 'AV'
    suffix = '' if baseline is None else f', {aware}'
    unaware = 'trust-unaware AV (α = 0)'
    base = baseline if baseline is not None and len(baseline) == len(records) else None
    thin = {'linestyle': '--', 'linewidth': 0.9, 'color': 'tab:grey'}
    axes[0].plot(t, [r.traffic_speed_mps for r in records], label='preceding traffic')
    axes[0].plot(t, [r.av_speed_mps for r in records], label=aware)
    axes[0].plot(t, [r.human_speed_mps for r in records], label='human', linestyle='--')
    axes[0].set_ylabel('speed (m/s)')
    axes[1].plot(t, [r.av_gap_m for r in records], label='AV to traffic')
    axes[1].plot(t, [r.human_gap_m for r in records], label='human to AV')
    axes[1].set_ylabel('gap (m)')
    axes[2].plot(t, [r.av_accel_mps2 for r in records], label=aware)
    axes[2].plot(t, [r.human_accel_mps2 for r in records], label='human', linestyle='--')
    axes[2].plot(t, [r.expected_plan_mps2[0] for r in records], label='expected (u_R^H)',
                 linestyle=':')
    axes[2].set_ylabel('acceleration (m/s²)')
    axes[3].plot(t, [r.explicability for r in records], color='tab:red', label=aware)
    axes[3].set_ylabel('explicability E')
    axes[3].set_title('E: 0 = the AV does what the human expects; higher = less explicable',
                      fontsize=9, loc='left')
    axes[4].plot(t, [r.performance for r in records], color='tab:purple', label=f'P{suffix}')
    axes[4].axhline(performance_threshold, color='black', linestyle='--', linewidth=0.9,
                    label=f'threshold P_thre = {performance_threshold:g}')
    axes[4].set_ylabel('performance P')
    # Trust is recorded after each step: after k steps of step_s, at most T(0) + delta*k*step_s.
    level = None
    if ceiling is not None:
        trust_initial, growth_per_s = ceiling
        level = trust_initial + growth_per_s * (np.asarray(t) + step_s)
        axes[5].plot(t, level, color='grey', linewidth=3.0, alpha=0.45,
                     label=f'ceiling T(0) + δ·t (δ = {growth_per_s:g}/s)')
        axes[6].plot(t, level - np.asarray([r.trust for r in records]), color='tab:green',
                     label=aware)
        axes[6].set_ylabel('ceiling − T')
        axes[6].set_title('trust lost against the ceiling (what α changes)', fontsize=9,
                          loc='left')
    axes[5].plot(t, [r.trust for r in records], color='tab:green', label=f'trust T{suffix}')
    axes[5].set_ylabel('trust T')
    axes[-1].set_xlabel('time since the start of the drive (s)')
    if base is not None:
        axes[0].plot(t, [r.av_speed_mps for r in base], label=unaware, **thin)
        axes[1].plot(t, [r.av_gap_m for r in base], label=f'AV to traffic, {unaware}', **thin)
        axes[2].plot(t, [r.av_accel_mps2 for r in base], label=unaware, **thin)
        axes[3].plot(t, [r.explicability for r in base], label=unaware, **thin)
        axes[4].plot(t, [r.performance for r in base], label=f'P, {unaware}', **thin)
        axes[5].plot(t, [r.trust for r in base], label=f'trust T, {unaware}', **thin)
        if level is not None:
            axes[6].plot(t, level - np.asarray([r.trust for r in base]), label=unaware, **thin)
    corners = ('upper right',) * 4 + ('lower left', 'upper left', 'upper left')
    for ax, corner in zip(axes, corners[:panels], strict=True):
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(loc=corner, fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    save_figure(fig, path, dpi=110)
    plt.close(fig)


def drive_time_s(records: Sequence[Any]) -> list[float]:
    """Each record's time since the first record's, in s (a bag's epoch stamps become 0...).

    Args:
        records: objects with a ``t_s`` attribute (s), in time order.
    """
    start = records[0].t_s if records else 0.0
    return [r.t_s - start for r in records]
