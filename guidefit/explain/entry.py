"""Entry points: explain a recording, a modes file or an Identification; the fitted model spec."""

from __future__ import annotations

from pathlib import Path

from guidefit.errors import RecordingError
from guidefit.explain.inputs import Explanation
from guidefit.explain.modes_json import is_unnamed_level, level_from, modes_from_identification, read_modes_json
from guidefit.explain.pipeline import explain_modes


def _effects_prepare(identification, candidates, modes: list, levels: list, notes: list):
    """Let each candidate effect with a ``prepare`` hook gather its data from the identification.

    An effect may need more than identify's modes and force levels, e.g.
    ``amplitude_dependence`` the force levels across runs that differ only in
    hit force (:class:`~guidefit.model.effects.EffectDef`, ``prepare``); a
    hook that fails on these data leaves a note, not an error.
    """
    from guidefit.errors import GuidefitError
    from guidefit.model.effects import ALIASES, EFFECTS

    if candidates is None:
        names = list(EFFECTS)
    else:  # an unknown name is explain_modes' error to report
        names = [ALIASES.get(n, n) for n in candidates if n in EFFECTS or n in ALIASES]
    for name in names:
        hook = EFFECTS[name].prepare
        if hook is None:
            continue
        try:
            modes, levels = hook(identification, modes, levels, notes)
        except GuidefitError as exc:
            notes.append(f"{name}: its data could not be gathered from the identification: {exc}")
    return modes, levels


def explain_identification(identification, candidates=None, progress=None) -> Explanation:
    """Explain the modes of an :class:`~guidefit.identify.Identification`, taken from its objects.

    Its modes, extra modes and sensors (:func:`modes_from_identification`),
    its runs' force levels, and what the candidate effects' ``prepare``
    hooks gather from it; the file is not read again.
    """
    where = str(identification.file)
    modes, sensors = modes_from_identification(identification)
    raw_levels = [lv for run in identification.runs for lv in run.force_levels]
    levels, notes = [], []
    unnamed = sorted({str(e["label"]) for e in raw_levels if is_unnamed_level(e)})
    if unnamed:  # identify gives none; a caller's own Identification may
        notes.append(f"force levels of {' and '.join(unnamed)} modes not used: a level must name a model mode")
    for k, entry in enumerate(raw_levels):
        if is_unnamed_level(entry):
            continue
        try:
            levels.append(level_from(entry, f"{where}: force_levels entry {k}"))
        except RecordingError as exc:
            notes.append(f"force level skipped: {exc}")
    modes, levels = _effects_prepare(identification, candidates, modes, levels, notes)
    return explain_modes(modes, identification.guide, sensors, levels, candidates=candidates,
                         progress=progress, source=where, notes=notes)


def explain(source, guide=None, candidates=None, progress=None, settings=None) -> Explanation:
    """Explain a recording (identified first), a modes JSON file or an Identification.

    Parameters
    ----------
    source : str, Path or Identification
        ``.h5``/``.hdf5``/``.csv`` recording, ``.json``/``.jsonl`` modes file
        (:func:`read_modes_json`), or an identification result.
    guide : str or Guide, optional
        Overrides the guide named by the source (default MRB35).
    settings : IdentifySettings, optional
        How a recording is identified (estimator, windows, ...); force levels
        are always on. ``guidefit report`` passes the same settings.
    """
    from guidefit.model.guides import load_guide

    if hasattr(source, "runs") and hasattr(source, "modes"):
        return explain_identification(source, candidates, progress)
    path = Path(source)
    if path.suffix.lower() in (".json", ".jsonl", ".ndjson"):
        modes, name, sensors, levels = read_modes_json(path)
        g = guide if guide is not None else (name or "MRB35")
        g = g if not isinstance(g, str | Path) else load_guide(g)
        return explain_modes(modes, g, sensors, levels, candidates=candidates, progress=progress,
                             source=str(path))
    ident = identify_for_explain(path, guide=guide, settings=settings)
    return explain_identification(ident, candidates, progress)


def identify_for_explain(path, guide=None, settings=None):
    """The identification ``explain`` starts from: :func:`~guidefit.identify.identify` with force levels on."""
    from dataclasses import replace

    from guidefit.identify import IdentifySettings, identify

    # force levels feed the amplitude_dependence candidate
    return identify(path, guide=guide, settings=replace(settings or IdentifySettings(), force_levels=True))


def fitted_spec(explanation: Explanation, guide=None):
    """The (small-amplitude) model spec behind ``model_after_hz``: the guide with the fitted effects.

    Use it with :func:`guidefit.model.vibration.solve_modes` and
    :func:`~guidefit.model.vibration.accelerance` for FRF overlays.
    """
    from guidefit.model import vibration as vib
    from guidefit.model.effects import apply_effects
    from guidefit.model.guides import Guide, load_guide

    g = guide if isinstance(guide, Guide) else load_guide(guide or explanation.guide)
    return apply_effects(vib.model_from_guide(g), g, list(explanation.fitted_effects))


