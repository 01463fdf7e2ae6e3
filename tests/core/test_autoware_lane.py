"""The Autoware adapters' pure core: the AV and the objects projected onto a lane centreline,
the lead chosen among them, the planner command as a longitudinal command, the status.

The lane is an L: 100 m east along y = 0, then 100 m north along x = 100 (arc length 0 at
the origin, 100 at the corner, 200 at the end)."""

from __future__ import annotations

import math

import pytest
from support.paths import REPO

from trust_av_autoware.adapter_status import AdapterStatus
from trust_av_autoware.control_output import ControlAdapterConfig, longitudinal
from trust_av_autoware.labels import TRUST_NAMES, finite_values, plan_names
from trust_av_autoware.lane_inputs import (
    BOUNDING_BOX,
    CYLINDER,
    POLYGON,
    InputError,
    LaneAdapterConfig,
    Planar,
    centreline_from_points,
    ego_on_lane,
    half_length_m,
    lead_from_objects,
    seen,
    yaw,
)
from trust_av_common.health import ERROR, OK, WARN
from trust_av_common.params import ParamsError

LANE = centreline_from_points([(0.0, 0.0), (100.0, 0.0), (100.0, 100.0)])
CONFIG = LaneAdapterConfig(vehicle_length_m=4.5)   # lane 3.5 m, base_link to front 3.79 m


def test_the_av_is_its_front_bumper_s_distance_along_the_lane_and_its_speed_along_it() -> None:
    straight = ego_on_lane(LANE, Planar(50.0, 0.3, 0.0, 10.0, 0.0), CONFIG)
    assert straight.position_m == pytest.approx(50.0 + 3.79)
    assert (straight.speed_mps, straight.lateral_m) == (pytest.approx(10.0), pytest.approx(0.3))
    # round the corner, heading north (yaw pi/2); x = 99.8 is 0.2 m left of the lane
    north = ego_on_lane(LANE, Planar(99.8, 40.0, math.pi / 2, 5.0, 0.0), CONFIG)
    assert north.position_m == pytest.approx(140.0 + 3.79)
    assert north.speed_mps == pytest.approx(5.0) and north.lateral_m == pytest.approx(0.2)
    # a body-frame twist of a car yawed 30 degrees off the lane: its component along the lane
    skew = ego_on_lane(LANE, Planar(20.0, 0.0, math.radians(30.0), 10.0, 0.0), CONFIG)
    assert skew.speed_mps == pytest.approx(10.0 * math.cos(math.radians(30.0)))


def test_the_lead_is_chosen_among_the_objects_on_a_bent_lane() -> None:
    ego_base = Planar(50.0, 0.0, 0.0, 10.0, 0.0)
    ego = ego_on_lane(LANE, ego_base, CONFIG)
    objects = [seen(Planar(30.0, 0.0, 0.0, 12.0, 0.0), 2.3),        # behind
               seen(Planar(70.0, 3.5, 0.0, 8.0, 0.0), 2.3),         # next lane, nearer
               seen(Planar(100.2, 20.0, math.pi / 2, 6.0, 0.0), 2.3),  # on the lane, farther
               seen(Planar(80.0, -0.5, 0.0, 7.0, 0.0), 2.3)]        # the lead
    lead = lead_from_objects(LANE, ego, 50.0, objects, CONFIG)
    assert lead is not None and lead.index == 3
    # published so that the planner's gap (x_lead - x_ego - vehicle_length_m) is the real one
    assert lead.gap_m == pytest.approx(80.0 - 2.3 - (50.0 + 3.79))
    assert lead.state.position_m - ego.position_m - CONFIG.vehicle_length_m == \
        pytest.approx(lead.gap_m)
    assert lead.state.speed_mps == pytest.approx(7.0)
    # without it, the one round the corner (speed along the lane there: north)
    lead = lead_from_objects(LANE, ego, 50.0, objects[:3], CONFIG)
    assert lead is not None and lead.index == 2 and lead.state.speed_mps == pytest.approx(6.0)
    assert lead_from_objects(LANE, ego, 50.0, objects[:2], CONFIG) is None
    assert lead_from_objects(LANE, ego, 50.0, [], CONFIG) is None


def test_an_av_off_its_lane_or_beyond_its_ends_is_refused() -> None:
    for planar in (Planar(50.0, 1.8, 0.0, 1.0, 0.0), Planar(-2.0, 0.0, 0.0, 1.0, 0.0),
                   Planar(100.0, 102.0, 0.0, 1.0, 0.0)):
        with pytest.raises(InputError, match='off the lane') as caught:
            ego_on_lane(LANE, planar, CONFIG)
        assert caught.value.kind == 'off_lane'
    ego_on_lane(LANE, Planar(-1.0, 0.0, 0.0, 1.0, 0.0), CONFIG)   # within half a lane width


@pytest.mark.parametrize(('call', 'kind', 'words'), [
    (lambda: ego_on_lane(LANE, Planar(math.nan, 0.0, 0.0, 1.0, 0.0), CONFIG), 'not_finite',
     'x is not finite'),
    (lambda: ego_on_lane(LANE, Planar(1.0, 0.0, 0.0, math.inf, 0.0), CONFIG), 'not_finite',
     'vx is not finite'),
    (lambda: yaw(0.0, 0.0, 0.0, 0.0, 'kinematic state'), 'bad_orientation', 'zero quaternion'),
    (lambda: yaw(0.0, 0.0, math.nan, 1.0, 'objects[2]'), 'not_finite',
     'objects[2] orientation.z is not finite'),
    (lambda: seen(Planar(1.0, 2.0, 0.0, 1.0, math.nan), 2.0), 'not_finite', 'vy'),
    (lambda: half_length_m(7, 4.0, []), 'bad_shape', 'unknown shape type 7'),
    (lambda: half_length_m(BOUNDING_BOX, -1.0, []), 'bad_shape', 'negative'),
    (lambda: half_length_m(POLYGON, 0.0, []), 'bad_shape', 'without footprint'),
    (lambda: half_length_m(BOUNDING_BOX, math.nan, []), 'not_finite', 'dimensions.x'),
    (lambda: centreline_from_points([(1.0, 1.0), (1.0, 1.0)]), 'bad_centreline',
     'at least 2 points'),
    (lambda: centreline_from_points([(0.0, 0.0), (math.inf, 1.0)]), 'bad_centreline',
     'not finite'),
])
def test_malformed_values_are_refused_with_their_name(call, kind: str, words: str) -> None:
    with pytest.raises(InputError, match=words.replace('[', r'\[').replace(']', r'\]')) as caught:
        call()
    assert caught.value.kind == kind


def test_shapes_give_the_distance_from_centre_to_rear() -> None:
    assert half_length_m(BOUNDING_BOX, 4.6, []) == 2.3
    assert half_length_m(CYLINDER, 0.6, []) == pytest.approx(0.3)
    assert half_length_m(POLYGON, 0.0, [2.0, 2.0, -1.5, -2.5]) == 2.5
    assert half_length_m(POLYGON, 0.0, [1.0, 3.0]) == 0.0   # the footprint is all ahead


def test_yaw_of_a_quaternion() -> None:
    half = math.radians(30.0) / 2
    assert yaw(0.0, 0.0, math.sin(half), math.cos(half), 'q') == pytest.approx(math.radians(30))
    assert yaw(0.0, 0.0, 0.0, 2.0, 'q') == 0.0   # not normalised: still a heading


def test_a_repeated_path_pose_is_not_a_segment() -> None:
    lane = centreline_from_points([(0.0, 0.0), (0.0, 0.0), (10.0, 0.0), (10.0, 0.0)])
    assert lane.length_m == 10.0


def test_the_longitudinal_command() -> None:
    config = ControlAdapterConfig()   # velocity over 0.1 s, |a| <= 10 m/s^2
    command = longitudinal(-2.0, 10.0, config, 100.0)
    assert (command.velocity_mps, command.acceleration_mps2) == (pytest.approx(9.8), -2.0)
    assert longitudinal(-3.0, 0.1, config, 100.0).velocity_mps == 0.0   # never below standstill
    assert longitudinal(1.5, 20.0, config, 100.0).velocity_mps == pytest.approx(20.15)
    for accel, speed, kind in ((math.nan, 1.0, 'not_finite'), (1.0, math.inf, 'not_finite'),
                               (-10.5, 1.0, 'out_of_range')):
        with pytest.raises(InputError) as caught:
            longitudinal(accel, speed, config, 100.0)
        assert caught.value.kind == kind


def test_adapter_parameters_are_checked() -> None:
    with pytest.raises(ParamsError, match='lane_width_m'):
        LaneAdapterConfig(vehicle_length_m=4.5, lane_width_m=0.0)
    with pytest.raises(ParamsError, match='velocity_horizon_s'):
        ControlAdapterConfig(velocity_horizon_s=-1.0)


def test_the_status_says_what_is_missing_dropped_or_done() -> None:
    status = AdapterStatus(('a', 'b'))
    level, message, values = status.report(10**9, 'no a received', 'working')
    assert (level, message) == (ERROR, 'not publishing: no a received')
    assert values['input_age_a_s'] == 'never' and values['dropped_total'] == '0'
    status.received('a', 0)
    status.dropped('a', 'frame', "in frame 'odom', expected 'map'")
    level, message, values = status.report(10**9, '', 'working')
    assert (level, message) == (WARN, "dropped a: in frame 'odom', expected 'map'")
    assert values['a_dropped_frame'] == '1' and values['input_age_a_s'] == '1.000'
    status.received('a', 0)
    status.used('a')
    status.published('out')
    level, message, values = status.report(10**9, '', 'working')
    assert (level, message) == (OK, 'working')
    assert (values['a_received'], values['a_used'], values['out_published']) == ('2', '1', '1')


def test_plan_values_are_named_by_their_time() -> None:
    assert plan_names([0.0, 0.5, 1.0, 10.0]) == ['accel_mps2_at_0s', 'accel_mps2_at_0.5s',
                                                 'accel_mps2_at_1s', 'accel_mps2_at_10s']
    assert TRUST_NAMES == ('explicability', 'performance', 'trust')
    assert finite_values([0.0, -1.0]) and not finite_values([0.0, math.nan])


def test_the_operations_page_lists_every_adapter_parameter_with_its_default() -> None:
    """docs/operations/real-vehicle.md has a row per field of both adapters' configurations,
    with the field's default (vehicle_length_m: the shipped /** value)."""
    import dataclasses

    page = (REPO / 'docs' / 'operations' /
            'real-vehicle.md').read_text()
    rows = {line.split('|')[1].strip(): line.split('|')[2].strip()
            for line in page.splitlines() if line.startswith('| `')}
    for cls in (LaneAdapterConfig, ControlAdapterConfig):
        for field in dataclasses.fields(cls):
            default = field.default
            if default is dataclasses.MISSING:
                assert rows[f'`{field.name}`'] == 'the `/**` value (4.5)'
            elif isinstance(default, str):
                assert rows[f'`{field.name}`'] == f'`{default}`'
            else:
                assert rows[f'`{field.name}`'] == f'{default:g}', field.name
