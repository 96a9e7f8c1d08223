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
from guidefit.modeshapes import (  # also re-exported: guidefit.identify.IdentifiedMode etc.
    UNNAMED_LABELS,
    IdentifiedMode,
    _coherence_at,
    _half_power_entry,
    energy_shares,
    real_shape,
    rigid_body_motion,
    sensor_matrix,
)

JOINT_LABELS = {"V": "vertical", "H": "roll_low"}


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


def _search_band(model, run, settings) -> tuple[float, float]:
    f_lo = settings.f_min_hz or 0.35 * float(np.min(model.frequencies_hz))
    f_hi = settings.f_max_hz or 1.3 * float(np.max(model.frequencies_hz))
    return f_lo, min(f_hi, 0.4 * run.sample_rate_hz)


def _hit_row(run_name: str, hit) -> dict:
    return {"run": run_name, "hit": int(hit.index), "start_sample": int(hit.start_sample),
            "peak_force_n": float(hit.peak_force_n), "accepted": bool(hit.accepted), "reason": hit.reason}


def _narrow_band(mode) -> tuple[float, float]:
    """A band around one fitted mode: +/- max(3 zeta, 3 %) of its frequency."""
    half_width = max(3 * mode.damping_ratio, 0.03) * mode.frequency_hz
    return mode.frequency_hz - half_width, mode.frequency_hz + half_width


def _refit_one(frf, mode, max_nfev: int = 20, uncertainty: bool = True):
    """Refit one mode in its narrow band, starting from ``mode`` (None when the fit fails)."""
    from guidefit import curvefit

    try:
        return curvefit.fit_modes(frf.frequency_hz, frf.H, _narrow_band(mode), 1, initial=[mode],
                                   max_nfev=max_nfev, uncertainty=uncertainty)[0]
    except (IdentificationError, ValueError, np.linalg.LinAlgError):
        return None


def _band_of(frf, f_lo_hz: float, f_hi_hz: float):
    """The FrfSet restricted to the bins in [f_lo_hz, f_hi_hz] (group sums included).

    The jackknife replicates then re-estimate a few hundred bins instead of
    the whole spectrum.
    """

    sel = (frf.frequency_hz >= f_lo_hz) & (frf.frequency_hz <= f_hi_hz)
    sums = {k: (v if k == "n_hits" else np.asarray(v)[:, sel]) for k, v in frf.group_sums.items()}
    return replace(frf, frequency_hz=frf.frequency_hz[sel], H=frf.H[sel],
                   coherence=frf.coherence[sel], group_sums=sums)


def _refit_in_band(frf, mode, run_fits, max_nfev: int = 40):
    """Refit ``mode`` in its narrow band on an FRF from which its near neighbours are taken out.

    The run's other modes (``run_fits``: (Mode, label) of its all-hits fit)
    outside the band whose own narrow band reaches into it are subtracted
    (:func:`guidefit.modes.synthesize`; channels then weighted by the share
    and relative amplitude of the band's modes in them), those inside are
    fitted with it, distant ones are left to the residual terms. A
    single-mode refit of the FRF itself is pulled by a neighbour: the flank
    of the 10 %-damped roll_low cut by pitch's +/- 6 % band biased pitch by
    +0.12 % on a linear recording, and pitch inside roll_low's +/- 31 % band
    pulled roll_low by 8 % in a vertical run. The band stays +/- max(3 zeta, 3 %), widened bin by bin until it
    holds enough bins: the estimator that explain's amplitude model follows.
    Tried in turn: with every mode in the band, with its labelled ones only
    (an extra peak may be a second pole of one amplitude-dependent peak,
    which a subset of the hits does not support), alone. The first refit
    whose pole stays within half the mode's bandwidth (``zeta f``) of the
    all-hits fit, as in ``modes.auto_fit``'s joint refit, and whose shape
    keeps a MAC of :data:`REFIT_MIN_MAC` with it is returned (None when none
    does), with the band (Hz).
    """
    import warnings as _w

    from guidefit import curvefit
    from guidefit import modes as modes_mod

    lo, hi = _narrow_band(mode)
    f = frf.frequency_hz
    step = float(np.median(np.diff(f)))

    def inside_band():
        return [(m, lab) for m, lab in run_fits if m is not mode and lo < m.frequency_hz < hi]

    inside = inside_band()
    # at least 4 bins more than a fit of every mode in the band needs (modes.fit_band: 3 n + 5)
    while np.count_nonzero((f > lo) & (f < hi)) < 3 * (len(inside) + 1) + 9 and hi - lo < mode.frequency_hz:
        lo, hi = lo - step, hi + step
        inside = inside_band()
    # near neighbours, whose own band reaches into this one, are subtracted; distant modes are left to the
    # residual terms, as in any narrow-band fit
    outside = [m for m, _ in run_fits if m is not mode and not lo < m.frequency_hz < hi
               and _narrow_band(m)[0] < hi and _narrow_band(m)[1] > lo]
    H, weights = frf.H, None
    if outside:
        try:
            H = H - modes_mod.synthesize(f, outside)
            # fit_modes scales every channel to unit RMS in the band: a channel that the band's modes
            # hardly move (pitch in x) would be what the subtraction leaves, scaled up; weight each
            # channel by the share of the band's modes in it instead
            sel = (f > lo) & (f < hi)
            own = np.sqrt(np.mean(np.abs(modes_mod.synthesize(f[sel], [mode] + [m for m, _ in inside])) ** 2, axis=0))
            share = own / np.maximum(np.sqrt(np.mean(np.abs(H[sel]) ** 2, axis=0)), 1e-300)
            # ... and by its amplitude relative to the strongest channel (both parts tiny: not a datum)
            weights = np.broadcast_to(np.clip(share, 0.0, 1.0) * own / max(float(own.max()), 1e-300), H.shape)
        except ValueError:  # residues of another channel set: refit the FRF as it is
            H, weights = frf.H, None
    tries, seen = [], set()
    for others in ([m for m, _ in inside], [m for m, lab in inside if lab != "extra"], []):
        key = tuple(id(m) for m in others)
        if key not in seen:
            seen.add(key)
            tries.append(sorted([mode, *others], key=lambda m: m.frequency_hz))
    for group in tries:
        try:
            with _w.catch_warnings():
                _w.simplefilter("ignore")
                fits = curvefit.fit_modes(f, H, (lo, hi), len(group), initial=group, weights=weights,
                                           max_nfev=max_nfev if len(group) > 1 else 20)
        except (IdentificationError, ValueError, np.linalg.LinAlgError):
            continue
        r = fits[group.index(mode)]  # both sorted by frequency
        if (abs(r.frequency_hz - mode.frequency_hz) <= mode.damping_ratio * mode.frequency_hz
                and _mac(r.modal_constants, mode.modal_constants) >= REFIT_MIN_MAC):
            return r, (lo, hi)
    return None, (lo, hi)


#: A force-level refit whose shape has a lower MAC with the all-hits shape is not the same mode.
REFIT_MIN_MAC = 0.9


def _mac(a, b) -> float:
    """Modal assurance criterion of two real shapes (:func:`real_shape` of modal constants)."""
    x, y = real_shape(a), real_shape(b)
    den = float((x @ x) * (y @ y))
    return float((x @ y) ** 2 / den) if den > 0 else 0.0


def _jackknife(frf, modes) -> list[tuple[float | None, float | None]]:
    """Delete-a-group jackknife std of (f_n, zeta) for each mode; None where too few groups.

    Each leave-one-group-out FRF is refitted mode by mode in a narrow band
    around the full fit (one mode and residual terms), which is what makes
    the jackknife affordable; the full fit's neighbours are outside the band
    or absorbed by the residual terms. The replicates are made one at a time,
    so memory holds one extra FRF set whatever the number of groups.
    """
    import warnings as _w

    if not modes or not hasattr(frf, "leave_one_group_out") or getattr(frf, "n_groups", 0) < 3:
        return [(None, None)] * len(modes)
    fits: list[list] = [[] for _ in modes]
    lo = min(_narrow_band(m)[0] for m in modes)
    hi = max(_narrow_band(m)[1] for m in modes)
    with _w.catch_warnings():
        _w.simplefilter("ignore")
        for sub in _band_of(frf, lo, hi).leave_one_group_out():
            for k, mode in enumerate(modes):
                r = _refit_one(sub, mode, uncertainty=False)
                if r is not None:
                    fits[k].append(r)
            del sub
    out = []
    for mode_fits in fits:
        n = len(mode_fits)
        if n < 3:
            out.append((None, None))
            continue
        fk = np.array([r.frequency_hz for r in mode_fits])
        zk = np.array([r.damping_ratio for r in mode_fits])
        out.append((math.sqrt((n - 1) / n * np.sum((fk - fk.mean()) ** 2)),
                    math.sqrt((n - 1) / n * np.sum((zk - zk.mean()) ** 2))))
    return out


def _with_jackknife(modes: list, frf_by_run: dict) -> list:
    """The selected joint modes (vertical, roll_low) with the hit-group jackknife in their std.

    The jackknife's eight refits per mode are most of identify's time, so it
    runs for the modes behind the joint parameters only, after selection;
    the other modes keep the curve fit's own standard error.
    """

    out = []
    for m in modes:
        if m.label in JOINT_LABELS.values() and m.fit is not None:
            (jk_f, jk_z), = _jackknife(frf_by_run[m.run], [m.fit])
            m = replace(m, frequency_std_hz=_combine(jk_f, m.fit.frequency_std_hz),
                        damping_std=_combine(jk_z, m.fit.damping_std))
        out.append(m)
    return out


MIN_BINS_IN_BAND = 8  # fewer FRF bins than this in the search band: no mode fit is attempted


def _fit_run(run, frf, guide, model, settings, warnings: list) -> list[IdentifiedMode]:
    from guidefit import curvefit
    from guidefit import frf as frf_mod
    from guidefit import modes as modes_mod
    from guidefit.model import vibration as vib

    band = _search_band(model, run, settings)
    if not band[1] > band[0] * 1.05:
        warnings.append(f"run '{run.name}': sample rate {run.sample_rate_hz:g} Hz too low for the modes "
                        f"searched from {band[0]:.0f} Hz (needs at least {band[0] / 0.4:.0f} Hz)")
        return []
    freq = np.asarray(frf.frequency_hz)
    if np.count_nonzero((freq >= band[0]) & (freq <= band[1])) < MIN_BINS_IN_BAND:
        n = 2 * (len(freq) - 1)
        warnings.append(f"run '{run.name}': records of about {n} samples give {freq[-1] / max(len(freq) - 1, 1):.0f} Hz "
                        f"resolution, too coarse for the modes between {band[0]:.0f} and {band[1]:.0f} Hz "
                        f"(fewer than {MIN_BINS_IN_BAND} bins); longer records are needed")
        return []
    try:
        import warnings as _w

        with _w.catch_warnings(record=True) as caught:
            _w.simplefilter("always")
            fitted = curvefit.auto_fit(frf.frequency_hz, frf.H, band[0], band[1])
        for w in caught:
            if issubclass(w.category, modes_mod.ModeFitWarning):
                warnings.append(f"run '{run.name}': {w.message}")
    except IdentificationError as exc:
        warnings.append(f"run '{run.name}': no mode found between {band[0]:.0f} and {band[1]:.0f} Hz ({exc})")
        return []
    fitted = sorted(fitted, key=lambda m: m.frequency_hz)
    sensors = sensor_matrix(frf_channels(run, frf))
    mass = vib.carriage_mass_matrix(vib.model_from_guide(guide))
    tau = getattr(frf, "exp_window_tau_s", None)
    candidates = []
    for mode in fitted:
        f_n, zeta = mode.frequency_hz, mode.damping_ratio
        if tau:
            f_n, zeta = frf_mod.exponential_window_damping_correction(zeta, f_n, tau)
        shape = real_shape(mode.modal_constants)
        q, _observed = rigid_body_motion(shape, sensors)
        norm = np.linalg.norm(q) or 1.0
        q = q / norm
        energy = energy_shares(q, mass)
        f_std, z_std = mode.frequency_std_hz, mode.damping_std
        candidates.append({
            "mode": mode, "frequency_hz": f_n, "damping_ratio": zeta, "q": q, "energy": energy,
            "shape": shape,
            "f_std": f_std, "z_std": z_std,
        })
    candidates = _significant(candidates)
    from guidefit import labels as lab_mod

    view = {run.name: lab_mod.RunView(frf_channels(run, frf), tuple(run.excitation_direction),
                                      None if run.excitation_position_m is None
                                      else tuple(run.excitation_position_m))}
    decided = lab_mod.label_modes([lab_mod.Measured(float(c["frequency_hz"]), {run.name: c["shape"]})
                                   for c in candidates], view, model)
    out = []
    names = [ch.name for ch in frf_channels(run, frf)]
    for c, dec in zip(candidates, decided):
        mode = c["mode"]
        label = "extra" if dec.label == "ambiguous" else dec.label  # one run alone: not told apart is extra
        model_f = model.frequency_hz(label) if label in model.labels else None
        out.append(IdentifiedMode(
            label=label, run=run.name, frequency_hz=float(c["frequency_hz"]),
            damping_ratio=float(c["damping_ratio"]),
            frequency_std_hz=c["f_std"], damping_std=c["z_std"], model_frequency_hz=model_f,
            shape=dict(zip(names, (float(v) for v in c["shape"]))),
            motion=tuple(float(v) for v in c["q"]), energy={k: float(v) for k, v in c["energy"].items()},
            coherence=_coherence_at(frf, mode.peak_frequency_hz, mode.residues),
            half_power=_half_power_entry(frf, mode, tau), raw_damping_ratio=float(mode.damping_ratio),
            fit=mode, label_basis=dec.basis, label_note=dec.note, label_mac=dec.mac, label_scale=dec.scale,
        ))
    return out


def _force_levels(run, frf, rows, modes, settings, warnings: list) -> list[dict]:
    """Frequencies of the run's labelled modes per hit-force bin (terciles of the accepted hits).

    Each bin's hits are averaged into their own FRF with the run's windows and
    each mode is refitted in its narrow band, its near neighbours subtracted
    and the modes inside the band fitted with it (:func:`_refit_in_band`); a
    preloaded Hertz contact shows as a frequency that falls with force. Only
    when the forces differ by at least ``min_force_ratio``; every bin needs
    two hits. A level gives the bin's mean peak force and its hits' peak
    forces (``hit_forces_n``: H1 weights each hit's FRF by its force squared,
    so the bin's frequency is that of its force-squared weighted hits, not of
    the mean force), the refit's band (``band_hz``) and shape (``shape``,
    real modal constants per channel). A bin whose hits do not reproduce the
    mode (the refit moves it by more than ``zeta f`` or to a MAC below
    :data:`REFIT_MIN_MAC`) gives a level without a frequency
    (``refit_failed``), and the mode is left out of its neighbours' refits of
    that bin.

    Only modes with a model label get levels: a level names the model mode
    whose trend it carries (``explain`` and the modes-file reader accept only
    those). An ``extra`` mode is a neighbour in the others' refits; an
    ``ambiguous`` one is refitted too (a bin that does not reproduce it
    leaves it out of its neighbours' refits), but neither gives a level.
    """
    from guidefit import frf as frf_mod
    from guidefit.hits import HitSettings, iter_hits

    accepted = [r for r in rows if r["accepted"]]
    fitted = sorted((m for m in modes if m.label != "extra" and m.fit is not None), key=lambda m: m.frequency_hz)
    run_fits = [(m.fit, m.label) for m in modes if m.fit is not None]  # extra peaks pull a neighbour too
    if not fitted or len(accepted) < 2 * settings.force_bins:
        return []
    forces = np.array([r["peak_force_n"] for r in accepted])
    if forces.max() < settings.min_force_ratio * forces.min():
        return []
    window = frf_mod.WindowSettings(force_window_s=frf.force_window_s, exp_tau_s=frf.exp_window_tau_s) \
        if frf.exp_window_tau_s else frf_mod.WindowSettings(none=True)
    names = [ch.name for ch in frf_channels(run, frf)]
    levels = []
    for level_index, members in enumerate(np.array_split(np.argsort(forces), settings.force_bins)):
        wanted = {accepted[i]["hit"] for i in members}
        hits = (h for h in iter_hits(run, settings.hits or HitSettings()) if h.index in wanted)
        try:
            sub = frf_mod.compute_frf(run, hits, estimator=settings.estimator, window=window,
                                      precision=frf.fft_precision, max_frequency_hz=frf_mod.top_of(frf))
        except IdentificationError as exc:
            warnings.append(f"run '{run.name}': force-level FRF failed ({exc})")
            return []
        # a narrow band around each mode, the run's other modes subtracted or refitted with it: robust
        # against modes trading places, and a neighbour cannot pull it. A mode that this bin's hits do not
        # reproduce is then left out of its neighbours' refits: its all-hits fit would pull them instead
        refits = {id(m): _refit_in_band(sub, m.fit, run_fits) for m in fitted}
        failed = {id(m.fit) for m in fitted if refits[id(m)][0] is None}
        if failed:
            kept = [(fit, lab) for fit, lab in run_fits if id(fit) not in failed]
            refits.update({id(m): _refit_in_band(sub, m.fit, kept) for m in fitted if id(m.fit) not in failed})
        for m in fitted:
            if m.label in UNNAMED_LABELS:
                continue  # an ambiguous mode: refitted above as a neighbour; a level needs a model label
            r, band = refits[id(m)]
            level = {"run": run.name, "label": m.label, "level": level_index,
                     "peak_force_n": float(np.mean(forces[members])),
                     "n_hits": int(len(members)), "hit_forces_n": [float(x) for x in np.sort(forces[members])],
                     "frequency_hz": None, "frequency_std_hz": None, "band_hz": [float(x) for x in band],
                     "hit_position_m": None if run.excitation_position_m is None
                     else [float(x) for x in run.excitation_position_m],
                     "hit_direction": [float(x) for x in run.excitation_direction]}
            if r is None:  # the mode is not reproduced by this bin's hits: a level without a frequency
                level["refit_failed"] = True
            else:
                f_n, z_n = r.frequency_hz, r.damping_ratio
                if frf.exp_window_tau_s:
                    f_n, z_n = frf_mod.exponential_window_damping_correction(r.damping_ratio, r.frequency_hz,
                                                                           frf.exp_window_tau_s)
                level["frequency_hz"], level["frequency_std_hz"] = float(f_n), r.frequency_std_hz
                level["damping_ratio"], level["damping_std"] = float(z_n), r.damping_std
                level["shape"] = dict(zip(names, (float(v) for v in real_shape(r.modal_constants))))
            levels.append(level)
    return levels


MIN_RELATIVE_AMPLITUDE = 5e-3
MAX_RELATIVE_FREQUENCY_STD = 3e-2


def _significant(candidates: list[dict]) -> list[dict]:
    """Drop computational modes of the curve fit: modes whose largest modal constant is below
    0.5 % of the run's strongest mode, or whose frequency is uncertain by more than 3 %.

    A real but weakly excited mode (an extra base mode, say) passes both tests
    on any usable recording; a fitted pole that only absorbs noise or a flank
    fails them.
    """
    if not candidates:
        return candidates
    top = max(float(np.max(np.abs(c["shape"]))) for c in candidates) or 1.0
    keep = []
    for c in candidates:
        amplitude = float(np.max(np.abs(c["shape"]))) / top
        rel_std = (c["f_std"] or 0.0) / c["frequency_hz"]
        if amplitude >= MIN_RELATIVE_AMPLITUDE and rel_std <= MAX_RELATIVE_FREQUENCY_STD:
            keep.append(c)
    return keep


def _combine(a: float | None, b: float | None) -> float | None:
    """Root-sum-square of two standard deviations, ignoring missing ones."""
    vals = [float(v) for v in (a, b) if v is not None and math.isfinite(v)]
    return math.sqrt(sum(v * v for v in vals)) if vals else None


def frf_channels(run, frf) -> list:
    """The run's Channel objects in the FRF's response order."""
    by_name = {ch.name: ch for ch in run.channels}
    return [by_name[name] for name in frf.channels]


# the excitation axis that drives each mode best (the paper: vertical run, lateral run)
_PREFERRED_AXIS = {"vertical": 1, "pitch": 1, "roll_low": 0, "yaw": 0}


def _select(all_modes: list[IdentifiedMode], model, warnings: list, run_axes: dict | None = None):
    """One estimate per label; the others are extra or duplicates.

    A label is taken from a run hit along the axis that drives it (vertical
    and pitch: a vertical run; roll_low and yaw: a lateral run) when such a
    run shows it, and among those from the estimate with the smallest relative
    frequency uncertainty.
    """
    chosen: dict[str, IdentifiedMode] = {}
    extras: list[IdentifiedMode] = []
    run_axes = run_axes or {}

    def quality(m):
        axis = _PREFERRED_AXIS.get(m.label)
        off_axis = axis is not None and run_axes.get(m.run) is not None and run_axes[m.run] != axis
        return (off_axis, (m.frequency_std_hz or 0.01 * m.frequency_hz) / m.frequency_hz)

    for m in all_modes:
        if m.label == "extra":
            extras.append(m)
            continue
        if m.label not in chosen or quality(m) < quality(chosen[m.label]):
            chosen[m.label] = m
    # the same physical mode seen in several runs is not an extra mode
    known = [m.frequency_hz for m in chosen.values()]
    unique_extras: list[IdentifiedMode] = []
    for m in sorted(extras, key=quality):
        near = [f for f in known + [e.frequency_hz for e in unique_extras] if abs(f / m.frequency_hz - 1) < 0.01]
        if not near:
            unique_extras.append(m)
    for m in unique_extras:
        warnings.append(f"run '{m.run}': a mode at {m.frequency_hz:.1f} Hz that the model does not predict "
                        f"(not paired with any carriage mode of the model)")
    missing = [lab for lab in model.labels if lab not in chosen and not lab.startswith("support")]
    for lab in missing:
        warnings.append(f"model mode '{lab}' ({model.frequency_hz(lab):.0f} Hz) not observed in any run")
    modes = sorted(chosen.values(), key=lambda m: m.frequency_hz)
    return modes, sorted(unique_extras, key=lambda m: m.frequency_hz), missing


def _quality_warnings(modes, settings, warnings: list) -> None:
    for m in modes:
        if m.label not in JOINT_LABELS.values():
            continue
        if m.coherence < settings.min_coherence:
            warnings.append(f"mode {m.label} at {m.frequency_hz:.1f} Hz: coherence {m.coherence:.3f} at the peak "
                            f"is below {settings.min_coherence}")
        hp = m.half_power
        if hp is None:
            warnings.append(f"mode {m.label}: half-power points not found inside the band")
        elif hp["bins_in_band"] < 3:
            warnings.append(f"mode {m.label}: half-power band spans only {hp['bins_in_band']} bins; "
                            f"the curve-fit damping is the one to trust")


MAX_FORCE_DROP_DB = 20.0  # hammer practice: use the band where the force spectrum is within 20 dB of its peak


def _excitation_warnings(modes, frf_by_run: dict, warnings: list) -> None:
    """Warn when a joint mode lies where the hammer barely excites (e.g. a soft tip's spectral notch)."""
    for m in modes:
        frf = frf_by_run.get(m.run)
        sff = (getattr(frf, "group_sums", None) or {}).get("Sff")
        if m.label not in JOINT_LABELS.values() or sff is None:
            continue
        sff = np.sum(np.asarray(sff, dtype=float), axis=0)
        freq = np.asarray(frf.frequency_hz)
        peak = float(np.max(sff[freq > 0], initial=0.0))
        here = float(sff[int(np.argmin(np.abs(freq - m.frequency_hz)))])
        if peak > 0 and here < peak * 10 ** (-MAX_FORCE_DROP_DB / 10):
            drop = "no" if here <= 0 else f"{-10 * np.log10(here / peak):.0f} dB less"
            warnings.append(f"mode {m.label} at {m.frequency_hz:.1f} Hz: the hammer puts {drop} force there than at "
                            f"its spectral peak (limit {MAX_FORCE_DROP_DB:.0f} dB; a harder tip helps); the frequency "
                            "and damping may be off by more than their std")


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
                          gate=gate, sensor_faults=sensors.faults)


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
    return Identification(str(path), guide, tuple(runs), tuple(modes), params, tuple(warnings),
                          tuple(res.extras), tuple(res.missing), tuple(failed_rows), hits_checked=not from_frfs,
                          modal=res, gate=gate, sensor_faults=check.faults)


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
