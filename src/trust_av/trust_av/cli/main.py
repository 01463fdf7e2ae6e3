"""``trust-av``: the project's command line.

Each subcommand lives in its own module that exposes ``register(subparsers)``; the module
adds its parser, built from the command's options dataclass, and sets ``func(args) -> int``
on it, which builds the typed options from the namespace and runs the command
(:mod:`trust_av.cli.typed_options`).
Every project error derives from :class:`~trust_av_common.errors.TrustAvError`; one
becomes one line on stderr and exit
code 2.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import signal
import sys

from trust_av.cli.parser import Parser
from trust_av.cli.typed_options import check_parser
from trust_av.graph import stop_signals
from trust_av_common.errors import TrustAvError, one_line

__all__ = ['build_parser', 'main']

COMMAND_MODULES = (
    'trust_av.cli.simulate',
    'trust_av.cli.run',
    'trust_av.cli.shadow',
    'trust_av.cli.drive',
    'trust_av.cli.reproduce',
    'trust_av.cli.compare',
    'trust_av.cli.bags',
    'trust_av.cli.repair_bag',
    'trust_av.cli.train_gru',
    'trust_av.cli.fit_driver',
    'trust_av.cli.eval_driver',
    'trust_av.cli.fit_trust',
    'trust_av.cli.design',
)
"""Modules that add a subcommand (in help order)."""


def build_parser() -> argparse.ArgumentParser:
    """The ``trust-av`` parser with every registered subcommand."""
    parser = Parser(
        prog='trust-av',
        description='Trust-aware longitudinal control of an automated vehicle followed by a '
                    'human driver (Ozkan & Ma): simulate the closed loop, run the ROS 2 graph, '
                    'reproduce the paper.')
    parser.add_argument('-v', '--verbose', action='store_true', help='log solver details')
    subparsers = parser.add_subparsers(dest='command', required=True, metavar='COMMAND')
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(subparsers)
    for command in subparsers.choices.values():
        check_parser(command)      # each option is a field of the command's options
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``trust-av``.

    Returns:
        0 done; 2 bad input or a failed run (one line on stderr); 128 + the signal number
        when stopped by SIGINT (130), SIGTERM (143) or SIGHUP (129), after everything started was
        stopped and every recording finished.
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.WARNING,
                        format='%(levelname)s %(name)s: %(message)s')
    # Ctrl-C, SIGTERM and SIGHUP raise Stopped: long commands stop what they started and finish
    # their files on the way out.
    with stop_signals.installed():
        try:
            code = int(args.func(args))
            # one that was not raised, or (a success after a stop) one that was swallowed
            stop_signals.deliver_pending(working=code == 0)
            return code
        except TrustAvError as err:
            say(f'trust-av {args.command}: error: {one_line(err)}')
            return 2
        except KeyboardInterrupt as err:
            # Everything started has been stopped and every recording finished on the way.
            signum = err.signum if isinstance(err, stop_signals.Stopped) else signal.SIGINT
            what = 'interrupted' if signum == signal.SIGINT else \
                f'stopped by {signal.Signals(signum).name}'
            say(f'trust-av {args.command}: {what}; everything it started was stopped and '
                'its recordings finished')
            return 128 + int(signum)


def say(line: str) -> None:
    """``line`` and its newline on stderr in one write: with ``PYTHONUNBUFFERED`` print's two
    writes can be split by another process writing to the same stderr (a child's
    multiprocessing resource tracker warning at exit), and the line is no longer one line."""
    sys.stderr.write(line + '\n')
    sys.stderr.flush()


if __name__ == '__main__':
    sys.exit(main())
