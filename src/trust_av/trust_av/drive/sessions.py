"""A participant's study session, pure part: pseudonymous ids, the counterbalanced order of
the conditions, the session's progress on disk (resume after a crash) and the participant's
lock.

Layout of a study directory::

    <study>/study.json                 enrolment counter and the study's id (no participant ids)
    <study>/<participant>/.trust_av_participant  marker: the study's id and the participant
    <study>/<participant>/session.json the session: order, drives done, their outcome
    <study>/<participant>/drive_<k>_<condition>/   one rosbag2 bag per drive
    <study>/<participant>/summary.csv  one row per drive
    <study>/<participant>/comparison.csv  ratings vs every trust model, per drive

Counterbalancing: the k-th participant enrolled gets row k of a balanced Latin square over
the conditions (Williams design: with n conditions every condition appears once in each
position in n rows, and each ordered pair of neighbours once; for odd n, 2n rows, the
second n reversed). After a withdrawal the enrolment counter keeps counting, so the next
participant still gets the next row, and two participants who enrol at the same instant
get two rows (the counter is read and written under a lock on the study folder).

A participant folder is created whole with its marker (:data:`MARKER`, made in a hidden
folder beside it and renamed into place), and a participant id whose folder exists without
one is refused at enrolment. The marker names the study's id (a random one, in
``study.json``); a marker proves a folder this study's only when both name the same id
(:func:`same_study`). Withdrawal, which deletes only what trust-av wrote:
:mod:`trust_av.drive.withdrawal`.

One live session per participant: a drive session and a withdrawal hold the participant's
lock (:func:`participant_lock`, ``<study>/<participant>.lock`` beside the folder; ``trust-av
repair-bag`` of one of their bags holds it too), and a second one is refused in one line
naming the holder's pid.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import re
import shutil
import tempfile
import time
import uuid
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from trust_av_common.errors import TrustAvError
from trust_av_common.output_lock import hold_output_lock

__all__ = ['MARKER', 'PARTICIPANT_ID', 'PRACTICE', 'Condition', 'DriveRecord', 'Session',
           'SessionError', 'balanced_latin_square_row', 'check_condition_name',
           'check_participant', 'drive_dir', 'enrol', 'load_session', 'marker_of',
           'participant_lock', 'same_study', 'save_session', 'study_id_of']

PARTICIPANT_ID = re.compile(r'[A-Za-z0-9][A-Za-z0-9_-]{0,31}')
"""A pseudonymous participant id: letters, digits, '_' and '-', at most 32 characters."""
CONDITION_NAME = re.compile(r'[A-Za-z0-9][A-Za-z0-9_-]{0,47}')
"""A condition name (part of its drives' folder names): letters, digits, '_' and '-', at
most 48 characters."""
PRACTICE = 'practice'
"""The name of the practice drive (never in the comparison or the order)."""
DONE, ABANDONED = 'done', 'abandoned'
MARKER = '.trust_av_participant'
"""The file trust-av writes into each participant folder it creates (JSON naming the
study's id and the participant); withdrawal deletes only a folder that carries it."""
STUDY_FILE = 'study.json'
"""The study's enrolment counter and id."""


class SessionError(TrustAvError):
    """A bad participant id, condition list or session file; the message names it."""


@dataclass(frozen=True)
class Condition:
    """One experimental condition: the planner's explicability weight, its plan estimator
    and the lead vehicle's speed trace."""

    name: str
    alpha: float
    predictor: str
    trace: str
    perturbation: str = 'none'
    """When the AV departs from its plan (:mod:`trust_av_planner.perturbations`)."""


def balanced_latin_square_row(n: int, row: int) -> list[int]:
    """Row ``row`` of a balanced (Williams) Latin square over ``n`` conditions.

    Args:
        n: number of conditions (>= 1).
        row: the row (any integer >= 0; taken modulo the square's rows: n, or 2n if odd).

    Returns:
        A permutation of ``range(n)``.
    """
    if n < 1:
        raise SessionError('need at least one condition')
    rows = n if n % 2 == 0 else 2 * n
    row %= rows
    out, low, high = [], 0, 0
    for i in range(n):
        if i < 2 or i % 2 == 1:
            value, low = low, low + 1
        else:
            value, high = n - high - 1, high + 1
        out.append((value + row) % n)
    if n % 2 == 1 and row >= n:
        out.reverse()
    return out


def check_participant(participant: str) -> str:
    """The id, if it is a valid pseudonymous id.

    Raises:
        SessionError: it is not (the rule is named).
    """
    if not PARTICIPANT_ID.fullmatch(participant):
        raise SessionError(f'participant id {participant!r}: use 1-32 letters, digits, _ or - '
                           '(a pseudonym, never a name)')
    return participant


def check_condition_name(name: object) -> str:
    """The name, if it is a valid condition name (:data:`CONDITION_NAME`; not the
    practice's).

    Raises:
        SessionError: it is not (the rule is named).
    """
    if not isinstance(name, str) or not CONDITION_NAME.fullmatch(name) or name == PRACTICE:
        raise SessionError(f'condition name {name!r}: use 1-48 letters, digits, _ or - (it '
                           f"names the drive's folder), and not {PRACTICE!r}")
    return name


@contextlib.contextmanager
def participant_lock(study: Path, participant: str) -> Iterator[None]:
    """Hold the participant's lock for the block (``<study>/<participant>.lock``, an
    :func:`~trust_av_common.output_lock.hold_output_lock` on the participant folder): one
    live session, withdrawal or repair of their bags at a time.

    Raises:
        SessionError: a bad id.
        OutputLockedError: another process holds it (the line names it and its pid).
    """
    directory = study / check_participant(participant)
    with hold_output_lock(directory, in_use=f'participant {participant} already has a live '
                          'session, withdrawal or bag repair running, one at a time per '
                          'participant'):
        yield


@dataclass
class DriveRecord:
    """One drive of a session as the session file holds it."""

    index: int
    condition: str
    bag: str
    status: str
    seed: int
    summary: dict[str, Any] = field(default_factory=dict)


@dataclass
class Session:
    """A participant's session: the order of the conditions and the drives so far."""

    participant: str
    row: int
    order: list[str]
    practice_done: bool = False
    drives: list[DriveRecord] = field(default_factory=list)

    def next_condition(self) -> str | None:
        """The next condition to drive (practice first unless done); None when finished."""
        if not self.practice_done:
            return PRACTICE
        done = {d.condition for d in self.drives if d.status == DONE}
        return next((name for name in self.order if name not in done), None)

    def to_json(self) -> str:
        """The session file's text."""
        return json.dumps(asdict(self), indent=1) + '\n'


def _write_json(path: Path, text: str) -> None:
    """Replace ``path`` with ``text`` atomically (a crash leaves the old or the new file)."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix='.tmp')
    try:
        with os.fdopen(fd, 'w') as out:
            out.write(text)
            out.flush()
            os.fsync(out.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def session_path(study: Path, participant: str) -> Path:
    """The participant's session file.

    Raises:
        SessionError: a bad id, or the participant folder is a symbolic link.
    """
    directory = study / check_participant(participant)
    if directory.is_symlink():
        raise SessionError(f'{directory}: the participant folder is a symbolic link; trust-av '
                           "never makes one, so it is not this study's")
    return directory / 'session.json'


def load_session(study: Path, participant: str) -> Session | None:
    """The participant's session, or None if they have none.

    Raises:
        SessionError: the session file is not one this module wrote.
    """
    path = session_path(study, participant)
    if not path.exists():
        return None
    try:
        data = json.loads(path.read_text())
        drives = [DriveRecord(**d) for d in data.pop('drives')]
        return Session(**data, drives=drives)
    except (ValueError, TypeError, KeyError) as err:
        raise SessionError(f'{path}: not a session file ({err})') from err


def save_session(study: Path, session: Session) -> None:
    """Write the session file (atomically)."""
    path = session_path(study, session.participant)
    path.parent.mkdir(parents=True, exist_ok=True)
    _write_json(path, session.to_json())


def enrol(study: Path, participant: str, conditions: list[Condition], *,
          practice: bool = True) -> Session:
    """The participant's session: resumed if they have one, else a new one with the next
    row of the balanced Latin square.

    Args:
        study: the study directory (created if missing).
        participant: the pseudonymous id.
        conditions: the study's conditions, in their listed order.
        practice: whether a new session starts with a practice drive.

    Raises:
        SessionError: a bad id, an empty or duplicated condition list, or a resumed session
            whose conditions are not this study's.
    """
    names = [check_condition_name(c.name) for c in conditions]
    if not names or len(set(names)) != len(names):
        raise SessionError(f'conditions must be distinct and non-empty: {names}')
    existing = load_session(study, participant)
    if existing is not None:
        if sorted(existing.order) != sorted(names):
            raise SessionError(f'participant {participant}: their session has conditions '
                               f'{existing.order}, the study now has {names}')
        if existing.participant != participant:
            raise SessionError(f'{session_path(study, participant)}: the session of '
                               f'{existing.participant!r}, not of {participant!r}')
        _participant_folder(study, participant)  # a folder made before markers gets one
        return existing
    study.mkdir(parents=True, exist_ok=True)
    _participant_folder(study, participant)
    with _enrolment_lock(study):    # one counter value per participant, also when two enrol
        row, study_id = _study_record(study)
        session = Session(participant, row,
                          [names[i] for i in balanced_latin_square_row(len(names), row)],
                          practice_done=not practice)
        save_session(study, session)
        _write_json(study / STUDY_FILE,
                    json.dumps({'enrolled': row + 1, 'study': study_id}) + '\n')
    return session


@contextlib.contextmanager
def _enrolment_lock(study: Path) -> Iterator[None]:
    """Hold the study's enrolment lock for the block: ``fcntl.flock`` on the study directory
    itself (no file of its own to leave behind), waited for, as it is held only while the
    counter in ``study.json`` is read and written. Two participants who enrol at the same
    instant (two lab machines on one shared study folder) get two rows; without it both read
    the same count."""
    fd = os.open(study, os.O_RDONLY | os.O_DIRECTORY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)                    # releases the lock


def _study_record(study: Path) -> tuple[int, str]:
    """(participants enrolled so far, the study's id) from ``study.json``; a study without
    one (new, or made before studies had ids) gets its id written now.

    Raises:
        SessionError: ``study.json`` is not one trust-av wrote.
    """
    path = study / STUDY_FILE
    try:
        data = json.loads(path.read_text()) if path.exists() else {'enrolled': 0}
        enrolled, study_id = int(data['enrolled']), data.get('study')
        if enrolled < 0 or not (study_id is None or isinstance(study_id, str)):
            raise ValueError('not a counter and an id')
    except (OSError, ValueError, TypeError, KeyError) as err:
        raise SessionError(f'{path}: not a study file of trust-av ({err})') from err
    if study_id is None:
        study_id = uuid.uuid4().hex
        _write_json(path, json.dumps({'enrolled': enrolled, 'study': study_id}) + '\n')
    return enrolled, study_id


def study_id_of(study: Path) -> str | None:
    """The study's id in its ``study.json``, or None (no file, no id, not ours); nothing
    is written."""
    try:
        data = json.loads((study / STUDY_FILE).read_text())
    except (OSError, ValueError):
        return None
    study_id = data.get('study') if isinstance(data, dict) else None
    return study_id if isinstance(study_id, str) else None


def _marker_text(study_id: str, participant: str) -> str:
    return json.dumps({'trust_av': 'participant folder', 'study': study_id,
                       'participant': participant,
                       'created': time.strftime('%Y-%m-%dT%H:%M:%SZ', time.gmtime())},
                      indent=1) + '\n'


def marker_of(directory: Path) -> dict[str, Any] | None:
    """The marker in ``directory``, or None (none, not a regular file, not ours)."""
    path = directory / MARKER
    try:
        if not os.path.isfile(path) or os.path.islink(path):
            return None
        data = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    if not (isinstance(data, dict) and data.get('trust_av') == 'participant folder'):
        return None
    return data


def same_study(marker: dict[str, Any], study: Path) -> bool:
    """Whether the marker names the study's id: both present (a marker or a study without
    an id proves nothing), non-empty and equal."""
    study_id, named = study_id_of(study), marker.get('study')
    return bool(study_id) and isinstance(named, str) and named == study_id


def _participant_folder(study: Path, participant: str) -> Path:
    """The participant's folder, created with its marker if missing (made in a hidden
    folder and renamed into place: it never exists without its marker). A folder of a
    resumed session made before markers existed gets its marker.

    Raises:
        SessionError: the folder exists and trust-av did not make it for this study.
    """
    directory = session_path(study, participant).parent
    if os.path.lexists(directory):
        marker = marker_of(directory)
        session = load_session(study, participant) if marker is None else None
        if session is not None and session.participant == participant:
            _write_json(directory / MARKER, _marker_text(_study_record(study)[1], participant))
        elif marker is None or marker.get('participant') != participant:
            raise SessionError(f'{directory}: exists and was not made by trust-av for '
                               f'participant {participant} (no {MARKER}); choose another '
                               'participant id or move it away')
        elif not same_study(marker, study):
            raise SessionError(f'{directory}: not made by trust-av for this study (its '
                               f'{MARKER} names study {marker.get("study")!r}); choose another '
                               'participant id or move it away')
        return directory
    study_id = _study_record(study)[1]
    staging = Path(tempfile.mkdtemp(dir=study, prefix=f'.{participant}.', suffix='.new'))
    try:
        umask = os.umask(0)
        os.umask(umask)
        staging.chmod(0o777 & ~umask)
        _write_json(staging / MARKER, _marker_text(study_id, participant))
        os.rename(staging, directory)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return directory


def drive_dir(study: Path, participant: str, index: int, condition: str) -> Path:
    """The bag directory of a drive; an earlier incomplete attempt is moved aside
    (``.attempt<k>``), never overwritten."""
    if condition != PRACTICE:
        check_condition_name(condition)
    path = study / check_participant(participant) / f'drive_{index:02d}_{condition}'
    if path.exists():
        k = 1
        while path.with_name(f'{path.name}.attempt{k}').exists():
            k += 1
        path.rename(path.with_name(f'{path.name}.attempt{k}'))
    return path
