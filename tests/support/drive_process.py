"""``trust-av drive`` run as a participant's experimenter runs it, for the browser tests."""

from __future__ import annotations

import os
import queue
import re
import subprocess
import sys
import threading
from pathlib import Path

__all__ = ['Drive']


class Drive:
    """``trust-av drive`` in a subprocess; its output lines in a queue."""

    def __init__(self, study: Path, participant: str, settings: Path,
                 practice: bool = False) -> None:
        self.lines: queue.Queue[str] = queue.Queue()
        self.output: list[str] = []
        self.process = subprocess.Popen(
            [sys.executable, '-m', 'trust_av.cli', 'drive', '--study', str(study),
             '--participant', participant, '--drive-file', str(settings),
             *([] if practice else ['--no-practice'])],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
            env={**os.environ, 'PYTHONUNBUFFERED': '1'})
        threading.Thread(target=self._read, daemon=True).start()
        self.url = self.wait_for(r'open (http://\S+)').group(1)

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            self.lines.put(line)

    def wait_for(self, pattern: str, timeout_s: float = 120.0) -> re.Match[str]:
        while True:
            try:
                line = self.lines.get(timeout=timeout_s)
            except queue.Empty:
                raise AssertionError(f'no line matching {pattern!r}; output so far:\n'
                                     + ''.join(self.output)) from None
            self.output.append(line)
            found = re.search(pattern, line)
            if found:
                return found

    def finish(self, timeout_s: float = 120.0) -> str:
        code = self.process.wait(timeout=timeout_s)
        while not self.lines.empty():
            self.output.append(self.lines.get())
        text = ''.join(self.output)
        assert code == 0, text
        return text

    def kill(self) -> None:
        if self.process.poll() is None:
            self.process.terminate()
            self.process.wait(timeout=60)
