"""A participant's study session, pure part: pseudonymous ids, the counterbalanced order of
the conditions, the session's progress on disk (resume after a crash) and withdrawal.

Layout of a study directory::

    <study>/study.json                 enrolment counter (no participant ids)
    <study>/<participant>/session.json the session: order, drives done, their outcome
    <study>/<participant>/drive_<k>_<condition>/   one rosbag2 bag per drive
    <study>/<participant>/summary.csv  one row per drive
    <study>/<participant>/comparison.csv  ratings vs every trust model, per drive

Counterbalancing: the k-th participant enrolled gets row k of a balanced Latin square over
the conditions (Williams design: with n conditions every condition appears once in each
position in n rows, and each ordered pair of neighbours once; for odd n, 2n rows, the
second n reversed). Withdrawal deletes the participant's directory; the enrolment counter
keeps counting, so the next participant still gets the next row.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import tempfile
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

PARTICIPANT_ID = re.compile(r'[A-Za-z0-9][A-Za-z0-9_-]{0,31}')
"""A pseudonymous participant id: letters, digits, '_' and '-', at most 32 characters."""
PRACTICE = 'practice'
"""The name of the practice drive (never in the comparison or the order)."""
DONE, ABANDONED = 'done', 'abandoned'


class SessionError(ValueError):
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
    """The participant's session file."""
    return study / check_participant(participant) / 'session.json'


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
    names = [c.name for c in conditions]
    if not names or len(set(names)) != len(names) or PRACTICE in names:
        raise SessionError(f'conditions must be distinct, non-empty and not {PRACTICE!r}: '
                           f'{names}')
    existing = load_session(study, participant)
    if existing is not None:
        if sorted(existing.order) != sorted(names):
            raise SessionError(f'participant {participant}: their session has conditions '
                               f'{existing.order}, the study now has {names}')
        return existing
    study.mkdir(parents=True, exist_ok=True)
    counter = study / 'study.json'
    enrolled = json.loads(counter.read_text())['enrolled'] if counter.exists() else 0
    row = int(enrolled)
    session = Session(participant, row,
                      [names[i] for i in balanced_latin_square_row(len(names), row)],
                      practice_done=not practice)
    save_session(study, session)
    _write_json(counter, json.dumps({'enrolled': row + 1}) + '\n')
    return session


def withdraw(study: Path, participant: str) -> bool:
    """Delete every file of the participant (bags, session, summaries).

    Returns:
        Whether there was anything to delete.
    """
    directory = study / check_participant(participant)
    if not directory.exists():
        return False
    shutil.rmtree(directory)
    return True


def drive_dir(study: Path, participant: str, index: int, condition: str) -> Path:
    """The bag directory of a drive; an earlier incomplete attempt is moved aside
    (``.attempt<k>``), never overwritten."""
    path = study / check_participant(participant) / f'drive_{index:02d}_{condition}'
    if path.exists():
        k = 1
        while path.with_name(f'{path.name}.attempt{k}').exists():
            k += 1
        path.rename(path.with_name(f'{path.name}.attempt{k}'))
    return path
