"""Small dense nonlinear least squares: a box-bounded Levenberg-Marquardt.

identify's modal stage solves a few least-squares problems of 2-20
parameters: the shared poles of the global fit (given the normal equations
of the variable-projection problem, :mod:`guidefit.modes.globalvp`) and the
mass-normalised carriage motion of a mode (:mod:`guidefit.modal_stage`).
:func:`scipy.optimize.least_squares` solves them well, but importing
:mod:`scipy.optimize` costs 0.2 s (its package pulls linprog, shgo, the
sparse and spatial packages), which is a quarter of ``guidefit identify`` on
the bundled sample and more than the whole modal stage on a 100-hit
recording. Nothing else of it is needed there, so the method is written here:
Levenberg-Marquardt with Nielsen's damping update (K. Madsen, H. B. Nielsen,
O. Tingleff, *Methods for non-linear least squares problems*, 2004, Alg.
3.16), steps projected into the bounds, run to a tight convergence so that
it lands where scipy's ``trf`` lands (tested on random problems and on the
global fit's own: ``tests/test_lsq.py``).

The problem is given by ``normal(x) -> (J^T J, J^T r, r^T r)`` and
``cost(x) -> r^T r``: callers that never form ``J`` (the variable projection)
and callers that do (:func:`from_residual`) use the same solver.

Examples
--------
>>> import numpy as np
>>> t = np.linspace(0.0, 1.0, 30)
>>> y = 2.0 * np.exp(-1.3 * t)
>>> def residual(x):
...     return x[0] * np.exp(-x[1] * t) - y, np.column_stack(
...         [np.exp(-x[1] * t), -x[0] * t * np.exp(-x[1] * t)])
>>> normal, cost = from_residual(residual)
>>> res = minimize(normal, cost, np.array([1.0, 0.5]))
>>> np.round(res.x, 9).tolist(), res.converged
([2.0, 1.3], True)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class LsqResult:
    """``x`` the solution; ``cost`` ``r^T r`` there; ``n_iter`` steps tried; ``converged``: a
    tolerance was met (else the iteration limit ended it)."""

    x: np.ndarray
    cost: float
    n_iter: int
    converged: bool


def from_residual(residual):
    """``(normal, cost)`` of a problem given as ``residual(x) -> (r, J)``."""

    def normal(x):
        r, J = residual(x)
        return J.T @ J, J.T @ r, float(r @ r)

    def cost(x):
        r, _ = residual(x)
        return float(r @ r)

    return normal, cost


def minimize(normal, cost, x0, lower=None, upper=None, *, tol: float = 1e-12, max_iter: int = 200) -> LsqResult:
    """The ``x`` in ``[lower, upper]`` that minimises ``cost(x) = r^T r``.

    Parameters
    ----------
    normal : callable
        ``normal(x) -> (J^T J, J^T r, r^T r)`` at ``x``.
    cost : callable
        ``cost(x) -> r^T r`` (cheaper than ``normal`` where it can be).
    x0 : array_like
        Start; moved into the bounds.
    lower, upper : array_like, optional
        Bounds (``-inf``/``inf`` by default).
    tol : float
        Converged when the cost falls by less than ``tol`` of itself in an
        accepted step, a step is shorter than ``tol (tol + |x|)``, or the
        gradient (its components that point into the box) is below ``tol``
        times the cost's scale.
    max_iter : int
        Steps tried at most.

    Returns
    -------
    LsqResult
    """
    x = np.array(x0, dtype=float)
    n = x.size
    lo = np.full(n, -np.inf) if lower is None else np.asarray(lower, dtype=float)
    hi = np.full(n, np.inf) if upper is None else np.asarray(upper, dtype=float)
    x = np.clip(x, lo, hi)
    A, g, c = normal(x)
    mu, nu = 1e-3, 2.0  # damping relative to diag(J^T J) (Marquardt's scaling: units of x do not matter)
    for it in range(1, max_iter + 1):
        free = ~(((x <= lo) & (g > 0)) | ((x >= hi) & (g < 0)))  # a bound that the descent presses on is held
        if not np.any(free) or float(np.max(np.abs(g[free]))) <= tol * max(c, 1e-300):
            return LsqResult(x, c, it - 1, True)
        h = np.zeros(n)
        Af = A[np.ix_(free, free)]
        d = np.diag(Af)
        d = np.maximum(d, 1e-12 * max(float(np.max(d)), 1e-300))  # a parameter the data do not move
        damped = Af + mu * np.diag(d)
        try:
            h[free] = np.linalg.solve(damped, -g[free])
        except np.linalg.LinAlgError:
            mu, nu = mu * nu, nu * 2.0
            continue
        x_new = np.clip(x + h, lo, hi)
        h = x_new - x
        if float(np.linalg.norm(h)) <= tol * (tol + float(np.linalg.norm(x))):
            return LsqResult(x, c, it, True)
        c_new = cost(x_new)
        predicted = -float(g @ h) - 0.5 * float(h @ A @ h)  # of (r^T r) / 2
        gain = 0.5 * (c - c_new) / predicted if predicted > 0 else -1.0
        if math.isfinite(c_new) and gain > 0:
            x, drop = x_new, c - c_new
            A, g, c = normal(x)
            mu *= max(1.0 / 3.0, 1.0 - (2.0 * gain - 1.0) ** 3)
            nu = 2.0
            if drop <= tol * c and 2.0 * predicted <= tol * c:  # actual and predicted: as MINPACK's ftol
                return LsqResult(x, c, it, True)
        else:
            mu, nu = mu * nu, nu * 2.0
    return LsqResult(x, c, max_iter, False)
