"""A node's health for ``/diagnostics``, pure (no rclpy): the levels of
``diagnostic_msgs/DiagnosticStatus`` and the planner's solve record
(:class:`SolveRecord`); ``trust_av_common.ros.diagnostics`` publishes them."""

from __future__ import annotations

from collections import deque

from trust_av_common.wall_clock import without_ages

__all__ = ['Report', 'SolveRecord', 'age']

OK, WARN, ERROR = 0, 1, 2
"""``diagnostic_msgs/msg/DiagnosticStatus`` levels (its constants OK, WARN, ERROR)."""

Report = tuple[int, str, dict[str, str]]
"""(level, message, values) of one status."""

RECENT_SOLVES = 100
"""Solves the solve-time maximum and the fallback warning look back over."""


def age(now_ns: int, received_ns: int | None) -> str:
    """An input's age for a status value, s ('never' if none was received)."""
    return 'never' if received_ns is None else f'{(now_ns - received_ns) / 1e9:.3f}'


class SolveRecord:
    """What the planner did since ``configure``: solves, fallbacks, stale-input ticks, the
    last :data:`RECENT_SOLVES` solve times, the latest trust and command."""

    def __init__(self, trust_initial: float) -> None:
        self.counts = dict.fromkeys(('solves', 'fallbacks', 'stale_input_ticks'), 0)
        self.recent: deque[tuple[float, bool]] = deque(maxlen=RECENT_SOLVES)
        self.status = ''
        self.trust = trust_initial
        self.command_mps2 = float('nan')

    def solved(self, solve_time_s: float, fallback: bool, status: str) -> None:
        self.counts['solves'] += 1
        self.counts['fallbacks'] += bool(fallback)
        self.recent.append((solve_time_s, bool(fallback)))
        self.status = status

    def stale(self) -> None:
        self.counts['stale_input_ticks'] += 1

    def published(self, trust: float, command_mps2: float) -> None:
        self.trust, self.command_mps2 = trust, command_mps2

    def report(self, stale_reason: str, stale_decel_mps2: float,
               ages: dict[str, str]) -> Report:
        """ERROR while the stale-input policy commands (``stale_reason``, in the message
        without the inputs' ages: a message that changed on every tick made the node publish
        ``/diagnostics`` on every tick, ``NodeDiagnostics.changed``), WARN while one of the
        last :data:`RECENT_SOLVES` solves fell back, else OK ``commanding``; values: the
        counts, the last and the longest recent solve time, the solver status, trust, command
        and ``input_age_<name>_s`` of ``ages``."""
        times = [t for t, _ in self.recent]
        values = {**{k: str(v) for k, v in self.counts.items()},
                  'solve_time_last_s': repr(times[-1]) if times else 'none',
                  'solve_time_max_recent_s': repr(max(times)) if times else 'none',
                  'solver_status': self.status, 'trust': repr(self.trust),
                  'command_mps2': repr(self.command_mps2),
                  **{f'input_age_{name}_s': value for name, value in ages.items()}}
        if stale_reason:
            return (ERROR, f'commanding {stale_decel_mps2:g} m/s^2 (stale-input policy): '
                    f'{without_ages(stale_reason)}', values)
        fell = sum(fallback for _, fallback in self.recent)
        if fell:
            return (WARN, f'commanding; NMPC fell back in {fell} of the last '
                    f'{len(self.recent)} solves (last status {self.status})', values)
        return OK, 'commanding', values
