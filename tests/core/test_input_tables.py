"""Ratings tables are checked where they enter (one line naming the file, the line and the
column), ratings and model trust meet on one scale, and a folder of results is written as
one set, never over anyone else's files."""

from __future__ import annotations

import codecs
import os
from pathlib import Path

import numpy as np
import pytest

from trust_av.cli.main import main
from trust_av.drive.table_input import MAX_TABLE_BYTES, RatingScale
from trust_av.drive.trust_fit_data import read_ratings_table
from trust_av.drive.trust_rating import DriveSeries, RatingError, compare, registered_models
from trust_av.errors import TrustAvAppError
from trust_av.system.output_sets import writing_set
from trust_av.system.outputs import MARKER
from trust_monitor.model_interface import UnitTrust, common_trust, unit_trust
from trust_monitor.paper_trust import TrustConfig
from trust_monitor.trust_fit import FitError

HEADER = 'participant,drive,t_s,explicability,rating\n'


def table(tmp_path: Path, rows: str, header: str = HEADER, name: str = 'r.csv') -> Path:
    path = tmp_path / name
    path.write_text(header + rows, encoding='utf-8')
    return path


def drive_rows(who: str = 'a', drive: str = 'd', steps: int = 4, rating: str = '50',
               at: float = 1.0) -> str:
    rows = ''.join(f'{who},{drive},{t},0.1,\n' for t in range(steps))
    return rows + f'{who},{drive},{at},,{rating}\n'


DEFAULT = RatingScale(0, 100)


def refused(path: Path, match: str, scale: RatingScale = DEFAULT) -> str:
    with pytest.raises(FitError) as err:
        read_ratings_table(path, scale)
    line = str(err.value)
    assert '\n' not in line and match in line, line
    return line


# ---- one scale -------------------------------------------------------------------------

CONFIG = TrustConfig(epsilon_mps2=6.0, trust_growth_rate=0.1, performance_threshold=0.8,
                     trust_initial=0.0)


def test_paper_trust_meets_ratings_on_the_common_scale() -> None:
    """A 120 s drive the person expects exactly: the paper's trust grows 0.1/s to 12 in its
    own units, 0.6 on the common scale (T(0) +- delta 600 s); ratings of 0.6 at the end
    agree with it (raw units gave RMSE 7.01 and the best lag pegged at its maximum)."""
    times = np.arange(0.0, 121.0, 1.0)                 # 120 steps of 1 s
    plans = [[0.5, 0.5, 0.5]] * len(times)
    series = DriveSeries(times, plans, plans, np.full(len(times), np.nan))
    paper = dict(registered_models(CONFIG))['paper']
    readings = paper(series)
    assert all(isinstance(v, UnitTrust) for v in readings)
    assert readings[-1] == pytest.approx(0.6)
    agreement, = compare([120.0], [0.6], series, [('paper', paper)])
    assert agreement.rmse == pytest.approx(0.0, abs=1e-9) and agreement.best_lag_s == 0.0


def test_a_raw_reading_or_a_rating_off_the_scale_is_refused() -> None:
    times = np.arange(0.0, 5.0)
    series = DriveSeries(times, [[0.0]] * 5, [[0.0]] * 5, np.full(5, np.nan))
    with pytest.raises(RatingError, match="'raw': its trust is not on the common scale"):
        compare([1.0], [0.5], series, [('raw', lambda s: np.full(len(s.times_s), 12.0))])
    with pytest.raises(RatingError, match=r'common scale \[0, 1\], got 50'):
        compare([1.0], [50.0], series, registered_models(CONFIG)[:1])
    model = dict(registered_models(CONFIG))     # the one conversion, by the model's range
    assert unit_trust(type('M', (), {'trust_range': (-60.0, 60.0)})(), 12.0) == 0.6
    assert isinstance(common_trust(type('N', (), {'trust': lambda self, s: s})(), 0.3),
                      UnitTrust) and model


@pytest.mark.parametrize(('scale', 'values', 'expected'), [
    ('0-1', ('0.2', '0.8'), [20.0, 80.0]),
    ('1-7', ('1', '7'), [0.0, 100.0]),
    ('0-100', ('20', '80'), [20.0, 80.0]),
])
def test_ratings_are_read_on_their_declared_scale(tmp_path: Path, scale: str,
                                                  values: tuple[str, str],
                                                  expected: list[float]) -> None:
    path = table(tmp_path, drive_rows(rating=values[0]) + drive_rows(drive='e',
                                                                     rating=values[1]))
    drives = read_ratings_table(path, RatingScale.parse(scale))
    assert [float(d.ratings[0]) for d in drives] == expected


def test_a_table_off_its_declared_scale_is_refused(tmp_path: Path) -> None:
    path = table(tmp_path, drive_rows(rating='0.2') + drive_rows(drive='e', rating='0.9'))
    refused(path, ':11: column rating: every rating on the declared scale 0-100 is at most '
            '0.9, in its bottom tenth')
    refused(table(tmp_path, drive_rows(rating='150')), ':6: column rating: 150 is outside '
            'the declared rating scale 0-100')
    likert = drive_rows(rating='6') + drive_rows(drive='e', rating='7')
    column = table(tmp_path, likert.replace('\n', ',\n'),
                   header=HEADER.strip() + ',rating_scale\n')
    refused(column, 'every rating on the declared scale 0-100 is at most 7')
    per_row = table(tmp_path, likert.replace(',\n', ',,\n').replace(',6\n', ',6,1-7\n')
                    .replace(',7\n', ',7,1-7\n'),
                    header=HEADER.strip() + ',rating_scale\n', name='s.csv')
    assert [float(d.ratings[0]) for d in read_ratings_table(per_row)] == \
        pytest.approx([500 / 6, 100.0])


# ---- every table checked ---------------------------------------------------------------

@pytest.mark.parametrize(('rows', 'message'), [
    (drive_rows() + 'a,d,1.0,,50\n', ':7: column rating: a second rating at t_s = 1 s of '
     "drive 'd' of 'a' (first on line 6)"),
    (drive_rows() + 'a,d,2,0.1,\n', ':7: column explicability: a second E at t_s = 2 s'),
    (drive_rows(at=35000.0), ':6: column t_s: a rating at 35000 s is outside its drive '
     "'d' of 'a' (0 to 4 s)"),
    (drive_rows() + 'a,x,1,,50\n', ":7: column drive: 'x' of 'a' has ratings but no row "
     'with an explicability'),
    (drive_rows(who='lab/P1') + drive_rows(who='lab_P1'), ":7: column participant: 'lab_P1' "
     "and 'lab/P1' (", ),
    (drive_rows(who='Zo\u00e9') + drive_rows(who='Zoe\u0301'), ':7: column participant: '),
    (drive_rows(who='P1') + drive_rows(who='p1'), ":7: column participant: 'p1' and 'P1'"),
    (drive_rows(who='=1+2'), ":2: column participant: '=1+2' starts with '='"),
    (drive_rows(who='@SUM(1)'), "starts with '@'"),
    ('a,d,0,1.5,\n', ':2: column explicability: 1.5 is outside [0, 1]'),
    ('a,d,x,0.1,\n', ':2: column t_s: not a number'),
    ('a,d,0,0.1,\n', ":2: column explicability: drive 'd' of 'a' has 1 row with an E"),
    ('', 'no rows, only the header'),
])
def test_a_bad_table_is_one_line_naming_file_line_and_column(tmp_path: Path, rows: str,
                                                             message: str) -> None:
    path = table(tmp_path, rows)
    assert refused(path, message).startswith(str(path))


def test_spreadsheet_exports_are_read(tmp_path: Path) -> None:
    rows = drive_rows() + drive_rows(drive='e', rating='70')
    plain = read_ratings_table(table(tmp_path, rows))
    bom = tmp_path / 'bom.csv'                           # Excel "CSV UTF-8"
    bom.write_bytes(codecs.BOM_UTF8 + (HEADER + rows).replace('\n', '\r\n').encode())
    utf16 = tmp_path / 'u16.txt'                         # Excel "Unicode text"
    utf16.write_text((HEADER + rows).replace(',', '\t'), encoding='utf-16')
    semicolon = tmp_path / 'semi.csv'                    # a decimal-comma locale
    semicolon.write_text((HEADER + rows).replace(',', ';').replace('0.1', '0,1'))
    for path in (bom, utf16, semicolon):
        drives = read_ratings_table(path)
        assert [(d.drive, d.ratings.tolist(), d.scores.tolist()) for d in drives] == \
            [(d.drive, d.ratings.tolist(), d.scores.tolist()) for d in plain], path


def test_a_large_or_binary_file_is_refused_without_reading_it(tmp_path: Path) -> None:
    big = tmp_path / 'big.csv'
    with big.open('wb') as handle:
        handle.write(HEADER.encode())
        handle.truncate(MAX_TABLE_BYTES + 1)             # sparse: no disk, no memory
    refused(big, 'MiB, larger than the 64 MiB an input table may be')
    binary = tmp_path / 'bin.csv'
    binary.write_bytes(HEADER.encode() + os.urandom(64) + b'\xff' * 5000)
    refused(binary, 'bin.csv')


# ---- fit-trust: repeated models, one set of outputs -------------------------------------

def fit_trust(tmp_path: Path, capsys: pytest.CaptureFixture[str], out: Path,
              *extra: str) -> tuple[int, str]:
    rows = ''.join(f'a,{d},{t},{0.05 * (t % 3) + k * 0.1},\n' for k, d in enumerate('de')
                   for t in range(12))
    rows += ''.join(f'a,{d},{t + 0.5},,{30 + 4 * t + 10 * k}\n' for k, d in enumerate('de')
                    for t in range(0, 12, 2))
    ratings = table(tmp_path, rows, name='ratings.csv')
    code = main(['fit-trust', '--ratings', str(ratings), '--out', str(out), '--models',
                 'paper', '--no-figures', '--no-partial-pooling', *extra])
    return code, capsys.readouterr().err


def test_a_model_given_twice_is_refused(tmp_path: Path,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    code = main(['fit-trust', '--ratings', str(tmp_path / 'r.csv'), '--out',
                 str(tmp_path / 'o'), '--models', 'paper,paper'])
    assert code == 2 and 'paper given twice' in capsys.readouterr().err


def test_fit_trust_never_writes_through_a_link_or_into_a_foreign_folder(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Refused before the fit (its whole run, marker included, is checked in
    tests/graph/test_trust_fit.py::test_fit_trust_from_a_ratings_table)."""
    theirs = tmp_path / 'theirs'
    theirs.mkdir()
    (theirs / 'fits.csv').write_text('their fits\n')
    link = tmp_path / 'link'
    link.symlink_to(theirs)
    ours = tmp_path / 'ours'
    with writing_set(ours, command='fit-trust') as new:
        (new / 'fits.csv').write_text('our fits\n')
    (ours / 'notes.txt').write_text('mine\n')          # a foreign file in our set
    for target, message in ((link, 'a symbolic link (to'),
                            (theirs, 'holds files trust-av did not write (fits.csv;'),
                            (ours, 'its .trust_av_output marker does not name (notes.txt)')):
        code, err = fit_trust(tmp_path, capsys, target)
        assert code == 2 and message in err and err.count('\n') == 1, err
    assert [p.name for p in theirs.iterdir()] == ['fits.csv']
    assert (ours / 'fits.csv').read_text() == 'our fits\n'


def test_a_set_replaces_its_own_and_a_failed_one_leaves_the_previous(tmp_path: Path) -> None:
    out = tmp_path / 'set'
    for _ in range(2):                                  # the second replaces the first
        with writing_set(out, command='test') as new:
            (new / 'a.csv').write_text('1\n')
            (new / 'b.csv').write_text('1\n')
    with pytest.raises(RuntimeError), writing_set(out, command='test') as new:
        (new / 'a.csv').write_text('2\n')
        raise RuntimeError('stopped half-way')
    assert sorted(p.name for p in out.iterdir()) == [MARKER, 'a.csv', 'b.csv']
    assert (out / 'a.csv').read_text() == '1\n'
    assert [p.name for p in tmp_path.iterdir()] == ['set']
    with pytest.raises(TrustAvAppError, match='is not a directory'), \
            writing_set(out / 'a.csv', command='test'):
        pass
