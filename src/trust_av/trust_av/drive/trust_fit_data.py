"""Rated drives for the trust fit, from a study's bags or from a tidy ratings table.

**A study** (``trust-av drive --study DIR``): every drive bag under DIR
(``DIR/<participant>/drive_<k>_<condition>``) except practice drives and earlier attempts
(``.attempt<k>``). E of each recorded plan is recomputed from the plan and the expected plan
with the run's eps (eq. 8), exactly as the monitor scored it; ratings are read from
``driver/rating`` (z: the rating as given, 0-100).

**A tidy table** (CSV, one header row, for data collected elsewhere), columns:

- ``participant``: any non-empty text;
- ``drive``: any non-empty text (unique per participant);
- ``t_s``: time in the drive, s;
- ``explicability``: E of the plan applied from ``t_s`` until the drive's next row with an
  E (empty on a row that only carries a rating);
- ``rating``: a trust rating given at ``t_s``, 0-100 (empty on a row without one).

Rows of a drive may come in any order; a drive needs at least two rows with an E.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

from trust_monitor.paper_trust import explicability
from trust_monitor.trust_fit import FitError, RatedDrive

__all__ = ['read_ratings_table', 'read_study']

COLUMNS = ('participant', 'drive', 't_s', 'explicability', 'rating')


def _number(text: str, what: str) -> float | None:
    if text.strip() == '':
        return None
    try:
        value = float(text)
    except ValueError:
        raise FitError(f'{what}: not a number: {text!r}') from None
    if not math.isfinite(value):
        raise FitError(f'{what}: not finite: {text!r}')
    return value


def read_ratings_table(path: Path) -> list[RatedDrive]:
    """The drives of a tidy ratings table (format above).

    Raises:
        FitError: unreadable, a missing column, a bad value (file and line named), or a
            drive with fewer than two scored rows.
    """
    try:
        with Path(path).open(newline='') as handle:
            rows = list(csv.DictReader(handle))
            header = rows[0].keys() if rows else []
    except (OSError, UnicodeDecodeError, csv.Error) as err:
        raise FitError(f'{path}: cannot read ({err})') from err
    missing = [c for c in COLUMNS if c not in header]
    if missing:
        raise FitError(f'{path}: missing column(s) {", ".join(missing)} (need '
                       f'{", ".join(COLUMNS)})')
    drives: dict[tuple[str, str], dict[str, list[tuple[float, float]]]] = {}
    for line, row in enumerate(rows, start=2):
        where = f'{path}:{line}'
        who, drive = (row['participant'] or '').strip(), (row['drive'] or '').strip()
        if not who or not drive:
            raise FitError(f'{where}: participant and drive must not be empty')
        t = _number(row['t_s'] or '', f'{where}: t_s')
        if t is None:
            raise FitError(f'{where}: t_s is empty')
        score = _number(row['explicability'] or '', f'{where}: explicability')
        rating = _number(row['rating'] or '', f'{where}: rating')
        entry = drives.setdefault((who, drive), {'scores': [], 'ratings': []})
        if score is not None:
            entry['scores'].append((t, score))
        if rating is not None:
            entry['ratings'].append((t, rating))
    if not drives:
        raise FitError(f'{path}: no rows')
    out = []
    for (who, drive), entry in drives.items():
        scores = sorted(entry['scores'])
        ratings = sorted(entry['ratings'])
        out.append(RatedDrive(who, drive, np.array([t for t, _ in scores]),
                              np.array([e for _, e in scores]),
                              np.array([t for t, _ in ratings]),
                              np.array([r for _, r in ratings])))
    return out


def drive_bags(study: Path) -> list[Path]:
    """The drive bags of a study (no practice drive, no earlier attempt), sorted."""
    return sorted(p.parent for p in Path(study).glob('*/drive_*/metadata.yaml')
                  if '.attempt' not in p.parent.name
                  and not p.parent.name.endswith('_practice'))


def read_study(study: Path, epsilon_mps2: float) -> list[RatedDrive]:
    """The rated drives of a study's bags (E recomputed with ``epsilon_mps2``).

    Raises:
        FitError: not a directory, or no drive bag in it.
        DriveBagError: a bag that is not a complete drive recording (named).
    """
    from trust_av.drive.bag_data import read_drive

    if not Path(study).is_dir():
        raise FitError(f'{study}: not a directory')
    bags = drive_bags(study)
    if not bags:
        raise FitError(f'{study}: no drive bags (<participant>/drive_<k>_<condition>)')
    out = []
    for bag in bags:
        drive = read_drive(bag)
        who = drive.metadata.get('trust_av.participant', bag.parent.name)
        scores = np.array([explicability(p, e, epsilon_mps2) for p, e in
                           zip(drive.series.plans, drive.series.expected, strict=True)])
        out.append(RatedDrive(who, bag.name, drive.series.times_s, scores,
                              drive.rating_times_s, 100.0 * np.asarray(drive.ratings)))
    return out
