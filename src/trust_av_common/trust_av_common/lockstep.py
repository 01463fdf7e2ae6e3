"""Lock-step bookkeeping (sim time): integer-nanosecond stamps and the per-step input buffer.

Every message that a node pairs by step carries a header stamp; a node acts when it holds
every input of a stamp (:class:`StepBuffer`), never by arrival order. The protocol itself is
described in :mod:`trust_av_common.topics`.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Iterable

__all__ = ['StepBuffer', 'split_ns', 'stamp_ns']


def stamp_ns(t_s: float) -> int:
    """Integer nanoseconds of a time in seconds (the key that pairs messages of a step)."""
    return round(t_s * 1e9)


def split_ns(ns: int) -> tuple[int, int]:
    """(sec, nanosec) of ``builtin_interfaces/Time``."""
    return ns // 1_000_000_000, ns % 1_000_000_000


class StepBuffer:
    """Messages keyed by (input, stamp); tells when every input of a stamp has arrived.

    Args:
        inputs: names of the inputs a step needs.
    """

    def __init__(self, inputs: Iterable[str]) -> None:
        self.inputs = tuple(inputs)
        self._items: dict[int, dict[str, object]] = defaultdict(dict)

    def put(self, name: str, stamp: int, item: object) -> None:
        """Store one input; a second message for the same input and stamp is an error."""
        if name not in self.inputs:
            raise KeyError(f'unknown input {name!r}')
        if name in self._items[stamp]:
            raise ValueError(f'duplicate {name} for stamp {stamp} ns')
        self._items[stamp][name] = item

    def ready(self, stamp: int, needed: Iterable[str] | None = None) -> bool:
        """True when every needed input of ``stamp`` is there."""
        have = self._items.get(stamp, {})
        return all(n in have for n in (self.inputs if needed is None else needed))

    def ready_stamps(self, needed: Iterable[str] | None = None) -> list[int]:
        """Stamps whose needed inputs are all there, oldest first."""
        needed = tuple(self.inputs if needed is None else needed)
        return sorted(s for s in self._items if self.ready(s, needed))

    def pop(self, stamp: int) -> dict[str, object]:
        """Take the inputs of ``stamp`` (and forget older stamps)."""
        items = self._items.pop(stamp)
        for old in [s for s in self._items if s < stamp]:
            del self._items[old]
        return items

    def take(self, name: str, stamp: int) -> object:
        """Take one stored input of ``stamp``."""
        return self._items[stamp].pop(name)
