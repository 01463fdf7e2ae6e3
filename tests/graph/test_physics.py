"""Physics is checked: a gap at or below 0 m is a collision (the run ends there, the summary
says so, exit status 3, in-process and through the graph, the bag complete); a trace that
speeds up or brakes beyond a road vehicle (km/h read as m/s) is refused with one line; no
summary figure is made of values that do not exist; the core never divides by a zero speed.
A graph run's record names what ran: each group's component and every node's effective
parameters (bag metadata, logs, printed header). Study axes are each case once."""

from __future__ import annotations

import csv
import dataclasses
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from rosbags.rosbag2 import Reader
from support.graph import assert_records_equal  # the graph == in-process comparison
from support.rosbag2_rules import check_bag_directory  # the test-side oracle module

from preceding_traffic.bags import write_trace_bag
from preceding_traffic.errors import PrecedingTrafficError
from preceding_traffic.sources import load_trace
from preceding_traffic.traces import SHIPPED_TRACES, TRAINING_TRACES, TraceConfig, trace_path
from trust_av.cli.options import EXIT_COLLISION, format_metrics
from trust_av.errors import TrustAvAppError
from trust_av.graph.bag_records import records_from_bag
from trust_av.study.sweep import sweep_cases
from trust_av.system import run_record
from trust_av.system.closed_loop import simulate
from trust_av.system.config import load_run_config
from trust_av.system.metrics import compute_metrics
from trust_av_common.kinematics import VehicleState, collision
from trust_av_common.topics import TOPICS, qualified
from trust_av_planner.planner import observe

COLLISION_STEP = 8
"""The step at which the AV of the shipped configuration reaches a lead that brakes from
30 m/s at 9 m/s^2 (the AV brakes at most 3 m/s^2)."""


def write_trace(path: Path, speeds: list[float]) -> Path:
    path.write_text('time_s,speed_mps\n' + ''.join(f'{t},{v}\n' for t, v in enumerate(speeds)))
    return path


def hard_stop(path: Path) -> Path:
    """A lead that cruises at 30 m/s, then brakes at 9 m/s^2 (within what a car can) to a
    stop and stands: the AV, which may brake at 3 m/s^2, cannot stop in time."""
    return write_trace(path, [30.0 if k <= 3 else max(0.0, 30.0 - 9.0 * (k - 3))
                              for k in range(31)])


def cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, '-m', 'trust_av.cli', *args],
                          capture_output=True, text=True, timeout=600, check=False)


def test_collision_names_the_step_and_the_vehicles() -> None:
    assert collision(3, 3.0, 10.0, 8.0) is None
    assert collision(3, 3.0, 10.0, float('nan')) is None      # the output checks' business
    ahead = collision(4, 4.0, 0.0, -1.0)                      # both: the AV's first
    assert ahead is not None and (ahead.front, ahead.rear, ahead.gap_m) == (
        'preceding traffic', 'AV', 0.0)
    behind = collision(5, 5.5, 2.0, -0.25)
    assert behind is not None and behind.line() == (
        'collision at step 5 (t = 5.5 s): the human reached the AV (gap -0.25 m)')
    assert collision(6, 6.0, 2.0, None) is None               # no follower known


def test_a_stopped_human_behind_a_touching_av_divides_by_no_zero() -> None:
    av, human = VehicleState(4.0, 0.0), VehicleState(0.0, 0.0)      # gap -0.5 m, speed 0
    seen = observe(av, human, 0.0, length_m=4.5, headway_cap_s=10.0)
    assert (seen.gap_m, seen.time_headway_s) == (-0.5, 0.0)
    far = observe(VehicleState(40.0, 0.0), human, 0.0, length_m=4.5, headway_cap_s=10.0)
    assert far.time_headway_s == 10.0                               # the cap, as before


def test_in_process_collision_ends_the_run_with_exit_3(tmp_path: Path) -> None:
    trace = hard_stop(tmp_path / 'stop.csv')
    out = tmp_path / 'steps.csv'
    proc = cli('simulate', '--trace', str(trace), '--out', str(out), '--no-progress')
    assert proc.returncode == EXIT_COLLISION == 3, proc.stderr
    assert proc.stderr.strip().splitlines() == [
        f'trust-av simulate: collision at step {COLLISION_STEP} (t = {COLLISION_STEP} s): the '
        'AV reached the preceding traffic (gap -11.02 m)']
    rows = dict(line.rsplit(None, 1) for line in proc.stdout.splitlines()
                if line.startswith(('steps ', 'min AV gap')))
    assert rows == {'steps': str(COLLISION_STEP + 1), 'min AV gap (m)': '-11.021'}
    assert f'collision                          step {COLLISION_STEP}, AV into preceding ' \
        'traffic' in proc.stdout
    assert proc.stdout.startswith('components: predictor ca, trust model paper, driver '
                                  'model mpc; parameters: ')
    assert len(out.read_text().splitlines()) == 1 + COLLISION_STEP + 1   # the table so far
    assert 'nan' not in proc.stdout


def test_a_run_without_collision_says_none(tmp_path: Path) -> None:
    proc = cli('simulate', '--trace', 'us06', '--max-steps', '5', '--no-progress')
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.splitlines()[-1].split() == ['collision', 'none']


def test_summary_figures_of_no_value_read_none(tmp_path: Path) -> None:
    config = load_run_config()
    trace = load_trace(str(hard_stop(tmp_path / 'stop.csv')), 1.0, config.trace)
    records = simulate(config, trace).records
    metrics = dataclasses.replace(compute_metrics(records, config.min_safe_gap_m),
                                  final_trust=math.nan, rmse_mps2=math.inf)
    table = format_metrics(metrics, 'title')
    assert 'nan' not in table and 'inf' not in table
    rows = {line[:35].strip(): line[35:].strip() for line in table.splitlines()[2:]}
    assert rows['final trust'] == rows['prediction RMSE (m/s^2)'] == 'none (not finite)'
    assert rows['min AV gap (m)'] == '-11.021'      # the others as they are
    with pytest.raises(ValueError, match='no steps'):
        compute_metrics([], config.min_safe_gap_m)


def kmh_trace(tmp_path: Path, name: str = 'nycc') -> Path:
    """A shipped trace with its speeds in km/h under the m/s header (the user's mistake)."""
    data = np.loadtxt(trace_path(name), delimiter=',', skiprows=1)
    return write_trace(tmp_path / f'{name}_kmh.csv', list(data[:, 1] * 3.6))


def test_a_trace_in_kmh_is_refused_naming_units_and_the_parameter(tmp_path: Path) -> None:
    trace = kmh_trace(tmp_path)                 # urban, peak 44.6 "m/s"
    proc = cli('simulate', '--trace', str(trace), '--no-progress')
    assert proc.returncode == 2
    line, = proc.stderr.strip().splitlines()
    assert line.startswith(f'trust-av simulate: error: {trace}: speeds up at 9.66 m/s^2')
    assert 'km/h' in line and 'preceding_traffic.trace_accel_max_mps2' in line
    assert proc.stdout == ''
    # the parameter overrides it: the trace is then run (and the AV cannot keep up)
    layer = tmp_path / 'fast.yaml'
    layer.write_text('/**/preceding_traffic:\n  ros__parameters:\n'
                     '    trace_accel_max_mps2: 12.0\n    trace_brake_max_mps2: 12.0\n'
                     '    trace_stopping_speed_max_mps: 50.0\n')
    proc = cli('simulate', '--trace', str(trace), '--params-file', str(layer), '--max-steps',
               '3', '--no-progress')
    assert proc.returncode == 0, proc.stderr


def test_a_bag_in_kmh_is_refused_too(tmp_path: Path) -> None:
    data = np.loadtxt(trace_path('commute_am'), delimiter=',', skiprows=1)  # peak 98 km/h
    bag = tmp_path / 'lead.mcap'
    write_trace_bag(data[:, 0], data[:, 1] * 3.6, bag, '/preceding_vehicle/odom')
    with pytest.raises(PrecedingTrafficError, match=r'speeds up at 6.\d+ m/s\^2 .*km/h'):
        load_trace(str(bag), 1.0, load_run_config().trace)


@pytest.mark.parametrize('name', SHIPPED_TRACES + TRAINING_TRACES)
def test_every_shipped_trace_is_within_a_road_vehicle(name: str) -> None:
    assert load_trace(name, 1.0, TraceConfig(trace=name, max_sample_gap_s=5.0)).steps > 500


def test_a_noisy_10_hz_trace_is_judged_over_1_s(tmp_path: Path) -> None:
    """0.3 m/s of sample noise at 10 Hz is 6 m/s^2 between samples, not a hard stop."""
    times = np.arange(0.0, 60.0, 0.1)
    speeds = 15.0 + 0.3 * (-1.0) ** np.arange(times.size)
    path = tmp_path / 'noisy.csv'
    path.write_text('time_s,speed_mps\n' + ''.join(f'{t:.1f},{v}\n'
                                                   for t, v in zip(times, speeds, strict=True)))
    assert load_trace(str(path), 0.1, TraceConfig(trace=str(path), max_sample_gap_s=5.0))


@pytest.mark.parametrize(('option', 'value', 'message'), [
    ('--predictors', '', '--predictors: no value given'),
    ('--alphas', ',', '--alphas: no value given'),
    ('--trust-models', '', '--trust-models: no value given'),
    ('--predictors', 'ca,ca', "--predictors: 'ca' given twice"),
    ('--alphas', '0.5,.50', '--alphas: 0.5 given twice'),
    ('--traces', 'us06,US06', "--traces: 'us06' and 'US06' given twice"),
    ('--driver-models', 'mpc,idm,mpc', "--driver-models: 'mpc' given twice"),
])
def test_study_axes_hold_each_case_once(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                        option: str, value: str, message: str) -> None:
    from trust_av.cli.main import main

    out = tmp_path / 'results'
    code = main(['reproduce', option, value, '--max-steps', '2', '--results-dir', str(out),
                 '--no-progress'])
    assert code == 2
    line, = capsys.readouterr().err.strip().splitlines()
    assert line.startswith(f'trust-av reproduce: error: {message} ')
    assert not out.exists()


def test_a_study_case_that_collides_says_so_in_its_row(tmp_path: Path) -> None:
    trace = hard_stop(tmp_path / 'stop.csv')
    out = tmp_path / 'results'
    proc = cli('reproduce', '--traces', f'{trace},nycc', '--predictors', 'ca', '--alphas',
               '0.5', '--max-steps', '12', '--results-dir', str(out), '--workers', '1',
               '--no-progress')
    assert proc.returncode == 0, proc.stderr
    assert f'1 of 2 cases collided: {trace}/TAC-CA/alpha=0.5: collision at step ' \
        f'{COLLISION_STEP} ' in proc.stdout
    rows = list(csv.DictReader((out / 'all_runs.csv').open()))
    assert [(r['steps'], r['collision'].split(':')[0]) for r in rows] == [
        (str(COLLISION_STEP + 1), f'collision at step {COLLISION_STEP} (t = {COLLISION_STEP} s)'),
        ('12', 'none')]


def test_sweep_cases_refuses_an_empty_or_repeated_axis() -> None:
    assert len(sweep_cases(['us06'], ['ca', 'cv'], [0.0, 1.0])) == 4
    with pytest.raises(TrustAvAppError, match='alphas: no value'):
        sweep_cases(['us06'], ['ca'], [])
    with pytest.raises(TrustAvAppError, match="predictors: 'ca' given twice"):
        sweep_cases(['us06'], ['ca', 'ca'], [0.5])


@pytest.fixture(scope='module')
def graph_collision(tmp_path_factory: pytest.TempPathFactory
                    ) -> tuple[subprocess.CompletedProcess[str], Path, Path]:
    """One graph run (reused by the tests below): the hard stop, with the asymmetric trust
    model from a params-file layer and alpha from the command line."""
    folder = tmp_path_factory.mktemp('graph_collision')
    trace = hard_stop(folder / 'stop.csv')
    layer = folder / 'model.yaml'
    layer.write_text('/**:\n  ros__parameters:\n    trust_model: asymmetric\n'
                     '    asymmetric_loss_ratio: 3.0\n')
    bag = folder / 'bag'
    proc = cli('run', '--trace', str(trace), '--params-file', str(layer), '--alpha', '0.25',
               '--bag', str(bag), '--no-progress', '--no-plot')
    return proc, bag, trace


@pytest.mark.slow
def test_graph_collision_ends_with_exit_3_and_the_in_process_summary(
        graph_collision: tuple[subprocess.CompletedProcess[str], Path, Path]) -> None:
    proc, bag, trace = graph_collision
    assert proc.returncode == EXIT_COLLISION, proc.stderr
    line = proc.stderr.strip().splitlines()[-1]
    assert line.startswith(f'trust-av run: collision at step {COLLISION_STEP} (t = '
                           f'{COLLISION_STEP} s): the AV reached the preceding traffic')
    layer = bag.parent / 'model.yaml'
    in_process = cli('simulate', '--trace', str(trace), '--params-file', str(layer), '--alpha',
                     '0.25', '--no-progress')
    assert in_process.returncode == EXIT_COLLISION
    table = [row for row in proc.stdout.splitlines() if row.startswith(
        ('steps', 'final trust', 'min ', 'collision'))]
    assert table == [row for row in in_process.stdout.splitlines() if row.startswith(
        ('steps', 'final trust', 'min ', 'collision'))]
    assert f'collision                          step {COLLISION_STEP}, AV into' in proc.stdout
    assert check_bag_directory(bag) == []          # complete and readable by rosbag2's rules


@pytest.mark.slow
def test_graph_collision_ends_the_recording_at_that_step(
        graph_collision: tuple[subprocess.CompletedProcess[str], Path, Path]) -> None:
    """The graph stops at the collision step as the in-process loop does: the bag holds
    every message of the steps up to and including it and none after (31 trace steps)."""
    _, bag, trace = graph_collision
    config = load_run_config([bag.parent / 'model.yaml'], {'planner': {'alpha': 0.25}})
    reference = simulate(config, load_trace(str(trace), config.planner.dt_s,
                                            config.trace)).records
    assert len(reference) == COLLISION_STEP + 1
    records = records_from_bag(bag)
    assert_records_equal(records, reference)
    with Reader(bag) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
    assert counts == {qualified(row.name, '/'): row.messages(COLLISION_STEP + 1)
                      for row in TOPICS if 'recorder' in row.subscribers}
    logs = bag.with_name(bag.name + '.logs')
    assert f'done: collision at step {COLLISION_STEP}' in (
        logs / 'preceding_traffic.log').read_text()


@pytest.mark.slow
def test_graph_record_names_every_component_and_parameter(
        graph_collision: tuple[subprocess.CompletedProcess[str], Path, Path]) -> None:
    proc, bag, trace = graph_collision
    assert proc.stdout.startswith('components: predictor ca, trust model asymmetric, driver '
                                  'model mpc; parameters: ')
    info = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    custom = info['custom_data']
    assert {key: custom[key] for key in run_record.COMPONENT_KEYS.values()} == {
        'trust_av.component.predictor': 'ca', 'trust_av.component.trust_model': 'asymmetric',
        'trust_av.component.driver_model': 'mpc'}
    params = yaml.safe_load(custom[run_record.PARAMS_KEY])
    logs = bag.with_name(bag.name + '.logs')
    assert yaml.safe_load((logs / run_record.PARAMS_FILE_NAME).read_text()) == params
    planner = params['/planner']['ros__parameters']
    monitor = params['/trust_monitor']['ros__parameters']
    # the layer's values, the command line's and the shipped file's, each where it ran
    assert (planner['trust_model'], planner['asymmetric_loss_ratio'], planner['alpha']) == (
        'asymmetric', 3.0, 0.25)
    assert (monitor['trust_model'], monitor['trust_growth_rate']) == ('asymmetric', 0.1)
    assert params['/preceding_traffic']['ros__parameters']['trace'] == str(trace)
    assert params['/human_driver']['ros__parameters']['driver_model'] == 'mpc'
    assert set(params) == {'/preceding_traffic', '/planner', '/human_driver', '/trust_monitor',
                           '/recorder', '/ego_plant'}
