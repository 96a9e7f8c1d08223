"""The fitting core shared by the per-run curve fit (:mod:`guidefit.modes.curvefit`) and the global
fit (:mod:`guidefit.modes.globalfit`, :mod:`guidefit.modes.globalvp`): the pole-residue basis, the linear
least squares of variable projection and its exact derivative.

The model is the pole-residue accelerance of :mod:`guidefit.modes.base`'s docstring,
``H_r = (jw)^2 sum_k [A_rk/(jw - p_k) + A_rk*/(jw - p_k*)] + residual terms``, with real
coefficients ``(Re A_rk, Im A_rk, ..., residual-term coefficients)``. For given poles the
coefficients are a linear least-squares problem (:func:`basis`, :func:`stack`, :func:`ls_fit`);
the poles, iterated as ``x = (ln w_n, ln zeta)`` (:func:`unpack`, :func:`poles`), minimise the
projected residual ``E = (I - A A^+) Y`` (Golub and Pereyra 1973), whose exact Jacobian is
:func:`projected_jacobian` with the column derivatives of :func:`pole_derivatives`.

Arrays only, numpy only (no scipy: identify imports this module on its hot path).
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "DEFAULT_RESIDUALS",
    "RESIDUAL_TERMS",
    "ZETA_BOUNDS",
    "basis",
    "cholesky_inverse",
    "ls_fit",
    "ls_residual",
    "ls_solver",
    "pole_derivatives",
    "poles",
    "projected_jacobian",
    "stack",
    "suspicious",
    "unpack",
]

#: residual terms of the fitted accelerance; each enters with one real coefficient per channel
RESIDUAL_TERMS = {
    "lower": lambda s: np.ones_like(s),  # L_r: mass line of the modes below the band
    "lower_damping": lambda s: 1.0 / s,  # L1_r / (jw): their damping tail
    "upper": lambda s: s * s,  # U_r (jw)^2: compliance of the modes above the band
    "upper_damping": lambda s: s**3,  # U1_r (jw)^3: their damping
}
#: the residual terms fitted unless the caller names others (see :func:`guidefit.modes.curvefit.fit_modes`)
DEFAULT_RESIDUALS = ("lower", "lower_damping", "upper")
#: (lowest, highest) damping ratio the nonlinear solvers allow; :func:`suspicious` flags a fit at them
ZETA_BOUNDS = (1e-5, 0.7)


def poles(wn: np.ndarray, zeta: np.ndarray) -> np.ndarray:
    """Poles ``p = w_n (-zeta + j sqrt(1 - zeta^2))`` (rad/s, upper half plane) of natural
    frequencies ``wn`` (rad/s) and damping ratios ``zeta``."""
    return wn * (-zeta + 1j * np.sqrt(1.0 - zeta**2))


def basis(s: np.ndarray, poles: np.ndarray, terms: tuple) -> np.ndarray:
    """(F, 2n + len(terms)) complex columns; real coefficients (Re A, Im A, ..., terms)."""
    s2 = (s * s)[:, None]
    poles = np.asarray(poles)
    a = s2 / (s[:, None] - poles[None, :])
    b = s2 / (s[:, None] - np.conj(poles)[None, :])
    out = np.empty((s.size, 2 * poles.size + len(terms)), dtype=complex)
    out[:, 0:2 * poles.size:2] = a + b  # the same element-wise operations as one column at a time
    out[:, 1:2 * poles.size:2] = 1j * (a - b)
    for j, t in enumerate(terms):
        out[:, 2 * poles.size + j] = RESIDUAL_TERMS[t](s)
    return out


def stack(z: np.ndarray) -> np.ndarray:
    """Real rows of complex rows: ``[Re z; Im z]`` along the first axis (the real least-squares
    problem of a complex one with real coefficients)."""
    return np.concatenate([z.real, z.imag], axis=0)


def ls_solver(A: np.ndarray):
    """``V -> (A^T A)^-1 V`` by a Cholesky factor of the normal matrix, or ``None``.

    ``None`` when ``A^T A`` is not numerically positive definite (rank-deficient
    ``A``); callers then fall back to an SVD solve. The inverse of the factor
    is formed once (these normal matrices are small, a few dozen columns, and
    one solver serves many right-hand sides), so that each solve is two matrix
    products. numpy.linalg, not scipy.linalg: importing scipy.linalg costs
    50-80 ms, a tenth of an identify run, and its triangular solves are not
    needed for matrices this size.
    """
    factor_inverse = cholesky_inverse(A.T @ A)
    if factor_inverse is None:
        return None

    def solve(V):
        return factor_inverse.T @ (factor_inverse @ V)

    return solve


def cholesky_inverse(N: np.ndarray) -> np.ndarray | None:
    """``L^-1`` of the Cholesky factor ``N = L L^T`` of a symmetric matrix, or ``None`` when ``N``
    is not numerically positive definite (or not finite)."""
    try:
        factor = np.linalg.cholesky(N)
    except np.linalg.LinAlgError:
        return None
    inverse = np.linalg.solve(factor, np.eye(N.shape[0]))
    return inverse if np.all(np.isfinite(inverse)) else None


def ls_fit(A: np.ndarray, Y: np.ndarray, solver=None):
    """Least-squares fit of Y by the columns of A (unit-norm columns).

    Normal equations with one step of iterative refinement: much cheaper
    than a QR for tall, narrow A, and as accurate while cond(A)^2 eps << 1.
    ``solver``: the :func:`ls_solver` of ``A`` when the caller has it (the
    same design fitted to other data).

    Returns
    -------
    (E, B, solve)
        Residual ``Y - A B``, coefficients ``B`` and the normal-matrix solver of
        :func:`ls_solver`; ``solve`` is ``None`` when A is rank deficient and the
        fit fell back to an SVD solve.
    """
    solve = solver or ls_solver(A)
    if solve is not None:
        B = solve(A.T @ Y)
        B += solve(A.T @ (Y - A @ B))
        if np.all(np.isfinite(B)):
            return Y - A @ B, B, solve
    B = np.linalg.lstsq(A, Y, rcond=None)[0]
    return Y - A @ B, B, None


def ls_residual(A: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """Residual of the least-squares fit of Y by the columns of A (see :func:`ls_fit`)."""
    return ls_fit(A, Y)[0]


def projected_jacobian(A, dA, pairs, E, B, solve) -> np.ndarray:
    """Jacobian of the variable-projection residual ``E = (I - A A^+) Y``.

    Golub and Pereyra's exact derivative for a design matrix whose parameter
    ``j`` moves only the two columns ``pairs[j]``:
    ``dE/dx_j = -(I - A A^+) dA_j B - A (A^T A)^-1 dA_j^T E``.

    Parameters
    ----------
    A : (M, L) design matrix (weighted, unit-norm columns).
    dA : (P, M, 2) derivatives of the two moved columns, scaled like A's columns.
    pairs : (P, 2) int, the columns each parameter moves.
    E, B : the fit's residual (M, R) and coefficients (L, R).
    solve : the normal-matrix solver of :func:`ls_solver`.

    Returns
    -------
    numpy.ndarray, shape (M, R, P)
    """
    n_params = dA.shape[0]
    L, R = B.shape
    M = A.shape[0]
    V = dA @ B[pairs]  # dA_j B, (P, M, R)
    Z = np.zeros((n_params, L, R))
    Z[np.arange(n_params)[:, None], pairs] = dA.transpose(0, 2, 1) @ E  # dA_j^T E
    rhs = (A.T @ V) - Z  # (P, L, R)
    coef = solve(rhs.transpose(1, 0, 2).reshape(L, -1))  # (L, P R)
    dE = (A @ coef).reshape(M, n_params, R) - V.transpose(1, 0, 2)
    dE = dE.transpose(0, 2, 1)
    return dE


def pole_derivatives(s, wn, zeta):
    """d(raw basis column pair)/dx of every pole parameter x = (ln w_n..., ln zeta...).

    Returns complex (P, F, 2) with P = 2n: the derivatives of the columns
    ``a + b`` and ``j (a - b)`` of :func:`basis` (``a = s^2/(s - p)``,
    ``b = s^2/(s - p*)``) with ``dp/d ln w_n = p`` and
    ``dp/d ln zeta = zeta w_n (-1 - j zeta / sqrt(1 - zeta^2))``.
    """
    pk = poles(wn, zeta)
    dp = np.concatenate([pk, zeta * wn * (-1.0 - 1j * zeta / np.sqrt(1.0 - zeta**2))])
    p = np.concatenate([pk, pk])
    s2 = (s * s)[None, :]
    da = s2 / (s[None, :] - p[:, None]) ** 2 * dp[:, None]
    db = s2 / (s[None, :] - np.conj(p)[:, None]) ** 2 * np.conj(dp)[:, None]
    return np.stack([da + db, 1j * (da - db)], axis=2)


def unpack(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(w_n, zeta)`` from the iterated pole parameters ``x = (ln w_n..., ln zeta...)``."""
    n = x.size // 2
    return np.exp(x[:n]), np.exp(x[n:])


def suspicious(mode, lo: float, hi: float) -> bool:
    """Fitted mode outside the band ``[lo, hi]`` (Hz) or at a damping bound of the solvers
    (:data:`ZETA_BOUNDS`: :func:`guidefit.modes.curvefit.fit_band`, :func:`guidefit.modes.globalvp.solve`)."""
    z = mode.damping_ratio
    return not lo <= mode.frequency_hz <= hi or z > 0.69 or z < 2e-5
