"""Withdrawal of a participant: every file trust-av wrote for them in a study is deleted, and
nothing else.

Only a folder trust-av made for this participant of this study is touched: one whose marker
(:data:`~trust_av.drive.sessions.MARKER`) names this participant and this study's id (both
present: a marker or a study without an id proves nothing,
:func:`~trust_av.drive.sessions.same_study`), or, for a folder made before markers existed,
one whose ``session.json`` is a session of this participant in a study with its
``study.json``. Of that folder it deletes the entries trust-av writes there
(:func:`written_by_trust_av`: the marker, the session, the tables, the drives' bags and
logs) and leaves anything else, named, with the folder; a bag the session names outside the
folder (an earlier version took condition names as paths) is named and left too. A symbolic
link (the study directory, the participant folder or anything in it) is refused: trust-av
never makes one. The caller holds :func:`~trust_av.drive.sessions.participant_lock`.
"""

from __future__ import annotations

import os
import re
import shutil
from dataclasses import dataclass
from pathlib import Path

from trust_av.drive.sessions import (
    CONDITION_NAME,
    MARKER,
    STUDY_FILE,
    SessionError,
    check_participant,
    load_session,
    marker_of,
    same_study,
    study_id_of,
)

__all__ = ['Withdrawal', 'withdraw', 'withdrawal_folder', 'withdrawal_plan',
           'written_by_trust_av']


def withdrawal_folder(study: Path, participant: str) -> Path | None:
    """The participant folder withdrawal would delete from, proven this study's (see the
    module notes), or None if the participant has no folder in the study.

    Raises:
        SessionError: a bad id; the study directory, the participant folder or anything in
            it is a symbolic link; the folder is not one trust-av made for this participant
            of this study. Nothing is deleted then.
    """
    directory = study / check_participant(participant)
    for path in (study, directory):
        if path.is_symlink():
            raise SessionError(f'{path}: a symbolic link; trust-av never makes one, so '
                               'nothing is deleted (remove the link yourself)')
    if not os.path.lexists(directory):
        return None
    if not directory.is_dir():
        raise SessionError(f'{directory}: not a folder; trust-av made no such participant '
                           'folder, so nothing is deleted')
    for root, dirs, files in os.walk(directory):
        for name in dirs + files:
            if os.path.islink(os.path.join(root, name)):
                raise SessionError(f'{os.path.join(root, name)}: a symbolic link in the '
                                   'participant folder; trust-av never makes one, so '
                                   'nothing is deleted')
    marker = marker_of(directory)
    if marker is not None:
        if marker.get('participant') != participant:
            raise SessionError(f'{directory / MARKER}: names participant '
                               f'{marker.get("participant")!r}, not {participant!r}; nothing '
                               'is deleted')
        if not same_study(marker, study):
            study_id = study_id_of(study)
            raise SessionError(
                f'{directory / MARKER}: names '
                + (f'study {marker["study"]!r}' if marker.get('study') else 'no study')
                + ', not this one ('
                + (f'{study_id!r} in {study / STUDY_FILE}' if study_id else
                   f'{study} has no {STUDY_FILE} with an id')
                + "): only a marker naming the study's id proves trust-av made the folder "
                'for it (copied from another study, or made by hand?); nothing is deleted')
        return directory
    try:
        session = load_session(study, participant)
    except SessionError:
        session = None
    if session is None or session.participant != participant or not (
            study / STUDY_FILE).is_file():
        raise SessionError(f'{directory}: not a participant folder of this study (no {MARKER} '
                           f'written by trust-av, no session.json of {participant}); nothing '
                           'is deleted')
    return directory            # made before markers existed: its session proves it


WRITTEN = re.compile(
    r'(?:\.trust_av_participant|session\.json)(?:\w+\.tmp)?'   # (and _write_json's temporary)
    r'|\.?(?:summary|comparison)\.csv(?:\.\w+\.tmp\.csv)?'       # (and write_text's)
    r'|\.?drive_\d{2,}_' + CONDITION_NAME.pattern + r'(?:\.attempt\d+|\.logs|\.repairing|\.lock)*')
"""The names of the entries trust-av writes in a participant folder: the marker, the session
file, the summary and comparison tables (with the temporary files they are written through),
and each drive's bag directory, its logs, an earlier attempt moved aside and the work folder
and lock of a ``repair-bag`` of it."""


def written_by_trust_av(name: str) -> bool:
    """Whether an entry of a participant folder has a name trust-av writes there
    (:data:`WRITTEN`)."""
    return WRITTEN.fullmatch(name) is not None


@dataclass(frozen=True)
class Withdrawal:
    """What withdrawal deletes of a participant (and what it leaves)."""

    directory: Path
    """the participant folder"""
    ours: tuple[Path, ...]
    """its entries trust-av wrote: deleted"""
    files: int
    """the files among (or in) them"""
    foreign: tuple[Path, ...]
    """its entries trust-av did not write: left, with the folder"""
    outside: tuple[Path, ...]
    """bags the session names outside the folder (written by an old version through a
    condition name that was a path): left"""

    def __str__(self) -> str:
        words = [f'every file trust-av wrote deleted ({self.files} file'
                 f'{"s" if self.files != 1 else ""}, {self.directory})']
        if self.foreign:
            shown = ', '.join(p.name for p in self.foreign[:5])
            words.append(f'left the folder with {len(self.foreign)} '
                         f'entr{"y" if len(self.foreign) == 1 else "ies"} trust-av did not '
                         f'write: {shown}{", ..." if len(self.foreign) > 5 else ""}')
        if self.outside:
            words.append('left outside the participant folder, though their session names '
                         'it: ' + ', '.join(str(p) for p in self.outside))
        return '; '.join(words)


def withdrawal_plan(study: Path, participant: str) -> Withdrawal | None:
    """What :func:`withdraw` would delete (None: the participant has no folder); nothing is
    deleted.

    Raises:
        SessionError: as :func:`withdrawal_folder`.
    """
    directory = withdrawal_folder(study, participant)
    if directory is None:
        return None
    entries = sorted(directory.iterdir())
    ours = tuple(p for p in entries if written_by_trust_av(p.name))
    files = sum(len(names) for p in ours if p.is_dir() for _, _, names in os.walk(p)) \
        + sum(1 for p in ours if not p.is_dir())
    outside: list[Path] = []
    try:
        session = load_session(study, participant)
    except SessionError:
        session = None
    inside = directory.resolve()
    for record in session.drives if session is not None else []:
        bag = (study / record.bag).resolve()
        if inside not in bag.parents and os.path.lexists(bag):
            outside.append(bag)
    return Withdrawal(directory, ours, files,
                      tuple(p for p in entries if not written_by_trust_av(p.name)),
                      tuple(outside))


def withdraw(study: Path, participant: str) -> Withdrawal | None:
    """Delete every file trust-av wrote for the participant (bags, session, summaries), only
    if the folder is proven this study's (:func:`withdrawal_folder`); the folder goes too
    unless it holds entries trust-av did not write. The caller holds
    :func:`participant_lock`.

    Returns:
        What was deleted and left (None: nothing to delete).

    Raises:
        SessionError: as :func:`withdrawal_folder` (nothing is deleted).
    """
    plan = withdrawal_plan(study, participant)
    if plan is None:
        return None
    # the marker last: a stop halfway leaves a folder withdrawal still recognises
    for path in sorted(plan.ours, key=lambda p: p.name == MARKER):
        if path.is_dir():
            shutil.rmtree(path)
        else:
            path.unlink()
    if not plan.foreign:
        plan.directory.rmdir()
    return plan
