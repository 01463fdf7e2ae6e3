"""trust_av_common.rcl_yaml (rcl's parser through ctypes, rclpy's section matching in
Python) against a node started with the same files (the oracle: rcl through rclpy).

For each case of the corpus below, one subprocess (for the whole corpus) runs what a node
started with ``--ros-args --params-file F [--params-file G]`` runs: ``rclpy.init`` with those
arguments (rcl ``arguments.c: _rcl_parse_param_file`` -> ``rcl_yaml_param_parser``
``parser.c: rcl_parse_yaml_file``), then a node ``planner`` in ``/`` and one in ``/car1``
with ``automatically_declare_parameters_from_overrides=True`` (rclpy ``node.py``), and reads
each declared parameter's type and value, or records the error. The binding must agree
on accept/refuse (same line where rcl names one), on which node refuses, and on every typed
value, bit for bit: the guard that the ctypes struct layouts, the reading of
``rcl_variant_t`` in rclpy's slot order and the section matching are rclpy's.
"""

from __future__ import annotations

import json
import math
import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path
from typing import Any

import pytest

from trust_av_common.params import ParamsError
from trust_av_common.rcl_yaml import node_matches, params_for_node, parse_params_text

NODES = ('/planner', '/car1/planner')


def _f(text: str) -> str:
    return textwrap.dedent(text).lstrip('\n')


# case id -> the params files given in order (each one --params-file).
CORPUS: dict[str, list[str]] = {
    'plain_types': [_f("""
        planner:
          ros__parameters:
            dt_s: 0.1
            horizon_steps: 3
            use_gru: true
            trace: "us06"
            name: us06
        """)],
    'int_for_double': [_f("""
        planner:
          ros__parameters:
            dt_s: 1
            alpha: 1.0
            gap_min_m: 5.
        """)],
    'alias': [_f("""
        planner:
          ros__parameters:
            dt_s: &step 0.1
            trace_dt_s: *step
        """)],
    'anchor_without_alias': [_f("""
        planner:
          ros__parameters:
            dt_s: &step 0.1
        """)],
    'merge_key': [_f("""
        defaults: &d
          ros__parameters: {dt_s: 0.1}
        planner:
          <<: *d
        """)],
    'tags': [_f("""
        planner:
          ros__parameters:
            a: !!str 5
            b: !!float 1
            c: !custom y
            d: !!int "7"
            e: !!str true
        """)],
    'nested_maps': [_f("""
        planner:
          ros__parameters:
            solver:
              tol: 1.0e-6
              max_iter: 50
              ipopt:
                print_level: 0
            alpha: 0.5
        """)],
    'arrays': [_f("""
        planner:
          ros__parameters:
            ints: [1, 2, 3]
            doubles: [0.5, 1.5]
            strings: [a, "b", '1']
            bools: [true, no, on]
            block:
              - 1.0
              - 2.0
        """)],
    'array_int_then_double': [_f("""
        planner:
          ros__parameters:
            weights: [1, 2.5]
        """)],
    'array_int_then_string': [_f("""
        planner:
          ros__parameters:
            names: [1, a]
        """)],
    'nested_array_single': [_f("""
        planner:
          ros__parameters:
            grid: [[1, 2]]
        """)],
    'nested_array_two': [_f("""
        planner:
          ros__parameters:
            grid: [[1, 2], [3, 4]]
        """)],
    'array_of_maps': [_f("""
        planner:
          ros__parameters:
            points: [{x: 1}]
        """)],
    'empty_value': [_f("""
        planner:
          ros__parameters:
            dt_s:
            alpha: 0.5
        """)],
    'null_words': [_f("""
        planner:
          ros__parameters:
            a: null
            b: ~
            c: ""
            d: ''
        """)],
    'empty_array': [_f("""
        planner:
          ros__parameters:
            alpha: 0.5
            weights: []
        """)],
    'empty_map_last': [_f("""
        planner:
          ros__parameters:
            alpha: 0.5
            solver: {}
        """)],
    'empty_map_then_key': [_f("""
        planner:
          ros__parameters:
            solver: {}
            alpha: 0.5
        """)],
    'two_documents': [_f("""
        planner:
          ros__parameters:
            alpha: 0.5
        ---
        planner:
          ros__parameters:
            alpha: 0.75
            beta: 2
        """)],
    'top_level_sequence': ['- planner\n- ros__parameters\n'],
    'top_level_scalar': ['planner\n'],
    'empty_file': [''],
    'comment_only': ['# nothing here\n'],
    'missing_ros_parameters': [_f("""
        planner:
          dt_s: 0.1
        """)],
    'value_for_node': ['planner: 5\n'],
    'ros_parameters_prefix': [_f("""
        planner:
          ros__parameters_v2:
            alpha: 0.5
        """)],
    'ros_parameters_without_node': [_f("""
        ros__parameters:
          alpha: 0.5
        """)],
    'wildcard_then_node': [_f("""
        /**:
          ros__parameters:
            alpha: 0.1
            dt_s: 0.1
        planner:
          ros__parameters:
            alpha: 0.5
        """)],
    'node_then_wildcard': [_f("""
        planner:
          ros__parameters:
            alpha: 0.5
        /**:
          ros__parameters:
            alpha: 0.1
            dt_s: 0.1
        """)],
    'single_star': [_f("""
        /*:
          ros__parameters:
            alpha: 0.2
        """)],
    'any_ns_planner': [_f("""
        /**/planner:
          ros__parameters:
            alpha: 0.3
        """)],
    'one_ns_planner': [_f("""
        /*/planner:
          ros__parameters:
            alpha: 0.35
        """)],
    'fully_qualified': [_f("""
        /car1/planner:
          ros__parameters:
            alpha: 0.4
        /planner:
          ros__parameters:
            alpha: 0.45
        """)],
    'nested_namespace_keys': [_f("""
        car1:
          planner:
            ros__parameters:
              alpha: 0.6
        /**:
          planner:
            ros__parameters:
              beta: 1
        """)],
    'relative_ns_slash': [_f("""
        car1/planner:
          ros__parameters:
            alpha: 0.65
        """)],
    'bad_node_name': [_f("""
        plan-ner:
          ros__parameters:
            alpha: 0.5
        """)],
    'repeated_slash': [_f("""
        /car1//planner:
          ros__parameters:
            alpha: 0.5
        """)],
    'namespace_starts_with_digit': [_f("""
        /1car/planner:
          ros__parameters:
            alpha: 0.5
        """)],
    'numbers': [_f("""
        planner:
          ros__parameters:
            hex: 0x1F
            octal: 010
            not_octal: 08
            exp: 1e3
            plus: +5
            minus_zero: -0.0
            big_int: 9223372036854775808
            too_big: 1e400
            tiny: 1e-310
            hexfloat: 0x1p3
            binary: 0b101
            underscore: 1_000
            inf_word: inf
            nan_word: NaN
            yaml_inf: .inf
            yaml_ninf: -.Inf
            yaml_nan: .nan
            odd_nan: .Nan
            sexagesimal: 1:30
            quoted_number: "1.5"
        """)],
    'bool_words': [_f("""
        planner:
          ros__parameters:
            a: y
            b: n
            c: Yes
            d: off
            e: TRUE
            f: "true"
            g: tRUE
            h: !!str on
        """)],
    'block_scalars': [_f("""
        planner:
          ros__parameters:
            folded: >-
              5
            literal: |
              5
            keep: |-
              x
        """)],
    'sequence_as_key': ['? [a, b]\n: 1\n'],
    'dotted_then_nested': [_f("""
        planner:
          ros__parameters:
            solver.tol: 1.0
            solver:
              tol: 2.0
        """)],
    'dotted_nested_namespace': [_f("""
        planner:
          ros__parameters:
            a:
              b.c:
                d: 1
              e: 2
        """)],
    'duplicate_key_types': [_f("""
        planner:
          ros__parameters:
            alpha: 1
            alpha: 2.5
            name: x
            name: 7
        """)],
    'array_then_scalar': [_f("""
        planner:
          ros__parameters:
            w: [1.0, 2.0]
            w: 5
            v: 5
            v: [1, 2]
        """)],
    'bad_yaml': ['planner:\n  ros__parameters:\n    alpha: [0.5\n'],
    'tab_indent': ['planner:\n\tros__parameters:\n\t\talpha: 0.5\n'],
    'nul_in_string': [_f("""
        planner:
          ros__parameters:
            s: "ab\\0cd"
        """)],
    'empty_key': [_f("""
        planner:
          ros__parameters:
            "": 1
        """)],
    'layered_one_key': [
        _f("""
        /**:
          ros__parameters:
            dt_s: 1.0
            max_sample_gap_s: 2.0
        planner:
          ros__parameters:
            alpha: 0.5
        """),
        _f("""
        /**:
          ros__parameters:
            max_sample_gap_s: 5.0
        """)],
    'layered_order_of_first_appearance': [
        _f("""
        /**:
          ros__parameters:
            alpha: 0.1
        planner:
          ros__parameters:
            alpha: 0.2
        """),
        _f("""
        /**:
          ros__parameters:
            alpha: 0.9
        """)],
    'layered_node_then_wildcard': [
        _f("""
        planner:
          ros__parameters:
            alpha: 0.2
        """),
        _f("""
        /**:
          ros__parameters:
            alpha: 0.9
        """)],
    'layered_int_survives_double': [
        _f("""
        planner:
          ros__parameters:
            dt_s: 1
        """),
        _f("""
        planner:
          ros__parameters:
            dt_s: 0.5
        """)],
    'layered_double_then_int': [
        _f("""
        planner:
          ros__parameters:
            dt_s: 0.5
            name: abc
        """),
        _f("""
        planner:
          ros__parameters:
            dt_s: 2
            name: 7
        """)],
    'layered_scalar_becomes_map': [
        _f("""
        planner:
          ros__parameters:
            solver: 5
        """),
        _f("""
        planner:
          ros__parameters:
            solver:
              name: ipopt
        """)],
    'layered_second_refused': [
        _f("""
        planner:
          ros__parameters:
            alpha: 0.5
        """),
        _f("""
        planner:
          ros__parameters:
            alpha: *nothing
        """)],
}

_ORACLE = r"""
import json, sys
import rclpy
from rclpy.context import Context
from rclpy.exceptions import ParameterUninitializedException
from rclpy.node import Node

def run(files):
    ctx = Context()
    args = ['--ros-args']
    for f in files:
        args += ['--params-file', f]
    try:
        rclpy.init(args=args, context=ctx)
    except Exception as err:
        return {'error': f'{type(err).__name__}: {err}'}
    nodes = {}
    try:
        for ns, fqn in (('/', '/planner'), ('/car1', '/car1/planner')):
            try:
                node = Node('planner', namespace=ns, context=ctx, enable_rosout=False,
                            start_parameter_services=False,
                            automatically_declare_parameters_from_overrides=True)
            except Exception as err:
                nodes[fqn] = {'node_error': f'{type(err).__name__}: {err}'}
                continue
            try:
                values = {}
                for name in node.list_parameters([], 0).names:
                    try:
                        p = node.get_parameter(name)
                        values[name] = [p.type_.name, p.value]
                    except ParameterUninitializedException:
                        values[name] = ['NOT_SET', None]
                assert node.get_fully_qualified_name() == fqn
                nodes[fqn] = {'params': values}
            finally:
                node.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)
    return {'nodes': nodes}

cases = json.loads(sys.stdin.read())
out = {case: run(files) for case, files in cases.items()}
print('ORACLE-JSON ' + json.dumps(out))
"""


@pytest.fixture(scope='module')
def oracle(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """What rcl/rclpy make of every case (one subprocess for the whole corpus)."""
    folder = tmp_path_factory.mktemp('rcl_corpus')
    cases: dict[str, list[str]] = {}
    for case, texts in CORPUS.items():
        paths = []
        for index, text in enumerate(texts):
            path = folder / f'{case}_{index}.yaml'
            path.write_text(text)
            paths.append(str(path))
        cases[case] = paths
    baseline = folder / 'baseline.yaml'
    baseline.write_text('')
    cases['__baseline__'] = [str(baseline)]
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE='OFF', ROS_DOMAIN_ID='0')
    done = subprocess.run([sys.executable, '-c', _ORACLE], input=json.dumps(cases), env=env,
                          capture_output=True, text=True, timeout=120, check=False)
    lines = [line for line in done.stdout.splitlines() if line.startswith('ORACLE-JSON ')]
    assert done.returncode == 0 and lines, done.stderr[-2000:]
    result: dict[str, Any] = json.loads(lines[-1][len('ORACLE-JSON '):])
    result['__paths__'] = cases
    return result


def _canon(value: Any) -> Any:
    """A value with its rclpy type, floats as exact hex (NaN as 'nan')."""
    if isinstance(value, bool):
        return ['BOOL', value]
    if isinstance(value, int):
        return ['INTEGER', value]
    if isinstance(value, float):
        return ['DOUBLE', 'nan' if math.isnan(value) else value.hex()]
    if isinstance(value, str):
        return ['STRING', value]
    if isinstance(value, list):
        kind = {bool: 'BOOL', int: 'INTEGER', float: 'DOUBLE', str: 'STRING'}[type(value[0])]
        return [f'{kind}_ARRAY', [_canon(item)[1] for item in value]]
    raise AssertionError(f'unexpected value {value!r}')


def _canon_oracle(type_name: str, value: Any) -> Any:
    if type_name == 'DOUBLE':
        return [type_name, 'nan' if math.isnan(value) else float(value).hex()]
    if type_name == 'DOUBLE_ARRAY':
        return [type_name, [float(item).hex() for item in value]]
    return [type_name, value]


def test_corpus_is_big_enough() -> None:
    assert len(CORPUS) >= 30
    assert sum(len(files) > 1 for files in CORPUS.values()) >= 5


@pytest.mark.parametrize('case', sorted(CORPUS))
def test_binding_agrees_with_rclpy(case: str, oracle: dict[str, Any]) -> None:
    expected = oracle[case]
    paths = oracle['__paths__'][case]
    builtins = set(oracle['__baseline__']['nodes']['/planner']['params'])
    parsed = []
    try:
        for path, text in zip(paths, CORPUS[case], strict=True):
            parsed.append(parse_params_text(text, path))
    except ParamsError as err:
        message = str(err)
        assert 'error' in expected, f'rclpy accepts {case}, the binding refuses: {message}'
        assert '\n' not in message and message.startswith(path)
        rcl_line = re.search(r'at line(?:_num)? (\d+)', expected['error'])
        if rcl_line:
            assert f'line {rcl_line.group(1)}:' in message, (message, expected['error'])
        return
    assert 'error' not in expected, (f'rclpy refuses {case} ({expected["error"]}); the '
                                     'binding accepts')
    for fqn in NODES:
        got = expected['nodes'][fqn]
        if 'node_error' in got:
            with pytest.raises(ParamsError):
                params_for_node(parsed, fqn)
            continue
        want = {name: _canon_oracle(*typed) for name, typed in got['params'].items()
                if name not in builtins}
        mine = {name: _canon(value) for name, value in params_for_node(parsed, fqn).items()}
        assert mine == want, fqn


@pytest.mark.parametrize(('pattern', 'fqn', 'matches'), [
    ('/**', '/planner', True), ('/**', '/car1/planner', True),
    ('/*', '/planner', True), ('/*', '/car1/planner', False),
    ('/**/planner', '/planner', True), ('/**/planner', '/a/b/planner', True),
    ('/**/planner', '/car1/monitor', False), ('/*/planner', '/planner', False),
    ('planner', '/planner', True), ('planner', '/car1/planner', False),
    ('/car1/planner', '/car1/planner', True), ('car1/planner', '/car1/planner', True),
    ('/car1/*', '/car1/planner', True), ('/car1/**', '/car1/x/planner', True),
])
def test_node_matches(pattern: str, fqn: str, matches: bool) -> None:
    """rclpy node.cpp _populate_node_parameters_from_rcl_params: '/*' -> '(/\\w+)'."""
    assert node_matches(pattern, fqn) is matches


def test_messages_name_the_key_not_the_content(tmp_path: Path) -> None:
    secret = 'hunter2-secret-value'
    text = f'planner:\n  ros__parameters:\n    alpha: [1, {secret}]\n'
    with pytest.raises(ParamsError) as caught:
        parse_params_text(text, 'f.yaml')
    message = str(caught.value)
    assert secret not in message and "'alpha'" in message and 'line 3' in message


def test_command_line_p_wins_over_a_section_written_for_the_node(ros_domain: str) -> None:
    """rcl keeps an unprefixed ``-p`` in the ``/**`` section of the structure the params files
    are read into (``ros2/rcl``, ``rcl/src/rcl/arguments.c: _rcl_parse_param_rule``:
    ``rcl_parse_yaml_value("/**", ...)``) and rclpy applies sections in order of first
    appearance, so the shipped file's ``/**/planner`` beats ``-p``, before it or after it:
    the overrides rclpy gives the node keep the file's values. The nodes' overrides
    (``node_overrides``: what ``declare_config`` reads) put the command line's ``-p`` last."""
    import rclpy

    from trust_av_common.param_layers import shipped_params_file
    from trust_av_common.ros.parameters import node_overrides, use_command_line

    shipped = str(shipped_params_file())
    for args in (['planner', '--ros-args', '--params-file', shipped, '-p',
                  'lead_preview:=constant_speed', '-p', 'autostart:=false'],
                 ['planner', '--ros-args', '-p', 'lead_preview:=constant_speed', '-p',
                  'autostart:=false', '--params-file', shipped]):
        context = rclpy.Context()
        rclpy.init(args=args, context=context, domain_id=int(ros_domain))
        node = rclpy.create_node('planner', context=context, start_parameter_services=False)
        try:
            rcl = {name: p.value for name, p in node._parameter_overrides.items()}
            assert (rcl['lead_preview'], rcl['autostart']) == ('recorded', True)
            use_command_line(args)
            ours = node_overrides(node)
            assert (ours['lead_preview'], ours['autostart']) == ('constant_speed', False)
            assert ours['dt_s'] == rcl['dt_s']          # the rest as rcl gave it
        finally:
            use_command_line([])
            node.destroy_node()
            rclpy.shutdown(context=context)
