r"""The variable-projection problem of the global fit: shared poles, residues per FRF column.

The global fit (:mod:`guidefit.modes.globalfit`) models every FRF column ``o`` of
every run as ``sum_k A_ko s^2/(s - p_k) + conj + residual terms``, the poles
``p_k`` shared, the residues and residual-term coefficients linear. Variable
projection (Golub and Pereyra 1973) eliminates the linear coefficients: for
poles ``x = (ln w_n, ln zeta)`` the residual is ``E(x) = (I - A A^+) Y``
with ``A`` the (unit-norm, weighted) design of a run group and ``Y`` its
weighted FRF columns, and only ``x`` is iterated.

Everything the fits need from the residual's Jacobian ``J`` (``2 F O`` rows,
``2n`` columns) is its normal matrix ``J^T J``, its gradient ``J^T E`` and,
for the jackknife, ``J^T D`` for replicate residual changes ``D``. With
Golub and Pereyra's exact derivative ``J_j = -(I - P) dA_j B_j - A (A^T
A)^-1 dA_j^T E`` (``P = A A^+``, ``dA_j`` the two design columns pole
parameter ``j`` moves, ``B_j`` their coefficients) and ``A^T (I - P) = 0``,
these are small products (:meth:`SharedProblem.normal`):

* ``(J^T J)_jk = tr(B_j^T dA_j^T (I - P) dA_k B_k) + tr(F_j^T (A^T A)^-1_jk F_k)``
  with ``F_j = dA_j^T E``;
* ``(J^T E)_j = -tr(B_j^T F_j)``;
* ``(J^T (I - P) D)_j = -tr(B_j^T dA_j^T (I - P) D)``.

``dA^T (I - P) dA`` and ``dA^T E`` come from one product of the ``4n``
derivative columns with ``[A, dA, E]`` (:meth:`SharedProblem._project`), so
no ``(2 F O, 2n)`` Jacobian is formed, and no SVD of one is taken at every
iteration (26 304 x 8 on the 100-hit benchmark recording: 3288 bins, 4
columns, 4 modes), as ``scipy.optimize.least_squares`` did. :func:`solve`
iterates with :func:`guidefit.modes.lsq.minimize` (bounded Levenberg-Marquardt) on
these normal equations, to a tighter tolerance than scipy's ``trf`` was run
with; :func:`gauss_newton` steps on the equivalent small problem of
:func:`compressed` (a residual of ``2n + 1`` entries with the same norm,
gradient and normal matrix). :meth:`SharedProblem.jacobian` still forms the
full Jacobian (for tests and diagnostics).

Examples
--------
>>> import numpy as np
>>> f = np.arange(800.0, 3000.0, 5.0)
>>> s = 2j * np.pi * f
>>> p = 2 * np.pi * 1500.0 * (-0.02 + 1j * np.sqrt(1 - 0.02**2))
>>> H = (s**2 * (0.3 / (s - p) + 0.3 / (s - np.conj(p))))[:, None]
>>> prob = SharedProblem(f, H, [slice(None)], [0.0])
>>> fit = solve(prob, [(1490.0, 0.03)], (800.0, 3000.0))
>>> round(fit.modes[0].frequency_hz, 3), round(fit.modes[0].damping_ratio, 5)
(1500.0, 0.02)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from guidefit.modes import fitcore
from guidefit.modes.base import Mode

#: a derivative column keeping less than this share of its squared norm outside the design's span is
#: projected explicitly (:meth:`SharedProblem._project`)
EXPLICIT_PROJECTION = 1e-4
#: what a fit at given poles shares with another problem of the same design (SharedProblem.fits)
_DESIGN_PARTS = ("Phi", "norm", "solve", "D", "dA", "GiC", "Ginv")
#: relative rank cut-off of numpy.linalg.lstsq's default (machine epsilon times the larger dimension)
_EPS = float(np.finfo(float).eps)


class SharedProblem:
    """Variable-projection problem of one band: FRF columns in groups (runs), each group's basis evaluated
    at ``s + 1/tau`` of its exponential window (the windowed FRF is ``H(s + 1/tau)``), residues and residual
    terms per column.

    Parameters
    ----------
    f : (F,) frequencies (Hz); H : (F, O) complex FRF columns
    groups : list of slices of the columns, one per run; shifts : ``1/tau`` (1/s) per group (0: no window)
    terms : residual terms (:data:`guidefit.modes.fitcore.DEFAULT_RESIDUALS`); scale : (O,) column weights
        (default ``1 / RMS`` of each column)

    The fits of the last pole set are kept: a residual, then the normal
    equations at the same poles (what every iteration asks) design and
    factorise once.
    """

    def __init__(self, f, H, groups, shifts, terms=None, scale=None):
        self.f = np.asarray(f, float)
        self.s = 2j * np.pi * self.f
        self.terms = tuple(terms or fitcore.DEFAULT_RESIDUALS)
        if scale is None:
            rms = np.sqrt(np.mean(np.abs(H) ** 2, axis=0))
            scale = 1.0 / np.where(rms > 0, rms, 1.0)
        self.scale = np.asarray(scale, float)
        self.Y = fitcore.stack(H * self.scale)
        self.groups = list(groups)  # slices of columns
        self.shifts = [float(x) for x in shifts]  # sigma_w (1/s) per group
        self._key = None
        self._fits: list = []
        self._terms: dict = {}
        self.share: SharedProblem | None = None  # a problem whose design at the same poles may be reused

    def _design(self, p, shift):
        """Unit-norm design ``(2F, L)`` at the poles ``p`` for a group's window shift, and the column norms.

        The values of ``guidefit.modes.fitcore.stack(guidefit.modes.fitcore.basis(s + shift, p, terms))`` (the same
        element-wise operations, written into one array; the residual-term columns, which do not
        depend on the poles, made once per shift).
        """
        # exponential window e^{-t/tau} on force and response: H_w(s) = H(s + 1/tau) exactly (Laplace shift), so the
        # whole basis (the s^2 of the accelerance and the residual terms too) is evaluated at s + 1/tau with the true
        # poles; only moving the poles (s^2 / (s - p + 1/tau)) biased a 2 kHz mode by -0.0024 % at tau = 0.05 s
        sg, s2, terms = self._shifted(shift)
        F, n = sg.size, p.size
        a = s2[:, None] / (sg[:, None] - p[None, :])
        b = s2[:, None] / (sg[:, None] - np.conj(p)[None, :])
        plus, minus = a + b, a - b
        Phi = np.empty((2 * F, 2 * n + terms.shape[1]))
        Phi[:F, 0:2 * n:2] = plus.real
        Phi[F:, 0:2 * n:2] = plus.imag
        Phi[:F, 1:2 * n:2] = -minus.imag  # j (a - b): real part -Im, imaginary part Re
        Phi[F:, 1:2 * n:2] = minus.real
        Phi[:, 2 * n:] = terms
        norm = np.sqrt(np.sum(Phi**2, axis=0))
        norm[norm == 0] = 1.0
        Phi /= norm
        return Phi, norm

    def _shifted(self, shift):
        """``s + shift``, its square and the stacked residual-term columns, made once per shift."""
        if shift not in self._terms:
            sg = self.s + shift
            terms = np.stack([fitcore.RESIDUAL_TERMS[t](sg) for t in self.terms], axis=1) if self.terms \
                else np.zeros((sg.size, 0), complex)
            self._terms[shift] = (sg, sg * sg, np.concatenate([terms.real, terms.imag], axis=0))
        return self._terms[shift]

    def fits(self, wn, z) -> list:
        """Per group ``{"Phi", "norm", "E", "B", "solve"}`` of the least-squares fit at these poles (kept).

        When :attr:`share` (another problem on the same bins, groups and
        shifts, e.g. the same FRFs weighted differently) holds a fit at the
        same poles, its design, factor and derivative products are reused.
        """
        key = (np.asarray(wn, float).tobytes(), np.asarray(z, float).tobytes())
        if key != self._key:
            src = self.share if self.share is not None and self.share._key == key else None
            p = fitcore.poles(wn, z)
            self._fits = []
            for i, (g, sh) in enumerate(zip(self.groups, self.shifts)):
                if src is None:
                    Phi, norm = self._design(p, sh)
                    E, B, solve = fitcore.ls_fit(Phi, self.Y[:, g])
                    fit = {"Phi": Phi, "norm": norm, "E": E, "B": B, "solve": solve}
                else:
                    fit = {k: v for k, v in src._fits[i].items() if k in _DESIGN_PARTS}
                    fit["E"], fit["B"], fit["solve"] = fitcore.ls_fit(fit["Phi"], self.Y[:, g], fit["solve"])
                self._fits.append(fit)
            self._key = key
        return self._fits

    def residual(self, wn, z) -> np.ndarray:
        """The projected residual, ``(2F O,)`` (rows: bin-major, columns within a row)."""
        E = np.empty_like(self.Y)
        for g, fit in zip(self.groups, self.fits(wn, z)):
            E[:, g] = fit["E"]
        return E.ravel()

    def cost(self, wn, z) -> float:
        """Sum of squared projected residuals."""
        return float(sum(np.sum(fit["E"] ** 2) for fit in self.fits(wn, z)))

    def _derivatives(self, wn, z, sh, norm):
        """d (design column pair) / d (ln w_n, ln zeta), stacked and scaled like the design: ``(2F, 4n)``,
        column ``2j + c`` the derivative of column ``c`` of the pair that parameter ``j`` moves; and the
        pairs ``(2n, 2)``."""
        n = wn.size
        F = self.s.size
        p = fitcore.poles(wn, z)
        dp = np.concatenate([p, z * wn * (-1.0 - 1j * z / np.sqrt(1.0 - z**2))])
        k = np.concatenate([np.arange(n), np.arange(n)])
        pairs = np.stack([2 * k, 2 * k + 1], axis=1)
        pg = p - sh
        s2 = ((self.s + sh) ** 2)[None, :]
        q = s2 / (self.s[None, :] - pg[:, None]) ** 2  # (n, F): each pole once, for both of its parameters
        qc = s2 / (self.s[None, :] - np.conj(pg)[:, None]) ** 2
        da = np.concatenate([q, q]) * dp[:, None]
        db = np.concatenate([qc, qc]) * np.conj(dp)[:, None]
        plus, minus = (da + db).T, (da - db).T  # columns a + b and j (a - b) = j minus
        dA = np.empty((2 * F, 4 * n))
        n0, n1 = norm[pairs[:, 0]], norm[pairs[:, 1]]
        dA[:F, 0::2] = plus.real / n0
        dA[F:, 0::2] = plus.imag / n0
        dA[:F, 1::2] = -minus.imag / n1  # Re(j x) = -Im x
        dA[F:, 1::2] = minus.real / n1  # Im(j x) = Re x
        return dA, pairs

    def jacobian(self, wn, z) -> np.ndarray:
        """Exact projected Jacobian d residual / d (ln w_n, ln zeta), ``(2F O, 2n)`` (Golub-Pereyra, as in
        guidefit.modes); the fits use :meth:`normal` instead."""
        n = wn.size
        J = np.empty(self.Y.shape + (2 * n,))
        for g, sh, fit in zip(self.groups, self.shifts, self.fits(wn, z)):
            if fit["solve"] is None:
                raise np.linalg.LinAlgError("rank-deficient design")
            dA, pairs = self._derivatives(wn, z, sh, fit["norm"])
            dPhi = dA.reshape(dA.shape[0], 2 * n, 2).transpose(1, 0, 2)  # (2n, 2F, 2)
            J[:, g, :] = fitcore.projected_jacobian(fit["Phi"], dPhi, pairs, fit["E"], fit["B"], fit["solve"])
        return J.reshape(-1, 2 * n)

    def normal(self, wn, z) -> tuple[np.ndarray, np.ndarray, float]:
        """``(J^T J, J^T E, E^T E)`` of the projected residual, without forming J (module docstring)."""
        n = wn.size
        JtJ = np.zeros((2 * n, 2 * n))
        g = np.zeros(2 * n)
        for sh, fit in zip(self.shifts, self.fits(wn, z)):
            if fit["solve"] is None:
                raise np.linalg.LinAlgError("rank-deficient design")
            if "Bj" not in fit:
                self._project(fit, wn, z, sh)
            Bj, Fj = fit["Bj"], fit["Fj"]
            JtJ += np.einsum("jar,jakb,kbr->jk", Bj, fit["D"], Bj)
            JtJ += np.einsum("jar,jakb,kbr->jk", Fj, fit["Ginv"], Fj)
            g -= np.einsum("jar,jar->j", Bj, Fj)
        return JtJ, g, self.cost(wn, z)

    def _project(self, fit: dict, wn, z, sh) -> None:
        """The small products of one group's derivatives (kept in ``fit``): ``D = dA^T (I - P) dA``,
        ``F = dA^T E``, the pairs' coefficients and ``(A^T A)^-1`` entries.

        ``D = dA^T dA - C^T (A^T A)^-1 C`` with ``C = A^T dA``: one product of the
        derivatives with ``[A, dA, E]`` instead of projecting every derivative
        column (four products with the design). It loses ``|dA_j|^2 / |(I - P)
        dA_j|^2`` in relative accuracy; the derivative columns keep about half
        their norm outside the design's span (0.45-0.67 on the benchmark
        files, 1e-15 relative error in D), and a column below
        :data:`EXPLICIT_PROJECTION` of it is projected explicitly instead
        (:func:`guidefit.modes.fitcore.ls_fit`'s fit with one refinement step).
        """
        n = wn.size
        A, solve = fit["Phi"], fit["solve"]
        k = np.concatenate([np.arange(n), np.arange(n)])
        pairs = np.stack([2 * k, 2 * k + 1], axis=1)
        if "D" not in fit:  # the design's part (shared with problems of the same design)
            dA, _ = self._derivatives(wn, z, sh, fit["norm"])
            L, P4 = A.shape[1], dA.shape[1]
            prods = dA.T @ np.hstack([A, dA, fit["E"]])  # (4n, L + 4n + R)
            C = prods[:, :L].T  # A^T dA
            GiC = solve(C)
            DD = prods[:, L:L + P4]
            D = DD - C.T @ GiC
            if np.any(np.diag(D) < EXPLICIT_PROJECTION * np.diag(DD)):  # nearly in the design's span: project them
                coef = solve(A.T @ dA)
                coef += solve(A.T @ (dA - A @ coef))
                dperp = dA - A @ coef
                D = dperp.T @ dperp
            fit["D"] = D.reshape(2 * n, 2, 2 * n, 2)
            fit["dA"], fit["GiC"] = dA, GiC
            fit["Fj"] = prods[:, L + P4:].reshape(2 * n, 2, -1)  # dA_j^T E
            ginv = solve(np.eye(L))
            fit["Ginv"] = ginv[pairs[:, :, None, None], pairs[None, None, :, :]]  # (2n, 2, 2n, 2)
        elif "Fj" not in fit:
            fit["Fj"] = (fit["dA"].T @ fit["E"]).reshape(2 * n, 2, -1)
        fit["Bj"] = fit["B"][pairs]  # (2n, 2, R)

    def gradient_of(self, wn, z, dY: list) -> np.ndarray:
        """``J^T (I - P) D`` for changes ``D`` of the data: ``dY`` per group ``(2F, R_g, K)`` -> ``(2n, K)``
        (a jackknife replicate's residual change is ``(I - P) D``, and ``J^T (I - P) D = -sum B_j^T dA_j^T
        (I - P) D`` needs only products with the derivatives)."""
        self.normal(wn, z)  # the derivatives' products at these poles
        out = 0.0
        for fit, d in zip(self.fits(wn, z), dY):
            R, K = d.shape[1], d.shape[2]
            d2 = d.reshape(d.shape[0], R * K)
            # dA^T (I - P) D = dA^T D - C^T (A^T A)^-1 A^T D
            proj = (fit["dA"].T @ d2 - fit["GiC"].T @ (fit["Phi"].T @ d2)).reshape(-1, 2, R, K)
            out = out - np.einsum("jar,jark->jk", fit["Bj"], proj)
        return out

    def coefficients(self, wn, z) -> np.ndarray:
        """(L, O) coefficients in the columns' own units (those of the kept fit: normal equations with one
        refinement step, or the SVD solve of a rank-deficient design)."""
        B = np.empty((2 * wn.size + len(self.terms), self.Y.shape[1]))
        for g, fit in zip(self.groups, self.fits(wn, z)):
            B[:, g] = fit["B"] / fit["norm"][:, None]
        return B / self.scale[None, :]


def compressed(JtJ: np.ndarray, g: np.ndarray, cost: float) -> tuple[np.ndarray, np.ndarray]:
    """A residual ``r~`` (P + 1,) and Jacobian ``J~`` (P + 1, P) with the normal matrix, gradient and
    norm of the full ones: ``J~^T J~ = J^T J``, ``J~^T r~ = J^T r``, ``|r~|^2 = |r|^2``.

    ``r~ = |r| e_last`` and ``J~ = [R; g^T / |r|]`` with ``R^T R = J^T J - g g^T / |r|^2 = J^T (I - r r^T
    / |r|^2) J`` (positive semi-definite; Cholesky, or the eigen-decomposition when it is singular).
    A least-squares step, a trust-region step and its predicted reduction depend on ``J`` and ``r``
    only through these, so scipy's trust-region iterations on the small problem are those on the full one.

    Examples
    --------
    >>> import numpy as np
    >>> J = np.random.default_rng(0).normal(size=(50, 3)); r = np.random.default_rng(1).normal(size=50)
    >>> rt, Jt = compressed(J.T @ J, J.T @ r, float(r @ r))
    >>> bool(np.allclose(Jt.T @ Jt, J.T @ J) and np.allclose(Jt.T @ rt, J.T @ r) and np.isclose(rt @ rt, r @ r))
    True
    """
    P = g.size
    rho = math.sqrt(cost) if cost > 0 else 0.0
    r = np.zeros(P + 1)
    r[P] = rho
    J = np.zeros((P + 1, P))
    if rho > 0:
        J[P] = g / rho
        rest = JtJ - np.outer(g, g) / cost
    else:
        rest = JtJ
    rest = 0.5 * (rest + rest.T)
    try:
        J[:P] = np.linalg.cholesky(rest).T
    except np.linalg.LinAlgError:
        lam, V = np.linalg.eigh(rest)
        J[:P] = np.sqrt(np.maximum(lam, 0.0))[:, None] * V.T
    return r, J


@dataclass(frozen=True)
class Fit:
    """Modes (sorted by frequency), residual-term coefficients per column, normalised RMS misfit; the
    poles as fitted (``wn`` rad/s, ``zeta``, in the modes' order: the problem's kept fit is at them)."""

    modes: list
    residuals: dict
    nrmse: float
    wn: np.ndarray | None = field(default=None, repr=False)
    zeta: np.ndarray | None = field(default=None, repr=False)


def _mode_list(wn, z, B, std_wn, std_z) -> list:
    n = wn.size
    return [Mode(float(wn[k] / (2 * np.pi)), float(z[k]), B[2 * k] + 1j * B[2 * k + 1], "global_fit",
                           float(std_wn[k] / (2 * np.pi)), float(std_z[k])) for k in range(n)]


def solve(prob: SharedProblem, init, band, *, uncertainty=True, max_nfev=200, tol=1e-10) -> Fit:
    """Variable-projection least squares of the shared poles from ``init`` [(f, zeta)], bounded to half the
    band's bottom .. twice its top and zeta in [1e-5, 0.7].

    The iterations are :func:`guidefit.modes.lsq.minimize`'s (Levenberg-Marquardt on the normal equations
    of :meth:`SharedProblem.normal`, run to ``tol**1.3``, tighter than scipy's ``trf`` with ``tol``
    was: they end where it ended, to 1e-11 in frequency on the check set of
    ``benchmarks/check_modal_same.py``), so that identify does not import :mod:`scipy.optimize`.
    """
    from guidefit.modes import lsq

    wn0 = 2 * np.pi * np.array([a for a, _ in init])
    z0 = np.array([b for _, b in init])
    n = wn0.size
    bw = (2 * np.pi * 0.5 * band[0], 2 * np.pi * 2.0 * band[1])
    lo = np.concatenate([np.full(n, math.log(bw[0])), np.full(n, math.log(1e-5))])
    hi = np.concatenate([np.full(n, math.log(bw[1])), np.full(n, math.log(0.7))])
    x0 = np.clip(np.concatenate([np.log(wn0), np.log(np.clip(z0, 1e-5, 0.7))]), lo + 1e-12, hi - 1e-12)

    def split(x):
        return np.exp(x[:n]), np.exp(x[n:])

    res = lsq.minimize(lambda x: prob.normal(*split(x)), lambda x: prob.cost(*split(x)), x0, lo, hi,
                       tol=tol**1.3, max_iter=max_nfev)
    wn, z = split(res.x)
    order = np.argsort(wn)
    wn, z = wn[order], z[order]
    B = prob.coefficients(wn, z)
    cost = res.cost
    std_wn = std_z = np.full(n, np.nan)
    if uncertainty:
        JtJ = prob.normal(wn, z)[0]
        dof = prob.Y.size - 2 * n - B.size
        if dof > 0:
            cov = np.linalg.pinv(JtJ) * cost / dof  # d ln wn, d ln zeta
            sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
            std_wn, std_z = sd[:n] * wn, sd[n:] * z
    resid = {t: B[2 * n + j].copy() for j, t in enumerate(prob.terms)}
    return Fit(_mode_list(wn, z, B, std_wn, std_z), resid, math.sqrt(cost / float(np.sum(prob.Y**2))), wn, z)


def gauss_newton(prob: SharedProblem, band, init, iterations: int = 4) -> Fit | None:
    """A few Gauss-Newton steps (step halved while the cost rises) of the shared-pole problem from
    ``init``; for refits that start next to the answer (per-run estimates, selection alternatives).
    Returns a :class:`Fit` with the fit's standard errors, or None when a pole leaves the band."""
    x = np.concatenate([np.log(2 * np.pi * np.array([a for a, _ in init])), np.log([b for _, b in init])])
    n = len(init)
    rcond = _EPS * max(prob.Y.size, 2 * n)  # numpy.linalg.lstsq's default cut-off for the full Jacobian

    def split(v):
        return np.exp(v[:n]), np.clip(np.exp(v[n:]), 1e-6, 0.69)

    cost = prob.cost(*split(x))
    for _ in range(iterations):
        rt_, Jt = compressed(*prob.normal(*split(x)))
        dx = -np.linalg.lstsq(Jt, rt_, rcond=rcond)[0]
        step = 1.0
        while step > 1e-3:
            trial = x + step * dx
            ct = prob.cost(*split(trial))
            if ct <= cost:
                break
            step /= 2
        else:
            break
        done = np.max(np.abs(step * dx)) < 1e-10
        x, cost = trial, ct
        if done:
            break
    wn, z = split(x)
    B = prob.coefficients(wn, z)
    JtJ = prob.normal(wn, z)[0]
    dof = prob.Y.size - 2 * n - B.size
    sd = np.sqrt(np.maximum(np.diag(np.linalg.pinv(JtJ)) * cost / max(dof, 1), 0.0))
    modes = _mode_list(wn, z, B, sd[:n] * wn, sd[n:] * z)
    if any(fitcore.suspicious(m, *band) for m in modes):
        return None
    order = np.argsort([m.frequency_hz for m in modes])
    return Fit([modes[k] for k in order], {t: B[2 * n + j].copy() for j, t in enumerate(prob.terms)},
               math.sqrt(cost / float(np.sum(prob.Y**2))))
