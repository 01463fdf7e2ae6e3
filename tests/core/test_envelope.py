"""The vehicle path's two gates, pure and property-based (hypothesis, derandomized): the input
checks of :mod:`trust_av_common.envelope` refuse exactly the messages with a value outside
its physical range, and a message they accept decodes without raising; the command envelope
gives a finite command within the acceleration and jerk limits for every input; the fallback
plan keeps its acceleration bounds at any speed; the Autoware Control is finite as float32."""

from __future__ import annotations

import itertools
import math
from types import SimpleNamespace as Ns
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from trust_av_autoware.control_output import ControlAdapterConfig, longitudinal
from trust_av_autoware.lane_inputs import InputError
from trust_av_common.envelope import (
    CommandEnvelope,
    InputRanges,
    odometry_problem,
    trajectory_problem,
    vector_problem,
)
from trust_av_common.kinematics import hold_gap_plan

RANGES = InputRanges()
SETTINGS = settings(max_examples=200, deadline=None, derandomize=True)
ANY_FLOAT = st.floats(allow_nan=True, allow_infinity=True)
WIDE = st.one_of(ANY_FLOAT, st.sampled_from([
    math.nan, math.inf, -math.inf, 500.0, -50.0, 1e39, 1e300, 3.5e38, -5.0, 100.0, 0.0,
    -5.000001, 100.000001, 1e9, -1e9, 1.000001e9]))
SEC = st.one_of(st.integers(-2**31, 2**31 - 1), st.sampled_from([-1, 0]))
NANOSEC = st.one_of(st.integers(0, 2**32 - 1), st.sampled_from([999_999_999, 10**9]))
FRAME = st.one_of(st.sampled_from(['odom', 'map', '', 'ego']), st.text(max_size=300))


def stamp(draw: Any) -> Ns:
    return Ns(sec=draw(SEC), nanosec=draw(NANOSEC))


def stamp_ok(t: Ns) -> bool:
    return t.sec >= 0 and t.nanosec < 10**9


def frame_ok(frame: str) -> bool:
    return len(frame) <= 256 and frame.isprintable()


@st.composite
def odometries(draw: Any) -> Ns:
    return Ns(header=Ns(stamp=stamp(draw), frame_id=draw(FRAME)), child_frame_id=draw(FRAME),
              pose=Ns(pose=Ns(position=Ns(x=draw(WIDE)))),
              twist=Ns(twist=Ns(linear=Ns(x=draw(WIDE)))))


@SETTINGS
@given(odometries())
def test_odometry_is_refused_exactly_when_a_read_value_is_out_of_its_range(msg: Ns) -> None:
    x, v = msg.pose.pose.position.x, msg.twist.twist.linear.x
    usable = (stamp_ok(msg.header.stamp) and frame_ok(msg.header.frame_id)
              and frame_ok(msg.child_frame_id)
              and math.isfinite(x) and abs(x) <= RANGES.input_position_abs_max_m
              and math.isfinite(v)
              and RANGES.input_speed_min_mps <= v <= RANGES.input_speed_max_mps)
    problem = odometry_problem(msg, RANGES)
    assert (problem == '') == usable, (problem, msg)
    assert '\n' not in problem


@st.composite
def trajectories(draw: Any) -> tuple[Ns, str]:
    field = draw(st.sampled_from(['velocities', 'accelerations']))
    points = []
    for _ in range(draw(st.integers(0, 6))):
        shape = draw(st.sampled_from(['one', 'none', 'positions', 'many']))
        values = {'one': [draw(WIDE)], 'none': [], 'positions': [],
                  'many': [draw(WIDE), draw(WIDE)]}[shape]
        other = 'accelerations' if field == 'velocities' else 'velocities'
        point = {field: values, other: [draw(WIDE)] if shape == 'none' else [],
                 'positions': [1.0] if shape == 'positions' else [],
                 'time_from_start': stamp(draw) if draw(st.booleans()) else
                 Ns(sec=len(points), nanosec=0)}
        points.append(Ns(**point))
    return Ns(header=Ns(stamp=stamp(draw), frame_id=draw(FRAME)), points=points), field


@SETTINGS
@given(trajectories())
def test_a_trajectory_is_refused_unless_every_point_carries_a_value_in_range(
        case: tuple[Ns, str]) -> None:
    from trust_av_common.ros.messages import trajectory_times, trajectory_values

    msg, field = case
    low, high = -10.0, 40.0
    problem = trajectory_problem(msg, field, low, high, 5)
    times = [p.time_from_start.sec * 10**9 + p.time_from_start.nanosec for p in msg.points]
    usable = (stamp_ok(msg.header.stamp) and frame_ok(msg.header.frame_id)
              and 1 <= len(msg.points) <= 5
              and all(len(getattr(p, field)) >= 1 and math.isfinite(getattr(p, field)[0])
                      and low <= getattr(p, field)[0] <= high and stamp_ok(p.time_from_start)
                      for p in msg.points)
              and all(b > a for a, b in itertools.pairwise(times)))
    assert (problem == '') == usable, (problem, msg)
    if not problem:   # what the nodes then read never raises
        values, at = trajectory_values(msg, field), trajectory_times(msg)
        assert len(values) == len(at) == len(msg.points)


def test_a_preview_with_positions_instead_of_velocities_or_no_points_is_named() -> None:
    header = Ns(stamp=Ns(sec=1, nanosec=0), frame_id='odom')
    positions = Ns(header=header, points=[Ns(positions=[1.0], velocities=[], accelerations=[],
                                             time_from_start=Ns(sec=0, nanosec=0))])
    assert trajectory_problem(positions, 'velocities', -5, 100, 10) == \
        'points[0] has no velocities'
    assert trajectory_problem(Ns(header=header, points=[]), 'velocities', -5, 100, 10) == \
        '0 points (need 1 to 10)'


@SETTINGS
@given(st.tuples(WIDE, WIDE, WIDE), st.builds(Ns, sec=SEC, nanosec=NANOSEC))
def test_trust_vector_is_refused_exactly_when_a_value_is_out_of_range(
        xyz: tuple[float, float, float], at: Ns) -> None:
    msg = Ns(header=Ns(stamp=at, frame_id=''), vector=Ns(x=xyz[0], y=xyz[1], z=xyz[2]))
    usable = stamp_ok(at) and all(math.isfinite(v) and abs(v) <= 1e6 for v in xyz)
    assert (vector_problem(msg, 1e6) == '') == usable


@settings(max_examples=200, deadline=None, derandomize=True)
@given(st.lists(st.tuples(WIDE, st.booleans()), min_size=1, max_size=60),
       st.sampled_from([0.001, 0.02, 0.1, 1.0]), st.sampled_from([5.0, 60.0]))
def test_the_envelope_holds_for_every_command_sequence(commands: list[tuple[float, bool]],
                                                      period_s: float, jerk: float) -> None:
    envelope = CommandEnvelope(-3.0, 3.0, jerk, -2.0)
    previous = None
    changed = 0
    for requested, stop in commands:
        value = envelope.command(requested, period_s, stop=stop)
        assert math.isfinite(value) and -3.0 <= value <= 3.0
        if previous is not None and not stop:
            assert abs(value - previous) <= jerk * period_s * (1 + 1e-12)
        changed += value != requested
        previous = value
    assert changed <= envelope.clipped   # every change counted (NaN != NaN counts too)
    # the plan published beside it: finite, within the bounds, starting with the command
    plan = envelope.plan(np.array([c for c, _ in commands]), previous, 1e-6)
    assert np.all(np.isfinite(plan)) and plan[0] == previous
    assert np.all((plan >= -3.0 - 1e-6) & (plan <= 3.0 + 1e-6))


def test_the_envelope_passes_sane_commands_unchanged_and_counts_what_it_clips() -> None:
    envelope = CommandEnvelope(-3.0, 3.0, None, -2.0)   # lock-step: no jerk limit
    sane = [0.0, 3.0, -3.0, 1.25, -2.0]
    assert [envelope.command(a, 1.0) for a in sane] == sane and envelope.clipped == 0
    assert envelope.command(math.nan, 1.0) == -2.0
    assert envelope.command(-4640.0, 1.0) == -3.0
    assert envelope.command(-1e301, 1.0) == -3.0 and envelope.command(500.0, 1.0) == 3.0
    assert dict(envelope.counts) == {'not_finite': 1, 'accel_bound': 3}
    wall = CommandEnvelope(-3.0, 3.0, 60.0, -2.0)
    assert [wall.command(a, 0.01) for a in (3.0, -3.0)] == [3.0, 2.4]   # 60 m/s^3 x 10 ms
    assert wall.command(-2.0, 0.01, stop=True) == -2.0                  # the hand-over
    assert wall.counts['jerk_bound'] == 1


FALLBACK = dict(standstill_gap_m=5.0, time_headway_s=1.2, gap_gain_per_s2=0.3,
                speed_gain_per_s=0.8, accel_min_mps2=-3.0, accel_max_mps2=3.0,
                speed_min_mps=0.0, speed_max_mps=36.0)
FINITE = st.floats(-1e300, 1e300)


@pytest.mark.parametrize(('speed', 'first'), [(500.0, -3.0), (-50.0, 3.0), (1e39, -3.0),
                                              (1e300, -3.0)])
def test_the_fallback_keeps_its_acceleration_bounds_at_the_issue_s_speeds(
        speed: float, first: float) -> None:
    """Before, the speed bound was applied last: (36 - 500) / 0.1 = -4640 m/s^2."""
    plan = hold_gap_plan(30.0, speed, [20.0] * 30, dt_s=0.1, **FALLBACK)
    assert plan[0] == first and all(-3.0 <= a <= 3.0 for a in plan)


@SETTINGS
@given(FINITE, FINITE, st.lists(FINITE, min_size=1, max_size=5),
       st.sampled_from([0.01, 0.1, 1.0]))
def test_the_fallback_plan_is_within_its_acceleration_bounds_for_every_finite_state(
        gap: float, speed: float, lead: list[float], dt_s: float) -> None:
    with np.errstate(all='ignore'):
        plan = hold_gap_plan(gap, speed, lead, dt_s=dt_s, **FALLBACK)
    # a finite state gives a finite first command within the bounds (the rolled-out later
    # states may overflow: inf - inf is NaN, which the node's envelope replaces)
    assert math.isfinite(plan[0]) and -3.0 <= plan[0] <= 3.0
    assert all(-3.0 <= a <= 3.0 or math.isnan(a) for a in plan)


@SETTINGS
@given(WIDE, WIDE)
def test_the_autoware_longitudinal_is_float32_finite_or_refused(accel: float,
                                                               speed: float) -> None:
    config = ControlAdapterConfig()
    try:
        command = longitudinal(accel, speed, config, RANGES.input_speed_max_mps)
    except InputError as error:
        assert error.kind in ('not_finite', 'out_of_range')
        return
    for value in (command.velocity_mps, command.acceleration_mps2):
        assert np.isfinite(np.float32(value))
    assert 0.0 <= command.velocity_mps <= RANGES.input_speed_max_mps
    assert abs(command.acceleration_mps2) <= config.max_abs_accel_mps2
