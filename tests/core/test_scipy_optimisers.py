"""The driver fit's optimisers are scipy's (human_driver_sim.irl): its Nelder-Mead, from the
same start, simplex step and iteration count, reaches a loss no worse than the numpy
Nelder-Mead the shipped driver fit was made with, and the inverse KKT's non-negative least
squares (scipy.optimize.nnls) a residual no worse than the projected gradient it replaced
(both kept here as the references)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
import scipy.optimize
from support.synthetic_car_following import leader_speed

from human_driver_sim import fitting
from human_driver_sim.car_following import FollowingPair
from human_driver_sim.evaluation import IdmFollower, make_runs, simulate
from human_driver_sim.idm import FIT_BOUNDS, IdmParams
from human_driver_sim.irl import nelder_mead


def reference_nelder_mead(func: Callable[[np.ndarray], float], start: np.ndarray, *,
                          step: float = 0.5, iterations: int = 60) -> tuple[np.ndarray, float]:
    """The hand-written Nelder-Mead (Nelder & Mead 1965; reflection 1, expansion 2, inside
    contraction 1/2, shrink 1/2) that made the shipped driver fit, as it was."""
    dim = len(start)
    simplex = [np.asarray(start, dtype=float)]
    simplex += [simplex[0] + step * np.eye(dim)[i] for i in range(dim)]
    values = [func(x) for x in simplex]
    for _ in range(iterations):
        order = np.argsort(values)
        simplex = [simplex[i] for i in order]
        values = [values[i] for i in order]
        centre = np.mean(simplex[:-1], axis=0)
        reflected = centre + (centre - simplex[-1])
        f_r = func(reflected)
        if f_r < values[0]:
            expanded = centre + 2.0 * (centre - simplex[-1])
            f_e = func(expanded)
            simplex[-1], values[-1] = (expanded, f_e) if f_e < f_r else (reflected, f_r)
        elif f_r < values[-2]:
            simplex[-1], values[-1] = reflected, f_r
        else:
            contracted = centre + 0.5 * (simplex[-1] - centre)
            f_c = func(contracted)
            if f_c < values[-1]:
                simplex[-1], values[-1] = contracted, f_c
            else:
                simplex = [simplex[0] + 0.5 * (x - simplex[0]) for x in simplex]
                values = [values[0]] + [func(x) for x in simplex[1:]]
    best = int(np.argmin(values))
    return simplex[best], float(values[best])


def rosenbrock(x: np.ndarray) -> float:
    return float(np.sum(100.0 * (x[1:] - x[:-1] ** 2) ** 2 + (1.0 - x[:-1]) ** 2))


@pytest.mark.parametrize('iterations', [20, 60, 200])
def test_scipy_reaches_the_reference_on_rosenbrock(iterations: int) -> None:
    start = np.array([-1.2, 1.0, -0.5])
    x, value = nelder_mead(rosenbrock, start, step=1.0, iterations=iterations)
    _, reference = reference_nelder_mead(rosenbrock, start, step=1.0, iterations=iterations)
    assert value <= reference
    assert value == pytest.approx(rosenbrock(x))
    assert value < rosenbrock(start)


def test_iterations_bound_the_work_and_the_start_is_evaluated_first() -> None:
    calls: list[np.ndarray] = []

    def counted(x: np.ndarray) -> float:
        calls.append(np.array(x))
        return rosenbrock(x)

    start = np.array([0.3, -0.7])
    nelder_mead(counted, start, step=0.5, iterations=5)
    np.testing.assert_array_equal(calls[0], start)
    # n + 1 vertices, then at most n + 2 evaluations an iteration (a shrink)
    assert 3 < len(calls) <= 3 + 5 * 4


def test_scipy_idm_fit_is_no_worse_than_the_reference_fit(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The same bounded IDM fit (same data, starts and iteration count) by both optimisers."""
    truth = IdmParams(30.0, 1.2, 2.0, 1.2, 2.0)
    lead = leader_speed(np.arange(120.0))
    seed = FollowingPair('seed', 1.0, lead, np.full(lead.size, 24.0),
                         np.full(lead.size, 30.0), pair_key='idm')
    gap, speed = simulate(IdmFollower(truth), make_runs([seed], 'full'))[0]
    runs = make_runs([FollowingPair('idm', 1.0, lead, speed, gap, pair_key='idm')], 'window')
    starts = fitting.IDM_STARTS[:2]
    found = fitting.fit_idm([runs], starts=starts, iterations=40)
    monkeypatch.setattr(fitting, 'nelder_mead', reference_nelder_mead)
    reference = fitting.fit_idm([runs], starts=starts, iterations=40)
    assert found.loss <= reference.loss, (found.loss, reference.loss)
    for name, (lo, hi) in FIT_BOUNDS.items():
        assert lo <= found.params[name] <= hi


def reference_nnls(a: np.ndarray, b: np.ndarray, iterations: int = 5000) -> np.ndarray:
    """The projected-gradient non-negative least squares the inverse KKT used before."""
    x = np.maximum(np.linalg.lstsq(a, b, rcond=None)[0], 0.0)
    step = 1.0 / max(float(np.linalg.norm(a, 2)) ** 2, 1e-12)
    for _ in range(iterations):
        x = np.maximum(x - step * (a.T @ (a @ x - b)), 0.0)
    return np.asarray(x, dtype=float)


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_scipy_nnls_is_no_worse_than_the_projected_gradient(seed: int) -> None:
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(60, 3)) * np.array([1.0, 30.0, 0.05])   # badly scaled, as the KKT
    b = a @ np.array([0.5, -0.2, 3.0]) + rng.normal(scale=0.1, size=60)   # one bound active
    x = scipy.optimize.nnls(a, b)[0]
    reference = reference_nnls(a, b)
    assert np.all(x >= 0.0)
    assert np.linalg.norm(a @ x - b) <= np.linalg.norm(a @ reference - b) + 1e-12
