"""The browser tier's shared fixture: one headless Debian Chromium per test."""

from __future__ import annotations

import sys
from collections.abc import Iterator
from typing import Any

import pytest
from support.paths import REPO

sys.path.insert(0, str(REPO / 'benchmarks'))
from synthetic_participant import CHROMIUM, CHROMIUM_ARGS


@pytest.fixture
def browser() -> Iterator[Any]:
    from playwright.sync_api import sync_playwright
    with sync_playwright() as playwright:
        chromium = playwright.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        try:
            yield chromium
        finally:
            chromium.close()
