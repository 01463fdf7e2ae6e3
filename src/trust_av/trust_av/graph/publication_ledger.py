"""What a wall-mode recording lost, from the DDS publication sequence numbers.

A lock-step run cannot lose a message: the step authority waits for the recorder's
acknowledgement (``recorder/ack``). In wall mode (``trust-av shadow``, ``--whole-graph``)
the nodes run on their own clocks and nothing waits for the recorder, so one that falls
behind (a busy host, a slow disk, the recording process stopped) can lose messages: the
best-effort sensor topics drop what its subscription cannot take, and a reliable topic
keeps only the last ``HISTORY_DEPTH`` samples for it. Such a loss is counted, not guessed:

- every message a subscription takes carries its publisher's *publication sequence number*
  (1, 2, ... per publisher; ``rmw_message_info_t``), so a missing number between two that
  were received is a lost message;
- every wall-mode node counts what it publishes per topic from its loop's start and writes
  the counts to its loop report on exit (``LoopStats.published``), so messages published
  after the last one received, and never received, are lost too.

One message is not counted: the last of a best-effort publisher, published while its node
is being stopped (after the run; nothing acknowledges a best-effort sample, so the node
cannot wait for the recorder to take it), when the one before it was recorded.

A publisher is told apart by topic and node (only ``/tf`` has several; its transforms name
their vehicle's frame). Messages published before the recording's subscription matched the
publisher are not part of the run and are not counted, except for a publisher that starts
only after the recording is ready (``from_first``): there the first message is number 1.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass

from trust_av.errors import TrustAvAppError

__all__ = ['Lost', 'PublicationLedger', 'Publisher', 'RecordingLossError', 'check_lossless']

Publisher = tuple[str, str]
"""(topic, node) of one publisher."""


@dataclass(frozen=True)
class Lost:
    """Messages of one publisher that are not in the recording."""

    topic: str
    node: str
    count: int
    first: int
    """The first and last missing publication sequence numbers."""
    last: int

    def describe(self) -> str:
        numbers = f'{self.first}' if self.first == self.last else f'{self.first}-{self.last}'
        return f'{self.topic} from {self.node}: {self.count} (publications {numbers})'


class RecordingLossError(TrustAvAppError):
    """A wall-mode recording lost messages; the bag holds the rest (the line says which)."""

    def __init__(self, message: str, losses: Sequence[Lost]) -> None:
        super().__init__(message)
        self.losses = list(losses)


class PublicationLedger:
    """The publication sequence numbers a recording received, per publisher."""

    def __init__(self) -> None:
        self._received: dict[Publisher, set[int]] = {}

    def received(self, topic: str, node: str, sequence: int) -> None:
        """The recording took message number ``sequence`` of ``node`` on ``topic``."""
        self._received.setdefault((topic, node), set()).add(sequence)

    def total(self) -> int:
        """Messages received."""
        return sum(len(numbers) for numbers in self._received.values())

    def lost(self, published: Mapping[Publisher, int],
             from_first: Collection[Publisher] = (),
             stop_edge: Collection[Publisher] = ()) -> list[Lost]:
        """Every publisher's missing messages.

        Args:
            published: messages each publisher reported publishing (a publisher missing
                here is checked up to the last number received).
            from_first: publishers whose every message belongs to the recording (they
                started after it was ready), so that number 1 on is expected.
            stop_edge: best-effort publishers whose very last message, alone, may be
                missing: the one a node publishes while it is being stopped, after the
                run (no acknowledgement exists to wait for on a best-effort topic).
        """
        losses = []
        for key in sorted(set(self._received) | {k for k, n in published.items() if n > 0}):
            numbers = self._received.get(key, set())
            last = max(published.get(key, 0), max(numbers, default=0))
            first = 1 if key in from_first or not numbers else min(numbers)
            missing = [n for n in range(first, last + 1) if n not in numbers]
            if key in stop_edge and missing[-1:] == [last] and last - 1 in numbers:
                missing.pop()
            if missing:
                losses.append(Lost(key[0], key[1], len(missing), missing[0], missing[-1]))
        return losses


def check_lossless(ledger: PublicationLedger, losses: Sequence[Lost]) -> None:
    """Raise :class:`RecordingLossError` naming every publisher that lost messages.

    Args:
        ledger: what the recording received.
        losses: what it lost (:meth:`PublicationLedger.lost`).

    Raises:
        RecordingLossError: one line: how many of how many messages, per publisher which.
    """
    if losses:
        count = sum(loss.count for loss in losses)
        raise RecordingLossError(
            f'the recording lost {count} of {ledger.total() + count} messages, '
            + '; '.join(loss.describe() for loss in losses)
            + ': the recording process did not take them in time (a busy host, a slow disk '
            'or the process stopped; wall mode does not wait for the recorder); the bag holds '
            'every other message', losses)
