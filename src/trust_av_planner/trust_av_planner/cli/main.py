"""``trust-av``: the project's command line.

Each subcommand lives in its own module that exposes ``register(subparsers)``; the module
adds its parser and sets ``func(args) -> int`` on it. The four packages' errors (each
package has one base class: :class:`~trust_monitor.errors.TrustMonitorError`,
:class:`~preceding_traffic.errors.PrecedingTrafficError`,
:class:`~human_driver_sim.errors.HumanDriverSimError`,
:class:`~trust_av_planner.errors.TrustAvPlannerError`) become one line on stderr and exit
code 2.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import signal
import sys

from human_driver_sim.errors import HumanDriverSimError
from preceding_traffic.errors import PrecedingTrafficError
from trust_av_planner.errors import TrustAvPlannerError
from trust_monitor.errors import TrustMonitorError

COMMAND_MODULES = (
    'trust_av_planner.cli.simulate',
    'trust_av_planner.cli.run',
    'trust_av_planner.cli.shadow',
    'trust_av_planner.cli.reproduce',
    'trust_av_planner.cli.bags',
    'trust_av_planner.cli.repair_bag',
    'trust_av_planner.cli.train_gru',
    'trust_av_planner.cli.fit_driver',
    'trust_av_planner.cli.eval_driver',
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


class Stopped(KeyboardInterrupt):
    """A stop signal other than SIGINT (SIGTERM, as ``timeout``, ``docker stop`` and systemd
    send it): raised like Ctrl-C so that every command takes the same way out."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def _stop(signum: int, _frame: object) -> None:
    raise Stopped(signum)


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``trust-av``.

    Returns:
        0 done; 2 bad input or a failed run (one line on stderr); 128 + the signal number
        when stopped by SIGINT (130) or SIGTERM (143), after everything started was
        stopped and every recording finished.
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    # Ctrl-C must always reach us (a background start inherits SIGINT as ignored), and
    # SIGTERM takes the same way: long commands stop what they started and finish their
    # files on the way out.
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, _stop)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.WARNING,
                        format='%(levelname)s %(name)s: %(message)s')
    try:
        return int(args.func(args))
    except (TrustMonitorError, PrecedingTrafficError, HumanDriverSimError,
            TrustAvPlannerError) as err:
        print(f'trust-av {args.command}: error: {err}', file=sys.stderr)
        return 2
    except KeyboardInterrupt as err:
        # Everything started has been stopped and every recording finished on the way out.
        signum = err.signum if isinstance(err, Stopped) else signal.SIGINT
        what = 'interrupted' if signum == signal.SIGINT else \
            f'stopped by {signal.Signals(signum).name}'
        print(f'trust-av {args.command}: {what}; everything it started was stopped and its '
              'recordings finished', file=sys.stderr)
        return 128 + int(signum)


if __name__ == '__main__':
    sys.exit(main())
