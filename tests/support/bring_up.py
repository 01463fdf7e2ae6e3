"""The bring-up commands of the operations and tutorial pages, run as printed on an install.

There is no ``ros2`` command here, so ``ros2 run PKG EXE ARGS`` is run the way ros2run runs
it (``ros2/ros2cli``, ``ros2run/api/__init__.py``: ``get_executable_path`` takes the package's
prefix from the ament index and the executable from ``<prefix>/lib/PKG``, then runs it with
``ARGS``): bash reads the printed line (its quoting, its comments, its continuations) with
``ros2`` a shell function that execs that executable with the arguments bash made.
``ros2 lifecycle set NODE TRANSITION`` is a ``change_state`` call on the test's side.
"""

from __future__ import annotations

import contextlib
import os
import queue
import re
import signal
import subprocess
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

from support.paths import REPO
from support.processes import hangup_by_default

PAGES = sorted((REPO / 'docs' / 'operations').glob('*.md')) + \
    sorted((REPO / 'docs' / 'tutorials').glob('*.md'))
FENCE = re.compile(r'^```(?P<lang>[a-z]*)(?P<attrs>[^\n]*)\n(?P<body>.*?)^```\s*$',
                   re.MULTILINE | re.DOTALL)
TITLE = re.compile(r'title="([^"]+)"')
TRANSITIONS = {'configure': 1, 'cleanup': 2, 'activate': 3, 'deactivate': 4}
"""``lifecycle_msgs/msg/Transition`` ids of the labels ``ros2 lifecycle set`` takes."""


@dataclass(frozen=True)
class Command:
    """One ``ros2 ...`` command of a page: its logical line as printed (continuations kept)."""

    page: str
    line: int
    text: str

    @property
    def words(self) -> list[str]:
        return self.text.replace('\\\n', ' ').split('#', 1)[0].split()


def commands(page: Path) -> tuple[list[Command], dict[str, str]]:
    """The ``ros2`` commands of ``page``'s bash blocks in order, and the files its titled
    blocks give (name -> content)."""
    text = page.read_text(encoding='utf-8')
    found: list[Command] = []
    files: dict[str, str] = {}
    for match in FENCE.finditer(text):
        title = TITLE.search(match['attrs'])
        if title:
            files[title.group(1)] = match['body']
        if match['lang'] != 'bash':
            continue
        first = text.count('\n', 0, match.start('body')) + 1
        logical = re.split(r'(?<!\\)\n', match['body'])
        at = first
        for line in logical:
            if line.startswith('ros2 '):
                found.append(Command(page.name, at, line))
            at += line.count('\n') + 1
    return found, files


def executable(install: Path, package: str, name: str) -> Path:
    """``<prefix>/lib/<package>/<name>`` of the package's prefix in the install, as ros2run
    finds it (the prefix that has the package's ament index marker)."""
    index = Path('share') / 'ament_index' / 'resource_index' / 'packages' / package
    prefixes = [p for p in install.iterdir() if (p / index).is_file()]
    assert len(prefixes) == 1, f'package {package} not (or twice) in {install}'
    path = prefixes[0] / 'lib' / package / name
    assert os.access(path, os.X_OK), f'`ros2 run {package} {name}` would fail: no {path}'
    return path


class Process:
    """A documented ``ros2 run`` line running in its own session; its output line by line."""

    def __init__(self, install: Path, command: Command, cwd: Path, env: dict[str, str]) -> None:
        words = command.words
        assert words[:2] == ['ros2', 'run'], command
        self.command = command
        exe = executable(install, words[2], words[3])
        script = (f'source {install / "setup.bash"} && '
                  f'ros2() {{ shift 3; exec {exe} "$@"; }}\n{command.text}\n')
        self.popen = subprocess.Popen(['bash', '-c', script], stdout=subprocess.PIPE,
                                      stderr=subprocess.STDOUT, text=True, env=env, cwd=cwd,
                                      start_new_session=True, preexec_fn=hangup_by_default)
        self.lines: list[str] = []
        self._queue: queue.Queue[str] = queue.Queue()
        assert self.popen.stdout is not None
        self._reader = threading.Thread(
            target=lambda out=self.popen.stdout: [self._queue.put(x) for x in out], daemon=True)
        self._reader.start()

    def output(self) -> str:
        return ''.join(self.lines)

    def wait_for(self, seen: Callable[[str], bool], timeout_s: float = 90.0) -> str:
        """The first output line ``seen`` accepts (read as it comes); fails if the process
        ends or nothing comes in ``timeout_s``."""
        for line in self.lines:
            if seen(line):
                return line
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            try:
                line = self._queue.get(timeout=0.2)
            except queue.Empty:
                assert self.popen.poll() is None, (
                    f'{self.command.page}:{self.command.line}: exit {self.popen.returncode}\n'
                    + self.output())
                continue
            self.lines.append(line)
            if seen(line):
                return line
        raise AssertionError(f'{self.command.page}:{self.command.line}: not seen in '
                             f'{timeout_s:g} s\n' + self.output())

    def stop(self) -> int:
        """Ctrl-C, as in the node's terminal; its exit code (all its output read)."""
        with contextlib.suppress(ProcessLookupError):
            os.killpg(self.popen.pid, signal.SIGINT)
        code = self.popen.wait(timeout=60)
        self._reader.join(timeout=10)
        while not self._queue.empty():
            self.lines.append(self._queue.get())
        return code


@contextlib.contextmanager
def started(install: Path, cmds: list[Command], cwd: Path,
            env: dict[str, str]) -> Iterator[list[Process]]:
    """Each ``ros2 run`` of ``cmds`` as its own process (as in its own terminal); all stopped
    at the end (exit 0, no traceback)."""
    processes: list[Process] = []
    try:
        for command in cmds:
            processes.append(Process(install, command, cwd, env))
        yield processes
    finally:
        codes = [process.stop() for process in processes]
    for process, code in zip(processes, codes, strict=True):
        where = f'{process.command.page}:{process.command.line}'
        assert code == 0, f'{where}: exit {code}\n' + process.output()
        assert 'Traceback' not in process.output(), where + '\n' + process.output()
