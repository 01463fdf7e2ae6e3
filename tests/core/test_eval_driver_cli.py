"""``trust-av eval-driver`` and ``trust-av fit-driver`` on small synthetic CSVs (tmp_path)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml
from support.synthetic_car_following import write_ngsim_chain, write_openacc

from human_driver_sim.fitting import MPC_BOUNDS
from trust_av.cli.main import main

MODELS = ('driver MPC (params file)', 'driver MPC, cautious (human_cautious.yaml)',
          'IDM, bounded fit', 'IDM, textbook motorway',
          'constant speed', 'recorded speed (noise floor)')


def test_eval_driver_openacc_table_and_json(tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    data = tmp_path / 'openacc'
    data.mkdir()
    write_openacc(data / 'trip_part1.csv', splice_at_s=60.0)
    (data / 'specs.csv').write_text('Vehicles,Max power (kW)\nA,1\n')   # not a data table
    out = tmp_path / 'scores.json'
    assert main(['eval-driver', '--data', str(data), '--json', str(out)]) == 0
    text = capsys.readouterr().out
    assert '1 files, 2 pairs (3 segments); splices cut: 1' in text
    for protocol in ('protocol: full (2 pairs', 'protocol: window (2 pairs'):
        assert protocol in text
    for model in MODELS:
        assert text.count(f'| {model} |') == 2
    scores = json.loads(out.read_text())
    assert set(scores['window']) == set(MODELS)
    pooled = scores['window']['recorded speed (noise floor)']['pooled']
    assert pooled['gap_nrmse'] < 0.05 and pooled['collisions'] == 0
    assert set(scores['full']['constant speed']['per_pair']) == {'trip_part1:1->2',
                                                                 'trip_part1:2->3'}


def test_eval_driver_ngsim(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    write_ngsim_chain(tmp_path / 'a.csv', [1, 2, 3, 4])
    write_ngsim_chain(tmp_path / 'b.csv', [2, 3, 4, 5], start_s=4.0)
    assert main(['eval-driver', '--data', str(tmp_path), '--format', 'ngsim']) == 0
    text = capsys.readouterr().out
    assert '2 files, 4 pairs (4 segments)' in text and 'repeated windows merged: 2' in text


@pytest.mark.parametrize('case', ['missing', 'wrong_format', 'bad_fit', 'bad_window'])
def test_eval_driver_bad_input_one_line_exit_2(tmp_path: Path, case: str,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    write_ngsim_chain(tmp_path / 'a.csv', [1, 2, 3])
    args = ['eval-driver', '--data', str(tmp_path)]
    expected = {'missing': 'absent: not a directory', 'wrong_format': 'no OpenACC file',
                'bad_fit': 'fit.yaml: idm must hold', 'bad_window': '--window-s must be > 0'}
    if case == 'missing':
        args[2] = str(tmp_path / 'absent')
    elif case == 'wrong_format':
        args += ['--format', 'openacc']
    elif case == 'bad_fit':
        (tmp_path / 'fit.yaml').write_text('idm: {min_gap_m: -1}\n')
        args += ['--driver-fit', str(tmp_path / 'fit.yaml')]
    else:
        args += ['--window-s', '0']
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and expected[case] in err, err


def test_fit_driver_writes_fit_and_evaluation(tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    openacc, ngsim = tmp_path / 'openacc', tmp_path / 'ngsim'
    openacc.mkdir()
    ngsim.mkdir()
    write_openacc(openacc / 'JRC-VC_280219_part2.csv', duration_s=70.0)
    write_openacc(openacc / 'JRC-VC_280219_part3.csv', duration_s=70.0)
    write_ngsim_chain(ngsim / 'a.csv', [1, 2, 3, 4, 5])
    out = tmp_path / 'fit' / 'driver_fit.yaml'
    assert main(['fit-driver', '--data', str(openacc), '--ngsim', str(ngsim), '--out', str(out),
                 '--iterations', '2', '--no-progress']) == 0
    fit = yaml.safe_load(out.read_text())
    for name, (lo, hi) in MPC_BOUNDS.items():
        assert lo <= fit['pooled'][name] <= hi
    assert fit['pooled']['weight_acceleration'] == 1.0
    assert 0.0 <= fit['pooled']['av_extra_decel_mps2'] <= 3.0
    # Selected on validation: the candidate with the lowest validation loss.
    candidates = ('MPC cautious (human_cautious.yaml)', 'MPC fitted caution',
                  'MPC fitted caution, a_extra = 0')
    assert fit['selected'] == min(candidates, key=lambda m: fit['validation_loss'][m]['mean'])
    assert fit['pooled']['cautious'] == (fit['selected'] == candidates[0])
    assert set(fit['fits']) == {'MPC fitted caution',
                                'driver JRC-VC_280219:Car2', 'driver JRC-VC_280219:Car3'}
    assert set(fit['per_driver']) == {'JRC-VC_280219:Car2', 'JRC-VC_280219:Car3'}
    assert fit['idm']['comfort_decel_mps2'] <= 4.0 and fit['idm']['min_gap_m'] >= 1.0
    assert len(fit['per_pair_inverse_kkt']) == 2
    evaluation = json.loads((tmp_path / 'fit' / 'driver_fit_eval.json').read_text())
    assert set(evaluation['target']) == {'openacc test', 'ngsim test'}
    assert set(evaluation['sets']) == {'openacc test', 'ngsim test'}
    # The three NGSIM roles hold disjoint followers: 4 trains, 2 validates, 3 and 5 test.
    roles = evaluation['split_pairs']['ngsim']
    assert [len(roles[r]) for r in ('train', 'validation', 'test')] == [1, 1, 2]
    assert roles['train'][0].endswith('->4') and roles['validation'][0].endswith('->2')
    target = evaluation['target']['ngsim test']['window']
    assert target['paired_difference']['pairs'] == 2
    assert 'target openacc test window' in capsys.readouterr().out
