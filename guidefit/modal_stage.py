r"""The modal stage of ``identify``: FRFs of every run -> global modes -> shapes -> labels.

:func:`identify_frfs` takes the FRF sets of a recording's runs and the
geometry of their channels (what an FRF file can also provide) and returns
the labelled modes of one modal model with shared poles
(:func:`guidefit.modes.globalfit.global_fit`):

1. **Band.** From the model's range (0.35 x its lowest to 1.3 x its highest
   carriage mode), never above 0.4 x the sample rate, widened to hold the
   data's own resonances next to it (:func:`global_band`: a base mode just
   above the carriage modes, a soft rig's lateral mode below them). The
   hammer's force spectrum does not cut the band (a soft tip's notches are
   warned about per mode instead).
2. **Global fit** of all runs and channels (LSCF stabilisation diagram,
   automatic pole selection, variable-projection refinement, jackknife and
   selection spread in the std).
3. **Shapes across runs.** A mode's modal constants in run ``j`` are
   ``phi(r) phi(e_j)``: the carriage motion ``q`` (u, v, theta, psi, phi) seen
   by the run's sensors (:func:`guidefit.modes.labels.sensor_matrix` ``S_j``),
   scaled by the motion at the hit point ``c_j``. :func:`assemble_motion`
   fits ``m_j = c_j S_j q`` to all runs together (alternating least squares;
   then, when every run's hit point is known, ``c_j = g_j . q`` with
   ``g_j`` the hit direction through the rigid-body map, which fixes the
   relative scale of motions seen by different runs and mass-normalises
   ``q``). Motion the sensors of the exciting runs cannot see is not
   fitted: q is the least-kinetic-energy completion of what they see
   (:func:`observable_basis`); when they see only mixtures of two motions,
   :func:`_resolve_groups` tests each motion's pure form against the
   hit-point residues.
4. **Labels** from the model seen through each run's own sensors and hit
   (:func:`guidefit.modes.labels.label_modes`: shape and frequency evidence, one
   optimal assignment, ``label_basis`` per mode). The assembled motion of
   step 3 is a product (report, mode shapes, sensor check), not the labeller.
   A mode whose label the evidence does not decide is ``ambiguous`` with its
   candidates and is not used for the joint parameters.

Examples
--------
>>> import numpy as np
>>> S1 = np.eye(5)[[1, 2, 4]]            # sensors that see v, theta, phi
>>> S2 = np.eye(5)[[0, 3, 4]]            # sensors that see u, psi, phi
>>> q = np.array([0.3, 0.0, 0.0, 0.0, 0.9])
>>> m = {"a": 2.0 * S1 @ q, "b": -0.5 * S2 @ q}
>>> qa, scale, observed = assemble_motion(m, {"a": S1, "b": S2})
>>> np.round(np.abs(qa) / np.abs(qa).max(), 3)
array([0.333, 0.   , 0.   , 0.   , 1.   ])
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from guidefit.errors import IdentificationError
from guidefit.model.vibration import JOINT_LABELS


@dataclass(frozen=True)
class _DefaultSettings:
    """The options :func:`identify_frfs` reads (those of guidefit.identify.IdentifySettings)."""

    f_min_hz: float | None = None
    f_max_hz: float | None = None
    jackknife: bool = True


@dataclass(frozen=True)
class RunGeometry:
    """What the modal stage needs to know of a run besides its FRFs."""

    name: str
    channels: tuple  # guidefit.io.Channel (name, position_m, direction) in FRF column order
    excitation_direction: tuple
    excitation_position_m: tuple | None = None
    sample_rate_hz: float | None = None


@dataclass(frozen=True)
class ModalResult:
    """Labelled modes of the global fit, plus what the diagnostics need."""

    modes: list  # IdentifiedMode, labelled (joint and other carriage modes)
    extras: list  # IdentifiedMode: unlabelled or ambiguous
    missing: list  # model labels not found
    fit: object  # guidefit.modes.globalfit.GlobalFit
    per_run: dict = field(default_factory=dict)  # run -> [Mode or None per global mode]
    band_hz: tuple = ()
    warnings: tuple = ()  # what the fit and the labeller found, one line each
    #: runs the labeller read at the opposite sign to the model's ("*": the whole recording) while their
    #: driving-point residues are positive (the hammer and accelerometers signed right): the modes do not
    #: fit one linear model of the carriage (identify looks for amplitude dependence: its force levels)
    antiphase_signed_right: tuple = ()


def geometry_of(run, frf) -> RunGeometry:
    """:class:`RunGeometry` of a recording's run, channels in the FRF's order; the hit point is the
    contract's (:func:`hit_point_of`: a file may give it as the force channel's position only)."""
    by_name = {ch.name: ch for ch in run.channels}
    from guidefit.io.records import hit_point_of

    hit = hit_point_of(run)
    return RunGeometry(run.name, tuple(by_name[c] for c in frf.channels), tuple(run.excitation_direction),
                       None if hit is None else tuple(hit), getattr(run, "sample_rate_hz", None))


def global_band(model, frf_by_run: dict, geometry: dict, settings) -> tuple[float, float]:
    """The fitted band: the model's range, cut to what the data can show (see the module docstring)."""
    f_lo = settings.f_min_hz or 0.35 * float(np.min(model.frequencies_hz))
    f_hi = settings.f_max_hz or 1.3 * float(np.max(model.frequencies_hz))
    for name, frf in frf_by_run.items():
        fs = geometry[name].sample_rate_hz if name in geometry else None
        f = np.asarray(frf.frequency_hz)
        f_hi = min(f_hi, 0.4 * fs if fs else 0.8 * float(f[-1]))
    f_lo, f_hi = _widen_to_peaks(frf_by_run, f_lo, f_hi, settings)
    return f_lo, f_hi


#: prominence (dB) of a mode-indicator peak outside the model's range that widens the band to hold it
PEAK_PROMINENCE_DB = 6.0


def _widen_to_peaks(frf_by_run: dict, f_lo: float, f_hi: float, settings) -> tuple[float, float]:
    """Widen the band to hold the data's own resonances next to it (a base mode just above the carriage
    modes, a soft rig's lateral mode below them): up to half ``f_lo`` and twice ``f_hi``, never past
    0.8 x the last bin."""
    from guidefit import modes as modes_mod

    lo_cap, hi_cap = 0.5 * f_lo, 2.0 * f_hi
    for frf in frf_by_run.values():
        f = np.asarray(frf.frequency_hz)
        hi_cap = min(hi_cap, 0.8 * float(f[-1]))
    new_lo, new_hi = f_lo, f_hi
    for frf in frf_by_run.values():
        if settings.f_min_hz is not None and settings.f_max_hz is not None:
            break
        f = np.asarray(frf.frequency_hz)
        sel = np.flatnonzero((f >= lo_cap) & (f <= max(hi_cap, lo_cap * 1.01)))
        if sel.size < 8:
            continue
        step = max(1, sel.size // 2000)  # long records: a coarser grid finds the same resonances
        sel = sel[::step]
        try:
            pk = modes_mod.find_peaks(f[sel], np.asarray(frf.H)[sel], min_prominence_db=PEAK_PROMINENCE_DB,
                                      min_snr_db=20.0)
        except (ValueError, IdentificationError):
            continue
        for fp in pk.frequency_hz:
            if not _excited(frf, float(fp), f_lo, f_hi):
                continue  # a notch of the hammer's force spectrum, not a resonance
            if settings.f_max_hz is None and f_hi < fp <= hi_cap / 1.15:
                new_hi = max(new_hi, 1.15 * float(fp))
            if settings.f_min_hz is None and lo_cap / 0.75 <= fp < f_lo:
                new_lo = min(new_lo, 0.75 * float(fp))
    return new_lo, min(new_hi, hi_cap) if new_hi > f_hi else f_hi


#: a peak where the hammer's force spectrum lies this far below its level in the model's range is not a mode
FORCE_NOTCH_DB = 20.0
#: ... nor one where the mean coherence is below this
PEAK_MIN_COHERENCE = 0.8


def _excited(frf, frequency_hz: float, f_lo: float, f_hi: float) -> bool:
    """Whether the hammer drove the structure at a peak outside the model's range.

    H1 = S_fx / S_ff rises where the force spectrum has a notch (a half-sine
    pulse of T s: the first at 1.5 / T, 12.5 kHz for 0.12 ms) and the
    coherence there is poor: such a peak is the hammer's, and widening the
    band to hold it would only add noisy bins to the fit (validation file
    v2_side: band to 14.4 kHz, f_H std 16 Hz; to 7.2 kHz, 1.1 Hz).
    """
    f = np.asarray(frf.frequency_hz)
    i = int(np.argmin(np.abs(f - frequency_hz)))
    coherence = getattr(frf, "coherence", None)
    if coherence is not None and float(np.mean(np.asarray(coherence)[i])) < PEAK_MIN_COHERENCE:
        return False
    sums = getattr(frf, "group_sums", None) or {}
    if sums.get("Sff") is not None:
        sff = np.asarray(sums["Sff"]).sum(axis=0)
        inside = sff[(f >= f_lo) & (f <= f_hi)]
        if inside.size and float(inside.max()) > 0 and sff[i] < float(inside.max()) * 10 ** (-FORCE_NOTCH_DB / 10):
            return False
    return True


def assemble_motion(constants: dict, sensors: dict, drive: dict | None = None, iterations: int = 20,
                    mass: np.ndarray | None = None):
    """Carriage motion q (5,) behind one mode's modal constants in every run.

    Parameters
    ----------
    constants : dict run -> (R_j,) real modal constants (1/kg)
    sensors : dict run -> (R_j, 5) sensor matrices
    drive : dict run -> (5,) hit-point row (hit direction . rigid-body map), optional
        When given for every run, ``c_j = drive_j . q`` and q is mass-normalised
        (``m_j = (S_j q)(drive_j . q)``); else each run has a free scale.
    mass : (5, 5) carriage mass matrix, optional
        When given, motion that the sensors of the runs exciting the mode cannot
        see (the null space of their stacked sensor matrices) is not fitted: q
        is the least-kinetic-energy motion that reproduces the readings
        (:func:`observable_basis`). Without it a least-squares fit through the
        hit-point rows would give that unseen motion an arbitrary size.

    Returns
    -------
    (q, scale, observed)
        q (5,); the run scales ``c_j``; which DOFs the runs with a non-negligible
        scale observe (bool (5,)).
    """
    runs = [r for r in constants if np.any(constants[r])]
    if not runs:
        return np.zeros(5), {r: 0.0 for r in constants}, np.zeros(5, bool)
    basis = np.eye(5)
    if mass is not None:
        basis = observable_basis(np.vstack([sensors[r] for r in runs]), mass)
    q, scale = _assemble_in(basis, constants, sensors, drive, runs, iterations)
    top_scale = max(abs(s) for s in scale.values()) or 1.0
    seen = [r for r in runs if abs(scale[r]) > 0.05 * top_scale]
    if not seen:  # no run's sensors read any of this motion (e.g. every sensor at one point, along one axis)
        return np.zeros(5), {r: 0.0 for r in constants}, np.zeros(5, bool)
    if mass is not None and len(seen) < len(runs):  # the unseen motion of the runs that excite the mode
        seen_basis = observable_basis(np.vstack([sensors[r] for r in seen]), mass)
        if seen_basis.shape[1] < basis.shape[1]:
            q, scale = _assemble_in(seen_basis, constants, sensors, drive, runs, iterations)
    observed = observed_dofs(np.vstack([sensors[r] for r in seen]))
    return q, {r: scale.get(r, 0.0) for r in constants}, observed


def observed_dofs(S: np.ndarray) -> np.ndarray:
    """bool (5,): the DOFs a sensor matrix determines on their own (no null-space component)."""
    _, s, vt = np.linalg.svd(S)
    null = vt[int(np.sum(s > 1e-8 * s[0])):] if s.size and s[0] > 0 else np.eye(5)
    return np.abs(null).sum(axis=0) < 1e-6 if null.size else np.ones(5, bool)


def null_space(S: np.ndarray) -> np.ndarray:
    """(5, d) orthonormal basis of the carriage motions a sensor matrix does not see."""
    _, s, vt = np.linalg.svd(np.atleast_2d(S), full_matrices=True)
    rank = int(np.sum(s > 1e-8 * s[0])) if s.size and s[0] > 0 else 0
    return vt[rank:].T


def observable_basis(S: np.ndarray, mass: np.ndarray) -> np.ndarray:
    """(5, r) basis of the least-kinetic-energy motions consistent with the readings of ``S``.

    Any motion ``q`` splits into ``q_o + n`` with ``n`` in the null space N of
    ``S``; ``n`` is unseen, and the completion with least kinetic energy
    ``q^T M q`` is the one M-orthogonal to N (``N^T M q = 0``). With every DOF
    seen this is the identity.

    Examples
    --------
    >>> import numpy as np
    >>> S = np.array([[0.0, 1.0, -0.045, 0.0, 0.0]])  # one y sensor at z = 0.045 m: sees v - 0.045 theta
    >>> B = observable_basis(S, np.diag([2.2, 2.2, 3.9e-3, 5.8e-3, 2.5e-3]))
    >>> B.shape
    (5, 1)
    """
    N = null_space(S)
    if N.shape[1] == 0:
        return np.eye(5)
    return null_space(N.T @ mass)


def _assemble_in(basis, constants, sensors, drive, runs, iterations):
    """ALS (then the driven fit) of ``m_j = c_j S_j q`` with ``q = basis @ a``."""
    Sb = {r: sensors[r] @ basis for r in runs}
    top = max(runs, key=lambda r: np.linalg.norm(constants[r]))
    a = np.linalg.lstsq(Sb[top], constants[top], rcond=1e-8)[0]
    scale = {r: 1.0 for r in runs}
    for _ in range(iterations):
        for r in runs:
            y = Sb[r] @ a
            den = float(y @ y)
            # a run whose sensors read only rounding error of this motion has no scale (dividing by
            # that round-off gave it ~1e13 and let it drown the runs that do see the mode)
            floor = (1e-9 * float(np.linalg.norm(Sb[r])) * float(np.linalg.norm(a))) ** 2
            scale[r] = float(y @ constants[r]) / den if den > floor else 0.0
        A = np.vstack([scale[r] * Sb[r] for r in runs])
        b = np.concatenate([constants[r] for r in runs])
        a_new = np.linalg.lstsq(A, b, rcond=1e-8)[0]
        n = np.linalg.norm(a_new)
        if n == 0:
            break
        a_new = a_new / n
        done = np.linalg.norm(a_new - a / (np.linalg.norm(a) or 1.0)) < 1e-10
        a = a_new
        if done:
            break
    if drive and all(r in drive and drive[r] is not None for r in runs):
        db = {r: np.asarray(drive[r]) @ basis for r in runs}
        a = _driven_motion(a, constants, Sb, db, runs)
        scale = {r: float(db[r] @ a) for r in runs}
    return basis @ a, scale


def _driven_motion(q0, constants, sensors, drive, runs):
    """Least squares of m_j = (S_j q)(g_j . q) from the free-scale solution (mass-normalised q).

    With at least as many readings as unknowns: :func:`guidefit.modes.lsq.minimize` with the exact
    Jacobian ``-(S_j (g_j . q) + (S_j q) g_j^T)``; with fewer (a minimiser among many, which the
    path decides) scipy's ``trf`` as it always was.
    """
    def resid(q):
        return np.concatenate([constants[r] - (sensors[r] @ q) * float(np.asarray(drive[r]) @ q) for r in runs])

    def resid_jac(q):
        jac = [-(sensors[r] * float(np.asarray(drive[r]) @ q) + np.outer(sensors[r] @ q, np.asarray(drive[r])))
               for r in runs]
        return resid(q), np.vstack(jac)

    # scale of the unit-norm q0 that best fits the quadratic model
    y = np.concatenate([(sensors[r] @ q0) * float(np.asarray(drive[r]) @ q0) for r in runs])
    b = np.concatenate([constants[r] for r in runs])
    den = float(y @ y)
    if den <= 0 or float(y @ b) <= 0:
        return q0
    start = q0 * math.sqrt(float(y @ b) / den)
    if sum(np.size(constants[r]) for r in runs) >= q0.size:
        from guidefit.modes import lsq

        x = lsq.minimize(*lsq.from_residual(resid_jac), start, tol=1e-13).x
    else:
        import scipy.optimize

        x = scipy.optimize.least_squares(resid, start, method="trf", xtol=1e-12, ftol=1e-12).x
    return x if np.sum(resid(x) ** 2) <= np.sum(resid(start) ** 2) else start


def identify_frfs(frf_by_run: dict, geometry: dict, guide, settings=None, model=None) -> ModalResult:
    """Fit -> shapes -> labels of the modes of all runs together (the modal stage of identify).

    Parameters
    ----------
    frf_by_run : dict of str to guidefit.frf.FrfSet
    geometry : dict of str to RunGeometry
        Channel positions and directions (FRF column order) and the hit of each run.
    guide : guidefit.model.guides.Guide
    settings : guidefit.identify.IdentifySettings, optional
        Reads ``f_min_hz``, ``f_max_hz`` (band limits, None: from model and data) and ``jackknife``.
    model : guidefit.model.vibration.ModalSolution, optional
        The guide's nominal modes (solved from ``guide`` when not given).

    Returns
    -------
    ModalResult
        ``modes`` hold the global estimate of every labelled mode (``run``:
        the run that shows it most; ``estimates``: every run's own f and zeta);
        ``warnings`` what the fit and the labeller found.

    Raises
    ------
    IdentificationError
        When no stable mode is found in the band.
    """
    from guidefit.modes import globalfit

    with globalfit.one_blas_thread():  # small matrices only: see globalfit.one_blas_thread
        return _identify_frfs(frf_by_run, geometry, guide, settings, model)


def _identify_frfs(frf_by_run, geometry, guide, settings, model) -> ModalResult:
    from guidefit.model import vibration as vib
    from guidefit.modes import globalfit
    from guidefit.modes.labels import driving_row, sensor_matrix

    settings = settings or _DefaultSettings()
    spec = vib.model_from_guide(guide)
    model = model or vib.solve_modes(spec)
    band = global_band(model, frf_by_run, geometry, settings)
    _check_band(band, frf_by_run, geometry)
    gf = globalfit.global_fit(frf_by_run, band, jackknife=settings.jackknife)
    excluded = tuple(f"run '{name}': its FRFs are on another frequency grid (FRFs read from a file, or a sample "
                     "rate that is not a whole number of Hz: no common grid by zero padding); left out of the "
                     "global fit" for name in gf.excluded_runs)
    per_run = globalfit.run_estimates(gf, frf_by_run)
    mass = vib.carriage_mass_matrix(spec)
    sensors = {r: sensor_matrix(geometry[r].channels) for r in gf.runs}
    drive = {r: driving_row(geometry[r].excitation_direction, geometry[r].excitation_position_m) for r in gf.runs}
    candidates = [_candidate(gf, k, sensors, drive, mass) for k in range(len(gf.modes))]
    res = _labelled(gf, candidates, per_run, frf_by_run, geometry, model, band, guide.mass_kg)
    return replace(res, warnings=excluded + res.warnings)


#: DOF indices (u, v, theta, psi, phi) of each kinetic-energy group
GROUP_DOFS = {"v": (1,), "theta": (2,), "psi": (3,), "u_phi": (0, 4)}
#: a motion hypothesis whose mass-normalised carriage energy q^T M q exceeds this is impossible (the carriage
#: cannot hold more than the mode's whole kinetic energy; the margin allows for calibration error)
MAX_CARRIAGE_ENERGY = 1.5
#: relative residual of the modal constants a group hypothesis may leave (or twice the full fit's)
HYPOTHESIS_RELRES = 0.15


def groups_separable(N: np.ndarray) -> bool:
    """Whether a null space (5, d) is the sum of its parts within each energy group, i.e. every unseen
    motion lies inside one group and the seen motion decides the group."""
    d = N.shape[1]
    if d == 0:
        return True
    inside = 0
    for dofs in GROUP_DOFS.values():
        other = [i for i in range(5) if i not in dofs]
        inside += d - np.linalg.matrix_rank(N[other, :], tol=1e-8)
    return inside == d


def _relres(q, constants, sensors, drive, runs) -> float:
    num = sum(float(np.sum((constants[r] - (sensors[r] @ q) * float(np.asarray(drive[r]) @ q)) ** 2)) for r in runs)
    den = sum(float(np.sum(constants[r] ** 2)) for r in runs) or 1.0
    return math.sqrt(num / den)


def _resolve_groups(q, observed, scale, constants, sensors, drive, mass):
    """The carriage motion of a mode when the sensors see only mixtures of two groups' DOFs.

    Points A and B alone (same z) read ``v - z theta`` and ``u + z psi``: the
    least-energy motion splits a vertical mode between v and theta. Each
    group's pure motion is then fitted to the modal constants of all runs
    (sensor readings times hit-point motion, mass-normalised); a hypothesis
    that leaves a large residual, or needs more kinetic energy in the carriage
    than the mode has (``q^T M q`` above :data:`MAX_CARRIAGE_ENERGY`), is out.
    Of the rest the one with most carriage energy is taken. The motion is a
    product (mode shapes, the sensor check); the label comes from
    :mod:`guidefit.modes.labels`. Returns ``(q, observed)``.
    """
    runs = [r for r in constants if np.any(constants[r])]
    top = max((abs(s) for s in scale.values()), default=0.0) or 1.0
    seen = [r for r in runs if abs(scale.get(r, 0.0)) > 0.05 * top]
    if not seen:
        return q, observed
    S = np.vstack([sensors[r] for r in seen])
    if groups_separable(null_space(S)):
        return q, observed
    base = _relres(q, constants, sensors, drive, runs)
    fits = []
    for g, dofs in GROUP_DOFS.items():
        if np.linalg.matrix_rank(S[:, dofs], tol=1e-8) < len(dofs):
            continue  # the group's own DOFs are not told apart: no test of it
        qg, _ = _assemble_in(np.eye(5)[:, dofs], constants, sensors, drive, runs, 20)
        rel, energy = _relres(qg, constants, sensors, drive, runs), float(qg @ mass @ qg)
        if rel <= max(HYPOTHESIS_RELRES, 2.0 * base) and energy <= MAX_CARRIAGE_ENERGY:
            fits.append((energy, g, qg))
    if not fits:
        return q, observed
    return max(fits, key=lambda t: t[0])[2], np.ones(5, bool)


def _candidate(gf, k, sensors, drive, mass) -> dict:
    from guidefit.modes.shapes import energy_shares, real_shape

    m = gf.modes[k]
    mc = real_shape(m.modal_constants)  # one phase for all runs
    constants = {r: mc[sl] for r, sl in gf.runs.items()}
    driven = all(d is not None for d in drive.values())
    # the driven fit reaches motion the sensors cannot see through the hit-point rows: keep it to the
    # least-energy completion of what they do see (the non-driven path keeps its per-DOF rules)
    q, scale, observed = assemble_motion(constants, sensors, drive, mass=mass if driven else None)
    if driven:
        q, observed = _resolve_groups(q, observed, scale, constants, sensors, drive, mass)
    norm = np.linalg.norm(q) or 1.0
    qn = q / norm
    amps = {r: float(np.linalg.norm(c)) for r, c in constants.items()}
    primary = max(amps, key=amps.get)
    carriage = float(q @ mass @ q) if driven else None
    return {"k": k, "mode": m, "carriage_energy": carriage, "frequency_hz": m.frequency_hz, "q": qn,
            "energy": energy_shares(qn, mass), "constants": constants, "primary": primary}


#: a run's driving-point residues are told from its sensors when the hit point's row lies in the span of
#: its sensor rows to this relative residual
DRIVE_SPAN_TOLERANCE = 0.05


def driving_point_signs(candidates, views: dict) -> dict:
    """Run -> +1 or -1, the sign of the run's driving-point residues, or None when its sensors cannot tell.

    A mode's modal constants in run j are ``(S_j q)(g_j . q)``; the rigid fit
    ``p = S_j^+ c`` gives ``g_j . p = (g_j . q)^2``, the driving-point
    residue, positive for any mode of a correctly signed test whatever the
    model says. Its sum over the modes (the strongest carry it; a weak mode
    of another run's hammer is noise) is the run's sign: -1 only when the
    hammer's direction, or every accelerometer's, is reversed. None when the
    run's hit point is unknown or its hammer's row is outside what its sensors
    read (:data:`DRIVE_SPAN_TOLERANCE`).
    """
    out = {}
    for name, view in views.items():
        g = view.drive
        if g is None:
            out[name] = None
            continue
        pinv = np.linalg.pinv(view.sensors)
        if np.linalg.norm(g - g @ pinv @ view.sensors) > DRIVE_SPAN_TOLERANCE * np.linalg.norm(g):
            out[name] = None
            continue
        total = sum(float(g @ pinv @ np.asarray(c["constants"][name], float))
                    for c in candidates if name in c["constants"])
        out[name] = None if total == 0 else (1 if total > 0 else -1)
    return out


def _scale_warnings(ev, mass_kg: float, signs: dict | None = None) -> tuple[list[str], tuple]:
    """What the labeller's scales say (:class:`guidefit.modes.labels.Evidence`): the whole recording, or one
    run against the others, off by a unit factor or reversed in sign. K and c do not depend on either.

    A reversed sign is said to be the hammer's (or every accelerometer's) only when the run's
    driving-point residues (``signs``, :func:`driving_point_signs`) do not contradict it; with them
    positive the modes are in antiphase with the model's, not the test: such runs are returned
    too (:attr:`ModalResult.antiphase_signed_right`)."""
    from guidefit.consistency import scale_factor_hint
    from guidefit.modes.labels import COMMON_SCALE_FACTOR

    signs = signs or {}
    reversed_ = "the excitation_direction, or every accelerometer's direction, is reversed"
    signed_right = ("yet the driving-point residues (the hit point's motion along the hammer, from the sensors' "
                    "rigid fit) are positive{}: the hammer and the accelerometers are signed right, and the "
                    "modes do not fit the model's at one sign")
    out, right = [], []
    common = ev.common_scale
    if common < 0:
        unit = f"; and {scale_factor_hint(1 / -common)}" if common != -1.0 else ""
        told = [r for r, v in signs.items() if v is not None]
        if told and all(signs[r] > 0 for r in told):
            right.append("*")
            runs = "" if len(told) == len(signs) else f" in run(s) {', '.join(told)}"
            why = signed_right.format(runs)
        else:
            why = reversed_
        out.append(f"every mode is in antiphase with the model at the hit point (modal constants {common:.3g} "
                   f"times those the model predicts): {why}{unit}; labels were made at the recording's "
                   "own scale and sign")
    elif common != 1.0:
        # constants s times the model's: the data of a body 1/s times the carriage's mass (1000: a prefix, 9.81: g)
        out.append(f"the modal constants are {common:.3g} times those the model predicts for a carriage of "
                   f"{mass_kg:.3g} kg at these sensors ({scale_factor_hint(1 / common)}; labels were made at "
                   "the recording's own scale)")
    for run, factor in ev.run_factors.items():
        parts = [f"its modal constants are {factor:.3g} times the other runs', every mode alike"]
        if factor < 0 and signs.get(run) is not None and signs[run] > 0:
            right.append(run)
            parts.append(f"every mode in antiphase with theirs, {signed_right.format('')}")
        elif factor < 0:
            parts.append(f"every mode in antiphase with theirs: in this run {reversed_}")
        if not 1 / COMMON_SCALE_FACTOR <= abs(factor) <= COMMON_SCALE_FACTOR:
            parts.append(f"{scale_factor_hint(1 / abs(factor))}, in this run's force or accelerometer calibration")
        out.append(f"run '{run}': {'; '.join(parts)}; labels were made with each run at its own scale and sign; "
                   "K and c do not depend on it")
    return out, tuple(right)


def _labelled(gf, candidates, per_run, frf_by_run, geometry, model, band, mass_kg) -> ModalResult:
    """The labelled modes of the global fit (:func:`guidefit.modes.labels.label_modes`), with the labeller's
    warnings (scale and sign, ambiguous, extra, missing) in ``ModalResult.warnings``."""
    from guidefit.modes import labels as lab_mod
    from guidefit.modes import shapes as ident

    views = {r: lab_mod.RunView(geometry[r].channels, geometry[r].excitation_direction,
                                geometry[r].excitation_position_m) for r in gf.runs}
    measured = [lab_mod.Measured(float(c["frequency_hz"]), c["constants"]) for c in candidates]
    predicted = lab_mod.predicted_constants(model, views)
    ev = lab_mod.evidence(measured, views, model, predicted)
    decided = lab_mod.label_modes(measured, views, model, predicted, ev)
    warnings, signed_right = _scale_warnings(ev, mass_kg, driving_point_signs(candidates, views))
    visible = dict(zip(model.labels, lab_mod.visible_modes(predicted)))
    modes, extras = [], []
    for c, dec in zip(candidates, decided):
        k, m, run = c["k"], c["mode"], c["primary"]
        label = dec.label
        amb = list(dec.candidates) if label == "ambiguous" else None
        frf = frf_by_run[run]
        view = gf.run_mode(k, run)
        names = [ch.name for ch in geometry[run].channels]
        estimates = [{"run": r, "level": None, "frequency_hz": float(e.frequency_hz),
                      "damping_ratio": float(e.damping_ratio), "frequency_std_hz": _finite(e.frequency_std_hz),
                      "damping_std": _finite(e.damping_std)}
                     for r, row in per_run.items() if (e := row[k]) is not None]
        parts = gf.std_parts[k]
        entry = ident.IdentifiedMode(
            label=label, run=run, frequency_hz=float(m.frequency_hz),
            damping_ratio=float(m.damping_ratio), frequency_std_hz=_finite(m.frequency_std_hz),
            damping_std=_finite(m.damping_std),
            model_frequency_hz=model.frequency_hz(label) if label in model.labels else None,
            shape=dict(zip(names, (float(v) for v in c["constants"][run]))),
            motion=tuple(float(v) for v in c["q"]), energy={kk: float(v) for kk, v in c["energy"].items()},
            coherence=ident._coherence_at(frf, view.peak_frequency_hz, view.residues),
            half_power=ident._half_power_entry(frf, view),
            raw_damping_ratio=_windowed_damping(m, frf), fit=view,
            estimates=tuple(estimates), candidates=tuple(amb or ()),
            shapes={r: dict(zip([ch.name for ch in geometry[r].channels], (float(v) for v in c["constants"][r])))
                    for r in gf.runs},
            std_parts={kk: {"frequency_hz": _finite(a), "damping_ratio": _finite(b)} for kk, (a, b) in parts.items()},
            global_index=k, carriage_energy=c["carriage_energy"],
            label_basis=dec.basis, label_note=dec.note, label_mac=dec.mac, label_scale=dec.scale,
        )
        if amb:
            text = " or ".join(f"{lab} ({share:.0%})" for lab, share in amb)
            warnings.append(f"mode at {m.frequency_hz:.1f} Hz: label ambiguous: {text} ({dec.note}); "
                            "not used for joint parameters")
            extras.append(entry)
        elif label == "extra":
            warnings.append(f"mode at {m.frequency_hz:.1f} Hz (strongest in run '{run}'): the model does not "
                            f"predict it ({dec.note})")
            extras.append(entry)
        else:
            if dec.basis == "frequency" and label in JOINT_LABELS.values():
                warnings.append(f"mode {label} at {m.frequency_hz:.1f} Hz: its label rests on its frequency alone "
                                f"({dec.note}); guidefit plan shows which layout decides it by shape")
            modes.append(entry)
    found = {m.label for m in modes}
    missing = [lab for lab in model.labels if lab not in found and not lab.startswith("support")]
    told = _candidate_labels(extras)
    for lab in missing:
        if lab in told:
            warnings.append(f"model mode '{lab}' ({model.frequency_hz(lab):.0f} Hz) not told apart: a candidate of "
                            f"the ambiguous mode(s) at {', '.join(f'{f:.0f}' for f in told[lab])} Hz")
        elif not visible.get(lab, True):
            warnings.append(f"model mode '{lab}' ({model.frequency_hz(lab):.0f} Hz) cannot be seen on this layout: "
                            "no run both excites it at its hit point and reads it at its sensors")
        else:
            warnings.append(f"model mode '{lab}' ({model.frequency_hz(lab):.0f} Hz) not observed in any run")
    missing = [lab for lab in missing if lab not in told]
    return ModalResult(sorted(modes, key=lambda m: m.frequency_hz), sorted(extras, key=lambda m: m.frequency_hz),
                       missing, gf, per_run, band, tuple(warnings), antiphase_signed_right=signed_right)


def _candidate_labels(extras) -> dict:
    """label -> frequencies of the ambiguous modes that name it as a candidate (found, but not told apart:
    not missing). A candidate "roll" names both roll modes; "vertical at 3529 Hz" names vertical."""
    told: dict = {}
    for m in extras:
        if m.label != "ambiguous":
            continue
        for cand, _ in m.candidates:
            word = str(cand).split()[0]
            for lab in (("roll_low", "roll_high") if word == "roll" else (word,)):
                if m.frequency_hz not in told.setdefault(lab, []):
                    told[lab].append(m.frequency_hz)
    return told


#: fewer FRF bins than this in the band: no mode fit is attempted
MIN_BINS_IN_BAND = 16


def _check_band(band, frf_by_run: dict, geometry: dict) -> None:
    """One clear line when the band cannot hold a fit: sample rate too low or records too short."""
    rates = [g.sample_rate_hz for g in geometry.values() if g.sample_rate_hz]
    if not band[1] > band[0] * 1.05:
        need = f" (needs at least {band[0] / 0.4:.0f} Hz)" if rates else ""
        raise IdentificationError(f"sample rate {min(rates, default=float('nan')):g} Hz too low or the hammer's force "
                                  f"spectrum too narrow for the modes searched from {band[0]:.0f} Hz{need}")
    frf = max(frf_by_run.values(), key=lambda x: np.count_nonzero((x.frequency_hz >= band[0])
                                                                  & (x.frequency_hz <= band[1])))
    freq = np.asarray(frf.frequency_hz)
    if np.count_nonzero((freq >= band[0]) & (freq <= band[1])) < MIN_BINS_IN_BAND:
        fs = getattr(frf, "sample_rate_hz", None)  # FRFs may end below the Nyquist frequency
        n = round(fs / float(freq[1] - freq[0])) if fs and len(freq) > 1 else 2 * (len(freq) - 1)
        raise IdentificationError(f"records of about {n} samples give {freq[-1] / max(len(freq) - 1, 1):.0f} Hz "
                                  f"resolution, too coarse for the modes between {band[0]:.0f} and {band[1]:.0f} Hz "
                                  f"(fewer than {MIN_BINS_IN_BAND} bins); longer records are needed")


def _finite(v):
    return float(v) if v is not None and math.isfinite(v) else None


def _windowed_damping(mode, frf) -> float:
    """The damping ratio the windowed FRF shows (before the exponential-window correction)."""
    tau = getattr(frf, "exp_window_tau_s", None)
    if not tau:
        return float(mode.damping_ratio)
    p = mode.pole - 1.0 / tau
    return float(-p.real / abs(p))
