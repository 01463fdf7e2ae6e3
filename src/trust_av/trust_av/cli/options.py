"""Options and output shared by the ``trust-av`` commands: the run options (trace or bag,
alpha, predictor, params file, :class:`RunOptions`) and the argparse types that check values
where they enter, the metrics table, and the progress bar (tqdm). How a command's options
dataclass becomes its parser is :mod:`trust_av.cli.typed_options`."""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path
from types import TracebackType
from typing import Any

from tqdm import tqdm

from human_driver_sim.followers import DRIVERS
from preceding_traffic.traces import SHIPPED_TRACES, SpeedTrace
from trust_av.cli.typed_options import Exclusive, option
from trust_av.errors import TrustAvAppError
from trust_av.graph import stop_signals
from trust_av.system.config import DEFAULT_PARAMS_FILE, RunConfig
from trust_av.system.metrics import Metrics
from trust_av_common import registry
from trust_av_common.output_files import cannot_write, link_refused, odd_path
from trust_av_common.params import field_spec
from trust_av_common.wall_clock import WallClockConfig
from trust_av_planner.nmpc import LEAD_PREVIEWS, PlannerConfig
from trust_av_planner.predictors import PREDICTORS
from trust_monitor.model_interface import trust_ceiling

__all__ = ['BAG_TYPES', 'EXIT_COLLISION', 'MAX_DRIVERS', 'MAX_ITERATIONS', 'MAX_SEED',
           'MAX_WORKERS', 'Progress', 'RunOptions', 'alpha_option', 'alpha_value', 'bounded_int',
           'ceiling_at_end', 'collision_exit', 'format_metrics', 'lead_preview_option',
           'output_file', 'params_files_option', 'positive_hz', 'positive_int',
           'positive_seconds', 'process_age_s', 'steps_value']


def alpha_value(text: str) -> float:
    """argparse type for alpha: a number in the range of ``PlannerConfig.alpha``."""
    try:
        value = float(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(f'alpha must be a number, got {text!r}') from err
    spec = field_spec(PlannerConfig, 'alpha')
    problem = spec.problem('alpha', value) if spec is not None else ''
    if problem:
        raise argparse.ArgumentTypeError(problem)
    return value


class _ParamsFiles(argparse.Action):
    """``--params-file F``, repeatable: ``args.params_files`` is every file in order and
    ``args.params_file`` the last one (the shipped file when none is given)."""

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                 values: object, option_string: str | None = None) -> None:
        files = [*getattr(namespace, 'params_files', []), Path(str(values))]
        namespace.params_files = files
        namespace.params_file = files[-1]


def params_files_option() -> Any:
    """The field ``params_files: tuple[Path, ...]``: ``--params-file``, repeatable, layered
    over the shipped config/trust_av.yaml, every file in order (``params_file`` in the
    namespace is the last one)."""
    return option('--params-file', action=_ParamsFiles, metavar='FILE',
                  also_sets={'params_files': [], 'params_file': DEFAULT_PARAMS_FILE},
                  help='ROS 2 params file layered over the shipped '
                       f'{DEFAULT_PARAMS_FILE.name}; repeat for more layers, later over '
                       "earlier, as a node's --ros-args --params-file layers them "
                       '(a file may hold only the keys it changes)')


def lead_preview_option() -> Any:
    """The field ``lead_preview: str | None``: the planner parameter ``lead_preview``."""
    return option('--lead-preview', choices=LEAD_PREVIEWS, default=None,
                  help="the lead's speed over the horizon: the recorded preview, or "
                       "built from the lead's odometry (default: the params file's)")


def alpha_option() -> Any:
    """The field ``alpha: float | None``: the planner parameter ``alpha``."""
    return option('--alpha', type=alpha_value, default=None,
                  help="explicability weight in [0, 1] (default: the params file's)")


BAG_TYPES = ('nav_msgs/msg/Odometry', 'geometry_msgs/msg/TwistStamped')
"""The message types a lead vehicle's bag topic may have."""
_SOURCE = Exclusive('trace or bag')


@dataclasses.dataclass(frozen=True)
class RunOptions:
    """The options of the commands that run one closed loop, first in their help: each one
    None where the params file's value holds."""

    trace: str | None = option(
        '--trace', default=None, exclusive=_SOURCE,
        help=f'preceding-traffic trace: one of {", ".join(SHIPPED_TRACES)}, a '
             'time_s,speed_mps CSV or a rosbag2 bag '
             "(default: the params file's preceding_traffic.trace)")
    bag_in: Path | None = option(
        '--bag-in', default=None, metavar='BAG', exclusive=_SOURCE,
        help='replay a rosbag2 bag (MCAP or sqlite3 directory or file) as the '
             'preceding vehicle; the same as --trace BAG')
    bag_topic: str | None = option(
        '--bag-topic', default=None,
        help="the preceding vehicle's topic in the bag (default: the params "
             "file's preceding_traffic.bag_topic)")
    bag_type: str | None = option(
        '--bag-type', default=None, choices=BAG_TYPES,
        help='its message type (default: preceding_traffic.bag_message_type)')
    alpha: float | None = alpha_option()
    predictor: str | None = option(
        '--predictor', choices=lambda: registry.names(PREDICTORS), default=None,
        help='registered estimator of the plan the human expects (default: '
             "the params file's predictor)")
    driver_model: str | None = option(
        '--driver-model', choices=lambda: registry.names(DRIVERS), default=None,
        help="registered human follower model (default: the params file's "
             'human_driver.driver_model)')
    lead_preview: str | None = lead_preview_option()
    params_files: tuple[Path, ...] = params_files_option()
    no_progress: bool = option('--no-progress', help='no progress bar')

    def overrides(self) -> dict[str, dict[str, object]]:
        """Params-file overrides from the options given."""
        planner: dict[str, object] = {}
        if self.lead_preview is not None:
            planner['lead_preview'] = self.lead_preview
        if self.alpha is not None:
            planner['alpha'] = self.alpha
        if self.predictor is not None:
            planner['predictor'] = self.predictor
        traffic: dict[str, object] = {}
        if self.trace is not None:
            traffic['trace'] = self.trace
        if self.bag_in is not None:
            traffic['trace'] = str(self.bag_in)
        if self.bag_topic is not None:
            traffic['bag_topic'] = self.bag_topic
        if self.bag_type is not None:
            traffic['bag_message_type'] = self.bag_type
        driver: dict[str, object] = {}
        if self.driver_model is not None:
            driver['driver_model'] = self.driver_model
        return {'planner': planner, 'preceding_traffic': traffic, 'human_driver': driver}


MAX_STEPS = 10_000_000
"""``--max-steps`` at most: 116 days at the paper's 1 Hz, 11.6 days at 10 Hz; every shipped
trace is far shorter and a bag's stamps end at 2^31 s."""
MAX_WORKERS = 256
"""``--workers`` and ``--jobs`` at most (processes on one machine or Ray cluster)."""
MAX_DRIVERS = 1000
"""``reproduce --drivers`` at most: every case runs once per driver (1000 drivers x 40
cases of US06 is about a CPU-day)."""
MAX_ITERATIONS = 100_000
"""``--epochs``, ``--dagger-rounds`` and ``--iterations`` at most."""
MAX_SEED = 2**32 - 1
"""Seeds are 0 .. 2^32 - 1 (what numpy's and torch's generators take)."""


def bounded_int(option: str, minimum: int, maximum: int,
                meaning: str = '') -> Callable[[str], int]:
    """argparse type: a whole number in ``minimum .. maximum`` (one line naming ``option``
    otherwise).

    Args:
        option: the option, for messages.
        minimum: the smallest value allowed.
        maximum: the largest value allowed (a documented maximum).
        meaning: what the smallest value means, e.g. ``'0: the whole trace'``.
    """
    def value_of(text: str) -> int:
        try:
            value = int(text, 10)
        except ValueError as err:
            raise argparse.ArgumentTypeError(f'{option} must be a whole number, got '
                                             f'{text!r}') from err
        if value < minimum:
            note = f' ({meaning})' if meaning else ''
            raise argparse.ArgumentTypeError(f'{option} must be >= {minimum}{note}, got '
                                             f'{value}')
        if value > maximum:
            raise argparse.ArgumentTypeError(f'{option} must be <= {maximum}, got {value}')
        return value
    return value_of


steps_value = bounded_int('--max-steps', 0, MAX_STEPS, '0: the whole trace')
"""argparse type for ``--max-steps``: a whole number in 0 .. :data:`MAX_STEPS`."""


def output_file(path: Path, option: str = '--out') -> Path:
    """Check, before any work, that ``path`` can be written as a file.

    Raises:
        TrustAvAppError: ``path`` is odd (a NUL or newline in it, ``.``), a symbolic
            link (:func:`~trust_av_common.output_files.link_refused`), a directory, or
            its nearest existing ancestor is not a writable directory.
    """
    odd = odd_path(path)
    if odd is not None:
        raise TrustAvAppError(f'{option} {str(path)!r}: {odd}')
    refused = link_refused(path)
    if refused is not None:
        raise TrustAvAppError(f'{option} {path}: {refused}')
    if path.is_dir():
        raise TrustAvAppError(f'{path}: is a directory; {option} needs a file name')
    ancestor = path.parent
    while not ancestor.exists() and ancestor != ancestor.parent:
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise TrustAvAppError(f'{path}: {ancestor} is not a directory')
    problem = cannot_write(path, ancestor)
    if problem is not None:
        raise TrustAvAppError(f'{path}: {problem}')
    return path


def positive_hz(text: str) -> float:
    """argparse type: a rate in Hz, > 0 and at most ``control_rate_hz``'s maximum."""
    try:
        value = float(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(f'expected a rate in Hz, got {text!r}') from err
    if not value > 0.0 or value == float('inf'):
        raise argparse.ArgumentTypeError(f'must be a finite rate > 0 Hz, got {text!r}')
    spec = field_spec(WallClockConfig, 'control_rate_hz')
    if spec is not None and spec.high is not None and value > spec.high:
        raise argparse.ArgumentTypeError(f'must be <= {spec.high:g} Hz, got {text!r}')
    return value


def positive_seconds(text: str) -> float:
    """argparse type: a number > 0."""
    try:
        value = float(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(f'expected a number of seconds, got {text!r}') from err
    if not value > 0.0:
        raise argparse.ArgumentTypeError(f'must be > 0, got {text!r}')
    return value


def positive_int(text: str) -> int:
    """argparse type: a whole number in 1 .. :data:`MAX_WORKERS` (a count of workers, jobs)."""
    try:
        value = int(text, 10)
    except ValueError as err:
        raise argparse.ArgumentTypeError(f'expected a whole number, got {text!r}') from err
    if value < 1:
        raise argparse.ArgumentTypeError(f'must be >= 1, got {text!r}')
    if value > MAX_WORKERS:
        raise argparse.ArgumentTypeError(f'must be <= {MAX_WORKERS}, got {text!r}')
    return value


EXIT_COLLISION = 3
"""Exit status of a run that ended in a collision (a gap at or below 0 m): the run itself
worked and its outputs are complete, but what it simulated is no car following."""


def _figure(value: float, spec: str) -> str:
    """A summary figure, or ``none`` for a value that does not exist (NaN, inf)."""
    return format(value, spec) if math.isfinite(value) else 'none (not finite)'


def format_metrics(metrics: Metrics, title: str, *,
                   trust_ceiling: float | None = None) -> str:
    """The metrics table printed at the end of a run; a figure computed from no finite value
    reads ``none``, and the last row says ``collision`` and where, or ``none``.
    ``trust_ceiling`` (the trust model's declared T(0) + delta * t over the run, see
    :func:`ceiling_at_end`) is shown under the final trust when given."""
    crash = metrics.collision
    ceiling = [] if trust_ceiling is None else [
        ('trust ceiling T(0) + delta*t', f'{trust_ceiling:.3f}')]
    rows = [('steps', f'{metrics.steps}'),
            ('final trust', _figure(metrics.final_trust, '.3f')),
            *ceiling,
            ('mean explicability E', _figure(metrics.mean_explicability, '.5f')),
            ('prediction RMSE (m/s^2)', _figure(metrics.rmse_mps2, '.4f')),
            ('min AV gap (m)', _figure(metrics.min_av_gap_m, '.3f')),
            ('min human gap (m)', _figure(metrics.min_human_gap_m, '.3f')),
            ('NMPC fallback steps', f'{metrics.fallback_steps}'),
            ('driver fallback steps', f'{metrics.driver_fallback_steps}'),
            ('unsafe steps (gap < d_s - margin)', f'{metrics.unsafe_steps}'),
            ('collision', 'none' if crash is None else crash.short())]
    width = max(len(k) for k, _ in rows)
    lines = [title, '-' * (width + 14)]
    lines += [f'{k:<{width}}  {v:>12}' for k, v in rows]
    return '\n'.join(lines)


def collision_exit(metrics: Metrics, command: str) -> int:
    """After the summary: 0, or for a run that collided its one line on stderr and
    :data:`EXIT_COLLISION`."""
    if metrics.collision is None:
        return 0
    print(f'trust-av {command}: {metrics.collision.line()}', file=sys.stderr)
    return EXIT_COLLISION


def ceiling_at_end(config: RunConfig, trace: SpeedTrace) -> float | None:
    """The most trust the configured trust model can reach on ``trace``, T(0) + delta * t
    at its end, from the ceiling the model declares
    (:func:`~trust_monitor.model_interface.trust_ceiling`); None when it declares none."""
    ceiling = trust_ceiling(config.trust_model())
    if ceiling is None:
        return None
    return ceiling[0] + ceiling[1] * trace.steps * trace.dt_s


def process_age_s() -> float:
    """How long this process has run, s (Linux's /proc; 0.0 where it cannot be read): what a
    command's timings add to its own clock for Python's start-up and imports."""
    try:
        with open('/proc/self/stat', encoding='ascii') as stat, \
                open('/proc/uptime', encoding='ascii') as uptime:
            started_ticks = int(stat.read().rsplit(')', 1)[1].split()[19])
            return max(0.0, float(uptime.read().split()[0])
                       - started_ticks / os.sysconf('SC_CLK_TCK'))
    except (OSError, ValueError, IndexError):
        return 0.0


class Progress:
    """A progress bar on stderr (tqdm) fed with absolute counts (``update(done, total)``, the
    ``on_step`` callback of the runners). On a terminal it is redrawn at most every 0.1 s;
    when stderr is not a terminal (CI logs) only one final line is written. Each update
    also raises a stop signal that arrived where Python could not raise it
    (:func:`~trust_av.graph.stop_signals.deliver_pending`), shown or not.

    Args:
        label: what is counted, e.g. ``simulate us06``.
        total: the expected count.
        shown: False writes nothing (``--no-progress``).
        timed: the final line gives the elapsed time (False: the command prints its own
            timings, which this one would not agree with).
    """

    def __init__(self, label: str, total: int, *, shown: bool = True,
                 timed: bool = True) -> None:
        self.label = label
        self.shown = shown
        self.timed = timed
        self.interactive = shown and sys.stderr.isatty()
        self._start = time.monotonic()
        self._bar = tqdm(total=max(total, 1), desc=label, unit='step', mininterval=0.1,
                         disable=not self.interactive, leave=True)
        self.done = 0
        self.total = max(total, 1)

    def update(self, done: int, total: int | None = None) -> None:
        """Report ``done`` of ``total`` items."""
        stop_signals.deliver_pending(working=True)
        self.done = done
        if total is not None and total != self.total:
            self.total = max(total, 1)
            self._bar.total = self.total
        self._bar.update(done - self._bar.n)

    def close(self) -> None:
        """Finish the bar (a final line when shown and stderr is not a terminal)."""
        self._bar.close()
        if self.shown and not self.interactive:
            elapsed = time.monotonic() - self._start
            timing = f' in {elapsed:.1f} s' if self.timed else ' steps'
            print(f'{self.label}: {self.done}/{self.total}{timing}', file=sys.stderr)

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 trace: TracebackType | None) -> None:
        self.close()
