r"""From a hammer recording to K_V, K_H, c_V, c_H (the paper's Eq. 24-29).

Pipeline: per run, hits (:mod:`guidefit.hits`) -> averaged FRFs of every
response channel (:mod:`guidefit.frf`); then one modal model of all runs
(:func:`guidefit.modal_stage.identify_frfs`: poly-reference LSCF
stabilisation diagram, pole selection by stability, global
variable-projection fit with shared poles, :mod:`guidefit.globalfit`) ->
each mode's modal constants of every run assembled into one rigid-body
motion of the carriage and labelled by the motion that carries most of its
kinetic energy (vertical v, pitch theta, yaw psi, roll u-phi); ambiguous
labels are reported, not assigned. Every run's own estimate is kept
(``estimates``). ``IdentifySettings(method="per_run")`` runs the previous
per-run fits (each label keeps the estimate with the smallest frequency
uncertainty), kept as a diagnostic.

The joint parameters follow the paper's single-DOF reading of the vertical
and horizontal (``roll_low``) modes, with M the carriage mass of the guide:

* Eq. (24), (25): ``K = 4 pi^2 M f^2`` (:func:`stiffness_from_frequency`)
* Eq. (26), (28): ``xi = (f2 - f1) / (2 f)`` (:func:`guidefit.modes.half_power`)
* Eq. (27), (29): ``c = 4 pi M f xi`` (:func:`damping_from_frequency`)

``f`` is the undamped natural frequency |p|/2pi of the fit and ``xi``
its viscous damping ratio; the half-power values are reported beside them.
Uncertainties (one standard deviation) combine the fit's own standard error,
the delete-a-group jackknife over hits and (global fit) the spread over
pole selection.

Examples
--------
>>> round(stiffness_from_frequency(2.2, 3450.0) / 1e9, 3)
1.034
>>> round(damping_from_frequency(2.2, 3450.0, 0.0288))
2747
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from guidefit.errors import IdentificationError, identification_failure
from guidefit.identify_runs import (  # noqa: F401 - the per-run stage (issue 22), importable from here
    MIN_BINS_IN_BAND,
    _excitation_warnings,
    _fit_run,
    _force_levels,
    _hit_row,
    _quality_warnings,
    _refit_in_band,
    _refit_one,
    _select,
    _with_jackknife,
    frf_channels,
)
from guidefit.model.vibration import JOINT_LABELS
from guidefit.modeshapes import (  # noqa: F401 - also re-exported: guidefit.identify.IdentifiedMode etc.
    IdentifiedMode,
    _coherence_at,
    _half_power_entry,
    energy_shares,
    real_shape,
    rigid_body_motion,
    sensor_matrix,
)

# --------------------------------------------------------------------------- Eq. (24)-(29)


def stiffness_from_frequency(mass_kg: float, frequency_hz: float) -> float:
    """Joint stiffness K = 4 pi^2 M f^2 (N/m), Eq. (24) vertical and Eq. (25) horizontal."""
    return 4.0 * math.pi**2 * mass_kg * frequency_hz**2


def damping_from_frequency(mass_kg: float, frequency_hz: float, damping_ratio: float) -> float:
    """Joint damping c = 4 pi M f xi (N s/m), Eq. (27) vertical and Eq. (29) horizontal."""
    return 4.0 * math.pi * mass_kg * frequency_hz * damping_ratio


def joint_parameters(mass_kg: float, modes: dict) -> dict:
    """The contract's ``parameters`` from the vertical and roll_low modes.

    ``modes`` maps "V"/"H" to an :class:`IdentifiedMode` (or None). Standard
    deviations propagate linearly: std_K = 2 K std_f / f;
    std_c / c = sqrt((std_f/f)^2 + (std_xi/xi)^2).
    """
    out: dict = {}
    for key in ("V", "H"):
        mode = modes.get(key)
        if mode is None:
            for name, unit in ((f"f_{key}", "Hz"), (f"zeta_{key}", "1"), (f"K_{key}", "N/m"), (f"c_{key}", "N*s/m")):
                out[name] = {"value": None, "unit": unit, "std": None}
            continue
        f, zeta = mode.frequency_hz, mode.damping_ratio
        sf, sz = mode.frequency_std_hz, mode.damping_std
        k = stiffness_from_frequency(mass_kg, f)
        c = damping_from_frequency(mass_kg, f, zeta)
        rel_f = sf / f if sf is not None else None
        rel_z = sz / zeta if (sz is not None and zeta > 0) else None
        out[f"f_{key}"] = {"value": f, "unit": "Hz", "std": sf}
        out[f"zeta_{key}"] = {"value": zeta, "unit": "1", "std": sz}
        out[f"K_{key}"] = {"value": k, "unit": "N/m", "std": None if rel_f is None else 2 * k * rel_f}
        std_c = None
        if rel_f is not None and rel_z is not None:
            std_c = c * math.hypot(rel_f, rel_z)
        out[f"c_{key}"] = {"value": c, "unit": "N*s/m", "std": std_c}
    return out


# --------------------------------------------------------------------------- results


@dataclass(frozen=True)
class IdentifySettings:
    """Options of :func:`identify`; ``None`` means chosen from the data."""

    estimator: str = "H1"
    window: object = None  # guidefit.frf.WindowSettings
    fft_precision: str = "auto"  # "auto" (that of the stored samples), "single" or "double"
    hits: object = None  # guidefit.hits.HitSettings
    f_min_hz: float | None = None
    f_max_hz: float | None = None
    min_coherence: float = 0.9
    min_accepted_hits: int = 3
    jackknife: bool = True
    force_levels: bool = False  # per force-level frequencies (for explain's amplitude_dependence)
    force_bins: int = 3
    min_force_ratio: float = 1.5
    method: str = "global"  # "global": one modal model of all runs (guidefit.globalfit); "per_run": legacy fits

    def __post_init__(self):
        if self.method not in ("global", "per_run"):
            raise ValueError(f"IdentifySettings.method must be 'global' or 'per_run', got {self.method!r}")


@dataclass(frozen=True)
class RunResult:
    """One run's FRFs, hit table and fitted modes."""

    name: str
    frf: object  # guidefit.frf.FrfSet
    hits: list
    modes: list
    excitation_direction: tuple
    channels: list  # guidefit.recording.Channel of the responses, in FRF order
    force_levels: list = field(default_factory=list)


@dataclass(frozen=True)
class Identification:
    """The result of :func:`identify` for one recording."""

    file: str
    guide: object
    runs: tuple
    modes: tuple
    parameters: dict
    warnings: tuple
    extra_modes: tuple = ()
    missing_modes: tuple = ()
    failed_run_hits: tuple = ()  # hit rows of runs that gave no FRF (every hit rejected)
    hits_checked: bool = True  # False: identified from an FRF file (no time data, no hit checks)
    modal: object = field(default=None, repr=False, compare=False)  # guidefit.modal_stage.ModalResult
    gate: str | None = None  # why the modes are not those of a carriage on this guide (no joint parameters)
    sensor_faults: tuple = ()  # guidefit.consistency.SensorFault of channels that do not fit rigid motion
    #: why a joint parameter the set-up should have given is missing (its mode excited and seen, yet not found
    #: or not told apart): the identification is incomplete (exit 1), the parameters found are still given
    unidentified: tuple = ()
    #: the Recording identify read (None from FRFs): explain iterates its hits again without reading the file
    recording: object = field(default=None, repr=False, compare=False)

    def hit_rows(self) -> list[dict]:
        """Every hit of every run, accepted or rejected, including runs that gave no FRF."""
        return [row for run in self.runs for row in run.hits] + list(self.failed_run_hits)

    def to_dict(self) -> dict:
        """The contract's JSON object (``identify --json``), with optional extra fields."""
        return {
            "file": self.file,
            "guide": self.guide.name,
            "parameters": self.parameters,
            "modes": [m.to_dict() for m in self.modes],
            "warnings": list(self.warnings),
            "extra_modes": [m.to_dict() for m in self.extra_modes],
            "missing_modes": list(self.missing_modes),
            "hits": self.hit_rows(),
            "hits_checked": self.hits_checked,
            "sensors": [
                {"name": ch.name, "position_m": [float(x) for x in ch.position_m],
                 "direction": [float(x) for x in ch.direction]}
                for ch in self._sensor_channels()
            ],
            "force_levels": [lvl for run in self.runs for lvl in run.force_levels],
            "run_modes": self.run_modes(),
            "method": "global_fit" if self.modal is not None else "per_run",
            "gate": self.gate,
            "unidentified": list(self.unidentified),
            "sensor_faults": [{"channel": f.channel, "kind": f.kind, "factor": f.factor, "axis": f.axis,
                               "alternatives": list(f.alternatives), "message": f.message}
                              for f in self.sensor_faults],
        }

    def run_modes(self) -> list[dict]:
        """Every run's own all-hits f and zeta of each mode (``level`` None: all hits; nothing dropped).

        The force bins within a run are the ``force_levels`` entries (each
        with its ``level`` index, 0 = softest hits, frequency and damping).
        """
        return [{"label": m.label, **e} for m in list(self.modes) + list(self.extra_modes) for e in m.estimates]

    def _sensor_channels(self):
        seen = {}
        for run in self.runs:
            for ch in run.channels:
                seen.setdefault(ch.name, ch)
        return list(seen.values())

    def to_frame(self):
        """One row per parameter: name, value, unit, std."""
        import pandas as pd

        return pd.DataFrame(
            [{"parameter": k, **v} for k, v in self.parameters.items()],
            columns=["parameter", "value", "unit", "std"],
        )

    def summary_row(self) -> dict:
        """One flat row for ``--csv``/``--summary`` (units in the column names)."""
        units = {"Hz": "hz", "1": "1", "N/m": "n_per_m", "N*s/m": "ns_per_m"}
        row = {"file": self.file, "guide": self.guide.name}
        for name, p in self.parameters.items():
            suffix = units.get(p["unit"], p["unit"])
            row[f"{name}_{suffix}"] = p["value"]
            row[f"{name}_std_{suffix}"] = p["std"]
        row["n_warnings"] = len(self.warnings)
        row["hits_checked"] = self.hits_checked  # False: from an FRF file
        row["gate"] = self.gate
        return row


# --------------------------------------------------------------------------- shapes and labels
# --------------------------------------------------------------------------- pipeline


def run_frfs(recording, settings: IdentifySettings, warnings: list, failed: list | None = None,
             max_frequency_hz: float | None = None):
    """Yield (run, FrfSet, hit rows) for every run that gives an FRF; problems go to ``warnings``.

    The hit rows of a run that gives no FRF are added to ``failed`` (when given).
    ``max_frequency_hz``: the FRFs end there (:func:`guidefit.frf.compute_frf`).

    Hits stream from the file into the spectral sums (bounded memory); each
    rejected hit is listed with its reason.
    """
    from guidefit.frf import WindowSettings, compute_frf
    from guidefit.hits import HitSettings, iter_hits

    for run in recording.runs:
        if not run.response_indices:
            from guidefit.errors import RecordingError

            raise RecordingError(f"{run.file}: run '{run.name}': no acceleration channel; an FRF needs "
                                 "'force' and at least one 'acc_<point>_<axis>'")
        rows: list[dict] = []

        def tapped(it, rows=rows, run=run):
            for hit in it:
                rows.append(_hit_row(run.name, hit))
                if not hit.accepted:
                    warnings.append(f"run '{run.name}' hit {hit.index}: rejected: {hit.reason}")
                yield hit

        hits = tapped(iter_hits(run, settings.hits or HitSettings()))
        try:
            frf = compute_frf(run, hits, estimator=settings.estimator, window=settings.window or WindowSettings(),
                              precision=settings.fft_precision, max_frequency_hz=max_frequency_hz)
        except IdentificationError as exc:
            text = str(exc)
            warnings.append(text if text.startswith(f"run '{run.name}'") else f"run '{run.name}': {text}")
            if failed is not None:
                failed.extend(rows)
            continue
        n_ok = sum(r["accepted"] for r in rows)
        if n_ok < settings.min_accepted_hits:
            warnings.append(f"run '{run.name}': only {n_ok} accepted hit(s); uncertainties are unreliable")
        yield run, frf, rows


def file_frfs(frf_file, settings: IdentifySettings, warnings: list):
    """Yield (run, FrfSet, no hit rows) for every run of an FRF file; what it lacks goes to ``warnings``.

    The modal stage then runs on them as on :func:`run_frfs`' FRFs. Another
    estimator than the file's is used where its jackknife sums allow.
    """
    warnings.extend(frf_file.notes)
    if settings.window is not None:
        warnings.append("the window settings do not apply: the file holds FRFs already computed")
    for run, frf in zip(frf_file.recording.runs, frf_file.frfsets):
        if settings.estimator != frf.estimator and frf.estimator in ("H1", "H2", "Hv"):  # else: not said
            if frf.n_groups >= 1:
                frf = frf.with_estimator(settings.estimator)
            else:
                warnings.append(f"run '{run.name}': the file holds {frf.estimator} FRFs; estimator "
                                f"{settings.estimator} needs the spectral sums (not in the file)")
        yield run, frf, []


def identify(path, guide=None, settings: IdentifySettings | None = None) -> Identification:
    """Identify the joint modes and K_V, K_H, c_V, c_H of one recording (or of FRFs measured from one).

    Parameters
    ----------
    path : str or Path
        A recording in any registered format, or FRFs: guidefit's ``frf.h5``
        or UFF-58 FRFs (:func:`guidefit.io.frf_files.read_input`). From FRFs the
        pipeline starts at the modal fit: no hit checks (``hits_checked``
        False), and without jackknife sums in the file the std is the fit's own.
    guide : str, Path or Guide, optional
        Overrides the file's ``guide`` attribute (default MRB35 when neither is given).
    settings : IdentifySettings, optional

    Raises
    ------
    RecordingError
        Malformed file (exit 2).
    IdentificationError
        Valid file, but no result can be trusted: every hit rejected, no joint mode found (exit 1).
    """
    from guidefit.io.axes import frame_hint
    from guidefit.io.frf_files import FrfFile, read_input
    from guidefit.model import vibration as vib
    from guidefit.model.guides import Guide, load_guide

    settings = settings or IdentifySettings()
    source = read_input(path)
    from_frfs = isinstance(source, FrfFile)
    recording = source.recording if from_frfs else source
    if not isinstance(guide, Guide):
        guide = load_guide(guide or recording.guide or "MRB35")
    model = vib.solve_modes(vib.model_from_guide(guide))
    if settings.method == "global":
        return _identify_global(path, source, guide, model, settings)
    warnings: list[str] = []
    runs = []
    all_modes: list[IdentifiedMode] = []
    failed_rows: list[dict] = []
    frfs = file_frfs(source, settings, warnings) if from_frfs else run_frfs(recording, settings, warnings,
                                                                           failed_rows)
    for run, frf, rows in frfs:
        modes = _fit_run(run, frf, guide, model, settings, warnings)
        all_modes.extend(modes)
        levels = _force_levels(run, frf, rows, modes, settings, warnings) if settings.force_levels else []
        runs.append(RunResult(run.name, frf, rows, modes, tuple(run.excitation_direction),
                              frf_channels(run, frf), levels))
    if not runs:
        raise identification_failure(f"{path}: no run gave an FRF", warnings)
    axes = {r.name: int(np.argmax(np.abs(r.excitation_direction))) for r in runs}
    # sensor consistency and plausibility gate (guidefit.consistency): a channel that does not fit rigid
    # carriage motion is named and its runs fitted again with it corrected; the gate below withholds K and c
    from guidefit import consistency

    sensors = consistency.check_sensors(runs, all_modes, recording, guide, model, settings,
                                        refit=lambda run, frf: _fit_run(run, frf, guide, model, settings, []))
    runs, all_modes = sensors.runs, sensors.modes
    warnings.extend(sensors.warnings)
    modes, extras, missing = _select(all_modes, model, warnings, axes)
    if settings.jackknife:
        modes = _with_jackknife(modes, {r.name: r.frf for r in runs})
    joint = {k: next((m for m in modes if m.label == lab), None) for k, lab in JOINT_LABELS.items()}
    if joint["V"] is None and joint["H"] is None:
        raise identification_failure(f"{path}: neither the vertical nor the horizontal joint mode was found", warnings,
                                     hint=frame_hint(recording))
    _quality_warnings(modes, settings, warnings)
    _excitation_warnings(modes, {r.name: r.frf for r in runs}, warnings)
    params = joint_parameters(guide.mass_kg, joint)
    warnings.extend(consistency.unknown_hit_warnings(recording))
    gate = consistency.plausibility(modes, missing, sensors.sets, model)
    warnings.extend(consistency.mass_warnings(modes, sensors.sets, vib.carriage_mass_matrix(
        vib.model_from_guide(guide)), guide.mass_kg, model))
    if gate is not None:
        gate += frame_hint(recording)
        params = joint_parameters(guide.mass_kg, {})
    return Identification(str(path), guide, tuple(runs), tuple(modes), params, tuple(warnings),
                          tuple(extras), tuple(missing), tuple(failed_rows), hits_checked=not from_frfs,
                          gate=gate, sensor_faults=sensors.faults, recording=None if from_frfs else recording)


def _identify_global(path, source, guide, model, settings) -> Identification:
    """:func:`identify` with one modal model of all runs (:func:`guidefit.modal_stage.identify_frfs`).

    ``source`` is a recording, or an FRF file (:class:`~guidefit.io.frf_files.FrfFile`: no hit checks).
    The global shapes are checked for sensors that do not fit rigid carriage motion
    (:mod:`guidefit.consistency`): a faulty channel is named, its FRFs corrected (a scale
    divided out, a wrong axis left out) and the global fit made again; the plausibility gate
    then withholds K and c when the modes are not those of a carriage on this guide.
    """
    from guidefit import consistency
    from guidefit.io.axes import frame_hint
    from guidefit.io.frf_files import FrfFile

    warnings: list[str] = []
    failed_rows: list[dict] = []
    from_frfs = isinstance(source, FrfFile)
    recording = source.recording if from_frfs else source
    from guidefit.modal_stage import frf_top_hz

    collected = list(file_frfs(source, settings, warnings) if from_frfs
                     else run_frfs(source, settings, warnings, failed_rows, frf_top_hz(model, settings)))
    if not collected:
        raise identification_failure(f"{path}: no run gave an FRF", warnings)
    order = {run.name: i for i, (run, _, _) in enumerate(collected)}
    run_of = {run.name: run for run, _, _ in collected}
    first = list(warnings)
    res, runs = _global_pass(collected, guide, model, settings, first)
    levels_only = []
    harder = _force_level_runs(collected)
    if harder and not _levels_agree(res, harder):  # amplitude-dependent: the harder levels fitted apart
        levels_only = [item for item in collected if item[0].name in harder]
        collected = [item for item in collected if item[0].name not in harder]
        for name, ratio in harder.items():
            warnings.append(f"run '{name}': the same hit point and direction as a softer run at {ratio:.1f}x its "
                            "mean hit force, and its modes move with the force (contacts soften with amplitude): "
                            "a force level, left out of the shared-pole fit; explain compares it through the "
                            "force-level model")
        first = list(warnings)
        res, runs = _global_pass(collected, guide, model, settings, first)
    check = consistency.check_global(runs, recording, guide, settings)
    if check.faults:  # the fit again without the faults; the first pass's warnings are dropped with it
        collected = consistency.corrected_runs(collected, check.faults, settings, recompute=not from_frfs)
        res, runs = _global_pass(collected, guide, model, settings, warnings)
        check = consistency.check_global(runs, recording, guide, settings, faults=check.faults)
    else:
        warnings = first
    warnings.extend(f.message for f in check.faults)
    runs += [RunResult(run.name, frf, rows, [], tuple(run.excitation_direction), frf_channels(run, frf), [])
             for run, frf, rows in levels_only]
    runs.sort(key=lambda r: order[r.name])
    if settings.force_levels:  # on the final fit only (a pass made again discards its views)
        runs = [replace(r, force_levels=_force_levels(run_of[r.name], r.frf, r.hits, r.modes, settings, warnings))
                if r.modes else r for r in runs]
    modes = res.modes if res is not None else []
    joint = {k: next((m for m in modes if m.label == lab), None) for k, lab in JOINT_LABELS.items()}
    neither = joint["V"] is None and joint["H"] is None
    if neither and (res is None or not (res.modes or res.extras)):
        raise identification_failure(f"{path}: neither the vertical nor the horizontal joint mode was found", warnings,
                                     hint=frame_hint(recording))
    frf_by_run = {r.name: r.frf for r in runs}
    _quality_warnings(modes, settings, warnings)
    _excitation_warnings(modes, frf_by_run, warnings)
    params = joint_parameters(guide.mass_kg, joint)
    warnings.extend(consistency.unknown_hit_warnings(recording))
    # modes that are found but not named (ambiguous) count as missing for the gate
    not_named = [lab for lab in model.labels if lab not in {m.label for m in modes} and not lab.startswith("support")]
    gate = consistency.plausibility(modes, not_named, check.sets, model)
    if gate is None and neither:  # modes found, none of them the vertical or the horizontal joint mode
        gate = (f"neither the vertical nor the horizontal joint mode was found among the {len(res.modes)} "
                f"labelled and {len(res.extras)} other modes: the recording does not look like a carriage on "
                "this guide, or its sensors cannot tell its modes apart (guidefit plan shows what they can)")
    warnings.extend(consistency.global_mass_warnings(runs, check.sets, guide, model))
    if gate is not None:
        gate += frame_hint(recording)
        params = joint_parameters(guide.mass_kg, {})
    unidentified = () if gate is not None else _unidentified(joint, model, check.sets, [*modes, *res.extras])
    return Identification(str(path), guide, tuple(runs), tuple(modes), params, tuple(warnings),
                          tuple(res.extras), tuple(res.missing), tuple(failed_rows), hits_checked=not from_frfs,
                          modal=res, gate=gate, sensor_faults=check.faults, unidentified=unidentified,
                          recording=None if from_frfs else recording)


def _unidentified(joint: dict, model, sets, modes) -> tuple:  # modes: the named ones and the extras
    """One sentence per joint parameter pair (f_V..c_V, f_H..c_H) left out although the set-up excites and
    sees its mode (:func:`guidefit.consistency.observable_modes`): not found, or found and not told apart
    (``ambiguous``). A layout that cannot see the mode is not a failure (the result says what it cannot tell)."""
    from guidefit import consistency

    observable = consistency.observable_modes(model, sets)
    ambiguous = any(getattr(m, "label", None) == "ambiguous" for m in modes)
    out = []
    for key, label in JOINT_LABELS.items():
        if joint.get(key) is None and label in observable:
            why = "found but not told apart from another mode" if ambiguous else "not found"
            out.append(f"f_{key}, K_{key}, c_{key} not identified: the {label} mode this set-up excites and sees "
                       f"was {why} (the warnings say why)")
    return tuple(out)


#: runs of one hit point and direction whose mean peak forces differ by this factor are force levels
LEVEL_FORCE_RATIO = 1.5


def _force_level_runs(collected) -> dict:
    """Runs that are only harder force levels of another run: name -> mean force ratio to the softest.

    Runs with the same hit point, hit direction, channels, sample rate and
    record length whose mean accepted peak forces differ by
    :data:`LEVEL_FORCE_RATIO` are levels of one test.
    """
    groups: dict = {}
    for run, frf, rows in collected:
        pos = run.excitation_position_m
        key = (None if pos is None else tuple(np.round(np.asarray(pos, float), 4)),
               tuple(np.round(np.asarray(run.excitation_direction, float), 3)), tuple(frf.channels),
               float(run.sample_rate_hz), int(getattr(run, "n_samples", 0) or 0))
        forces = [r["peak_force_n"] for r in rows if r.get("accepted")]
        if forces:
            groups.setdefault(key, []).append((float(np.mean(forces)), run.name))
    out = {}
    for members in groups.values():
        low = min(f for f, _ in members)
        out.update({name: f / low for f, name in members if low > 0 and f >= LEVEL_FORCE_RATIO * low})
    return out


def _levels_agree(res, harder: dict) -> bool:
    """Whether the harder force levels share the softer run's poles (linear contacts).

    Preloaded Hertz contacts soften with amplitude (rollers unload), so a
    harder level's modes move (on MRB35 f_V -0.3 % at 1 kN, -18 % at 5 kN):
    then a shared-pole fit would average levels that differ. They agree when
    the global fit found modes and each harder run's own estimate of every
    mode lies within max(3 std, 0.1 %) of the shared frequency, and no harder
    run has lost most of the modes a softer run shows (modes that moved far
    leave a shared-pole fit without them: no estimate is no agreement).
    """
    if res is None or not res.modes:
        return False
    soft_modes, shown = 0, dict.fromkeys(harder, 0)
    for m in res.modes:
        seen = {e.get("run") for e in m.estimates if e.get("level") is None and e.get("frequency_hz") is not None}
        if seen - set(harder):
            soft_modes += 1
            for h in seen & set(harder):
                shown[h] += 1
    if any(2 * n < soft_modes for n in shown.values()):  # a harder run lost most of the softer run's modes: moved
        return False
    for m in res.modes:
        for e in m.estimates:
            if e.get("run") not in harder or e.get("level") is not None or e.get("frequency_hz") is None:
                continue
            std = e.get("frequency_std_hz") or 0.0
            if abs(e["frequency_hz"] - m.frequency_hz) > max(3.0 * std, 1e-3 * m.frequency_hz):
                return False
    return True


def _global_pass(collected, guide, model, settings, warnings: list):
    """One global fit of the (run, FrfSet, hit rows) triples: the ModalResult (None when it failed,
    the reason in ``warnings``) and each run's RunResult with its views of the shared modes
    (force levels are added by the caller, on the final fit)."""
    from guidefit import modal_stage

    frf_by_run = {run.name: frf for run, frf, _ in collected}
    geometry = {run.name: modal_stage.geometry_of(run, frf) for run, frf, _ in collected}
    try:
        res = modal_stage.identify_frfs(frf_by_run, geometry, guide, settings, warnings, model=model)
    except IdentificationError as exc:
        warnings.append(str(exc))
        res = None
    runs = []
    for run, frf, rows in collected:
        views = []
        if res is not None:
            for m in res.modes + res.extras:
                k = m.global_index
                if run.name in res.fit.runs and res.per_run.get(run.name, [None] * (k + 1))[k] is not None:
                    views.append(replace(m, run=run.name, fit=res.fit.run_mode(k, run.name),
                                         shape=m.shapes.get(run.name, m.shape)))
        runs.append(RunResult(run.name, frf, rows, views, tuple(run.excitation_direction),
                              frf_channels(run, frf)))
    return res, runs


def frf_of_recording(path, settings: IdentifySettings | None = None):
    """FRF sets of every run of any recording (guideway or not) and the warnings.

    Raises :class:`IdentificationError` when no run gives an FRF.
    """
    from guidefit.io.frf_files import FrfFile, read_input

    settings = settings or IdentifySettings()
    warnings: list[str] = []
    source = read_input(path)
    frfs = file_frfs(source, settings, warnings) if isinstance(source, FrfFile) else run_frfs(source, settings,
                                                                                              warnings)
    frfsets = [frf for _run, frf, _rows in frfs]
    if not frfsets:
        raise identification_failure(f"{path}: no run gave an FRF", warnings)
    return frfsets, warnings


from guidefit._api import make_callable  # noqa: E402

make_callable(__name__, "identify")
