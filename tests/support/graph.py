"""Graph runs started with `trust-av run` and compared with the in-process loop."""

from __future__ import annotations

import dataclasses
import subprocess
import sys
from pathlib import Path

import pytest

from trust_av.system.metrics import StepRecord

from .processes import INTERRUPTED_RUN_STEPS, hangup_by_default, long_trace

STEPS = 120
"""Steps of :func:`run_command`'s run."""


def run_command(bag: Path, *extra: str, plot: bool = False) -> list[str]:
    """``trust-av run`` on US06 (TAC-CA, alpha 0.5); only ``graph_run`` draws the plot."""
    return [sys.executable, '-m', 'trust_av.cli', 'run', '--trace', 'us06',
            '--alpha', '0.5', '--predictor', 'ca', '--max-steps', str(STEPS), '--bag', str(bag),
            '--no-progress', *([] if plot else ['--no-plot']), *extra]


RECORD_TOLERANCE = 1e-7
"""How far a graph value may be from the in-process one. The two paths agree to ~1e-16 per
step (the graph's numbers differ in the last bits; the source is not found), and each
iterative solve returns a point within its termination tolerance, so such a difference can
come out of the NMPC's SQP as ~1e-8 (measured: 1.7e-8 in the AV's plan at t = 39 s of the
60 s TAC-GRU graph run, from inputs 1e-14 apart). 1e-7 is ten times that and far below any
physical difference."""
SOLVER_DETAILS = {'solver_status': 'solver_success', 'solver_iterations': 'solver_success'}
"""How the AV's successful SQP solve got there: the graph's numbers differ from the in-process
ones in the last bits (measured up to ~1e-13), and at a degenerate point (the AV standing at
d_s with a zero plan) that decides whether qrqp reports Solve_Succeeded in 1 iteration or
Search_Direction_Becomes_Too_Small in 2, for the same plan. Success itself and every number
of the plans are compared (the driver's one QP solve has one success status, compared as is)."""


def assert_records_equal(graph: list[StepRecord], ref: list[StepRecord]) -> None:
    assert len(graph) == len(ref)
    for g, r in zip(graph, ref, strict=True):
        for field in dataclasses.fields(StepRecord):
            if 'solve_time' in field.name:
                continue
            success = SOLVER_DETAILS.get(field.name)
            if success is not None and getattr(g, success) and getattr(r, success):
                continue
            a, b = getattr(g, field.name), getattr(r, field.name)
            if isinstance(b, (tuple, float)):
                assert a == pytest.approx(b, abs=RECORD_TOLERANCE), (r.t_s, field.name)
            else:
                assert a == b, (r.t_s, field.name)


def stoppable_run(bag: Path) -> subprocess.Popen[str]:
    """A run of :func:`support.processes.long_trace` (written beside ``bag``) that a test
    stops, in its own process group and with SIGHUP at its default action, as a terminal's
    shell starts it."""
    command = [sys.executable, '-m', 'trust_av.cli', 'run', '--trace',
               str(long_trace(bag.parent)), '--max-steps', str(INTERRUPTED_RUN_STEPS),
               '--bag', str(bag), '--no-progress', '--no-plot']
    return subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True, preexec_fn=hangup_by_default)
