"""The wall-clock soak's checks (:mod:`soak_wall`): sequence numbers per publisher, the
bag's messages per topic, the start and stop edges, gaps, and growth per process.

No ROS import (the bag is read back with rosbags): the runner feeds them what it received.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

STOP_EDGE = 1
"""Messages per publisher of a topic that may be published and not recorded when the nodes
are stopped."""
STALE_S = 0.5
"""The planner's default ``input_timeout_s``: a gap above it is an input it calls stale."""


@dataclass
class Stream:
    """The publication sequence numbers seen from one publisher, in constant memory."""

    first: int = 0
    last: int = 0
    count: int = 0
    holes: int = 0
    out_of_order: int = 0
    first_received_ns: int = 0

    def add(self, seq: int, received_ns: int) -> None:
        """One recorded message with sequence number ``seq``, received at ``received_ns``."""
        if self.count == 0:
            self.first, self.first_received_ns = seq, received_ns
        elif seq > self.last:
            self.holes += seq - self.last - 1
        else:
            self.out_of_order += 1
        self.last = max(self.last, seq)
        self.count += 1


@dataclass
class Sequences:
    """The publication sequence numbers seen on one topic, per publisher (``source``)."""

    streams: dict[str, Stream] = field(default_factory=dict)

    def add(self, seq: int, received_ns: int = 0, source: str = '') -> None:
        """One recorded message of publisher ``source`` (wall time of receipt, ns)."""
        self.streams.setdefault(source, Stream()).add(seq, received_ns)

    @property
    def count(self) -> int:
        """Messages received, all publishers."""
        return sum(s.count for s in self.streams.values())

    @property
    def holes(self) -> int:
        """Sequence numbers missing between each publisher's first and last received."""
        return sum(s.holes for s in self.streams.values())

    @property
    def out_of_order(self) -> int:
        """Messages received after one with a higher sequence number (same publisher)."""
        return sum(s.out_of_order for s in self.streams.values())

    @property
    def last(self) -> int:
        """The publishers' last received sequence numbers, summed (= messages published up
        to them)."""
        return sum(s.last for s in self.streams.values())

    def start_edge(self) -> int:
        """Messages published before each publisher's first received one, summed."""
        return sum(s.first - 1 for s in self.streams.values())

    def late_start(self, start_ns: int) -> int:
        """Start-edge messages of the publishers first received after ``start_ns``."""
        return sum(s.first - 1 for s in self.streams.values()
                   if s.first_received_ns > start_ns)


@dataclass
class Recorded:
    """One topic as read back from the bag: message count, first stamp, gaps (ns)."""

    count: int = 0
    first_ns: int = 0
    max_gap_ns: int = 0
    gaps_over_stale: int = 0
    stamps_after_start: int = 0
    _last_ns: int | None = field(default=None, repr=False)

    def add(self, stamp_ns: int, start_ns: int) -> None:
        """One message stamped ``stamp_ns``; gaps are counted from ``start_ns`` on."""
        if self.count == 0:
            self.first_ns = stamp_ns
        self.count += 1
        if stamp_ns < start_ns:
            return
        if self._last_ns is not None:
            gap = stamp_ns - self._last_ns
            self.max_gap_ns = max(self.max_gap_ns, gap)
            self.gaps_over_stale += gap > STALE_S * 1e9
        self.stamps_after_start += 1
        self._last_ns = stamp_ns


def read_bag(bag: Path, start_ns: int) -> dict[str, Recorded]:
    """Every topic of the bag (rosbags; log time = header stamp in wall mode)."""
    from rosbags.highlevel import AnyReader

    out: dict[str, Recorded] = {}
    with AnyReader([bag]) as reader:
        for connection, log_time, _raw in reader.messages():
            out.setdefault(connection.topic, Recorded()).add(log_time, start_ns)
    return out


def topic_checks(published: dict[str, int], recorded: dict[str, Recorded],
                 sequences: dict[str, Sequences], *, start_ns: int, max_gap_s: float,
                 publishers: dict[str, int] | None = None
                 ) -> tuple[list[dict[str, Any]], list[str]]:
    """Per topic: published (by its nodes) against recorded, the start and stop edges,
    holes and the longest gap; returns the rows and the problems found (one line each).
    ``publishers``: topic -> its number of publishers (default 1 each), each allowed
    :data:`STOP_EDGE`; a topic in the bag but not in ``published`` is a problem."""
    rows, problems = [], []
    for topic in sorted(set(recorded) - set(published)):
        problems.append(f'{topic}: {recorded[topic].count} messages in the bag on a topic '
                        'the run does not record')
    for topic, sent in published.items():
        got, seq = recorded.get(topic, Recorded()), sequences.get(topic, Sequences())
        allowed_stop = STOP_EDGE * (publishers or {}).get(topic, 1)
        start_edge = seq.start_edge() if seq.count else sent
        stop_edge = sent - seq.last
        row = {'topic': topic, 'published': sent, 'recorded': got.count,
               'publishers_seen': len(seq.streams),
               'start_edge': start_edge, 'holes': seq.holes, 'stop_edge': stop_edge,
               'out_of_order': seq.out_of_order,
               'first_recorded_after_start_s': (got.first_ns - start_ns) / 1e9,
               'max_gap_s': got.max_gap_ns / 1e9,
               'gaps_over_stale_s': got.gaps_over_stale}
        rows.append(row)
        where = f'{topic}: '
        if got.count == 0 or got.stamps_after_start == 0:
            problems.append(where + 'nothing recorded after /sim/start')
            continue
        if got.count != seq.count:
            problems.append(where + f'{got.count} messages in the bag, {seq.count} received')
        if seq.holes or seq.out_of_order:
            problems.append(where + f'{seq.holes} messages missing between the first and the '
                            f'last recorded ({seq.out_of_order} out of order)')
        late = seq.late_start(start_ns)
        if late:
            problems.append(where + f'the first {late} messages of a publisher are missing and '
                            'its first recorded one came after /sim/start')
        if not 0 <= stop_edge <= allowed_stop:
            problems.append(where + f'{stop_edge} messages published after the last recorded '
                            f'ones (allowed 0 to {allowed_stop})')
        if sent - got.count != start_edge + stop_edge + seq.holes:
            problems.append(where + f'published {sent}, recorded {got.count}: not explained '
                            f'by the edges ({start_edge} + {stop_edge})')
        if got.max_gap_ns > max_gap_s * 1e9:
            problems.append(where + f'a gap of {got.max_gap_ns / 1e9:.3f} s between two '
                            f'messages (limit {max_gap_s:g} s)')
    return rows, problems


def growth_checks(series: dict[str, list[dict[str, float]]], baseline_min: float,
                  rss_limit_mb: float) -> tuple[dict[str, dict[str, float]], list[str]]:
    """Per process: RSS, fds and threads at the first sample at or after ``baseline_min``
    and at the last sample; returns the growth and the problems (one line each)."""
    out, problems = {}, []
    for name, samples in series.items():
        base = next((s for s in samples if s['t_min'] >= baseline_min), None)
        if base is None or base is samples[-1]:
            problems.append(f'{name}: no sample after the baseline minute {baseline_min:g}')
            continue
        end = samples[-1]
        grow = {'from_min': base['t_min'], 'to_min': end['t_min'],
                'rss_mb': end['rss_mb'] - base['rss_mb'], 'fds': end['fds'] - base['fds'],
                'threads': end['threads'] - base['threads']}
        out[name] = grow
        if grow['rss_mb'] > rss_limit_mb:
            problems.append(f'{name}: RSS grew by {grow["rss_mb"]:.1f} MB from minute '
                            f'{base["t_min"]:.1f} to {end["t_min"]:.1f} (limit {rss_limit_mb:g})')
        for what in ('fds', 'threads'):
            if grow[what] > 0:
                problems.append(f'{name}: {grow[what]:+.0f} {what} from minute '
                                f'{base["t_min"]:.1f} to {end["t_min"]:.1f}')
    return out, problems
