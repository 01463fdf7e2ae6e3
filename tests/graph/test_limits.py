"""Every limit is one line, before anything starts: counts have documented maxima, Ray
addresses nothing answers on are refused within seconds, FIFOs and directories are refused
as inputs without being opened, time ranges a recording cannot stamp are refused, every
numeric parameter has a range, odd output paths are refused, and the plant never reports a
negative speed."""

from __future__ import annotations

import contextlib
import dataclasses
import importlib
import io
import math
import os
import pkgutil
import resource
import signal
import subprocess
import sys
import typing
from collections.abc import Iterator
from pathlib import Path

import pytest
from rosbags.rosbag2 import Reader
from support.bags import fail_commit, record
from support.cli import trust_av
from support.paths import TESTS
from support.rosbag2_rules import check_bag_directory

from trust_av.errors import TrustAvAppError
from trust_av.graph.bag_writer import BagWriter
from trust_av.study.sweep import check_ray_address
from trust_av_common.kinematics import VehicleState, advance, integrate
from trust_av_common.params import PARAM_METADATA_KEY

TINY_TRACE = 'time_s,speed_mps\n0,10\n1,10.5\n2,11\n3,11\n'


@contextlib.contextmanager
def within(seconds: int) -> Iterator[None]:
    """Fail (SIGALRM) instead of hanging if the block blocks, e.g. on opening a FIFO."""
    def expired(signum: int, frame: object) -> None:
        raise AssertionError(f'still blocked after {seconds} s')
    previous = signal.signal(signal.SIGALRM, expired)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


@pytest.mark.parametrize(('argv', 'words'), [
    (['reproduce', '--drivers', '1000000000'], '--drivers must be <= 1000, got 1000000000'),
    (['reproduce', '--workers', '100000'], "--workers: must be <= 256, got '100000'"),
    (['reproduce', '--max-steps', '99999999999'], '--max-steps must be <= 10000000'),
    (['reproduce', '--drivers-seed', '-1'], '--drivers-seed must be >= 0, got -1'),
    (['run', '--max-steps', '10000001'], '--max-steps must be <= 10000000'),
    (['train-gru', '--epochs', '1000000000'], '--epochs must be <= 100000'),
    (['train-gru', '--jobs', '100000'], "--jobs: must be <= 256, got '100000'"),
    (['fit-driver', '--data', '.', '--iterations', '1000000000'],
     '--iterations must be <= 100000'),
])
def test_every_count_has_a_documented_maximum(tmp_path: Path, argv: list[str], words: str,
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    code, err = trust_av(*argv)
    assert code == 2 and words in err, err
    assert list(tmp_path.iterdir()) == []


def test_an_unreachable_ray_address_is_refused_at_once(tmp_path: Path) -> None:
    """ray.init retried an address nothing listens on for minutes (measured: > 3 min)."""
    with pytest.raises(TrustAvAppError, match=r'127\.0\.0\.1:1: cannot connect within '
                                                  r'5 s \(Connection refused\)'):
        check_ray_address('127.0.0.1:1')
    with pytest.raises(TrustAvAppError, match='expected HOST:PORT'):
        check_ray_address('no-port')
    check_ray_address(None)
    check_ray_address('auto')
    code, err = trust_av('reproduce', '--executor', 'ray', '--ray-address', 'ray://127.0.0.1:1',
                         '--results-dir', str(tmp_path / 'results'), '--no-progress')
    assert code == 2 and err.count('\n') == 1 and 'cannot connect' in err, err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize('kind', ['fifo', 'directory'])
@pytest.mark.parametrize('role', ['params file', 'trace', 'estimator input', 'bag'])
def test_non_regular_inputs_are_refused_unopened(tmp_path: Path, kind: str,
                                                 role: str) -> None:
    odd = tmp_path / ('input.mcap' if role == 'bag' else 'input')
    if kind == 'fifo':
        os.mkfifo(odd)
    else:
        odd.mkdir()
        if role == 'bag':
            os.mkfifo(odd / 'input_0.mcap')
            (odd / 'metadata.yaml').write_text('rosbag2_bagfile_information: {}\n')
    trace = tmp_path / 'trace.csv'
    trace.write_text(TINY_TRACE)
    with within(20):
        if role == 'estimator input':
            from trust_monitor.estimate import main as estimate
            err = io.StringIO()
            with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
                code = estimate([str(odd), '-o', str(tmp_path / 'out.csv')])
            text = err.getvalue()
        else:
            option = {'params file': ['--params-file', str(odd), '--trace', str(trace)],
                      'trace': ['--trace', str(odd)], 'bag': ['--trace', str(odd)]}[role]
            code, text = trust_av('simulate', '--no-progress', *option)
    assert code == 2 and 'not a regular file' in text, text
    assert text.count('\n') == 1 and 'Traceback' not in text


@pytest.mark.parametrize(('rows', 'words'), [
    ('-2,1\n-1,2\n0,2\n', 'time -2 s is before 0'),
    ('2147483000,1\n2147483001,2\n', 'is beyond 2147480048 s'),
])
def test_times_a_recording_cannot_stamp_are_refused_before_start(tmp_path: Path, rows: str,
                                                                  words: str) -> None:
    trace = tmp_path / 'trace.csv'
    trace.write_text('time_s,speed_mps\n' + rows)
    code, err = trust_av('run', '--trace', str(trace), '--bag', str(tmp_path / 'bag'),
                         '--no-progress')
    assert code == 2 and words in err and err.count('\n') == 1, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ['trace.csv']


@pytest.mark.parametrize(('bag', 'words'), [
    ('.', 'names no file or directory of its own'),
    ('..', 'names no file or directory of its own'),
    ('d/..', 'names no file or directory of its own'),
    ('new\nline', 'holds a newline or another control character'),
    ('nul\x00byte', 'holds a NUL character'),
])
def test_odd_output_paths_are_refused_before_anything_starts(
        tmp_path: Path, bag: str, words: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    (tmp_path / 'trace.csv').write_text(TINY_TRACE)
    for argv in (['run', '--bag', bag], ['simulate', '--out', bag]):
        code, err = trust_av(*argv, '--trace', 'trace.csv', '--no-progress')
        assert code == 2 and words in err and err.count('\n') == 1, (argv, err)
    assert sorted(p.name for p in tmp_path.iterdir()) == ['trace.csv']


def _config_classes() -> list[type]:
    """Every dataclass with param() fields in the seven packages (nodes included: their
    fields become the rcl descriptors)."""
    found: dict[str, type] = {}
    for package in ('trust_av_common', 'trust_monitor', 'trust_av_planner', 'human_driver_sim',
                    'preceding_traffic', 'trust_av', 'trust_av_autoware'):
        root = importlib.import_module(package)
        for info in pkgutil.walk_packages(root.__path__, package + '.'):
            if info.name.endswith('__main__'):
                continue
            for value in vars(importlib.import_module(info.name)).values():
                if (isinstance(value, type) and dataclasses.is_dataclass(value)
                        and any(PARAM_METADATA_KEY in f.metadata
                                for f in dataclasses.fields(value))):
                    found[f'{value.__module__}.{value.__qualname__}'] = value
    return [found[name] for name in sorted(found)]


def test_every_numeric_parameter_has_a_range() -> None:
    """The same range goes to the rcl descriptor and the CLI's check (param() metadata):
    negative standstill_gap_m and rates of 1e308 were accepted."""
    classes = _config_classes()
    assert len(classes) >= 10
    missing = []
    for cls in classes:
        hints = typing.get_type_hints(cls)
        for field in dataclasses.fields(cls):
            spec = field.metadata.get(PARAM_METADATA_KEY)
            if spec is not None and hints[field.name] in (int, float) and (
                    spec.low is None or spec.high is None):
                missing.append(f'{cls.__name__}.{field.name}')
    assert missing == []


def test_the_plant_never_reports_a_negative_speed() -> None:
    for step in (integrate(VehicleState(0.0, 1.0), -1.0, 1.0),          # -0.0 before
                 integrate(VehicleState(0.0, 0.7), -0.7 / 0.3, 0.3),    # rounding below 0
                 integrate(VehicleState(0.0, 2.0), -3.0, 1.0)):
        assert step.speed_mps == 0.0 and math.copysign(1.0, step.speed_mps) == 1.0
    assert 0.7 + (-0.7 / 0.3) * 0.3 < 0.0                                # the case is real
    assert math.isnan(integrate(VehicleState(0.0, math.nan), 0.0, 1.0).speed_mps)
    _, speed = advance(0.0, 1.0, -1.0, 1.0)
    assert math.copysign(1.0, speed) == 1.0
    assert integrate(VehicleState(0.0, 1.0), 0.5, 1.0) == VehicleState(1.0, 1.5)


FILE_LIMIT_CHILD = """
import sys
from pathlib import Path
sys.path.insert(0, sys.argv[2])
from support.bags import fail_commit, record
from trust_av.graph.bag_writer import BagWriter
writer = BagWriter(Path(sys.argv[1]))
record(writer, 100_000, finish=False)
print(writer.steps)
print(writer.disk_full)
"""


def _file_size_limit(limit: int) -> None:
    """In the child before exec: a file-size limit, and SIGXFSZ ignored (as a shell's
    ``ulimit -f`` with ``trap '' XFSZ``)."""
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)


def test_a_file_size_limit_ends_the_recording_like_a_full_disk(tmp_path: Path) -> None:
    """EFBIG (RLIMIT_FSIZE): the recorder died with a traceback and left the bag unfinished;
    now the bag is finished with every complete step before the MCAP reaches the limit."""
    bag = tmp_path / 'limited'
    limit = 256 * 1024
    proc = subprocess.run([sys.executable, '-c', FILE_LIMIT_CHILD, str(bag),
                           str(TESTS)], capture_output=True, text=True,
                          timeout=120, preexec_fn=lambda: _file_size_limit(limit))
    assert proc.returncode == 0, proc.stderr
    steps_text, line = proc.stdout.splitlines()
    steps = int(steps_text)
    assert line == (f'{bag}: file-size limit of {limit} bytes (RLIMIT_FSIZE) after {steps} '
                    'complete steps; the bag holds them and is finished')
    assert steps > 10
    assert check_bag_directory(bag) == []
    with Reader(bag) as reader:
        assert {c.topic: c.msgcount for c in reader.connections} == {'/a/odom': steps,
                                                                     '/b/odom': steps}
    assert all(p.stat().st_size <= limit for p in bag.iterdir())


def test_any_other_write_error_ends_the_recording_like_a_full_disk(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """EIO (a failing disk) writing step 31's chunk: one line naming it, the 30 complete
    steps kept and the bag finished."""
    fail_commit(monkeypatch, 31)
    bag = tmp_path / 'eio'
    writer = BagWriter(bag)
    record(writer, 200, finish=False)
    assert writer.finished and writer.steps == 30
    assert writer.disk_full == (f'{bag}: cannot write (Input/output error) after 30 complete '
                                'steps; the bag holds them and is finished')
    assert check_bag_directory(bag) == []
    with Reader(bag) as reader:
        assert {c.msgcount for c in reader.connections} == {30}


def test_the_smallest_control_step_runs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``dt_s: 0.01`` (the bottom of its range) runs the closed loop."""
    monkeypatch.chdir(tmp_path)
    Path('trace.csv').write_text(TINY_TRACE)
    Path('fine.yaml').write_text('/**:\n  ros__parameters:\n    dt_s: 0.01\n')
    code, err = trust_av('simulate', '--trace', 'trace.csv', '--params-file', 'fine.yaml',
                         '--out', 'run.csv', '--no-progress')
    assert code == 0, err
    assert len(Path('run.csv').read_text().splitlines()) == 1 + 300      # 3 s at 100 Hz


@pytest.mark.parametrize('steps', [1, 6])
def test_reproduce_a_few_steps(tmp_path: Path, steps: int) -> None:
    """``reproduce --max-steps 1..6`` divided by the alpha = 0 trust, still 0 (T(0))."""
    results = tmp_path / 'results'
    code, err = trust_av('reproduce', '--traces', 'nycc', '--predictors', 'ca', '--workers',
                         '1', '--max-steps', str(steps), '--results-dir', str(results),
                         '--no-progress')
    assert code == 0, err
    table = (results / 'table_IV_max_improvements.md').read_text()
    assert '| TAC-CA | nycc |' in table


def test_a_rate_of_1e308_is_one_line() -> None:
    """It was an OverflowError traceback (an infinite prediction step count)."""
    from trust_av.system.config import load_run_config
    from trust_av_common.params import ParamsError
    from trust_av_planner.planner_params import check_control_rate
    for argv in (['shadow', '--bag', 'x', '--out', 'y', '--rate-hz', '1e308'],
                 ['simulate', '--control-rate-hz', '1e308']):
        code, err = trust_av(*argv)
        assert code == 2 and "must be <= 1000 Hz, got '1e308'" in err, err
    with pytest.raises(ParamsError, match=r'^control_rate_hz 1e\+308: '):
        check_control_rate(load_run_config().planner, 1e308)


@pytest.mark.parametrize('path', ['', '/', '\x00x'])
def test_repair_bag_of_no_name_is_one_line(path: str) -> None:
    """An empty PATH, the root or a NUL: one line, exit 2 (an empty one was a traceback:
    the repair's work directory beside a path with no name)."""
    code, err = trust_av('repair-bag', path)
    assert code == 2 and err.count('\n') == 1 and 'Traceback' not in err, err


def test_repair_bag_dot_inside_the_bag_repairs_it(tmp_path: Path,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    """``trust-av repair-bag .`` in the bag directory repairs that bag, as its path would."""
    bag = tmp_path / 'rec'
    record(BagWriter(bag), 5, finish=False)
    monkeypatch.chdir(bag)
    code, err = trust_av('repair-bag', '.')
    assert (code, err) == (0, '')
    assert check_bag_directory(bag) == []
