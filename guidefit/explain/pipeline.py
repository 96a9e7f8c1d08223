"""The explain pipeline: prepare -> fit candidates -> select -> verdict (:func:`explain_modes`).

Each stage returns a typed result (:class:`~guidefit.explain.data.PreparedData`,
:class:`~guidefit.explain.candidates.Candidates`,
:class:`~guidefit.explain.selection.Selection`,
:class:`~guidefit.explain.verdict.Verdict`); rendering is
:mod:`guidefit.report`'s. Two outer passes leave data out: modes whose force
bins do not reproduce them, and unlabelled extra peaks that no accepted
model produces (docs/explain.md, "Extra peaks").
"""

from __future__ import annotations

from dataclasses import replace

from guidefit.explain.candidates import fit_candidates
from guidefit.explain.data import prepare
from guidefit.explain.evaluation import Context
from guidefit.explain.inputs import Explanation
from guidefit.explain.selection import bic, is_accepted, select
from guidefit.explain.settings import canonical_label
from guidefit.explain.verdict import decide, explanation, pairing_notes, trend_notes
from guidefit.model.measured import ForceLevel, MeasuredMode


def explain_modes(measured, guide, sensors=(), force_levels=(), candidates=None, progress=None,
                  source: str | None = None, notes=(), *, drop_unproduced_extras: bool = True) -> Explanation:
    """Pair measured modes with the model, fit candidate effects and select the explanation.

    Parameters
    ----------
    measured : list of MeasuredMode
        Identified modes (frequency, uncertainty, optional label, shape, run).
    guide : str or Guide
        Catalogue name (``"MRB35"``), guide file or :class:`~guidefit.model.guides.Guide`.
    sensors : list of Sensor, optional
        Positions and directions of the shape channels; channels named
        ``acc_<point>_<axis>`` default to the guide's measuring points.
    force_levels : list of ForceLevel, optional
        Frequency per hit-force bin; needed by ``amplitude_dependence``.
    candidates : list of str, optional
        Effect names to try (default: every effect of
        :data:`guidefit.model.effects.EFFECTS`).
    progress : callable, optional
        Called as ``progress(done, total, name)`` after each candidate.
    source : str, optional
        Where the modes came from (the ``file`` of the JSON result).
    notes : list of str, optional
        Notes of the caller to carry into the result.
    drop_unproduced_extras : bool
        When nothing explains the data and some unlabelled modes (extra
        peaks) have no partner in the nominal model, try once more without
        them (see "Extra peaks" in the module documentation).

    Returns
    -------
    Explanation

    Raises
    ------
    RecordingError
        Malformed measured data (names the mode and field).
    ModelError
        Unknown candidate effect.

    Examples
    --------
    >>> from guidefit.model.guides import load_guide
    >>> from guidefit.model.vibration import model_from_guide, solve_modes
    >>> sol = solve_modes(model_from_guide(load_guide("MRB35")))
    >>> modes = [MeasuredMode(f * 1.0004, 0.001 * f, label=lab) for lab, f in zip(sol.labels, sol.frequencies_hz)]
    >>> result = explain_modes(modes, "MRB35", candidates=["contact_stiffness"])
    >>> result.verdict, result.effects
    ('adequate', ())
    """
    from guidefit.model import vibration as vib
    from guidefit.model.effects import EFFECTS
    from guidefit.model.guides import Guide, load_guide

    guide = guide if isinstance(guide, Guide) else load_guide(guide)
    measured, sensors, force_levels = list(measured), list(sensors or ()), list(force_levels or ())
    unreproduced = _unreproduced(measured, force_levels)
    if unreproduced and len(unreproduced) < len(measured):
        return _without_unreproduced(measured, unreproduced, guide, sensors, force_levels, candidates, progress,
                                     source, notes, drop_unproduced_extras)
    caller_notes, notes = tuple(notes), list(notes)
    data = prepare(measured, guide, sensors, force_levels, notes)
    ctx = Context(guide, vib.model_from_guide(guide))
    fitted = fit_candidates(
        ctx, data, list(EFFECTS) if candidates is None else list(candidates), notes, progress,
        accepted=lambda f, choices, nominal: is_accepted(f, data, choices, nominal),
        bic_of=lambda f, choices: bic(f, data, choices), try_pairs=not _adequate(ctx, data))
    selection = select(fitted, data)
    verdict = decide(selection, fitted, data)
    notes = [verdict.lead, *notes, *pairing_notes(data, measured, fitted.nominal), *trend_notes(data),
             *verdict.notes]
    result = explanation(verdict, selection, fitted, data, measured, guide.name, notes, source, ctx.n_eval)
    extras = [i for i in range(data.f.size) if data.labels[i] is None and fitted.nominal.pairing[i] < 0]
    if verdict.verdict == "unexplained" and extras and drop_unproduced_extras and len(extras) < data.f.size:
        return _without_extras(result, measured, extras, guide, sensors, force_levels, candidates, progress,
                               source, caller_notes)
    return result


def _adequate(ctx, data) -> bool:
    """Whether the nominal model passes the chi-square test (then pairs of effects are not tried)."""
    from guidefit.explain.data import p_value
    from guidefit.explain.evaluation import evaluate
    from guidefit.explain.settings import ACCEPT_P_VALUE

    return p_value(evaluate(ctx, data, []).chi2, data.n_data) >= ACCEPT_P_VALUE


def _unreproduced(measured, force_levels) -> list:
    """Modes whose frequency the hits of their force bins do not reproduce.

    identify refits every mode on the hits of each force bin; a level
    without a frequency means the refit moved the pole by more than the
    mode's half-power half-bandwidth (``zeta f``) or failed. A mode with such
    levels and fewer than two good ones (a weak mode on the flank of a
    strong, amplitude-dependent neighbour: pitch in a lateral run next to
    the 10 %-damped roll_low) has an all-hits frequency that depends on which
    hits are averaged by more than its bandwidth; its fit standard deviation
    (a few Hz) does not say so.
    """
    good: dict = {}
    bad: set = set()
    for lv in force_levels:
        if not isinstance(lv, ForceLevel):
            continue
        key = (lv.run, canonical_label(lv.label))
        if lv.frequency_hz is None:
            bad.add(key)
        else:
            good[key] = good.get(key, 0) + 1
    return [i for i, m in enumerate(measured) if isinstance(m, MeasuredMode)
            and (m.run, canonical_label(m.label)) in bad and good.get((m.run, canonical_label(m.label)), 0) < 2]


def _left_out_row(mode) -> dict:
    """The result row of a measured mode left out of the explanation (no model pairing, no error)."""
    return {"label": mode.label or "extra", "run": mode.run, "measured_hz": float(mode.frequency_hz),
            "measured_std_hz": mode.frequency_std_hz, "identified_hz": float(mode.frequency_hz),
            "sigma_hz": None, "model_before_hz": None, "model_before_label": None, "model_after_hz": None,
            "model_after_label": None, "error_before_pct": None, "error_after_pct": None,
            "mac_before": None, "mac_after": None, "status": "left out"}


def _without_unreproduced(measured, drop, guide, sensors, force_levels, candidates, progress, source, notes,
                          drop_unproduced_extras) -> Explanation:
    """Explain without the modes of :func:`_unreproduced`; they are listed with status ``left out``."""

    keep = [m for i, m in enumerate(measured) if i not in set(drop)]
    text = ", ".join(f"{measured[i].label} ({measured[i].run} run) {measured[i].frequency_hz:.1f} Hz" for i in drop)
    note = (f"left out: {text}: the hits of its force bins do not reproduce it (identify's refit moved it by more "
            "than its half-power half-bandwidth), so its frequency depends on which hits are averaged")
    sub = explain_modes(keep, guide, sensors, force_levels, candidates=candidates, progress=progress,
                        source=source, notes=(*notes, note), drop_unproduced_extras=drop_unproduced_extras)
    left = [_left_out_row(measured[i]) for i in drop]
    return replace(sub, modes=tuple(sub.modes) + tuple(left),
                   settings={**sub.settings, "left_out_unreproduced_hz": [float(measured[i].frequency_hz)
                                                                          for i in drop]})


def _without_extras(result, measured, extras, guide, sensors, force_levels, candidates, progress, source,
                    notes) -> Explanation:
    """Explain again without unlabelled extra peaks that no accepted model produces.

    An extra peak of the modal fit is weak evidence: real (a base body, which
    ``base_mode`` would then have explained) or a fit artefact, e.g. a
    carriage mode whose frequency sweeps with amplitude fitted by two poles.
    If an effect explains every other datum, it is named, and the extra
    peaks are listed as not explained by it.
    """

    keep = [m for i, m in enumerate(measured) if i not in set(extras)]
    sub = explain_modes(keep, guide, sensors, force_levels, candidates=candidates, progress=progress,
                        source=source, notes=(), drop_unproduced_extras=False)
    if sub.verdict != "explained":
        return result
    text = ", ".join(f"{measured[i].frequency_hz:.1f} Hz" for i in extras)
    note = (f"extra peak(s) at {text} (unlabelled) left out: no candidate produces them together with the "
            "carriage modes; the effect below explains everything else (the peaks are a fit artefact, e.g. an "
            "amplitude-dependent peak fitted by two poles, or a cause outside the library)")
    ignored = [_left_out_row(measured[i]) for i in extras]
    return replace(sub, notes=(note, *sub.notes, *notes), modes=tuple(sub.modes) + tuple(ignored),
                   settings={**sub.settings, "left_out_extra_hz": [float(measured[i].frequency_hz) for i in extras]})


