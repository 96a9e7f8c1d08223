"""Stage 3 of explain: assess and rank the fitted candidates (:class:`Selection`).

Score: ``BIC = chi2 + k ln n + 2 ln N``, with k fitted parameters, n data
and N the number of discrete variants each effect of the candidate chose
among (a uniform prior over them: a row of four costs 2 ln 4 = 2.8, a corner
of six 3.6). A candidate is *accepted* when

1. it leaves at least one degree of freedom (``n > k``),
2. its chi-square p-value is at least :data:`~guidefit.explain.settings.ACCEPT_P_VALUE`,
3. every fitted parameter is identifiable (finite, not at a bound),
4. for a combination: the data it moves by more than 3 sigma from the
   nominal model outnumber its parameters,
5. every effect's own ``accept`` rule passes (``amplitude_dependence``: the
   fit predicts a trend over the force levels).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from guidefit.explain.data import p_value
from guidefit.explain.settings import ACCEPT_P_VALUE


@dataclass(frozen=True)
class Selection:
    """The candidates assessed and ranked.

    ``entries``: (fit, entry) pairs of the fitted candidates, best BIC first
    (ties keep the library's order); ``nominal_entry``; ``ranked``: every
    entry, nominal included, best BIC first (the ``candidates`` of the
    result); ``chi2_nominal``/``p_nominal``: the nominal model's test.
    """

    entries: tuple
    nominal_entry: dict
    ranked: tuple
    chi2_nominal: float
    p_nominal: float

    @property
    def accepted(self) -> list:
        return [(f, e) for f, e in self.entries if e["accepted"]]


def param_dict(fit) -> list:
    """Effects of a fit as the contract's list of {name, variant, parameters{value, std, unit, ...}}."""
    out, pos = [], 0
    for v in fit.variants:
        params = {}
        for key, val in v.fixed.items():
            params[key] = {"value": val, "std": None, "unit": ""}
        for fr in v.free:
            params[fr.name] = {"value": float(fit.values[pos]), "std": float(fit.std[pos]), "unit": fr.unit,
                               "identifiable": fit.identifiable[pos], "at_bound": fit.at_bound[pos]}
            pos += 1
        out.append({"name": v.effect, "variant": v.tag, "parameters": params})
    return out


def rms_pct(data, ev) -> tuple[float, list]:
    """RMS relative frequency error (%): paired modes, unpaired ones against the nearest model mode."""
    errs = []
    for i in range(data.f.size):
        if ev.pairing[i] >= 0 and math.isfinite(ev.f_pred[i]):
            errs.append(100.0 * (ev.f_pred[i] - data.f[i]) / data.f[i])
        elif ev.sol is not None:
            fm = ev.sol.frequencies_hz
            j = int(np.argmin(np.abs(np.log(fm / data.f[i]))))
            errs.append(100.0 * (fm[j] - data.f[i]) / data.f[i])
        else:
            errs.append(float("nan"))
    arr = np.array(errs)
    return float(np.sqrt(np.nanmean(arr**2))), errs


def n_responsive(data, nominal, ev) -> int:
    """How many data the fitted parameters move by more than 3 sigma from the nominal model.

    A measured mode that only the candidate can pair (an extra peak) counts
    twice: its existence and its frequency. A mode shape counts once.
    """
    n = data.f.size
    d = np.abs(ev.r - nominal.r)
    newly = (nominal.pairing < 0) & (ev.pairing >= 0)
    count = int(np.sum(np.where(newly, 2, d[:n] > 3.0)))
    pos = n
    for s in data.shapes:
        width = s.unit.shape[1]
        for _ in s.index:
            count += int(np.linalg.norm(ev.r[pos:pos + width] - nominal.r[pos:pos + width]) > 3.0)
            pos += width
    return count + int(np.sum(d[pos:] > 3.0))


def choice_penalty(fit, choices: dict) -> float:
    """2 ln N per effect that chose among N discrete variants (a uniform prior over them)."""
    n = [choices.get(v.effect, 1) / (v.choices if v.whole and not getattr(fit, "profiled", False) else 1)
         for v in fit.variants]  # whole-number parameters left continuous are counted in k instead
    return float(sum(2.0 * math.log(max(1.0, x)) for x in n))


def bic(fit, data, choices: dict) -> float:
    """BIC = chi2 + k ln n + 2 ln N_choices: the discrete choices counted (module docstring)."""
    return fit.chi2 + fit.k * math.log(data.n_data) + choice_penalty(fit, choices)


def effect_refusals(fit, data) -> list:
    """Reasons of the effects' own ``accept`` rules (e.g. no predicted trend over force levels)."""
    from guidefit.model.effects import EFFECTS, resolve_name

    out = []
    for v in fit.variants:
        rule = EFFECTS[resolve_name(v.effect)].accept
        if rule is not None and fit.ev.ok:
            reason = rule(data.levels, fit.ev.lv_pred)
            if reason:
                out.append(f"{v.effect}: {reason}")
    return out


def _unidentified(fit) -> list:
    bad, pos = [], 0
    for v in fit.variants:
        for fr in v.free:
            if not fit.identifiable[pos] or fit.at_bound[pos]:
                bad.append(f"{v.effect}.{fr.name}" + (" at its bound" if fit.at_bound[pos] else ""))
            pos += 1
    return bad


def candidate_entry(fit, data, bic_min: float, nominal, choices: dict) -> dict:
    """The assessment of one fitted candidate (an entry of the result's ``candidates``; module docstring)."""
    dof = data.n_data - fit.k
    p = p_value(fit.chi2, dof)
    problems = []
    n_resp = n_responsive(data, nominal, fit.ev)
    if dof <= 0:
        problems.append(f"not identifiable from these data ({data.n_data} data, {fit.k} parameters)")
    elif n_resp <= fit.k and len(fit.variants) > 1:
        problems.append(f"not identifiable from these data: only {n_resp} data respond to its {fit.k} "
                        "parameters, which fit them by construction")
    bad = _unidentified(fit)
    if bad and dof > 0:
        problems.append("not identifiable: " + ", ".join(bad))
    within = dof > 0 and p >= ACCEPT_P_VALUE
    if dof > 0 and not within:
        problems.append(f"misfit beyond uncertainty (chi2 {fit.chi2:.1f} for {dof} dof)")
    combination_ok = len(fit.variants) == 1 or n_resp > fit.k
    refused = effect_refusals(fit, data)
    problems += refused
    accepted = within and not bad and combination_ok and not refused
    if accepted and n_resp <= fit.k:
        problems.append(f"within uncertainty; it moves {n_resp} data with {fit.k} parameter(s), the data it "
                        "leaves unchanged are its test")
    score = bic(fit, data, choices)
    effects = param_dict(fit)
    return {
        "name": "+".join(v.effect for v in fit.variants),
        "variant": " + ".join(v.title for v in fit.variants),
        "effects": effects,
        "parameters": {f"{e['name']}.{k}": v for e in effects for k, v in e["parameters"].items()},
        "n_params": fit.k, "n_choices": int(round(math.exp(choice_penalty(fit, choices) / 2))),
        "n_responsive": n_resp, "chi2": fit.chi2, "dof": dof, "p_value": p, "bic": score,
        "delta_bic": score - bic_min,
        "rms_frequency_error_pct": rms_pct(data, fit.ev)[0],
        "accepted": bool(accepted),
        "note": "; ".join(problems) if problems else "within uncertainty",
    }


def is_accepted(fit, data, choices: dict, nominal) -> bool:
    """Whether a fitted candidate passes the acceptance rules (module docstring)."""
    return candidate_entry(fit, data, 0.0, nominal, choices)["accepted"]


def select(candidates, data) -> Selection:
    """Assess every fitted candidate and rank all of them, the nominal model included, by BIC."""
    nominal = candidates.nominal
    chi2_0 = nominal.chi2
    p0 = p_value(chi2_0, data.n_data)
    fits = candidates.fits
    bic_min = min([chi2_0] + [bic(f, data, candidates.choices) for f in fits])
    entries = [(f, candidate_entry(f, data, bic_min, nominal, candidates.choices)) for f in fits]
    nominal_entry = {"name": "nominal", "variant": "nominal", "effects": [], "n_params": 0, "n_choices": 1,
                     "chi2": chi2_0, "dof": data.n_data, "p_value": p0, "bic": chi2_0, "delta_bic": chi2_0 - bic_min,
                     "rms_frequency_error_pct": rms_pct(data, nominal)[0],
                     "accepted": bool(p0 >= ACCEPT_P_VALUE),
                     "note": "within uncertainty" if p0 >= ACCEPT_P_VALUE else
                     f"misfit beyond uncertainty (chi2 {chi2_0:.1f} for {data.n_data} dof)"}
    entries.sort(key=lambda fe: round(fe[1]["bic"], 3))  # stable: ties keep the library's order
    ranked = [nominal_entry] + [e for _, e in entries]
    ranked.sort(key=lambda e: round(e["bic"], 3))
    return Selection(tuple(entries), nominal_entry, tuple(ranked), chi2_0, p0)
