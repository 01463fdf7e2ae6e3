"""A mistyped name gets a "did you mean" in one line, exit 2: a command, an option, an
option's value (the parser's choices), a component (the registry), a trace, a parameter or
a node section of a params file. A refused command line prints a one-line usage first."""

from __future__ import annotations

from pathlib import Path

import pytest

from trust_av.cli.main import main
from trust_av.cli.parser import suggest
from trust_av_common.errors import did_you_mean, with_suggestions


def refused(capsys: pytest.CaptureFixture[str], *argv: str) -> list[str]:
    """The stderr lines of ``trust-av argv``, which must exit 2."""
    try:
        code = main(list(argv))
    except SystemExit as stop:                   # argparse exits from parse_args
        code = int(stop.code or 0)
    assert code == 2
    return capsys.readouterr().err.splitlines()


@pytest.mark.parametrize(('argv', 'hint'), [
    (['simulate', '--predictor', 'gur'], "(did you mean 'gru'?)"),
    (['rnu'], "(did you mean 'run'?)"),
    (['simulate', '--alpah', '1'], "--alpah (did you mean '--alpha'?)"),
    (['reproduce', '--profile', 'as_reportd'], "(did you mean 'as_reported'?)"),
])
def test_a_mistyped_argument_is_usage_and_one_line(capsys: pytest.CaptureFixture[str],
                                                   argv: list[str], hint: str) -> None:
    usage, error = refused(capsys, *argv)
    assert usage.startswith('usage: trust-av') and '--help' in usage
    assert ': error: ' in error and hint in error


def test_a_number_out_of_range_names_the_range(capsys: pytest.CaptureFixture[str]) -> None:
    _usage, error = refused(capsys, 'simulate', '--alpha', '-0.5')
    assert error == ('trust-av simulate: error: argument --alpha: alpha must be in [0, 1], '
                     'got -0.5')


@pytest.mark.parametrize(('argv', 'hint'), [
    (['simulate', '--trace', 'us6'], "us6: cannot open trace (No such file or directory) "
                                     "(did you mean 'us06'?)"),
    (['reproduce', '--predictors', 'gur'], "unknown predictor(s) gur (did you mean 'gru'?)"),
    (['reproduce', '--driver-models', 'imd'], "(did you mean 'idm'?)"),
])
def test_a_mistyped_name_is_one_line(capsys: pytest.CaptureFixture[str], argv: list[str],
                                     hint: str, tmp_path: Path) -> None:
    if argv[0] == 'reproduce':
        argv = [*argv, '--results-dir', str(tmp_path / 'r'), '--no-progress']
    (error,) = refused(capsys, *argv, '--max-steps', '2')
    assert hint in error


@pytest.mark.parametrize(('body', 'hint'), [
    ('/**/planner:\n  ros__parameters:\n    predictr: ca\n',
     "unknown parameter(s) predictr (did you mean 'predictor'"),
    ('/**/planner:\n  ros__parameters:\n    predictor: gur\n', "got 'gur' (did you mean 'gru'?)"),
    ('/**/plannr:\n  ros__parameters:\n    predictor: ca\n', "(did you mean 'planner'?)"),
])
def test_a_mistyped_params_file_name_is_one_line(capsys: pytest.CaptureFixture[str],
                                                 tmp_path: Path, body: str, hint: str) -> None:
    params = tmp_path / 'p.yaml'
    params.write_text(body)
    (error,) = refused(capsys, 'simulate', '--params-file', str(params), '--max-steps', '2')
    assert error.startswith(f'trust-av simulate: error: {params}: ') and hint in error


def test_nothing_close_suggests_nothing() -> None:
    assert did_you_mean('zzz', ['ca', 'cv', 'gru']) == ''
    assert with_suggestions(['gur', 'zzz'], ['gru']) == "gur (did you mean 'gru'?), zzz"
    assert suggest("argument --x: invalid choice: 'q' (choose from 'a', 'b')") == \
        "argument --x: invalid choice: 'q' (choose from 'a', 'b')"
