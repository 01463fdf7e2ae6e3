"""A private ROS domain per run.

Each run leases a free ``ROS_DOMAIN_ID`` with an exclusive lock file, so parallel runs,
tests and CI of one user never share a domain; before it is used, the domain is checked for
participants that are not ours (another user's run, any other ROS 2 process on this
machine: discovery is localhost-only) and skipped if it has any.

The lock files live in a per-user directory (``$XDG_RUNTIME_DIR`` or the temporary
directory, ``trust_av_domains-<uid>``, mode 0700), opened without following symbolic links:
no other user can take every lock, and a planted link cannot make a run write through it.
A directory that is a link, or owned by someone else, is refused with one line.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import random
import stat
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

from trust_av.errors import TrustAvAppError
from trust_av.graph.processes import GraphError
from trust_av_common.rcl_values import TOPIC_NAME_MAX, namespace_problem
from trust_av_common.topics import TOPICS, qualified

__all__ = ['DOMAIN_ID_MAX', 'check_domain_id', 'check_namespace', 'domain_ports_in_use',
           'lease_domain']

DOMAIN_ID_MAX = 232
"""The largest ROS domain id Fast DDS (Jazzy's rmw_fastrtps) can use: it derives every UDP
port from the domain id (RTPS port mapping, ``include/fastdds/rtps/common/PortParameters.h``
and ``src/cpp/rtps/network/NetworkFactory.cpp: calculate_well_known_port``: 7400 + 250 *
domain + offset, the process exits when that exceeds 65535; 7400 + 250 * 233 = 65650)."""
RTPS_PORT_BASE = 7400
RTPS_DOMAIN_GAIN = 250
"""DDS-RTPS 2.5, 9.6.1.1: every port of domain d is PB + DG * d + offset + PG * participant
(PB 7400, DG 250; offsets 0, 1, 10, 11; PG 2), so [PB + DG*d, PB + DG*(d+1)) is domain
d's block. Fast DDS (rmw_fastrtps, also for LOCALHOST discovery) binds its unicast
discovery and user ports there; so does any other RTPS implementation on its defaults."""
UDP_TABLES = (Path('/proc/net/udp'), Path('/proc/net/udp6'))


def domain_ports_in_use(domain: int, tables: tuple[Path, ...] = UDP_TABLES) -> list[int] | None:
    """The UDP ports of ``domain``'s RTPS port block that a socket on this host has bound
    (from the kernel's socket tables), or None when no table can be read."""
    low = RTPS_PORT_BASE + RTPS_DOMAIN_GAIN * domain
    found: set[int] = set()
    read_any = False
    for table in tables:
        try:
            lines = table.read_text().splitlines()[1:]
        except OSError:
            continue
        read_any = True
        for line in lines:
            fields = line.split()
            if len(fields) > 1 and ':' in fields[1]:
                port = int(fields[1].rsplit(':', 1)[1], 16)
                if low <= port < low + RTPS_DOMAIN_GAIN:
                    found.add(port)
    return sorted(found) if read_any else None


DOMAIN_RANGE = range(1, 102)
"""ROS domain ids leased to runs (Fast DDS: 0-232 are valid; 1-101 avoid the defaults)."""
RANGE_ENV = 'TRUST_AV_DOMAIN_RANGE'
"""``first-last`` (e.g. ``120-130``): lease only from these domain ids instead."""


def domain_range() -> range:
    """The domain ids runs may lease: :data:`RANGE_ENV` if set, else :data:`DOMAIN_RANGE`.

    Raises:
        GraphError: the variable is not ``first-last`` with 0 <= first <= last <= 232.
    """
    text = os.environ.get(RANGE_ENV, '')
    if not text:
        return DOMAIN_RANGE
    first, _, last = text.partition('-')
    try:
        low, high = int(first), int(last or first)
    except ValueError:
        low = high = -1
    if not 0 <= low <= high <= DOMAIN_ID_MAX:
        raise GraphError(f'{RANGE_ENV}={text!r}: expected first-last domain ids in '
                         f'0..{DOMAIN_ID_MAX}')
    return range(low, high + 1)


def check_domain_id(domain_id: object, option: str = 'domain_id') -> int:
    """``domain_id`` if it is a ROS domain id Fast DDS can use (0..:data:`DOMAIN_ID_MAX`).

    Raises:
        TrustAvAppError: it is not a whole number in that range (one line naming
            ``option``).
    """
    if isinstance(domain_id, bool) or not isinstance(domain_id, int) or \
            not 0 <= domain_id <= DOMAIN_ID_MAX:
        raise TrustAvAppError(f'{option} {domain_id!r}: a ROS domain id is a whole number '
                              f'in 0..{DOMAIN_ID_MAX} (Fast DDS derives its UDP ports '
                              'from it)')
    return domain_id


def check_namespace(namespace: object, option: str = 'namespace') -> str:
    """``namespace`` if a whole graph can run in it: a valid ROS 2 node namespace (rmw
    ``validate_namespace.c: rmw_validate_namespace``, which rcl's ``rcl_node_init`` applies:
    absolute, ``/`` alone or tokens of ``[A-Za-z0-9_]`` not starting with a digit, no
    repeated or trailing ``/``, at most 245 characters) whose every topic of the table is a
    valid full topic name (rmw ``validate_full_topic_name.c``: at most 247 characters).

    Raises:
        TrustAvAppError: it is not (one line naming ``option`` and rmw's reason).
    """
    if not isinstance(namespace, str):
        raise TrustAvAppError(f'{option} {namespace!r}: a ROS namespace is a string')
    problem = namespace_problem(namespace)
    if problem is None:
        longest = max((qualified(t.name, namespace) for t in TOPICS), key=len)
        if len(longest) > TOPIC_NAME_MAX:
            problem = (f"topic {longest[:40]}... would be longer than rmw's "
                       f'{TOPIC_NAME_MAX} characters')
    if problem is not None:
        raise TrustAvAppError(f'{option} {namespace!r}: {problem}')
    return namespace


def lock_dir() -> Path:
    """This user's lease directory: ``$XDG_RUNTIME_DIR/trust_av_domains-<uid>`` when that
    runtime directory exists and is the user's own, else in the temporary directory."""
    runtime = os.environ.get('XDG_RUNTIME_DIR', '')
    base = Path(tempfile.gettempdir())
    if runtime:
        with contextlib.suppress(OSError):
            info = os.stat(runtime)
            if stat.S_ISDIR(info.st_mode) and info.st_uid == os.getuid():
                base = Path(runtime)
    return base / f'trust_av_domains-{os.getuid()}'


def secure_lock_dir(path: Path) -> Path:
    """Create ``path`` (mode 0700) or check an existing one: a real directory, owned by the
    current user, not readable or writable by others (tightened to 0700 if it is).

    Raises:
        GraphError: ``path`` is a link or not a directory, or belongs to another user.
    """
    with contextlib.suppress(FileExistsError):
        os.mkdir(path, 0o700)
    info = os.lstat(path)
    if stat.S_ISLNK(info.st_mode) or not stat.S_ISDIR(info.st_mode):
        raise GraphError(f'{path}: the domain lease directory is not a directory (a symbolic '
                         'link?); remove it')
    if info.st_uid != os.getuid():
        raise GraphError(f'{path}: the domain lease directory belongs to uid {info.st_uid}, '
                         f'not to you (uid {os.getuid()}); remove it or set TMPDIR')
    if info.st_mode & 0o077:
        os.chmod(path, 0o700)
    return path


def _open_lock(path: Path) -> int:
    """Open (create) a lock file without following a link; never truncates.

    Raises:
        GraphError: the lock file is a symbolic link or cannot be opened.
    """
    try:
        return os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, 0o600)
    except OSError as err:
        if err.errno == errno.ELOOP:
            raise GraphError(f'{path}: a lease file is a symbolic link; refusing to write '
                             'through it (remove it)') from err
        raise GraphError(f'{path}: cannot open the lease file ({err.strerror})') from err


@contextlib.contextmanager
def lease_domain(foreign: Callable[[int], str] | None = None,
                 directory: Path | None = None) -> Iterator[int]:
    """Hold an exclusive lease on a free, private ROS domain id for the duration of a run.

    Args:
        foreign: called with a leased domain id before it is used; returns '' when the
            domain has no participants of others, else a description of them (the domain
            is then skipped).
        directory: the lease directory (default :func:`lock_dir`).

    Raises:
        GraphError: the lease directory is unsafe, or no domain is free and private.
    """
    root = secure_lock_dir(directory or lock_dir())
    skipped: list[str] = []
    domains = domain_range()
    # Start at a random place: runs of other users (other lease directories) then rarely
    # probe the same domain at the same moment.
    start = random.randrange(len(domains))
    for domain in [*domains[start:], *domains[:start]]:
        fd = _open_lock(root / f'{domain}.lock')
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            continue
        try:
            others = foreign(domain) if foreign is not None else ''
            if others:
                skipped.append(f'{domain} ({others})')
                continue
            yield domain
            return
        finally:
            fcntl.flock(fd, fcntl.LOCK_UN)
            os.close(fd)
    detail = f'; not private: {", ".join(skipped[:3])}' if skipped else ''
    raise GraphError(f'no free ROS domain id in {domains.start}..{domains.stop - 1}{detail}')
