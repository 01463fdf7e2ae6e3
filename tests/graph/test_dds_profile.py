"""The Fast DDS profile every participant of a run gets (config/fastdds_graph.xml).

Fast DDS reads a profiles file when the first participant of a process is created; a file it
cannot parse is logged (on standard output) as an ``XMLPARSER Error`` and then ignored: the
participant comes up with the defaults. So the check is that Fast DDS itself, in a fresh
process, takes the shipped file and prints nothing, and that the same check sees a broken
copy.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from trust_av.graph import processes
from trust_av.graph.processes import (
    DDS_PROFILE,
    PROFILE_VARIABLES,
    Graph,
    GraphError,
    use_run_discovery,
)
from trust_av_common.param_layers import shipped_params_file

SHIPPED = shipped_params_file(DDS_PROFILE)
NODE = ('import rclpy; rclpy.init(); node = rclpy.create_node("profile_check"); '
        'print("up", flush=True); node.destroy_node(); rclpy.shutdown()')


def start_a_node(profile: Path) -> subprocess.CompletedProcess[str]:
    """A node in a fresh process with ``profile`` as its Fast DDS profiles file (discovery
    off: the profile is parsed all the same, and no domain is touched)."""
    env = {k: v for k, v in os.environ.items() if k not in PROFILE_VARIABLES}
    env.update(FASTRTPS_DEFAULT_PROFILES_FILE=str(profile), ROS_DOMAIN_ID='0',
               ROS_AUTOMATIC_DISCOVERY_RANGE='OFF', RMW_IMPLEMENTATION='rmw_fastrtps_cpp')
    return subprocess.run([sys.executable, '-c', NODE], capture_output=True, text=True,
                          env=env, timeout=60)


def test_fast_dds_takes_the_shipped_profile_and_refuses_a_broken_one(tmp_path: Path) -> None:
    good = start_a_node(SHIPPED)
    said = good.stdout + good.stderr
    assert good.returncode == 0 and said.split() == ['up'], said
    broken = tmp_path / 'broken.xml'
    broken.write_text(SHIPPED.read_text().replace('leaseAnnouncement', 'leaseAnouncement'))
    bad = start_a_node(broken)
    said = bad.stdout + bad.stderr  # Fast DDS logs to standard output
    assert bad.returncode == 0 and 'up' in said.split()  # it goes on with its defaults ...
    assert 'XMLPARSER' in said and 'leaseAnouncement' in said  # ... naming what it ignored


def test_a_run_uses_the_shipped_profile_unless_the_user_names_one(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    env: dict[str, str] = {}
    use_run_discovery(env)
    assert env == {'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST',
                   'FASTRTPS_DEFAULT_PROFILES_FILE': str(SHIPPED)}
    for name in PROFILE_VARIABLES:
        theirs = {name: '/etc/their_profile.xml'}
        use_run_discovery(theirs)
        assert theirs == {name: '/etc/their_profile.xml',
                          'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'}
    # A graph's nodes get the same, from this process's environment (an in-process session
    # earlier in this worker may have set the variable already: start from none).
    for name in (*PROFILE_VARIABLES, 'OPENBLAS_NUM_THREADS'):
        monkeypatch.delenv(name, raising=False)
    graph = Graph([], [], 7, tmp_path / 'logs')
    assert graph.env['ROS_DOMAIN_ID'] == '7'
    assert graph.env['FASTRTPS_DEFAULT_PROFILES_FILE'] == str(SHIPPED)
    assert graph.env['OPENBLAS_NUM_THREADS'] == '1'
    monkeypatch.setenv('FASTDDS_DEFAULT_PROFILES_FILE', '/etc/their_profile.xml')
    monkeypatch.setenv('OPENBLAS_NUM_THREADS', '2')
    graph = Graph([], [], 7, tmp_path / 'logs')
    assert 'FASTRTPS_DEFAULT_PROFILES_FILE' not in graph.env
    assert graph.env['FASTDDS_DEFAULT_PROFILES_FILE'] == '/etc/their_profile.xml'
    assert graph.env['OPENBLAS_NUM_THREADS'] == '2'


def test_a_missing_profile_is_one_error(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setattr(processes, 'shipped_params_file', lambda name: tmp_path / name)
    with pytest.raises(GraphError, match=f'Fast DDS profile {tmp_path / DDS_PROFILE} is '
                                         'missing'):
        use_run_discovery({})
