"""Two runs side by side: ``trust-av compare`` and :func:`compare_runs` read a simulate CSV
and a graph recording alike, replay every trust model over each run's E, and refuse bad
input with one line and exit 2."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from support.cli import Ran, trust_av_run
from support.graph import STEPS
from support.paths import REPO

from trust_av.study.compare_runs import compare_runs, read_run, trust_per_model
from trust_av.system.config import load_run_config
from trust_monitor.model_interface import COMMON_SCALE

PNG = b'\x89PNG\r\n\x1a\n'


def trust_av(*args: str) -> Ran:
    """``trust-av ARGS`` in-process (support.cli): no interpreter start per command."""
    return trust_av_run(*args)


@pytest.fixture(scope='module')
def runs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, Path]:
    """A stop-and-go trace and its runs at alpha 0 and 1 (simulate CSVs)."""
    folder = tmp_path_factory.mktemp('runs')
    trace = folder / 'stop_go.csv'
    speeds = [min(t, 12) if t < 25 else max(12 - 2 * (t - 25), 0) for t in range(40)]
    trace.write_text('time_s,speed_mps\n' + '\n'.join(f'{t},{v}' for t, v in
                                                      enumerate(speeds)) + '\n')
    out = []
    for alpha in ('0', '1'):
        path = folder / f'alpha{alpha}.csv'
        proc = trust_av('simulate', '--trace', str(trace), '--alpha', alpha, '--out', str(path))
        assert proc.returncode == 0, proc.stderr
        out.append(path)
    return trace, out[0], out[1]


def test_python_call_draws_both_and_returns_final_trust(runs: tuple[Path, Path, Path],
                                                       tmp_path: Path) -> None:
    _, a, b = runs
    figure = tmp_path / 'side.png'
    final = compare_runs(a, b, figure, models=['paper', 'optimo'], labels=['unaware', 'aware'])
    assert figure.read_bytes()[:8] == PNG
    assert set(final) == {'unaware', 'aware'}
    assert set(final['aware']) == {'paper', 'optimo'}
    assert all(0.0 <= v <= 1.0 for models in final.values() for v in models.values())


def test_the_replayed_paper_model_is_the_recorded_trust(runs: tuple[Path, Path, Path]) -> None:
    """The run ran the shipped paper model: replayed over its E it gives the recorded trust,
    mapped to the common scale by the model's trust_range."""
    import pandas as pd

    _, a, _ = runs
    recorded = pd.read_csv(a).trust.to_numpy()
    replayed = trust_per_model(read_run(a), ['paper'])['paper']
    model = load_run_config([]).trust_model()
    low, high = getattr(model, 'trust_range', COMMON_SCALE)
    np.testing.assert_allclose(replayed, np.clip((recorded - low) / (high - low), 0, 1),
                               atol=1e-9)


def test_cli_prints_each_runs_final_trust(runs: tuple[Path, Path, Path],
                                          tmp_path: Path) -> None:
    _, a, b = runs
    figure = tmp_path / 'out' / 'side.svg'
    proc = trust_av('compare', str(a), str(b), '--out', str(figure), '--trust-models',
                    'paper,beta_bernoulli')
    assert proc.returncode == 0, proc.stderr
    assert figure.read_text().lstrip().startswith('<?xml')
    lines = proc.stdout.splitlines()
    assert lines[0].startswith('alpha0.csv: final trust (common scale) paper ')
    assert 'beta_bernoulli' in lines[1] and lines[-1] == f'figure: {figure}'


@pytest.mark.parametrize(('args', 'message'), [
    (('MISSING', 'B', '--out', 'x.png'), 'MISSING: no such file or directory'),
    (('A', 'B', '--out', 'x.txt'), 'x.txt: the figure must end in one of .png, .pdf, .svg'),
    (('A', 'B', '--out', 'x.png', '--trust-models', 'papr'), "did you mean 'paper'?"),
    (('A', 'TRACE', '--out', 'x.png'), 'missing column(s) t_s'),
    (('A', 'B', '--out', 'x.png', '--labels', 'one'), "'one': give two names"),
])
def test_bad_input_is_one_line_and_exit_2(runs: tuple[Path, Path, Path], tmp_path: Path,
                                          args: tuple[str, ...], message: str,
                                          monkeypatch: pytest.MonkeyPatch) -> None:
    trace, a, b = runs
    paths = {'A': str(a), 'B': str(b), 'TRACE': str(trace)}
    monkeypatch.chdir(tmp_path)
    proc = trust_av('compare', *(paths.get(x, x) for x in args))
    assert proc.returncode == 2
    assert message in proc.stderr and len(proc.stderr.strip().splitlines()) <= 2
    assert not (tmp_path / 'x.png').exists()


def _edited(source: Path, target: Path, edit: str) -> Path:
    """``source`` (a simulate CSV) with one defect, or as a spreadsheet exports it."""
    lines = source.read_text().splitlines()
    header = lines[0].split(',')
    if edit == 'nan':
        row = lines[4].split(',')
        row[header.index('av_gap_m')] = 'nan'
        lines[4] = ','.join(row)
    elif edit == 'twice':
        lines.insert(4, lines[3])
    elif edit == 'header only':
        lines = lines[:1]
    elif edit == 'empty cell':
        row = lines[2].split(',')
        row[header.index('explicability')] = ''
        lines[2] = ','.join(row)
    text = '\n'.join(lines) + '\n'
    if edit == 'spreadsheet':       # Excel's "CSV UTF-8" where the decimal sign is a comma
        text = '\ufeff' + '\n'.join(';'.join(cell.replace('.', ',') if _number(cell) else cell
                                              for cell in line.split(','))
                                     for line in lines) + '\n'
    target.write_text(text, encoding='utf-8')
    return target


def _number(cell: str) -> bool:
    try:
        float(cell)
    except ValueError:
        return False
    return True


@pytest.mark.parametrize(('edit', 'message'), [
    ('nan', ":5: column av_gap_m: not finite: 'nan'"),
    ('twice', ':5: column t_s: 2 s is not after the row before (2 s): rows out of order, '
              'or one given twice?'),
    ('header only', ': no rows, only the header'),
    ('empty cell', ':3: column explicability is empty'),
])
def test_a_simulate_table_is_checked_like_every_input_table(
        runs: tuple[Path, Path, Path], tmp_path: Path, edit: str, message: str) -> None:
    """A run's table names the file, the line and the column of what is wrong with it, and
    nothing is drawn."""
    _, a, b = runs
    bad = _edited(a, tmp_path / 'bad.csv', edit)
    proc = trust_av('compare', str(bad), str(b), '--out', str(tmp_path / 'x.png'))
    assert proc.returncode == 2, proc.stdout
    assert proc.stderr == f'trust-av compare: error: {bad}{message}\n'
    assert not (tmp_path / 'x.png').exists()


def test_a_spreadsheet_export_of_a_simulate_table_reads_the_same(
        runs: tuple[Path, Path, Path], tmp_path: Path) -> None:
    """A byte-order mark, semicolons and decimal commas (a spreadsheet's export) read as the
    table they came from."""
    _, a, _ = runs
    exported = read_run(_edited(a, tmp_path / 'exported.csv', 'spreadsheet'))
    original = read_run(a)
    assert np.array_equal(exported.t_s, original.t_s)
    assert all(np.array_equal(exported.values[k], original.values[k]) for k in original.values)


def test_help_names_what_a_run_is() -> None:
    proc = trust_av('compare', '--help')
    assert proc.returncode == 0
    text = ' '.join(proc.stdout.split())
    assert 'rosbag2 recording' in text and 'simulate --out' in text and '--trust-models' in text


def test_a_graph_recording_compares_with_its_simulated_run(us06_graph_run: tuple[Path, str],
                                                           tmp_path: Path) -> None:
    """The same case through the node graph (the suite's shared US06 run, a bag) and
    in-process (``trust-av simulate``, a CSV): the bag reads as a run, and every model's
    replayed trust is the same on both."""
    bag, _ = us06_graph_run
    simulated = tmp_path / 'us06.csv'
    proc = trust_av('simulate', '--trace', 'us06', '--alpha', '0.5', '--predictor', 'ca',
                    '--max-steps', str(STEPS), '--no-progress', '--out', str(simulated))
    assert proc.returncode == 0, proc.stderr
    from_bag = read_run(bag)
    assert len(from_bag.t_s) == STEPS
    short = read_run(simulated)
    for name, series in trust_per_model(from_bag, ['paper', 'optimo']).items():
        np.testing.assert_allclose(series, trust_per_model(short, [name])[name][:STEPS],
                                   atol=1e-6)
    figure = tmp_path / 'graph_vs_sim.png'
    mcap = next(bag.glob('*.mcap'))                       # the file names the run too
    proc = trust_av('compare', str(mcap), str(simulated), '--out', str(figure))
    assert proc.returncode == 0, proc.stderr
    assert figure.read_bytes()[:8] == PNG


def test_a_drive_recording_reads_at_the_plan_times(tmp_path: Path,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """A trust-av drive bag (recognised by its start time in custom_data): odometry read at
    each plan's time, gaps bumper to bumper, the AV's first planned acceleration, E from the
    plan and the expected plan with the params file's eps."""
    from trust_av.drive import bag_data
    from trust_av.drive.trust_rating import DriveSeries
    from trust_monitor.paper_trust import explicability

    bag = tmp_path / 'drive_02_calm'
    bag.mkdir()
    (bag / 'metadata.yaml').write_text(
        'rosbag2_bagfile_information:\n  custom_data:\n    trust_av.drive.start_ns: "5"\n')
    plans = [[0.0, 0.0], [-3.0, 0.0], [0.5, 0.5]]
    expected = [[0.0, 0.0], [0.0, 0.0], [0.5, 0.5]]
    odometry = {  # (t_s, position_m, speed_mps), sampled at twice the plan rate
        '/preceding_vehicle/odom': np.array([[k / 2, 60.0 + k, 10.0] for k in range(6)]),
        '/ego/odom': np.array([[k / 2, 30.0 + k, 10.0] for k in range(6)]),
        '/human/odom': np.array([[k / 2, float(k), 10.0 + k] for k in range(6)])}

    def fake(path: Path) -> bag_data.DriveBag:
        series = DriveSeries(np.array([0.0, 1.0, 2.0]), plans, expected, np.zeros(3))
        return bag_data.DriveBag(Path(path), {}, series, np.array([]), np.array([]), [],
                                 odometry)

    monkeypatch.setattr(bag_data, 'read_drive', fake)
    run = read_run(bag)
    config = load_run_config([])
    length = config.shared.vehicle_length_m
    np.testing.assert_allclose(run.values['av_gap_m'], 30.0 - length)
    np.testing.assert_allclose(run.values['human_gap_m'], 30.0 - length)
    np.testing.assert_allclose(run.values['human_speed_mps'], [10.0, 12.0, 14.0])
    np.testing.assert_allclose(run.values['human_accel_mps2'], 2.0)
    assert run.values['av_accel_mps2'].tolist() == [0.0, -3.0, 0.5]
    assert run.values['explicability'][1] == explicability(plans[1], expected[1],
                                                           config.trust.epsilon_mps2) > 0.05
    assert run.values['explicability'][0] == 0.0


def test_the_cli_reference_documents_compare() -> None:
    from trust_av.cli import reference

    page = reference.fill((REPO / 'docs' / 'reference' /
                           'cli.md').read_text())
    assert '### `trust-av compare`' in page and '`--trust-models TRUST_MODELS`' in page
