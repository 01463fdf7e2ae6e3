"""GRU plan estimator (TAC-GRU, eqs. 6-7): the human's expected AV plan from 10 s of history.

Inputs per step (eq. 6): gap d_H, relative speed rs_H = v_R - v_H, time headway tau_H and
the AV's executed acceleration u_R, for the last H steps; output (eq. 7): the next N AV
accelerations. The network is a one-layer GRU followed by a linear read-out, trained in
torch (:mod:`trust_av.study.gru_training`) and stored as plain arrays in an ``.npz``; the
forward pass here is the same maths in numpy (PyTorch's GRU equations), so that a control
step costs tens of microseconds and loads without torch. A test checks numpy == torch.

Warm-up rule:
until H observations exist, the prediction is the constant-acceleration one (the last
observed acceleration held; zero before the first). Predictions are clipped to the AV's
acceleration bounds.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from trust_av_common.params import check_fields, param, require
from trust_av_common.registry import FOLLOWER_STATE, Component
from trust_av_planner.errors import TrustAvPlannerError
from trust_av_planner.predictors import Observation

if TYPE_CHECKING:
    from trust_av_planner.nmpc import PlannerConfig

__all__ = ['COMPONENT', 'FEATURES', 'MODELS_DIR', 'GruConfig', 'GruPredictor', 'GruWeights',
           'ModelError', 'gru_forward', 'load_weights']

MODELS_DIR = Path(__file__).resolve().parents[1] / 'models'
FEATURES = ('gap_m', 'relative_speed_mps', 'time_headway_s', 'av_accel_mps2')
ARRAYS = ('weight_ih', 'weight_hh', 'bias_ih', 'bias_hh', 'out_weight', 'out_bias',
          'feature_mean', 'feature_std')


class ModelError(TrustAvPlannerError):
    """A GRU weights file is missing or does not fit; the message names file and problem."""


@dataclass(frozen=True)
class GruWeights:
    """The network's arrays (PyTorch layout: gates r, z, n stacked) and normalisation."""

    weight_ih: np.ndarray   # (3 hidden, features)
    weight_hh: np.ndarray   # (3 hidden, hidden)
    bias_ih: np.ndarray     # (3 hidden,)
    bias_hh: np.ndarray     # (3 hidden,)
    out_weight: np.ndarray  # (N, hidden)
    out_bias: np.ndarray    # (N,)
    feature_mean: np.ndarray  # (features,)
    feature_std: np.ndarray   # (features,)
    history_steps: int
    dt_s: float  # control step the model was trained at (H and N are counted in it)

    @property
    def hidden(self) -> int:
        """Hidden size of the GRU."""
        return int(self.weight_hh.shape[1])

    @property
    def horizon_steps(self) -> int:
        """Number of predicted accelerations."""
        return int(self.out_weight.shape[0])


def resolve_model(name: str) -> Path:
    """A model file by name (in the package's ``models/``) or by path."""
    path = Path(name)
    return path if path.is_absolute() or path.parent != Path('.') else MODELS_DIR / name


def load_weights(path: Path, horizon_steps: int, *, dt_s: float | None = None) -> GruWeights:
    """Load and check a weights file.

    Args:
        path: the ``.npz`` file.
        horizon_steps: the planner's N (the model must predict exactly N accelerations).
        dt_s: the planner's control step in s; if given, it must be the one the model was
            trained at (its 10-step history would otherwise span another time).

    Raises:
        ModelError: missing file, missing array, shapes that do not fit each other or the
            planner's horizon, or another control step.
    """
    if not path.exists():
        raise ModelError(f'{path}: GRU weights file not found (train one with '
                         f'`trust-av train-gru`, or set planner.gru_model)')
    try:
        with np.load(path) as data:
            arrays = {k: np.asarray(data[k], dtype=float) for k in ARRAYS}
            history = int(data['history_steps'])
            trained_dt_s = float(data['dt_s'])
    except KeyError as err:
        raise ModelError(f'{path}: not a GRU weights file (missing array {err})') from err
    except (OSError, ValueError) as err:
        raise ModelError(f'{path}: cannot read GRU weights ({err})') from err
    weights = GruWeights(**arrays, history_steps=history, dt_s=trained_dt_s)
    h, f = weights.hidden, len(FEATURES)
    expected = {'weight_ih': (3 * h, f), 'weight_hh': (3 * h, h), 'bias_ih': (3 * h,),
                'bias_hh': (3 * h,), 'out_weight': (horizon_steps, h),
                'out_bias': (horizon_steps,), 'feature_mean': (f,), 'feature_std': (f,)}
    for name, shape in expected.items():
        actual = getattr(weights, name).shape
        if actual != shape:
            raise ModelError(f'{path}: {name} has shape {actual}, expected {shape} '
                             f'(hidden {h}, {f} features, horizon {horizon_steps} steps)')
    if history < 1:
        raise ModelError(f'{path}: history_steps must be >= 1, got {history}')
    if np.any(weights.feature_std <= 0):
        raise ModelError(f'{path}: feature_std must be > 0, got {weights.feature_std.tolist()}')
    if dt_s is not None and abs(trained_dt_s - dt_s) > 1e-9:
        raise ModelError(f'{path}: trained at dt_s = {trained_dt_s:g} s, but the planner runs at '
                         f'dt_s = {dt_s:g} s (retrain with `trust-av train-gru` at that step)')
    return weights


def _sigmoid(x: np.ndarray) -> np.ndarray:
    out: np.ndarray = 1.0 / (1.0 + np.exp(-x))
    return out


def gru_forward(weights: GruWeights, inputs: np.ndarray) -> np.ndarray:
    """Run the GRU over normalised inputs (time, features); return the N outputs.

    PyTorch's equations: r = s(W_ir x + b_ir + W_hr h + b_hr), z = s(W_iz x + b_iz + W_hz h +
    b_hz), n = tanh(W_in x + b_in + r * (W_hn h + b_hn)), h = (1 - z) n + z h.
    """
    h = np.zeros(weights.hidden)
    size = weights.hidden
    for x in inputs:
        gi = weights.weight_ih @ x + weights.bias_ih
        gh = weights.weight_hh @ h + weights.bias_hh
        r = _sigmoid(gi[:size] + gh[:size])
        z = _sigmoid(gi[size:2 * size] + gh[size:2 * size])
        n = np.tanh(gi[2 * size:] + r * gh[2 * size:])
        h = (1.0 - z) * n + z * h
    out: np.ndarray = weights.out_weight @ h + weights.out_bias
    return out


def features(observation: Observation) -> np.ndarray:
    """The four inputs of eq. (6), in :data:`FEATURES` order."""
    return np.array([observation.gap_m, observation.relative_speed_mps,
                     observation.time_headway_s, observation.av_accel_mps2])


@dataclass(frozen=True)
class GruConfig:
    """Parameters of the GRU plan estimator (declared in the planner's section)."""

    gru_model: str = param('GRU weights: a file in trust_av_planner/models/ or a path',
                           default='gru_plan_estimator.npz',
                           reason='the plan estimator and its history are built at start-up')

    def __post_init__(self) -> None:
        check_fields(self)
        require(bool(self.gru_model), 'gru_model must name a weights file')


class GruPredictor:
    """GRU plan estimator with its history buffer (part of the predictor's state)."""

    def __init__(self, weights: GruWeights, accel_min_mps2: float,
                 accel_max_mps2: float) -> None:
        self.weights = weights
        self.accel_min_mps2 = accel_min_mps2
        self.accel_max_mps2 = accel_max_mps2
        self._history: deque[np.ndarray] = deque(maxlen=weights.history_steps)

    @classmethod
    def from_file(cls, path: Path, horizon_steps: int, dt_s: float, accel_min_mps2: float,
                  accel_max_mps2: float) -> GruPredictor:
        """Load weights (checked against the horizon and the control step) and build the
        predictor."""
        return cls(load_weights(path, horizon_steps, dt_s=dt_s), accel_min_mps2,
                   accel_max_mps2)

    @property
    def history_steps(self) -> int:
        """H: how many model steps of history a prediction uses."""
        return self.weights.history_steps

    def reset(self) -> None:
        """Forget the history."""
        self._history.clear()

    def observe(self, observation: Observation) -> None:
        """Append the step just executed to the history."""
        self._history.append(features(observation))

    def predict(self) -> np.ndarray:
        """GRU prediction, or CA during warm-up; clipped to the acceleration bounds."""
        w = self.weights
        if len(self._history) < w.history_steps:
            last = self._history[-1][3] if self._history else 0.0
            plan = np.full(w.horizon_steps, last)
        else:
            inputs = (np.array(self._history) - w.feature_mean) / w.feature_std
            plan = gru_forward(w, inputs)
        clipped: np.ndarray = np.clip(plan, self.accel_min_mps2, self.accel_max_mps2)
        return clipped


def build(planner: PlannerConfig, params: GruConfig) -> GruPredictor:
    """The GRU estimator of ``params.gru_model`` on the planner's horizon, step and bounds.

    Raises:
        ModelError: the weights file is missing or does not fit (:func:`load_weights`).
    """
    return GruPredictor.from_file(resolve_model(params.gru_model), planner.horizon_steps,
                                  planner.dt_s, planner.accel_min_mps2, planner.accel_max_mps2)


COMPONENT = Component(
    name='gru', factory=build, config_type=GruConfig, needs=frozenset({FOLLOWER_STATE}),
    description='GRU trained on the 10 s history of gap, relative speed, headway and the '
                "AV's acceleration (TAC-GRU, eqs. 6-7)")
"""Registered as ``gru`` in ``trust_av.predictors`` (trust_av_planner's setup.py)."""
