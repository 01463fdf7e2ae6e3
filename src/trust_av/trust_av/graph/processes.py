"""The node processes of one run: started as ``python -m <node module> --ros-args ...``
(exactly what ``ros2 run`` would start), each in its own process group. When the
orchestrator dies, even by SIGKILL, its nodes stop as on SIGTERM (the parent check of
:func:`trust_av_common.ros.spin.spin_node`; ``PR_SET_PDEATHSIG`` continues a node that was
stopped by a signal, so that it makes that check too), so the recorder still finishes its bag
and no process is left. A node stopped by a signal is continued with every stop signal it
gets. They are stopped in the order that keeps the
recording complete (the step authority first, the recorder last), each with SIGINT, then
SIGTERM, then SIGKILL after grace periods."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from collections.abc import MutableMapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

from trust_av.errors import TrustAvAppError
from trust_av.graph import stop_signals
from trust_av_common.param_layers import node_fqn, shipped_params_file, to_params_text

__all__ = ['DDS_PROFILE', 'PROFILE_VARIABLES', 'RECORDER', 'Graph', 'GraphError', 'NodeSpec',
           'use_run_discovery']

GRACE_S = {'SIGINT': 10.0, 'SIGTERM': 3.0}
"""How long a group of nodes has to exit after each signal before the next, s. A node's own
stop takes about 1.5 s on an idle host (what is queued for 0.3 s, its subscribers'
acknowledgements for at most 1 s, then rclpy's teardown: trust_av_common.ros.spin); on a
2-core host loaded by a whole test suite a node took longer than 8 s and was killed, so
SIGINT is given 10 s. A second stop signal to trust-av moves on to the next rung at once."""


class GraphError(TrustAvAppError):
    """The graph could not start or a node died; the message names the node."""


@dataclass(frozen=True)
class NodeSpec:
    """One node process."""

    name: str
    module: str
    params: dict[str, Any]


STEP_AUTHORITY = 'preceding_traffic'
PROFILE_ENV = 'TRUST_AV_PROFILE_DIR'
"""If set, every node runs under cProfile and writes ``<dir>/<node>.prof`` when it stops
(``python -m pstats``, snakeviz; benchmarks/bench_graph.py --profile-dir)."""
RECORDER = 'recorder'
DDS_PROFILE = 'fastdds_graph.xml'
"""The Fast DDS participant profile of a run (config/fastdds_graph.xml: discovery timing
for a graph whose participants start within seconds of each other; the file says why)."""
PROFILE_VARIABLES = ('FASTRTPS_DEFAULT_PROFILES_FILE', 'FASTDDS_DEFAULT_PROFILES_FILE')
"""Where Fast DDS looks for a profiles file (2.x reads the first; 3.x the second)."""


def use_run_discovery(env: MutableMapping[str, str]) -> None:
    """Set the discovery settings every participant of a run gets in ``env``: ROS 2's
    LOCALHOST range (this machine only) and the shipped Fast DDS profile, unless the user
    names a profiles file of their own (theirs is kept, untouched).

    Raises:
        GraphError: the shipped profile is missing (Fast DDS would log an error and go on
            with its defaults: a run that connects seconds later, for no visible reason).
    """
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    if not any(env.get(name) for name in PROFILE_VARIABLES):
        profile = shipped_params_file(DDS_PROFILE)
        if not profile.is_file():
            raise GraphError(f'the Fast DDS profile {profile} is missing (a broken install?)')
        env['FASTRTPS_DEFAULT_PROFILES_FILE'] = str(profile)


@dataclass
class Process:
    """A started node."""

    spec: NodeSpec
    popen: subprocess.Popen[bytes]
    log_path: Path
    log: IO[bytes]

    def tail(self, lines: int = 6) -> str:
        """The last lines of the node's output, on one line (`` | `` between them), and
        where the whole output is."""
        if not self.log.closed:
            self.log.flush()
        text = [line.strip() for line in self.log_path.read_text(errors='replace').splitlines()
                if line.strip()]
        return f"last output ({self.log_path}): {' | '.join(text[-lines:]) or 'none'}"

    def state(self) -> str:
        """The kernel's one-letter state of the process (``/proc/PID/stat``: R running, S
        sleeping, D waiting for a disk, T/t stopped by a signal or a debugger); '' once it is
        gone."""
        try:
            stat = Path(f'/proc/{self.popen.pid}/stat').read_text()
        except OSError:
            return ''
        fields = stat.rsplit(')', 1)[-1].split()
        return fields[0] if fields else ''

    def exit_message(self, code: int) -> str:
        """Why the node exited with ``code``: its own one-line refusal (``spin_node``: exit 2
        and an ``error:`` line, e.g. a plug-in that broke its interface), else the code and
        its last output."""
        line = self.error_line() if code == 2 else ''
        if line:
            return f'node {self.spec.name}: {line}'
        return (f'node {self.spec.name} exited with code {code}'
                f'{" (killed by signal " + str(-code) + ")" if code < 0 else ""}; '
                f'{self.tail()}')

    def error_line(self) -> str:
        """The node's last ``error: ...`` line ('' if none)."""
        if not self.log.closed:
            self.log.flush()
        lines = self.log_path.read_text(errors='replace').splitlines()
        return next((line[len('error: '):] for line in reversed(lines)
                     if line.startswith('error: ')), '')


class Graph:
    """The processes of one run."""

    def __init__(self, specs: list[NodeSpec], params_files: Sequence[Path], domain: int,
                 log_dir: Path, namespace: str = '/') -> None:
        self.specs = specs
        self.params_files = tuple(params_files)
        self.domain = domain
        self.log_dir = log_dir
        self.namespace = namespace
        self.processes: list[Process] = []
        from trust_av_common.ros.spin import PARENT_ENV  # rclpy: only when a graph starts

        self.env = dict(os.environ, ROS_DOMAIN_ID=str(domain),
                        RMW_IMPLEMENTATION='rmw_fastrtps_cpp', PYTHONUNBUFFERED='1',
                        ROS_LOG_DIR=str(log_dir / 'ros'), **{PARENT_ENV: str(os.getpid())})
        use_run_discovery(self.env)
        # One BLAS thread per node unless the user set it (trust_av.cli says why).
        self.env.setdefault('OPENBLAS_NUM_THREADS', '1')

    def start(self) -> None:
        """Start every node process.

        Every node gets the run's params files in the same order (layers: the shipped file
        first), then one more file with the per-run values, one section per node under its
        fully qualified name: written after everything else, it wins over the same key in
        the user's files (``-p`` would not: rcl lets a node's own section win over a
        command-line ``-p``); written by :func:`~trust_av_common.param_layers.
        to_params_text`, so rcl reads back exactly these values and types.
        """
        run_params = self.log_dir / 'run_params.yaml'
        try:
            self.log_dir.mkdir(parents=True, exist_ok=True)
            run_params.write_text(to_params_text(
                {node_fqn(self.namespace, spec.name): spec.params
                 for spec in self.specs if spec.params}))
        except OSError as err:
            raise GraphError(f'{self.log_dir}: cannot write the node logs and per-run '
                             f'parameters there ({err.strerror})') from err
        layers = [arg for path in self.params_files for arg in ('--params-file', str(path))]
        profile_dir = os.environ.get(PROFILE_ENV)
        for spec in self.specs:
            profiler = ([] if not profile_dir else
                        ['-m', 'cProfile', '-o', str(Path(profile_dir) / f'{spec.name}.prof')])
            command = [sys.executable, *profiler, '-m', spec.module, '--ros-args', '-r',
                       f'__node:={spec.name}', '-r', f'__ns:={self.namespace}', *layers,
                       '--params-file', str(run_params)]
            log_path = self.log_dir / f'{spec.name}.log'
            try:
                log = log_path.open('wb')
            except OSError as err:
                raise GraphError(f'{log_path}: cannot write the node log ({err.strerror})') \
                    from err
            popen = subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT,
                                     stdin=subprocess.DEVNULL, env=self.env,
                                     start_new_session=True,
                                     preexec_fn=stop_signals.continue_with_parent)
            self.processes.append(Process(spec, popen, log_path, log))

    def by_name(self, name: str) -> Process:
        """The process of a node."""
        return next(p for p in self.processes if p.spec.name == name)

    def suspended(self) -> list[str]:
        """The nodes stopped by a signal (SIGSTOP, SIGTSTP) or a debugger."""
        return [p.spec.name for p in self.processes if p.state() in ('T', 't')]

    def check_alive(self, allowed_done: set[str]) -> None:
        """Raise :class:`GraphError` naming a node that exited when it should not have."""
        for process in self.processes:
            code = process.popen.poll()
            if code is None:
                continue
            if process.spec.name in allowed_done and code == 0:
                continue
            raise GraphError(process.exit_message(code))

    def stop(self, names: list[str] | None = None) -> None:
        """Stop nodes: while the recorder still runs, first the step authority (no new step
        starts), then the other nodes (each takes what is queued and waits until the recorder
        has acknowledged its messages), then the recorder (it finishes the bag); once the
        recorder is gone, all at once. Each group: SIGINT, then SIGTERM, then SIGKILL after
        grace periods; a stop signal to this process meanwhile moves on to the next one at
        once, and none interrupts the stop (:func:`stop_signals.stopping`)."""
        with stop_signals.stopping():   # further signals escalate this stop, never end it
            self._stop(names)

    def _stop(self, names: list[str] | None) -> None:
        targets = [p for p in self.processes if names is None or p.spec.name in names]
        recorder = [p for p in targets if p.spec.name == RECORDER and p.popen.poll() is None]
        if recorder:
            first = [p for p in targets if p.spec.name == STEP_AUTHORITY]
            rest = [p for p in targets if p not in first and p not in recorder]
            groups = [first, rest, recorder]
        else:
            groups = [targets]
        for group in groups:
            _stop_group(group, recorder=group is not targets and group == recorder)
        for process in targets:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(process.popen.pid, signal.SIGKILL)  # stray children of the group
            process.log.close()


STOP_LADDER = ((signal.SIGINT, GRACE_S['SIGINT']), (signal.SIGTERM, GRACE_S['SIGTERM']),
               (signal.SIGKILL, 5.0))
"""The signals a group of nodes gets, each after the previous one's grace period, s."""


def _stop_group(group: list[Process], recorder: bool = False) -> None:
    """Stop a group of nodes along :data:`STOP_LADDER`; every further stop signal this process
    gets meanwhile (:func:`stop_signals.escalations`) moves on to the next rung at once, and
    a group stopped after two of them starts at SIGKILL; the ``recorder`` is first given
    SIGTERM and its grace period to finish the bag (a signal during that grace kills it,
    and the bag is then repaired from its chunks). Returns once every node is gone."""
    rung = min(stop_signals.escalations(), 1 if recorder else len(STOP_LADDER) - 1)
    while rung < len(STOP_LADDER):
        sig, grace = STOP_LADDER[rung]
        alive = [p for p in group if p.popen.poll() is None]
        if not alive:
            break
        for process in alive:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(process.popen.pid, sig)
                os.killpg(process.popen.pid, signal.SIGCONT)  # a stopped node takes it too
        seen = stop_signals.escalations()
        deadline = time.monotonic() + grace
        while (time.monotonic() < deadline and stop_signals.escalations() == seen
               and any(p.popen.poll() is None for p in alive)):
            time.sleep(0.02)
        rung += 1
    for process in group:
        if process.popen.poll() is None:
            process.popen.wait()
