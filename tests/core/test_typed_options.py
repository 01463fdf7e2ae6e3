"""Each ``trust-av`` command reads a frozen, typed options dataclass that is the one
declaration its parser is built from, and is built from argparse's namespace
(trust_av.cli.typed_options): every option the parser defines is a field of the command's
options, every field is an option of the parser, a field without a declaration or an option
added outside the builder is refused, and a value of the wrong type is refused where the
namespace becomes options."""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import pytest

from trust_av.cli import (
    bags,
    compare,
    design,
    drive,
    eval_driver,
    fit_driver,
    fit_trust,
    repair_bag,
    reproduce,
    run,
    shadow,
    simulate,
    train_gru,
    typed_options,
)
from trust_av.cli.main import build_parser
from trust_av.cli.options import RunOptions
from trust_av.cli.typed_options import options_from

COMMANDS: dict[str, tuple[type, list[str]]] = {
    'simulate': (simulate.SimulateOptions, []),
    'run': (run.GraphRunOptions, []),
    'shadow': (shadow.ShadowOptions, ['--bag', 'b', '--out', 'o']),
    'drive': (drive.DriveOptions, ['--study', 's', '--participant', 'p']),
    'reproduce': (reproduce.ReproduceOptions, []),
    'trace-to-bag': (bags.TraceToBagOptions, ['us06', 'out']),
    'repair-bag': (repair_bag.RepairBagOptions, ['bag']),
    'train-gru': (train_gru.TrainGruOptions, []),
    'fit-driver': (fit_driver.FitDriverOptions, ['--data', 'd']),
    'eval-driver': (eval_driver.EvalDriverOptions, ['--data', 'd']),
    'fit-trust': (fit_trust.FitTrustOptions, ['--ratings', 'r.csv', '--out', 'o']),
    'compare': (compare.CompareOptions, ['a', 'b', '--out', 'f.png']),
    'design-evaluate': (design.DesignOptions, []),
    'design-power': (design.DesignOptions, []),
    'design-propose': (design.ProposeOptions, ['--budget-min', '60']),
}
NOT_OPTIONS = {'help', 'func', 'command', 'verbose', 'params_file', 'params_files'}
"""Namespace entries that are no command's own option: argparse's and main's, and the
params file option, whose two entries a command reads one of."""


def subparsers() -> dict[str, argparse.ArgumentParser]:
    parser = build_parser()
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(action.choices)


def test_every_command_has_typed_options() -> None:
    assert set(COMMANDS) == set(subparsers())


@pytest.mark.parametrize('name', sorted(COMMANDS))
def test_options_are_the_parsers_options(name: str) -> None:
    kind, argv = COMMANDS[name]
    namespace = build_parser().parse_args(['-v', name, *argv])
    options: object = options_from(kind, namespace)
    assert dataclasses.is_dataclass(options)
    with pytest.raises(dataclasses.FrozenInstanceError):
        setattr(options, dataclasses.fields(options)[0].name, None)
    fields = {f.name for f in dataclasses.fields(kind)}
    dests = {a.dest for a in subparsers()[name]._actions} - NOT_OPTIONS
    assert dests <= fields, f'{name}: options the command never reads: {dests - fields}'
    assert fields - NOT_OPTIONS - {'verbose'} <= dests, fields - dests


def test_lists_become_tuples_and_types_are_checked() -> None:
    namespace = build_parser().parse_args(['simulate', '--params-file', 'a.yaml',
                                           '--params-file', 'b.yaml', '--alpha', '0.25'])
    options = options_from(simulate.SimulateOptions, namespace)
    assert options.params_files == (Path('a.yaml'), Path('b.yaml'))
    assert options.alpha == 0.25 and options.max_steps == 0
    assert options.overrides()['planner'] == {'alpha': 0.25}
    namespace.max_steps = '3'               # a parser whose type= was forgotten
    with pytest.raises(TypeError, match=r'SimulateOptions.max_steps: .3. is not'):
        options_from(simulate.SimulateOptions, namespace)
    namespace.max_steps = True
    with pytest.raises(TypeError, match='max_steps'):
        options_from(simulate.SimulateOptions, namespace)
    del namespace.max_steps
    with pytest.raises(TypeError, match='sets no such option'):
        options_from(simulate.SimulateOptions, namespace)


def test_run_overrides_name_each_section() -> None:
    namespace = build_parser().parse_args(['simulate', '--bag-in', 'x', '--bag-topic', '/t',
                                           '--driver-model', 'idm', '--lead-preview',
                                           'recorded'])
    options = options_from(RunOptions, namespace)
    assert options.overrides() == {
        'planner': {'lead_preview': 'recorded'},
        'preceding_traffic': {'trace': 'x', 'bag_topic': '/t'},
        'human_driver': {'driver_model': 'idm'}}


def test_fit_trust_takes_one_source() -> None:
    with pytest.raises(TypeError, match='one of them'):
        fit_trust.FitTrustOptions(params_files=(), study=None, ratings=None, out=Path('o'),
                                  models='', rating_scale='0-100', no_figures=False,
                                  no_partial_pooling=False, workers=None, ray_address=None)


_SIDE = typed_options.Exclusive('side')


@dataclasses.dataclass(frozen=True)
class _Declared:
    """Every kind of declaration the builder knows."""

    source: Path = typed_options.positional(metavar='SRC', help='a source')
    out: Path | None = typed_options.option('--out', default=None, help='an output')
    count: int = typed_options.option('--count', default=2, help=lambda: 'built %(default)s')
    fast: bool = typed_options.option('--fast', help='be fast')
    left: str | None = typed_options.option('--left', exclusive=_SIDE, also_sets={'extra': 1})
    right: str | None = typed_options.option('--right', exclusive=_SIDE)


def test_the_parser_is_built_from_the_fields() -> None:
    parser = argparse.ArgumentParser(prog='p')
    typed_options.add_command(parser, _Declared, lambda options: 0)
    typed_options.check_parser(parser)
    assert [a.dest for a in parser._actions] == ['help', 'source', 'out', 'count', 'fast',
                                                  'left', 'right']
    namespace = parser.parse_args(['s', '--count', '5', '--fast', '--left', 'x'])
    assert options_from(_Declared, namespace) == _Declared(
        source=Path('s'), out=None, count=5, fast=True, left='x', right=None)
    assert namespace.extra == 1 and 'built 2' in parser.format_help()
    with pytest.raises(SystemExit):           # the exclusive group
        parser.parse_args(['s', '--left', 'x', '--right', 'y'])


def test_a_field_without_a_declaration_is_refused() -> None:
    @dataclasses.dataclass(frozen=True)
    class Undeclared(_Declared):
        forgotten: int

    with pytest.raises(TypeError, match=r'Undeclared.forgotten: no option declared'):
        typed_options.add_options(argparse.ArgumentParser(), Undeclared)


def test_a_flag_that_names_another_field_is_refused() -> None:
    @dataclasses.dataclass(frozen=True)
    class Renamed:
        out: Path = typed_options.option('--output')

    with pytest.raises(TypeError, match=r"--output sets 'output', not the field"):
        typed_options.add_options(argparse.ArgumentParser(), Renamed)


def test_an_option_added_outside_the_builder_is_caught() -> None:
    parser = argparse.ArgumentParser(prog='p')
    typed_options.add_command(parser, _Declared, lambda options: 0)
    parser.add_argument('--stray')
    with pytest.raises(TypeError, match='p: --stray is no field of _Declared'):
        typed_options.check_parser(parser)



def test_every_command_parser_is_its_options() -> None:
    for parser in subparsers().values():
        typed_options.check_parser(parser)
