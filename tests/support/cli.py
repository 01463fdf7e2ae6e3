"""`trust-av` and `trust-monitor-estimate` run in-process, as a command's test reads them:
exit code, stdout and stderr (no interpreter start per case; a test of the process boundary
itself starts the real process)."""

from __future__ import annotations

import contextlib
import io
from collections.abc import Callable
from dataclasses import dataclass

from trust_av.cli.main import main
from trust_monitor.estimate import main as estimate_main


@dataclass(frozen=True)
class Ran:
    """What a command run in-process left: as ``subprocess.CompletedProcess`` names it."""

    returncode: int
    stdout: str
    stderr: str


def run_main(entry: Callable[[list[str]], int], *argv: str) -> Ran:
    """``entry(argv)`` in-process: its exit code (argparse's too), stdout and stderr."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
        try:
            code = entry(list(argv))
        except SystemExit as exit_:
            code = exit_.code if isinstance(exit_.code, int) else int(exit_.code is not None)
    return Ran(code, out.getvalue(), err.getvalue())


def trust_av(*argv: str) -> tuple[int, str]:
    """``main(argv)`` in-process: its exit code (argparse's too) and stderr."""
    ran = run_main(main, *argv)
    return ran.returncode, ran.stderr


def trust_av_run(*argv: str) -> Ran:
    """``trust-av argv`` in-process: exit code, stdout and stderr."""
    return run_main(main, *argv)


def estimate_run(*argv: str) -> Ran:
    """``trust-monitor-estimate argv`` in-process: exit code, stdout and stderr."""
    return run_main(estimate_main, *argv)


def one_line(err: str) -> str:
    """The single line a failed command printed (fails on a traceback or more lines)."""
    lines = [line for line in err.splitlines() if line.strip() and ': ' in line
             and not line.startswith('simulate ')]
    assert 'Traceback' not in err, err
    assert len(lines) == 1, err
    return lines[0]
