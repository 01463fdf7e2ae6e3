"""What a newcomer's first runs print: the trust ceiling beside the final trust, timings that
add up, a truncated study saying so wherever it meets the paper, and a study's safety
warnings naming their case, one per run, summarised once."""

from __future__ import annotations

import logging
import re
from pathlib import Path

import pytest

from preceding_traffic.sources import load_trace
from preceding_traffic.traces import truncate
from trust_av.cli.main import main
from trust_av.cli.options import Progress, ceiling_at_end, format_metrics
from trust_av.cli.reproduce import truncation_note, unsafe_cases
from trust_av.study.sweep import Case
from trust_av.system.closed_loop import simulate
from trust_av.system.config import load_run_config


def test_the_summary_names_the_ceiling() -> None:
    config = load_run_config()
    trace = load_trace('us06', config.planner.dt_s, config.trace)
    ceiling = ceiling_at_end(config, trace)
    assert ceiling == pytest.approx(60.0)                  # T(0) = 0, delta = 0.1/s, 600 s
    metrics = simulate(config, truncate(trace, 3)).metrics
    table = format_metrics(metrics, 'x', trust_ceiling=ceiling_at_end(config, truncate(trace, 3)))
    assert re.search(r'^trust ceiling T\(0\) \+ delta\*t +0\.300$', table, re.MULTILINE)
    assert 'ceiling' not in format_metrics(metrics, 'x')


def test_a_bar_that_leaves_timing_to_its_command(capsys: pytest.CaptureFixture[str]) -> None:
    with Progress('graph us06', 4, timed=False) as bar:
        bar.update(4)
    assert capsys.readouterr().err == 'graph us06: 4/4 steps\n'


def test_a_truncated_study_says_so_in_every_comparison(tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    assert truncation_note(0, 1.0, [600]) == '' and truncation_note(600, 1.0, [600]) == ''
    note = truncation_note(30, 1.0, [600, 598])
    assert note.startswith('TRUNCATED: --max-steps 30 stopped each run after 30 s of 600 s')
    out = tmp_path / 'quick'
    assert main(['reproduce', '--predictors', 'ca', '--traces', 'us06', '--alphas', '0,1',
                 '--max-steps', '3', '--results-dir', str(out), '--no-progress']) == 0
    printed = capsys.readouterr().out
    assert printed.count('TRUNCATED: --max-steps 3 ') == 3    # above each table, at the end
    for table in ('table_III_tac_ca_us06.md', 'table_IV_max_improvements.md'):
        assert (out / table).read_text().startswith('**TRUNCATED: --max-steps 3 ')


def test_safety_warnings_name_their_case_once(caplog: pytest.LogCaptureFixture) -> None:
    config = load_run_config(overrides={'human_driver': {'driver_model': 'idm'}})
    trace = truncate(load_trace('us06', config.planner.dt_s, config.trace), 60)
    with caplog.at_level(logging.WARNING):
        result = simulate(config, trace)
    assert result.metrics.unsafe_steps > 0            # the textbook IDM closes in at the start
    (line,) = [r.getMessage() for r in caplog.records if 'safety minimum' in r.getMessage()]
    assert line.startswith('us06, TAC-CA, alpha = 0.5, idm follower: gap below the safety '
                           f'minimum 4.50 m at {result.metrics.unsafe_steps} steps')
    every = {Case('us06', 'ca', 0.5, driver_model='idm'): {'metrics': {'unsafe_steps': 7}},
             Case('us06', 'ca', 0.0): {'metrics': {'unsafe_steps': 0}}}
    assert unsafe_cases(every) == ('gap below the safety minimum in 1 of 2 cases (unsafe steps '
                                   'in all_runs.csv): us06 ca alpha 0.5 idm (7 steps)')
