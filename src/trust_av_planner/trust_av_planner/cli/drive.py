"""``trust-av drive``: a person drives the follower behind the trust-aware AV in a browser;
a study session of drives in counterbalanced order, recorded one bag per drive."""

from __future__ import annotations

import argparse
from pathlib import Path

from trust_av_planner.cli.options import add_params_file_option, positive_seconds
from trust_av_planner.errors import TrustAvPlannerError
from trust_av_planner.system.config import DEFAULT_PARAMS_FILE

DEFAULT_DRIVE_FILE = DEFAULT_PARAMS_FILE.with_name('drive.yaml')


def run(args: argparse.Namespace) -> int:
    """Run ``trust-av drive``."""
    from trust_av_planner.drive.sessions import SessionError, check_participant, withdraw

    try:
        check_participant(args.participant)
    except SessionError as err:
        raise TrustAvPlannerError(str(err)) from err
    if args.withdraw:
        gone = withdraw(args.study, args.participant)
        print(f'participant {args.participant}: ' + ('every file deleted' if gone else
                                                     'no data in this study'))
        return 0
    from trust_av_planner.study.drive_session import run_session
    try:
        return run_session(args)
    except SessionError as err:
        raise TrustAvPlannerError(str(err)) from err


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
                    '0 done (or stopped by an abandoned drive: run again to resume), 2 bad '
                    'input or a node failed, 130 interrupted.')
    parser.add_argument('--study', type=Path, required=True,
                        help='study directory (created; one sub-directory per participant)')
    parser.add_argument('--participant', required=True,
                        help='pseudonymous participant id (1-32 letters, digits, _ or -)')
    parser.add_argument('--drive-file', type=Path, default=DEFAULT_DRIVE_FILE,
                        help='study settings and conditions (default: the shipped '
                             f'{DEFAULT_DRIVE_FILE.name})')
    parser.add_argument('--no-practice', action='store_true',
                        help='a new session starts without the practice drive')
    parser.add_argument('--duration-s', type=positive_seconds, default=None,
                        help="wall time of each drive, s (default: the drive file's)")
    parser.add_argument('--port', type=int, default=None,
                        help="TCP port of the page (0: any free; default: the drive file's)")
    parser.add_argument('--withdraw', action='store_true',
                        help='delete every file of the participant in this study and exit')
    parser.add_argument('--startup-timeout-s', type=positive_seconds, default=60.0,
                        help='how long to wait for the nodes to connect (default: %(default)s)')
    add_params_file_option(parser)
    parser.set_defaults(func=run)
