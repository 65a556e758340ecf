"""Levenberg-Marquardt on SO(3) with right increments `R <- R @ Exp(step)`, for any smooth cost.

Used by the normals-only solver (`manhattan.py`) and the joint solver (`joint.py`); with moment
forms each iteration is O(1) in pixels and segments.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from ..rotations import exp_so3

# Damping of a Hessian scaled to O(1) at a minimum (dimensionless).
DAMPING_START = 1e-6
DAMPING_MIN = 1e-9
DAMPING_GIVE_UP = 1e8
_EYE3 = np.eye(3)
_EYE3.setflags(write=False)


def levenberg_marquardt_so3(cost: Callable[[np.ndarray], float],
                            gradient_hessian: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
                            R0: np.ndarray, max_iterations: int, step_tolerance_rad: float
                            ) -> tuple[np.ndarray, int, float, bool]:
    """Minimise `cost(R)` from `R0`; `gradient_hessian(R)` gives (3,) and (3, 3) with respect to the
    right perturbation (paper eq. 4-5). Returns (R, iterations, cost, converged)."""
    R = R0
    value = float(cost(R))
    damping = DAMPING_START
    iterations = 0
    while iterations < max_iterations:
        iterations += 1
        grad, hess = gradient_hessian(R)
        eig_min = np.linalg.eigvalsh(hess)[0]
        # Levenberg-Marquardt: a shift that makes the model convex, grown while steps fail.
        mu = max(damping, DAMPING_MIN - eig_min)
        step = np.linalg.solve(hess + mu * _EYE3, -grad)
        R_new = R @ exp_so3(step)
        if np.linalg.norm(step) < step_tolerance_rad:
            # Converged: below this the cost change is under double precision anyway.
            return R_new, iterations, float(cost(R_new)), True
        value_new = float(cost(R_new))
        if value_new <= value:
            R, value = R_new, value_new
            damping = max(damping / 4.0, DAMPING_MIN)
        else:
            damping = mu * 8.0
            if damping > DAMPING_GIVE_UP:
                break
    return R, iterations, value, False
