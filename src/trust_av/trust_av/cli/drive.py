"""``trust-av drive``: a person drives the follower behind the trust-aware AV in a browser;
a study session of drives in counterbalanced order, recorded one bag per drive."""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

from trust_av.cli.options import params_files_option, positive_seconds
from trust_av.cli.typed_options import add_command, option
from trust_av.errors import TrustAvAppError
from trust_av.system.config import DEFAULT_PARAMS_FILE

__all__: list[str] = []

DEFAULT_DRIVE_FILE = DEFAULT_PARAMS_FILE.with_name('drive.yaml')


@dataclasses.dataclass(frozen=True)
class DriveOptions:
    """``trust-av drive``'s options."""

    study: Path = option(
        '--study', required=True,
        help='study directory (created; one sub-directory per participant)')
    participant: str = option(
        '--participant', required=True,
        help='pseudonymous participant id (1-32 letters, digits, _ or -)')
    drive_file: Path = option(
        '--drive-file', default=DEFAULT_DRIVE_FILE,
        help=f'study settings and conditions (default: the shipped {DEFAULT_DRIVE_FILE.name})')
    no_practice: bool = option('--no-practice',
                               help='a new session starts without the practice drive')
    duration_s: float | None = option(
        '--duration-s', type=positive_seconds, default=None,
        help="wall time of each drive, s (default: the drive file's)")
    port: int | None = option(
        '--port', default=None,
        help="TCP port of the page (0: any free; default: the drive file's)")
    withdraw: bool = option(
        '--withdraw',
        help='delete every file trust-av wrote for the participant in this '
             'study and exit: only in a folder trust-av made for them (its '
             '.trust_av_participant marker naming this study, or a '
             'session.json of theirs from before markers), never through a '
             'symbolic link, never a file it did not write (named, left with '
             'the folder); asks for confirmation on the terminal')
    yes: bool = option(
        '--yes', help='--withdraw without asking (needed when stdin is not a terminal)')
    startup_timeout_s: float = option(
        '--startup-timeout-s', type=positive_seconds, default=60.0,
        help='how long to wait for the nodes to connect (default: %(default)s)')
    params_files: tuple[Path, ...] = params_files_option()


def run(args: DriveOptions) -> int:
    """Run ``trust-av drive``: the participant's session or withdrawal, holding their lock
    (:func:`~trust_av.drive.sessions.participant_lock`: one at a time per participant)."""
    from trust_av.drive.sessions import SessionError, check_participant, participant_lock

    try:
        check_participant(args.participant)
        with participant_lock(args.study, args.participant):
            if args.withdraw:
                return _withdraw(args)
            from trust_av.drive.run_session import run_session
            return run_session(args)
    except SessionError as err:
        raise TrustAvAppError(str(err)) from err


def _withdraw(args: DriveOptions) -> int:
    """Delete what trust-av wrote for the participant, only if their folder is proven this
    study's, after a confirmation on the terminal (or ``--yes``)."""
    from trust_av.drive.withdrawal import withdraw, withdrawal_plan

    plan = withdrawal_plan(args.study, args.participant)
    if plan is None:
        print(f'participant {args.participant}: no data in this study')
        return 0
    if not args.yes:
        if sys.stdin is None or not sys.stdin.isatty():
            raise TrustAvAppError(f'--withdraw would delete {plan.files} files in '
                                  f'{plan.directory}; no terminal to confirm on, pass --yes')
        try:
            answer = input(f'delete the {plan.files} files trust-av wrote in '
                           f'{plan.directory} for good? [y/N] ')
        except EOFError:
            answer = ''
        if answer.strip().lower() not in ('y', 'yes'):
            print(f'participant {args.participant}: nothing deleted')
            return 0
    done = withdraw(args.study, args.participant)      # checked again just before deleting
    print(f'participant {args.participant}: {done or "nothing left to delete"}')
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add ``drive`` to ``trust-av``."""
    parser = subparsers.add_parser(
        'drive', help='a person drives behind the AV in a browser (driver-in-the-loop study)',
        description='Serve a page on localhost (the URL is printed) where a participant drives '
                    'the car behind the trust-aware AV with keyboard, pointer or gamepad; the '
                    'node graph runs in wall mode with the follower_plant node integrating the '
                    "person's pedal. A session: a practice drive, then every condition of the "
                    'drive file in a balanced Latin square order, in-drive trust ratings, the '
                    'Jian et al. (2000) questionnaire after each drive, one rosbag2 bag per '
                    'drive under STUDY/PARTICIPANT/, a summary table and the comparison of the '
                    "person's ratings with every trust model. Run again to resume. Exit codes: "
                    '0 done (or stopped by an abandoned drive: run again to resume; a withdrawal '
                    'done or declined), 2 bad input, a node failed or a withdrawal refused, '
                    '130 interrupted.')
    add_command(parser, DriveOptions, run)
