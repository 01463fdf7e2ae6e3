"""One drive through the node graph with a scripted page (no browser): its clock is the
participant's, and its recording accounts for every message.

The page is played in this process: the drive's server is a stand-in that keeps the frames
it is given, and the participant presses Start through the drive's own link
(:class:`~trust_av.drive.link.DriveLink`) after reading the start screen for
:data:`READING_S`, far longer than the drive. The drive's recording loop is stalled once for
:data:`STALL_S` with room for 3 samples per topic (its subscriptions' depth, patched in this
process; the nodes keep theirs), so it falls behind and loses messages. The study rates
continuously: the participant sets the scale on the start screen and moves it once while
driving. One drive serves every test here (a node-graph run is the expensive part)."""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import pytest
from support.rosbag2_rules import check_bag_directory

pytestmark = pytest.mark.wall_clock

READING_S = 4.0
"""How long the participant reads the start screen before pressing Start."""
DRIVE_S = 6.0
STALL_S = 2.0
"""The recording loop's one stall, once the drive runs (3 samples at 10 Hz are 0.3 s)."""
RATING_PERIOD_S = 1.0
SCALE = (30, 80)
"""The continuous scale's position on the start screen, and after the move (made once the
scale's first sample, at the start, is taken)."""


class _Page:
    """The drive's server as the drive sees it: the frames sent to the page."""

    def __init__(self) -> None:
        self.frames: list[dict[str, Any]] = []

    def send(self, frame: dict[str, Any]) -> None:
        self.frames.append(frame)


@dataclass
class Driven:
    bag: Path
    outcome: Any
    config: Any
    started_after_s: float
    moved_ns: int


@pytest.fixture(scope='module')
def driven(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Driven]:
    import trust_av_common.ros.qos as qos
    from human_driver_sim.follower_plant import FollowerConfig
    from preceding_traffic.sources import load_trace
    from trust_av.drive import page_hooks
    from trust_av.drive.gate import READY, Gate
    from trust_av.drive.graph_run import run_drive
    from trust_av.drive.link import DriveLink
    from trust_av.drive.server import DriveServer
    from trust_av.system.config import load_run_config

    work = tmp_path_factory.mktemp('drive')
    patch = pytest.MonkeyPatch()
    patch.setattr(qos, 'HISTORY_DEPTH', 3)
    stalls: list[float] = []

    def stall(_self: Any, _run: Any, _now_ns: int) -> None:
        if not stalls:
            stalls.append(time.monotonic())
            time.sleep(STALL_S)          # the recording loop takes nothing meanwhile

    patch.setattr(page_hooks.DrivePage, 'every_second', stall, raising=False)
    sampled = threading.Event()
    sample_scale = page_hooks.DrivePage.sample_scale

    def observed(self: Any, due_s: float) -> None:
        sample_scale(self, due_s)
        sampled.set()

    patch.setattr(page_hooks.DrivePage, 'sample_scale', observed)
    config = load_run_config()
    trace = load_trace('us06', config.planner.dt_s, config.trace)
    follower = FollowerConfig()
    rate_hz = config.clock.control_rate_hz
    link = DriveLink(Gate(rate_hz, follower.accel_min_mps2, follower.accel_max_mps2,
                          continuous=True))
    shown: list[float] = []
    moved: list[int] = []

    def participant() -> None:
        while link.greet.get('phase') != READY:     # the start screen is shown
            time.sleep(0.01)
        shown.append(time.monotonic())
        link.on_message({'type': 'trust', 'value': SCALE[0]}, time.time_ns())
        time.sleep(READING_S)
        link.on_message({'type': 'ready'}, time.time_ns())
        sampled.wait(timeout=60)
        moved.append(time.time_ns())
        link.on_message({'type': 'trust', 'value': SCALE[1]}, moved[0])

    page = _Page()
    reader = threading.Thread(target=participant, daemon=True)
    reader.start()
    bag = work / 'drive_01'
    try:
        outcome = run_drive(config, 'us06', trace, bag, server=cast(DriveServer, page),
                            link=link, follower=follower, metadata={'trust_av.drive': '1'},
                            duration_s=DRIVE_S, rate_hz=rate_hz, abandon_after_s=60.0,
                            start_timeout_s=60.0, questionnaire=False,
                            questionnaire_timeout_s=1.0, rating_period_s=RATING_PERIOD_S,
                            rating_mode='continuous')
    finally:
        patch.undo()
    assert stalls, 'the recording loop was never stalled'
    reader.join(timeout=60)
    yield Driven(bag, outcome, config, READING_S, moved[0])


def test_a_slow_start_counts_trust_from_the_start_only(driven: Driven) -> None:
    """The monitor's trust at the drive's end is within its ceiling for the drive's time,
    delta * t_drive, although the participant read the start screen for longer than the
    drive (it used to grow from the nodes' start: 8.28 after a 30 s drive whose ceiling
    is 3.0)."""
    from trust_av.drive.bag_data import read_drive

    drive = read_drive(driven.bag)
    outcome = driven.outcome
    assert outcome.status == 'done' and outcome.driven_s >= DRIVE_S
    trust = drive.series.monitor_trust
    finite = trust[trust == trust]
    assert len(finite) > 0
    ceiling = driven.config.trust.trust_growth_rate * outcome.driven_s
    assert float(finite[-1]) <= ceiling + 1e-9, (float(finite[-1]), ceiling)
    assert float(finite.max()) <= ceiling + 1e-9
    meta = drive.metadata
    start, end = int(meta['trust_av.drive.start_ns']), int(meta['trust_av.drive.end_ns'])
    assert (end - start) / 1e9 == pytest.approx(outcome.driven_s, abs=0.1)
    assert drive.series.times_s[0] >= 0.0 and drive.series.times_s[-1] <= outcome.driven_s


def test_the_summary_gives_the_monitor_trust_on_the_ratings_scale(driven: Driven) -> None:
    """summary.csv's final_monitor_trust is the monitor's last trust on [0, 1], the scale of
    the ratings beside it (the paper's model maps T(0) + delta * 600 s to 1), not its raw T."""
    from trust_av.drive.bag_data import read_drive
    from trust_av.drive.study import drive_summary

    model = driven.config.trust_model()
    low, high = model.trust_range
    summary, _ = drive_summary(driven.bag, None, driven.outcome, [], 4.5, 10.0, model)
    raw = read_drive(driven.bag).series.monitor_trust
    last = float(raw[raw == raw][-1])
    assert high - low > 1.0   # a raw T and its unit value differ: the test can tell them apart
    assert summary['final_monitor_trust'] == pytest.approx((last - low) / (high - low),
                                                           abs=1e-4)
    assert 0.0 <= summary['final_monitor_trust'] <= 1.0


def test_a_drive_whose_recorder_fell_behind_names_what_it_lost(driven: Driven) -> None:
    """The drive keeps its bag and names every publisher that lost messages, in its outcome
    and in the bag's metadata; for the traffic node (it publishes only after the start),
    recorded + lost = what it reports publishing."""
    from rosbags.highlevel import AnyReader

    from trust_av.drive.bag_data import custom_data

    outcome, bag = driven.outcome, driven.bag
    assert check_bag_directory(bag) == []
    losses = {(loss.topic, loss.node): loss.count for loss in outcome.losses}
    assert losses, 'a stalled recording lost nothing?'
    meta = custom_data(bag)
    assert int(meta['trust_av.recording.lost']) == sum(losses.values())
    for loss in outcome.losses:
        key = f'trust_av.recording.lost.{loss.topic.strip("/").replace("/", ".")}.{loss.node}'
        assert meta[key].startswith(f'{loss.count} (publications {loss.first}'), key
    with AnyReader([bag]) as reader:
        recorded = {c.topic: c.msgcount for c in reader.connections}
    reports = {path.name.split('.')[0]: json.loads(path.read_text())['published']
               for path in bag.with_name(bag.name + '.logs').glob('*.jitter.json')}
    topic = '/preceding_vehicle/odom'
    assert losses.get((topic, 'preceding_traffic'), 0) > 0, losses   # 2 s at 10 Hz > 3
    assert recorded[topic] + losses[(topic, 'preceding_traffic')] == \
        reports['preceding_traffic'][topic]


def test_the_continuous_scale_is_recorded_from_the_start_at_its_period(driven: Driven) -> None:
    """Each /driver/rating is the scale's position when it was taken: the first, due at the
    start, the start screen's value; the moved value after the move; none before its time
    on the period's grid (a stalled loop takes them late); y is how long the scale had stood
    there (the first: at least the start screen's reading time)."""
    from rosbags.highlevel import AnyReader

    from trust_av.drive.bag_data import custom_data

    start = int(custom_data(driven.bag)['trust_av.drive.start_ns'])
    with AnyReader([driven.bag]) as reader:
        ratings = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages(
            connections=[c for c in reader.connections if c.topic == '/driver/rating'])]
    stamps = [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for m in ratings]
    # due at 0 and 1 s, both taken before the loop's stall (at a second of the loop's own
    # clock, which starts after the drive's); more after it, as the drive goes on
    assert len(ratings) >= 2, [ns - start for ns in stamps]
    assert ratings[0].vector.z == SCALE[0] and ratings[-1].vector.z == SCALE[1]
    for k, (msg, ns) in enumerate(zip(ratings, stamps, strict=True)):
        assert ns - start >= k * RATING_PERIOD_S * 1e9 - 0.05e9   # never ahead of its time
        assert msg.vector.y >= 0.0
        if ns < driven.moved_ns:
            assert msg.vector.z == SCALE[0], (k, ns - driven.moved_ns)
        elif ns > driven.moved_ns + 0.05e9:
            assert msg.vector.z == SCALE[1], (k, ns - driven.moved_ns)
        assert msg.vector.x == pytest.approx(msg.vector.z / 100.0)
    assert ratings[0].vector.y >= driven.started_after_s - 0.5   # set on the start screen
    assert [v for _, v in driven.outcome.ratings] == [m.vector.x for m in ratings]
