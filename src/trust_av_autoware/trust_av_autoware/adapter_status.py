"""What an adapter node did, for its ``/diagnostics`` status, pure (no rclpy): per input the
messages received, used and dropped (by reason), its last receive time, and the last reason a
message was dropped; per output the messages published."""

from __future__ import annotations

from collections import Counter

from trust_av_common.health import ERROR, OK, WARN, Report, age

__all__ = ['AdapterStatus']


class AdapterStatus:
    """Counts and the last drop of an adapter.

    Args:
        inputs: the inputs' short names (``kinematic_state``, ``objects``, ...), in the order
            the status lists them.
    """

    def __init__(self, inputs: tuple[str, ...]) -> None:
        self.inputs = inputs
        self.counts: Counter[str] = Counter()
        self.received_ns: dict[str, int | None] = dict.fromkeys(inputs)
        self.last_drop = ''
        self.last_drop_input = ''

    def received(self, name: str, now_ns: int) -> None:
        self.counts[f'{name}_received'] += 1
        self.received_ns[name] = now_ns

    def dropped(self, name: str, kind: str, reason: str) -> None:
        """A message of input ``name`` not used: counted under ``<name>_dropped_<kind>``."""
        self.counts[f'{name}_dropped_{kind}'] += 1
        self.last_drop, self.last_drop_input = reason, name

    def used(self, name: str) -> None:
        self.counts[f'{name}_used'] += 1
        if self.last_drop_input == name:
            self.last_drop = self.last_drop_input = ''

    def published(self, output: str) -> None:
        self.counts[f'{output}_published'] += 1

    def dropped_total(self) -> int:
        return sum(v for k, v in self.counts.items() if '_dropped_' in k)

    def report(self, now_ns: int, missing: str, working: str,
               extra: dict[str, str] | None = None) -> Report:
        """ERROR ``not publishing: <missing>`` while something needed is missing, WARN with
        the reason while the newest message of an input was dropped, else OK ``working``;
        values: every count, ``input_age_<name>_s`` and ``extra``."""
        values = {k: str(v) for k, v in sorted(self.counts.items())}
        values['dropped_total'] = str(self.dropped_total())
        values.update({f'input_age_{name}_s': age(now_ns, self.received_ns[name])
                       for name in self.inputs})
        values.update(extra or {})
        if missing:
            return ERROR, f'not publishing: {missing}', values
        if self.last_drop:
            return WARN, f'dropped {self.last_drop_input}: {self.last_drop}', values
        return OK, working, values
