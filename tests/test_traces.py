"""Speed traces: shipped data, resampling, preview and every validation error."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from preceding_traffic.sources import load_trace
from preceding_traffic.traces import TraceConfig, TraceError, resample

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
    ('time_s,speed_mps\n0,1\n1,2\n1,3\n', r':4: time 1.0 s does not increase'),
    ('time_s,speed_mps\n0,1\n10,2\n', r':3: gap of 10 s .* exceeds max_sample_gap_s'),
    ('time_s,speed_mps\n0,1\n1,fast\n', r':3: not a number'),
    ('time_s,speed_mps\n0,1\n1,2,3\n', r':3: expected 2 values'),
    ('t,v\n0,1\n1,2\n', r':1: expected columns time_s,speed_mps'),
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
