"""One validator: what ``trust-av`` accepts every node accepts, and what a node refuses
``trust-av`` refuses first, with one line. Checked against the real nodes: one subprocess
builds every graph node (their real classes, ``rclpy.init`` with real ``--ros-args``, the
start-up of ``spin_node``) for each params file of a small corpus, layered exactly as the
orchestrator layers them (shipped file, the corpus file, per-run values); a few nodes are
also started as their own processes, as a user would start them by hand."""

from __future__ import annotations

import ast
import contextlib
import json
import os
import signal
import subprocess
import sys
import threading
from pathlib import Path

import pytest
from support.paths import REPO

from preceding_traffic.sources import load_trace
from trust_av.graph.domains import lease_domain
from trust_av.system.config import (
    DEFAULT_PARAMS_FILE,
    NODE_COMPONENTS,
    load_run_config,
)
from trust_av_common.param_layers import to_params_text

# name: (file over the shipped one, trust-av accepts, every node accepts)
CORPUS: dict[str, tuple[str, bool, bool]] = {
    'one_key': ('preceding_traffic:\n  ros__parameters:\n    max_sample_gap_s: 3.0\n',
                True, True),
    'integer_for_double': ('/**:\n  ros__parameters:\n    dt_s: 1\n', True, True),
    'any_namespace': ('/**/planner:\n  ros__parameters:\n    alpha: 0.25\n', True, True),
    'tag_ignored': ('/**/planner:\n  ros__parameters:\n    alpha: !!float 1\n', True, True),
    'yaml11_bool': ('/**:\n  ros__parameters:\n    speed_max_from_trace: off\n', True, True),
    'null_is_a_string': ('/**/planner:\n  ros__parameters:\n    gru_model: null\n', True, True),
    'alias': ('/**/planner:\n  ros__parameters:\n    a: &a 0.5\n    alpha: *a\n', False, False),
    'unknown_in_node_section': ('planner:\n  ros__parameters:\n    alhpa: 0.5\n', False, False),
    # a shared bring-up file: other stacks' keys in /** are ignored (a warning), a typo in a
    # section written for a node of the graph is refused
    'unknown_in_wildcard': ('/**:\n  ros__parameters:\n    speed_limit: 3.0\n', True, True),
    'unknown_in_node_wildcard_section': ('/**/planner:\n  ros__parameters:\n'
                                         '    alhpa: 0.5\n', False, False),
    'double_for_integer': ('/**/planner:\n  ros__parameters:\n    horizon_steps: 4.0\n',
                           False, False),
    'out_of_range': ('/**/planner:\n  ros__parameters:\n    alpha: 1.5\n', False, False),
    'bool_for_double': ('/**/planner:\n  ros__parameters:\n    alpha: on\n', False, False),
    'bool_for_string': ('/**/planner:\n  ros__parameters:\n    predictor: yes\n', False, False),
    'no_value': ('planner:\n  ros__parameters:\n    alpha: []\n', False, False),
    'tiny_step': ('/**:\n  ros__parameters:\n    dt_s: 1.0e-9\n', False, False),
    'trace_is_etc_passwd': ('preceding_traffic:\n  ros__parameters:\n    trace: /etc/passwd\n',
                            False, False),
    # wall-mode parameters, declared by every node, refused alike in any clock mode
    'negative_control_rate': ('/**:\n  ros__parameters:\n    control_rate_hz: -1.0\n',
                              False, False),
    'control_period_over_dt_s': ('/**:\n  ros__parameters:\n    clock_mode: wall\n'
                                 '    control_rate_hz: 0.5\n', False, False),
    'control_rate_unused_in_lock_step': ('/**:\n  ros__parameters:\n    control_rate_hz: 0.5\n',
                                         True, True),
    'zero_input_timeout': ('/**:\n  ros__parameters:\n    input_timeout_s: 0.0\n', False, False),
    # each node's section holds what that node declares: the wall-mode keys in every node
    'wall_key_in_driver_section': ('human_driver:\n  ros__parameters:\n'
                                   '    control_rate_hz: 20.0\n', True, True),
    'wall_key_in_traffic_section': ('preceding_traffic:\n  ros__parameters:\n'
                                    '    input_timeout_s: 0.4\n', True, True),
    'per_node_model_value': ('/**/human_driver:\n  ros__parameters:\n'
                             '    standstill_gap_m: 3.0\n', True, True),
    # Stricter than the nodes: rcl would silently drop these values; trust-av says so.
    'shadowed_by_shipped_section': ('/**:\n  ros__parameters:\n    alpha: 0.3\n', False, True),
    'type_change_over_shipped': ('/**:\n  ros__parameters:\n    horizon_steps: 4.0\n',
                                 False, True),
    'section_of_no_node': ('planer:\n  ros__parameters:\n    alpha: 0.5\n', False, True),
    # Stricter than the nodes: one value for the whole graph (each node alone cannot know
    # that another has another value; the graph would differ from the in-process loop, or
    # stall)
    'trust_model_differs': ('planner:\n  ros__parameters:\n    epsilon_mps2: 3.0\n',
                            False, True),
    'vehicle_length_differs': ('human_driver:\n  ros__parameters:\n'
                               '    vehicle_length_m: 4.0\n', False, True),
    'step_differs': ('planner:\n  ros__parameters:\n    dt_s: 0.5\n    horizon_steps: 6\n',
                     False, True),
    'clock_differs': ('planner:\n  ros__parameters:\n    clock_mode: wall\n', False, True),
    # a node trust-av configures per run: its values come from /** and the run
    'plant_section': ('ego_plant:\n  ros__parameters:\n    clock_mode: lockstep\n',
                      False, True),
}

# The orchestrator's per-run values, in sections that first appear in their own file.
RUN_VALUES = {'/human_driver': {'initial_position_m': 0.0, 'initial_speed_mps': 0.0,
                                'start_time_s': 0.0},
              '/ego_plant': {'initial_position_m': 10.0, 'initial_speed_mps': 0.0,
                             'start_time_s': 0.0}}

PROBE = r"""
import json, sys
import rclpy
from rclpy.exceptions import InvalidParameterValueException, ParameterUninitializedException
from human_driver_sim.driver_node import DriverNode
from preceding_traffic.traffic_node import TrafficNode
from trust_av_planner.ego_plant_node import EgoPlantNode
from trust_av_planner.planner_node import PlannerNode
from trust_monitor.monitor_node import MonitorNode
from trust_av_common.params import ParamsError
from trust_av_common.ros.spin import init_rclpy, start_node

results = {}
for name, args in json.loads(sys.argv[1]).items():
    command_line = ['probe', '--ros-args', *args]
    try:
        init_rclpy(command_line)
    except ParamsError as err:   # every node of this command line stops here
        results[name] = {'rcl': 'refused: ' + str(err)}
        continue
    verdicts = {}
    for cls in (TrafficNode, PlannerNode, DriverNode, MonitorNode, EgoPlantNode):
        try:
            node = start_node(cls, command_line)
        except (ValueError, InvalidParameterValueException,
                ParameterUninitializedException) as err:
            verdicts[cls.__name__] = 'refused: ' + str(err)
            continue
        except Exception as err:  # a crash: neither accepted nor refused in one line
            verdicts[cls.__name__] = f'crash: {type(err).__name__}: {err}'
            continue
        values = {}
        for param in ('dt_s', 'alpha'):
            if node.has_parameter(param):
                p = node.get_parameter(param)
                values[param] = [p.type_.name, p.value]
        verdicts[cls.__name__] = values
        node.close()
        node.destroy_node()
    rclpy.shutdown()
    results[name] = verdicts
print(json.dumps(results))
"""


def ros_env(tmp_path: Path, domain: int) -> dict[str, str]:
    return dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
                ROS_LOG_DIR=str(tmp_path / 'ros_log'), PYTHONUNBUFFERED='1')


def trust_av_verdict(path: Path) -> str:
    """What ``trust-av`` does before it starts any node: read the configuration, load the
    trace. '' when it accepts, else its one-line message."""
    try:
        config = load_run_config(path)
        load_trace(config.trace.trace, config.planner.dt_s, config.trace)
    except ValueError as err:   # every package's error class is a ValueError
        return str(err)
    return ''


@pytest.fixture(scope='module')
def node_verdicts(tmp_path_factory: pytest.TempPathFactory) -> dict[str, dict[str, object]]:
    tmp = tmp_path_factory.mktemp('corpus')
    run_values = tmp / 'run_values.yaml'
    run_values.write_text(to_params_text(RUN_VALUES))
    cases = {}
    for name, (text, _, _) in CORPUS.items():
        (tmp / f'{name}.yaml').write_text(text)
        cases[name] = ['--params-file', str(DEFAULT_PARAMS_FILE), '--params-file',
                       str(tmp / f'{name}.yaml'), '--params-file', str(run_values)]
    with lease_domain() as domain:   # a private domain: no other graph's nodes of these names
        proc = subprocess.run([sys.executable, '-c', PROBE, json.dumps(cases)],
                              capture_output=True, text=True, timeout=300,
                              env=ros_env(tmp, domain))
    assert proc.returncode == 0, proc.stderr[-3000:]
    verdicts: dict[str, dict[str, object]] = json.loads(proc.stdout.strip().splitlines()[-1])
    return verdicts


@pytest.mark.parametrize('name', sorted(CORPUS))
def test_trust_av_refuses_first_what_a_node_refuses(
        name: str, node_verdicts: dict[str, dict[str, object]], tmp_path: Path) -> None:
    text, trust_av_accepts, nodes_accept = CORPUS[name]
    path = tmp_path / f'{name}.yaml'
    path.write_text(text)
    mine = trust_av_verdict(path)
    nodes = node_verdicts[name]
    crashes = {k: v for k, v in nodes.items() if str(v).startswith('crash')}
    assert not crashes
    refusals = {k: v for k, v in nodes.items() if str(v).startswith('refused')}
    assert (mine == '') == trust_av_accepts, mine
    assert (not refusals) == nodes_accept, refusals
    # the rule itself: trust-av accepts => every node accepts; a node refuses => trust-av
    # refused first
    assert not (mine == '' and refusals)
    for message in [mine, *map(str, refusals.values())]:
        assert '\n' not in message and 'root:' not in message


def test_an_integer_for_a_double_is_declared_double(
        node_verdicts: dict[str, dict[str, object]]) -> None:
    """``dt_s: 1`` (rcl: INTEGER) works in a node; its parameter is DOUBLE 1.0."""
    assert node_verdicts['integer_for_double']['PlannerNode'] == {
        'dt_s': ['DOUBLE', 1.0], 'alpha': ['DOUBLE', 0.5]}
    assert node_verdicts['tag_ignored']['PlannerNode']['alpha'] == ['DOUBLE', 1.0]  # type: ignore[index]
    assert node_verdicts['any_namespace']['PlannerNode']['alpha'] == ['DOUBLE', 0.25]  # type: ignore[index]
    # what rcl does to the values trust-av refuses: silently keeps the earlier ones
    assert node_verdicts['shadowed_by_shipped_section']['PlannerNode']['alpha'] == [  # type: ignore[index]
        'DOUBLE', 0.5]


NODE_MODULES = {'preceding_traffic': 'preceding_traffic/preceding_traffic/traffic_node.py',
                'planner': 'trust_av_planner/trust_av_planner/planner_node.py',
                'human_driver': 'human_driver_sim/human_driver_sim/driver_node.py',
                'trust_monitor': 'trust_monitor/trust_monitor/monitor_node.py'}
PER_RUN = {'TrafficRunConfig': 'the trace and steps of the run',
           'FollowerState': "the human's initial state (its vehicle_length_m is SharedConfig's)"}
"""Configurations a node declares that trust-av sets for each run (not a params file's)."""


def declared_components(path: Path) -> set[str]:
    """The configuration classes a node module passes to ``declare_config`` by name (the
    registered components' classes, trust models included, are declared by the node that
    runs their group: ``system.config.COMPONENT_GROUPS``, checked by the contract tests)."""
    calls = [call for call in ast.walk(ast.parse(path.read_text()))
             if isinstance(call, ast.Call) and isinstance(call.func, ast.Name)]
    return {call.args[1].id for call in calls
            if call.func.id == 'declare_config' and isinstance(call.args[1], ast.Name)}


@pytest.mark.parametrize('node', sorted(NODE_MODULES))
def test_each_node_section_holds_what_the_node_declares(node: str) -> None:
    """trust-av's table of node sections is the nodes' own declarations (read from their
    source), so a key a node takes from its section is not refused by trust-av; trust-av
    adds SharedConfig only, which it reads itself."""
    src = REPO / 'src'
    declared = declared_components(src / NODE_MODULES[node]) - set(PER_RUN)
    listed = {component.__name__ for component in NODE_COMPONENTS[node]}
    assert declared and declared <= listed, declared - listed
    assert listed - declared <= {'SharedConfig'}, listed - declared


@pytest.mark.parametrize(('text', 'message'), [
    (CORPUS['plant_section'][0],
     "{path}: section 'ego_plant': trust-av sets the ego_plant node's values for each run "
     '(its clock settings come from /**); node sections: preceding_traffic, planner, '
     'human_driver, trust_monitor'),
    # The files come in the order the two nodes are named, whichever sorts first by path
    # (the checkout and the temporary directory sort either way on different machines).
    (CORPUS['trust_model_differs'][0],
     '{path}, {shipped}: epsilon_mps2 is 3.0 for planner but 6.0 for trust_monitor: the '
     'planner and the monitor must run the same trust model; set it once, in /**'),
    ('trust_monitor:\n  ros__parameters:\n    epsilon_mps2: 3.0\n',
     '{shipped}, {path}: epsilon_mps2 is 6.0 for planner but 3.0 for trust_monitor: the '
     'planner and the monitor must run the same trust model; set it once, in /**'),
], ids=['plant_section', 'planner_set', 'monitor_set'])
def test_stricter_refusals_say_why(tmp_path: Path, text: str, message: str) -> None:
    """What trust-av refuses beyond the nodes is explained: a node configured per run, a
    value that must be one for the whole graph (both nodes named)."""
    path = tmp_path / 'params.yaml'
    path.write_text(text)
    assert trust_av_verdict(path) == message.format(path=path, shipped=DEFAULT_PARAMS_FILE)


def start(tmp_path: Path, domain: int, module: str, *args: str) -> subprocess.Popen[str]:
    return subprocess.Popen([sys.executable, '-m', module, '--ros-args', *args],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env=ros_env(tmp_path, domain), start_new_session=True)


def test_hand_started_nodes(tmp_path: Path) -> None:
    """As a user starts them: an unknown parameter from -p or from the node's section of a
    params file is one line naming it and where it came from, and exit 2; one in a wildcard
    section is a warning; with no params file of the graph a node runs on the shipped
    values and takes an integer for a double from -p."""
    typo = tmp_path / 'typo.yaml'
    typo.write_text('trust_monitor:\n  ros__parameters:\n    epsilon: 3.0\n')
    shared = tmp_path / 'bringup.yaml'     # another stack's keys in the wildcard section
    shared.write_text('/**:\n  ros__parameters:\n    wheel_base: 2.79\n')
    procs = {
        'p_typo': start(tmp_path, 226, 'trust_monitor.monitor_node', '-p', 'alhpa:=3'),
        'file_typo': start(tmp_path, 227, 'trust_monitor.monitor_node', '--params-file',
                           str(typo)),
        'alone': start(tmp_path, 228, 'trust_av_planner.planner_node', '-p', 'dt_s:=1',
                       '--params-file', str(shared)),
    }
    outputs = {}
    alone = procs.pop('alone')
    assert alone.stdout is not None
    seen = []
    # until it says it is ready (its 'ready' line follows the overrides' check and its
    # warning), or ends; a node that never says so is stopped after 60 s
    watchdog = threading.Timer(60.0, os.killpg, (alone.pid, signal.SIGINT))
    watchdog.start()
    try:
        for line in alone.stdout:
            seen.append(line)
            if 'ready (' in line:
                break
    finally:
        watchdog.cancel()
    with contextlib.suppress(ProcessLookupError):
        os.killpg(alone.pid, signal.SIGINT)
    rest, _ = alone.communicate(timeout=60)
    assert alone.returncode == 0 and 'ready (lock-step)' in ''.join(seen) + rest, \
        ''.join(seen) + rest
    assert ('ignoring parameter(s) wheel_base of a wildcard section: not parameters of any '
            'node of the graph') in ''.join(seen) + rest
    for name, proc in procs.items():
        outputs[name] = proc.communicate(timeout=120)[0]
        assert proc.returncode == 2, outputs[name]
        assert 'Traceback' not in outputs[name]
    errors = {name: [line for line in out.splitlines() if line.startswith('error:')]
              for name, out in outputs.items()}
    assert errors['p_typo'] == ['error: /trust_monitor: unknown parameter(s) alhpa (not a '
                                'parameter of this node or of any node of the graph) (from '
                                'the command line (-p))']
    assert errors['file_typo'] == ['error: /trust_monitor: unknown parameter(s) epsilon (did '
                                   "you mean 'epsilon_mps2'?) (not a "
                                   'parameter of this node or of any node of the graph) (from '
                                   f'{typo}: section trust_monitor)']
