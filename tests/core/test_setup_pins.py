"""What the set-up (scripts/bootstrap.sh) relies on when it installs requirements.txt: the
pins are the whole closure at their versions (pip --no-deps resolves nothing), and no two
pinned wheels install the same file (two pip processes install every other pin each, side by
side, into one environment)."""

from __future__ import annotations

import collections
import importlib.metadata
import re

from packaging.specifiers import SpecifierSet
from packaging.utils import canonicalize_name
from packaging.version import Version
from support.paths import REPO

PIN = re.compile(r'^([A-Za-z0-9][A-Za-z0-9._-]*)==(\S+)$')


def pins() -> dict[str, str]:
    found = {}
    for line in (REPO / 'requirements.txt').read_text().splitlines():
        match = PIN.match(line.strip())
        if match:
            found[canonicalize_name(match[1])] = match[2]
    return found


def test_every_pin_is_installed_at_its_version() -> None:
    wanted = pins()
    assert len(wanted) > 150
    installed = {canonicalize_name(d.metadata['Name']): d.version
                 for d in importlib.metadata.distributions()}
    wrong = {name: (version, installed.get(name)) for name, version in wanted.items()
             if name not in installed        # PEP 440: ==2.13.0 takes 2.13.0+cpu
             or Version(installed[name]) not in SpecifierSet(f'=={version}')}
    assert not wrong, f'pinned vs installed: {wrong}'


def test_no_two_pinned_wheels_install_the_same_file() -> None:
    wanted = pins()
    owners: dict[str, set[str]] = collections.defaultdict(set)
    seen = set()
    for dist in importlib.metadata.distributions():
        name = canonicalize_name(dist.metadata['Name'])
        # the wheel's own record; an .egg-info a ROS wheel carries lists its sources
        if name not in wanted or not dist.read_text('RECORD'):
            continue
        seen.add(name)
        for path in dist.files or ():
            if '__pycache__' not in path.parts:
                owners[str(path)].add(name)
    assert len(seen) > 150
    shared = {path: sorted(names) for path, names in owners.items() if len(names) > 1}
    assert not shared, f'installed by more than one pinned wheel: {shared}'
