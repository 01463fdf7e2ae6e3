"""The params files: shipped values, layering over the shipped file by rcl's rules, sections
in any namespace, and every kind of bad value rejected with its name."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
from support.paths import REPO

from trust_av.cli.reference import parameters_markdown
from trust_av.system.config import (
    DEFAULT_PARAMS_FILE,
    NODE_COMPONENTS,
    all_components,
    load_run_config,
)
from trust_av_common.param_layers import (
    layered_params,
    read_layer,
    text_layer,
    to_params_text,
)
from trust_av_common.params import CONTROL_STEP_RANGE_S, ParamsError
from trust_av_common.rcl_yaml import parse_params_text


def write(tmp_path: Path, text: str, name: str = 'p.yaml') -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_packaged_params_file_is_the_repository_one() -> None:
    assert DEFAULT_PARAMS_FILE.resolve() == (REPO / 'config' / 'trust_av.yaml').resolve()


def test_shipped_values_are_table_one(run_config) -> None:
    p = run_config.planner
    assert (p.horizon_steps, p.dt_s, p.accel_min_mps2, p.accel_max_mps2) == (3, 1.0, -3.0, 3.0)
    assert (p.gap_min_m, p.gap_max_m, p.standstill_gap_m, p.time_headway_s) == (5, 60, 5, 1.2)
    assert (p.trust_min, run_config.trust.epsilon_mps2) == (0.0, 6.0)
    assert run_config.trust.trust_growth_rate == 0.1
    assert run_config.trust.performance_threshold == 0.8


def test_shipped_file_names_every_parameter_of_the_graph_once() -> None:
    """The nodes accept a key they do not declare only if the shipped file holds it (a /**
    key for another node); trust-av accepts a /** key of any component. Both lists agree on
    every node's own parameters; a registered component's parameters (all with defaults)
    are declared by the node that runs it and need not be in the shipped file."""
    names = {name for values in read_layer(DEFAULT_PARAMS_FILE).values() for name in values}
    base = {f.name for comps in NODE_COMPONENTS.values() for cls in comps
            for f in dataclasses.fields(cls)}
    every = {f.name for cls in all_components() for f in dataclasses.fields(cls)}
    assert base <= names <= every, (base - names, names - every)


@pytest.mark.parametrize(('node', 'values', 'message'), [
    ('/**', {'horizon_steps': -3}, r'horizon_steps must be in \[1, 50\]'),
    ('planner', {'alpha': 1.5}, r'alpha must be in \[0, 1\]'),
    ('planner', {'gap_min_m': 70.0}, r'gap_min_m < gap_max_m'),
    ('planner', {'predictor': 'lstm'}, r"predictor must be one of .*'lstm'"),
    ('planner', {'alpha': 'high'}, r'parameter alpha: expected a number'),
    ('planner', {'alhpa': 0.5}, r'unknown parameter\(s\) alhpa'),
    ('/**', {'alhpa': 0.5}, r'command-line options: section /\*\*: unknown parameter\(s\) '
                            r'alhpa'),     # a typo on the command line, even for every node
    ('planner', {'horizon_steps': 3.0}, r'parameter horizon_steps: expected an integer'),
    ('/**', {'horizon_steps': 4.0}, r'horizon_steps = 4.0 would not reach .* rcl keeps the '
                                    r'integer written for it in an earlier file; write an '
                                    r'integer here'),
    ('human_driver', {'weight_relative_speed': -1.0},
     r'weight_relative_speed must be in \[0, 1e\+06\]'),
    ('nonsense_node', {'x': 1}, r"unknown node section '/nonsense_node'"),
    ('trust_monitor', {'performance_threshold': 1.0}, r'performance_threshold must be in'),
    ('planner', {'dt_s': 1e-9}, r'dt_s must be in \[0.01, 10\]'),
])
def test_bad_values_are_named(node: str, values: dict[str, object], message: str) -> None:
    with pytest.raises(ParamsError, match=message):
        load_run_config(DEFAULT_PARAMS_FILE, {node: values})


def test_unknown_names_of_wildcard_sections_are_ignored_with_a_line(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A shared bring-up file's /** section feeds other stacks' nodes too: names no node of
    the graph has are accepted with one warning line; in a section written for a node of the
    graph (any namespace) they are typos, refused with one line."""
    shared = tmp_path / 'bringup.yaml'
    shared.write_text('/**:\n  ros__parameters:\n    use_sim_time: false\n'
                      '    wheel_base: 2.79\n    alpha: 0.3\n'
                      '/**/planner:\n  ros__parameters:\n    alpha: 0.25\n')
    config = load_run_config(shared)
    line = (f'{shared}: section /**: ignoring use_sim_time, wheel_base (not a parameter of '
            'any node of the graph)')
    assert config.ignored == (line,) and config.planner.alpha == 0.25
    assert capsys.readouterr().err == f'warning: {line}\n'
    typo = tmp_path / 'typo.yaml'
    typo.write_text('/**/planner:\n  ros__parameters:\n    alhpa: 0.25\n')
    with pytest.raises(ParamsError, match=r'section /\*\*/planner: unknown parameter\(s\) '
                                          r"alhpa \(did you mean 'alpha'\?\)$"):
        load_run_config(typo)


def test_control_step_bounds_are_documented() -> None:
    assert CONTROL_STEP_RANGE_S == (0.01, 10.0)
    row = next(line for line in parameters_markdown().splitlines()
               if line.startswith('| `dt_s` |'))
    assert '| s | [0.01, 10] |' in row            # the generated parameter reference


def test_one_key_file_is_a_complete_configuration(tmp_path: Path) -> None:
    """The shipped file is always the bottom layer: a file may hold only what it changes."""
    one = write(tmp_path, 'preceding_traffic:\n  ros__parameters:\n    max_sample_gap_s: 3.0\n')
    config = load_run_config(one)
    assert config.trace.max_sample_gap_s == 3.0
    assert config == dataclasses.replace(load_run_config(), trace=config.trace)
    assert config.params_files == (DEFAULT_PARAMS_FILE, one)


def test_later_files_over_earlier_ones(tmp_path: Path) -> None:
    first = write(tmp_path, '/**/planner:\n  ros__parameters:\n    alpha: 0.25\n    '
                            'time_headway_s: 1.5\n', 'first.yaml')
    second = write(tmp_path, '/**/planner:\n  ros__parameters:\n    alpha: 0.75\n',
                   'second.yaml')
    config = load_run_config([first, second])
    assert (config.planner.alpha, config.planner.time_headway_s) == (0.75, 1.5)
    assert config.params_files == (DEFAULT_PARAMS_FILE, first, second)
    assert load_run_config([second, first]).planner.alpha == 0.25


def test_an_integer_for_a_double_is_the_double(tmp_path: Path) -> None:
    config = load_run_config(write(tmp_path, '/**:\n  ros__parameters:\n    dt_s: 2\n'))
    assert config.planner.dt_s == 2.0 and isinstance(config.planner.dt_s, float)


def test_sections_match_as_rclpy_matches_them(tmp_path: Path) -> None:
    """``planner`` is /planner only; /**/planner and car1/planner also match in /car1."""
    anywhere = write(tmp_path, to_params_text({
        (name if name.startswith('/') else f'/**/{name}'): values
        for name, values in read_layer(DEFAULT_PARAMS_FILE).items()}), 'anywhere.yaml')
    plain = write(tmp_path, 'planner:\n  ros__parameters:\n    alpha: 0.1\n', 'plain.yaml')
    car1 = write(tmp_path, 'car1/planner:\n  ros__parameters:\n    alpha: 0.9\n', 'car1.yaml')
    assert load_run_config([plain]).planner.alpha == 0.1
    assert load_run_config([anywhere, plain, car1], namespace='/car1').planner.alpha == 0.9
    assert load_run_config([anywhere, car1], namespace='/car2').planner.alpha == 0.5
    # The shipped file's node sections are /**/planner: plain.yaml's planner first appears
    # after them, so it is applied after them, in / only.
    assert load_run_config([anywhere, plain]).planner.alpha == 0.1
    assert load_run_config([anywhere, plain], namespace='/car1').planner.alpha == 0.5
    # a section that first appeared earlier still wins over a later /**: refused, as rcl
    # would silently keep the earlier value
    with pytest.raises(ParamsError, match=r'alpha = 0.3 would not reach /car1/planner'):
        load_run_config([write(tmp_path, '/**:\n  ros__parameters:\n    alpha: 0.3\n',
                               'wild.yaml')], namespace='/car1')


def test_a_later_value_rcl_would_drop_is_refused(tmp_path: Path) -> None:
    """rcl applies a section at its first appearance: a later /** loses against the shipped
    planner section. A node would silently keep 0.5; trust-av says so."""
    wildcard = write(tmp_path, '/**:\n  ros__parameters:\n    alpha: 0.3\n')
    with pytest.raises(ParamsError, match=r'alpha = 0.3 would not reach /planner, which would '
                                          r'get 0.5: .* e.g. /\*\*/planner'):
        load_run_config(wildcard)


def test_subnormal_doubles_cannot_be_written() -> None:
    with pytest.raises(ParamsError, match='subnormal'):
        to_params_text({'/planner': {'v': 5e-324}})


def test_layering_is_rcl_layering() -> None:
    """layered_params gives what rcl gives (params_for_node, held to the real parser by
    test_rcl_yaml_rules), and refuses only where the last writer would be overruled."""
    base = parse_params_text('/**:\n  ros__parameters:\n    a: 1.5\n    b: x\n'
                             'planner:\n  ros__parameters:\n    b: y\n', 'base')
    top = parse_params_text('/**/planner:\n  ros__parameters:\n    a: 2\n    b: z\n', 'top')
    assert layered_params([base, top], '/planner') == {'a': 2, 'b': 'z'}
    assert layered_params([base], '/car1/planner') == {'a': 1.5, 'b': 'x'}
    late = parse_params_text('/**:\n  ros__parameters:\n    b: w\n', 'late')
    with pytest.raises(ParamsError, match=r"late: parameter b = 'w' would not reach /planner"):
        layered_params([base, late], '/planner')
    assert layered_params([base, late], '/car1/planner')['b'] == 'w'


@pytest.mark.parametrize('value', ['1e3', 'inf', 'yes', '08', '010', 'null', '~', '', "it's",
                                   'planner: x', '0x1F', True, 3, -0.0, 1e300, 2.5, [1.0, 2.0],
                                   ['a', 'b'], 2.2250738585072014e-308])
def test_values_written_for_the_nodes_read_back_unchanged(value: object) -> None:
    """What the orchestrator writes for the nodes (to_params_text) rcl reads back with the
    same type and value: strings quoted, doubles that strtod (not strtoll) reads."""
    text = to_params_text({'/planner': {'v': value}})
    got = parse_params_text(text, 'x')['/planner']['v']
    assert type(got) is type(value)
    assert repr(got) == repr(value)
    assert text_layer({'/planner': {'v': value}}, 'x')['/planner']['v'] == got


@pytest.mark.parametrize(('text', 'message'), [
    ('planner: [\n', "line 1: key 'planner': rcl: Sequences can only be values"),
    ('planner:\n  alpha: 0.5\n', r"line 2: key 'planner/alpha': rcl: Cannot have a value "
                                  'before ros__parameters'),
    ('planner:\n  ros__parameters:\n    a: &a 0.5\n    alpha: *a\n', 'YAML alias'),
    ('planner:\n  ros__parameters:\n    alpha: [1, 2.0]\n', r"line 3: parameter 'alpha' .*"
                                                            'items of one list must have one '
                                                            'type'),
    ('planner:\n  ros__parameters:\n    alpha: []\n', 'has no value'),
    ('planner:\n  ros__parameters:\n    alpha: on\n', 'parameter alpha: expected a number, '
                                                      'got True'),
    ('plan-ner:\n  ros__parameters:\n    alpha: 0.5\n', "section 'plan-ner': rcl: node name"),
    ('planer:\n  ros__parameters:\n    alpha: 0.5\n', "unknown node section 'planer'"),
    ('planner:\n  ros__parameters:\n    alpha: "0.5\n', 'not valid YAML'),
])
def test_bad_params_files(tmp_path: Path, text: str, message: str) -> None:
    path = write(tmp_path, text)
    with pytest.raises(ParamsError, match=message) as info:
        load_run_config(path)
    assert str(path) in str(info.value) and '\n' not in str(info.value)


def test_unreadable_params_files(tmp_path: Path) -> None:
    with pytest.raises(ParamsError, match='cannot read params file'):
        load_run_config(tmp_path / 'missing.yaml')
    binary = tmp_path / 'binary.yaml'
    binary.write_bytes(b'\xff\xfe\x00planner')
    with pytest.raises(ParamsError, match='not UTF-8 text'):
        load_run_config(binary)
    with pytest.raises(ParamsError, match='cannot read params file'):
        load_run_config(tmp_path)
    with pytest.raises(ParamsError, match='not a regular file'):
        load_run_config('/dev/zero')


def test_yaml_errors_do_not_echo_the_file(tmp_path: Path) -> None:
    secret = write(tmp_path, 'planner:\n  ros__parameters:\n    alpha: "hunter2\n')
    with pytest.raises(ParamsError) as info:
        load_run_config(secret)
    assert 'hunter2' not in str(info.value)
