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
- ``rating``: a trust rating given at ``t_s`` (empty on a row without one), on the table's
  declared scale: ``--rating-scale`` (default ``0-100``), or an optional column
  ``rating_scale`` per row (``0-1``, ``1-7``, any ``LOW-HIGH``); mapped to 0-100.

Rows of a drive may come in any order; a drive needs at least two rows with an E, and
spans from its first E row to its last plus one step (the median). Refused, each in one line
naming the file, the line and the column (:mod:`trust_av.drive.table_input` for the file
and id rules): a row given twice (an E or a rating at the same time of the same drive), a
rating outside its drive's span (a time in ms among times in s), a rating of a drive with
no E rows (an unknown drive), a rating outside the declared scale or a table whose ratings
all sit in its bottom tenth (ratings on 0-1 given as 0-100), ids that collide on disk or in
a spreadsheet or start like a formula.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from trust_av.drive.table_input import IdCheck, RatingScale, cell_number, table_rows
from trust_monitor.paper_trust import explicability
from trust_monitor.trust_fit import FitError, RatedDrive

__all__ = ['read_ratings_table', 'read_study']

COLUMNS = ('participant', 'drive', 't_s', 'explicability', 'rating')
SCALE_COLUMN = 'rating_scale'
DEFAULT_SCALE = RatingScale(0.0, 100.0)
"""Ratings are 0-100 unless declared otherwise (the drive page's slider)."""


@dataclass
class _Drive:
    first_line: int
    scores: dict[float, tuple[float, int]] = field(default_factory=dict)
    ratings: dict[float, tuple[float, int]] = field(default_factory=dict)


def read_ratings_table(path: Path, scale: RatingScale = DEFAULT_SCALE) -> list[RatedDrive]:
    """The drives of a tidy ratings table (format above), ratings mapped to 0-100.

    Args:
        path: the table.
        scale: the ratings' scale where the table has no ``rating_scale`` value.

    Raises:
        FitError: one line naming the file, the line and the column (see above).
    """
    drives: dict[tuple[str, str], _Drive] = {}
    people, names = IdCheck('participant'), IdCheck('drive')
    largest: dict[RatingScale, tuple[float, int]] = {}
    for line, row, decimal in table_rows(path, COLUMNS):
        where = f'{path}:{line}'
        who = people.check(where, row['participant'])
        drive = names.check(where, row['drive'])
        t = cell_number(row['t_s'], f'{where}: column t_s', decimal)
        if t is None:
            raise FitError(f'{where}: column t_s is empty')
        if t < 0.0:
            raise FitError(f'{where}: column t_s: {t:g} s is before the drive starts (0 s)')
        entry = drives.setdefault((who, drive), _Drive(line))
        score = cell_number(row['explicability'], f'{where}: column explicability', decimal)
        if score is not None:
            if not 0.0 <= score <= 1.0:
                raise FitError(f'{where}: column explicability: {score:g} is outside [0, 1]')
            if t in entry.scores:
                raise FitError(f'{where}: column explicability: a second E at t_s = {t:g} s '
                               f'of drive {drive!r} of {who!r} (first on line '
                               f'{entry.scores[t][1]}): a row given twice?')
            entry.scores[t] = (score, line)
        rating = cell_number(row['rating'], f'{where}: column rating', decimal)
        if rating is not None:
            own = (row.get(SCALE_COLUMN) or '').strip()
            declared = RatingScale.parse(own, f'{where}: column {SCALE_COLUMN}') if own \
                else scale
            if t in entry.ratings:
                raise FitError(f'{where}: column rating: a second rating at t_s = {t:g} s of '
                               f'drive {drive!r} of {who!r} (first on line '
                               f'{entry.ratings[t][1]}): a row given twice?')
            entry.ratings[t] = (declared.percent(f'{where}: column rating', rating), line)
            if rating > largest.get(declared, (-math.inf, 0))[0]:
                largest[declared] = (rating, line)
    for declared, (top, line) in largest.items():
        if declared.too_narrow(top):
            raise FitError(f'{path}:{line}: column rating: every rating on the declared scale '
                           f'{declared} is at most {top:g}, in its bottom tenth: ratings on '
                           'another scale (0-1, 1-7)? Declare it with --rating-scale or a '
                           f'{SCALE_COLUMN} column')
    out = []
    for (who, drive), entry in drives.items():
        if not entry.scores:
            line = min(line for _, line in entry.ratings.values())
            raise FitError(f'{path}:{line}: column drive: {drive!r} of {who!r} has ratings '
                           'but no row with an explicability (an unknown drive?)')
        times = np.array(sorted(entry.scores))
        if len(times) < 2:
            raise FitError(f'{path}:{entry.first_line}: column explicability: drive {drive!r} '
                           f'of {who!r} has {len(times)} row with an E, a drive needs two')
        end = times[-1] + float(np.median(np.diff(times)))
        for t, (_, line) in entry.ratings.items():
            if not times[0] <= t <= end:
                raise FitError(f'{path}:{line}: column t_s: a rating at {t:g} s is outside its '
                               f'drive {drive!r} of {who!r} ({times[0]:g} to {end:g} s): a '
                               'time in ms among times in s?')
        rating_times = sorted(entry.ratings)
        out.append(RatedDrive(who, drive, times,
                              np.array([entry.scores[t][0] for t in times]),
                              np.array(rating_times),
                              np.array([entry.ratings[t][0] for t in rating_times])))
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
    people = IdCheck('participant')
    for bag in bags:
        drive = read_drive(bag)
        who = people.check(str(bag), drive.metadata.get('trust_av.participant',
                                                        bag.parent.name))
        scores = np.array([explicability(p, e, epsilon_mps2) for p, e in
                           zip(drive.series.plans, drive.series.expected, strict=True)])
        out.append(RatedDrive(who, bag.name, drive.series.times_s, scores,
                              drive.rating_times_s, 100.0 * np.asarray(drive.ratings)))
    return out
