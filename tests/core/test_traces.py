"""Speed traces: shipped data, resampling, preview and every validation error."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from support.paths import REPO

from preceding_traffic.sources import load_trace
from preceding_traffic.traces import (
    MAX_SPEED_MPS,
    MAX_TRACE_STEPS,
    TraceConfig,
    TraceError,
    resample,
    truncate,
)

CONFIG = TraceConfig(trace='us06', max_sample_gap_s=5.0)


def write(tmp_path: Path, text: str, name: str = 'trace.csv') -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.mark.parametrize(('name', 'steps', 'vmax'), [('us06', 600, 35.90), ('nycc', 598, 12.38)])
def test_shipped_traces(name: str, steps: int, vmax: float) -> None:
    trace = load_trace(name, 1.0, CONFIG)
    assert trace.steps == steps
    assert trace.max_speed_mps == pytest.approx(vmax, abs=0.01)
    assert trace.speeds_mps[0] == 0.0


def test_resample_interpolates_onto_grid() -> None:
    speeds = resample(np.array([0.0, 1.0, 3.0]), np.array([0.0, 2.0, 6.0]), 0.5)
    assert speeds.tolist() == [0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0]


def test_irregular_samples_and_offset_start(tmp_path: Path) -> None:
    path = write(tmp_path, 'time_s,speed_mps\n6,0\n7,1\n10,4\n')
    trace = load_trace(str(path), 1.0, CONFIG)
    assert trace.t0_s == 6.0
    assert trace.speeds_mps.tolist() == [0.0, 1.0, 2.0, 3.0, 4.0]


def test_preview_holds_last_speed(tmp_path: Path) -> None:
    trace = load_trace(str(write(tmp_path, 'time_s,speed_mps\n0,1\n1,2\n2,3\n')), 1.0, CONFIG)
    assert trace.preview(0, 3).tolist() == [1.0, 2.0, 3.0]
    assert trace.preview(1, 3).tolist() == [2.0, 3.0, 3.0]


@pytest.mark.parametrize(('body', 'message'), [
    ('time_s,speed_mps\n0,1\n1,nan\n', r':3: NaN or infinite'),
    ('time_s,speed_mps\n0,1\n1,inf\n', r':3: NaN or infinite'),
    ('time_s,speed_mps\n0,1\n1,-0.5\n', r':3: negative speed'),
    ('time_s,speed_mps\n0,1\n1,2\n1,3\n', r':4: time 1 s does not increase'),
    ('time_s,speed_mps\n0,1\n10,2\n', r':3: gap of 10 s .* exceeds max_sample_gap_s'),
    ('time_s,speed_mps\n0,1\n1,fast\n', r':3: speed_mps is not a number'),
    ('time_s,speed_mps\n0,1\n1,1e9\n', r':3: speed 1e\+09 m/s is above 100 m/s'),
    ('time_s,speed_mps\n0,1\n0.5,2\n', r'spans 0.5 s, shorter than one control step'),
    ('time_s,speed_mps\n0,1\n' + 'x' * 5000 + '\n', r':3: line longer than 4096'),
    ('time_s,speed_mps\n0,1\n1,"2\n', r'not CSV text'),
    ('time_s,speed_mps\n0,1\n1,2,3\n', r':3: expected 2 values'),
    ('t,v\n0,1\n1,2\n', r':1: expected the header time_s,speed_mps'),
    ('', r'empty file'),
    ('time_s,speed_mps\n0,1\n', r'at least 2 samples'),
])
def test_bad_traces_name_file_row_and_problem(tmp_path: Path, body: str, message: str) -> None:
    path = write(tmp_path, body)
    with pytest.raises(TraceError, match=message) as info:
        load_trace(str(path), 1.0, CONFIG)
    assert str(path) in str(info.value)


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(TraceError, match='cannot open trace'):
        load_trace(str(tmp_path / 'nope.csv'), 1.0, CONFIG)


@pytest.mark.parametrize(('data', 'message'), [
    (b'time_s,speed_mps\n0,1\n1,2\n2,\xe9\n', 'not UTF-8 text'),           # Latin-1
    (bytes(range(256)) * 4, 'not UTF-8 text'),                              # binary
    (b'time_s,speed_mps\n0,1\n1,\x002\n', ':3: speed_mps is not a number'),  # NUL byte
])
def test_non_text_files_are_one_line(tmp_path: Path, data: bytes, message: str) -> None:
    path = tmp_path / 'trace.csv'
    path.write_bytes(data)
    with pytest.raises(TraceError, match=message) as info:
        load_trace(str(path), 1.0, CONFIG)
    assert str(path) in str(info.value) and '\n' not in str(info.value)


def test_only_regular_files_are_read() -> None:
    with pytest.raises(TraceError, match='/dev/zero: not a regular file'):
        load_trace('/dev/zero', 1.0, CONFIG)


def test_errors_never_echo_the_file(tmp_path: Path) -> None:
    """A trace path may point anywhere (a params file's trace:): name the file and the
    problem, never its content."""
    for body in ('hunter2:x:0:0:hunter2:/bin/bash\n', 'time_s,speed_mps\n0,1\nhunter2,2\n',
                 'time_s,speed_mps\n0,1\n1,hunter2\n', 'time_s,speed_mps\n0,hunter2,1\n',
                 'time_s,speed_mps\n0,1\n1,"hunter2\n'):
        path = write(tmp_path, body)
        with pytest.raises(TraceError) as info:
            load_trace(str(path), 1.0, CONFIG)
        assert 'hunter2' not in str(info.value)
    if Path('/etc/passwd').is_file():
        with pytest.raises(TraceError) as info:
            load_trace('/etc/passwd', 1.0, CONFIG)
        assert str(info.value) == ('/etc/passwd:1: expected the header time_s,speed_mps (a CSV '
                                   'with these two columns)')


def test_byte_order_mark_is_accepted(tmp_path: Path) -> None:
    path = tmp_path / 'excel.csv'
    path.write_bytes(b'\xef\xbb\xbftime_s,speed_mps\r\n0,1\r\n1,2\r\n')
    assert load_trace(str(path), 1.0, CONFIG).speeds_mps.tolist() == [1.0, 2.0]


def test_steps_are_bounded_before_allocating() -> None:
    """dt_s = 1e-9 on US06 would be 6e11 steps (4 TiB): refused by the step limit."""
    with pytest.raises(TraceError, match=rf'600000000000 steps, more than the '
                                         rf'{MAX_TRACE_STEPS}'):
        load_trace('us06', 1e-9, CONFIG)
    assert load_trace('us06', 600 / MAX_TRACE_STEPS, CONFIG).steps == MAX_TRACE_STEPS


@pytest.mark.parametrize('name', ['my_trace', 'urban_commute'])
def test_gentle_stop_and_go_in_kmh_is_refused_with_the_units_hint(tmp_path: Path,
                                                                  name: str) -> None:
    """Read as m/s, a gentle trace in km/h accelerates below trace_accel_max_mps2 but stops
    and goes at 207 km/h (the own-trace tutorial's my_trace) or 252 km/h (an urban commute
    peaking at 70 km/h, 1 m/s^2)."""
    t = np.arange(0.0, 120.0, 0.5)
    if name == 'my_trace':
        speeds = np.maximum(0.0, 8 + 8 * np.sin(t / 20))
    else:
        speeds = 19.4 * np.sin(np.pi * t / 60) ** 2      # stops at 0, 60, 120 s
    kmh = write(tmp_path, 'time_s,speed_mps\n' + ''.join(
        f'{a},{3.6 * v:.3f}\n' for a, v in zip(t, speeds, strict=True)))
    with pytest.raises(TraceError) as err:
        load_trace(str(kmh), 1.0, CONFIG)
    line = str(err.value)
    assert 'stop-and-go above motorway speeds' in line and 'km/h (divide by 3.6' in line
    assert 'preceding_traffic.trace_stopping_speed_max_mps' in line and '\n' not in line
    right = write(tmp_path, 'time_s,speed_mps\n' + ''.join(    # the trace in m/s: fine
        f'{a},{v:.3f}\n' for a, v in zip(t, speeds, strict=True)), 'right.csv')
    assert load_trace(str(right), 1.0, CONFIG).max_speed_mps <= 19.4
    for shipped in ('us06', 'commute_pm', 'wltc_3b'):       # fast cycles with stops pass
        load_trace(shipped, 1.0, CONFIG)


def test_limits_are_documented() -> None:
    page = (REPO / 'docs' / 'tutorials' /
            'own-trace-or-bag.md').read_text()
    assert f'{MAX_SPEED_MPS:g} m/s' in page and f'{MAX_TRACE_STEPS:,}' in page


def test_truncate_changes_the_length_only() -> None:
    whole = load_trace('us06', 1.0, CONFIG)
    short = truncate(whole, 5)
    assert short.steps == 5 and whole.steps == 600
    assert short.max_speed_mps == whole.max_speed_mps > 35.0   # speed limit: the whole trace
    assert short.preview(4, 3).tolist() == whole.preview(4, 3).tolist()  # the recorded future
    assert truncate(whole, 0) is whole and truncate(whole, 601) is whole
    with pytest.raises(TraceError, match='max_steps must be >= 0'):
        truncate(whole, -5)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.one_of(
    st.binary(max_size=400),
    st.text(max_size=300).map(lambda t: t.encode('utf-8')),
    st.text(max_size=200).map(lambda t: t.encode('utf-16')),
    st.lists(st.tuples(st.one_of(st.floats(allow_nan=True), st.integers(), st.text(max_size=8)),
                       st.one_of(st.floats(allow_nan=True), st.integers(), st.text(max_size=8))),
             max_size=20).map(lambda rows: ('time_s,speed_mps\n' + ''.join(
                 f'{a},{b}\n' for a, b in rows)).encode('utf-8', 'surrogatepass')),
))
def test_fuzzed_csv_gives_a_trace_or_one_line(data: bytes) -> None:
    """Any bytes: a valid trace or a TraceError of one line naming the file, never another
    exception."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / 'fuzz.csv'
        path.write_bytes(data)
        try:
            trace = load_trace(str(path), 1.0, CONFIG)
        except TraceError as err:
            assert str(err).startswith(str(path)) and '\n' not in str(err)
        else:
            assert trace.steps >= 1 and np.all(np.isfinite(trace.speeds_mps))
            assert 0.0 <= trace.max_speed_mps <= MAX_SPEED_MPS
