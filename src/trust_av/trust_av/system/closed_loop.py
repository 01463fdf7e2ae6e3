"""In-process closed loop: traffic -> predictor -> AV NMPC -> trust -> human -> integrate.

One step follows do-mpc's ``make_step`` idiom (here, as for every model of the project,
called ``step``) and calls exactly the core the ROS nodes call, so the node graph reproduces
these trajectories (a test checks it). Per step ``t``:

1. the preceding traffic gives v_PT(t) and the preview v_PT(t .. t+N-1);
2. the AV's planner (:class:`~trust_av_planner.planner.AvPlanner`) lets its
   predictor observe what the human saw after step t-1, predicts the expected plan
   u_R^H(t), and plans u_R(t) with the NMPC from its gap, speed, the preview, u_R^H(t), T(t);
3. the trust monitor scores E(t) = dist(u_R(t), u_R^H(t)) and updates T(t+1), eqs. 8-11;
4. the human's MPC plans u_H(t) against u_R^H(t);
5. every vehicle's odometry is integrated one step with its first planned acceleration.

The control period is the trace's step (:func:`control_trace` interpolates a trace to a
control rate; 1 Hz is the paper's loop). At another period the planner predicts on its own
grid and feeds its estimator 1 s samples (:class:`~trust_av_planner.planner.AvPlanner`), the
trust update is scaled by the period (trust per second), and the human driver model keeps its
1 s grid and replans every period (sampled-data, as a person does), fed the expected plan
read on that grid (:func:`trust_av_common.grids.hold_at`, as the driver node reads the
expected-plan message by its times).
"""

from __future__ import annotations

import csv
import logging
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from human_driver_sim.followers import make_follower
from preceding_traffic.sources import load_trace
from preceding_traffic.traces import SpeedTrace
from trust_av.system.config import RunConfig
from trust_av.system.metrics import Metrics, StepRecord, compute_metrics
from trust_av_common.component_checks import ComponentError
from trust_av_common.grids import grid_times, hold_at
from trust_av_common.kinematics import VehicleState, collision, gap_m, integrate
from trust_av_planner.planner import AvPlanner
from trust_monitor.paper_trust import TrustEstimator

__all__ = ['ClosedLoop', 'InitialState', 'SimResult', 'control_trace', 'equilibrium_start',
           'simulate']

LOG = logging.getLogger(__name__)


@dataclass(frozen=True)
class InitialState:
    """Initial odometry of the three vehicles (front-bumper positions, m; speeds, m/s)."""

    traffic: VehicleState
    av: VehicleState
    human: VehicleState


def equilibrium_start(config: RunConfig, trace: SpeedTrace) -> InitialState:
    """Every vehicle at the traffic's first speed, each at its own desired gap.

    The AV starts at its CTH gap ``d_s + tau_R v``, the human at ``d_s + tau_H v``; the human's
    front bumper is at 0 m.
    """
    speed = float(trace.speeds_mps[0])
    length = config.shared.vehicle_length_m
    human_gap = config.driver.standstill_gap_m + config.driver.time_headway_s * speed
    av_gap = config.planner.standstill_gap_m + config.planner.time_headway_s * speed
    av_position = human_gap + length
    return InitialState(traffic=VehicleState(av_position + av_gap + length, speed),
                        av=VehicleState(av_position, speed), human=VehicleState(0.0, speed))


@dataclass
class SimResult:
    """Records of a run and its metrics."""

    trace: str
    alpha: float
    predictor: str
    min_safe_gap_m: float
    records: list[StepRecord] = field(default_factory=list)
    plan_step_s: float | None = None
    """The step of the plans' grid when it is not the control period, s."""

    @property
    def metrics(self) -> Metrics:
        """Final trust, mean E, prediction RMSE, minimum gaps, fallback and unsafe counts."""
        return compute_metrics(self.records, self.min_safe_gap_m, self.plan_step_s)

    def write_csv(self, path: Path) -> None:
        """One row per step; plans are spread over ``<name>_0 .. <name>_{N-1}`` columns."""
        rows = [_flatten(r) for r in self.records]
        with path.open('w', newline='') as handle:
            writer = csv.DictWriter(handle, fieldnames=list(rows[0]) if rows else [])
            writer.writeheader()
            writer.writerows(rows)


def _flatten(record: StepRecord) -> dict[str, object]:
    out: dict[str, object] = {}
    for key, value in asdict(record).items():
        if isinstance(value, tuple):
            out.update({f'{key}_{k}': v for k, v in enumerate(value)})
        else:
            out[key] = value
    return out


def control_trace(config: RunConfig, rate_hz: float | None = None) -> SpeedTrace:
    """The params file's trace on the control grid: its samples interpolated to ``rate_hz``
    (default: one per ``dt_s``, the paper's 1 Hz).

    Raises:
        ValueError: ``rate_hz`` is not > 0.
    """
    if rate_hz is not None and not rate_hz > 0.0:
        raise ValueError(f'control rate must be > 0 Hz, got {rate_hz}')
    period = config.planner.dt_s if rate_hz is None else 1.0 / rate_hz
    return load_trace(config.trace.trace, period, config.trace)


def trace_preview(trace: SpeedTrace, step: int, grid_step_s: float, steps: int) -> np.ndarray:
    """The recorded future of the trace from control step ``step`` on the prediction grid
    (k * grid_step_s, k = 0..steps-1; the last speed held past the end)."""
    if abs(grid_step_s - trace.dt_s) <= 1e-12 * trace.dt_s:
        return trace.preview(step, steps)
    times = step * trace.dt_s + np.arange(steps) * grid_step_s
    preview: np.ndarray = np.interp(times, np.arange(len(trace.speeds_mps)) * trace.dt_s,
                                    trace.speeds_mps)
    return preview


class ClosedLoop:
    """The in-process closed loop over one trace; :meth:`step` advances one control period
    (the trace's step)."""

    def __init__(self, config: RunConfig, trace: SpeedTrace,
                 initial: InitialState | None = None) -> None:
        self.config = config.for_trace(trace)
        self.trace = trace
        state = initial or equilibrium_start(self.config, trace)
        self.traffic, self.av, self.human = state.traffic, state.av, state.human
        self.period_s = trace.dt_s
        # One trust model: the monitor updates it, the NMPC's constraint propagates it.
        trust_model = self.config.trust_model()
        self.planner = AvPlanner(self.config.planner, self.config.trust,
                                 self.config.shared.vehicle_length_m, period_s=self.period_s,
                                 predictor_params=self.config.predictor_params,
                                 trust_model=trust_model)
        self.driver = make_follower(self.config.driver, self.config.follower,
                                    self.config.driver_params)
        self.monitor = TrustEstimator(self.config.trust, trust_model)
        self.step_index = 0

    @property
    def done(self) -> bool:
        """True after the last step of the trace."""
        return self.step_index >= self.trace.steps

    def step(self) -> StepRecord:
        """Advance the closed loop by one control step and return its record."""
        c = self.config
        dt, length = self.period_s, c.shared.vehicle_length_m
        t = self.step_index
        self.traffic = VehicleState(self.traffic.position_m, float(self.trace.speeds_mps[t]))
        preview = (trace_preview(self.trace, t, *self.planner.grid)
                   if c.planner.lead_preview == 'recorded' else None)
        out = self.planner.step(self.traffic, preview, self.av, self.human, self.monitor.state,
                                t_s=t * dt)
        plan, expected = out.result, out.expected_mps2
        estimate = self.monitor.step(plan.plan_mps2, expected, dt)
        human_gap = gap_m(self.av, self.human, length)
        step_s, steps = self.planner.grid
        human = self.driver.step(human_gap, self.human.speed_mps, self.av.speed_mps,
                                 hold_at(grid_times(step_s, steps), expected,
                                         c.driver.dt_s, c.driver.horizon_steps))
        record = StepRecord(
            t_s=self.trace.time_s(t),
            traffic_position_m=self.traffic.position_m, traffic_speed_mps=self.traffic.speed_mps,
            av_position_m=self.av.position_m, av_speed_mps=self.av.speed_mps, av_gap_m=out.gap_m,
            human_position_m=self.human.position_m, human_speed_mps=self.human.speed_mps,
            human_gap_m=human_gap, av_accel_mps2=float(plan.plan_mps2[0]),
            human_accel_mps2=float(human.plan_mps2[0]),
            av_plan_mps2=tuple(float(x) for x in plan.plan_mps2),
            expected_plan_mps2=tuple(float(x) for x in expected),
            human_plan_mps2=tuple(float(x) for x in human.plan_mps2),
            explicability=estimate.explicability, performance=estimate.performance,
            trust=estimate.trust, explicability_max=plan.explicability_max,
            solver_status=plan.status, solver_success=plan.success,
            solver_iterations=plan.iterations, solve_time_s=plan.solve_time_s,
            driver_status=human.status, driver_success=human.success,
            driver_solve_time_s=human.solve_time_s)
        self.traffic = integrate(self.traffic, 0.0, dt)
        self.av = integrate(self.av, record.av_accel_mps2, dt)
        self.human = integrate(self.human, record.human_accel_mps2, dt)
        self.step_index += 1
        return record

    def steps(self) -> Iterator[StepRecord]:
        """Run the remaining steps, yielding each record."""
        while not self.done:
            yield self.step()


def simulate(config: RunConfig, trace: SpeedTrace, *, initial: InitialState | None = None,
             on_step: Callable[[int, int], None] | None = None) -> SimResult:
    """Run the closed loop over the whole trace.

    Args:
        config: run configuration.
        trace: preceding-traffic speeds on the control grid.
        initial: initial odometry; default :func:`equilibrium_start`.
        on_step: called with (steps done, total steps) after each step (progress).

    A gap at or below 0 m is a collision (:func:`~trust_av_common.kinematics.collision`):
    the run ends with that step (its record is the last one) and ``result.metrics.collision``
    names it.

    Raises:
        ComponentError: a component broke its interface; its ``partial`` holds the steps
            before (a :class:`SimResult`).
    """
    loop = ClosedLoop(config, trace, initial)
    step_s = loop.planner.grid[0]
    result = SimResult(trace=trace.name, alpha=config.planner.alpha,
                       predictor=config.planner.predictor,
                       min_safe_gap_m=config.min_safe_gap_m,
                       plan_step_s=None if step_s == loop.period_s else step_s)
    close = []
    for record in _keeping(loop.steps(), result):
        result.records.append(record)
        crash = collision(len(result.records) - 1, record.t_s, record.av_gap_m,
                          record.human_gap_m)
        if crash is not None:      # the run ends: what follows is no car following
            LOG.info('%s', crash.line())   # the command prints it, once
            if on_step is not None:
                on_step(len(result.records), trace.steps)
            break
        if min(record.av_gap_m, record.human_gap_m) < config.min_safe_gap_m:
            close.append(record)
        if on_step is not None:
            on_step(len(result.records), trace.steps)
    if close:   # one line per run, naming it (a study runs many, in parallel)
        least = min(close, key=lambda r: min(r.av_gap_m, r.human_gap_m))
        LOG.warning('%s, TAC-%s, alpha = %g, %s follower: gap below the safety minimum %.2f m '
                    'at %d steps from t = %.1f s (least: AV %.3f m, human %.3f m at t = %.1f s)',
                    trace.name, config.planner.predictor.upper(), config.planner.alpha,
                    config.follower.driver_model, config.min_safe_gap_m, len(close),
                    close[0].t_s, least.av_gap_m, least.human_gap_m, least.t_s)
    return result


def _keeping(records: Iterator[StepRecord], result: SimResult) -> Iterator[StepRecord]:
    """``records``; a component's failure on the way carries ``result`` (the steps before
    it, the run's record) as its ``partial``."""
    try:
        yield from records
    except ComponentError as err:
        err.partial = result
        raise
