"""The shipped Foxglove layout (``config/foxglove_layout.json``) read back: its panels, the
topics and message paths they name, and its plot panels drawn from a recording to PNG
(matplotlib) through the same message paths, so what the layout shows can be looked at and
tested without Foxglove.

Message paths are the subset of Foxglove's syntax the layout uses:
``/topic.field.field[0].list[:]{key=="name"}.value``: fields, array indices, ``[:]`` (every
element) and equality filters on a field. A string value is plotted as the number it spells,
as Foxglove's Plot panel does (the diagnostics' ``gap_m`` values are ``repr`` of floats).
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from trust_av.errors import TrustAvAppError
from trust_av_common.output_files import OutputFileError, link_refused

__all__ = ['LAYOUT_FILE', 'LayoutError', 'load_layout', 'main', 'parse_path', 'read_series',
           'render_plots']

LAYOUT_FILE = Path(__file__).resolve().parents[1] / 'config' / 'foxglove_layout.json'
"""The shipped layout (the repository's ``config/``; ``share/trust_av/config/`` holds
a copy when installed by colcon)."""

_SEGMENT = re.compile(
    r'\.(?P<field>[A-Za-z_][A-Za-z0-9_]*)'
    r'|\[(?P<index>\d+)\]'
    r'|\[(?P<all>:)\]'
    r'|\{(?P<key>[A-Za-z_][A-Za-z0-9_]*)==(?P<literal>"[^"]*"|-?\d+(?:\.\d+)?|true|false)\}')


class LayoutError(TrustAvAppError):
    """The layout or one of its message paths cannot be read (the message says which)."""


@dataclass(frozen=True)
class MessagePath:
    """A parsed message path: the topic and the steps into its message."""

    text: str
    topic: str
    steps: tuple[tuple[str, Any], ...]

    def values(self, msg: Any) -> list[Any]:
        """Every value the path reaches in ``msg`` (several after ``[:]``).

        Raises:
            LayoutError: a field the message does not have, or an index out of range.
        """
        current = [msg]
        for kind, arg in self.steps:
            following: list[Any] = []
            for item in current:
                if kind == 'field':
                    if not hasattr(item, arg):
                        raise LayoutError(f'{self.text}: no field {arg!r} in '
                                          f'{type(item).__name__}')
                    following.append(getattr(item, arg))
                elif kind == 'index':
                    if arg >= len(item):
                        raise LayoutError(f'{self.text}: index {arg} of a sequence of '
                                          f'{len(item)}')
                    following.append(item[arg])
                elif kind == 'all':
                    following.extend(item)
                else:
                    key, wanted = arg
                    if not hasattr(item, key):
                        raise LayoutError(f'{self.text}: no field {key!r} to filter on in '
                                          f'{type(item).__name__}')
                    if getattr(item, key) == wanted:
                        following.append(item)
            current = following
        return current

    def number(self, msg: Any) -> float:
        """The one number the path reaches in ``msg`` (a plot sample).

        Raises:
            LayoutError: no value, several values, or one that is not a number.
        """
        found = self.values(msg)
        if len(found) != 1:
            raise LayoutError(f'{self.text}: {len(found)} values in one message, expected 1')
        value = found[0]
        if isinstance(value, str):
            try:
                return float(value)
            except ValueError:
                raise LayoutError(f'{self.text}: {value!r} is not a number') from None
        if isinstance(value, (bool, int, float)):
            return float(value)
        raise LayoutError(f'{self.text}: reaches a {type(value).__name__}, not a number')


def parse_path(text: str) -> MessagePath:
    """Parse a Foxglove message path (the subset in the module docstring).

    Raises:
        LayoutError: the path does not start with a topic or has a segment outside the
            subset.
    """
    match = re.match(r'/[A-Za-z0-9_/]+', text)
    if match is None:
        raise LayoutError(f'{text!r}: a message path starts with a topic name')
    steps: list[tuple[str, Any]] = []
    position = match.end()
    while position < len(text):
        segment = _SEGMENT.match(text, position)
        if segment is None:
            raise LayoutError(f'{text!r}: cannot read the path from position {position}')
        if segment['field'] is not None:
            steps.append(('field', segment['field']))
        elif segment['index'] is not None:
            steps.append(('index', int(segment['index'])))
        elif segment['all'] is not None:
            steps.append(('all', None))
        else:
            steps.append(('filter', (segment['key'], _literal(segment['literal']))))
        position = segment.end()
    return MessagePath(text, match.group(0), tuple(steps))


def _literal(text: str) -> Any:
    if text.startswith('"'):
        return text[1:-1]
    if text in ('true', 'false'):
        return text == 'true'
    return float(text) if '.' in text else int(text)


@dataclass(frozen=True)
class PlotSeries:
    """One line of a plot panel: its message path, legend label and whether it is shown."""

    path: MessagePath
    label: str
    enabled: bool


@dataclass(frozen=True)
class PlotPanel:
    """A Plot panel of the layout: its title and lines."""

    panel_id: str
    title: str
    series: tuple[PlotSeries, ...]


@dataclass(frozen=True)
class Layout:
    """What the layout names: plot panels, 3D-panel topics and the frame it follows."""

    plots: tuple[PlotPanel, ...]
    scene_topics: tuple[str, ...]
    follow_frames: tuple[str, ...]

    @property
    def topics(self) -> set[str]:
        """Every topic the layout reads."""
        return ({s.path.topic for p in self.plots for s in p.series} | set(self.scene_topics))


def load_layout(path: Path = LAYOUT_FILE) -> Layout:
    """Read a Foxglove layout file.

    Raises:
        LayoutError: unreadable JSON, a plot line without a label, or a bad message path.
    """
    try:
        data = json.loads(path.read_text())
        panels: dict[str, Any] = data['configById']
    except (OSError, ValueError, KeyError, TypeError) as err:
        raise LayoutError(f'{path}: not a Foxglove layout ({err})') from err
    plots, scene_topics, follow = [], [], []
    for panel_id, config in panels.items():
        kind = panel_id.split('!')[0]
        if kind == 'Plot':
            series = []
            for line in config['paths']:
                if not line.get('label'):
                    raise LayoutError(f'{path}: {panel_id}: {line["value"]} has no label')
                series.append(PlotSeries(parse_path(line['value']), line['label'],
                                         bool(line.get('enabled', True))))
            plots.append(PlotPanel(panel_id, config.get('foxglovePanelTitle', panel_id),
                                   tuple(series)))
        elif kind == '3D':
            scene_topics += [t for t, c in config.get('topics', {}).items() if c.get('visible')]
            if config.get('followTf'):
                follow.append(config['followTf'])
    return Layout(tuple(plots), tuple(scene_topics), tuple(follow))


def read_series(bag: Path, paths: Iterable[MessagePath]) -> dict[str, tuple[list[float],
                                                                             list[float]]]:
    """Each path's samples in a recording: (log times in s from the first message, values).

    Raises:
        LayoutError: a path's topic is not in the recording, or a message lacks the path.
    """
    from rosbags.highlevel import AnyReader

    from trust_av.graph.bag_records import TYPESTORE

    wanted = list(paths)
    out: dict[str, tuple[list[float], list[float]]] = {p.text: ([], []) for p in wanted}
    try:
        reader = AnyReader([bag], default_typestore=TYPESTORE)
        reader.open()
    except Exception as err:  # rosbags raises several unrelated types for a bad file
        raise LayoutError(f'{bag}: cannot read the recording ({err})') from err
    try:
        present = {c.topic for c in reader.connections}
        missing = sorted({p.topic for p in wanted} - present)
        if missing:
            raise LayoutError(f'{bag}: no topic {", ".join(missing)} in the recording')
        start = reader.start_time
        topics = {p.topic for p in wanted}
        connections = [c for c in reader.connections if c.topic in topics]
        for connection, log_time, raw in reader.messages(connections=connections):
            msg = reader.deserialize(raw, connection.msgtype)
            for path in wanted:
                if path.topic == connection.topic:
                    times, values = out[path.text]
                    times.append((log_time - start) * 1e-9)
                    values.append(path.number(msg))
    finally:
        reader.close()
    return out


def render_plots(bag: Path, png: Path, layout: Layout | None = None, dpi: int = 110) -> None:
    """Draw the layout's plot panels from a recording into one PNG, one axis per panel,
    every line with its label (dotted and marked: a line the layout leaves switched off)."""
    from trust_av.study.plots import pyplot, save_figure

    plt = pyplot()

    layout = layout if layout is not None else load_layout()
    series = read_series(bag, [s.path for p in layout.plots for s in p.series])
    fig, axes = plt.subplots(len(layout.plots), 1, figsize=(10, 2.6 * len(layout.plots)),
                             sharex=True, squeeze=False)
    for ax, panel in zip(axes[:, 0], layout.plots, strict=True):
        for line in panel.series:
            times, values = series[line.path.text]
            label = line.label if line.enabled else f'{line.label} [off by default]'
            ax.plot(times, values, linewidth=1.0, label=label,
                    linestyle='-' if line.enabled else ':')
        ax.set_title(panel.title, fontsize=9)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc='best')
    axes[-1, 0].set_xlabel('time since the first message (s)')
    fig.suptitle(f'Foxglove layout plot panels: {bag.name}', fontsize=10)
    fig.tight_layout()
    save_figure(fig, png, dpi=dpi)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    """``python -m trust_av.study.layout_plots BAG PNG``: the layout's plot panels
    of a recording as one PNG; a bad recording or layout gives one line and exit code 2."""
    parser = argparse.ArgumentParser(
        prog='python -m trust_av.study.layout_plots',
        description="Draw the Foxglove layout's plot panels from a recording into a PNG.")
    parser.add_argument('bag', type=Path, help='recording (rosbag2 bag directory or MCAP)')
    parser.add_argument('png', type=Path, help='PNG to write')
    parser.add_argument('--layout', type=Path, default=LAYOUT_FILE, help='Foxglove layout')
    parser.add_argument('--dpi', type=int, default=110, help='resolution of the PNG')
    args = parser.parse_args(argv)
    refused = link_refused(args.png)      # before reading the recording
    if refused is not None:
        print(f'error: {args.png}: {refused}', file=sys.stderr)
        return 2
    try:
        render_plots(args.bag, args.png, load_layout(args.layout), args.dpi)
    except (TrustAvAppError, OutputFileError) as err:
        print(f'error: {err}', file=sys.stderr)
        return 2
    return 0


if __name__ == '__main__':
    sys.exit(main())
