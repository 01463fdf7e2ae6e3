"""Real-vehicle ("wall") mode, pure part: its configuration, the latest-input store and the
control-loop jitter statistics. No rclpy: the nodes pass times in (nanoseconds of the wall
clock they read), so everything here is testable without ROS.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from trust_av_common.params import check_fields, param

__all__ = ['NS_PER_S', 'LatestInputs', 'LoopStats', 'WallClockConfig', 'format_summary',
           'without_ages']

CLOCK_MODES = ('lockstep', 'wall')
STARTUP = 'the timer, the QoS profiles and the subscriptions are made at start-up'
NS_PER_S = 1_000_000_000
PERCENTILES = (50.0, 99.0)
_AGE = re.compile(r' \(\d+\.\d{3} s old\)')
"""The age :meth:`LatestInputs.problems` gives a stale input (`` (0.523 s old)``)."""


def without_ages(reason: str) -> str:
    """A :meth:`LatestInputs.problems` reason without the inputs' ages (``stale: traffic``),
    which change on every tick: what a status message that must not change with them says."""
    return _AGE.sub('', reason)


@dataclass(frozen=True)
class WallClockConfig:
    """How a node runs: lock-step on sim time (default) or on a wall-clock timer.

    Attributes:
        clock_mode: ``lockstep`` (inputs paired by header stamp, today's graph) or ``wall``
            (a timer at ``control_rate_hz`` acting on the latest inputs).
        control_rate_hz: wall-mode loop rate, Hz (> 0).
        input_timeout_s: wall mode: an input received longer ago than this is stale, s (> 0).
        jitter_report_path: wall mode: JSON file the loop statistics are written to at
            shutdown ('' = only the node log).
        jitter_log_period_s: wall mode: how often p50/p99 are logged, s (> 0).
        input_deadline_qos: wall mode: vehicle inputs request a QoS deadline of
            ``input_timeout_s``, so that a silent publisher is reported by a DDS deadline
            event at once. Off by default: a subscription that requests a deadline matches
            only publishers that offer one at least as short, and ordinary vehicle stacks
            offer none (rmw ``rmw_qos_profile_check_compatible``: "Subscription has a
            deadline, but publisher does not"). Either way an input received longer ago
            than ``input_timeout_s`` is stale (receive times).
    """

    clock_mode: str = param('lockstep (sim time, inputs paired by stamp) or wall (timer, '
                            'latest inputs)', choices=CLOCK_MODES, default='lockstep',
                            reason=STARTUP)
    control_rate_hz: float = param('wall mode: control loop rate', unit='Hz', low=0.0,
                                   low_inclusive=False, high=1000.0, default=10.0,
                                   reason=STARTUP)
    input_timeout_s: float = param('wall mode: an input received longer ago than this is '
                                   'stale', unit='s', low=0.0, low_inclusive=False, high=3600.0,
                                   default=0.5,
                                   reason=STARTUP)
    jitter_report_path: str = param("wall mode: JSON file for the loop's jitter statistics at "
                                    "shutdown ('' = log only)", default='', reason=STARTUP)
    jitter_log_period_s: float = param('wall mode: period of the jitter log line', unit='s',
                                       low=0.0, low_inclusive=False, high=86_400.0,
                                       default=10.0, reason=STARTUP)
    input_deadline_qos: bool = param('wall mode: vehicle inputs request a QoS deadline of '
                                     'input_timeout_s (then only publishers that offer one '
                                     'match); false: staleness from receive times alone',
                                     default=False, reason=STARTUP)

    def __post_init__(self) -> None:
        check_fields(self)

    @property
    def wall(self) -> bool:
        """True in wall-clock mode."""
        return self.clock_mode == 'wall'

    @property
    def period_ns(self) -> int:
        """Nominal loop period, ns."""
        return round(NS_PER_S / self.control_rate_hz)


class LatestInputs:
    """The latest message of each named input and when it was received (wall ns)."""

    def __init__(self, names: list[str]) -> None:
        self.names = list(names)
        self._latest: dict[str, tuple[int, Any]] = {}

    def put(self, name: str, received_ns: int, msg: Any) -> None:
        """Keep ``msg`` as the latest ``name``, received at ``received_ns``."""
        if name not in self.names:
            raise KeyError(f'unknown input {name!r}')
        self._latest[name] = (received_ns, msg)

    def get(self, name: str) -> Any | None:
        """The latest message of ``name`` or None."""
        item = self._latest.get(name)
        return None if item is None else item[1]

    def received(self, name: str) -> int | None:
        """When the latest ``name`` was received (wall ns), None if never."""
        item = self._latest.get(name)
        return None if item is None else item[0]

    def problems(self, now_ns: int, timeout_s: float, names: list[str] | None = None) -> str:
        """Why the inputs cannot be used now: '' when every one is present and fresh.

        Args:
            now_ns: the current wall time, ns.
            timeout_s: an input older than this is stale, s.
            names: the inputs to check (default: all).
        """
        missing, stale = [], []
        for name in names if names is not None else self.names:
            item = self._latest.get(name)
            if item is None:
                missing.append(name)
            elif now_ns - item[0] > timeout_s * NS_PER_S:
                stale.append(f'{name} ({(now_ns - item[0]) / NS_PER_S:.3f} s old)')
        parts = ([f'missing: {", ".join(missing)}'] if missing else []) + \
            ([f'stale: {", ".join(stale)}'] if stale else [])
        return '; '.join(parts)


class LoopStats:
    """Tick-to-tick period error (actual period - nominal) and compute time of a loop, and
    the messages the node published per topic while it ran."""

    def __init__(self, period_ns: int) -> None:
        if period_ns <= 0:
            raise ValueError(f'loop period must be > 0 ns, got {period_ns}')
        self.period_ns = period_ns
        self._last_tick_ns: int | None = None
        self.jitter_ns: list[int] = []
        self.compute_ns: list[int] = []
        self.published: dict[str, int] = {}

    def publish(self, topic: str) -> None:
        """The node published one message on ``topic``."""
        self.published[topic] = self.published.get(topic, 0) + 1

    def tick(self, now_ns: int) -> None:
        """A loop iteration starts at ``now_ns``."""
        if self._last_tick_ns is not None:
            self.jitter_ns.append(now_ns - self._last_tick_ns - self.period_ns)
        self._last_tick_ns = now_ns

    def done(self, compute_ns: int) -> None:
        """The iteration took ``compute_ns`` of wall time."""
        self.compute_ns.append(compute_ns)

    def summary(self) -> dict[str, Any]:
        """p50/p99/max of |period error| and of compute time, ms, the tick count and the
        messages published per topic."""
        return {'ticks': len(self.compute_ns), 'period_ms': self.period_ns / 1e6,
                'jitter_ms': _percentiles(np.abs(np.asarray(self.jitter_ns, dtype=float))),
                'compute_ms': _percentiles(np.asarray(self.compute_ns, dtype=float)),
                'published': dict(sorted(self.published.items()))}

    def write(self, path: str | Path, node: str) -> None:
        """Write :meth:`summary` (with the node name) as JSON, whole or not at all; a
        symbolic link is refused (:mod:`~trust_av_common.output_files`)."""
        from trust_av_common.output_files import write_text

        write_text(Path(path), json.dumps({'node': node, **self.summary()}, indent=1) + '\n')


def _percentiles(values_ns: np.ndarray) -> dict[str, float | None]:
    if values_ns.size == 0:
        return {'p50': None, 'p99': None, 'max': None}
    p50, p99 = np.percentile(values_ns, PERCENTILES)
    return {'p50': float(p50) / 1e6, 'p99': float(p99) / 1e6,
            'max': float(values_ns.max()) / 1e6}


def format_summary(summary: dict[str, Any]) -> str:
    """One line: ticks, jitter and compute p50/p99/max in ms."""
    def fmt(stats: dict[str, float | None]) -> str:
        return ' / '.join('n/a' if stats[k] is None else f'{stats[k]:.2f}'
                          for k in ('p50', 'p99', 'max'))
    return (f'{summary["ticks"]} ticks, |period error| p50/p99/max {fmt(summary["jitter_ms"])} '
            f'ms, compute p50/p99/max {fmt(summary["compute_ms"])} ms')
