"""Modal curve fitting of one run's FRFs: variable projection of poles and residues in a band
(:func:`fit_band`, :func:`fit_modes`) and the automatic per-run fit (:func:`auto_fit`).

Built on :mod:`guidefit.modes.base` (types, peak picking, :func:`guidefit.modes.base.synthesize`)
and on :mod:`guidefit.modes.fitcore` (the basis, least squares and derivative it shares with the global fit);
every public name here is importable from :mod:`guidefit.modes` too.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence

import numpy as np

from guidefit.errors import IdentificationError
from guidefit.modes import fitcore
from guidefit.modes.halfpower import half_power, sdof_from_half_power

__all__ = ["auto_fit", "fit_band", "fit_modes"]
from guidefit.modes.base import (
    BandFit,
    HalfPowerWarning,
    Mode,
    ModeFitWarning,
    _as_frequency,
    _as_frf,
    _band_mask,
    _noise_power,
    find_peaks,
    mode_indicator,
    synthesize,
)


class _Problem:
    """Weighted, normalised band data of one fit (internal)."""

    def __init__(self, f, H, weights, terms):
        self.f = f
        self.s = 2j * np.pi * f
        self.terms = terms
        rms = np.sqrt(np.mean(np.abs(H) ** 2, axis=0))
        self.scale = np.where(rms > 0, 1.0 / np.where(rms > 0, rms, 1.0), 1.0)  # per channel
        W = np.ones((f.size, H.shape[1])) if weights is None else weights
        self.W2 = np.concatenate([W, W], axis=0)  # (2F, R) for stacked rows
        self.common = bool(np.all(W == W[:, :1]))
        self.Y = fitcore.stack(H * self.scale) * self.W2  # (2F, R)

    def _design(self, poles):
        Phi = fitcore.stack(fitcore.basis(self.s, poles, self.terms))  # (2F, L)
        norm = np.sqrt(np.sum(Phi**2, axis=0))
        norm[norm == 0] = 1.0
        return Phi / norm, norm

    def _groups(self):
        """Channel groups sharing one weighted design: all at once or one by one."""
        if self.common:
            return [slice(None)]
        return [slice(r, r + 1) for r in range(self.Y.shape[1])]

    def residual(self, poles) -> np.ndarray:
        Phi, _ = self._design(poles)
        E = np.empty_like(self.Y)
        for g in self._groups():
            w = self.W2[:, g][:, :1]
            E[:, g] = fitcore.ls_residual(Phi * w, self.Y[:, g])
        return E.ravel()

    def jacobian(self, wn, zeta) -> np.ndarray | None:
        """d residual / d (ln w_n, ln zeta), shape (2F R, 2n); ``None`` if rank deficient.

        The exact variable-projection derivative (:func:`guidefit.modes.fitcore.projected_jacobian`):
        one factorisation per channel group instead of the 2n extra residual
        evaluations of finite differences. Column scaling does not change the
        projection, so the unit-norm design is used with its columns'
        derivatives divided by the same norms.
        """
        Phi, norm = self._design(fitcore.poles(wn, zeta))
        n = wn.size
        dcols = fitcore.pole_derivatives(self.s, wn, zeta)  # (2n, F, 2) complex
        dPhi = np.concatenate([dcols.real, dcols.imag], axis=1)  # (2n, 2F, 2)
        k = np.concatenate([np.arange(n), np.arange(n)])
        pairs = np.stack([2 * k, 2 * k + 1], axis=1)
        dPhi = dPhi / norm[pairs][:, None, :]
        J = np.empty(self.Y.shape + (2 * n,))
        for g in self._groups():
            w = self.W2[:, g][:, :1]
            A = Phi * w
            E, B, solve = fitcore.ls_fit(A, self.Y[:, g])
            if solve is None:
                return None
            J[:, g, :] = fitcore.projected_jacobian(A, dPhi * w[None], pairs, E, B, solve)
        return J.reshape(-1, 2 * n)

    def coefficients(self, poles) -> np.ndarray:
        """(L, R) real coefficients of the normalised, weighted problem."""
        Phi, norm = self._design(poles)
        B = np.empty((Phi.shape[1], self.Y.shape[1]))
        for r in range(self.Y.shape[1]):
            B[:, r] = np.linalg.lstsq(Phi * self.W2[:, r : r + 1], self.Y[:, r], rcond=None)[0]
        return B / norm[:, None]


def _covariance(prob: _Problem, wn, zeta, B) -> tuple[np.ndarray, np.ndarray]:
    """Std of (wn, zeta) per mode from the full Jacobian of the weighted residual."""
    n, R = wn.size, B.shape[1]
    s = prob.s
    poles = fitcore.poles(wn, zeta)
    Phi = fitcore.stack(fitcore.basis(s, poles, prob.terms))  # (2F, L)
    L = Phi.shape[1]
    rows = 2 * s.size
    J = np.zeros((rows * R, 2 * n + R * L))
    E = np.empty((rows, R))
    for r in range(R):
        w = prob.W2[:, r]
        sl = slice(r * rows, (r + 1) * rows)
        E[:, r] = prob.Y[:, r] - w * (Phi @ B[:, r])
        J[sl, 2 * n + r * L : 2 * n + (r + 1) * L] = w[:, None] * Phi
        for k in range(n):
            A = B[2 * k, r] + 1j * B[2 * k + 1, r]
            p = poles[k]
            dA = s * s * A / (s - p) ** 2
            dB = s * s * np.conj(A) / (s - np.conj(p)) ** 2
            dp_dwn = p / wn[k]
            dp_dz = wn[k] * (-1.0 - 1j * zeta[k] / math.sqrt(1.0 - zeta[k] ** 2))
            J[sl, k] = w * fitcore.stack(dA * dp_dwn + dB * np.conj(dp_dwn))
            J[sl, n + k] = w * fitcore.stack(dA * dp_dz + dB * np.conj(dp_dz))
    dof = J.shape[0] - J.shape[1]
    if dof <= 0:
        return np.full(n, np.nan), np.full(n, np.nan)
    sigma2 = float(np.sum(E**2)) / dof
    norm = np.sqrt(np.sum(J**2, axis=0))
    norm[norm == 0] = 1.0
    Js = J / norm
    cov = np.linalg.pinv(Js.T @ Js) / np.outer(norm, norm) * sigma2
    var = np.diag(cov)[: 2 * n]
    std = np.sqrt(np.maximum(var, 0.0))
    return std[:n], std[n:]


def _solve(prob: _Problem, wn0, z0, bounds_wn, max_nfev):
    """Variable-projection least squares from initial (wn, zeta); returns (wn, zeta, cost)."""
    import scipy.optimize

    zlo, zhi = fitcore.ZETA_BOUNDS
    x0 = np.concatenate([np.log(np.clip(wn0, *bounds_wn)), np.log(np.clip(z0, zlo, zhi))])
    n = wn0.size
    lo = np.concatenate([np.full(n, math.log(bounds_wn[0])), np.full(n, math.log(zlo))])
    hi = np.concatenate([np.full(n, math.log(bounds_wn[1])), np.full(n, math.log(zhi))])
    x0 = np.clip(x0, lo + 1e-12, hi - 1e-12)

    def fun(x):
        wn, z = fitcore.unpack(x)
        return prob.residual(fitcore.poles(wn, z))

    def jac(x):
        J = prob.jacobian(*fitcore.unpack(x))
        if J is not None:
            return J
        # Rank-deficient design: forward differences, as least_squares' "2-point".
        f0 = fun(x)
        steps = np.sqrt(np.finfo(float).eps) * np.maximum(1.0, np.abs(x))
        return np.stack([(fun(x + h * e) - f0) / h for h, e in zip(steps, np.eye(x.size))], axis=1)

    res = scipy.optimize.least_squares(
        fun,
        x0,
        jac=jac,
        bounds=(lo, hi),
        method="trf",
        x_scale=1.0,
        max_nfev=max_nfev,
        xtol=1e-12,
        ftol=1e-12,
        gtol=1e-12,
    )
    wn, z = fitcore.unpack(res.x)
    return wn, z, float(np.sum(res.fun**2))


def _peak_guesses(f, H, n, min_prominence_db=1.0, min_snr_db=15.0):
    """Up to n (f_n, zeta) guesses from peaks of the band's mode indicator."""
    pk = find_peaks(
        f,
        H,
        min_prominence_db=min_prominence_db,
        min_snr_db=min_snr_db,
        floor_db=60.0,
        max_peaks=n,
    )
    mag = np.sqrt(mode_indicator(f, H))
    return [_sdof_guess(f, mag, int(i), float(fp))[:2] for fp, i in zip(pk.frequency_hz, pk.index)]


def _sdof_guess(f, mag, i, fp) -> tuple[float, float, bool]:
    """(f_n, zeta, ok) from half-power on a magnitude; (fp, 0.03, False) if that fails."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", HalfPowerWarning)
            hp = half_power(f, mag, i)
        est = sdof_from_half_power(hp.f1_hz, hp.f2_hz)
        return est.f_n_hz, min(max(est.zeta, 1e-4), 0.5), True
    except IdentificationError:
        return fp, 0.03, False


def _initial(prob: _Problem, H, n_modes, bounds_wn, max_nfev):
    """Initial poles: peaks of the band, then greedy additions at residual peaks."""
    f = prob.f
    guesses = _peak_guesses(f, H, n_modes)
    if not guesses:
        i = int(np.argmax(mode_indicator(f, H)))
        i = min(max(i, 1), f.size - 2)
        guesses = [_sdof_guess(f, np.sqrt(mode_indicator(f, H)), i, float(f[i]))[:2]]
    wn = 2 * np.pi * np.array([g[0] for g in guesses])
    z = np.array([g[1] for g in guesses])
    while wn.size < n_modes:
        wn, z, _ = _solve(prob, wn, z, bounds_wn, max_nfev)
        B = prob.coefficients(fitcore.poles(wn, z))
        model = fitcore.basis(prob.s, fitcore.poles(wn, z), prob.terms) @ B
        E = H * prob.scale - model
        cand = _peak_guesses(f, E, 3, min_prominence_db=0.5, min_snr_db=None)
        i = int(np.argmax(mode_indicator(f, E)))
        cand.append((float(f[i]), 0.03))
        best = None
        for fc, zc in cand:
            wn_t, z_t, cost = _solve(
                prob, np.append(wn, 2 * np.pi * fc), np.append(z, zc), bounds_wn, max_nfev
            )
            if best is None or cost < best[2]:
                best = (wn_t, z_t, cost)
        wn, z = best[0], best[1]
    return wn, z


def _initial_from(initial, n_modes):
    init = list(initial)
    if len(init) != n_modes:
        raise ValueError(f"initial must hold n_modes={n_modes} entries, got {len(init)}")
    fn, z = [], []
    for k, m in enumerate(init):
        if isinstance(m, Mode):
            fk, zk = m.frequency_hz, m.damping_ratio
        else:
            try:
                fk, zk = (float(v) for v in m)
            except (TypeError, ValueError):
                raise ValueError(
                    f"initial[{k}] must be a Mode or (frequency_hz, zeta), got {m!r}"
                ) from None
        if not (fk > 0 and 0 < zk < 1):
            raise ValueError(f"initial[{k}] needs frequency_hz > 0 and 0 < zeta < 1, got {m!r}")
        fn.append(fk)
        z.append(zk)
    return 2 * np.pi * np.array(fn), np.array(z)


def _band_arguments(f, Hf, band_hz, n_modes, residuals, weights):
    """:func:`fit_band`'s arguments checked: ``(lo, hi, sel, terms, n_bins, W)`` with the band's
    bins ``sel``, the residual terms, the bin count and the weights in the band (or ``None``).

    Raises ``ValueError`` naming the argument for a malformed band, mode count, residual term or
    weights, or a band with too few bins for ``n_modes``.
    """
    try:
        lo, hi = (float(b) for b in band_hz)
    except (TypeError, ValueError):
        raise ValueError(f"band_hz must be (f_lo, f_hi) in Hz, got {band_hz!r}") from None
    sel = _band_mask(f, lo, hi, "band_hz")
    if not isinstance(n_modes, (int, np.integer)) or n_modes < 1:
        raise ValueError(f"n_modes must be an integer >= 1, got {n_modes!r}")
    terms = (residuals,) if isinstance(residuals, str) else tuple(residuals)
    for term in terms:
        if term not in fitcore.RESIDUAL_TERMS:
            raise ValueError(f"residuals entries must be in {tuple(fitcore.RESIDUAL_TERMS)}, got {term!r}")
    if len(set(terms)) != len(terms):
        raise ValueError(f"residuals has repeated entries: {terms}")
    n_bins = int(sel.sum())
    n_lin = 2 * n_modes + len(terms)
    need = n_lin + n_modes + 2
    if n_bins < need:
        raise ValueError(
            f"band_hz={band_hz} holds {n_bins} bins; {n_modes} modes need at least {need}"
        )
    W = None
    if weights is not None:
        W = np.asarray(weights, dtype=float)
        if W.shape == (f.size,):
            W = np.repeat(W[:, None], Hf.shape[1], axis=1)
        if W.shape != Hf.shape or not np.all(np.isfinite(W)) or np.any(W < 0):
            raise ValueError(
                f"weights must be finite, >= 0 and of shape ({f.size},) or {Hf.shape}, "
                f"got shape {np.shape(weights)}"
            )
        W = W[sel]
    return lo, hi, sel, terms, n_bins, W


def fit_band(
    frequency_hz,
    H,
    band_hz: tuple[float, float],
    n_modes: int,
    initial: Sequence | None = None,
    *,
    residuals: Sequence[str] = fitcore.DEFAULT_RESIDUALS,
    weights=None,
    max_nfev: int = 200,
    uncertainty: bool = True,
) -> BandFit:
    """Multi-channel modal curve fit in a band; :func:`fit_modes` plus residual terms.

    See :func:`fit_modes` for the method and the parameters.

    Returns
    -------
    BandFit
        Modes, residual-term coefficients per channel, the band, the
        normalised RMS misfit and the bin count.

    Examples
    --------
    >>> import numpy as np
    >>> f = np.arange(2000.0, 3000.0, 10.0)
    >>> s = 2j * np.pi * f
    >>> p = 2 * np.pi * 2400 * (-0.02 + 1j * np.sqrt(1 - 0.02**2))
    >>> A = np.array([1e-6j, -2e-6j])
    >>> H = s[:, None]**2 * (A / (s[:, None] - p) + A.conj() / (s[:, None] - p.conjugate())) + 0.1
    >>> fit = fit_band(f, H, (2000, 3000), 1)
    >>> round(fit.modes[0].frequency_hz, 3), np.round(fit.residuals["lower"], 6)
    (2400.0, array([0.1, 0.1]))
    """
    f = _as_frequency(frequency_hz)
    Hf = _as_frf(f, H)
    lo, hi, sel, terms, n_bins, W = _band_arguments(f, Hf, band_hz, n_modes, residuals, weights)
    fb, Hb = f[sel], Hf[sel]
    prob = _Problem(fb, Hb, W, terms)
    if not np.any(prob.Y):
        raise IdentificationError(f"fit_band: H is zero in band_hz={band_hz}")
    bounds_wn = (2 * np.pi * 0.5 * fb[0], 2 * np.pi * 2.0 * fb[-1])
    if initial is None:
        wn0, z0 = _initial(prob, Hb, n_modes, bounds_wn, max_nfev)
    else:
        wn0, z0 = _initial_from(initial, n_modes)
    wn, z, cost = _solve(prob, wn0, z0, bounds_wn, max_nfev)
    order = np.argsort(wn)
    wn, z = wn[order], z[order]
    poles = fitcore.poles(wn, z)
    B = prob.coefficients(poles)  # for unit-RMS channels
    if uncertainty:
        std_wn, std_z = _covariance(prob, wn, z, B)
    else:
        std_wn = std_z = np.full(n_modes, np.nan)
    B = B / prob.scale[None, :]
    modes = []
    for k in range(n_modes):
        A = B[2 * k] + 1j * B[2 * k + 1]
        fk = float(wn[k] / (2 * np.pi))
        mode = Mode(
            fk, float(z[k]), A, "curve_fit", float(std_wn[k] / (2 * np.pi)), float(std_z[k])
        )
        if fitcore.suspicious(mode, fb[0], fb[-1]):
            warnings.warn(
                f"fit_band: mode {k} at {fk:.1f} Hz, zeta={z[k]:.3g} is outside "
                f"band_hz={band_hz} or at a damping bound; n_modes={n_modes} may be too many",
                ModeFitWarning,
                stacklevel=2,
            )
        modes.append(mode)
    coef = {t: B[2 * n_modes + j].copy() for j, t in enumerate(terms)}
    nrmse = math.sqrt(cost / float(np.sum(prob.Y**2)))
    return BandFit(modes, coef, (lo, hi), nrmse, n_bins)


def fit_modes(
    frequency_hz,
    H,
    band_hz: tuple[float, float],
    n_modes: int,
    initial: Sequence | None = None,
    *,
    residuals: Sequence[str] = fitcore.DEFAULT_RESIDUALS,
    weights=None,
    max_nfev: int = 200,
    uncertainty: bool = True,
) -> list[Mode]:
    # long because: its docstring is the method's description and the parameters' reference; the body is one call
    """Fit ``n_modes`` modes with global poles to all channels in a band.

    The model is the pole-residue accelerance of the module docstring,
    ``H_r = (jw)^2 sum_k [A_rk/(jw - p_k) + A_rk*/(jw - p_k*)] + L_r + U_r (jw)^2``,
    with poles shared by all channels and complex residues per channel
    (conjugate pairs enforced). It is solved by variable projection: for
    given poles the residues and residual terms are a linear least-squares
    problem (real and imaginary parts stacked); the poles, parametrised by
    ``ln w_n`` and ``ln zeta``, minimise the projected misfit with
    :func:`scipy.optimize.least_squares`, given the exact Jacobian of the
    projected residual (Golub and Pereyra's formula, one Cholesky factor per
    evaluation; finite differences took 2n extra residual evaluations). Each channel is scaled to unit RMS in
    the band, so all channels count alike. The initial poles come from the
    band's peaks (:func:`find_peaks`, SDOF half-power damping); while fewer
    peaks than ``n_modes`` are seen (merged close modes), a mode is added at
    the strongest peak of the misfit and all are refitted.

    Parameters
    ----------
    frequency_hz : array_like
        ``(F,)`` strictly increasing frequencies in Hz.
    H : array_like
        ``(F,)`` or ``(F, R)`` complex accelerance in (m/s^2)/N.
    band_hz : (float, float)
        Fitted band in Hz. Include about two half-power bandwidths on each
        side of the outer modes; modes just outside the band are only
        approximated by the residual terms, so include a near neighbour
        in the band (and in ``n_modes``) rather than cut through its flank.
    n_modes : int
        Number of modes in the band.
    initial : sequence of Mode or (frequency_hz, zeta), optional
        Start values (``n_modes`` entries) instead of peak picking, e.g. the
        modes of the all-hits fit when refitting jackknife subsets.
    residuals : sequence of str, default ("lower", "lower_damping", "upper")
        Residual terms for the modes outside the band, each with one real
        coefficient per channel: ``"lower"`` ``L_r`` (the mass line of the
        modes below), ``"lower_damping"`` ``L1_r / (jw)`` (their damping
        tail), ``"upper"`` ``U_r (jw)^2`` (the residual compliance of the
        modes above), ``"upper_damping"`` ``U1_r (jw)^3``. They are the
        leading terms of a mode's accelerance far above (``1, 1/s``) and far
        below (``s^2, s^3``) its pole. In accelerance the modes below a band
        contribute O(1) and their damping tail decays only as ``1/w``, while
        modes above are suppressed by ``(w/w_k)^2``; hence the default. On
        the guideway test system of ``tests/test_modes.py`` the default cut
        the close pair's damping bias from 3.3 % (real ``L_r``, ``U_r`` only)
        to 0.2 %; adding ``"upper_damping"`` made the 10 %-damped mode's
        frequency 0.07 % biased at 3 % noise.
    weights : array_like, optional
        ``(F,)`` or ``(F, R)`` non-negative weights on the residual of each
        bin (e.g. derived from coherence), applied after the RMS scaling.
    max_nfev : int, default 200
        Function-evaluation limit of each nonlinear solve.
    uncertainty : bool, default True
        Compute ``frequency_std_hz`` and ``damping_std`` (NaN when False, e.g.
        for jackknife replicates, whose scatter is the uncertainty).

    Returns
    -------
    list of Mode
        Sorted by frequency; ``method="curve_fit"``. ``frequency_std_hz`` and
        ``damping_std`` are ``sqrt(diag(s^2 (J^T J)^-1))`` from the full
        Jacobian at the optimum, ``s^2`` the residual variance; they assume
        independent bins and ignore model error (band truncation).

    Raises
    ------
    ValueError
        For malformed arguments or a band with too few bins.
    guidefit.errors.IdentificationError
        If ``H`` is zero in the band.

    Warns
    -----
    ModeFitWarning
        If a fitted mode ends outside the band or at a damping bound.

    Examples
    --------
    >>> import numpy as np
    >>> f = np.arange(500.0, 1800.0, 10.0)
    >>> s = 2j * np.pi * f
    >>> wn, zeta = 2 * np.pi * 1075.0, 0.105
    >>> H = s**2 * 0.45 / (wn**2 + s**2 + 2 * zeta * wn * s)   # 1/m = 0.45 1/kg
    >>> [m] = fit_modes(f, H, (500.0, 1800.0), 1)
    >>> round(m.frequency_hz, 2), round(m.damping_ratio, 4), np.round(m.modal_constants.real, 4)
    (1075.0, 0.105, array([0.45]))
    """
    return fit_band(
        frequency_hz,
        H,
        band_hz,
        n_modes,
        initial,
        residuals=residuals,
        weights=weights,
        max_nfev=max_nfev,
        uncertainty=uncertainty,
    ).modes


def auto_fit(
    frequency_hz,
    H,
    f_min: float,
    f_max: float,
    *,
    min_prominence_db: float = 3.0,
    band_factor: float = 2.5,
    grow: bool = True,
    refine: bool = True,
    **fit_kwargs,
) -> list[Mode]:
    """Find and fit all modes between ``f_min`` and ``f_max`` without a model.

    1. :func:`find_peaks` lists the peaks; each gets a half-power bandwidth
       ``B`` from :func:`half_power` on ``sqrt(MIF)`` (5 % of the frequency
       if that fails) and the interval ``f_peak +/- band_factor * B``.
    2. Peaks whose intervals overlap form a group; each group is fitted by
       :func:`fit_band` with one mode per peak in the union of its intervals
       (clipped to ``[f_min, f_max]``). Modes that end outside the band or at
       a damping bound are dropped and the rest refitted.
    3. With ``grow`` (default), a group gets up to two more modes while its
       misfit exceeds 5 % and three times the noise level and an added mode
       (started at a peak of the misfit, in a band widened to hold it) is well
       determined and halves the squared misfit: a heavily damped mode next to
       a light one often has no peak of its own.
    4. With ``refine`` (default), all modes are refitted together over the
       union of the group bands, starting from the group results, so the
       flanks of neighbouring groups are modelled by modes instead of
       residual terms. The joint result replaces the group results unless it
       fits worse.

    Parameters
    ----------
    frequency_hz : array_like
        ``(F,)`` strictly increasing frequencies in Hz.
    H : array_like
        ``(F,)`` or ``(F, R)`` complex accelerance.
    f_min, f_max : float
        Search range in Hz.
    min_prominence_db : float, default 3.0
        Passed to :func:`find_peaks`.
    band_factor : float, default 2.5
        Half-width of a peak's fit interval in half-power bandwidths.
    grow : bool, default True
        Add modes that have no peak of their own (step 3).
    refine : bool, default True
        Refit all modes jointly at the end.
    **fit_kwargs
        ``residuals``, ``weights``, ``max_nfev`` for :func:`fit_band`.

    Returns
    -------
    list of Mode
        Sorted by frequency.

    Raises
    ------
    guidefit.errors.IdentificationError
        If no peak is found in ``[f_min, f_max]``.

    Examples
    --------
    >>> import numpy as np
    >>> f = np.arange(500.0, 5000.0, 5.0)
    >>> s = 2j * np.pi * f
    >>> def acc(fn, z, c):
    ...     w = 2 * np.pi * fn
    ...     return c * s**2 / (w**2 + s**2 + 2 * z * w * s)
    >>> H = np.stack([acc(1075, 0.105, 0.4) + acc(3450, 0.03, 0.5),
    ...               acc(1075, 0.105, 0.3) - acc(3450, 0.03, 0.2)], axis=1)
    >>> modes = auto_fit(f, H, 600.0, 4500.0)
    >>> [(round(m.frequency_hz, 1), round(m.damping_ratio, 4)) for m in modes]
    [(1075.0, 0.105), (3450.0, 0.03)]
    """
    f = _as_frequency(frequency_hz)
    Hf = _as_frf(f, H)
    if not band_factor > 0:
        raise ValueError(f"band_factor must be > 0, got {band_factor}")
    pk = find_peaks(f, Hf, f_min=f_min, f_max=f_max, min_prominence_db=min_prominence_db)
    if pk.index.size == 0:
        raise IdentificationError(
            f"auto_fit: no peak with prominence >= {min_prominence_db} dB "
            f"between f_min={f_min} Hz and f_max={f_max} Hz"
        )
    groups = _peak_groups(f, Hf, pk, band_factor)
    lo_all, hi_all = max(f_min, f[0]), min(f_max, f[-1])
    modes, groups_fitted = _fit_groups(f, Hf, groups, lo_all, hi_all, grow, fit_kwargs)
    if not modes:
        raise IdentificationError(
            f"auto_fit: no mode could be fitted between f_min={f_min} Hz and f_max={f_max} Hz"
        )
    if refine and len(groups_fitted) > 1 and len(modes) <= _MAX_JOINT_MODES:
        modes = _refit_jointly(f, Hf, modes, groups_fitted, fit_kwargs)
    return sorted(modes, key=lambda m: m.frequency_hz)


def _peak_groups(f, Hf, pk, band_factor) -> list[list[tuple]]:
    """:func:`auto_fit`'s step 1: the peaks ``pk`` as ``(f_n, zeta, interval low, interval high)``
    (half-power estimates on ``sqrt(MIF)``), sorted, in groups of overlapping intervals."""
    order = np.argsort(pk.frequency_hz)
    mag = np.sqrt(mode_indicator(f, Hf))
    items = []  # (f_n, zeta, interval low, interval high)
    for j in order:
        fp, i = float(pk.frequency_hz[j]), int(pk.index[j])
        fn, z, ok = _sdof_guess(f, mag, i, fp)
        bw = 2.0 * z * fn if ok else 0.1 * fp
        items.append((fn, z, fp - band_factor * bw, fp + band_factor * bw))
    groups = [[items[0]]]
    for it in items[1:]:
        if it[2] <= max(g[3] for g in groups[-1]):
            groups[-1].append(it)
        else:
            groups.append([it])
    return groups


def _fit_groups(f, Hf, groups, lo_all, hi_all, grow, fit_kwargs) -> tuple[list[Mode], list]:
    """:func:`auto_fit`'s steps 2 and 3: each group fitted in its band (:func:`_fit_dropping`) and,
    with ``grow``, given the modes it misses (:func:`_grow`) within its territory.

    Returns the modes of all groups and ``(band, modes)`` of each group fitted.
    """
    modes, groups_fitted = [], []
    for j, g in enumerate(groups):
        # the group's territory ends a half-power bandwidth short of the modes fitted
        # so far below it and of the next group's peaks above it
        below = [m.frequency_hz * (1 + 2 * m.damping_ratio) for m in modes]
        t_lo = max([lo_all, *below])
        t_hi = (
            hi_all
            if j == len(groups) - 1
            else min(hi_all, min(it[0] * (1 - 2 * it[1]) for it in groups[j + 1]))
        )
        band = _widen(
            f,
            max(min(it[2] for it in g), lo_all),
            min(max(it[3] for it in g), hi_all),
            len(g),
            lo_all,
            hi_all,
        )
        fit = _fit_dropping(f, Hf, band, [(it[0], it[1]) for it in g], fit_kwargs)
        if fit is not None:
            fit = _grow(f, Hf, fit, (t_lo, t_hi), fit_kwargs) if grow else fit
            modes.extend(fit.modes)
            groups_fitted.append((fit.band_hz, fit.modes))
    return modes, groups_fitted


def _refit_jointly(f, Hf, modes, groups_fitted, fit_kwargs) -> list[Mode]:
    """:func:`auto_fit`'s step 4: all modes refitted over the union of the group bands; the joint
    fit replaces ``modes`` unless a mode ends at a bound or moved by more than half its bandwidth."""
    band = (groups_fitted[0][0][0], groups_fitted[-1][0][1])
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", ModeFitWarning)
            joint = fit_band(f, Hf, band, len(modes), modes, **fit_kwargs).modes
    except ModeFitWarning:
        joint = None
    # keep the joint fit only if no mode moved by more than half its bandwidth
    if joint is not None and all(
        abs(a.frequency_hz - b.frequency_hz) <= b.damping_ratio * b.frequency_hz
        for a, b in zip(joint, sorted(modes, key=lambda m: m.frequency_hz))
    ):
        return joint
    return modes


_MAX_JOINT_MODES = 12


def _widen(f, lo, hi, n_modes, lo_all, hi_all, min_bins=None):
    """Widen (lo, hi) symmetrically, within (lo_all, hi_all), to hold enough bins for a fit."""
    need = min_bins if min_bins is not None else 3 * n_modes + 12
    while np.count_nonzero((f >= lo) & (f <= hi)) < need:
        if lo <= lo_all and hi >= hi_all:
            break
        step = float(np.median(np.diff(f)))
        lo, hi = max(lo - step, lo_all), min(hi + step, hi_all)
    return lo, hi


def _quiet_fit(f, H, band, init, fit_kwargs) -> BandFit | None:
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ModeFitWarning)
            return fit_band(f, H, band, len(init), init, **fit_kwargs)
    except ValueError:  # too few bins for this many modes
        return None


def _fit_dropping(f, H, band, init, fit_kwargs) -> BandFit | None:
    """Fit a group; drop modes that end outside the band or at a bound, refit; None if none."""
    while init:
        fit = _quiet_fit(f, H, band, init, fit_kwargs)
        if fit is None:
            init = init[:-1]
            continue
        good = [m for m in fit.modes if not fitcore.suspicious(m, band[0], band[1])]
        if len(good) == len(fit.modes):
            return fit
        init = good
    return None


def _noise_nrmse(f, H, band) -> float:
    """Misfit that noise alone would leave, in the units of BandFit.nrmse."""
    sel = (f >= band[0]) & (f <= band[1])
    power = np.mean(np.abs(H[sel]) ** 2, axis=0)
    used = power > 0
    return math.sqrt(float(np.mean(_noise_power(H[sel])[used] / power[used])) / 2.0)


def _misfit(f, H, band, fit: BandFit) -> float:
    """Relative misfit (as BandFit.nrmse, unweighted) of a fit's model over ``band``."""
    sel = (f >= band[0]) & (f <= band[1])
    power = np.mean(np.abs(H[sel]) ** 2, axis=0)
    power[power == 0] = 1.0
    E = H[sel] - synthesize(f[sel], fit.modes, fit.residuals)
    return math.sqrt(float(np.mean(np.mean(np.abs(E) ** 2, axis=0) / power)))


def _grow(f, H, fit: BandFit, territory, fit_kwargs, max_extra=2) -> BandFit:
    """Add modes a group misses (e.g. a heavily damped mode without a peak of its own).

    While the group's misfit exceeds both 5 % and three times the noise
    level (smaller misfits are mostly band truncation), a mode is tried at each of the strongest peaks of the misfit, in a band
    widened (within ``territory``, which ends short of the neighbouring
    groups' peaks) to 2.5 of its half-power bandwidths either side. The best
    trial is kept if all its modes lie inside its band with a free damping
    ratio, the new mode is well determined (standard deviations below 10 %
    of its bandwidth and 30 % of its damping ratio) and it halves the squared
    misfit over the group's band.
    """
    band = fit.band_hz
    noise = _noise_nrmse(f, H, band)
    for _ in range(max_extra):
        current = _misfit(f, H, band, fit)
        if current <= max(0.05, 3.0 * noise):
            break
        sel = (f >= fit.band_hz[0]) & (f <= fit.band_hz[1])
        E = H[sel] - synthesize(f[sel], fit.modes, fit.residuals)
        cand = _peak_guesses(f[sel], E, 3, min_prominence_db=0.5, min_snr_db=None)
        i = int(np.argmax(mode_indicator(f[sel], E)))
        cand.append((float(f[sel][i]), 0.05))
        best, best_misfit = None, current
        for fc, zc in cand:
            half = 5.0 * min(max(zc, 0.005), 0.3) * fc
            lo = max(min(fit.band_hz[0], fc - half), territory[0])
            hi = min(max(fit.band_hz[1], fc + half), territory[1])
            if not lo < fc < hi:
                continue
            trial = _quiet_fit(
                f, H, (lo, hi), [*fit.modes, (fc, min(max(zc, 0.005), 0.3))], fit_kwargs
            )
            if trial is None or any(fitcore.suspicious(m, lo, hi) for m in trial.modes):
                continue
            new = min(trial.modes, key=lambda m: abs(m.frequency_hz - fc))
            bandwidth = 2.0 * new.damping_ratio * new.frequency_hz
            if not (
                new.frequency_std_hz < 0.1 * bandwidth and new.damping_std < 0.3 * new.damping_ratio
            ):
                continue
            m = _misfit(f, H, band, trial)
            if m < best_misfit:
                best, best_misfit = trial, m
        if best is None or best_misfit**2 > 0.5 * current**2:
            break
        fit = best
    return fit
