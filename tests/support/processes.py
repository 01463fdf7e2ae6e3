"""Graph runs seen from outside: their processes, their growing bags, long traces for runs
a test stops midway."""

from __future__ import annotations

import signal
import subprocess
import time
from pathlib import Path


def hangup_by_default() -> None:
    """``preexec_fn`` for a command a test starts as a terminal's shell would: SIGHUP at its
    default action. A suite started under ``nohup`` passes SIGHUP on as ignored, and trust-av
    and its nodes honour that (they outlive a closed terminal as asked), so a test of a
    closed terminal would see nothing happen."""
    signal.signal(signal.SIGHUP, signal.SIG_DFL)


def assert_every_topic_complete(bag: Path) -> int:
    """Every recorded topic of the table holds every complete step, the topics within one
    step of each other (a topic absent from the bag holds none); returns the number of
    complete steps.

    Step k is complete with the vehicles' odometry and tf at stamp k, which the plants
    publish at the end of step k - 1 (stamp 0: the initial state, before the first step). So
    these topics run ahead: complete stamps when the run stopped before the plants finished
    the last complete step, complete + 1 once they had, complete + 2 when they had also
    finished the next step, which the other nodes had not.
    """
    from trust_av.graph.bag_records import read_topics, records_from_bag  # rosbags
    from trust_av_common.topics import TOPICS
    topics = read_topics(bag)
    complete = len(records_from_bag(bag))
    bad = {}
    for row in TOPICS:
        if 'recorder' in row.subscribers:
            name = row.name if row.name.startswith('/') else f'/{row.name}'
            stamps = len(topics.get(name, {}))
            ahead = name in ('/ego/odom', '/human/odom', '/tf')
            low, high = (complete, complete + 2) if ahead else (complete, complete + 1)
            if not low <= stamps <= high:
                bad[name] = (stamps, (low, high))
    assert not bad, f'{complete} complete steps; topics outside their range: {bad}'
    return complete


def recorded_chunks(mcap: Path) -> int:
    """Chunks written so far to a growing MCAP (the recorder writes one chunk per step), read
    with mcap's stream reader up to the first incomplete record."""
    import struct

    from mcap.exceptions import McapError
    from mcap.records import Chunk
    from mcap.stream_reader import StreamReader

    chunks = 0
    try:
        with mcap.open('rb') as stream:
            for record in StreamReader(stream, emit_chunks=True).records:
                chunks += isinstance(record, Chunk)
    except FileNotFoundError:
        return 0                # not created yet
    except (McapError, struct.error):
        pass                    # the file ends mid-record while it is written: count so far
    return chunks


def wait_for_steps(bag: Path, steps: int, proc: subprocess.Popen[str] | None = None,
                   timeout_s: float = 120.0) -> None:
    """Wait until the run recording the bag directory ``bag`` holds ``steps`` steps (MCAP
    chunks); fail if ``proc`` (the run) ends first or the time runs out."""
    mcap = bag / f'{bag.name}.mcap'
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and recorded_chunks(mcap) < steps:
        assert proc is None or proc.poll() is None, proc.communicate()
        time.sleep(0.1)
    assert recorded_chunks(mcap) >= steps, f'{mcap}: fewer than {steps} steps in {timeout_s:g} s'


INTERRUPTED_RUN_STEPS = 3000
"""Steps of :func:`long_trace`: a run a test stops midway must not be able to finish first."""


def long_trace(directory: Path) -> Path:
    """A 3000-step CSV trace (a smooth 5-15 m/s profile, 1 s steps) in ``directory``, for
    runs that a test interrupts, kills or intrudes on after some recorded steps. With US06
    (600 steps) a run could step through all of them before the stop arrived on a loaded
    machine, where the recorder lags the graph (seen with four busy processes beside the
    SIGINT test: all 600 steps recorded after waiting for 150), and the test would then not
    test an interruption."""
    import math

    path = directory / 'long.csv'
    path.write_text('time_s,speed_mps\n' + ''.join(
        f'{t},{10.0 + 5.0 * math.sin(t / 30.0):.3f}\n'
        for t in range(INTERRUPTED_RUN_STEPS + 1)))
    return path


def children_of(pid: int) -> list[int]:
    """Every live process whose parent is ``pid``."""
    found = []
    for entry in Path('/proc').iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / 'stat').read_text().rsplit(')', 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == pid and fields[0] != 'Z':
                found.append(int(entry.name))
    return found


def wait_ready(process: subprocess.Popen[str]) -> None:
    """Read ``process``'s stdout up to its ``ready`` line; Fast DDS may log a transport
    error there first (seen: ``RTPS_TRANSPORT_SHM Error ... open_and_lock_file failed``).
    If it ends without one, it is killed and the lines are the assertion's message (a
    helper that raised with its process alive left an intruder on the domain for the next
    tests)."""
    assert process.stdout is not None
    lines = [process.stdout.readline()]
    while lines[-1] not in ('ready\n', ''):
        lines.append(process.stdout.readline())
    if lines[-1] != 'ready\n':
        process.kill()
        process.wait()
        raise AssertionError(f'no ready line: {lines}')
