"""The global fit's fast paths against the direct computations they replace (guidefit.modes.globalvp, globalfit).

Each fast path is exact algebra, so it must agree with the direct form to
rounding, amplified at most by the conditioning of the small problems here:
normal equations from projected derivatives vs the full Jacobian; scipy's
trust-region fit on the compressed residual vs on the full one; the
jackknife's one-product replicate steps vs replicate residuals; numpy
average-linkage clusters vs scipy.cluster; the sparse-table peak
prominences vs scipy.signal. Problems: two modes, three FRF columns in two
run groups (one with an exponential-window shift), complex noise, seeded.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from guidefit.modes import globalfit, globalvp

MODES = [(1500.0, 0.02), (2600.0, 0.06)]


def _problem(seed=3, noise=2e-3):
    f = np.arange(900.0, 4000.0, 4.0)
    s = 2j * np.pi * f[:, None]
    rng = np.random.default_rng(seed)
    cols = []
    for shift in (0.0, 17.5):  # the second group: an exponential window of tau = 1/17.5 s
        sg = s + shift
        H = np.zeros((f.size, 3 if shift == 0.0 else 2), complex)
        for fn, z in MODES:
            wn = 2 * np.pi * fn
            p = wn * (-z + 1j * math.sqrt(1 - z * z))
            A = rng.normal(size=H.shape[1]) / (2j * p.imag)
            H += sg**2 * (A / (sg - p) + np.conj(A) / (sg - np.conj(p)))
        H += noise * np.abs(H).mean() * (rng.normal(size=H.shape) + 1j * rng.normal(size=H.shape))
        cols.append(H)
    H = np.hstack(cols)
    prob = globalvp.SharedProblem(f, H, [slice(0, 3), slice(3, 5)], [0.0, 17.5])
    wn = 2 * np.pi * np.array([1503.0, 2590.0])
    z = np.array([0.021, 0.058])
    return prob, wn, z


def test_normal_equations_equal_those_of_the_full_jacobian():
    prob, wn, z = _problem()
    J = prob.jacobian(wn, z)
    r = prob.residual(wn, z)
    JtJ, g, cost = prob.normal(wn, z)
    np.testing.assert_allclose(JtJ, J.T @ J, rtol=1e-9, atol=1e-9 * np.abs(J.T @ J).max())
    np.testing.assert_allclose(g, J.T @ r, rtol=1e-7, atol=1e-9 * np.linalg.norm(J.T @ r))
    assert cost == pytest.approx(float(r @ r), rel=1e-12)


def test_explicit_projection_of_derivatives_near_the_design_span_gives_the_same_normal_equations(monkeypatch):
    """The fallback of SharedProblem._project (columns projected one by one) agrees with the Gram form and
    with the full Jacobian."""
    prob, wn, z = _problem()
    gram = prob.normal(wn, z)[0]
    monkeypatch.setattr(globalvp, "EXPLICIT_PROJECTION", 2.0)  # every column "nearly in the span"
    prob._key = None
    explicit = prob.normal(wn, z)[0]
    J = prob.jacobian(wn, z)
    np.testing.assert_allclose(explicit, J.T @ J, rtol=1e-9, atol=1e-9 * np.abs(J.T @ J).max())
    np.testing.assert_allclose(gram, explicit, rtol=1e-9, atol=1e-9 * np.abs(explicit).max())


def test_design_is_the_fitcore_basis_stacked_and_normalised():
    from guidefit.modes import fitcore

    prob, wn, z = _problem()
    p = fitcore.poles(wn, z)
    for shift in prob.shifts:
        Phi, norm = prob._design(p, shift)
        ref = fitcore.stack(fitcore.basis(prob.s + shift, p, prob.terms))
        np.testing.assert_allclose(norm, np.sqrt(np.sum(ref**2, axis=0)), rtol=1e-14)
        np.testing.assert_allclose(Phi, ref / norm, rtol=1e-14, atol=1e-16)


def test_compressed_problem_has_the_full_problems_normal_equations():
    prob, wn, z = _problem()
    JtJ, g, cost = prob.normal(wn, z)
    rt, Jt = globalvp.compressed(JtJ, g, cost)
    np.testing.assert_allclose(Jt.T @ Jt, JtJ, rtol=1e-10, atol=1e-12 * np.abs(JtJ).max())
    np.testing.assert_allclose(Jt.T @ rt, g, rtol=1e-9, atol=1e-12 * np.linalg.norm(g))
    assert float(rt @ rt) == pytest.approx(cost, rel=1e-13)


def test_trust_region_fit_on_the_compressed_problem_ends_where_the_full_one_does():
    """The fit (guidefit.modes.lsq on the normal equations) against scipy's trf on the full residual and
    Jacobian (the first implementation): the same optimum to far below the fit's own std."""
    import scipy.optimize

    prob, _, _ = _problem()
    band = (900.0, 3996.0)
    init = [(1490.0, 0.025), (2610.0, 0.05)]
    fit = globalvp.solve(prob, init, band)
    n = len(init)
    lo = np.concatenate([np.full(n, math.log(2 * np.pi * 450.0)), np.full(n, math.log(1e-5))])
    hi = np.concatenate([np.full(n, math.log(2 * np.pi * 7992.0)), np.full(n, math.log(0.7))])
    x0 = np.concatenate([np.log(2 * np.pi * np.array([a for a, _ in init])), np.log([b for _, b in init])])

    def split(x):
        return np.exp(x[:n]), np.exp(x[n:])

    ref = scipy.optimize.least_squares(lambda x: prob.residual(*split(x)), x0, jac=lambda x: prob.jacobian(*split(x)),
                                       bounds=(lo, hi), method="trf", xtol=1e-10, ftol=1e-10, gtol=1e-10)
    wn, z = split(ref.x)
    for m, w, zz in zip(fit.modes, wn, z):
        assert m.frequency_hz == pytest.approx(w / (2 * np.pi), rel=1e-9)
        assert m.damping_ratio == pytest.approx(zz, rel=1e-7)
        assert abs(m.frequency_hz - w / (2 * np.pi)) < 1e-3 * m.frequency_std_hz
    for m, (fn, zt) in zip(fit.modes, MODES):  # and it is the right optimum
        assert abs(m.frequency_hz - fn) < 4 * m.frequency_std_hz
        assert abs(m.damping_ratio - zt) < 4 * m.damping_std


def test_gauss_newton_steps_are_those_of_the_full_jacobian():
    """One step of gauss_newton equals -lstsq(J, r) of the full Jacobian (the previous implementation)."""
    prob, wn, z = _problem()
    J, r = prob.jacobian(wn, z), prob.residual(wn, z)
    full = -np.linalg.lstsq(J, r, rcond=None)[0]
    rt, Jt = globalvp.compressed(*prob.normal(wn, z))
    small = -np.linalg.lstsq(Jt, rt, rcond=np.finfo(float).eps * J.shape[0])[0]
    np.testing.assert_allclose(small, full, rtol=1e-7, atol=1e-10 * np.abs(full).max())


def test_replicate_steps_equal_those_from_replicate_residuals():
    """J^T (I - P) D (gradient_of) against J^T (r(Y + D) - r(Y)) of refitted replicate data."""
    prob, wn, z = _problem()
    rng = np.random.default_rng(7)
    dY = 1e-2 * rng.normal(size=prob.Y.shape + (4,))
    fast = prob.gradient_of(wn, z, [dY[:, g] for g in prob.groups])
    J, r0 = prob.jacobian(wn, z), prob.residual(wn, z)
    direct = []
    for k in range(dY.shape[2]):
        rep = globalvp.SharedProblem(prob.f, np.zeros((prob.f.size, prob.Y.shape[1])), prob.groups, prob.shifts,
                                     scale=prob.scale)
        rep.Y = prob.Y + dY[:, :, k]
        direct.append(J.T @ (rep.residual(wn, z) - r0))
    direct = np.array(direct).T
    np.testing.assert_allclose(fast, direct, rtol=1e-8, atol=1e-10 * np.abs(direct).max())


@pytest.mark.parametrize("seed", range(6))
def test_average_linkage_gives_scipys_flat_clusters(seed):
    from scipy.cluster.hierarchy import fcluster, linkage

    rng = np.random.default_rng(seed)
    centres = rng.normal(size=(5, 2)) * 3.0
    x = centres[rng.integers(0, 5, 80)] + rng.normal(size=(80, 2)) * 0.4
    ref = fcluster(linkage(x, method="average"), t=1.0, criterion="distance")
    got = globalfit.average_linkage_labels(x, 1.0)

    def partition(labels):
        return sorted(tuple(np.flatnonzero(labels == k)) for k in np.unique(labels))

    assert partition(got) == partition(ref)
    assert len(np.unique(got)) > 1


@pytest.mark.parametrize("seed", range(4))
def test_prominent_peaks_equal_scipy_on_long_curves_and_non_finite_values(seed):
    import scipy.signal

    from guidefit.modes import prominent_peaks

    rng = np.random.default_rng(seed)
    y = np.round(np.cumsum(rng.normal(size=3000)), 1)  # long, with plateaus
    if seed % 2:
        y[rng.integers(0, y.size, 5)] = np.nan
        y[rng.integers(0, y.size, 2)] = np.inf
    idx, prom = prominent_peaks(y, 0.5)
    ref, props = scipy.signal.find_peaks(y, prominence=0.5)
    assert idx.tolist() == ref.tolist()
    np.testing.assert_array_equal(prom, props["prominences"])


def test_problem_sharing_a_design_gives_its_own_data_fit():
    """A problem that reuses another's design at the same poles (other column weights, as the global fit's
    equally weighted check of the noise-weighted fit) has the residual and normal equations it would
    have on its own."""
    prob, wn, z = _problem()
    prob.normal(wn, z)
    H = (prob.Y[: prob.f.size] + 1j * prob.Y[prob.f.size:]) / prob.scale
    weights = np.linspace(0.5, 2.0, H.shape[1]) / np.sqrt(np.mean(np.abs(H) ** 2, axis=0))
    alone = globalvp.SharedProblem(prob.f, H, prob.groups, prob.shifts, scale=weights)
    shared = globalvp.SharedProblem(prob.f, H, prob.groups, prob.shifts, scale=weights)
    shared.share = prob
    ref, got = alone.normal(wn, z), shared.normal(wn, z)
    assert shared.fits(wn, z)[0]["Phi"] is prob.fits(wn, z)[0]["Phi"]  # the design was not made again
    np.testing.assert_allclose(got[0], ref[0], rtol=1e-12, atol=1e-12 * np.abs(ref[0]).max())
    np.testing.assert_allclose(got[1], ref[1], rtol=1e-9, atol=1e-12 * np.linalg.norm(ref[1]))
    assert got[2] == pytest.approx(ref[2], rel=1e-13)
    np.testing.assert_allclose(shared.residual(wn, z), alone.residual(wn, z), rtol=0, atol=1e-13)
