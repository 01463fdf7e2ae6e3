"""The ctypes binding of rcl's params-file parser (trust_av_common.rcl_parser): found
without help from the loader's path, one line when missing, nothing left behind, rcl's
messages made one line without the C source location or file content.

That it reads every value bit for bit as rclpy does is tests/graph/test_rcl_yaml_rules.py.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from trust_av_common.params import ParamsError
from trust_av_common.rcl_parser import (
    PARSER_LIBRARY,
    RclParseError,
    parse_files,
    parse_value,
    rcl_error_line,
)

# No LD_LIBRARY_PATH, and the PyPI wheels' bootstrapper (which sets it and re-executes
# Python) told that it already ran: the loader alone cannot find the ROS libraries.
BARE_ENV = {key: value for key, value in os.environ.items()
            if key not in ('LD_LIBRARY_PATH', 'AMENT_PREFIX_PATH')}
BARE_ENV['_ROS_WHEELS_BOOTSTRAP_COMPLETE'] = '1'


def _python(code: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, '-c', code], env=BARE_ENV, capture_output=True,
                          text=True, timeout=120, check=False)


def test_library_is_found_in_the_prefix_when_the_loader_cannot_find_it() -> None:
    probe = _python('import ctypes\ntry:\n    ctypes.CDLL("librcl_yaml_param_parser.so")\n'
                    'except OSError:\n    print("not on the loader path")\n')
    assert probe.stdout.strip() == 'not on the loader path', probe.stderr
    done = _python('from trust_av_common.rcl_parser import parse_files\n'
                   'print(parse_files([(b"/a:\\n  ros__parameters:\\n    x: [1.5]\\n", "f")]))')
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "{'/a': {'x': [1.5]}}"


def test_missing_library_is_one_line_exit_2_from_the_cli(tmp_path: Path) -> None:
    """The CLI reads the shipped params file first: without rcl it stops with one line."""
    code = ('import runpy, sys\n'
            'import trust_av_common.rcl_parser as binding\n'
            'binding._library_dirs = lambda: []\n'
            'sys.argv = ["trust-av", "simulate", "--max-steps", "1", "--no-progress", '
            f'"--out", {str(tmp_path / "run.csv")!r}]\n'
            'runpy.run_module("trust_av.cli", run_name="__main__")\n')
    done = _python(code)
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and PARSER_LIBRARY in lines[0], done.stderr
    assert "cannot load rcl's params-file parser" in lines[0] and 'Traceback' not in done.stderr
    assert not (tmp_path / 'run.csv').exists()


def test_parsing_leaves_no_descriptor_or_file_behind(tmp_path: Path) -> None:
    before = set(os.listdir('/proc/self/fd'))
    text = b'planner:\n  ros__parameters:\n    alpha: 0.5\n'
    for _ in range(50):
        assert parse_files([(text, 'p')]) == {'planner': {'alpha': 0.5}}
        with pytest.raises(ParamsError):
            parse_files([(b'planner: *a\n', 'p')])
    assert set(os.listdir('/proc/self/fd')) == before


def test_files_share_one_structure_in_order() -> None:
    """arguments.c: every --params-file goes into one rcl_params_t; sections keep the order
    of their first appearance and a value fills its own type's slot (rclpy reads the
    integer slot before the double one)."""
    first = b'/**:\n  ros__parameters:\n    a: 1\nplanner:\n  ros__parameters:\n    b: x\n'
    second = b'/**:\n  ros__parameters:\n    a: 2.5\n    c: [true]\n'
    got = parse_files([(first, 'f1'), (second, 'f2')])
    assert list(got) == ['/**', 'planner']
    assert got['/**'] == {'a': 1, 'c': [True]} and got['planner'] == {'b': 'x'}


def test_refusal_names_the_file_and_rcls_line() -> None:
    with pytest.raises(RclParseError) as caught:
        parse_files([(b'planner:\n  ros__parameters:\n    a: 1\n', 'ok.yaml'),
                      (b'planner:\n  ros__parameters:\n    a: [1, x]\n', 'bad.yaml')])
    err = caught.value
    assert (err.where, err.line) == ('bad.yaml', 3) and err.stored == {'planner'}
    assert str(err).startswith('bad.yaml: line 3: Sequence should be of same type')


@pytest.mark.parametrize(('message', 'line', 'text'), [
    ('Will not support aliasing at line 4\n, at ./src/parse.c:894', 4,
     'Will not support aliasing'),
    ("Sequence should be of same type. Value type 'double' do not belong at line_num 3, at "
     './src/parse.c:392', 3, "Sequence should be of same type: value type 'double' do not "
                             'belong'),
    ('Error parsing value hunter2 secret at line 7, at ./src/parse.c:273', 7,
     'Error parsing value (...)'),
    ('Unknown data type of value hunter2 at line 2\n, at ./src/parse.c:281', 2,
     'Unknown data type of value (...)'),
    ("node name must not contain characters other than alphanumerics or '_', at "
     './src/parse.c:490', None, "node name must not contain characters other than "
                                "alphanumerics or '_'"),
])
def test_rcl_messages_become_one_line(message: str, line: int | None, text: str) -> None:
    """parse.c's texts: the line is taken out, the C location and any value dropped."""
    assert rcl_error_line(message) == (line, text)


def test_a_command_line_value_is_typed_as_rcl_types_it() -> None:
    """``-p name:=text`` as rcl reads it (``rcl_parse_yaml_value``): the quoted empty string
    a shell passes for ``"name:=''"``, numbers, booleans, lists; the empty text (what
    ``-p name:=''`` reaches rcl as) refused, in one line."""
    assert parse_value('human_odom_topic', "''") == ''
    assert parse_value('alpha', '0.25') == 0.25 and parse_value('horizon_steps', '3') == 3
    assert parse_value('autostart', 'false') is False
    assert parse_value('lead_preview', 'constant_speed') == 'constant_speed'
    assert parse_value('gains', '[1.0, 2.5]') == [1.0, 2.5]
    with pytest.raises(ParamsError, match=r'^-p human_odom_topic: .*\(rcl_parse_yaml_value\)$'):
        parse_value('human_odom_topic', '')


def test_the_command_line_s_p_rules_for_a_node_last_one_wins() -> None:
    from trust_av_common.ros.parameters import command_line_values, param_rules

    args = ['planner', '--ros-args', '--params-file', 'f.yaml', '-p', 'alpha:=0.3',
            '-p', "human_odom_topic:=''", '--param', 'planner:alpha:=0.25', '-p',
            'trust_monitor:alpha:=0.9', '--', '-p', 'not_ros:=1', '--ros-args', '-p',
            'autostart:=false']
    assert param_rules(args) == [('/**', 'alpha', '0.3'), ('/**', 'human_odom_topic', "''"),
                                 ('planner', 'alpha', '0.25'), ('trust_monitor', 'alpha', '0.9'),
                                 ('/**', 'autostart', 'false')]
    assert command_line_values(args, '/planner') == {'alpha': 0.25, 'human_odom_topic': '',
                                                     'autostart': False}
    assert command_line_values(args, '/car1/planner') == {'alpha': 0.3, 'human_odom_topic': '',
                                                          'autostart': False}
