"""`ros2 run` compatibility: colcon builds the four ament_python packages, and every
installed executable (what `ros2 run <pkg> <exe>` starts) comes up and stops cleanly."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PARAMS = REPO / 'config' / 'trust_av.yaml'
EXECUTABLES = {
    ('preceding_traffic', 'traffic'): ['-p', 'trace:=nycc'],
    ('trust_av_planner', 'planner'): [],
    ('trust_av_planner', 'ego_plant'): ['-p', 'initial_position_m:=0.0', '-p',
                                        'initial_speed_mps:=0.0', '-p', 'start_time_s:=0.0'],
    ('trust_av_planner', 'recorder'): ['-p', 'expected_steps:=10'],
    ('human_driver_sim', 'driver'): ['-p', 'initial_position_m:=0.0', '-p',
                                     'initial_speed_mps:=0.0', '-p', 'start_time_s:=0.0'],
    ('trust_monitor', 'monitor'): [],
}


@pytest.fixture(scope='module')
def install(tmp_path_factory: pytest.TempPathFactory) -> Path:
    colcon = Path(sys.executable).parent / 'colcon'
    assert colcon.exists(), 'colcon-common-extensions is pinned in requirements.txt'
    work = tmp_path_factory.mktemp('colcon')
    proc = subprocess.run([str(colcon), '--log-base', str(work / 'log'), 'build',
                           '--base-paths', str(REPO / 'src'), '--build-base',
                           str(work / 'build'), '--install-base', str(work / 'install')],
                          cwd=work, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert 'Summary: 4 packages finished' in proc.stdout
    return work / 'install'


@pytest.mark.parametrize(('package', 'executable'), sorted(EXECUTABLES))
def test_installed_executable_comes_up(install: Path, package: str, executable: str,
                                       tmp_path: Path) -> None:
    exe = install / package / 'lib' / package / executable
    assert exe.exists(), f'{exe} missing: `ros2 run {package} {executable}` would fail'
    extra = list(EXECUTABLES[(package, executable)])
    if executable == 'recorder':
        extra += ['-p', f'bag_path:={tmp_path / "r.mcap"}']
    script = (f'source {install / "setup.bash"} && exec {exe} --ros-args --params-file '
              f'{PARAMS} ' + ' '.join(extra))
    env = dict(os.environ, ROS_DOMAIN_ID='231', ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
               ROS_LOG_DIR=str(tmp_path / 'ros_log'), PYTHONUNBUFFERED='1')
    proc = subprocess.Popen(['bash', '-c', script], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, env=env,
                            start_new_session=True)
    deadline = time.monotonic() + 60
    lines = []
    assert proc.stdout is not None
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line:
            break
        lines.append(line)
        if 'ready' in line or 'waiting for /sim/start' in line:
            break
    assert proc.poll() is None, ''.join(lines)
    # it imports the installed copy, not the source tree
    os.killpg(proc.pid, signal.SIGINT)
    rest, _ = proc.communicate(timeout=30)
    assert proc.returncode == 0, ''.join(lines) + rest
    assert 'Traceback' not in ''.join(lines) + rest
    shutil.rmtree(tmp_path / 'ros_log', ignore_errors=True)


@pytest.mark.parametrize(('args', 'message'), [
    (['-p', 'horizon_steps:=-3'], 'horizon_steps out of range. Min: 1, Max: 50'),
    (['--params-file', 'OVERRIDE'], 'alpha out of range Min: 0.0, Max: 1.0'),
    (['-p', 'speed_min_mps:=50.0'], 'need 0 <= speed_min_mps < speed_max_mps'),
])
def test_node_rejects_bad_parameters_at_start_up(tmp_path: Path, args: list[str],
                                                 message: str) -> None:
    """A node started with a bad value stops at once, naming it (exit 2)."""
    override = tmp_path / 'override.yaml'
    override.write_text('planner:\n  ros__parameters:\n    alpha: 1.5\n')
    args = [str(override) if a == 'OVERRIDE' else a for a in args]
    env = dict(os.environ, ROS_DOMAIN_ID='230', ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
               ROS_LOG_DIR=str(tmp_path / 'ros_log'))
    proc = subprocess.run([sys.executable, '-m', 'trust_av_planner.planner_node', '--ros-args',
                           '--params-file', str(PARAMS), *args], capture_output=True,
                          text=True, timeout=60, env=env)
    assert proc.returncode == 2
    assert message in proc.stderr and 'Traceback' not in proc.stderr
