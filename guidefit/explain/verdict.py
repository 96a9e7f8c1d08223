"""Stage 4 of explain: the verdict (:class:`Verdict`) and the result it makes (:class:`~guidefit.explain.inputs.Explanation`).

* ``adequate``: the nominal model passes the chi-square test; no effect is
  claimed (a note says so when an effect would lower the BIC by more than 10).
* ``explained``: among the accepted models, the one with the fewest effects,
  then the lowest BIC; accepted models of the same size within
  :data:`~guidefit.explain.settings.EQUAL_BIC` are named as equally good
  (``alternatives``).
* ``unexplained``: nothing is accepted; ``effects`` is empty (contract), the
  best attempt (lowest BIC with a degree of freedom left) is
  ``best_attempt``, marked not accepted; models with as many parameters as
  data are "not identifiable from these data".
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from guidefit.explain.inputs import Explanation
from guidefit.explain.selection import rms_pct
from guidefit.explain.settings import (
    ACCEPT_P_VALUE,
    DEFAULT_FREQUENCY_STD,
    DEFAULT_SHAPE_STD,
    EQUAL_BIC,
    ESTIMATED_SHAPE_STD_FLOOR,
    FORCE_LEVEL_FLOOR,
    FREQUENCY_FLOOR,
    UNPAIRED_PENALTY,
)


@dataclass(frozen=True)
class Verdict:
    """The decision: ``verdict``, the "after" model (its fit and entry), alternatives, best attempt, notes.

    ``lead``: the note that states the verdict (first in the result);
    ``notes``: the further notes of the decision.
    """

    verdict: str
    after_fit: object
    after_entry: dict
    alternatives: tuple
    best_attempt: dict | None
    lead: str
    notes: tuple


def fmt_effect(entry: dict) -> str:
    """``name(param=value, ...) + ...`` of a candidate entry."""
    parts = []
    for eff in entry["effects"]:
        ps = []
        for k, p in eff["parameters"].items():
            val = p["value"]
            ps.append(f"{k}={val:.3g}" if isinstance(val, float) else f"{k}={val}")
        parts.append(f"{eff['name']}({', '.join(ps)})")
    return " + ".join(parts)


def equal_notes(best: dict, others: list, what: str) -> list:
    """Notes naming models within EQUAL_BIC of the best one."""
    if not others:
        return []
    names = [best["variant"]] + [e["variant"] for e in others]
    gap = max(0.0, max(e["bic"] - best["bic"] for e in others))
    same = all(e["name"] == best["name"] for e in others)
    out = [f"{' and '.join(names)} {what} (delta BIC {gap:.1f})"
           + ("" if same else "; the data cannot tell these effects apart")]
    return out + _ambiguity_notes([best, *others])


def _ambiguity_notes(entries: list) -> list:
    """The effects' own notes (registry ``ambiguity``) on several of their variants being equally good."""
    from guidefit.model.effects import EFFECTS, resolve_name

    tags: dict = {}
    for e in entries:
        if len(e["effects"]) == 1:
            tags.setdefault(e["effects"][0]["name"], []).append(e["effects"][0]["variant"])
    out = []
    for name, found in tags.items():
        rule = EFFECTS[resolve_name(name)].ambiguity
        note = rule(found) if rule is not None and len(found) > 1 else None
        if note:
            out.append(note)
    return out


def trend_notes(data) -> list:
    """Weighted straight-line trend of frequency with hit force, per (run, label) group."""
    out = []
    for g in data.lv_groups:
        idx, lab = list(g), data.lv_label[g[0]]
        x, y, s = data.lv_force[idx], data.lv_f[idx], data.lv_sigma[idx]
        w = 1.0 / s**2
        xm = np.sum(w * x) / np.sum(w)
        sxx = np.sum(w * (x - xm) ** 2)
        if sxx <= 0:
            continue
        slope = np.sum(w * (x - xm) * y) / sxx
        z = slope * math.sqrt(sxx)
        drop = 100.0 * slope * (x.max() - x.min()) / np.average(y, weights=w)
        runs = sorted({str(data.lv_run[j]) for j in idx if data.lv_run[j] is not None})
        where = f" ({', '.join(runs)} run{'s' if len(runs) > 1 else ''})" if runs else ""
        out.append(f"{lab}{where}: frequency changes {drop:+.2f} % from {x.min():.0f} N to "
                   f"{x.max():.0f} N ({abs(z):.1f} sigma{', significant' if abs(z) > 3 else ''})")
    return out


def pairing_notes(data, measured, nominal) -> list:
    """Extra peaks without a nominal partner, and model modes not observed."""
    notes = []
    for i in np.flatnonzero(nominal.pairing < 0):
        notes.append(f"measured mode at {data.f[i]:.1f} Hz ({measured[i].label or 'unlabelled'}) has no partner "
                     "in the nominal model: an extra peak (evidence for a base or rail body, base_mode)")
    observed = set(nominal.pairing[nominal.pairing >= 0].tolist())
    missing = [f"{lab} {f:.0f} Hz" for j, (lab, f) in enumerate(zip(nominal.sol.labels, nominal.sol.frequencies_hz))
               if j not in observed]
    if missing:
        notes.append("model modes not observed (no residual): " + ", ".join(missing))
    return notes


def _adequate(selection, nominal_fit, data) -> Verdict:
    chi2_0, p0 = selection.chi2_nominal, selection.p_nominal
    lead = (f"the nominal model agrees within uncertainty (chi2 {chi2_0:.1f} for {data.n_data} data, "
            f"p = {p0:.2f}); no effect is claimed")
    better = [e for _, e in selection.entries if e["accepted"] and e["bic"] < chi2_0 - 10.0]
    notes = [f"{better[0]['variant']} would lower the BIC by {chi2_0 - better[0]['bic']:.1f}, "
             "but the nominal model needs no effect; not claimed"] if better else []
    return Verdict("adequate", nominal_fit, selection.nominal_entry, (), None, lead, tuple(notes))


def _explained(selection) -> Verdict:
    accepted = selection.accepted
    n_min = min(len(f.variants) for f, _ in accepted)
    simplest = [(f, e) for f, e in accepted if len(f.variants) == n_min]  # entries are BIC-ranked
    after_fit, after_entry = simplest[0]
    alternatives = [e for _, e in simplest[1:] if e["bic"] - after_entry["bic"] < EQUAL_BIC]
    lead = (f"explained by {fmt_effect(after_entry)}: chi2 {after_entry['chi2']:.1f} for {after_entry['dof']} dof "
            f"(p = {after_entry['p_value']:.2f}); nominal chi2 {selection.chi2_nominal:.1f}")
    notes = equal_notes(after_entry, alternatives, "explain the data equally well")
    return Verdict("explained", after_fit, after_entry, tuple(alternatives), None, lead, tuple(notes))


def _exact_fits(selection, fits, after_entry) -> list:
    """Models with as many parameters as data that fit (almost) exactly, one per effect combination."""
    order = {id(f): k for k, f in enumerate(fits)}
    exact = [(order[id(f)], e) for f, e in selection.entries
             if e["dof"] <= 0 and e["chi2"] < max(1.0, 1e-3 * after_entry["chi2"])]
    exact.sort(key=lambda oe: (after_entry["variant"] not in oe[1]["variant"], oe[1]["n_params"], oe[0]))
    first: dict = {}
    for _, e in exact:
        first.setdefault(e["name"], e)
    return list(first.values())


def _unexplained(selection, nominal_fit, candidates, data) -> Verdict:
    entries = list(selection.entries)
    testable = [(f, e) for f, e in entries if e["dof"] > 0]
    after_fit, after_entry = (testable or entries or [(nominal_fit, selection.nominal_entry)])[0]
    best_attempt = dict(after_entry, accepted=False)
    alternatives = [dict(e, accepted=False) for _, e in testable[1:] if e["bic"] - after_entry["bic"] < EQUAL_BIC]
    lead = ("no candidate brings the model within uncertainty with identifiable parameters; best attempt (not "
            f"accepted): {fmt_effect(after_entry)}, chi2 {after_entry['chi2']:.1f} for {after_entry['dof']} dof "
            f"({after_entry['note']}); nominal chi2 {selection.chi2_nominal:.1f}")
    notes = equal_notes(after_entry, alternatives, "are equally good (not accepted) attempts")
    exact = _exact_fits(selection, candidates.fits, after_entry)
    if exact:
        notes.append(f"models with as many parameters as data ({data.n_data}) fit exactly but are not "
                     "identifiable from these data, e.g. " + "; ".join(fmt_effect(e) for e in exact[:4]))
    if not candidates.pairs_tried and data.n_data >= 2:
        notes.append("pairs of effects were not tried")
    return Verdict("unexplained", after_fit, after_entry, tuple(alternatives), best_attempt, lead, tuple(notes))


def decide(selection, candidates, data) -> Verdict:
    """The verdict from the ranked candidates (module docstring)."""
    nominal_fit = candidates.nominal_fit
    if selection.p_nominal >= ACCEPT_P_VALUE:
        return _adequate(selection, nominal_fit, data)
    verdict = _explained(selection) if selection.accepted else _unexplained(selection, nominal_fit, candidates,
                                                                              data)
    after = verdict.after_entry
    unident = [e for _, e in selection.entries
               if "not identifiable: " in e["note"] and e["chi2"] <= after["chi2"] and e["dof"] > 0]
    extra = [f"{e['variant']}: {e['note'].split('; ')[0]} (not supported, not excluded)" for e in unident[:3]]
    return Verdict(verdict.verdict, verdict.after_fit, after, verdict.alternatives, verdict.best_attempt,
                   verdict.lead, verdict.notes + tuple(extra))


def error_dict(data, ev, chi2: float, k: int, model: str, measured) -> dict:
    """``error_before``/``error_after``: RMS relative frequency error, uncertainty, chi2 test, per mode."""
    from guidefit.explain.data import p_value

    rms, errs = rms_pct(data, ev)
    dof = data.n_data - k
    return {
        "rms_frequency_error_pct": rms,
        "rms_uncertainty_pct": float(100.0 * np.sqrt(np.mean((data.sigma / data.f) ** 2))),
        "chi2": chi2, "n_data": data.n_data, "n_params": k, "dof": dof,
        "p_value": p_value(chi2, dof),
        "within_uncertainty": bool(dof > 0 and p_value(chi2, dof) >= ACCEPT_P_VALUE),
        "model": model,
        "per_mode": [{"label": m.label, "run": m.run, "measured_hz": float(fi), "error_pct": e}
                     for m, fi, e in zip(measured, data.f, errs)],
    }


def mode_rows(data, measured, nominal, after) -> list:
    """One row per measured mode: measured, model before and after, errors, MACs, status."""
    rows = []
    for i, m in enumerate(measured):
        jb, ja = int(nominal.pairing[i]), int(after.pairing[i])
        rows.append({
            "label": m.label if m.label is not None else (nominal.sol.labels[jb] if jb >= 0 else "extra"),
            "run": m.run, "measured_hz": float(data.f[i]),
            "measured_std_hz": None if m.frequency_std_hz is None else float(m.frequency_std_hz),
            "identified_hz": float(m.frequency_hz),
            "sigma_hz": float(data.sigma[i]),
            "model_before_hz": float(nominal.f_pred[i]) if jb >= 0 else None,
            "model_before_label": nominal.sol.labels[jb] if jb >= 0 else None,
            "model_after_hz": float(after.f_pred[i]) if ja >= 0 else None,
            "model_after_label": after.sol.labels[ja] if ja >= 0 and after.sol is not None else None,
            "error_before_pct": (100.0 * (nominal.f_pred[i] - data.f[i]) / data.f[i]) if jb >= 0 else None,
            "error_after_pct": (100.0 * (after.f_pred[i] - data.f[i]) / data.f[i]) if ja >= 0 else None,
            "mac_before": None if math.isnan(nominal.mac[i]) else float(nominal.mac[i]),
            "mac_after": None if math.isnan(after.mac[i]) else float(after.mac[i]),
            "status": "paired" if ja >= 0 else "extra",
        })
    return rows


def settings_dict(n_eval: int) -> dict:
    """The floors and thresholds used, and the number of model evaluations."""
    from guidefit.model.effects.amplitude_dependence import AMPLITUDE_MODEL_FORM

    return {"frequency_floor_pct": 100 * FREQUENCY_FLOOR, "default_frequency_std_pct": 100 * DEFAULT_FREQUENCY_STD,
            "default_shape_std_pct": 100 * DEFAULT_SHAPE_STD, "accept_p_value": ACCEPT_P_VALUE,
            "equal_bic": EQUAL_BIC, "unpaired_penalty_sigma": UNPAIRED_PENALTY,
            "score": "BIC = chi2 + k ln n + 2 ln N_choices",
            "force_level_floor_pct": 100 * FORCE_LEVEL_FLOOR,
            "estimated_shape_std_floor_pct": 100 * ESTIMATED_SHAPE_STD_FLOOR,
            "amplitude_model_form": AMPLITUDE_MODEL_FORM, "model_evaluations": n_eval}


def explanation(verdict: Verdict, selection, candidates, data, measured, guide_name: str, notes: list,
                source, n_eval: int) -> Explanation:
    """The :class:`~guidefit.explain.inputs.Explanation` of a verdict."""
    from guidefit.explain.candidates import effects_of

    nominal = candidates.nominal
    after_fit = verdict.after_fit
    after_model = {"adequate": "nominal", "explained": "selected",
                   "unexplained": "best attempt (not accepted)"}[verdict.verdict]
    return Explanation(
        verdict=verdict.verdict, guide=guide_name,
        error_before=error_dict(data, nominal, selection.chi2_nominal, 0, "nominal", measured),
        error_after=error_dict(data, after_fit.ev, after_fit.chi2, after_fit.k, after_model, measured),
        effects=tuple(verdict.after_entry["effects"]) if verdict.verdict == "explained" else (),
        candidates=selection.ranked, modes=tuple(mode_rows(data, measured, nominal, after_fit.ev)),
        notes=tuple(notes), source=source, best_attempt=verdict.best_attempt,
        alternatives=verdict.alternatives, n_data=data.n_data, settings=settings_dict(n_eval),
        fitted_effects=tuple(effects_of(after_fit.variants, after_fit.values)),
    )
