"""Helpers for tests of the study (``trust_av.study``)."""

from __future__ import annotations

from trust_av.study import sweep
from trust_av.study.sweep import Case

__all__ = ['InlineExecutor']


class InlineExecutor:
    """Runs cases in this process (a test's study needs no worker pool) and remembers which
    it was asked to run."""

    def __init__(self) -> None:
        self.ran: list[Case] = []

    def run(self, cases, params_file, on_result,  # type: ignore[no-untyped-def]
            settings=None) -> None:
        for case in cases:
            self.ran.append(case)
            on_result(case, sweep.run_case(case, params_file, settings or sweep.RunSettings()))
