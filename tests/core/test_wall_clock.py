"""Pure core of the real-vehicle (wall-clock) mode: config, latest inputs, loop statistics."""

from __future__ import annotations

import json

import pytest

from trust_av_common.params import ParamsError, build_config
from trust_av_common.wall_clock import (
    NS_PER_S,
    LatestInputs,
    LoopStats,
    WallClockConfig,
    format_summary,
    without_ages,
)


def test_config_defaults_and_validation() -> None:
    config = WallClockConfig()
    assert config.clock_mode == 'lockstep' and not config.wall
    assert WallClockConfig(clock_mode='wall', control_rate_hz=10.0).period_ns == 100_000_000
    with pytest.raises(ValueError, match='clock_mode'):
        WallClockConfig(clock_mode='realtime')
    with pytest.raises(ValueError, match='control_rate_hz'):
        WallClockConfig(control_rate_hz=0.0)
    with pytest.raises(ParamsError, match='input_timeout_s'):
        build_config(WallClockConfig, {'input_timeout_s': -1.0})


def test_latest_inputs_missing_and_stale() -> None:
    inputs = LatestInputs(['lead', 'ego'])
    assert inputs.problems(0, 0.5) == 'missing: lead, ego'
    inputs.put('lead', 0, 'a')
    inputs.put('lead', NS_PER_S, 'b')
    inputs.put('ego', 0, 'c')
    assert inputs.get('lead') == 'b'
    assert inputs.problems(NS_PER_S, 0.5) == 'stale: ego (1.000 s old)'
    assert inputs.problems(NS_PER_S, 0.5, ['lead']) == ''
    with pytest.raises(KeyError):
        inputs.put('human', 0, 'd')


def test_loop_stats_percentiles(tmp_path) -> None:  # type: ignore[no-untyped-def]
    stats = LoopStats(100_000_000)
    assert stats.summary()['jitter_ms']['p99'] is None
    for k, error_ns in enumerate([0, 1_000_000, -2_000_000, 3_000_000]):
        stats.tick(k * 100_000_000 + error_ns)
        stats.done(500_000)
    summary = stats.summary()
    # period errors: +1, -3, +5 ms -> |.| = 1, 3, 5
    assert summary['ticks'] == 4
    assert summary['jitter_ms']['p50'] == pytest.approx(3.0)
    assert summary['jitter_ms']['max'] == pytest.approx(5.0)
    assert summary['compute_ms']['p99'] == pytest.approx(0.5)
    assert 'p50/p99/max 3.00' in format_summary(summary)
    assert summary['published'] == {}
    for topic in ('/ego/plan', '/ego/accel_cmd', '/ego/plan'):
        stats.publish(topic)
    stats.write(tmp_path / 'j.json', 'planner')
    written = json.loads((tmp_path / 'j.json').read_text())
    assert written['node'] == 'planner'
    assert written['published'] == {'/ego/accel_cmd': 1, '/ego/plan': 2}
    with pytest.raises(ValueError):
        LoopStats(0)


def test_planner_core_without_follower_observes_the_av_only(run_config) -> None:  # type: ignore[no-untyped-def]
    import dataclasses

    from trust_av_common.kinematics import VehicleState
    from trust_av_planner.planner import AvPlanner

    planner = AvPlanner(run_config.planner, run_config.trust, 4.5)
    lead, av = VehicleState(40.0, 10.0), VehicleState(0.0, 5.0)
    first = planner.step(lead, [10.0, 10.0, 10.0], av, None, 0.0)
    second = planner.step(lead, [10.0, 10.0, 10.0], av, None, 0.0)
    # CA: the expected plan is the AV's last executed acceleration, held
    assert second.expected_mps2 == pytest.approx([first.result.plan_mps2[0]] * 3)
    gru = AvPlanner(dataclasses.replace(run_config.planner, predictor='gru'),
                    run_config.trust, 4.5)
    with pytest.raises(ValueError, match='predictor gru needs the human follower state'):
        gru.step(lead, [10.0, 10.0, 10.0], av, None, 0.0)


def test_diagnostics_message_of_stale_inputs_keeps_still_while_they_age() -> None:
    """The planner's ``/diagnostics`` message while its inputs are stale names them without
    their ages (in ``values``): a message that changed on every tick was published on every
    tick (``/diagnostics`` at 10 Hz instead of 1 Hz)."""
    from trust_av_common.health import ERROR, SolveRecord

    inputs = LatestInputs(['lead', 'ego'])
    inputs.put('lead', 0, object())
    inputs.put('ego', 0, object())
    reports = [SolveRecord(0.5).report(f'deadline missed (QoS event): ego; '
                                       f'{inputs.problems(now, 0.5)}', -2.0,
                                       {'ego': f'{now / NS_PER_S:.3f}'})
               for now in (NS_PER_S, 2 * NS_PER_S)]
    assert [level for level, _, _ in reports] == [ERROR, ERROR]
    assert reports[0][1] == reports[1][1] == ('commanding -2 m/s^2 (stale-input policy): '
                                              'deadline missed (QoS event): ego; stale: lead, ego')
    assert [values['input_age_ego_s'] for _, _, values in reports] == ['1.000', '2.000']
    assert without_ages('stale: lead (0.523 s old), ego (12.000 s old)') == 'stale: lead, ego'
