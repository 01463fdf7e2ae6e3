"""A private ROS domain per run: each run leases a free ``ROS_DOMAIN_ID`` with a lock file,
so parallel runs, tests and CI never hear each other."""

from __future__ import annotations

import contextlib
import fcntl
import tempfile
from collections.abc import Iterator
from pathlib import Path

from trust_av_planner.graph.processes import GraphError

DOMAIN_RANGE = range(1, 102)
"""ROS domain ids leased to runs (Fast DDS: 0-232 are valid; 1-101 avoid the defaults)."""
LOCK_DIR = Path(tempfile.gettempdir()) / 'trust_av_domains'


@contextlib.contextmanager
def lease_domain() -> Iterator[int]:
    """Hold an exclusive lock on a free ROS domain id for the duration of a run."""
    LOCK_DIR.mkdir(parents=True, exist_ok=True)
    for domain in DOMAIN_RANGE:
        handle = (LOCK_DIR / f'{domain}.lock').open('w')
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            handle.close()
            continue
        try:
            yield domain
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)
            handle.close()
        return
    raise GraphError(f'no free ROS domain id in {DOMAIN_RANGE.start}..{DOMAIN_RANGE.stop - 1}')
