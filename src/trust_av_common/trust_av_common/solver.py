"""CasADi solver settings shared by the project's small MPCs (the AV's and the driver's),
the AV NMPC's choice of QP solver by grid size, and the one way they call a solver."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from trust_av_common.held_stops import held

__all__ = ['nmpc_solver_options', 'qp_options', 'solve', 'sqp_options']


def solve(solver: Callable[..., dict[str, Any]], **arguments: Any) -> dict[str, Any]:
    """``solver(**arguments)`` (a CasADi ``Function``) with the stop signals held until it
    returns (:func:`~trust_av_common.held_stops.held`): a Ctrl-C or SIGTERM during the
    solve stops the program after it, instead of failing the solve inside CasADi."""
    with held():
        return solver(**arguments)


def sqp_options(max_iter: int) -> dict[str, Any]:
    """Quiet ``sqpmethod`` + ``qrqp`` options for a few-variable NLP.

    SQP with an active-set QP fits problems of N = 3..10 variables: a handful of
    iterations of a dense QP, no interior-point barrier. ``convexify_strategy`` keeps the QP
    convex where the exact Hessian of a non-convex term (the Tanimoto distance) is not.
    Failures are reported through ``stats()`` (``error_on_fail`` off), never raised.
    """
    quiet_qp = {'print_iter': False, 'print_header': False, 'print_info': False,
                'error_on_fail': False}
    return {'qpsol': 'qrqp', 'qpsol_options': quiet_qp, 'convexify_strategy': 'none',
            'max_iter': max_iter, 'print_time': False, 'print_header': False,
            'print_iteration': False, 'print_status': False, 'error_on_fail': False}


QRQP_MAX_STEPS = 10
"""Largest grid solved with ``qrqp``; finer grids use DAQP, which solves the standstill
corner ``qrqp`` stalled on at N = 30 (docs/MODEL.md, "QP solver on fine grids")."""


def nmpc_solver_options(max_iter: int, steps: int) -> dict[str, Any]:
    """SQP options of the NMPC: the shared ``qrqp`` settings up to :data:`QRQP_MAX_STEPS`
    steps (the paper's grid), DAQP for finer grids."""
    options = sqp_options(max_iter)
    if steps > QRQP_MAX_STEPS:
        options['qpsol'] = 'daqp'
        options['qpsol_options'] = {'error_on_fail': False}
    return options


def qp_options(max_iter: int) -> dict[str, Any]:
    """Options of a convex QP solved directly with DAQP (``casadi.qpsol``): the driver MPC.

    Its problem is a convex QP (docs/MODEL.md, "The human's safety gap"), so it needs no SQP
    around it. ``sqpmethod`` with ``qrqp`` stopped on some feasible ones with
    ``Search_Direction_Becomes_Too_Small`` at a plan that broke the active gap bound (the human
    5.2 m behind, 1 m/s faster than an AV expected to hold its speed: d^2 = 4.64 m < d_s; 7 of
    24,000 steps of the paper sweep), and with DAQP inside it at standstill; one DAQP solve
    answers all of them. ``max_iter`` bounds DAQP's active-set iterations. Failures are
    reported through ``stats()``, never raised.
    """
    return {'error_on_fail': False, 'daqp': {'iter_limit': max_iter}}
