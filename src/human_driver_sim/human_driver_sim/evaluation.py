"""Scoring car-following models on recorded pairs: protocol, scores, confidence intervals.

Protocol (docs/DRIVER_IRL.md, "Protocol"): a model follows the recorded leader from a
recorded state, integrated with explicit Euler on the control step exactly as the MPC
predicts and the simulator moves (``kinematics.step``; the speed stops at 0):

* ``full``: from each segment's first sample to its end (open loop, drift included);
* ``window``: re-initialised to the recorded gap and speed every ``window_s`` (30 s).

The driver MPC's v_max is the leader's highest speed over the pair, the paper's rule
v_max = max(v_PT) for the trace followed (Table I; the simulator's ``speed_max_from_trace``).

Per pair (all segments and windows of one leader->follower pair together), the gap NRMSE
is RMSE(gap) / mean recorded gap and the speed NRMSE RMSE(speed) / mean recorded speed
(each mean floored at 0.1, m or m/s: a pair standing still or touching divides by no zero),
over every simulated sample (the re-initialised first samples excluded). Pooled: the mean
over pairs with a 95 % Student-t confidence interval (``trust_av_common.stats``).
Every table carries the data's own noise floor: the follower's *recorded* speed replayed
through the same gap computation.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from human_driver_sim.car_following import FollowingPair
from human_driver_sim.driver_mpc import DriverConfig
from human_driver_sim.driver_qp import BatchDriver
from human_driver_sim.idm import IdmParams, idm_accel_array
from trust_av_common import kinematics
from trust_av_common.stats import mean_ci95

__all__ = ['MIN_WINDOW_STEPS', 'NOISE_FLOOR', 'PROTOCOLS', 'WINDOW_S', 'ConstantSpeed',
           'Evaluation', 'Follower', 'IdmFollower', 'MpcFollower', 'Run', 'cluster_ci95',
           'evaluate', 'format_table', 'make_runs', 'mean_gap_nrmse', 'paired_difference',
           'platoons', 'simulate']

WINDOW_S = 30.0
"""Length of a re-initialised window, s."""
MIN_WINDOW_STEPS = 5
"""A trailing window shorter than this many steps is dropped."""
CLOSE_GAP_M = 2.0
"""Simulated gaps below this are counted ("gaps below 2 m"), m."""
PROTOCOLS = ('full', 'window')
NOISE_FLOOR = 'recorded speed (noise floor)'


class Follower(Protocol):
    """A car-following model: accelerations for many (rows) states at once."""

    def accel(self, gap_m: np.ndarray, speed_mps: np.ndarray, leader_speed_mps: np.ndarray,
              leader_accel_mps2: np.ndarray, speed_max_mps: np.ndarray) -> np.ndarray:
        """Accelerations, m/s^2, one per row (``speed_max_mps``: max(v_PT) of each row's
        leader trace, m/s)."""


class MpcFollower:
    """The driver MPC (eq. 13); the leader's expected plan: constant acceleration at its
    last observed one (as the planner's CA predictor)."""

    def __init__(self, config: DriverConfig) -> None:
        self.driver = BatchDriver(config)
        self._n = config.horizon_steps

    def accel(self, gap_m: np.ndarray, speed_mps: np.ndarray, leader_speed_mps: np.ndarray,
              leader_accel_mps2: np.ndarray, speed_max_mps: np.ndarray) -> np.ndarray:
        """First planned accelerations, m/s^2."""
        expected = np.repeat(np.asarray(leader_accel_mps2, dtype=float)[:, None], self._n, 1)
        return self.driver.plans(gap_m, speed_mps, leader_speed_mps, expected,
                                 speed_max_mps)[:, 0]


class IdmFollower:
    """The Intelligent Driver Model with fixed parameters."""

    def __init__(self, params: IdmParams) -> None:
        self.params = params

    def accel(self, gap_m: np.ndarray, speed_mps: np.ndarray, leader_speed_mps: np.ndarray,
              leader_accel_mps2: np.ndarray, speed_max_mps: np.ndarray) -> np.ndarray:
        """IDM accelerations, m/s^2 (its own desired speed; v_max unused)."""
        return idm_accel_array(self.params, gap_m, speed_mps, leader_speed_mps)


class ConstantSpeed:
    """Keeps its speed (a baseline that knows nothing)."""

    def accel(self, gap_m: np.ndarray, speed_mps: np.ndarray, leader_speed_mps: np.ndarray,
              leader_accel_mps2: np.ndarray, speed_max_mps: np.ndarray) -> np.ndarray:
        """Zeros."""
        return np.zeros(len(gap_m))


@dataclass(frozen=True)
class Run:
    """One simulated stretch: a segment, or a window of one, from a recorded state."""

    key: str
    dt_s: float
    leader_speed_mps: np.ndarray
    gap_m: np.ndarray
    speed_mps: np.ndarray
    leader_accel0_mps2: float
    speed_max_mps: float
    """max(v_PT): the leader's highest speed over the whole pair, m/s."""


def make_runs(pairs: Sequence[FollowingPair], protocol: str,
              window_s: float = WINDOW_S) -> list[Run]:
    """The runs of a protocol (``full`` or ``window``) over the pairs' segments.

    Raises:
        ValueError: Unknown protocol or a window shorter than one step.
    """
    if protocol not in PROTOCOLS:
        raise ValueError(f'unknown protocol {protocol!r} (known: {", ".join(PROTOCOLS)})')
    runs = []
    trace_max: dict[str, float] = {}
    for pair in pairs:
        trace_max[pair.key] = max(trace_max.get(pair.key, 0.0),
                                  float(np.max(pair.leader_speed_mps)))
    for pair in pairs:
        count = len(pair.gap_m)
        if protocol == 'full':
            bounds = [(0, count)]
        else:
            steps = round(window_s / pair.dt_s)
            if steps < 1:
                raise ValueError(f'window {window_s} s is shorter than one step')
            bounds = [(s, min(s + steps + 1, count)) for s in range(0, count - 1, steps)]
            bounds = [b for b in bounds if b[1] - b[0] > MIN_WINDOW_STEPS]
        lead = pair.leader_speed_mps
        for lo, hi in bounds:
            accel0 = (lead[lo] - lead[lo - 1]) / pair.dt_s if lo > 0 else 0.0
            runs.append(Run(pair.key, pair.dt_s, lead[lo:hi], pair.gap_m[lo:hi],
                            pair.follower_speed_mps[lo:hi], float(accel0),
                            max(trace_max[pair.key], 0.1)))
    return runs


def simulate(follower: Follower | None, runs: Sequence[Run]) -> list[tuple[np.ndarray,
                                                                             np.ndarray]]:
    """Simulate every run at once (explicit Euler, speed stops at 0).

    Args:
        follower: The model, or None for the noise floor: the recorded speed replayed.
        runs: From :func:`make_runs`.

    Returns:
        (gap_m, speed_mps) per run, the run's length.
    """
    if not runs:
        return []
    lengths = np.array([len(r.gap_m) for r in runs])
    width = int(lengths.max())
    lead = np.zeros((len(runs), width))
    recorded = np.zeros((len(runs), width))
    for row, run in enumerate(runs):
        lead[row, :lengths[row]] = run.leader_speed_mps
        recorded[row, :lengths[row]] = run.speed_mps
    steps = {r.dt_s for r in runs}
    if len(steps) != 1:
        raise ValueError(f'runs with different steps {sorted(steps)} cannot share a batch')
    dt = steps.pop()
    gap = np.zeros((len(runs), width))
    speed = np.zeros((len(runs), width))
    gap[:, 0] = [r.gap_m[0] for r in runs]
    speed[:, 0] = [r.speed_mps[0] for r in runs]
    accel0 = np.array([r.leader_accel0_mps2 for r in runs])
    speed_max = np.array([r.speed_max_mps for r in runs])
    for k in range(width - 1):
        rows = np.flatnonzero(lengths > k + 1)
        if follower is None:
            accel = (recorded[rows, k + 1] - speed[rows, k]) / dt
        else:
            lead_accel = (accel0[rows] if k == 0
                          else (lead[rows, k] - lead[rows, k - 1]) / dt)
            accel = follower.accel(gap[rows, k], speed[rows, k], lead[rows, k], lead_accel,
                                   speed_max[rows])
        new_gap, new_speed = kinematics.step(gap[rows, k], speed[rows, k], lead[rows, k],
                                               accel, dt)
        gap[rows, k + 1] = new_gap
        speed[rows, k + 1] = np.maximum(new_speed, 0.0)
    return [(gap[row, :n], speed[row, :n]) for row, n in enumerate(lengths)]


@dataclass
class PairScore:
    """Scores of one model on one pair (all its runs of one protocol)."""

    gap_rmse_m: float
    speed_rmse_mps: float
    gap_nrmse: float
    speed_nrmse: float
    min_gap_m: float
    collision: bool
    steps_below_close_gap: int
    steps: int


def score(runs: Sequence[Run], simulated: Sequence[tuple[np.ndarray, np.ndarray]]
          ) -> dict[str, PairScore]:
    """Per pair key: RMSE, NRMSE, closest gap, collisions (gap <= 0), steps below 2 m."""
    grouped: dict[str, list[tuple[Run, np.ndarray, np.ndarray]]] = {}
    for run, (gap, speed) in zip(runs, simulated, strict=True):
        grouped.setdefault(run.key, []).append((run, gap, speed))
    out = {}
    for key, items in grouped.items():
        gap_err = np.concatenate([g[1:] - r.gap_m[1:] for r, g, _ in items])
        speed_err = np.concatenate([s[1:] - r.speed_mps[1:] for r, _, s in items])
        gaps = np.concatenate([g[1:] for _, g, _ in items])
        mean_gap = float(np.mean(np.concatenate([r.gap_m[1:] for r, _, _ in items])))
        mean_speed = float(np.mean(np.concatenate([r.speed_mps[1:] for r, _, _ in items])))
        gap_rmse = float(np.sqrt(np.mean(gap_err ** 2)))
        speed_rmse = float(np.sqrt(np.mean(speed_err ** 2)))
        out[key] = PairScore(gap_rmse, speed_rmse, gap_rmse / max(mean_gap, 0.1),
                             speed_rmse / max(mean_speed, 0.1), float(gaps.min()),
                             bool(gaps.min() <= 0.0), int(np.sum(gaps < CLOSE_GAP_M)),
                             len(gaps))
    return out


def mean_gap_nrmse(follower: Follower, runs: Sequence[Run]) -> float:
    """Mean over pairs of the gap NRMSE (the fitting loss of one data set)."""
    scores = score(runs, simulate(follower, runs))
    return float(np.mean([s.gap_nrmse for s in scores.values()]))


@dataclass
class Evaluation:
    """Scores of several models on one set of pairs, per protocol."""

    pairs: list[str]
    per_pair: dict[str, dict[str, dict[str, PairScore]]] = field(default_factory=dict)
    """protocol -> model -> pair key -> scores."""

    def pooled(self, protocol: str, model: str) -> dict[str, Any]:
        """Mean and 95 % CI half-width over pairs, collisions, close-gap steps."""
        scores = list(self.per_pair[protocol][model].values())
        gap = mean_ci95([s.gap_nrmse for s in scores])
        speed = mean_ci95([s.speed_nrmse for s in scores])
        return {'gap_nrmse': gap[0], 'gap_nrmse_ci95': gap[1], 'speed_nrmse': speed[0],
                'speed_nrmse_ci95': speed[1], 'gap_rmse_m': float(np.mean(
                    [s.gap_rmse_m for s in scores])),
                'collisions': sum(s.collision for s in scores),
                'steps_below_2m': sum(s.steps_below_close_gap for s in scores),
                'min_gap_m': min(s.min_gap_m for s in scores), 'pairs': len(scores)}

    def to_dict(self, *, per_pair: bool = True) -> dict[str, object]:
        """JSON-ready: pooled scores, and per-pair scores unless ``per_pair`` is False."""
        out: dict[str, object] = {'pairs': self.pairs}
        for protocol, models in self.per_pair.items():
            out[protocol] = {
                model: {'pooled': self.pooled(protocol, model),
                        **({'per_pair': {k: vars(s) for k, s in scores.items()}}
                           if per_pair else {})}
                for model, scores in models.items()}
        return out


def evaluate(models: Mapping[str, Follower], pairs: Sequence[FollowingPair], *,
             protocols: Sequence[str] = PROTOCOLS, window_s: float = WINDOW_S) -> Evaluation:
    """Score every model (and the noise floor) on the pairs under each protocol."""
    result = Evaluation(pairs=sorted({p.key for p in pairs}))
    for protocol in protocols:
        runs = make_runs(pairs, protocol, window_s)
        result.per_pair[protocol] = {NOISE_FLOOR: score(runs, simulate(None, runs))}
        for name, model in models.items():
            result.per_pair[protocol][name] = score(runs, simulate(model, runs))
    return result


def paired_difference(result: Evaluation, protocol: str, model: str,
                      other: str) -> dict[str, Any]:
    """Gap NRMSE of ``model`` minus ``other`` pair by pair: mean, 95 % CI half-width (Student
    t over pairs), the number of pairs and of pairs where ``model`` is better (lower), the
    number of platoons and the cluster-bootstrap interval over them (:func:`cluster_ci95`)."""
    mine = result.per_pair[protocol][model]
    theirs = result.per_pair[protocol][other]
    diffs = {k: mine[k].gap_nrmse - theirs[k].gap_nrmse for k in sorted(mine)}
    mean, half = mean_ci95(list(diffs.values()))
    low, high = cluster_ci95(diffs)
    return {'mean': mean, 'ci95': half, 'pairs': len(diffs),
            'better': int(sum(d < 0.0 for d in diffs.values())),
            'platoons': len(set(platoons(list(diffs)).values())),
            'cluster_ci95': [low, high]}


def platoons(pairs: Sequence[str]) -> dict[str, int]:
    """The platoon of each pair (named ``SOURCE:LEADER->FOLLOWER``): pairs that share a
    vehicle, directly or through other pairs, are one platoon; numbered from 0 in the order
    of their first pair."""
    parent: dict[str, str] = {}

    def root(vehicle: str) -> str:
        while parent.setdefault(vehicle, vehicle) != vehicle:
            parent[vehicle] = parent[parent[vehicle]]
            vehicle = parent[vehicle]
        return vehicle

    ends = {}
    for pair in pairs:
        source, _, link = pair.rpartition(':')
        leader, arrow, follower = link.partition('->')
        if not arrow:
            raise ValueError(f'{pair!r} is not a pair name SOURCE:LEADER->FOLLOWER')
        ends[pair] = (f'{source}:{leader}', f'{source}:{follower}')
        parent[root(ends[pair][0])] = root(ends[pair][1])
    numbers: dict[str, int] = {}
    return {pair: numbers.setdefault(root(a), len(numbers)) for pair, (a, _) in ends.items()}


CLUSTER_RESAMPLES = 9999
"""Resamples of :func:`cluster_ci95`."""


def cluster_ci95(values: Mapping[str, float], *, seed: int = 0) -> tuple[float, float]:
    """95 % interval of the mean over pairs from a cluster bootstrap: whole platoons
    (:func:`platoons`) are resampled, because pairs of one platoon share vehicles and are
    not independent (a Student t over pairs is then too narrow). scipy's percentile
    bootstrap of the ratio sum / count over platoons, seeded. One platoon gives no interval
    (nan, nan)."""
    cluster = platoons(list(values))
    count = max(cluster.values()) + 1
    sums = np.zeros(count)
    sizes = np.zeros(count)
    for pair, value in values.items():
        sums[cluster[pair]] += value
        sizes[cluster[pair]] += 1
    if count < 2:
        return math.nan, math.nan
    from scipy import stats  # lazy: importing scipy costs every trust-av start

    result = stats.bootstrap(
        (sums, sizes), lambda s, n, axis=-1: s.sum(axis=axis) / n.sum(axis=axis),
        paired=True, vectorized=True, n_resamples=CLUSTER_RESAMPLES, method='percentile',
        rng=np.random.default_rng(seed))
    interval = result.confidence_interval
    return float(interval.low), float(interval.high)


def format_table(result: Evaluation, protocol: str) -> str:
    """A Markdown table of the pooled scores of one protocol."""
    lines = [f'protocol: {protocol} ({len(result.pairs)} pairs; mean over pairs ± 95 % CI)',
             '| model | gap NRMSE | speed NRMSE | gap RMSE (m) | collisions | steps < 2 m '
             '| min gap (m) |', '| --- | --- | --- | --- | --- | --- | --- |']
    for model in result.per_pair[protocol]:
        p = result.pooled(protocol, model)
        lines.append(f'| {model} | {p["gap_nrmse"]:.3f} ± {p["gap_nrmse_ci95"]:.3f} | '
                     f'{p["speed_nrmse"]:.3f} ± {p["speed_nrmse_ci95"]:.3f} | '
                     f'{p["gap_rmse_m"]:.2f} | {p["collisions"]} | {p["steps_below_2m"]} | '
                     f'{p["min_gap_m"]:.2f} |')
    return '\n'.join(lines)
