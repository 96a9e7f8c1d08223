r"""The one labeller: measured modes named by the model seen through the test's own sensors.

A hammer test does not see the carriage's motion; it sees modal constants
``A_r = phi(r) phi(e)`` at its sensors ``r`` for its hit point ``e``. For
each run ``j`` and each mode ``i`` of the vibration model (Eq. 5-23,
mass-normalised shape ``phi_i`` over u, v, theta, psi, phi) the test would
read

.. math::  r_{ij} = (S_j \phi_i)\,(g_j \cdot \phi_i)

with ``S_j`` the run's sensor matrix (:func:`sensor_matrix`) and ``g_j`` the
hammer's row (:func:`driving_row`). A measured mode ``k`` with real modal
constants ``m_kj`` is compared with each ``r_i`` on the channels the runs
have, all runs stacked, sign included:

* **shape**: ``rho = 1 - MAC`` of ``m_k`` against ``a r_i`` with one scale
  ``a`` for every run whose hit point is known (a run without one gets its
  own scale: its participation is unknown), and the scale ``a`` itself (the
  driving-point residue: the carriage's share of the mode, 1 for a carriage
  mode on a well-scaled recording; a recording off by a unit factor is
  measured against its own common scale), negative ``a`` penalised. A rig
  effect mixes the modes of one motion group (:func:`motion_groups`: the
  roll pair turns in the u-phi plane), so ``r_i`` is the best motion of
  mode ``i``'s group, with a prior on the mixing angle
  (:data:`MIXING_ANGLE_STD`) and the cost profiled over it;
* **frequency**: ``ln(f_k / f_i)`` with a prior std of :data:`FREQUENCY_LOG_STD`
  (wide enough for a soft rig that moves f_H by more than 50 %).

The costs (negative log-likelihoods, up to constants) are added and one
assignment of measured modes to model modes is solved over all of them at
once (:func:`best_assignment`, exact); a measured mode may stay ``extra``
(:func:`extra_costs`: more, the more of it is carriage motion) and a model
mode may stay unmatched. A label is
**decided** when every assignment that takes it away costs at least
:data:`DECIDE_MARGIN` more; ``label_basis`` says what decides it:
``"shape"``, ``"frequency"`` or ``"shape+frequency"`` (both, or only the two
together). A mode is ``ambiguous`` only when the combined evidence does not
decide it; model modes no run excites and observes are not offered
(:func:`visible_modes`), and :func:`layout_view` tells before a test which
labels a layout can decide by shape (``guidefit plan``).

Examples
--------
>>> import numpy as np
>>> from guidefit.model import vibration as vib
>>> from guidefit.model.guides import load_guide
>>> model = vib.solve_modes(vib.model_from_guide(load_guide("MRB35")))
>>> ys = tuple(Sensor(f"acc_{p}_y", xyz, (0.0, 1.0, 0.0)) for p, xyz in
...            (("A", (0.03, 0, 0.045)), ("B", (-0.03, 0, 0.045)), ("C", (-0.03, 0, -0.045)),
...             ("D", (0.03, 0, -0.045))))
>>> runs = {"vertical": RunView(ys, (0.0, -1.0, 0.0), (-0.01, 0.0, -0.025))}
>>> pred = predicted_constants(model, runs)
>>> i = model.labels.index("vertical")
>>> measured = [Measured(model.frequencies_hz[i] * 1.01, {"vertical": pred[i]["vertical"]})]
>>> [(lab.label, lab.basis) for lab in label_modes(measured, runs, model)]
[('vertical', 'shape')]
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

#: prior std of ln(f_measured / f_model): a soft rig or a large added mass moves a mode by tens of percent
FREQUENCY_LOG_STD = 0.4
#: scale of 1 - MAC in the shape cost: a carriage mode distorted by a rig effect keeps 1 - MAC below ~0.1
SHAPE_RHO_SCALE = 0.05
#: prior std of ln(a / common scale) of the driving-point residue
AMPLITUDE_LOG_STD = math.log(2.0)
#: cost of a negative scale (measured mode in antiphase with the model mode at the hit point)
SIGN_COST = 3.0
#: cost of leaving a measured mode unlabelled (``extra``) ...
EXTRA_COST = 8.0
#: ... plus this much per unit of its carriage share (:func:`extra_costs`)
EXTRA_SHARE_COST = 8.0
#: a label is decided when every assignment without it costs this much more (likelihood ratio e^2)
DECIDE_MARGIN = 2.0
#: a model mode whose predicted readings are below this fraction of the largest is not offered
VISIBLE_FRACTION = 1e-3
#: the common scale is taken from measured modes whose best MAC is at least this
SCALE_MAC = 0.8
#: ... and used only when it is off by more than this factor (a unit error, not physics or calibration)
COMMON_SCALE_FACTOR = 3.0
#: prior std (rad) of the mixing angle of a two-mode group (the roll pair) away from the model's
MIXING_ANGLE_STD = 0.35



# --------------------------------------------------------------------------- the layout


@dataclass(frozen=True)
class Sensor:
    """An accelerometer: channel name, position (m, carriage frame) and unit direction."""

    name: str
    position_m: tuple
    direction: tuple


def sensor_matrix(channels) -> np.ndarray:
    """(n_channels, 5): each sensor's reading per unit carriage motion (u, v, theta, psi, phi).

    The one sensor matrix of guidefit: a channel along unit ``d`` at ``p``
    reads ``d . T(p) q`` (:func:`guidefit.model.vibration.rigid_body_map`).

    >>> sensor_matrix([Sensor("acc_A_x", (0.03, 0.0, 0.045), (1.0, 0.0, 0.0))]).round(3)
    array([[1.   , 0.   , 0.   , 0.045, 0.   ]])
    """
    from guidefit.model.vibration import rigid_body_map

    rows = [np.asarray(ch.direction, float) @ rigid_body_map(ch.position_m) for ch in channels]
    return np.array(rows, float).reshape(len(rows), 5)


def driving_row(direction, position_m) -> np.ndarray | None:
    """The hammer's row g (5,): its direction through the rigid-body map at the hit point; None when
    the hit point is unknown (its participation is then not known either)."""
    from guidefit.model.vibration import rigid_body_map

    if position_m is None:
        return None
    return np.asarray(direction, float) @ rigid_body_map(np.asarray(position_m, float))


@dataclass(frozen=True)
class RunView:
    """What the labeller needs of a run: its channels (in modal-constant order) and its hit."""

    channels: tuple  # objects with position_m and direction (guidefit.io.Channel)
    excitation_direction: tuple
    excitation_position_m: tuple | None = None

    @property
    def sensors(self) -> np.ndarray:
        return sensor_matrix(self.channels)

    @property
    def drive(self) -> np.ndarray | None:
        return driving_row(self.excitation_direction, self.excitation_position_m)


def predicted_constants(model, runs: dict) -> list[dict]:
    """Per model mode, run -> the modal constants (1/kg) the run's sensors would read for it.

    ``r_ij = (S_j phi_i)(g_j . phi_i)``; for a run without a known hit point the
    participation is taken as the largest ``|d . T(p) phi_i|`` over the run's own
    sensor positions (a hammer hits near its sensors): a guess of the size only,
    its scale is fitted freely (:func:`evidence`).
    """
    from guidefit.model.vibration import rigid_body_map

    phi = np.asarray(model.shapes)[:5]
    out = []
    for i in range(phi.shape[1]):
        entry = {}
        for name, run in runs.items():
            reading = run.sensors @ phi[:, i]
            g = run.drive
            if g is None:
                d = np.asarray(run.excitation_direction, float)
                part = max((abs(float(d @ rigid_body_map(ch.position_m) @ phi[:, i])) for ch in run.channels),
                           default=0.0)
            else:
                part = float(g @ phi[:, i])
            entry[name] = reading * part
        out.append(entry)
    return out


def visible_modes(predicted: list[dict]) -> np.ndarray:
    """bool per model mode: its predicted readings reach :data:`VISIBLE_FRACTION` of the largest mode's
    (a mode no run both excites and observes cannot be found, so it is not offered as a label)."""
    size = np.array([math.sqrt(sum(float(v @ v) for v in p.values())) for p in predicted])
    top = float(size.max()) if size.size else 0.0
    return size > VISIBLE_FRACTION * top if top > 0 else np.zeros(size.shape, bool)


# --------------------------------------------------------------------------- the evidence


@dataclass(frozen=True)
class Measured:
    """A measured mode: natural frequency (Hz) and its real modal constants per run (1/kg)."""

    frequency_hz: float
    constants: dict  # run -> (R_j,) real


def motion_groups(model) -> list[list[int]]:
    """The model's modes grouped by the motion that dominates them (v, theta, psi, u-phi): a rig effect
    (a soft lateral support, a mass at a corner) mixes the modes of one group (the roll pair turns in the
    u-phi plane) far more than it mixes groups."""
    energy = np.asarray(model.energy_fractions)[:, :4]
    dominant = np.argmax(energy, axis=1)
    return [list(np.flatnonzero(dominant == g)) for g in range(4) if np.any(dominant == g)]


#: grid of mixing angles (rad) in a two-mode group
_ANGLES = np.linspace(0.0, math.pi, 181)[:-1]


def _readings(runs: dict, names, phi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Predicted modal constants of motions ``phi`` (5, T), stacked over runs (T, R), and the run index of
    each reading (-1: hit point known; else the run's number, whose scale is free)."""
    cols, owner = [], []
    for n, name in enumerate(names):
        run = runs[name]
        S = run.sensors
        reading = phi.T @ S.T  # (T, R_j)
        g = run.drive
        if g is None:
            d = np.asarray(run.excitation_direction, float)
            from guidefit.model.vibration import rigid_body_map

            parts = np.array([d @ rigid_body_map(ch.position_m) @ phi for ch in run.channels]).reshape(-1, phi.shape[1])
            part = np.abs(parts).max(axis=0) if parts.size else np.zeros(phi.shape[1])
            owner += [n] * S.shape[0]
        else:
            part = g @ phi
            owner += [-1] * S.shape[0]
        cols.append(reading * part[:, None])
    R = np.hstack(cols) if cols else np.zeros((phi.shape[1], 0))
    top = float(np.abs(R).max()) if R.size else 0.0
    R[np.abs(R) <= 1e-9 * top] = 0.0  # rounding, not a reading (a free run scale would make it any shape)
    return R, np.array(owner, int)


def _profile(m: np.ndarray, R: np.ndarray, owner: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each row of R (T, n) the unexplained share of ``m`` (n,) after the best scale(s), and the common
    scale of the known-hit readings (nan where there are none)."""
    total = float(m @ m)
    known = owner < 0
    explained = np.zeros(R.shape[0])
    scale = np.full(R.shape[0], np.nan)
    if np.any(known):
        mr, rr = R[:, known] @ m[known], np.einsum("ij,ij->i", R[:, known], R[:, known])
        ok = rr > 0
        explained[ok] += mr[ok] ** 2 / rr[ok]
        scale[ok] = mr[ok] / rr[ok]
    for n in np.unique(owner[~known]):
        sel = owner == n
        mr, rr = R[:, sel] @ m[sel], np.einsum("ij,ij->i", R[:, sel], R[:, sel])
        ok = rr > 0
        explained[ok] += mr[ok] ** 2 / rr[ok]
    rho = np.clip(1.0 - explained / total, 0.0, 1.0) if total > 0 else np.ones(R.shape[0])
    return rho, scale


@dataclass(frozen=True)
class Evidence:
    """Cost matrices (measured x model mode) of the shape and the frequency, and what they came from."""

    rho: np.ndarray  # 1 - MAC with the best motion of the model mode's group
    scale: np.ndarray  # modal scale s^2 (carriage share of the mode) relative to the common scale (nan: unknown)
    shape: np.ndarray  # shape cost (rho, mixing angle, scale, sign), profiled over the group's mixing angle
    frequency: np.ndarray  # frequency cost
    visible: np.ndarray  # bool per model mode
    common_scale: float  # the recording's scale against the model's mass-normalised modes (1: as predicted)
    run_factors: dict = field(default_factory=dict)  # run -> its scale against the others' (off by > 3x or reversed)

    @property
    def combined(self) -> np.ndarray:
        return self.shape + self.frequency


def _amplitude_cost(scale: np.ndarray) -> np.ndarray:
    """Prior on the modal scale s^2 (1: all the mode's kinetic energy in the carriage), sign included."""
    with np.errstate(divide="ignore", invalid="ignore"):
        cost = np.log(np.abs(scale)) ** 2 / (2 * AMPLITUDE_LOG_STD**2)
    cost = np.where(np.isfinite(scale) & (scale == 0), EXTRA_COST, cost)
    cost = np.where(np.isfinite(scale), cost, 0.0)
    return cost + np.where(np.isfinite(scale) & (scale < 0), SIGN_COST, 0.0)


def evidence(measured: list[Measured], runs: dict, model, predicted: list[dict] | None = None) -> Evidence:
    """The shape and frequency costs of every measured mode against every model mode.

    The shape of model mode ``i`` is tested as the best motion of its group
    (:func:`motion_groups`): for a two-mode group (the roll pair) the motion
    ``cos t phi_a + sin t phi_b`` over every mixing angle ``t``, with a prior
    of :data:`MIXING_ANGLE_STD` on the angle away from mode ``i``'s own; the
    cost is profiled over ``t`` (a layout that cannot see the mix leaves both
    labels of the pair equally likely by shape).
    """
    predicted = predicted if predicted is not None else predicted_constants(model, runs)
    names = list(runs)
    n, n_model = len(measured), len(predicted)
    phi = np.asarray(model.shapes)[:5]
    run_factors = _run_factors(measured, runs, phi, np.asarray(model.frequencies_hz, float)[:phi.shape[1]])
    if run_factors:  # each run at its own scale: one run's force or sensitivities off by a unit factor
        measured = [Measured(x.frequency_hz, {r: np.asarray(c, float) / run_factors.get(r, 1.0)
                                              for r, c in x.constants.items()}) for x in measured]
    stacked = [np.concatenate([np.asarray(x.constants.get(r, np.zeros(len(runs[r].channels))), float)
                               for r in names]) for x in measured]
    rho = np.ones((n, n_model))
    raw = np.full((n, n_model), np.nan)
    angle_cost = np.zeros((n, n_model))
    fits = {}  # (k, i) -> (rho over angles, scale over angles, angle prior cost over angles)
    for group in motion_groups(model):
        if len(group) == 2:
            a, b = group
            basis = np.outer(phi[:, a], np.cos(_ANGLES)) + np.outer(phi[:, b], np.sin(_ANGLES))
            own = {a: np.minimum(_ANGLES, math.pi - _ANGLES), b: np.abs(_ANGLES - math.pi / 2)}
        else:  # one mode (or a group too large to scan): each mode its own motion
            basis, own = None, None
        for i in group:
            B = phi[:, [i]] if basis is None else basis
            R, owner = _readings(runs, names, B)
            prior = np.zeros(B.shape[1]) if own is None else own[i] ** 2 / (2 * MIXING_ANGLE_STD**2)
            for k in range(n):
                r, sc = _profile(stacked[k], R, owner)
                fits[k, i] = (r, sc, prior)
    # the recording's common scale: a force or sensitivity off by a unit factor scales every mode alike
    for (k, i), (r, sc, prior) in fits.items():
        j = int(np.argmin(r / SHAPE_RHO_SCALE + prior))
        rho[k, i], raw[k, i] = r[j], sc[j]
    best = [(_best_model_mode(rho[k], measured[k].frequency_hz, model), k) for k in range(n)] if n_model else []
    good = [raw[k, i] for i, k in best if 1.0 - rho[k, i] >= SCALE_MAC and np.isfinite(raw[k, i])]
    common = float(np.median(good)) if len(good) >= 2 else (float(good[0]) if good else 1.0)
    if not (abs(common) > 0 and abs(math.log(abs(common))) > math.log(COMMON_SCALE_FACTOR)):
        common = math.copysign(1.0, common) if common else 1.0  # within a calibration error: the physics'
    shape_cost = np.zeros((n, n_model))
    for (k, i), (r, sc, prior) in fits.items():
        total = r / SHAPE_RHO_SCALE + prior + _amplitude_cost(sc / common)
        j = int(np.argmin(total))
        shape_cost[k, i], rho[k, i], raw[k, i], angle_cost[k, i] = total[j], r[j], sc[j], prior[j]
    f_meas = np.array([x.frequency_hz for x in measured], float).reshape(-1, 1)
    f_model = np.asarray(model.frequencies_hz, float).reshape(1, -1)
    freq_cost = np.log(f_meas / f_model) ** 2 / (2 * FREQUENCY_LOG_STD**2)
    return Evidence(rho, raw / common, shape_cost, freq_cost, visible_modes(predicted), common, run_factors)


def _best_model_mode(rho_k: np.ndarray, frequency_hz: float, model) -> int:
    """The model mode whose shape fits a measured mode best; of those within :data:`SCALE_MAC_TIE` of the best
    (one sensor: every MAC is 1, the order decided by rounding), the nearest in frequency."""
    i = int(np.argmin(rho_k))
    tied = np.flatnonzero(rho_k <= rho_k[i] + SCALE_MAC_TIE)
    if tied.size > 1:
        f_model = np.asarray(model.frequencies_hz, float)[: rho_k.size]
        i = int(tied[np.argmin(np.abs(np.log(f_model[tied] / frequency_hz)))])
    return i


#: a mode whose modal constants in a run are below this fraction of the run's strongest has no say in its scale
SCALE_STRONG = 0.1
#: model modes whose MAC with a measured mode is this close to the best are told apart by frequency
SCALE_MAC_TIE = 0.02


def predicted_readings(run, phi: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(R, rr, seen)``: each model mode's predicted modal constants in ``run`` (its sensors and hammer
    row ``run.drive``, not None), (model modes, channels), rounding residues set to 0; their squared
    norms; and which model modes the run's hit and sensors show at all."""
    R = (phi.T @ run.sensors.T) * (run.drive @ phi)[:, None]
    R[np.abs(R) <= 1e-9 * float(np.abs(R).max(initial=0.0))] = 0.0  # rounding, not a reading
    rr = np.einsum("ij,ij->i", R, R)
    return R, rr, rr > 1e-6 * float(rr.max(initial=0.0))


def mac_with_model(constants: np.ndarray, R: np.ndarray, rr: np.ndarray, seen: np.ndarray) -> np.ndarray:
    """MAC of a measured mode's modal constants (channels,) with each model mode's predicted ones
    (:func:`predicted_readings`); 0 for the model modes the run does not show."""
    mm = float(constants @ constants)
    return np.where(seen, (R @ constants) ** 2 / (np.where(seen, rr, 1.0) * mm), 0.0)


def run_scale(constants: list, run, phi: np.ndarray, freqs=None, model_freqs=None) -> float | None:
    """The median scale of a run's well-fitting modes (MAC >= :data:`SCALE_MAC` with a model mode through
    the run's own sensors and hit, modal constants at least :data:`SCALE_STRONG` of the run's strongest)
    against the model's predicted constants; None when it has none.

    A mode the run's hammer does not excite still has constants in it (the shared poles of the global
    fit give every run every mode): noise, 1000x below the run's own modes, which can fit a one-mode
    pattern by chance; before this floor such modes outvoted a run's one real mode (a vertical hit at
    the top centre excites only the vertical mode: its run's scale came out 0.0002)."""
    if run.drive is None:
        return None
    R, rr, seen = predicted_readings(run, phi)
    values = []
    top = max((float(m @ m) for m in constants), default=0.0)
    for j, m in enumerate(constants):
        mm = float(m @ m)
        if mm <= 0 or not np.any(seen) or mm < SCALE_STRONG**2 * top:
            continue  # a mode this run barely shows (noise through shared poles) has no say in its scale
        mr = R @ m
        mac = mac_with_model(m, R, rr, seen)
        i = int(np.argmax(mac))
        tied = np.flatnonzero(mac >= mac[i] - SCALE_MAC_TIE)
        if tied.size > 1 and freqs is not None and model_freqs is not None:  # one sensor: every MAC is 1
            i = int(tied[np.argmin(np.abs(np.log(np.asarray(model_freqs, float)[tied] / freqs[j])))])
        if mac[i] >= SCALE_MAC:
            values.append(mr[i] / rr[i])
    return float(np.median(values)) if values else None


def _run_factors(measured: list[Measured], runs: dict, phi: np.ndarray, model_freqs=None) -> dict:
    """Runs whose modal constants are more than :data:`COMMON_SCALE_FACTOR` times the others', or of the
    opposite sign (a force or sensitivity calibration of one run off by a unit factor, or its hammer or
    every accelerometer reversed: every mode of the run scaled alike), as {run: factor against the run
    nearest the model's scale}; {} when the runs agree (or only one has a scale).

    Each run's scale is the median over its well-fitting modes of the driving-point scale against the model
    through its own sensors (:func:`run_scale`); without this a run 1000 times the others would make the
    modes it does not see look 1000 times too weak to be the carriage's.
    """
    scales = {}
    for name, run in runs.items():
        mine = [x for x in measured if name in x.constants]
        constants = [np.asarray(x.constants[name], float) for x in mine]
        freqs = np.array([float(x.frequency_hz) for x in mine])
        scale = run_scale(constants, run, phi, freqs, model_freqs)
        if scale is not None and scale != 0:
            scales[name] = scale
    if len(scales) < 2:
        return {}
    # the reference: the run nearest the model's scale, among those of the model's sign if any
    positive = [v for v in scales.values() if v > 0] or list(scales.values())
    reference = min(positive, key=lambda v: abs(math.log(abs(v))))
    return {name: v / reference for name, v in scales.items()
            if v / reference < 0 or abs(math.log(v / reference)) > math.log(COMMON_SCALE_FACTOR)}


def extra_costs(ev: Evidence) -> np.ndarray:
    """The cost of calling each measured mode ``extra`` (another body's mode, not one of the carriage).

    :data:`EXTRA_COST`, plus :data:`EXTRA_SHARE_COST` per unit of the carriage
    share ``s^2`` of its best-fitting carriage motion: another body's mode moves
    the carriage little, so of two modes with the carriage's vertical motion (a
    heavy base splits the vertical mode in two) the one carrying more of it is
    the carriage mode (the contract's "v-dominated" mode).
    """
    n = ev.rho.shape[0]
    out = np.full(n, EXTRA_COST)
    if ev.rho.shape[1] == 0:
        return out
    for k in range(n):
        fits = ev.visible & (ev.rho[k] < 0.2) & np.isfinite(ev.scale[k])
        if np.any(fits):  # the most carriage-like reading (a layout may not tell a group's modes apart)
            out[k] += EXTRA_SHARE_COST * float(np.clip(np.max(ev.scale[k][fits]), 0.0, 1.0))
    return out


# --------------------------------------------------------------------------- the assignment


def best_assignment(cost: np.ndarray, extra_cost, require: tuple = ()) -> tuple[float, list]:
    """The cheapest assignment of rows (measured modes) to distinct columns (model modes) or to none.

    ``cost`` (n, m) with ``inf`` for a forbidden pair; ``extra_cost`` (n,) the
    cost of row k taking no column (``inf``: it must take one). Returns the
    total and each row's column (None: extra); ``(inf, [])`` when none is
    possible. Columns in ``require`` must be taken. Exact, by dynamic programming over the set of columns used
    (m <= 12, a carriage has five modes): written here rather than calling
    :func:`scipy.optimize.linear_sum_assignment` because rows may stay
    unassigned at their own cost, and so that identify does not import
    :mod:`scipy.optimize` (0.2-0.6 s of every run).

    >>> best_assignment(np.array([[1.0, 5.0], [2.0, 1.0]]), np.array([9.0, 9.0]))
    (2.0, [0, 1])
    >>> best_assignment(np.array([[1.0, 5.0], [2.0, 9.0]]), np.array([9.0, 0.5]))
    (1.5, [0, None])
    """
    cost = np.asarray(cost, float)
    n, m = cost.shape
    extra = np.broadcast_to(np.asarray(extra_cost, float), (n,))
    if m > 12:
        raise ValueError(f"best_assignment: {m} columns; at most 12 (the DP is over subsets of columns)")
    size = 1 << m
    dp = np.full(size, np.inf)
    dp[0] = 0.0
    masks = np.arange(size)
    choice = np.zeros((n, size), int)  # -1: extra, else the column taken
    for k in range(n):
        new = dp + extra[k]
        pick = np.full(size, -1)
        for i in range(m):
            if not np.isfinite(cost[k, i]):
                continue
            bit = 1 << i
            has = (masks & bit) != 0
            cand = np.full(size, np.inf)
            cand[has] = dp[masks[has] ^ bit] + cost[k, i]
            better = cand < new
            new[better] = cand[better]
            pick[better] = i
        dp, choice[k] = new, pick
    if require:
        need = sum(1 << int(i) for i in require)
        dp = np.where((masks & need) == need, dp, np.inf)
    end = int(np.argmin(dp))
    total = float(dp[end])
    if not np.isfinite(total):
        return math.inf, []
    out: list = [None] * n
    mask = end
    for k in range(n - 1, -1, -1):
        i = int(choice[k, mask])
        if i >= 0:
            out[k] = i
            mask ^= 1 << i
    return total, out


def _total(cost: np.ndarray, extra: np.ndarray, assignment: list) -> float:
    return float(sum(extra[k] if i is None else cost[k, i] for k, i in enumerate(assignment)))


def _margin(cost: np.ndarray, extra: np.ndarray, assignment: list, k: int, allow_extra: bool):
    """(how much more the best assignment costs in which row k takes another column, that assignment).

    With ``allow_extra`` row k may also stay extra, but then another row must
    take its column: "this mode is not a carriage mode" alone (k extra, its
    label unmatched) is not another label.
    """
    i = assignment[k]
    c = cost.copy()
    c[k, i] = np.inf
    e = extra.copy()
    e[k] = np.inf
    total, alt = best_assignment(c, e)
    if allow_extra:
        c2 = cost.copy()
        c2[k, :] = np.inf
        total2, alt2 = best_assignment(c2, extra, require=(i,))
        if alt2 and total2 < total:
            total, alt = total2, alt2
    if not alt:
        return math.inf, None
    return total - _total(cost, extra, assignment), alt


# --------------------------------------------------------------------------- the labels


@dataclass(frozen=True)
class Label:
    """The label of one measured mode and what decided it."""

    label: str  # a model label, "extra" or "ambiguous"
    basis: str | None  # "shape", "frequency", "shape+frequency"; None for extra
    model_label: str | None  # the best model label (also for an ambiguous mode)
    mac: float | None  # MAC with the chosen model mode's predicted readings
    scale: float | None  # driving-point scale a (relative to the recording's common scale)
    margin: float  # cost margin of the decision (inf: no alternative)
    candidates: tuple = ()  # ambiguous: ((label or "label at F Hz", probability), ...)
    note: str = ""  # one plain sentence
    shape_margin: float = math.nan  # what the shape alone would lose by another label (>= DECIDE_MARGIN: decides)
    frequency_margin: float = math.nan  # the same for the frequency alone

    @property
    def by_shape(self) -> bool:
        """The shape alone decides this label."""
        return self.shape_margin >= DECIDE_MARGIN


def label_modes(measured: list[Measured], runs: dict, model, predicted: list[dict] | None = None,
                ev: Evidence | None = None) -> list[Label]:
    """Label every measured mode at once (see the module docstring).

    Parameters
    ----------
    measured : list of Measured
    runs : dict run name -> RunView
        The channels of each run in the order of the measured constants, and its hit.
    model : guidefit.model.vibration.ModalSolution
        The nominal model (labels, frequencies, mass-normalised shapes).

    Returns
    -------
    list of Label, one per measured mode.
    """
    ev = ev if ev is not None else evidence(measured, runs, model, predicted)
    labels = list(model.labels)
    n = len(measured)
    offered = np.flatnonzero(ev.visible)
    if n == 0:
        return []
    if offered.size == 0:
        return [Label("extra", None, None, None, None, math.inf,
                      note="no model mode is both excited and observed by these runs") for _ in measured]
    comb, shp, frq = (x[:, offered] for x in (ev.combined, ev.shape, ev.frequency))
    extra = extra_costs(ev)
    _, assign = best_assignment(comb, extra)
    out, rivals = [], {}
    for k in range(n):
        j = assign[k]
        if j is None:
            i_best = int(offered[int(np.argmin(comb[k]))])
            out.append(Label("extra", None, labels[i_best], 1.0 - float(ev.rho[k, i_best]), _fin(ev.scale[k, i_best]),
                             math.inf, note=_extra_note(ev, k, i_best, labels)))
            continue
        i = int(offered[j])
        d_comb, alt = _margin(comb, extra, assign, k, allow_extra=True)
        d_shape, alt_s = _margin(shp, extra, assign, k, allow_extra=False)
        d_freq, _ = _margin(frq, extra, assign, k, allow_extra=False)
        by_shape, by_freq = d_shape >= DECIDE_MARGIN, d_freq >= DECIDE_MARGIN
        basis = "shape+frequency" if (by_shape == by_freq) else ("shape" if by_shape else "frequency")
        mac = 1.0 - float(ev.rho[k, i])
        if d_comb < DECIDE_MARGIN:
            other, rival = _alternative(alt, k, j, offered, labels, measured)
            p = 1.0 / (1.0 + math.exp(-max(d_comb, 0.0)))
            mine = labels[i] if rival is None else f"{labels[i]} at {measured[k].frequency_hz:.0f} Hz"
            cands = ((mine, p), (other, 1.0 - p))
            out.append(Label("ambiguous", None, labels[i], mac, _fin(ev.scale[k, i]), float(d_comb), cands,
                             _ambiguous_note(cands, d_comb), float(d_shape), float(d_freq)))
            if rival is not None:
                rivals[rival] = k
            continue
        note = _decided_note(basis, labels[i], mac, measured[k].frequency_hz, float(model.frequencies_hz[i]),
                             alt_s, d_shape, d_freq, k, offered, labels)
        out.append(Label(labels[i], basis, labels[i], mac, _fin(ev.scale[k, i]), float(d_comb), (), note,
                         float(d_shape), float(d_freq)))
    for rival, k in rivals.items():  # the mode that would take an ambiguous label is not told apart either
        if out[rival].label == "extra":
            lab = out[k]
            cands = (lab.candidates[1], lab.candidates[0])
            out[rival] = Label("ambiguous", None, lab.model_label, out[rival].mac, out[rival].scale, lab.margin,
                               cands, _ambiguous_note(cands, lab.margin), out[rival].shape_margin,
                               out[rival].frequency_margin)
    return out


def _ambiguous_note(cands, margin: float) -> str:
    return (f"neither shape nor frequency tells {cands[0][0]} from {cands[1][0]} on these sensors "
            f"(evidence ratio {math.exp(max(margin, 0.0)):.1f}:1)")


def _fin(x) -> float | None:
    return float(x) if x is not None and np.isfinite(x) else None


def _alternative(alt, k, j, offered, labels, measured) -> tuple[str, int | None]:
    """What row k's label would be in the alternative assignment, or which mode (its index, the rival) would
    take its label."""
    if alt is None:
        return "extra", None
    if alt[k] is not None:
        return labels[int(offered[alt[k]])], None
    rival = next((kk for kk, jj in enumerate(alt) if jj == j), None)
    if rival is None:
        return "extra", None
    return f"{labels[int(offered[j])]} at {measured[rival].frequency_hz:.0f} Hz", rival


def _extra_note(ev, k, i_best, labels) -> str:
    return (f"not paired with any carriage mode of the model (closest: {labels[i_best]}, MAC "
            f"{1.0 - float(ev.rho[k, i_best]):.2f} with its predicted readings)")


def _decided_note(basis, label, mac, f_meas, f_model, alt_s, d_shape, d_freq, k, offered, labels) -> str:
    shift = f"{100.0 * (f_meas / f_model - 1.0):+.1f} % from the model's {f_model:.0f} Hz"
    alt_shape = labels[int(offered[alt_s[k]])] if alt_s and alt_s[k] is not None else None
    if basis == "shape":
        return f"{label} by its shape at the sensors (MAC {mac:.2f}); frequency {shift} does not decide"
    if basis == "frequency":
        why = f"these sensors read {label} and {alt_shape} alike" if alt_shape else "the shape does not decide"
        return f"{label} by frequency only ({shift}): {why}"
    if d_shape >= DECIDE_MARGIN and d_freq >= DECIDE_MARGIN:
        return f"{label} by shape (MAC {mac:.2f}) and frequency ({shift})"
    return f"{label} by shape (MAC {mac:.2f}) and frequency ({shift}) together; neither decides alone"


# --------------------------------------------------------------------------- what a layout can tell


@dataclass(frozen=True)
class LayoutView:
    """The model's modes as a layout will see them (``guidefit plan``): the labeller's own numbers."""

    labels: tuple
    frequencies_hz: tuple
    participation: dict  # run -> (n_modes,) |g_j . phi_i| (None: hit point unknown)
    readings: dict  # run -> (n_modes,) norm of the predicted modal constants at the run's sensors
    visible: tuple  # bool per model mode
    auto_mac: np.ndarray  # (n_modes, n_modes) MAC of the predicted readings, all runs stacked
    decided: tuple  # per model mode: the Label the labeller gives its own predicted readings (None: not visible)


def layout_view(model, runs: dict) -> LayoutView:
    """What a layout can tell: participation, readings, auto-MAC, and the labeller run on the model's own
    predicted readings (noise-free) at the model's frequencies: which labels shape decides."""
    predicted = predicted_constants(model, runs)
    n = len(predicted)
    stacked = [np.concatenate([np.asarray(p[r], float) for r in runs]) if runs else np.zeros(0) for p in predicted]
    mac = np.zeros((n, n))
    for i in range(n):
        for j in range(n):
            den = float(stacked[i] @ stacked[i]) * float(stacked[j] @ stacked[j])
            mac[i, j] = float(stacked[i] @ stacked[j]) ** 2 / den if den > 0 else 0.0
    visible = visible_modes(predicted)
    measured = [Measured(float(model.frequencies_hz[i]), predicted[i]) for i in range(n)]
    idx = [i for i in range(n) if visible[i]]
    own = label_modes([measured[i] for i in idx], runs, model, predicted) if idx else []
    decided = [None] * n
    for i, lab in zip(idx, own):
        decided[i] = lab
    phi = np.asarray(model.shapes)[:5]
    part = {}
    for r, v in runs.items():
        g = v.drive
        part[r] = None if g is None else np.abs(g @ phi)
    readings = {r: np.array([float(np.linalg.norm(p[r])) for p in predicted]) for r in runs}
    return LayoutView(tuple(model.labels), tuple(float(f) for f in model.frequencies_hz), part, readings,
                      tuple(bool(x) for x in visible), mac, tuple(decided))
