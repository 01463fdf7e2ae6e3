"""``trust-av``: the project's command line (simulate, and the commands other modules add).

Each subcommand lives in its own module that exposes ``register(subparsers)``; the module
adds its parser and sets ``func(args) -> int`` on it. The project's errors for bad input
become one line on stderr and exit code 2: :class:`~trust_monitor.params.ParamsError`,
:class:`~preceding_traffic.traces.TraceError` and
:class:`~trust_av_planner.errors.TrustAvError` (and its subclasses).
"""

from __future__ import annotations

import argparse
import importlib
import logging
import signal
import sys

from preceding_traffic.traces import TraceError
from trust_av_planner.errors import TrustAvError
from trust_monitor.params import ParamsError

COMMAND_MODULES = (
    'trust_av_planner.cmd_simulate',
    'trust_av_planner.cmd_run',
    'trust_av_planner.cmd_shadow',
    'trust_av_planner.cmd_reproduce',
    'trust_av_planner.cmd_bags',
    'trust_av_planner.cmd_train_gru',
    'trust_av_planner.cmd_fit_driver',
    'trust_av_planner.cmd_eval_driver',
)
"""Modules that add a subcommand (in help order)."""


def build_parser() -> argparse.ArgumentParser:
    """The ``trust-av`` parser with every registered subcommand."""
    parser = argparse.ArgumentParser(
        prog='trust-av',
        description='Trust-aware longitudinal control of an automated vehicle followed by a '
                    'human driver (Ozkan & Ma): simulate the closed loop, run the ROS 2 graph, '
                    'reproduce the paper.')
    parser.add_argument('-v', '--verbose', action='store_true', help='log solver details')
    subparsers = parser.add_subparsers(dest='command', required=True, metavar='COMMAND')
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``trust-av``."""
    parser = build_parser()
    args = parser.parse_args(argv)
    # Ctrl-C must always reach us (a background start inherits SIGINT as ignored): long
    # commands stop what they started and finish their files on the way out.
    signal.signal(signal.SIGINT, signal.default_int_handler)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.WARNING,
                        format='%(levelname)s %(name)s: %(message)s')
    try:
        return int(args.func(args))
    except (ParamsError, TraceError, TrustAvError) as err:
        print(f'trust-av {args.command}: error: {err}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        # Everything started has been stopped and every recording finished on the way out.
        print(f'trust-av {args.command}: interrupted', file=sys.stderr)
        return 130


if __name__ == '__main__':
    sys.exit(main())
