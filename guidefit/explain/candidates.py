"""Stage 2 of explain: fit the candidate effects (:class:`CandidateFit`, :class:`Candidates`).

Each candidate is a set of effect variants from the registry of
:mod:`guidefit.model.effects` (discrete options fixed: ``added_mass`` at
ABCD, each of A-D or the centre; ``row_damage`` rows 1-4; ...); the
continuous parameters are fitted by :func:`scipy.optimize.least_squares`
(trust-region reflective) in transformed coordinates (log for stiffnesses,
masses and factors, linear for offsets and roller positions) within
physical bounds. Misfits of springs and masses are not convex: a grid of
starts across decades is scored first (fewest unpaired modes, then chi2)
and the best few are polished. Standard deviations come from the Jacobian,
``cov = (J^T J)^-1 max(1, chi2/dof)``.

Pairs of effects are fitted only when no single effect is accepted: the
three best single effects (each with its variants as good as its best one)
are combined with the best variants of every other effect they may combine
with (the registry's ``combinable``), screened by a short fit, and the six
best pairs are refitted fully.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from guidefit.errors import ModelError
from guidefit.explain.evaluation import Context, Evaluation, evaluate
from guidefit.explain.settings import EQUAL_BIC, IDENTIFIABLE_LOG_STD, PAIR_PARTNER_VARIANTS, WHOLE_MISFIT_CHI2
from guidefit.model.effects import Variant


@dataclass(frozen=True)
class CandidateFit:
    """A fitted combination of variants: parameter values (physical) with standard deviations.

    ``identifiable``/``at_bound`` per free parameter; ``ev`` the evaluation
    at the fitted values; ``k`` the number of fitted parameters;
    ``profiled``: its whole-number parameters were profiled (they count as
    discrete choices, :func:`profile_whole`), false when they stayed continuous.
    """

    variants: tuple
    theta: np.ndarray
    values: list
    std: list
    chi2: float
    ev: Evaluation
    k: int
    identifiable: list
    at_bound: list
    profiled: bool = False


@dataclass(frozen=True)
class Candidates:
    """Everything fitted in one explain call.

    ``nominal``: the nominal model's evaluation; ``fits``: single effects,
    then pairs (if tried); ``variants``: the variants tried; ``choices``:
    per effect the number of discrete variants it chose among (counted in
    the BIC); ``pairs_tried``.
    """

    nominal: Evaluation
    fits: tuple
    variants: tuple
    choices: dict
    pairs_tried: bool

    @property
    def nominal_fit(self) -> CandidateFit:
        return CandidateFit((), np.zeros(0), [], [], self.nominal.chi2, self.nominal, 0, [], [])


def effects_of(variants, values) -> list:
    """The :class:`~guidefit.model.effects.Effect` list of a combination at the given free-parameter values."""
    from guidefit.model.effects import Effect

    out, pos = [], 0
    for v in variants:
        params = dict(v.fixed)
        for fr in v.free:
            params[fr.name] = values[pos]
            pos += 1
        out.append(Effect(v.effect, params))
    return out


def level_trend(data) -> tuple[float, int, float]:
    """(chi2, dof, p) of "the frequency does not change with hit force" over every level group."""
    from guidefit.explain.data import p_value

    chi2, dof = 0.0, 0
    for g in data.lv_groups:
        w = data.lv_sigma[g] ** -2.0
        z = (data.lv_f[g] - np.sum(w * data.lv_f[g]) / np.sum(w)) / data.lv_sigma[g]
        chi2 += float(z @ z)
        dof += len(g) - 1
    return chi2, dof, (p_value(chi2, dof) if dof > 0 else math.nan)


def library_variants(guide, data, names, notes) -> list[Variant]:
    """The variants of the named effects (the registry's), each effect's ``gate`` consulted first."""
    from guidefit.model.effects import EFFECTS, FitContext, resolve_name

    chi2, dof, p = level_trend(data)
    extra = tuple(float(data.f[i]) for i, lab in enumerate(data.labels) if lab is None)
    ctx = FitContext(guide=guide, extra_frequencies_hz=extra, n_levels=int(data.lv_f.size),
                     level_trend_chi2=chi2, level_trend_dof=dof, level_trend_p=p)
    out: list[Variant] = []
    for name in names:
        try:
            effect = EFFECTS[resolve_name(name)]
        except ModelError:
            raise ModelError(f"explain: unknown candidate effect '{name}'; have {', '.join(EFFECTS)}") from None
        reason = effect.gate(ctx) if effect.gate is not None else None
        if reason:
            notes.append(f"{effect.name} not tried: {reason}")
            continue
        out += effect.variants(ctx)
    return out


def compatible(a: Variant, b: Variant) -> bool:
    """Whether two variants may be fitted together (the registry's :func:`~guidefit.model.effects.combinable`)."""
    from guidefit.model.effects import combinable

    return combinable(a.effect, b.effect)


def grid_starts(variant: Variant) -> list:
    """The variant's start points: explicit ones, else the product of its parameters' grids."""
    if variant.starts:
        return [tuple(s) for s in variant.starts]
    return [tuple(p) for p in itertools.product(*[fr.grid for fr in variant.free])]


def _scored_starts(ctx, data, variants, free, starts, lo, hi) -> list:
    """Start points in fit coordinates, best first (fewest unpaired modes, then chi2)."""
    span = hi - lo
    inner_lo, inner_hi = lo + 1e-6 * span, hi - 1e-6 * span
    scored = []
    for s in starts:
        theta = np.clip([fr.encode(x) for fr, x in zip(free, s)], inner_lo, inner_hi)
        ev = evaluate(ctx, data, effects_of(variants, [fr.decode(t) for fr, t in zip(free, theta)]))
        ctx.n_eval += 1
        scored.append((int(np.sum(ev.pairing < 0)), ev.chi2, tuple(theta)))
    scored.sort(key=lambda t: t[:2])
    return [theta for _, _, theta in scored]


def _std_in_fit_coordinates(jac: np.ndarray, chi2: float, dof: int, k: int) -> np.ndarray:
    """Standard deviations from the Jacobian: ``cov = (J^T J)^-1 max(1, chi2/dof)`` (inf where singular)."""
    try:
        cov = np.linalg.pinv(jac.T @ jac) * max(1.0, chi2 / dof if dof > 0 else 1.0)
        std_t = np.sqrt(np.maximum(np.diag(cov), 0.0))
        sv = np.linalg.svd(jac, compute_uv=False)
        if sv.size and sv[-1] <= 1e-8 * max(sv[0], 1e-300):
            std_t = np.where(np.abs(jac).sum(axis=0) > 0, std_t, np.inf)
            std_t = np.full(k, np.inf) if sv[0] == 0 else std_t
    except np.linalg.LinAlgError:
        std_t = np.full(k, np.inf)
    return std_t


def fit(ctx: Context, data, variants: tuple, starts: list, n_polish: int = 2, max_nfev: int = 60,
        profile: bool = True) -> CandidateFit:
    """Least-squares fit of the free parameters of a combination of variants.

    Parameters that a variant declares ``whole`` are then profiled over whole
    numbers (:func:`profile_whole`) unless ``profile`` is false.
    """
    from scipy.optimize import least_squares

    free = [fr for v in variants for fr in v.free]
    lo = np.array([fr.bounds[0] for fr in free])
    hi = np.array([fr.bounds[1] for fr in free])

    def decode(theta):
        return [fr.decode(t) for fr, t in zip(free, theta)]

    def fun(theta):
        ctx.n_eval += 1
        return evaluate(ctx, data, effects_of(variants, decode(theta))).r

    best = None
    for theta0 in list(dict.fromkeys(_scored_starts(ctx, data, variants, free, starts, lo, hi)))[:n_polish]:
        res = least_squares(fun, np.array(theta0), bounds=(lo, hi), method="trf", x_scale=1.0,
                            max_nfev=max_nfev, xtol=1e-10, ftol=1e-10, gtol=1e-10, diff_step=1e-5)
        cost = float(res.fun @ res.fun)
        if best is None or cost < best[0]:
            best = (cost, res)
    res = best[1]
    ev = evaluate(ctx, data, effects_of(variants, decode(res.x)))
    k = len(free)
    std_t = _std_in_fit_coordinates(np.asarray(res.jac), ev.chi2, data.n_data - k, k)
    values = decode(res.x)
    std, ident, at_bound = [], [], []
    for fr, t, st, v in zip(free, res.x, std_t, values):
        if fr.kind == "log":
            std.append(v * st if math.isfinite(st) else math.inf)
            ident.append(bool(math.isfinite(st) and st < IDENTIFIABLE_LOG_STD))
        else:
            std.append(fr.scale * st if math.isfinite(st) else math.inf)
            ident.append(bool(math.isfinite(st) and fr.scale * st < 0.25 * (fr.upper - fr.lower)))
        b0, b1 = fr.bounds
        at_bound.append(bool(not fr.bound_is_value and min(t - b0, b1 - t) < 1e-3 * (b1 - b0)))
    out = CandidateFit(tuple(variants), res.x, values, std, ev.chi2, ev, k, ident, at_bound)
    return profile_whole(ctx, data, out) if profile and any(v.whole for v in variants) else out


def _whole_options(fr, x: float, centre: float | None = None) -> list:
    """Whole numbers within one of floor/ceil of ``x`` (or of ``centre``), inside the parameter's bounds."""
    c = x if centre is None else centre
    lo, hi = max(math.ceil(fr.lower), math.floor(c) - 1), min(math.floor(fr.upper), math.ceil(c) + 1)
    return list(range(int(lo), int(hi) + 1))


def _fit_whole_combo(ctx, data, fit_: CandidateFit, whole_pos: list, combo: tuple):
    """The combination with the whole parameters fixed at ``combo`` and the others refitted (None if invalid)."""
    fixed_at = dict(zip(whole_pos, combo))
    subs, start, pos = [], [], 0
    for v in fit_.variants:
        fixed, free = dict(v.fixed), []
        for fr in v.free:
            if pos in fixed_at:
                fixed[fr.name] = float(fixed_at[pos])
            else:
                free.append(fr)
                start.append(fit_.values[pos])
            pos += 1
        subs.append(Variant(v.effect, v.tag, fixed, tuple(free)))
    keep = [i for i in range(pos) if i not in fixed_at]
    grid = grid_starts(fit_.variants[0]) if len(fit_.variants) == 1 else []
    starts = list(dict.fromkeys([tuple(start)] + [tuple(g[i] for i in keep) for g in grid]))
    try:
        return fit(ctx, data, tuple(subs), starts, n_polish=1, max_nfev=40, profile=False), keep
    except ModelError:  # an impossible combination (a segment's first roller after its last)
        return None, keep


def profile_whole(ctx, data, fit_: CandidateFit, rounds: int = 4) -> CandidateFit:
    """The continuous fit ``fit_`` with its ``whole`` parameters profiled over whole numbers.

    Every whole-number combination within one of the continuous optimum's
    floor and ceiling (the window moved to the best one while that lies on
    its edge, up to ``rounds`` times) is fitted with the other parameters
    free; the lowest chi2 wins. Its whole parameters count as discrete
    choices (``Variant.choices``), not fitted parameters (``k``). When the
    best whole-number fit is worse than the continuous one by more than
    ``WHOLE_MISFIT_CHI2`` the continuous fit is returned unchanged (its
    whole parameters stay fitted parameters, not choices). Standard
    deviations are the spread over the combinations weighted by
    ``exp(-delta chi2 / 2)`` (each one's own std added in quadrature), so a
    segment whose ends the data do not pin down keeps a wide factor.
    """
    free = [(v, fr) for v in fit_.variants for fr in v.free]
    whole_pos = [i for i, (v, fr) in enumerate(free) if fr.name in v.whole]
    tried: dict = {}
    centre = [None] * len(whole_pos)
    for _ in range(rounds):
        options = [_whole_options(free[i][1], fit_.values[i], c) for i, c in zip(whole_pos, centre)]
        for combo in itertools.product(*options):
            if combo not in tried:
                tried[combo] = _fit_whole_combo(ctx, data, fit_, whole_pos, combo)
        valid = {c: r for c, r in tried.items() if r[0] is not None}
        if not valid:
            return fit_
        best_combo = min(valid, key=lambda c: valid[c][0].chi2)
        edge = [(c == o[0] and c > math.ceil(free[i][1].lower)) or (c == o[-1] and c < math.floor(free[i][1].upper))
                for i, c, o in zip(whole_pos, best_combo, options)]
        if not any(edge):
            break
        centre = list(best_combo)
    best, keep = valid[best_combo]
    if best.chi2 - fit_.chi2 > WHOLE_MISFIT_CHI2:
        return fit_  # the ends are not whole rollers: the continuous fit, its ends counted as parameters
    w = {c: math.exp(-0.5 * (r[0].chi2 - best.chi2)) for c, r in valid.items()}
    w = {c: x for c, x in w.items() if x > 1e-9}  # combinations the data rule out (and their inf stds) drop
    valid = {c: valid[c] for c in w}
    total = sum(w.values())
    values, std = [0.0] * len(free), [0.0] * len(free)
    for i, c in zip(whole_pos, best_combo):
        values[i] = float(c)
    for j, i in enumerate(keep):
        values[i] = best.values[j]
    for n, i in enumerate(whole_pos):
        std[i] = math.sqrt(sum(w[c] * (c[n] - values[i]) ** 2 for c in valid) / total)
    for j, i in enumerate(keep):
        var = sum(w[c] * (r[0].std[j] ** 2 + (r[0].values[j] - values[i]) ** 2) for c, r in valid.items())
        std[i] = math.sqrt(var / total) if math.isfinite(var) else math.inf
    ident, at_bound = [], []
    for i, (_v, fr) in enumerate(free):
        if i in keep:
            j = keep.index(i)
            rel = std[i] / values[i] if fr.kind == "log" and values[i] > 0 else std[i]
            ident.append(bool(math.isfinite(std[i]) and (rel < IDENTIFIABLE_LOG_STD if fr.kind == "log"
                                                         else std[i] < 0.25 * (fr.upper - fr.lower))))
            at_bound.append(best.at_bound[j])
        else:
            ident.append(bool(std[i] < 0.25 * (fr.upper - fr.lower)))
            at_bound.append(False)
    theta = np.array([fr.encode(x) for (_, fr), x in zip(free, values)])
    return CandidateFit(fit_.variants, theta, values, std, best.chi2, best.ev, best.k, ident, at_bound, True)


def reduced(fit_: CandidateFit, variants: list):
    """The same combination with a variant whose stiffness went rigid replaced by its simpler form.

    Returns (variants, start values) or None.
    """
    out_variants, out_values, changed, pos = [], [], False, 0
    by_title = {v.title: v for v in variants}
    for v in fit_.variants:
        sl = slice(pos, pos + len(v.free))
        vals = list(fit_.values[sl])
        # a stiffness at (or unidentifiably near) its rigid bound
        ups = [fr.name for fr, at, ok, t in zip(v.free, fit_.at_bound[sl], fit_.identifiable[sl], fit_.theta[sl])
               if (at or not ok) and t > 0.5 * sum(fr.bounds)]
        pos += len(v.free)
        target = next((tag for name, tag in v.reduces if name in ups), None)
        simpler = by_title.get(f"{v.effect} ({target})") if target else None
        if simpler is None:
            out_variants.append(v)
            out_values += vals
            continue
        changed = True
        keep = {fr.name: val for fr, val in zip(v.free, vals)}
        out_variants.append(simpler)
        out_values += [keep[fr.name] for fr in simpler.free]
    return (tuple(out_variants), tuple(out_values)) if changed else None


def _pair_jobs(data, fits: list, variants: list, bic) -> tuple[list, set]:
    """(combination, starts) of every pair to screen: seeds x the best variants of each compatible effect."""
    by_effect: dict = {}
    testable = [f for f in fits if f.k < data.n_data] or fits
    for f in sorted(testable, key=lambda f: round(bic(f), 3)):
        by_effect.setdefault(f.variants[0].effect, []).append(f)
    top = sorted(by_effect.values(), key=lambda fs: round(bic(fs[0]), 3))[:3]
    # each seed effect with its variants that are as good as its best one (at most two)
    seeds = [f for fs in top for f in fs[:2] if bic(f) - bic(fs[0]) < EQUAL_BIC]
    single_of = {f.variants[0].title: f for f in fits}
    ranked: dict = {}
    for f in sorted(fits, key=lambda f: round(bic(f), 3)):
        ranked.setdefault(f.variants[0].effect, []).append(f.variants[0].title)
    partners = [v for v in variants if v.title in ranked.get(v.effect, [])[:PAIR_PARTNER_VARIANTS]]
    jobs, seen = [], set()
    for seed in seeds:
        for v in partners:
            key = frozenset((seed.variants[0].title, v.title))
            too_many = len(seed.variants[0].free) + len(v.free) > data.n_data
            if compatible(seed.variants[0], v) and key not in seen and not too_many:
                seen.add(key)
                starts = [tuple(seed.values) + tuple(single_of[v.title].values)]
                starts += [tuple(seed.values) + s for s in grid_starts(v)]
                jobs.append(((seed.variants[0], v), starts))
    return jobs, seen


def fit_pairs(ctx: Context, data, fits: list, variants: list, bic, progress) -> list:
    """Pairs of effects by forward selection from the three best single effects (module docstring).

    A pair whose stiffness went rigid is refitted in its simpler form.
    """
    jobs, seen = _pair_jobs(data, fits, variants, bic)
    total = len(variants) + len(jobs)
    screened = []
    for n_done, (combo, starts) in enumerate(jobs, start=len(variants) + 1):
        screened.append((fit(ctx, data, combo, starts, n_polish=1, max_nfev=6, profile=False), starts))
        if progress is not None:
            progress(n_done, total, " + ".join(v.title for v in combo))
    screened.sort(key=lambda fs: bic(fs[0]))
    out = [f for f, _ in screened[6:]]
    for f, starts in screened[:6]:
        full = fit(ctx, data, f.variants, [tuple(f.values)] + starts, n_polish=2, max_nfev=80)
        out.append(full)
        red = reduced(full, variants)
        if red is not None and frozenset(v.title for v in red[0]) not in seen:
            seen.add(frozenset(v.title for v in red[0]))
            out.append(fit(ctx, data, red[0], [red[1]], n_polish=1, max_nfev=80))
    return out


def fit_candidates(ctx: Context, data, names, notes: list, progress, accepted: Callable, bic_of: Callable,
                   try_pairs: bool) -> Candidates:
    """Fit every single effect, then pairs when ``try_pairs`` and no single one is ``accepted``.

    ``accepted(fit, choices)`` and ``bic_of(fit, choices)`` are the
    selection stage's rules (:mod:`guidefit.explain.selection`).
    """
    variants = library_variants(ctx.guide, data, names, notes)
    choices: dict = {}
    for v in variants:
        choices[v.effect] = choices.get(v.effect, 0) + v.choices  # whole-number options counted too
    nominal = evaluate(ctx, data, [])
    skipped = [v.title for v in variants if len(v.free) > data.n_data]
    if skipped:
        notes.append(f"not fitted (more parameters than the {data.n_data} data): {', '.join(skipped)}")
    total = len(variants)
    variants = [v for v in variants if len(v.free) <= data.n_data]
    fits: list[CandidateFit] = []
    for done, v in enumerate(variants, start=1):
        fits.append(fit(ctx, data, (v,), grid_starts(v)))
        if progress is not None:
            progress(done, total, v.title)
    pairs = try_pairs and data.n_data >= 2 and not any(accepted(f, choices, nominal) for f in fits)
    if pairs:
        fits += fit_pairs(ctx, data, fits, variants, lambda f: bic_of(f, choices), progress)
    return Candidates(nominal, tuple(fits), tuple(variants), choices, pairs)
