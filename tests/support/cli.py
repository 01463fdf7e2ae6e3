"""`trust-av` run in-process, as a command's test reads it: exit code and stderr."""

from __future__ import annotations

import contextlib
import io

from trust_av.cli.main import main


def trust_av(*argv: str) -> tuple[int, str]:
    """``main(argv)`` in-process: its exit code (argparse's too) and stderr."""
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            code = main(list(argv))
        except SystemExit as exit_:
            code = int(exit_.code or 0)
    return code, err.getvalue()


def one_line(err: str) -> str:
    """The single line a failed command printed (fails on a traceback or more lines)."""
    lines = [line for line in err.splitlines() if line.strip() and ': ' in line
             and not line.startswith('simulate ')]
    assert 'Traceback' not in err, err
    assert len(lines) == 1, err
    return lines[0]
