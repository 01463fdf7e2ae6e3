"""`ros2 run` compatibility: colcon builds the six ament_python packages; every installed
executable (what `ros2 run <pkg> <exe>` starts) comes up with no params file, on the shipped
values installed in share/trust_av_common/config (found through ament_index_python), and stops
cleanly; trust-monitor-estimate runs from the install."""

from __future__ import annotations

import hashlib
import os
import queue
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from support import bring_up
from support.paths import REPO
from support.processes import hangup_by_default
from support.rosbag2_rules import check_bag_directory

PARAMS = REPO / 'config' / 'trust_av.yaml'
EXECUTABLES = {
    ('preceding_traffic', 'traffic'): ['-p', 'trace:=nycc'],
    ('trust_av_planner', 'planner'): [],
    ('trust_av_planner', 'ego_plant'): ['-p', 'initial_position_m:=0.0', '-p',
                                        'initial_speed_mps:=0.0', '-p', 'start_time_s:=0.0'],
    ('trust_av', 'recorder'): ['-p', 'expected_steps:=10'],
    # kept in trust_av_planner for one release (its home is trust_av)
    ('trust_av_planner', 'recorder'): ['-p', 'expected_steps:=10'],
    ('human_driver_sim', 'driver'): ['-p', 'initial_position_m:=0.0', '-p',
                                     'initial_speed_mps:=0.0', '-p', 'start_time_s:=0.0'],
    ('trust_monitor', 'monitor'): [],
}


COLCON_TEST_K = ('test_known_pair_by_hand or test_resample_interpolates_onto_grid or '
                 'test_textbook_and_bounds or test_mean_ci95_by_hand or '
                 'test_solver_failure_is_reported_not_raised or test_help_explains or '
                 'test_the_lead_is_chosen_among_the_objects_on_a_bent_lane')
"""One quick test of each package for `colcon test` (the suite runs them all itself)."""


def clone(destination: Path) -> None:
    """The repository's files as `git clone` gives them (tracked and new, not ignored:
    no .venv, bags or build trees), copied from this working tree into ``destination``."""
    listed = subprocess.run(['git', 'ls-files', '-z', '--cached', '--others',
                             '--exclude-standard'], cwd=REPO, capture_output=True,
                            check=True).stdout.decode().split('\0')
    for name in filter(None, listed):
        source = REPO / name
        if source.is_file():
            (destination / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(source, destination / name, follow_symlinks=False)


def colcon(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    """Plain ``colcon ARGS`` in workspace ``cwd``, this environment's tools first on PATH."""
    env = dict(os.environ, PATH=f'{Path(sys.executable).parent}:{os.environ["PATH"]}')
    return subprocess.run([str(Path(sys.executable).parent / 'colcon'), *args], cwd=cwd,
                          capture_output=True, text=True, timeout=900, env=env)


@pytest.fixture(scope='module')
def install(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The documented layout (docs/operations/colcon.md): the repository as
    ``ws/src/trust-av`` (a virtual environment inside it too, as scripts/bootstrap.sh makes
    one), then plain ``colcon build`` in ``ws``: exactly the seven packages, never
    vendor/ (tf2_msgs, a one-message copy for the virtual environment that would overlay a
    native tf2_msgs, and the Autoware message packages) nor the environment's own packages."""
    assert (Path(sys.executable).parent / 'colcon').exists(), \
        'colcon-common-extensions is pinned in requirements.txt'
    ws = tmp_path_factory.mktemp('ws')
    clone(ws / 'src' / 'trust-av')
    venv = ws / 'src' / 'trust-av' / '.venv'   # a clone's environment, as bootstrap.sh left ours
    shutil.copytree(Path(sys.prefix) / 'share' / 'geometry_msgs', venv / 'share' / 'geometry_msgs')
    if (Path(sys.prefix) / 'COLCON_IGNORE').exists():
        (venv / 'COLCON_IGNORE').touch()
    listed = colcon('list', '--names-only', cwd=ws)
    assert listed.returncode == 0, listed.stdout + listed.stderr
    assert sorted(listed.stdout.split()) == ['human_driver_sim', 'preceding_traffic', 'trust_av',
                                             'trust_av_autoware', 'trust_av_common',
                                             'trust_av_planner', 'trust_monitor']
    proc = colcon('build', cwd=ws)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert 'Summary: 7 packages finished' in proc.stdout
    install = ws / 'install'
    # each package installs the config files it holds (real files, no links out of it)
    share = install / 'trust_av_common' / 'share' / 'trust_av_common' / 'config'
    assert (share / 'trust_av.yaml').read_text() == PARAMS.read_text()
    layout = install / 'trust_av' / 'share' / 'trust_av' / 'config'
    assert (layout / 'foxglove_layout.json').read_text() == \
        (REPO / 'config' / 'foxglove_layout.json').read_text()
    for package in ('trust_av_common', 'trust_av'):
        config = REPO / 'src' / package / package / 'config'
        assert config.is_dir() and not config.is_symlink()
        assert not any(path.is_symlink() for path in config.iterdir())
    return install


def in_install(install: Path, command: str, tmp_path: Path, domain: str = '232',
               timeout: float = 120) -> subprocess.CompletedProcess[str]:
    """Run a shell command with the install sourced (as a ROS user would), outside the repo."""
    env = dict(os.environ, ROS_DOMAIN_ID=domain, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
               ROS_LOG_DIR=str(tmp_path / 'ros_log'), PYTHONUNBUFFERED='1')
    return subprocess.run(['bash', '-c', f'source {install / "setup.bash"} && {command}'],
                          capture_output=True, text=True, env=env, cwd=tmp_path,
                          timeout=timeout)


def test_installed_copy_finds_its_share(install: Path, tmp_path: Path) -> None:
    # this interpreter (the venv's, with ament_index_python) whether or not PATH leads to it
    proc = in_install(install, f'{sys.executable} -c "import trust_av_common.param_layers as m; '
                               'print(m.__file__); print(m.shipped_params_file()); '
                               "print(m.shipped_params_file('fastdds_graph.xml'))\"", tmp_path)
    assert proc.returncode == 0, proc.stderr
    module, shipped, profile = proc.stdout.split()
    assert Path(module).is_relative_to(install / 'trust_av_common')
    share = install / 'trust_av_common' / 'share' / 'trust_av_common' / 'config'
    assert Path(shipped) == share / 'trust_av.yaml'
    assert Path(profile) == share / 'fastdds_graph.xml' and Path(profile).is_file()


def test_installed_drive_server_serves_the_page_and_its_library(install: Path,
                                                                  tmp_path: Path) -> None:
    """The colcon install of trust_av serves every file of the drive page from itself, the
    vendored Konva included, byte for byte as in the repository."""
    proc = in_install(install, f'{sys.executable} -c "import hashlib, trust_av.drive.server as s; '
                               'print(s.__file__); [print(p, hashlib.sha256(s.page_file(n))'
                               '.hexdigest()) for p, (n, _) in sorted(s.PAGES.items())]"',
                      tmp_path)
    assert proc.returncode == 0, proc.stderr
    module, *pages = proc.stdout.splitlines()
    assert Path(module).is_relative_to(install / 'trust_av')
    web = REPO / 'src' / 'trust_av' / 'trust_av' / 'drive' / 'web'
    served = dict(line.split() for line in pages)
    assert served['/vendor/konva/konva.min.js'] == hashlib.sha256(
        (web / 'vendor' / 'konva' / 'konva.min.js').read_bytes()).hexdigest()
    assert served['/'] == hashlib.sha256((web / 'index.html').read_bytes()).hexdigest()
    assert len(served) == len(list(web.glob('*.*'))) + 1     # every page file + the library


@pytest.mark.parametrize(('package', 'executable'), sorted(EXECUTABLES))
def test_installed_executable_comes_up(install: Path, package: str, executable: str,
                                       tmp_path: Path, ros_domain: str) -> None:
    exe = install / package / 'lib' / package / executable
    assert exe.exists(), f'{exe} missing: `ros2 run {package} {executable}` would fail'
    extra = list(EXECUTABLES[(package, executable)])
    if executable == 'recorder':
        extra += ['-p', f'bag_path:={tmp_path / "r"}']
    # no --params-file: a node started alone runs on the installed shipped values
    script = f'source {install / "setup.bash"} && exec {exe} --ros-args ' + ' '.join(extra)
    env = dict(os.environ, ROS_DOMAIN_ID=ros_domain, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
               ROS_LOG_DIR=str(tmp_path / 'ros_log'), PYTHONUNBUFFERED='1')
    proc = subprocess.Popen(['bash', '-c', script], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, env=env,
                            start_new_session=True, preexec_fn=hangup_by_default)
    words = ('recording ',) if executable == 'recorder' else ('ready', 'waiting for /sim/start')
    lines: queue.Queue[str] = queue.Queue()
    assert proc.stdout is not None
    reader = threading.Thread(target=lambda out=proc.stdout: [lines.put(x) for x in out],
                              daemon=True)
    reader.start()
    seen: list[str] = []
    deadline = time.monotonic() + 60
    while not any(word in line for line in seen for word in words):
        assert time.monotonic() < deadline, f'{executable} not up in 60 s:\n' + ''.join(seen)
        try:
            seen.append(lines.get(timeout=0.5))
        except queue.Empty:
            assert proc.poll() is None, ''.join(seen)
    assert proc.poll() is None, ''.join(seen)
    # Ctrl-C; the recorder's terminal closes instead (SIGHUP): it finishes its bag either way
    os.killpg(proc.pid, signal.SIGHUP if executable == 'recorder' else signal.SIGINT)
    proc.wait(timeout=30)
    reader.join(timeout=10)                             # the pipe is drained to its end
    while not lines.empty():
        seen.append(lines.get())
    assert proc.returncode == 0, ''.join(seen)
    assert 'Traceback' not in ''.join(seen)
    if executable == 'recorder':
        assert check_bag_directory(tmp_path / 'r') == []
    shutil.rmtree(tmp_path / 'ros_log', ignore_errors=True)


def test_installed_node_names_what_it_misses(install: Path, tmp_path: Path) -> None:
    """The three executables with per-run values and no shipped default for them (ego_plant,
    driver, recorder): one line naming every value a run must supply and how to pass it,
    exit 2; the other three start from the installed params file alone (above)."""
    exe = install / 'trust_av_planner' / 'lib' / 'trust_av_planner' / 'ego_plant'
    proc = in_install(install, f'{exe} --ros-args -p initial_speed_mps:=0.0', tmp_path)
    assert proc.returncode == 2
    errors = [line for line in proc.stderr.splitlines() if line.startswith('error:')]
    assert errors == ['error: parameters initial_position_m, start_time_s are missing '
                      '(PlantConfig): no params file sets them, each run supplies them '
                      '(trust-av does; by hand: pass --ros-args -p initial_position_m:=VALUE '
                      '-p start_time_s:=VALUE)'], proc.stderr
    for package, executable, line in (
            ('human_driver_sim', 'driver', 'parameters initial_position_m, initial_speed_mps, '
             'start_time_s are missing (FollowerState): no params file sets them, each run '
             'supplies them (trust-av does; by hand: pass --ros-args -p '
             'initial_position_m:=VALUE -p initial_speed_mps:=VALUE -p start_time_s:=VALUE)'),
            ('trust_av', 'recorder', 'parameter bag_path is missing (RecorderConfig): '
             'no params file sets it, each run supplies it (trust-av does; by hand: pass '
             '--ros-args -p bag_path:=VALUE)')):
        exe = install / package / 'lib' / package / executable
        proc = in_install(install, str(exe), tmp_path)
        assert proc.returncode == 2
        errors = [line for line in proc.stderr.splitlines() if line.startswith('error:')]
        assert errors == [f'error: {line}'], proc.stderr


def test_installed_trust_monitor_estimate(install: Path, tmp_path: Path) -> None:
    plans = tmp_path / 'plans.csv'
    plans.write_text('t,plan_0,expected_0\n0,0.5,0.4\n1,0.2,0.2\n')
    exe = install / 'trust_monitor' / 'lib' / 'trust_monitor' / 'trust-monitor-estimate'
    proc = in_install(install, f'{exe} {plans} -o {tmp_path / "trust.csv"}', tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == f'wrote 2 rows to {tmp_path / "trust.csv"}'
    rows = (tmp_path / 'trust.csv').read_text().splitlines()
    assert rows[0] == 't,E,P,trust' and len(rows) == 3


@pytest.mark.parametrize(('args', 'message'), [
    (['-p', 'horizon_steps:=-3'], 'horizon_steps must be in [1, 50], got -3'),
    (['--params-file', 'OVERRIDE'], 'alpha must be in [0, 1], got 1.5'),
    (['-p', 'speed_min_mps:=50.0'], 'need 0 <= speed_min_mps < speed_max_mps'),
    (['-p', 'alhpa:=0.5'], 'unknown parameter(s) alhpa'),
])
def test_node_rejects_bad_parameters_at_start_up(tmp_path: Path, args: list[str],
                                                 message: str, ros_domain: str) -> None:
    """A node started with a bad value stops at once, naming it (exit 2)."""
    override = tmp_path / 'override.yaml'
    override.write_text('planner:\n  ros__parameters:\n    alpha: 1.5\n')
    args = [str(override) if a == 'OVERRIDE' else a for a in args]
    env = dict(os.environ, ROS_DOMAIN_ID=ros_domain, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
               ROS_LOG_DIR=str(tmp_path / 'ros_log'))
    proc = subprocess.run([sys.executable, '-m', 'trust_av_planner.planner_node', '--ros-args',
                           '--params-file', str(PARAMS), *args], capture_output=True,
                          text=True, timeout=60, env=env)
    assert proc.returncode == 2
    assert message in proc.stderr and 'Traceback' not in proc.stderr
    assert ']: ready' not in proc.stderr, proc.stderr     # refused: never said it was ready


def test_a_refused_adapter_never_says_it_is_ready(tmp_path: Path, ros_domain: str) -> None:
    """A node that is not managed (``autoware_lane``) refused for an unknown ``-p``: one
    line, exit 2, and no ``ready`` line before it (before, it said ready, then refused)."""
    env = dict(os.environ, ROS_DOMAIN_ID=ros_domain, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
               ROS_LOG_DIR=str(tmp_path / 'ros_log'))
    proc = subprocess.run([sys.executable, '-m', 'trust_av_autoware.lane_adapter_node',
                           '--ros-args', '-p', 'lane_widht_m:=3.0'], capture_output=True,
                          text=True, timeout=60, env=env)
    assert proc.returncode == 2, proc.stderr
    assert 'unknown parameter(s) lane_widht_m' in proc.stderr, proc.stderr
    assert ']: ready' not in proc.stderr, proc.stderr


def test_colcon_test_runs_each_package_s_tests(install: Path) -> None:
    """Plain ``colcon test`` in the workspace runs pytest (the package's ``test`` extra) on
    each package's modules of tests/ (its setup.cfg) against the install, one quick test of
    each here (``-k``; the suite itself runs them all), and ``colcon test-result`` finds
    their results: one test per package, none failed."""
    ws = install.parent
    proc = colcon('test', '--pytest-args', '-k', COLCON_TEST_K, '-p', 'no:cacheprovider',
                  cwd=ws)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert 'Summary: 7 packages finished' in proc.stdout, proc.stdout
    result = colcon('test-result', '--all', cwd=ws)
    assert result.returncode == 0, result.stdout + result.stderr
    lines = [line for line in result.stdout.splitlines() if line.endswith('.xml: 1 test, 0 '
                                                                       'errors, 0 failures, '
                                                                       '0 skipped')]
    assert len(lines) == 7, result.stdout
    assert result.stdout.splitlines()[-1] == 'Summary: 7 tests, 0 errors, 0 failures, 0 skipped'


BRING_UP = {
    # page: what each of its `ros2 run` lines reaches, in order (a line seen in its output)
    'colcon.md': ['active'],
    'real-vehicle.md': ['inactive: waiting for activate (clock_mode wall)',
                        "ready: lane in 'map' from /your/centreline",
                        'ready: /ego/accel_cmd -> /control/trust_av/control_cmd'],
    'connect-a-vehicle.md': ['inactive: waiting for activate (clock_mode wall)',
                             'inactive: waiting for activate (clock_mode wall)'],
}
"""Every page of docs/operations and docs/tutorials with a ``ros2 run`` line in a bash block,
and the state each line is documented to reach."""
COMMANDED_ON = {'real-vehicle.md': '/ego/accel_cmd', 'connect-a-vehicle.md': '/control/accel_cmd'}
"""Where the planner's commands go once a page's ``ros2 lifecycle set /planner activate`` ran."""


def test_every_documented_bring_up_line_is_run() -> None:
    """The pages' ``ros2`` lines are those the test below runs: a new one needs its state."""
    found = {page.name: [c.words[:4] for c in bring_up.commands(page)[0]
                         if c.words[:2] == ['ros2', 'run']] for page in bring_up.PAGES}
    assert {name: len(lines) for name, lines in found.items() if lines} == \
        {name: len(states) for name, states in BRING_UP.items()}
    every = [c for page in bring_up.PAGES for c in bring_up.commands(page)[0]]
    assert {' '.join(c.words[:3]) for c in every} == {'ros2 run trust_av_planner',
                                                      'ros2 run trust_av_autoware',
                                                      'ros2 run trust_monitor',
                                                      'ros2 lifecycle set'}


@pytest.mark.parametrize('page', sorted(BRING_UP))
def test_documented_bring_up_runs_as_printed(install: Path, page: str, tmp_path: Path,
                                             ros_domain: str) -> None:
    """Each ``ros2 run`` line of the page as printed (bash reads it: quoting, comments,
    continuations), from a clone's root (``config/``) with the page's files written, each in
    its own process on the colcon install, until it says the state the page gives; then the
    page's ``ros2 lifecycle set`` lines (``change_state``): each succeeds, after the planner's
    ``activate`` its first command is on the wire (the stale-input deceleration: no vehicle
    here), after ``deactivate`` it has handed over. A ``-p`` wins over the params file's
    ``/**/planner`` (``lead_preview``, ``human_odom_topic``): the planner's ready line says
    so."""
    from geometry_msgs.msg import AccelStamped
    from lifecycle_msgs.msg import Transition
    from lifecycle_msgs.srv import ChangeState
    from support.lifecycle import Manager

    from trust_av_common.ros.qos import topic_qos
    from trust_av_common.wall_clock import WallClockConfig

    cmds, files = bring_up.commands(next(p for p in bring_up.PAGES if p.name == page))
    (tmp_path / 'config').symlink_to(REPO / 'config')
    for name, content in files.items():
        (tmp_path / name).write_text(content, encoding='utf-8')
    env = dict(os.environ, ROS_DOMAIN_ID=ros_domain, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
               ROS_LOG_DIR=str(tmp_path / 'ros_log'), PYTHONUNBUFFERED='1')
    runs = [c for c in cmds if c.words[:2] == ['ros2', 'run']]
    sets = [c.words[3:5] for c in cmds if c.words[:3] == ['ros2', 'lifecycle', 'set']]
    with bring_up.started(install, runs, tmp_path, env) as processes:
        for process, state in zip(processes, BRING_UP[page], strict=True):
            process.wait_for(lambda line, state=state: f']: {state}' in line)
        planner = processes[0]
        ready = planner.wait_for(lambda line: ']: ready (' in line)
        if page != 'colcon.md':   # the vehicle pages: constant-speed lead, no follower
            assert 'lead preview constant_speed' in ready and 'human' not in ready, ready
        if not sets:
            return
        manager = Manager(int(ros_domain), 'planner')
        try:
            sent: list[AccelStamped] = []
            manager.node.create_subscription(
                AccelStamped, COMMANDED_ON[page], sent.append,
                topic_qos('ego/accel_cmd', WallClockConfig(clock_mode='wall')))
            for node, transition in sets:
                client = manager.node.create_client(ChangeState, f'{node}/change_state')
                request = ChangeState.Request(
                    transition=Transition(id=bring_up.TRANSITIONS[transition]))
                assert manager.call(client, request).success, (node, transition)
                if node == '/planner' and transition == 'activate':
                    assert manager.spin_until(lambda: len(sent) >= 1), 'no command'
                    assert sent[0].accel.linear.x == -2.0, sent[0]
                elif node == '/planner':
                    planner.wait_for(lambda line: 'handed over with -2 m/s^2' in line)
        finally:
            manager.close()
