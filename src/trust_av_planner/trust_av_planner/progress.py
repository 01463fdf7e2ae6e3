"""A dependency-free progress bar for long runs (stderr; silent when stderr is not a TTY
except for a final line, so CI logs stay short)."""

from __future__ import annotations

import sys
import time
from typing import TextIO


class ProgressBar:
    """``label [#####.....] 120/600 (20%) 3.1 s``, redrawn at most every 0.1 s."""

    def __init__(self, label: str, total: int, stream: TextIO | None = None) -> None:
        self.label = label
        self.total = max(total, 1)
        self.stream = stream if stream is not None else sys.stderr
        self.interactive = self.stream.isatty()
        self._start = time.monotonic()
        self._drawn = 0.0
        self.done = 0

    def update(self, done: int, total: int | None = None) -> None:
        """Report ``done`` of ``total`` steps."""
        self.done = done
        if total is not None:
            self.total = max(total, 1)
        now = time.monotonic()
        if self.interactive and (now - self._drawn >= 0.1 or done >= self.total):
            self._drawn = now
            self.stream.write('\r' + self._line(now))
            self.stream.flush()

    def close(self) -> None:
        """Finish the bar with a final line."""
        line = self._line(time.monotonic())
        self.stream.write(('\r' if self.interactive else '') + line + '\n')
        self.stream.flush()

    def _line(self, now: float) -> str:
        width = 30
        filled = int(width * self.done / self.total)
        return (f'{self.label} [{"#" * filled}{"." * (width - filled)}] {self.done}/{self.total} '
                f'({100 * self.done // self.total}%) {now - self._start:.1f} s')
