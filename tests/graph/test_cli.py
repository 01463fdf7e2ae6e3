"""Command lines: trust-av simulate and trust-monitor-estimate, run as a user would.

Most cases call the commands' ``main`` in-process (exit code, stdout, stderr: what they
check); the process itself (``python -m``, its exit status from the OS, its whole stderr) is
started for real by one success and one refusal of each command."""

from __future__ import annotations

import csv
import dataclasses
import math
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from support.cli import estimate_run, trust_av_run
from support.closed_loop import closed_loop
from support.paths import REPO

from preceding_traffic.sources import load_trace
from preceding_traffic.traces import truncate
from trust_av.system.closed_loop import simulate
from trust_av.system.config import load_run_config
from trust_av.system.metrics import StepRecord
from trust_monitor.estimate import EstimateError, estimate_csv

CONFIG = load_run_config()


def trust_av_process(*args: str) -> subprocess.CompletedProcess[str]:
    """``python -m trust_av.cli args`` as its own process."""
    return subprocess.run([sys.executable, '-m', 'trust_av.cli', *args],
                          capture_output=True, text=True, timeout=300)


trust_av = trust_av_run            # in-process: the same exit code, stdout and stderr
estimate = estimate_run


@pytest.fixture
def short_trace(tmp_path: Path) -> Path:
    path = tmp_path / 'ramp.csv'
    rows = [f'{t},{min(t * 1.5, 15.0) if t < 30 else max(15.0 - (t - 30) * 2, 0.0)}'
            for t in range(60)]
    path.write_text('time_s,speed_mps\n' + '\n'.join(rows) + '\n')
    return path


def test_simulate_prints_metrics_and_writes_table(short_trace: Path, tmp_path: Path) -> None:
    out = tmp_path / 'run.csv'
    proc = trust_av_process('simulate', '--trace', str(short_trace), '--alpha', '0.5', '--out',
                            str(out), '--no-progress')
    assert proc.returncode == 0, proc.stderr
    assert 'final trust' in proc.stdout and 'mean explicability E' in proc.stdout
    with out.open() as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == 59
    assert {'av_plan_mps2_0', 'expected_plan_mps2_2', 'trust', 'solver_status'} <= set(rows[0])


def test_simulate_max_steps_is_the_start_of_the_whole_run(tmp_path: Path) -> None:
    """--max-steps 5 writes the first 5 steps of the whole US06 run (the speed limit and the
    preview still come from the whole trace); a negative count is one line, exit 2."""
    out = tmp_path / 'run.csv'
    proc = trust_av('simulate', '--trace', 'us06', '--max-steps', '5', '--out', str(out),
                    '--no-progress')
    assert proc.returncode == 0, proc.stderr
    with out.open() as handle:
        rows = list(csv.DictReader(handle))
    whole = simulate(CONFIG, load_trace('us06', CONFIG.planner.dt_s, CONFIG.trace)).records
    assert [float(r['trust']) for r in rows] == [r.trust for r in whole[:5]]
    proc = trust_av_process('simulate', '--max-steps', '-5', '--no-progress')
    assert proc.returncode == 2 and '--max-steps must be >= 0' in proc.stderr
    assert proc.stderr.splitlines()[0].startswith('usage: trust-av simulate')   # argparse's
    assert len(proc.stderr.splitlines()) == 2 and 'Traceback' not in proc.stderr


@pytest.mark.parametrize(('args', 'message'), [
    (['--alpha', '1.5'], 'alpha must be in [0, 1]'),
    (['--predictor', 'magic'], "invalid choice: 'magic'"),
    (['--trace', '/no/such/trace.csv'], '/no/such/trace.csv: cannot open trace'),
    (['--params-file', '/no/such.yaml'], '/no/such.yaml: cannot read params file'),
    (['--control-rate-hz', '0'], 'must be a finite rate > 0 Hz'),
    (['--control-rate-hz', 'nan'], 'must be a finite rate > 0 Hz'),
    (['--control-rate-hz', '0.5'], 'control_rate_hz 0.5: a 2 s control period is longer '
                                   'than the model step'),
    (['--control-rate-hz', '101'], 'needs 303 steps (at most 300)'),
])
def test_bad_arguments_give_one_clear_line(args: list[str], message: str) -> None:
    proc = trust_av('simulate', '--no-progress', *args)
    assert proc.returncode == 2
    assert message in proc.stderr
    assert 'Traceback' not in proc.stderr


@pytest.mark.parametrize(('args', 'message'), [
    (['--workers', '0'], "argument --workers: must be >= 1, got '0'"),
    (['--workers', '-1'], "argument --workers: must be >= 1, got '-1'"),
    (['--workers', 'two'], "argument --workers: expected a whole number, got 'two'"),
    (['--traces', 'nope'], 'nope: cannot open trace (No such file or directory)'),
    (['--results-dir', '/dev/null/x'], '--results-dir /dev/null/x: cannot create it (Not a '
                                       'directory)'),
])
def test_reproduce_refuses_bad_arguments_before_any_case(args: list[str], message: str,
                                                         tmp_path: Path) -> None:
    results = ['--results-dir', str(tmp_path / 'results')] if '--results-dir' not in args else []
    proc = trust_av('reproduce', '--no-progress', *results, *args)
    assert proc.returncode == 2, proc.stderr
    last = proc.stderr.splitlines()[-1]          # argparse prints its usage first
    assert last.startswith('trust-av reproduce: error: ') and message in last
    assert 'Traceback' not in proc.stderr and 'case ' not in proc.stderr
    assert not (tmp_path / 'results' / 'cache').exists() or not list(
        (tmp_path / 'results' / 'cache').iterdir())


def test_help_explains() -> None:
    proc = trust_av('simulate', '--help')
    assert proc.returncode == 0 and '--alpha' in proc.stdout and 'explicability' in proc.stdout


def test_every_command_and_option_says_what_it_is() -> None:
    """`trust-av --help` lists every command with a plain one-line summary (not a docstring's
    markup), each command's --help has a description, and every option has a help text."""
    import argparse

    from trust_av.cli.main import build_parser

    parser = build_parser()
    commands = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    summaries = {c.dest: c.help for c in commands._choices_actions}
    assert set(summaries) == set(commands.choices)
    for name, sub in commands.choices.items():
        summary = summaries[name]
        assert summary and '``' not in summary and not summary.startswith('trust-av'), name
        assert sub.description, name
        for action in sub._actions:
            assert action.help, f'trust-av {name} {"/".join(action.option_strings)}'


def test_offline_estimator_matches_the_loop(tmp_path: Path) -> None:
    """trust-monitor-estimate on the loop's observed plans gives the loop's E and trust."""
    records = closed_loop('us06', 0.5).records[:200]
    plans = tmp_path / 'plans.csv'
    with plans.open('w', newline='') as handle:
        writer = csv.writer(handle)
        writer.writerow(['t', *(f'plan_{k}' for k in range(3)),
                         *(f'expected_{k}' for k in range(3))])
        for r in records:
            writer.writerow([r.t_s, *map(repr, r.av_plan_mps2), *map(repr, r.expected_plan_mps2)])
    out = tmp_path / 'trust.csv'
    proc = subprocess.run([sys.executable, '-m', 'trust_monitor.estimate', str(plans), '-o',
                           str(out)], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    with out.open() as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == len(records)
    for row, r in zip(rows, records, strict=True):
        assert float(row['E']) == r.explicability
        assert float(row['trust']) == r.trust


def test_offline_estimator_names_bad_row(tmp_path: Path) -> None:
    plans = tmp_path / 'plans.csv'
    plans.write_text('t,plan_0,expected_0\n0,0.1,0.2\n1,nan,0.2\n')
    proc = subprocess.run([sys.executable, '-m', 'trust_monitor.estimate', str(plans), '-o',
                           str(tmp_path / 'o.csv')], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    assert f'{plans}:3: NaN or infinite value' in proc.stderr
    assert proc.stderr.count('\n') == 1      # the whole process's stderr: no warning either


@pytest.mark.parametrize(('body', 'message'), [
    ('', 'header needs t, plan_0.., expected_0..'),
    ('t,a,b\n0,1,2\n', 'header needs t, plan_0.., expected_0..'),
    ('t,plan_0,expected_0\n1,0.1,0.2\n1,0.1,0.2\n', ':3: time 1.0 does not increase'),
    ('t,plan_0,expected_0\n0,fast,0.2\n', ':2: plan_0 is not a number'),
])
def test_offline_estimator_rejects_bad_files(tmp_path: Path, body: str, message: str) -> None:
    plans = tmp_path / 'plans.csv'
    plans.write_text(body)
    out = tmp_path / 'o.csv'
    proc = estimate(str(plans), '-o', str(out))
    assert proc.returncode == 2 and message in proc.stderr
    assert proc.stderr.count('\n') == 1 and not out.exists()


@pytest.mark.parametrize(('data', 'message'), [
    (bytes(range(256)) * 2, 'not UTF-8 text'),
    (b't,plan_a,expected_a\n0,1,2\n', "column 'plan_a' is not plan_<k>"),
    (b't,plan_0,plan_2,expected_0,expected_2\n0,1,2,3,4\n', 'plan columns must be plan_0..'),
    (b't,plan_0,plan_1,expected_0,expected_1,expected_2\n0,1,2,3,4,5\n',
     '2 plan columns but 3 expected columns'),
    (b't,plan_0,expected_0\n0,1e308,-1e308\n', ':2: plan_0 = 1e+308 m/s^2 is outside +-100'),
    (b't,plan_0,expected_0\n0,0.1,0.2\n1,0.1\n', ':3: expected 3 values, got 2'),
    (b't,plan_0,expected_0\n0,0.1,hunter2\n', ':2: expected_0 is not a number'),
])
def test_offline_estimator_refuses_in_one_line(tmp_path: Path, data: bytes,
                                               message: str) -> None:
    plans = tmp_path / 'plans.csv'
    plans.write_bytes(data)
    out = tmp_path / 'o.csv'
    proc = estimate(str(plans), '-o', str(out))
    assert proc.returncode == 2 and message in proc.stderr, proc.stderr
    assert proc.stderr.count('\n') == 1 and 'hunter2' not in proc.stderr
    assert list(tmp_path.iterdir()) == [plans]   # no output, no temporary file


def test_a_multi_line_reason_from_a_library_is_one_line(tmp_path: Path) -> None:
    """A bag directory whose metadata.yaml is not YAML: rosbags passes on the YAML parser's
    message with its caret diagram (seven lines); the command prints it as one line."""
    bag = tmp_path / 'bag'
    bag.mkdir()
    (bag / 'metadata.yaml').write_text('rosbag2_bagfile_information: [\n')
    proc = trust_av('simulate', '--trace', str(bag), '--no-progress')
    assert proc.returncode == 2
    assert proc.stderr.count('\n') == 1 and 'Traceback' not in proc.stderr
    assert proc.stderr.startswith(f'trust-av simulate: error: {bag}: cannot read bag (Could '
                                  f'not load YAML from {bag}/metadata.yaml: while parsing')


def test_offline_estimator_checks_its_output_first(tmp_path: Path) -> None:
    plans = tmp_path / 'plans.csv'
    plans.write_bytes(bytes(range(256)))   # would fail too, later
    for out, message in ((tmp_path / 'no' / 'o.csv', 'no such directory'),
                         (tmp_path, 'is a directory; -o needs a file name'),
                         (Path('/proc/o.csv'),
                          f'cannot write in directory /proc ({proc_refusal()})')):
        proc = estimate(str(plans), '-o', str(out))
        assert proc.returncode == 2 and message in proc.stderr
        assert proc.stderr.count('\n') == 1
    assert not (tmp_path / 'no').exists()


def test_offline_estimator_largest_inputs_are_finite(tmp_path: Path) -> None:
    """At the acceleration limit the estimate is finite (eq. 8 does not overflow)."""
    plans = tmp_path / 'plans.csv'
    plans.write_text('t,plan_0,plan_1,expected_0,expected_1\n0,100,-100,-100,100\n'
                     '1e308,-100,100,100,-100\n')
    out = tmp_path / 'o.csv'
    proc = estimate(str(plans), '-o', str(out))
    assert proc.returncode == 0, proc.stderr
    rows = list(csv.DictReader(out.open()))
    assert len(rows) == 2
    assert all(math.isfinite(float(v)) for row in rows for v in row.values())


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                   HealthCheck.function_scoped_fixture])
@given(header=st.lists(st.sampled_from(['t', 'plan_0', 'plan_1', 'expected_0', 'expected_1',
                                        'plan_x', 'expected_01', 'note', '']),
                       min_size=1, max_size=6),
       rows=st.lists(st.lists(st.one_of(st.floats(), st.integers(), st.text(max_size=6)),
                              max_size=7), max_size=6),
       raw=st.binary(max_size=200))
def test_fuzzed_plans_give_rows_or_one_line(tmp_path: Path, header: list[str],
                                            rows: list[list[object]], raw: bytes) -> None:
    """Random headers, numbers, text and bytes: finite rows or one EstimateError line."""
    plans = tmp_path / 'fuzz.csv'
    body = ','.join(header) + '\n' + ''.join(','.join(map(str, r)) + '\n' for r in rows)
    for data in (body.encode('utf-8', 'surrogatepass'), raw):
        plans.write_bytes(data)
        out = tmp_path / 'fuzz_out.csv'
        out.unlink(missing_ok=True)
        try:
            count = estimate_csv(plans, out, CONFIG.trust)
        except EstimateError as err:
            assert str(err).startswith(str(plans)) and '\n' not in str(err)
            assert not out.exists()
        else:
            values = [float(v) for row in csv.reader(out.open()) for v in row
                      if v not in ('t', 'E', 'P', 'trust')]
            assert all(math.isfinite(v) for v in values) and count >= 0


@pytest.mark.parametrize(('setup', 'args', 'message'), [
    ('latin1', ['--trace', 'TRACE'], 'not UTF-8 text'),
    ('short', ['--trace', 'TRACE', '--out', 'OUT'], 'shorter than one control step'),
    ('fast', ['--trace', 'TRACE'], 'is above 100 m/s'),
    ('dt', ['--params-file', 'PARAMS'], r'dt_s must be in [0.01, 10]'),
    ('passwd', ['--params-file', 'PARAMS'], '/etc/passwd:1: expected the header'),
    ('dir', ['--trace', 'nycc', '--out', 'DIR'], 'is a directory; --out needs a file name'),
    ('dir', ['--trace', 'TRACE', '--out', 'DIR'], 'is a directory; --out needs a file name'),
])
def test_simulate_bad_inputs_one_line(tmp_path: Path, setup: str, args: list[str],
                                      message: str) -> None:
    """Each refused in one line with exit 2, before any output is written; --out is checked
    before the trace is read or the loop runs."""
    trace = tmp_path / 'trace.csv'
    body = {'latin1': b'time_s,speed_mps\n0,1\n1,\xe9\n',
            'short': b'time_s,speed_mps\n0,1\n0.5,2\n',
            'fast': b'time_s,speed_mps\n0,1\n1,1e9\n2,1\n'}.get(setup, bytes(range(256)))
    trace.write_bytes(body)
    params = tmp_path / 'p.yaml'
    params.write_text({'dt': '/**:\n  ros__parameters:\n    dt_s: 1.0e-9\n',
                       'passwd': 'preceding_traffic:\n  ros__parameters:\n    trace: /etc/passwd\n'
                       }.get(setup, ''))
    (tmp_path / 'adir').mkdir()
    subs = {'TRACE': str(trace), 'OUT': str(tmp_path / 'out.csv'), 'PARAMS': str(params),
            'DIR': str(tmp_path / 'adir')}
    proc = trust_av('simulate', '--no-progress', *[subs.get(a, a) for a in args])
    assert proc.returncode == 2 and message in proc.stderr, proc.stderr
    assert proc.stderr.count('\n') == 1 and 'root:' not in proc.stderr
    assert not (tmp_path / 'out.csv').exists() and not list((tmp_path / 'adir').iterdir())
    assert not [p for p in tmp_path.iterdir() if p.name.startswith('.')]


def test_run_refuses_negative_max_steps() -> None:
    proc = trust_av('run', '--max-steps', '-5', '--no-progress')
    assert proc.returncode == 2
    assert '--max-steps must be >= 0 (0: the whole trace), got -5' in proc.stderr
    assert 'Traceback' not in proc.stderr


def test_max_steps_changes_the_length_only() -> None:
    """A run limited to 200 steps is the first 200 steps of the whole run (the speed limit
    and the preview come from the whole trace); 5 steps work (the limit of the first 5 s of
    US06 would be 0 m/s)."""
    def untimed(records: list[StepRecord]) -> list[StepRecord]:
        return [dataclasses.replace(r, solve_time_s=0.0, driver_solve_time_s=0.0)
                for r in records]

    config = load_run_config()
    whole = load_trace('us06', config.planner.dt_s, config.trace)
    full = untimed(simulate(config.for_trace(whole), whole).records)
    for steps in (5, 200):
        short = truncate(whole, steps)
        part = simulate(config.for_trace(short), short).records
        assert untimed(part) == full[:steps]


def proc_refusal() -> str:
    """What the system says to a new entry in /proc: ENOENT for root, EACCES for others
    (the kernel's own answer, asked the way the commands ask it)."""
    try:
        os.rmdir(tempfile.mkdtemp(dir='/proc'))
    except OSError as err:
        return err.strerror
    raise AssertionError('/proc took a new entry')


@pytest.mark.parametrize(('args', 'message'), [
    (['run', '--no-progress', '--bag', '/dev/null/x'],
     '/dev/null: not a directory (--bag /dev/null/x)'),
    # /proc is a directory that passes os.access (as root: every one does) and refuses
    # every new entry: only trying to create one tells
    (['run', '--no-progress', '--bag', '/proc/trust_av_bag'],
     '/proc: cannot write there (--bag /proc/trust_av_bag: {proc})'),
    (['shadow', '--bag', 'COMMUTE', '--out', '/proc/trust_av_bag', '--duration-s', '1'],
     '/proc: cannot write there (--out /proc/trust_av_bag: {proc})'),
    (['train-gru', '--out', '/proc/m.npz'],
     '/proc/m.npz: cannot write in directory /proc ({proc})'),
    (['simulate', '--out', '/proc/steps.csv'],
     '/proc/steps.csv: cannot write in directory /proc ({proc})'),
    (['run', '--no-progress', '--startup-timeout-s', '-1', '--bag', 'BAG'],
     "argument --startup-timeout-s: must be > 0, got '-1'"),
    (['train-gru', '--out', '/dev/null/m.npz'], '/dev/null/m.npz: /dev/null is not a directory'),
    (['train-gru', '--out', 'DIR'], 'is a directory; --out needs a file name'),
    (['eval-driver', '--data', 'DIR', '--json', 'DIR'],
     'is a directory; --json needs a file name'),
])
def test_outputs_are_checked_before_the_work(tmp_path: Path, args: list[str],
                                             message: str) -> None:
    """A place the result cannot go is one line and exit 2 before minutes of training or a
    graph start (it was a traceback, or a finished training with nowhere to write)."""
    subs = {'DIR': str(tmp_path), 'BAG': str(tmp_path / 'bag'),
            'COMMUTE': str(REPO / 'bags' / 'commute_am')}
    proc = trust_av(*[subs.get(a, a) for a in args])
    assert proc.returncode == 2, proc.stderr
    message = message.format(proc=proc_refusal())
    assert message in proc.stderr.splitlines()[-1] and 'Traceback' not in proc.stderr
    assert list(tmp_path.iterdir()) == []


def test_run_refuses_a_wall_clock_params_file_at_once(tmp_path: Path) -> None:
    """``trust-av run`` steps the graph on sim time: a wall-mode params file is one line
    before any node starts (it used to wait 30 s for a graph that never connected)."""
    params = tmp_path / 'wall.yaml'
    params.write_text('/**:\n  ros__parameters:\n    clock_mode: wall\n')
    proc = trust_av('run', '--no-progress', '--params-file', str(params), '--bag',
                    str(tmp_path / 'bag'))
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr == ('trust-av run: error: clock_mode wall (params file): this command '
                           'steps the graph on sim time (lockstep); wall-clock runs are '
                           'trust-av shadow, or the nodes started by hand\n')
    assert sorted(p.name for p in tmp_path.iterdir()) == ['wall.yaml']
