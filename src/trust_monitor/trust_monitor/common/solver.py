"""CasADi solver settings shared by the project's small MPCs (the AV's and the driver's)."""

from __future__ import annotations

from typing import Any


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
