"""What the driving page may send, pure part: which messages fit the study's phase, how
fast pedal samples may come, which rating prompts and acknowledgements are open, and a
count of everything refused (never stored).

One :class:`Gate` per drive, fed every message of the controlling tab (the server refuses
other tabs' messages before this). Thread-safe: the server's thread checks messages, the
drive's loop changes the phase and opens prompts. Times are passed in (ns); no rclpy.
"""

from __future__ import annotations

import math
import re
import threading
from collections import Counter
from dataclasses import dataclass
from typing import Any

__all__ = ['INPUT_BURST', 'TRUST_BURST', 'TRUST_PER_S', 'Gate', 'reason_key']

READY, DRIVING, WAIT, QUESTIONNAIRE, IDLE = 'ready', 'driving', 'wait', 'questionnaire', 'idle'
"""The drive's phases as the gate sees them (IDLE: between drives)."""
ALLOWED = {READY: frozenset({'ready', 'trust'}),
           DRIVING: frozenset({'input', 'ack', 'rating', 'trust'}),
           WAIT: frozenset({'ack', 'rating'}),
           QUESTIONNAIRE: frozenset({'questionnaire'}),
           IDLE: frozenset()}
"""Message types each phase takes (``take_over`` is the server's, in every phase)."""
ACK_KEEP_NS = 5_000_000_000
"""An acknowledgement not echoed within this long is forgotten (a lost frame)."""
INPUT_BURST = 10
"""Pedal samples that may come at once above the control rate, counted on the page's clock
(its send times, ``t_ms``): the page keeps its own bucket of 3 (a press and a release
between two periodic samples) refilled a little slower, so it never meets this one; 10 at
once (1 s of samples at 10 Hz) does the graph no harm. It also takes up a stall at the very
start of a connection, before any sample came promptly (the page's clock is then not yet
known, and a bunch counts at its arrival)."""
TRUST_BURST = 10
"""``trust`` messages (the continuous scale's position) that may come at once, refilled at
:data:`TRUST_PER_S` a second on their arrival: the page sends one at most every 0.2 s
while the scale moves (5 a second)."""
TRUST_PER_S = 10.0
"""``trust`` messages a second allowed on average."""


def finite_number(value: Any) -> float | None:
    """``value`` as a finite float, or None: not a number (a bool is not), NaN, infinite, or
    an integer too large for a float (JSON allows any number of digits)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    try:
        number = float(value)
    except OverflowError:
        return None
    return number if math.isfinite(number) else None


def reason_key(reason: str) -> str:
    """A refusal reason as a metadata key: lower-case words joined by ``_``
    (``'input over the control rate'`` -> ``input_over_the_control_rate``)."""
    return re.sub(r'[^a-z0-9]+', '_', reason.lower()).strip('_')


@dataclass
class _Bucket:
    """A token bucket: ``burst`` tokens at most, refilled at ``per_s`` a second on the clock
    of the times it is given; a time earlier than one already credited refills nothing."""

    burst: float
    per_s: float
    at_s: float = -math.inf         # the latest time credited, s

    def __post_init__(self) -> None:
        self.tokens = self.burst

    def take(self, at_s: float) -> bool:
        """Take a token at ``at_s``; False when none is left."""
        self.tokens = min(self.burst, self.tokens + max(0.0, at_s - self.at_s) * self.per_s)
        self.at_s = max(self.at_s, at_s)
        if self.tokens < 1.0:
            return False
        self.tokens -= 1.0
        return True


@dataclass(frozen=True)
class Sample:
    """An accepted pedal sample: the server's sequence number, the command (clipped to the
    pedal's range, m/s^2) and whether clipping changed it."""

    seq: int
    accel_mps2: float
    clipped: bool


class Gate:
    """The drive's message policy.

    Args:
        control_rate_hz: pedal samples per second allowed on average.
        accel_min_mps2: full brake (samples below are clipped).
        accel_max_mps2: full gas (samples above are clipped).
        continuous: the study's rating is the continuous scale (``trust`` messages, its
            position, sampled by the drive); else rated prompts (``rating`` messages).
    """

    def __init__(self, control_rate_hz: float, accel_min_mps2: float,
                 accel_max_mps2: float, continuous: bool = False) -> None:
        self.continuous = continuous
        self.rate_hz = control_rate_hz
        self.accel_min, self.accel_max = accel_min_mps2, accel_max_mps2
        self.lock = threading.Lock()
        self.phase = IDLE
        self.refused: Counter[str] = Counter()
        self._inputs = _Bucket(INPUT_BURST, control_rate_hz)
        self._offset_s: float | None = None   # least (arrival - t_ms) of this connection
        self._seq = 0
        self._prompts: dict[int, int] = {}           # prompt id -> sent at, ns
        self._next_prompt = 1
        self._acks: dict[int, tuple[int, int, int]] = {}   # seq -> arrived, applied, sent
        self.questionnaire_taken = False
        self._trust: tuple[float, int] | None = None     # scale position, set at ns
        self._trusts = _Bucket(TRUST_BURST, TRUST_PER_S)

    def set_phase(self, phase: str) -> None:
        """The drive moved to ``phase`` (a new ``READY`` starts a new drive's bookkeeping)."""
        with self.lock:
            if phase == READY:          # each drive's scale starts unset
                self._prompts.clear()
                self._trust = None
                self._acks.clear()
                self.questionnaire_taken = False
            if phase in (QUESTIONNAIRE, IDLE, READY):
                self._prompts.clear()
            self.phase = phase

    def refuse(self, reason: str) -> None:
        """Count one refused message."""
        with self.lock:
            self.refused[reason] += 1

    def admit(self, message: dict[str, Any]) -> bool:
        """Whether the message's type fits the phase (refused and counted if not)."""
        with self.lock:
            if message['type'] in ALLOWED[self.phase]:
                return True
            self.refused[f'{message["type"]} during {self.phase}'] += 1
            return False

    def new_page(self) -> None:
        """Another page (or a reconnection) drives from now: its clock is put on this one
        anew, from its own samples."""
        with self.lock:
            self._offset_s = None

    def sample(self, message: dict[str, Any], now_ns: int) -> Sample | None:
        """An admitted ``input`` as a command, or None (refused and counted): not a finite
        number, a ``t_ms`` that is not a finite number, or over the rate.

        The rate is a token bucket of ``INPUT_BURST`` samples refilled at the control rate
        on the page's clock: each sample's send time (``t_ms``, the page's
        ``performance.now()``) put on this clock through the connection's least delayed
        sample so far (the smallest arrival - t_ms), so samples sent a control period apart
        pass however they arrive (bunched after a stall of this process). That clock never
        runs ahead of the arrivals (the sample being counted is one of those the least is
        taken over), so a page lying about its time gains nothing: its samples count at
        their arrival at the latest. A sample without ``t_ms`` counts at its arrival; a
        time earlier than one already credited refills nothing."""
        value = finite_number(message.get('accel_mps2'))
        if value is None:
            self.refuse('input without a finite accel_mps2')
            return None
        sent_ms = finite_number(message.get('t_ms'))
        if sent_ms is None and 't_ms' in message:
            self.refuse('input with a t_ms that is not a finite number')
            return None
        now_s = now_ns / 1e9
        with self.lock:
            at_s = now_s
            if sent_ms is not None:
                offset_s = now_s - sent_ms / 1e3
                if self._offset_s is None or offset_s < self._offset_s:
                    self._offset_s = offset_s
                at_s = sent_ms / 1e3 + self._offset_s       # <= now_s
            if not self._inputs.take(at_s):
                self.refused['input over the control rate'] += 1
                return None
            self._seq += 1
            accel = min(self.accel_max, max(self.accel_min, value))
            return Sample(self._seq, accel, accel != value)

    def open_prompt(self, now_ns: int) -> int:
        """Open a rating prompt; its id (the page answers with it)."""
        with self.lock:
            prompt = self._next_prompt
            self._next_prompt += 1
            self._prompts[prompt] = now_ns
            return prompt

    def open_prompts(self) -> list[int]:
        """The prompts not yet answered (a reopened tab shows them)."""
        with self.lock:
            return sorted(self._prompts)

    def rating(self, message: dict[str, Any], now_ns: int) -> tuple[int, float, float] | None:
        """An admitted ``rating`` as (prompt id, value 0-100, response time s measured here
        from the prompt), or None (refused and counted): no open prompt of that id, or a value
        that is not a number in [0, 100]."""
        value, prompt = finite_number(message.get('value')), message.get('id')
        with self.lock:
            if isinstance(prompt, bool) or not isinstance(prompt, int) \
                    or prompt not in self._prompts:
                self.refused['rating outside a prompt'] += 1
                return None
            if value is None or not 0 <= value <= 100:
                self.refused['rating not in [0, 100]'] += 1
                return None
            shown = self._prompts.pop(prompt)
        return prompt, value, max(0, now_ns - shown) / 1e9

    def trust(self, message: dict[str, Any], now_ns: int) -> float | None:
        """An admitted ``trust`` (the continuous scale moved) as its value 0-100, kept as the
        scale's position from ``now_ns``; None (refused and counted): the study rates by
        prompts, a value that is not a number in [0, 100], or over :data:`TRUST_PER_S`."""
        value = finite_number(message.get('value'))
        with self.lock:
            if not self.continuous:
                self.refused['trust without the continuous rating'] += 1
                return None
            if value is None or not 0 <= value <= 100:
                self.refused['rating not in [0, 100]'] += 1
                return None
            if not self._trusts.take(now_ns / 1e9):
                self.refused['trust over its rate'] += 1
                return None
            self._trust = (value, now_ns)
            return value

    def trust_now(self) -> tuple[float, int] | None:
        """The continuous scale's position (0-100) and when it was set (ns), or None: not
        set since this drive's start screen."""
        with self.lock:
            return self._trust

    def sent_ack(self, seq: int, arrived_ns: int, applied_ns: int, sent_ns: int) -> None:
        """A state frame acknowledging sample ``seq`` was sent to the page."""
        with self.lock:
            for old in [s for s, v in self._acks.items() if sent_ns - v[2] > ACK_KEEP_NS]:
                del self._acks[old]
            self._acks[seq] = (arrived_ns, applied_ns, sent_ns)

    def echo(self, message: dict[str, Any], now_ns: int) -> tuple[float, float, float] | None:
        """An admitted ``ack`` (the page echoing an acknowledgement) as the sample's latency,
        s, measured on this clock: (round trip arrival -> echo, arrival -> applied by the
        follower plant, applied -> echo); None (refused and counted) for a sequence number
        not sent or already echoed."""
        seq = message.get('seq')
        with self.lock:
            found = self._acks.pop(seq, None) if isinstance(seq, int) \
                and not isinstance(seq, bool) else None
            if found is None:
                self.refused['ack of no sent frame'] += 1
                return None
        arrived, applied, _sent = found
        return ((now_ns - arrived) / 1e9, (applied - arrived) / 1e9, (now_ns - applied) / 1e9)

    def take_questionnaire(self) -> bool:
        """Whether this is the phase's first questionnaire (later ones are refused)."""
        with self.lock:
            if self.questionnaire_taken:
                self.refused['a second questionnaire'] += 1
                return False
            self.questionnaire_taken = True
            return True

    def refused_counts(self) -> dict[str, int]:
        """Refused messages by reason."""
        with self.lock:
            return dict(self.refused)
