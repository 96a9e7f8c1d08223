r"""``amplitude_dependence``: nonlinear preloaded Hertz contacts; frequencies fall as hits unload the rows.

Each element follows the guide's preloaded contact law ``Q = C delta^e``
(:func:`guidefit.model.static.roller_force`, calibration "nominal": K_n at
the guide's preload equals the vibration model's): Palmgren's line contact,
``e = 10/9``, for rollers (Eq. 4), Hertz point contact, ``e = 3/2``, for balls
(Eq. 3); :func:`guidefit.model.static.exponent`. With preload
``Delta' = p Delta`` (``p`` = ``preload_factor``) the small-amplitude element
stiffness is ``K_n p^(e-1)`` (rollers ``K_n ~ delta^(1/9)``, balls
``K_n ~ delta^(1/2)``): that is the linear model (``apply``).

Tried only where there is force-level information whose frequencies change
with hit force (``gate``), and accepted only when the fitted preload itself
predicts that trend (``accept``): without it the effect would act as a hidden
global stiffness scale (``contact_stiffness`` is that effect).

Its fit (``forward``) is the describing-function model below, a fast
approximation: every model mode m rings after a half-sine hit of peak force
F and duration T with modal amplitude ``A_m = |b_m| F |P(w_m)| / w_m``,
decaying as ``exp(-zeta_m w_m t)``; roller i moves with the RMS sum
``a_i(t) = sqrt(sum_m (g_i . phi_m A_m(t))^2)``; mode j's frequency at time
t is the Rayleigh quotient with each roller's describing-function stiffness
``k_eq(a) = K_n p^(e-1) D(a/Delta')`` at ``a_i(t)``; the chirped decay is
fitted by one pole in the band of identify's refit. Every prediction carries
a model-form error of :data:`AMPLITUDE_MODEL_FORM` of its predicted shift
(docs/explain.md, "Amplitude dependence").
"""

from __future__ import annotations

import math

import numpy as np

from guidefit.model import vibration as vib
from guidefit.model.effects.base import DocRow, EffectDef, Forward, Parameter, Variant, log_free

#: Model-form error of the describing-function model, as a share of the frequency shift it predicts
#: (against identify on RK4-simulated recordings the predicted shift is off by up to a factor 2).
AMPLITUDE_MODEL_FORM = 0.5
#: Largest predicted shift (2 % of the frequency) that the model's error allowance grows with.
AMPLITUDE_SHIFT_CAP = 0.02
#: Damping ratio of a mode that gives none (simulate's default for most modes).
DEFAULT_DECAY_DAMPING = 0.02
#: p-value below which force levels show a trend with hit force (the effect is tried only then), and
#: below which the fitted model's own predicted trend must be detectable (the effect is accepted only then).
TREND_P_VALUE = 0.01
_DECAY_TIMES = np.linspace(0.0, 1.0, 65) ** 2  # t / t_end at which w(t) is evaluated (dense early)
_DF_CACHE: dict = {}


def apply(spec, guide, p):
    """Small-amplitude (linearised) model: K_n ~ Delta^(e-1): Delta^(1/9) for rollers, Eq. (4), Delta^(1/2) for
    balls, Eq. (3)."""
    from guidefit.model import static

    return vib.scale_roller_stiffness(spec, p["preload_factor"] ** (static.exponent(guide) - 1.0))


def effective_force(hit_forces_n) -> float:
    """Force (N) at which a frequency falling as F^2 equals that of the H1 average of hits.

    H1 = sum X F* / sum |F|^2 weights each hit's FRF by its force squared, so
    the fitted frequency is about the F^2-weighted mean of the hits'
    frequencies; with ``f(F) = f0 - c F^2`` (the describing function below
    lift-off, ``1 + (e-1)(e-2) r^2/8``: ``1 - r^2/81`` for rollers, ``1 - r^2/32`` for
    balls) that is ``f(F_eff)``,
    ``F_eff = sqrt(sum F^4 / sum F^2)``: above the mean force when the
    forces spread.

    >>> round(effective_force([100.0, 200.0, 300.0]), 1)
    264.6
    >>> effective_force([250.0, 250.0])
    250.0
    """
    forces = np.asarray(hit_forces_n, float)
    return float(np.sqrt(np.sum(forces**4) / np.sum(forces**2)))


def describing_function_table(guide):
    """(ln r, D(r)): D = k_eq(a) / K_n(Delta) with r = a / Delta, the first harmonic of the guide's contact law.

    Below lift-off (r < 1) ``D = 1 + (e-1)(e-2) r^2/8 + O(r^4)`` for ``Q = C delta^e``
    (:func:`guidefit.model.static.exponent`): ``1 - r^2/81`` for rollers, ``1 - r^2/32`` for balls.
    """
    from guidefit.model import static

    key = (guide.name, guide.preload_m, guide.roller_stiffness_n_per_m, static.exponent(guide))
    if key in _DF_CACHE:
        return _DF_CACHE[key]
    delta = guide.preload_m
    r = np.logspace(-3, 3, 301)
    theta = (np.arange(2048) + 0.5) * 2 * math.pi / 2048
    sin = np.sin(theta)
    k0 = float(static.roller_stiffness(delta, guide, "nominal"))
    d = np.array([2.0 * np.mean(static.roller_force(delta * (1 + x * sin), guide, "nominal") * sin)
                  / (x * delta * k0) for x in r])
    _DF_CACHE[key] = (np.log(r), d)
    return _DF_CACHE[key]


def pulse_spectrum(w: float, t: float) -> float:
    """|int_0^T sin(pi s / T) e^(-i w s) ds| of a unit half-sine pulse of duration T (s), w in rad/s."""
    a = math.pi / t
    if abs(a - w) < 1e-9 * a:
        return t / 2.0
    return abs(a * (1 + np.exp(-1j * w * t)) / (a * a - w * w))


def roller_modal(spec, sol) -> np.ndarray:
    """(N, n_modes) roller deflection per unit modal coordinate, support body included."""
    from dataclasses import replace

    g = vib.roller_gradients(spec.rollers)
    if spec.support is not None:
        rel = spec.rollers.position_m - np.asarray(spec.support.reference_m, float)
        g_body = vib.roller_gradients(replace(spec.rollers, position_m=rel))
        free = np.isfinite(np.asarray(spec.support.stiffness_to_ground, float))
        g = np.hstack([g, -g_body[:, free]])
    return g @ sol.shapes


def amplitude_frequency(guide, spec, sol, j: int, force: float, hit, preload_factor: float,
                        roller_modal_=None, zetas=None, band: float | None = None) -> float:
    """Frequency (Hz) that a modal fit finds for model mode j after a hit of peak force F (N).

    ``hit`` = (point_m, unit direction, pulse_s). Every model mode m rings
    after the hit with modal amplitude ``A_m(t) = A_m exp(-zeta_m w_m t)``; a
    roller's excursion is the RMS sum ``a_i(t) = sqrt(sum_m (g_i . phi_m A_m(t))^2)``
    (so a vertical hit also softens pitch and roll), and mode j's frequency
    at time t is the Rayleigh quotient with each roller's describing-function
    stiffness at ``a_i(t)``. The resulting decay is fitted as identify does
    (:func:`decay_fit_frequency`, in the relative half-width ``band`` of the
    refit, default +/- max(3 zeta, 3 %)). ``roller_modal_``: :func:`roller_modal`
    of (spec, sol) if already computed; ``zetas``: damping ratio per model
    mode (nan or missing: :data:`DEFAULT_DECAY_DAMPING`).
    """
    log_r, table = describing_function_table(guide)
    point, direction, pulse = hit
    w_all = 2 * math.pi * sol.frequencies_hz
    b = direction @ (vib.rigid_body_map(point) @ sol.shapes[:5])
    a0 = np.abs(b) * force * np.array([pulse_spectrum(w, pulse) for w in w_all]) / w_all
    z = np.full(w_all.size, DEFAULT_DECAY_DAMPING)
    if zetas is not None:
        zz = np.asarray(zetas, float)
        ok = np.isfinite(zz) & (zz > 0) & (zz < 0.5)
        z[ok] = zz[ok]
    c = roller_modal(spec, sol) if roller_modal_ is None else roller_modal_
    k = spec.rollers.stiffness_n_per_m
    delta = preload_factor * guide.preload_m
    w0, zj = w_all[j], z[j]
    t_end = math.log(1e4) / (zj * w0)
    t = t_end * _DECAY_TIMES
    amp = a0[None, :] * np.exp(-(z * w_all)[None, :] * t[:, None])  # (times, modes)
    r = np.sqrt(np.square(c) @ np.square(amp).T) / delta  # (rollers, times)
    d = np.interp(np.log(np.maximum(r, 1e-3)), log_r, table)
    w = np.sqrt(np.maximum(w0**2 + np.sum((k * c[:, j] ** 2)[:, None] * (d - 1.0), axis=0), (0.05 * w0) ** 2))
    if np.max(np.abs(w - w0)) <= 1e-7 * w0:
        return float(w0 / (2 * math.pi))
    return decay_fit_frequency(w0, w, zj, band)


def decay_fit_frequency(w0: float, w_of_time: np.ndarray, zeta: float, band: float | None = None) -> float:
    """Frequency (Hz) of a single-pole fit to the spectrum of a decay with a time-varying frequency.

    The response ``a(t) sin(theta(t))``, ``a = exp(-zeta w0 t)``,
    ``theta' = w(t) sqrt(1 - zeta^2)`` (``w_of_time`` in rad/s at
    ``_DECAY_TIMES`` of ``t_end = ln(1e4) / (zeta w0)``), is transformed
    and fitted near its peak (relative half-width ``band``, default
    +/- max(3 zeta, 3 %) as identify's force-level refits) by
    ``r/(s - p) + c`` (linearised, two reweighting passes towards the output
    error). A fit of an FRF weights the slowly sweeping small-amplitude tail
    most, so it sees a smaller drop than the energy-weighted mean of ``w``.
    """
    f0 = w0 / (2 * math.pi)
    fs = 16.0 * f0
    t_end = math.log(1e4) / (zeta * w0)
    n = int(min(max(t_end * fs, 256), 65536))
    t = np.arange(n) / fs
    level = np.exp(-zeta * w0 * t)
    w = np.interp(t, t_end * _DECAY_TIMES, w_of_time) * math.sqrt(1.0 - zeta * zeta)  # |p| = w
    theta = np.concatenate([[0.0], np.cumsum(0.5 * (w[1:] + w[:-1]) / fs)])
    x = -(w**2) * level * np.sin(theta)
    nfft = 1 << int(math.ceil(math.log2(8 * n)))
    spec = np.fft.rfft(x, nfft)
    freq = np.arange(spec.size) * fs / nfft
    half = (max(3.0 * zeta, 0.03) if band is None else band) * f0
    sel = (freq > f0 - half) & (freq < f0 + half)
    h, s = spec[sel], 2j * math.pi * freq[sel]
    a = np.column_stack([np.ones_like(h), h, s])
    weight = np.ones(h.size)
    pole = complex(-zeta * w0, w0)
    for _ in range(3):
        coef = np.linalg.lstsq(a * weight[:, None], h * s * weight, rcond=None)[0]
        pole = complex(coef[1])
        weight = 1.0 / np.maximum(np.abs(s - pole), 1e-12 * w0)
    return float(abs(pole) / (2 * math.pi))


def simulated_forward(req, measured) -> Forward:
    """The forward model of :mod:`guidefit.nonlinear`: every level's hits simulated with the Hertz law and
    passed through the measurement's windows, H1 and one-pole fit.

    ``measured``: the registered :class:`guidefit.nonlinear.MeasuredLevel` of
    each level. The simulated apparent/small-amplitude frequency ratio of the
    guide (on a grid of preload factors, interpolated) scales the candidate
    model's small-amplitude frequency, so other linear effects combine with
    it; a mode compared through its levels is their H1 (sum F^2) weighted
    mean. Model-form error: :data:`guidefit.nonlinear.FORWARD_MODEL_ERROR`.
    """
    from guidefit import nonlinear

    fm, lv, pairing = req.solution.frequencies_hz, req.levels, req.mode_model
    ok = req.level_model >= 0
    small = np.where(ok, fm[np.maximum(req.level_model, 0)], np.nan)
    level_hz = np.where(ok, nonlinear.level_predictions(req.guide, measured, small, req.parameters["preload_factor"],
                                                        req.cache), np.nan)
    paired = pairing >= 0
    f_pred = np.where(paired, fm[np.maximum(pairing, 0)], np.nan)
    for i in np.flatnonzero(paired):
        # the levels measure their own mode only; another mode of the lowest run is at small amplitude
        js = [k for k in (req.mode_levels[i] or ()) if lv.label[k] == req.mode_label[i]]
        if js and np.all(np.isfinite(level_hz[js])):
            w2 = lv.weight[js]
            f_pred[i] = float(np.sum(w2 * level_hz[js]) / np.sum(w2))
    err = nonlinear.FORWARD_MODEL_ERROR
    return Forward(f_pred, level_hz, err * np.nan_to_num(f_pred), err * np.nan_to_num(level_hz))


def forward(req) -> Forward:
    """The prediction of every measured mode and force level.

    With force levels measured by :func:`guidefit.nonlinear.measure_levels`
    (runs that differ only in hit force), the simulated forward model
    (:func:`simulated_forward`); otherwise the describing-function model of
    the module docstring (identify's within-run force bins, below lift-off
    where it is accurate). A mode whose FRF came from hits with force levels
    is predicted as the H1 (sum F^2) weighted mean of its levels'
    predictions; one without at small amplitude.
    """
    from guidefit import nonlinear

    measured = nonlinear.registered_levels(req.levels) if req.levels.size else None
    if measured is not None:
        return simulated_forward(req, measured)
    p = req.parameters["preload_factor"]
    sol, spec, lv = req.solution, req.spec, req.levels
    fm = sol.frequencies_hz
    pairing = req.mode_model
    paired = pairing >= 0
    f_pred = np.where(paired, fm[np.maximum(pairing, 0)], np.nan)
    c_all = roller_modal(spec, sol)
    zetas = req.model_damping
    for i in np.flatnonzero(paired):
        js = req.mode_levels[i]
        if not js:
            continue
        own = all(lv.label[k] == req.mode_label[i] for k in js)  # the levels' refit bands
        fk = [amplitude_frequency(req.guide, spec, sol, pairing[i], lv.force_n[k], lv.hit[k], p, c_all, zetas,
                                  lv.band[k] if own else None) for k in js]
        w2 = lv.weight[js]
        f_pred[i] = float(np.sum(w2 * fk) / np.sum(w2))
    shift = np.where(paired, fm[np.maximum(pairing, 0)] - f_pred, 0.0)
    shift = np.minimum(np.abs(np.nan_to_num(shift)), AMPLITUDE_SHIFT_CAP * req.mode_measured_hz)
    mode_std = AMPLITUDE_MODEL_FORM * shift
    level_hz = np.full(lv.size, np.nan)
    for k in range(lv.size):
        j = int(req.level_model[k])
        if j >= 0:
            level_hz[k] = amplitude_frequency(req.guide, spec, sol, j, lv.force_n[k], lv.hit[k], p, c_all, zetas,
                                              lv.band[k])
    level_std = np.zeros(lv.size)
    for g in lv.groups:
        j = int(req.level_model[g[0]])
        if j < 0 or not np.all(np.isfinite(level_hz[g])):
            continue
        s = np.clip(fm[j] - level_hz[g], 0.0, AMPLITUDE_SHIFT_CAP * lv.frequency_hz[g])
        level_std[g] = AMPLITUDE_MODEL_FORM * np.abs(s - s.mean())
    return Forward(f_pred, level_hz, mode_std, level_std)


def gate(ctx) -> str | None:
    """Tried only with force levels that change with hit force, and a guide with a preload."""
    if ctx.n_levels == 0:
        return ("it needs the frequency per hit-force level (identify's force levels, or runs that differ "
                "only in hit force)")
    if not ctx.guide.preload_m > 0:
        return f"guide {ctx.guide.name} has no preload"
    if not ctx.level_trend_p < TREND_P_VALUE:
        return (f"the force levels show no trend with hit force (chi2 {ctx.level_trend_chi2:.1f} for "
                f"{ctx.level_trend_dof} dof, p = {ctx.level_trend_p:.2f}): it would only scale the stiffness")
    return None


def accept(levels, level_hz) -> str | None:
    """The fitted preload must itself predict a detectable trend over the force levels.

    ``level_hz``: the fitted model's level predictions; their de-meaned
    spread per (run, label) group against the levels' standard deviations
    must be significant (p < :data:`TREND_P_VALUE`).
    """
    from scipy.special import chdtrc

    chi2, dof = 0.0, 0
    for g in levels.groups:
        f, s = level_hz[g], levels.sigma_hz[g]
        if not np.all(np.isfinite(f)):
            continue
        w = s ** -2.0
        chi2 += float(np.sum(((f - np.sum(w * f) / np.sum(w)) / s) ** 2))
        dof += len(g) - 1
    if dof == 0:
        return "no force-level trend to compare"
    p = float(chdtrc(dof, chi2))
    if p < TREND_P_VALUE:
        return None
    return (f"the fitted preload predicts no trend over the force levels (chi2 {chi2:.1f} for {dof} dof): "
            "a global stiffness scale, not amplitude dependence")


def variants(ctx) -> list[Variant]:
    """One variant: the preload factor."""
    return [Variant("amplitude_dependence", "", {},
                    (log_free("preload_factor", "1", 0.01, 10.0, (0.03, 0.1, 0.2, 0.35, 0.5, 0.7, 1.0, 2.0, 5.0)),))]


def prepare(identification, modes, levels, notes):
    """Force levels across runs that differ only in hit force (:func:`guidefit.nonlinear.prepare_for_explain`):
    measured with the level estimator of the forward model, the harder runs' modes entering through them."""
    from guidefit import nonlinear
    from guidefit.errors import RecordingError

    try:
        return nonlinear.prepare_for_explain(identification, modes, levels, notes)
    except OSError as exc:  # the recording moved or vanished since identify read it
        raise RecordingError(f"{identification.file}: cannot be read again for its force levels ({exc})") from None


EFFECT = EffectDef(
    name="amplitude_dependence",
    meaning="nonlinear preloaded Hertz contacts: stiffness falls as hits unload the rows",
    parameters={"preload_factor": Parameter("1", 1.0, "preload Delta relative to the guide's", 0.01, 10.0)},
    apply=apply,
    variants=variants,
    doc=DocRow("only with force levels that show a trend with hit force, and a preload",
               "`preload_factor` (0.01 - 10)",
               "nonlinear preloaded Hertz contacts: the frequency falls once hits unload rows; small-amplitude "
               "K_n scales as `preload_factor^(1/9)` (rollers) or `preload_factor^(1/2)` (balls); accepted only "
               "when the fit predicts the levels' trend"),
    order=40,
    gate=gate,
    forward=forward,
    accept=accept,
    prepare=prepare,
    nonlinear=True,
)
