"""guidefit.modes.lsq: the hand-written Levenberg-Marquardt lands where scipy's least_squares does."""

from __future__ import annotations

import numpy as np
import pytest

from guidefit.modes.lsq import from_residual, minimize


def _damped_sines(seed: int, n_modes: int):
    """Residual of a sum of damped sines (frequencies and log decays fitted), noisy data."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 0.05, 400)
    f_true = np.sort(rng.uniform(200.0, 900.0, n_modes))
    d_true = rng.uniform(20.0, 80.0, n_modes)
    y = sum(np.exp(-d * t) * np.sin(2 * np.pi * f * t) for f, d in zip(f_true, d_true))
    y = y + rng.normal(0.0, 0.01, t.size)

    def residual(x):
        f, d = x[:n_modes], np.exp(x[n_modes:])
        e = np.exp(-d[:, None] * t) * np.sin(2 * np.pi * f[:, None] * t)
        J = np.vstack([np.exp(-d[:, None] * t) * np.cos(2 * np.pi * f[:, None] * t) * 2 * np.pi * t,
                       -d[:, None] * t * e])
        return e.sum(axis=0) - y, J.T

    x0 = np.concatenate([f_true * (1 + rng.normal(0, 0.01, n_modes)), np.log(d_true * 1.3)])
    return residual, x0


@pytest.mark.parametrize("seed", range(6))
def test_unbounded_minimum_is_scipys(seed):
    from scipy.optimize import least_squares

    residual, x0 = _damped_sines(seed, 1 + seed % 3)
    normal, cost = from_residual(residual)
    ours = minimize(normal, cost, x0, tol=1e-13)
    ref = least_squares(lambda x: residual(x)[0], x0, jac=lambda x: residual(x)[1], method="trf",
                        xtol=1e-14, ftol=1e-14, gtol=1e-14)
    assert ours.converged
    assert ours.cost <= float(ref.fun @ ref.fun) * (1 + 1e-10)
    np.testing.assert_allclose(ours.x, ref.x, rtol=1e-8, atol=1e-10)


def test_a_bound_that_the_minimum_presses_on_is_held():
    """min (x0 - 3)^2 + (x1 + 1)^2 on [0, 2] x [0, 5]: the answer (2, 0) sits on two bounds."""
    def residual(x):
        return np.array([x[0] - 3.0, x[1] + 1.0]), np.eye(2)

    normal, cost = from_residual(residual)
    res = minimize(normal, cost, [1.0, 4.0], [0.0, 0.0], [2.0, 5.0])
    assert res.converged
    np.testing.assert_allclose(res.x, [2.0, 0.0], atol=1e-12)
    assert res.cost == pytest.approx(2.0, rel=1e-12)


def test_rosenbrock_from_far():
    def residual(x):
        return np.array([10.0 * (x[1] - x[0] ** 2), 1.0 - x[0]]), np.array([[-20.0 * x[0], 10.0], [-1.0, 0.0]])

    normal, cost = from_residual(residual)
    res = minimize(normal, cost, [-1.2, 1.0])
    assert res.converged
    np.testing.assert_allclose(res.x, [1.0, 1.0], rtol=1e-9)
