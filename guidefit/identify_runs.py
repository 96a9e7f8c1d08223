"""Per-run stage code of :mod:`guidefit.identify`: force levels, narrow-band refits, warnings, and the
per-run diagnostic.

The identify pipeline (:func:`guidefit.identify.identify`) fits one modal
model of all runs; what it takes from here works per run on that model's
modes: the force-level refits (:func:`_force_levels`, each mode refitted in
its narrow band per hit-force bin, :func:`_refit_in_band`) and the quality
and excitation warnings on the joint modes. Every function returns its
warnings (no list is passed in to be changed).

:func:`fit_runs` is a diagnostic beside the pipeline, not a path of it: each
run's FRFs fitted on their own by per-run curve fits (:func:`_fit_run`),
one estimate per label (:func:`_select`) with the delete-a-group jackknife
of the joint modes (:func:`_with_jackknife`), as identify did before the
global fit (``benchmarks/bench_global.py`` compares the two). Nothing here
imports :mod:`guidefit.identify`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from guidefit.errors import IdentificationError
from guidefit.frf.windows import undo_window_damping
from guidefit.io.records import hit_point_of
from guidefit.model.vibration import JOINT_LABELS, UNNAMED_LABELS
from guidefit.modes.labels import sensor_matrix
from guidefit.modes.shapes import (
    IdentifiedMode,
    _coherence_at,
    _half_power_entry,
    energy_shares,
    real_shape,
    rigid_body_motion,
)


@dataclass(frozen=True)
class RunFits:
    """What :func:`fit_runs` gives: one estimate per label, the extra modes, the model modes not seen,
    and the warnings of the fits and the selection."""

    modes: tuple
    extras: tuple
    missing: tuple
    warnings: tuple


def fit_runs(collected, guide, model, settings) -> RunFits:
    """The per-run diagnostic: every run's FRFs fitted on their own, one estimate per label.

    Parameters
    ----------
    collected : sequence of (Run, FrfSet, hit rows)
        The FRF stage's runs (:func:`guidefit.identify.run_frfs`).
    guide, model
        The guide and its nominal modal solution (labels, search band).
    settings : guidefit.identify.IdentifySettings
        Reads the band limits and ``jackknife``.

    Returns
    -------
    RunFits
        Each label from the run hit along the axis that drives it, among
        those the estimate with the smallest relative frequency uncertainty;
        joint modes with the jackknife in their std. No sensor check, gate or
        joint parameters: the result of :func:`guidefit.identify.identify`
        is the global fit's.
    """
    warnings: list[str] = []
    all_modes, frf_by_run, axes = [], {}, {}
    for run, frf, _rows in collected:
        modes, notes = _fit_run(run, frf, guide, model, settings)
        warnings.extend(notes)
        all_modes.extend(modes)
        frf_by_run[run.name] = frf
        axes[run.name] = int(np.argmax(np.abs(run.excitation_direction)))
    modes, extras, missing, notes = _select(all_modes, model, axes)
    if settings.jackknife:
        modes = _with_jackknife(modes, frf_by_run)
    return RunFits(tuple(modes), tuple(extras), tuple(missing), tuple(warnings) + tuple(notes))


def _search_band(model, run, settings) -> tuple[float, float]:
    f_lo = settings.f_min_hz or 0.35 * float(np.min(model.frequencies_hz))
    f_hi = settings.f_max_hz or 1.3 * float(np.max(model.frequencies_hz))
    return f_lo, min(f_hi, 0.4 * run.sample_rate_hz)


def _hit_row(run_name: str, hit) -> dict:
    return {"run": run_name, "hit": int(hit.index), "start_sample": int(hit.start_sample),
            "peak_force_n": float(hit.peak_force_n), "accepted": bool(hit.accepted), "reason": hit.reason}


#: a channel whose largest |FRF| is below this fraction of its run's largest reads nothing (dead)
DEAD_CHANNEL_FRACTION = 1e-9


def dead_channel_warnings(run_name: str, frf) -> list[str]:
    """One warning per response channel of ``frf`` that reads nothing in every accepted hit (its
    FRF zero to :data:`DEAD_CHANNEL_FRACTION` of the run's largest): a dead sensor, an unplugged
    cable or a channel exported empty; its shapes carry no information."""
    size = np.nanmax(np.abs(np.asarray(frf.H)), axis=0) if np.size(frf.H) else np.zeros(0)
    top = float(np.max(size)) if size.size else 0.0
    return [f"run '{run_name}': channel '{name}' reads nothing (zero in every accepted hit): a dead sensor, an "
            "unplugged cable or an empty export; it tells nothing about the modes (leave it out or fix it)"
            for name, v in zip(frf.channels, size) if top > 0 and v <= DEAD_CHANNEL_FRACTION * top]


def _narrow_band(mode) -> tuple[float, float]:
    """A band around one fitted mode: +/- max(3 zeta, 3 %) of its frequency."""
    half_width = max(3 * mode.damping_ratio, 0.03) * mode.frequency_hz
    return mode.frequency_hz - half_width, mode.frequency_hz + half_width


def _refit_one(frf, mode, max_nfev: int = 20, uncertainty: bool = True):
    """Refit one mode in its narrow band, starting from ``mode`` (None when the fit fails)."""
    from guidefit.modes import curvefit

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

    from guidefit import modes as modes_mod
    from guidefit.modes import curvefit

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


def _fit_run(run, frf, guide, model, settings) -> tuple[list[IdentifiedMode], list[str]]:
    """One run's modes by per-run curve fits in the search band, labelled from that run alone, and the
    warnings of the fit (band, resolution, :class:`guidefit.modes.ModeFitWarning`)."""
    from guidefit import modes as modes_mod
    from guidefit.model import vibration as vib
    from guidefit.modes import curvefit

    warnings: list[str] = []
    band = _search_band(model, run, settings)
    if not band[1] > band[0] * 1.05:
        warnings.append(f"run '{run.name}': sample rate {run.sample_rate_hz:g} Hz too low for the modes "
                        f"searched from {band[0]:.0f} Hz (needs at least {band[0] / 0.4:.0f} Hz)")
        return [], warnings
    freq = np.asarray(frf.frequency_hz)
    if np.count_nonzero((freq >= band[0]) & (freq <= band[1])) < MIN_BINS_IN_BAND:
        n = 2 * (len(freq) - 1)
        warnings.append(f"run '{run.name}': records of about {n} samples give {freq[-1] / max(len(freq) - 1, 1):.0f} Hz "
                        f"resolution, too coarse for the modes between {band[0]:.0f} and {band[1]:.0f} Hz "
                        f"(fewer than {MIN_BINS_IN_BAND} bins); longer records are needed")
        return [], warnings
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
        return [], warnings
    fitted = sorted(fitted, key=lambda m: m.frequency_hz)
    sensors = sensor_matrix(frf_channels(run, frf))
    mass = vib.carriage_mass_matrix(vib.model_from_guide(guide))
    candidates = []
    for mode in fitted:
        f_n, zeta = undo_window_damping(mode.frequency_hz, mode.damping_ratio, frf)
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
    from guidefit.modes import labels as lab_mod

    hit = hit_point_of(run)
    view = {run.name: lab_mod.RunView(frf_channels(run, frf), tuple(run.excitation_direction),
                                      None if hit is None else tuple(hit))}
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
            half_power=_half_power_entry(frf, mode), raw_damping_ratio=float(mode.damping_ratio),
            fit=mode, label_basis=dec.basis, label_note=dec.note, label_mac=dec.mac, label_scale=dec.scale,
        ))
    return out, warnings


def _force_levels(run, frf, rows, modes, settings) -> tuple[list[dict], list[str]]:
    """Frequencies of the run's labelled modes per hit-force bin (terciles of the accepted hits), and
    the warning when a bin's FRF cannot be made (then no levels).

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
    from guidefit.frf.windows import window_settings_of
    from guidefit.hits import HitSettings, iter_hits

    accepted = [r for r in rows if r["accepted"]]
    fitted = sorted((m for m in modes if m.label != "extra" and m.fit is not None), key=lambda m: m.frequency_hz)
    run_fits = [(m.fit, m.label) for m in modes if m.fit is not None]  # extra peaks pull a neighbour too
    if not fitted or len(accepted) < 2 * settings.force_bins:
        return [], []
    forces = np.array([r["peak_force_n"] for r in accepted])
    if forces.max() < settings.min_force_ratio * forces.min():
        return [], []
    window = window_settings_of(frf)  # each bin windowed as the run's own FRF (force window and taper, exp window)
    names = [ch.name for ch in frf_channels(run, frf)]
    levels = []
    for level_index, members in enumerate(np.array_split(np.argsort(forces), settings.force_bins)):
        wanted = {accepted[i]["hit"] for i in members}
        hits = (h for h in iter_hits(run, settings.hits or HitSettings()) if h.index in wanted)
        try:
            sub = frf_mod.compute_frf(run, hits, estimator=settings.estimator, window=window,
                                      precision=frf.fft_precision, max_frequency_hz=frf_mod.top_of(frf),
                                      n_fft=frf.n_fft)
        except IdentificationError as exc:
            return [], [f"run '{run.name}': force-level FRF failed ({exc})"]
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
                     "hit_position_m": None if hit_point_of(run) is None
                     else [float(x) for x in hit_point_of(run)],
                     "hit_direction": [float(x) for x in run.excitation_direction]}
            if r is None:  # the mode is not reproduced by this bin's hits: a level without a frequency
                level["refit_failed"] = True
            else:
                f_n, z_n = undo_window_damping(r.frequency_hz, r.damping_ratio, frf)
                level["frequency_hz"], level["frequency_std_hz"] = float(f_n), r.frequency_std_hz
                level["damping_ratio"], level["damping_std"] = float(z_n), r.damping_std
                level["shape"] = dict(zip(names, (float(v) for v in real_shape(r.modal_constants))))
            levels.append(level)
    return levels, []


#: a mode whose softest and hardest force bins differ by more than this fraction (and 3 std) moves with force
AMPLITUDE_SHIFT = 2e-3


def amplitude_dependence(run, result, modes, settings) -> str | None:
    """One line when a run's modes move with its hits' force (amplitude dependence), else None.

    ``result`` is the run's RunResult (its hits and FRF, and its ``force_levels``
    when identify made them), ``modes`` the global modes as this run sees them
    (its own refit of a mode that moves with force may have failed). Its accepted hits' peak forces
    must differ by ``settings.min_force_ratio``; each labelled mode is refitted
    in the softest and the hardest force bin (:func:`_force_levels`) and the
    largest move beyond ``max(3 std, AMPLITUDE_SHIFT f)`` is named with the
    forces. A hammer reversed moves no frequency: this tells the two apart.
    """
    forces = [r["peak_force_n"] for r in result.hits if r.get("accepted")]
    if not modes or len(forces) < 2 or max(forces) < settings.min_force_ratio * min(forces):
        return None
    levels = result.force_levels or _force_levels(run, result.frf, result.hits, modes, settings)[0]
    best = None
    for label in dict.fromkeys(lv["label"] for lv in levels):
        own = sorted((lv for lv in levels if lv["label"] == label), key=lambda lv: lv["level"])
        soft, hard = own[0], own[-1]
        if soft is hard or soft["frequency_hz"] is None or hard["frequency_hz"] is None:
            continue
        shift = hard["frequency_hz"] - soft["frequency_hz"]
        std = math.hypot(soft["frequency_std_hz"] or 0.0, hard["frequency_std_hz"] or 0.0)
        if abs(shift) > max(3.0 * std, AMPLITUDE_SHIFT * soft["frequency_hz"]):
            if best is None or abs(shift) / soft["frequency_hz"] > abs(best[3]) / best[1]["frequency_hz"]:
                best = (label, soft, hard, shift)
    if best is None:
        return None
    label, soft, hard, shift = best
    return (f"run '{result.name}': amplitude dependence: the hits' peak forces range from {min(forces):.0f} to "
            f"{max(forces):.0f} N ({max(forces) / min(forces):.1f}x), and the {label} mode moves from "
            f"{soft['frequency_hz']:.0f} Hz (softest hits, mean {soft['peak_force_n']:.0f} N) to "
            f"{hard['frequency_hz']:.0f} Hz (hardest, mean {hard['peak_force_n']:.0f} N; "
            f"{100 * shift / soft['frequency_hz']:+.1f} %): the carriage's contacts change with the force, so "
            "one linear model does not fit these hits (not a reversed hammer); guidefit explain compares the "
            "force levels (docs/identify.md, 'force levels'), and hits of one force give a linear result")


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


def _select(all_modes: list[IdentifiedMode], model, run_axes: dict | None = None):
    """One estimate per label; the others are extra or duplicates: (modes, extras, missing, warnings).

    A label is taken from a run hit along the axis that drives it (vertical
    and pitch: a vertical run; roll_low and yaw: a lateral run) when such a
    run shows it, and among those from the estimate with the smallest relative
    frequency uncertainty.
    """
    chosen: dict[str, IdentifiedMode] = {}
    extras: list[IdentifiedMode] = []
    warnings: list[str] = []
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
    return modes, sorted(unique_extras, key=lambda m: m.frequency_hz), missing, warnings


def _quality_warnings(modes, settings) -> list[str]:
    """Warnings on the joint modes: coherence at the peak below ``settings.min_coherence``, half-power
    points not found or too few bins between them."""
    warnings = []
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
    return warnings


MAX_FORCE_DROP_DB = 20.0  # hammer practice: use the band where the force spectrum is within 20 dB of its peak


def _excitation_warnings(modes, frf_by_run: dict) -> list[str]:
    """Warnings for joint modes that lie where the hammer barely excites (e.g. a soft tip's spectral notch)."""
    warnings = []
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
    return warnings


#: every labelled mode this many times the model's frequency (or 1/this), all on one side: a time-base error
FREQUENCY_SCALE_WARN = 1.5


def _frequency_scale_warnings(modes, recording) -> list[str]:
    """One warning when every labelled carriage mode (at least two) lies :data:`FREQUENCY_SCALE_WARN` or more
    times above (or below) the model's frequency: a wrong sample rate in a file (a MAT ``fs`` of 100 kHz
    for 200 kHz) scales every frequency alike, K by the square and c by the factor, and nothing else in
    the data shows it (shapes, labels and modal masses come out as on the right rate). A carriage whose
    preload or guide differs from the model moves its modes far less, and not all alike."""
    ratios = [m.frequency_hz / m.model_frequency_hz for m in modes
              if getattr(m, "model_frequency_hz", None) and m.frequency_hz > 0]
    if len(ratios) < 2:
        return []
    low, high = min(ratios), max(ratios)
    if not (low >= FREQUENCY_SCALE_WARN or high <= 1.0 / FREQUENCY_SCALE_WARN):
        return []
    factor = math.exp(float(np.mean(np.log(ratios))))
    rates = sorted({float(r.sample_rate_hz) for r in getattr(recording, "runs", ())})
    said = ", ".join(f"{r:.9g}" for r in rates)
    times = f"{factor:.3g}" if high < 1.02 * low else f"{low:.3g}-{high:.3g}"
    return [f"every mode found is {times} times the model's frequency: a sample rate that is wrong by "
            f"that factor (the recording says {said} Hz; {', '.join(f'{r / factor:.6g}' for r in rates)} Hz would put "
            f"the modes at the model's) scales every frequency alike, K by its square ({factor ** 2:.3g}x) and c "
            "by it; check the DAQ's sample rate, or the guide"]
