"""A plan estimator fed on its own 1 s grid, whatever the control rate.

The plan estimators (CA and the GRU, which was trained on it) are defined on the model step
``dt_s`` (the paper's 1 s): one observation per second, predictions of one acceleration per
second. :class:`ModelGridPredictor` runs one at any control period: it keeps what happened at
every control tick and, for each prediction, hands the estimator the samples a 1 s observer
would have taken ending now (a sliding 1 s grid): at each sample time s = now, now - 1 s, ...
the gap, relative speed and headway at s (the latest tick at or before s) and the AV's mean
acceleration over (s - 1 s, s]. At a control period equal to the model step it is the
estimator itself, observation for observation.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, replace

import numpy as np

from trust_av_planner.predictors import Observation, Predictor

__all__ = ['ModelGridPredictor']

TIME_TOLERANCE_S = 1e-6
"""Tick times within this of a sample time count as that time (float grids, wall stamps)."""


@dataclass(frozen=True)
class _Tick:
    t_s: float
    observation: Observation  # state at t_s; av_accel_mps2 = accel applied over (prev, t_s]
    duration_s: float


class ModelGridPredictor:
    """Feeds ``inner`` (defined on ``model_step_s``) from control ticks of any period.

    Args:
        inner: the estimator on the model grid.
        model_step_s: its step, s (``dt_s``).
        history_samples: how many 1 s samples it may use (the GRU's H; 1 for CA).
    """

    def __init__(self, inner: Predictor, model_step_s: float, history_samples: int,
                 aligned: bool = True) -> None:
        if not model_step_s > 0.0 or history_samples < 1:
            raise ValueError(f'need model_step_s > 0 and history_samples >= 1, got '
                             f'{model_step_s}, {history_samples}')
        self.inner = inner
        self.model_step_s = model_step_s
        self.history_samples = history_samples
        self.aligned = aligned
        self.origin_s: float | None = None
        self._ticks: deque[_Tick] = deque()
        self._cached: tuple[float, np.ndarray] | None = None

    def reset(self) -> None:
        """Forget the history."""
        self._ticks.clear()
        self.inner.reset()
        self.origin_s = None
        self._cached = None

    def sample_end_s(self, now_s: float) -> float:
        """Time of the newest sample a prediction at ``now_s`` uses: ``now_s`` itself
        (sliding), or the latest instant of the 1 s grid started at the first prediction."""
        if self.origin_s is None:
            self.origin_s = now_s
        if not self.aligned:
            return now_s
        whole = np.floor((now_s - self.origin_s) / self.model_step_s + TIME_TOLERANCE_S)
        return self.origin_s + float(whole) * self.model_step_s

    def observe(self, observation: Observation, t_s: float, duration_s: float) -> None:
        """What the human saw at ``t_s`` after the AV applied ``observation.av_accel_mps2``
        for the last ``duration_s`` seconds.

        Raises:
            ValueError: ``t_s`` is not after the previous tick, or ``duration_s`` < 0.
        """
        if self._ticks and t_s <= self._ticks[-1].t_s:
            raise ValueError(f'ticks must move forward: {t_s} s after {self._ticks[-1].t_s} s')
        if duration_s < 0.0:
            raise ValueError(f'duration_s must be >= 0, got {duration_s}')
        self._ticks.append(_Tick(t_s, observation, duration_s))
        keep_from = t_s - (self.history_samples + 1) * self.model_step_s
        while len(self._ticks) > 1 and self._ticks[1].t_s <= keep_from:
            self._ticks.popleft()

    def samples(self, now_s: float) -> list[Observation]:
        """The 1 s samples ending at ``now_s``, oldest first (at most ``history_samples``;
        fewer while the history is shorter)."""
        if not self._ticks:
            return []
        out: list[Observation] = []
        first = self._ticks[0].t_s - self._ticks[0].duration_s
        for j in range(self.history_samples):
            at = now_s - j * self.model_step_s
            if at < first + self.model_step_s - TIME_TOLERANCE_S:
                break  # a full second of history is not there yet
            state = self._state_at(at)
            if state is None:
                break
            out.append(replace(state, av_accel_mps2=self._mean_accel(at - self.model_step_s,
                                                                     at)))
        return out[::-1]

    def predict(self, now_s: float) -> tuple[np.ndarray, float]:
        """The inner estimator's plan (model grid) from the samples ending at
        :meth:`sample_end_s`, and how long before ``now_s`` that plan starts, s."""
        end = self.sample_end_s(now_s)
        if self._cached is not None and self._cached[0] == end:
            return self._cached[1].copy(), now_s - end  # the same samples: the same plan
        self.inner.reset()
        for sample in self.samples(end):
            self.inner.observe(sample)
        plan = self.inner.predict()
        self._cached = (end, plan.copy())
        return plan, now_s - end

    def _state_at(self, t_s: float) -> Observation | None:
        found = None
        for tick in self._ticks:
            if tick.t_s <= t_s + TIME_TOLERANCE_S:
                found = tick.observation
            else:
                break
        return found

    def _mean_accel(self, start_s: float, end_s: float) -> float:
        """Time-weighted mean of the applied accelerations over (start_s, end_s]."""
        total = covered = 0.0
        for tick in self._ticks:
            lo, hi = max(tick.t_s - tick.duration_s, start_s), min(tick.t_s, end_s)
            if hi > lo:
                total += tick.observation.av_accel_mps2 * (hi - lo)
                covered += hi - lo
        return total / covered if covered > 0.0 else 0.0
