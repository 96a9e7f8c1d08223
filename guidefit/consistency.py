r"""Sensor consistency and the plausibility gate of an identification.

Two checks on the modes that :func:`guidefit.identify.identify` found, both
built on one fact: the carriage is a rigid body, so every mode's modal
constants at the accelerometers (``Mode.modal_constants = phi(r) phi(e)``,
1/kg) are the readings of one rigid motion ``q = (u, v, theta, psi, phi)``,
``s = S q`` with ``S`` the sensor matrix (:func:`guidefit.modes.labels.sensor_matrix`,
row ``r``: the sensor's direction times :func:`~guidefit.model.vibration.rigid_body_map`
at its position).

Sensor consistency
------------------
Eight sensors (A-D, x and y) over five DOFs leave three redundant readings
per mode. A channel mounted upside down (factor -1), with its sensitivity
entered wrong (x10, x1000, x9.81) or along another axis breaks the rigid fit
of *every* mode in the same way, while noise and fit errors do not. The
test, per channel ``c`` (:func:`find_sensor_faults`):

1. leave ``c`` out and fit each mode's rigid motion from the other channels
   of its run; this predicts ``c``'s reading ``p_k`` (all modes ``k`` of all
   runs in which ``c`` appears and the others determine it);
2. fault models: a scale ``a = sum p s / sum p^2`` on the declared axis (sign
   and scale), or the same on another axis (x, y, z);
3. the total rigid residual of all modes with ``c`` corrected by each model.

A fault is reported when the uncorrected residual is large (relative RMS
above :data:`FAULT_MIN_RELRES` of the shapes), the best correction removes
most of it (sum of squares down :data:`FAULT_MIN_IMPROVEMENT`-fold) and its
size is beyond calibration tolerance (:data:`SCALE_TOLERANCE`). Channels
whose correction explains the data equally well (the A and B x-sensors sit at
the same z, so rigid motion alone cannot tell which of them is wrong) are
told apart by the driving-point residue, which must be positive for every
mode, and by the modal mass (below); when neither decides, the warning names
both. Up to :data:`MAX_FAULTS` faults are found one after the other, or as
a pair when no single correction explains the residual; then identify
corrects the FRFs (:func:`corrected_frf`: a scale fault divided out, an
axis fault's channel left out and the FRFs computed again,
:func:`guidefit.identify.corrected_frfs`) and fits them again, so labels,
K and c come from good data. Real
coupled physics (a corner mass, a damaged row, a base with its own mode)
keeps the carriage rigid and stays silent; shapes of modes fitted from a
noisy or weak peak are weighted by their amplitude relative to the run's
strongest mode, so they cannot raise a false alarm alone.

Modal mass
----------
For a rigid carriage of mass matrix ``M`` (the guide's: M, M, Jx, Jy, Jz)
and the hammer's row ``b`` (its direction times the rigid-body map at the hit
point), the fitted motion is ``q = phi (b . phi)`` with ``phi^T M phi = 1``,
so ``(b . q) / (q^T M q) = 1``. A ratio ``r`` far from 1 says the data belong
to a body ``r`` times heavier: a force or acceleration scale error
(:func:`modal_mass_ratio`, :func:`scale_factor_hint`: 1000 for mV/N entered
as mV/kN, 9.81 for g read as m/s^2) or another structure.

Plausibility gate
-----------------
:func:`plausibility` gives one line why the modes are not those of a carriage
on this guide, or None: most of the model's carriage modes that the set-up
can excite and observe are missing; the joint mode is not seen by any sensor
(its label came from its frequency alone); strong modes the carriage cannot
have outnumber its own; or the shapes are not rigid-body motions. Then
identify reports the modes but no joint parameters, and exits 1.

Examples
--------
>>> import numpy as np
>>> S = np.array([[1, 0, 0, 0.045, 0], [0, 1, -0.045, 0, 0.03], [1, 0, 0, 0.045, 0],
...               [0, 1, -0.045, 0, -0.03], [1, 0, 0, -0.045, 0], [0, 1, 0.045, 0, -0.03],
...               [1, 0, 0, -0.045, 0], [0, 1, 0.045, 0, 0.03]])
>>> names = tuple(f"acc_{p}_{a}" for p in "ABCD" for a in "xy")
>>> rng = np.random.default_rng(0)
>>> shapes = rng.standard_normal((4, 5)) @ S.T            # four rigid modes
>>> shapes[:, 3] *= -1                                     # acc_B_y mounted upside down
>>> sets = [ShapeSet("vertical", names, S, np.zeros((8, 3)), np.zeros((8, 3)), shapes)]
>>> [(f.channel, f.kind, round(f.factor, 3)) for f in find_sensor_faults(sets)]
[('acc_B_y', 'scale', -1.0)]
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from guidefit.model.vibration import JOINT_LABELS

#: Relative RMS rigid-fit residual of all shapes below which no sensor fault is looked for.
FAULT_MIN_RELRES = 0.01
#: The best correction must cut the residual sum of squares at least this many times.
FAULT_MIN_IMPROVEMENT = 16.0
#: A scale within this factor of 1 (either way) is calibration tolerance, not a fault.
SCALE_TOLERANCE = 1.1
#: At most this many faulty channels are named and corrected (one after the other).
MAX_FAULTS = 2
#: Corrections within this factor of the best one (residual sum of squares) explain the data equally.
EQUIVALENT = 3.0
#: Known factors of unit and sensitivity mix-ups, with what they usually mean.
KNOWN_FACTORS = (
    (1000.0, "a sensitivity entered with the wrong prefix: mV vs V, or per N vs per kN"),
    (9.80665, "g and m/s^2 mixed up"),
    (100.0, "a sensitivity entered with a decimal slip"),
    (10.0, "a sensitivity entered with a decimal slip"),
)


def _num(x: float) -> str:
    """Three significant digits without an exponent below 1e6 (1000, 9.81, 0.102)."""
    return format(float(f"{x:.3g}"), "g")
#: A measured factor within this ratio of a known one is named as that one.
FACTOR_MATCH = 1.08
#: Modal mass / guide mass outside [1/MASS_TOLERANCE, MASS_TOLERANCE] is warned about.
MASS_TOLERANCE = 2.5
#: Relative rigid residual of a mode above which its shape is not a rigid carriage motion.
RIGID_MAX_RELRES = 0.3
#: A mode at least this fraction of its run's strongest one is "strong".
STRONG = 0.2

_AXES = {"x": np.array([1.0, 0.0, 0.0]), "y": np.array([0.0, 1.0, 0.0]), "z": np.array([0.0, 0.0, 1.0])}


@dataclass(frozen=True)
class ShapeSet:
    """The real modal constants (1/kg) of one run's modes at its sensors.

    ``sensors`` is (n_channels, 5) (:func:`guidefit.modes.labels.sensor_matrix`),
    ``shapes`` (n_modes, n_channels); ``driving`` is the hammer's row (5,)
    (its direction times the rigid-body map at the hit point), None if unknown;
    ``labels`` and ``frequencies_hz`` name the modes, ``band_hz`` is where they
    were searched (a model mode outside it is not expected).
    """

    run: str
    channels: tuple
    sensors: np.ndarray
    positions_m: np.ndarray
    directions: np.ndarray
    shapes: np.ndarray
    driving: np.ndarray | None = None
    labels: tuple = ()
    frequencies_hz: tuple = ()
    band_hz: tuple = (0.0, math.inf)  # the band in which the run's modes were searched


@dataclass(frozen=True)
class SensorFault:
    """A channel whose readings do not fit rigid carriage motion, and the fault model that explains them.

    ``kind`` is "scale" (factor on its declared axis; -1 is a sign flip) or
    "axis" (it reads ``axis`` times ``factor``); ``alternatives`` are channels
    whose correction would explain the data equally well. ``relres_before``
    and ``relres_after`` are the relative RMS rigid-fit residuals of all shapes.
    """

    channel: str
    kind: str
    factor: float
    axis: str | None
    alternatives: tuple
    relres_before: float
    relres_after: float
    note: str = ""  # the whole warning, when the fault was found another way (guidefit.sensor_signs)

    @property
    def message(self) -> str:
        """One line for the warnings: channel, likely fault and its size."""
        if self.note:
            return self.note
        who = " or ".join((self.channel, *self.alternatives))
        if self.kind == "axis":
            size = "" if abs(abs(self.factor) - 1) < 0.2 else f", {_num(abs(self.factor))}x"
            sign = "-" if self.factor < 0 else "+"
            what = f"reads the {sign}{self.axis} axis, not its declared one{size} (mounted on the wrong face?)"
        else:
            what = describe_factor(self.factor)
        more = " (rigid motion cannot tell which)" if self.alternatives else ""
        action = "modes fitted without it" if self.kind == "axis" else "modes fitted with it corrected"
        return (f"{who}: {what}{more}; rigid-fit residual of the shapes {100 * self.relres_before:.0f} % -> "
                f"{100 * self.relres_after:.1f} % with it corrected; {action}")


def describe_factor(factor: float) -> str:
    """Words for a channel read ``factor`` times what rigid motion predicts.

    >>> describe_factor(-1.01)
    'sign reversed (mounted upside down?)'
    >>> describe_factor(9.79)
    'reads 9.79x what rigid motion predicts (g and m/s^2 mixed up: factor 9.81?)'
    >>> describe_factor(-0.001)
    'sign reversed and reads 1/1000 (0.001x) of what rigid motion predicts (a sensitivity entered with the wrong prefix: mV vs V, or per N vs per kN: factor 1000?)'
    """
    size = abs(factor)
    sign = factor < 0
    if sign and abs(math.log(size)) < math.log(SCALE_TOLERANCE):
        return "sign reversed (mounted upside down?)"
    hint = _known_factor(size)
    if size >= 1:
        text = f"reads {_num(size)}x what rigid motion predicts"
    else:
        text = f"reads 1/{_num(1 / size)} ({_num(size)}x) of what rigid motion predicts"
    why = f" ({hint[1]}: factor {_num(hint[0])}?)" if hint else " (sensitivity entered wrong?)"
    return ("sign reversed and " if sign else "") + text + why


def _known_factor(size: float):
    """The known mix-up factor (value, meaning) that ``size`` or 1/``size`` matches, or None."""
    dist = [(min(abs(math.log(size / value)), abs(math.log(size * value))), value, meaning)
            for value, meaning in KNOWN_FACTORS]
    d, value, meaning = min(dist)
    return (value, meaning) if d < math.log(FACTOR_MATCH) else None


# --------------------------------------------------------------------------- rigid fits


def rigid_residual(sensors: np.ndarray, shapes: np.ndarray) -> np.ndarray:
    """(n_modes, n_channels): each shape minus its least-squares rigid-body fit."""
    if shapes.size == 0:
        return np.zeros_like(shapes)
    q, *_ = np.linalg.lstsq(sensors, shapes.T, rcond=1e-10)
    return shapes - (sensors @ q).T


def _normalised(sets: list[ShapeSet]) -> list[ShapeSet]:
    """Each run's shapes divided by its strongest modal constant (a common noise floor per run)."""
    out = []
    for s in sets:
        top = float(np.max(np.abs(s.shapes))) if s.shapes.size else 0.0
        out.append(replace(s, shapes=s.shapes / top) if top > 0 else s)
    return out


def _total(sets: list[ShapeSet]) -> tuple[float, float]:
    """(residual sum of squares, shape sum of squares) over all sets."""
    res = sum(float(np.sum(rigid_residual(s.sensors, s.shapes) ** 2)) for s in sets)
    energy = sum(float(np.sum(s.shapes ** 2)) for s in sets)
    return res, energy


def _redundant(sets: list[ShapeSet]) -> bool:
    return any(s.sensors.shape[0] > np.linalg.matrix_rank(s.sensors) for s in sets if s.shapes.size)


def _row(s: ShapeSet, j: int, axis: np.ndarray | None) -> np.ndarray:
    """Sensor row of channel j, along ``axis`` instead of its declared direction when given."""
    if axis is None:
        return s.sensors[j]
    from guidefit.model.vibration import rigid_body_map

    return axis @ rigid_body_map(s.positions_m[j])


def _loo_prediction(s: ShapeSet, j: int, row: np.ndarray, exclude=()) -> np.ndarray | None:
    """Channel j's reading of every mode (``row`` . q) with q fitted from the other channels (but those of
    ``exclude``, indices); None if they do not determine it."""
    others = np.array([i for i in range(len(s.channels)) if i != j and i not in exclude], dtype=int)
    sub = s.sensors[others]
    if sub.size == 0:
        return None
    # the row must lie in the span of the other rows, else the others do not determine it
    coef, *_ = np.linalg.lstsq(sub.T, row, rcond=1e-10)
    if np.linalg.norm(sub.T @ coef - row) > 1e-6 * max(np.linalg.norm(row), 1e-12):
        return None
    q, *_ = np.linalg.lstsq(sub, s.shapes[:, others].T, rcond=1e-10)
    return row @ q


def _corrected(sets: list[ShapeSet], name: str, factor: float, axis: np.ndarray | None) -> list[ShapeSet]:
    """The sets with channel ``name`` divided by ``factor`` and (axis fault) its row along ``axis``."""
    out = []
    for s in sets:
        if name not in s.channels:
            out.append(s)
            continue
        j = s.channels.index(name)
        shapes = s.shapes.copy()
        shapes[:, j] /= factor
        sensors, directions = s.sensors, s.directions
        if axis is not None:
            sensors = sensors.copy()
            sensors[j] = _row(s, j, axis)
            directions = directions.copy()
            directions[j] = axis
        out.append(replace(s, shapes=shapes, sensors=sensors, directions=directions))
    return out


def _hypotheses(sets: list[ShapeSet], name: str, exclude: str | None = None):
    """Yield (factor, axis name or None, axis vector or None) fault models of channel ``name``, predicted
    from the other channels but ``exclude`` (a second suspect)."""
    with_it = [s for s in sets if name in s.channels]
    declared = with_it[0].directions[with_it[0].channels.index(name)]
    for axis_name, axis in [(None, None)] + list(_AXES.items()):
        if axis is not None and abs(float(axis @ declared)) > 0.5:
            continue
        p_all, s_all = [], []
        for s in with_it:
            j = s.channels.index(name)
            skip = (s.channels.index(exclude),) if exclude in s.channels else ()
            p = _loo_prediction(s, j, _row(s, j, axis), skip)
            if p is not None:
                p_all.append(p)
                s_all.append(s.shapes[:, j])
        if not p_all:
            continue
        p, x = np.concatenate(p_all), np.concatenate(s_all)
        pp = float(p @ p)
        if pp <= 1e-12 * max(float(x @ x), 1e-300):
            continue
        factor = float(p @ x) / pp
        if factor != 0 and math.isfinite(factor):
            yield factor, axis_name, axis


def _significant_fault(factor: float, axis_name: str | None) -> bool:
    return axis_name is not None or factor < 0 or abs(math.log(abs(factor))) >= math.log(SCALE_TOLERANCE)


def find_sensor_faults(sets: list[ShapeSet], mass_matrix: np.ndarray | None = None) -> tuple[SensorFault, ...]:
    """Channels whose sign, scale or axis does not fit rigid carriage motion (see the module docstring).

    Parameters
    ----------
    sets : list of ShapeSet
        One per run; a channel may appear in several runs (one fault model for all).
    mass_matrix : (5, 5) array, optional
        The guide's carriage mass matrix, to tell equivalent channels apart by the modal mass.

    Returns
    -------
    tuple of SensorFault
        In the order found; empty on consistent data.
    """
    sets = _normalised([s for s in sets if s.shapes.size])
    if not sets or not _redundant(sets):
        return ()
    faults: list[SensorFault] = []
    for _ in range(MAX_FAULTS):
        res0, energy = _total(sets)
        if energy <= 0 or res0 / energy < FAULT_MIN_RELRES**2:
            break
        found = _best_correction(sets, res0, mass_matrix)
        if found is None:
            if not faults and MAX_FAULTS >= 2:  # two faults at once: no single correction explains them
                pair = _best_pair(sets, res0, mass_matrix)
                if pair is not None:
                    (first, second), fixed = pair
                    after = math.sqrt(_total(fixed)[0] / energy)
                    faults = [replace(f, relres_before=math.sqrt(res0 / energy), relres_after=after)
                              for f in (first, second)]
            break
        fault, sets = found
        faults.append(replace(fault, relres_before=math.sqrt(res0 / energy),
                              relres_after=math.sqrt(_total(sets)[0] / energy)))
    return tuple(faults)


def _best_correction(sets, res0, mass_matrix):
    """(SensorFault, corrected sets) of the correction that explains the residual, or None."""
    names = sorted({c for s in sets for c in s.channels})
    best_per_channel = []
    for name in names:
        trials = []
        for factor, axis_name, axis in _hypotheses(sets, name):
            fixed = _corrected(sets, name, factor, axis)
            trials.append((_total(fixed)[0], name, factor, axis_name, fixed))
        if trials:
            best_per_channel.append(min(trials, key=lambda t: t[0]))
    if not best_per_channel:
        return None
    best_per_channel.sort(key=lambda t: t[0])
    res, name, factor, axis_name, fixed = best_per_channel[0]
    if res * FAULT_MIN_IMPROVEMENT > res0 or not _significant_fault(factor, axis_name):
        return None
    floor = 1e-9 * res0
    equal = [t for t in best_per_channel if t[0] <= EQUIVALENT * res + floor
             and _significant_fault(t[2], t[3])]
    if len(equal) > 1:
        equal = _physical_choice(equal, mass_matrix)
    res, name, factor, axis_name, fixed = equal[0]
    fault = SensorFault(name, "axis" if axis_name else "scale", factor, axis_name,
                        tuple(t[1] for t in equal[1:]), 0.0, 0.0)
    return fault, fixed


def _best_pair(sets, res0, mass_matrix=None):
    """((SensorFault, SensorFault), corrected sets) of the two-channel correction that explains the
    residual (each channel's factor predicted with both left out), or None.

    Pairs whose residual is within :data:`EQUIVALENT` of the best are told apart by physics
    (:func:`_physical_choice`: positive driving-point residues, modal mass near M), as single
    channels are: on side-face x sensors, two sign flips on one face and two on the diagonal fit
    rigid motion equally well, the diagonal one by trading u for psi (the labels roll_low and yaw
    then swap). Pairs physics cannot rule out are each fault's ``alternatives``.
    """
    from itertools import combinations

    names = sorted({c for s in sets for c in s.channels})
    trials = []
    for a, b in combinations(names, 2):
        best = None
        for fa, axa_name, axa in _hypotheses(sets, a, exclude=b):
            if not _significant_fault(fa, axa_name):
                continue
            once = _corrected(sets, a, fa, axa)
            for fb, axb_name, axb in _hypotheses(sets, b, exclude=a):
                if not _significant_fault(fb, axb_name):
                    continue
                fixed = _corrected(once, b, fb, axb)
                res = _total(fixed)[0]
                if best is None or res < best[0]:
                    best = (res, ((a, fa, axa_name), (b, fb, axb_name)), None, None, fixed)
        if best is not None:
            trials.append(best)
    if not trials:
        return None
    trials.sort(key=lambda t: t[0])
    if trials[0][0] * FAULT_MIN_IMPROVEMENT > res0:
        return None
    equal = [t for t in trials if t[0] <= EQUIVALENT * trials[0][0] + 1e-9 * res0]
    if len(equal) > 1:
        equal = _physical_choice(equal, mass_matrix)
    _, pair, _, _, fixed = equal[0]
    others = tuple(dict.fromkeys(n for t in equal[1:] for n, _, _ in t[1] if n not in {m for m, _, _ in pair}))
    faults = tuple(SensorFault(n, "axis" if ax else "scale", f, ax, others, 0.0, 0.0) for n, f, ax in pair)
    return faults, fixed


def _physical_choice(equal: list, mass_matrix) -> list:
    """Order equivalent corrections by physics: positive driving-point residues, then modal mass near M.

    Returns the chosen correction first; the list keeps only the candidates
    physics could not rule out.
    """
    def score(trial):
        sets = trial[4]
        negative, mass_err = 0.0, 0.0
        for s in sets:
            if s.driving is None:
                continue
            q, *_ = np.linalg.lstsq(s.sensors, s.shapes.T, rcond=1e-10)
            drive = s.driving @ q  # (n_modes,)
            weight = np.max(np.abs(s.shapes), axis=1)
            negative += float(np.sum(weight[drive < 0]))
            if mass_matrix is None:
                continue
            for k in np.flatnonzero(weight >= STRONG * weight.max()):
                ratio = modal_mass_ratio(q[:, k], s.driving, mass_matrix)
                if ratio is not None and ratio > 0:
                    mass_err += float(weight[k] / weight.max()) * abs(math.log(ratio))
        return negative, mass_err

    scored = sorted(((score(t), t) for t in equal), key=lambda x: (round(x[0][0], 2), x[0][1]))
    (neg0, mass0), first = scored[0]
    keep = [first] + [t for (neg, mass), t in scored[1:]
                      if round(neg, 2) <= round(neg0, 2) and mass - mass0 < math.log(1.5)]
    return keep


def apply_faults(sets: list[ShapeSet], faults) -> list[ShapeSet]:
    """The sets (unnormalised) with every fault's channel corrected."""
    for f in faults:
        sets = _corrected(sets, f.channel, f.factor, _AXES.get(f.axis) if f.axis else None)
    return sets


# --------------------------------------------------------------------------- modal mass


def modal_mass_ratio(q: np.ndarray, driving: np.ndarray, mass_matrix: np.ndarray) -> float | None:
    """Apparent mass over the guide's mass from one mode's rigid motion: (b . q) / (q^T M q).

    ``q`` is the rigid motion fitted to the modal constants (1/kg); 1 for the
    carriage of mass matrix ``M`` measured with calibrated force and
    acceleration; 1000 when the force reads 1000x high (or the acceleration
    1000x low). None when the motion is not observed.

    >>> M = np.diag([2.2, 2.2, 3.9e-3, 5.8e-3, 2.5e-3])
    >>> q = np.array([0.0, -1 / 2.2, 0, 0, 0])            # vertical mode, hammer down (b_v = -1)
    >>> round(modal_mass_ratio(q, np.array([0, -1.0, 0, 0, 0]), M), 6)
    1.0
    >>> round(modal_mass_ratio(q / 1000, np.array([0, -1.0, 0, 0, 0]), M))
    1000
    """
    qmq = float(q @ mass_matrix @ q)
    if qmq <= 0:
        return None
    return float(driving @ q) / qmq


def scale_factor_hint(ratio: float) -> str:
    """What a modal-mass ratio (apparent mass / guide mass) suggests.

    >>> scale_factor_hint(1003.0)
    'factor 1000: force reads 1000x high (sensitivity in mV/N entered as mV/kN?) or acceleration 1000x low'
    >>> scale_factor_hint(1 / 9.8)
    'factor 9.81: accelerations read 9.81x high (data in m/s^2 declared as g, or a sensitivity in mV/(m/s^2) entered \
with unit = "g"?)'
    """
    size = ratio if ratio >= 1 else 1 / ratio
    known = _known_factor(size)
    if known is None:
        return (f"{_num(size)}x {'heavier' if ratio > 1 else 'lighter'} than the guide's carriage: another "
                "structure, or force/acceleration calibration off")
    value = known[0]
    if value == 9.80665:
        return ('factor 9.81: accelerations read 9.81x low (data in g declared as m/s^2, or a sensitivity in mV/g '
                'entered with unit = "m/s^2"?)' if ratio > 1 else
                'factor 9.81: accelerations read 9.81x high (data in m/s^2 declared as g, or a sensitivity in '
                'mV/(m/s^2) entered with unit = "g"?)')
    if value == 1000.0:
        return ("factor 1000: force reads 1000x high (sensitivity in mV/N entered as mV/kN?) or acceleration "
                "1000x low" if ratio > 1 else
                "factor 1000: force reads 1000x low (sensitivity in mV/kN entered as mV/N?) or acceleration "
                "1000x high")
    return f"factor {value:g}: force or acceleration {'high' if ratio < 1 else 'low'} by {value:g}x ({known[1]}?)"


# --------------------------------------------------------------------------- plausibility gate


def rigid_misfit(sets: list[ShapeSet]) -> list[tuple[str, str, float, float, float]]:
    """Per mode: (run, label, frequency_hz, relative amplitude in its run, relative rigid residual).

    The relative residual is ``|s - S q| / |s|`` of the mode's own shape; it is
    0 for a rigid carriage motion and NaN where the run's sensors leave no
    redundancy (as many independent readings as DOFs they observe).
    """
    out = []
    for s in sets:
        if not s.shapes.size:
            continue
        redundant = s.sensors.shape[0] > np.linalg.matrix_rank(s.sensors)
        res = rigid_residual(s.sensors, s.shapes)
        amp = np.max(np.abs(s.shapes), axis=1)
        top = float(amp.max()) or 1.0
        for k in range(s.shapes.shape[0]):
            norm = float(np.linalg.norm(s.shapes[k])) or 1.0
            rel = float(np.linalg.norm(res[k])) / norm if redundant else math.nan
            label = s.labels[k] if k < len(s.labels) else "?"
            f = s.frequencies_hz[k] if k < len(s.frequencies_hz) else math.nan
            out.append((s.run, label, float(f), float(amp[k]) / top, rel))
    return out


def observable_modes(model, sets: list[ShapeSet], threshold: float = 0.1) -> set:
    """Labels of the model's carriage modes that some run both excites and sees.

    A mode's visibility in a run is ``|b . phi| |S phi|`` (the size of its
    modal constants); it counts when it reaches ``threshold`` of the run's most
    visible model mode. A run whose hit point is unknown (``driving`` None)
    may have excited any mode: there ``|b . phi|`` is taken as 1, so every mode
    its sensors see is expected (an unknown hit point makes the gate stricter,
    never blind: a hit assumed at the origin would excite only a few modes).
    """
    seen = set()
    shapes = np.asarray(model.shapes)[:5]
    labels = [lab for lab in model.labels]
    freqs = np.asarray(model.frequencies_hz)
    for s in sets:
        if not len(s.channels):
            continue
        vis = _participation(s, shapes) * np.linalg.norm(s.sensors @ shapes, axis=0)
        vis = np.where((freqs >= s.band_hz[0]) & (freqs <= s.band_hz[1]), vis, 0.0)
        top = float(vis.max())
        if top <= 0:
            continue
        seen.update(lab for lab, v in zip(labels, vis) if v >= threshold * top and not lab.startswith("support"))
    return seen


def _participation(s: ShapeSet, shapes: np.ndarray) -> np.ndarray:
    """``|b . phi|`` per mode at the run's hit point; ones when the hit point is unknown (any mode the
    sensors see may have been excited: an unknown hit point makes the gate expect more, never less)."""
    if s.driving is None:
        return np.ones(shapes.shape[1])
    return np.abs(s.driving @ shapes)


#: excitation_position_m and the force channel's position further apart than this (m) are two hit points
HIT_POINT_TOLERANCE_M = 0.002


def unknown_hit_warnings(recording) -> list[str]:
    """One warning per run whose hit point the file does not give (:attr:`Run.hit_position_m` None),
    and one per run whose two hit points (``excitation_position_m`` and the force channel's
    position) are more than :data:`HIT_POINT_TOLERANCE_M` apart."""
    out = [f"run '{r.name}': the hit point is unknown (the file does not say where the hammer hit): the "
           "plausibility gate expects every carriage mode its sensors see, and the labels do not use the "
           "hammer's participation" for r in recording.runs
           if r.hit_position_m is None]
    for r in recording.runs:
        given = getattr(r, "excitation_position_m", None)
        if given is None or not getattr(r, "force_position_known", True):
            continue
        force = np.asarray(r.force_channel.position_m, float)
        apart = float(np.linalg.norm(np.asarray(given, float) - force))
        if apart > HIT_POINT_TOLERANCE_M:
            out.append(f"run '{r.name}': excitation_position_m {vector_text(given)} and the force channel's position "
                       f"{vector_text(force)} are {apart * 1000:.0f} mm apart; both are the hit point: the labels and "
                       "the modal-constant checks use excitation_position_m (correct the one that is wrong)")
    return out


def vector_text(v) -> str:
    """A vector for a message: ``(0, -1, 0)`` (no ``-0``)."""
    return "(" + ", ".join(format(float(x) + 0.0, "g") for x in np.asarray(v, float)) + ")"


def plausibility(modes, missing, sets: list[ShapeSet], model) -> str | None:
    """One line why the modes are not those of a carriage on this guide, or None.

    Parameters
    ----------
    modes : sequence
        The selected modes (objects with ``label``, ``frequency_hz``, ``energy``).
    missing : sequence of str
        Model modes not observed in any run.
    sets : list of ShapeSet
        All significant modes of every run (sensor faults corrected), with labels.
    model : ModalSolution
        The guide's nominal modes.
    """
    by_label = {m.label: m for m in modes}
    for label in JOINT_LABELS.values():
        m = by_label.get(label)
        if m is not None and not any(v > 0 for v in m.energy.values()):
            return (f"no sensor sees carriage motion in the {label} mode at {m.frequency_hz:.0f} Hz: its label rests "
                    "on its frequency alone, and the recording may not be of this guide")
    far = _frequency_alone_far(by_label, sets, model)
    if far:
        return far
    observable = observable_modes(model, sets)
    lost = sorted(lab for lab in missing if lab in observable)
    if len(lost) >= 2 and 2 * len(lost) > len(observable):
        verb = "may excite (hit point unknown)" if any(s.driving is None for s in sets) else "excites"
        return (f"{len(lost)} of the {len(observable)} carriage modes this set-up {verb} and sees are missing "
                f"({', '.join(lost)}): the recording does not look like a carriage on this guide")
    misfit = rigid_misfit(sets)
    for run in dict.fromkeys(r[0] for r in misfit):
        rows = [r for r in misfit if r[0] == run and r[3] >= STRONG]
        extra = [r for r in rows if r[1] == "extra"]
        own = [r for r in rows if r[1] != "extra"]
        if len(extra) >= 3 and len(extra) > len(own):
            freqs = ", ".join(f"{r[2]:.0f}" for r in sorted(extra, key=lambda r: r[2]))
            return (f"run '{run}': {len(extra)} strong modes the carriage cannot have ({freqs} Hz) against "
                    f"{len(own)} carriage mode(s): the recording does not look like a carriage on this guide")
    strong = [r for r in misfit if r[3] >= STRONG and not math.isnan(r[4])]
    bad = [r for r in strong if r[4] > RIGID_MAX_RELRES]
    joint_bad = [r for r in bad if r[1] in JOINT_LABELS.values()]
    if strong and (joint_bad or 2 * len(bad) > len(strong)):
        worst = max(joint_bad or bad, key=lambda r: r[4])
        return (f"{len(bad)} of {len(strong)} strong mode shapes are not rigid-body motions of the carriage (run "
                f"'{worst[0]}', {worst[2]:.0f} Hz: {100 * worst[4]:.0f} % of it off the best rigid fit)")
    return None


#: on one accelerometer in one run, a joint mode's label rests on its frequency: at most this factor off the model's
SINGLE_CHANNEL_FREQUENCY_FACTOR = 1.5


def _frequency_alone_far(by_label: dict, sets: list[ShapeSet], model) -> str | None:
    """Why a recording of one accelerometer in one run is not trusted: a joint mode labelled more than
    :data:`SINGLE_CHANNEL_FREQUENCY_FACTOR` from the model's frequency (one channel tells no shape: every MAC
    is 1, and another structure's modes get the carriage's labels by elimination), or None."""
    if sum(len(s.channels) for s in sets) != 1:
        return None
    for label in JOINT_LABELS.values():
        m = by_label.get(label)
        if m is None or label not in model.labels:
            continue
        ratio = float(m.frequency_hz) / model.frequency_hz(label)
        if not 1 / SINGLE_CHANNEL_FREQUENCY_FACTOR <= ratio <= SINGLE_CHANNEL_FREQUENCY_FACTOR:
            return (f"one accelerometer in one run tells no mode shape, and the {label} mode's "
                    f"{m.frequency_hz:.0f} Hz is {ratio:.2f} times the model's {model.frequency_hz(label):.0f} Hz: "
                    "its label rests on its frequency alone, and the recording may not be of this guide")
    return None


def _sees(sensors: np.ndarray, motion: np.ndarray, mass_matrix: np.ndarray) -> bool:
    """Whether the sensors determine a mode of ``motion`` (5,): no motion they cannot see (null space of
    the sensor matrix) shares more than 10 % of its kinetic energy metric (the mass-weighted cosine)."""
    _, sv, vt = np.linalg.svd(sensors)
    rank = int(np.sum(sv > 1e-8 * sv[0])) if sv.size and sv[0] > 0 else 0
    norm = math.sqrt(max(float(motion @ mass_matrix @ motion), 1e-300))
    for n in vt[rank:]:
        cos = float(motion @ mass_matrix @ n) / (norm * math.sqrt(float(n @ mass_matrix @ n)))
        if abs(cos) > 0.1:
            return False
    return True


def mass_warnings(modes, sets: list[ShapeSet], mass_matrix: np.ndarray, mass_kg: float, model=None) -> list[str]:
    """Warnings for joint modes whose modal mass from the residues is far from the guide's carriage.

    Uses each mode's shape in its own run (sensor faults corrected) and the
    run's driving point; see :func:`modal_mass_ratio`. With ``model`` given, a
    run whose sensors cannot determine the model's motion of that mode (A and
    B alone cannot tell u from psi) is skipped: its least-squares motion, and
    so its modal mass, would be biased.
    """
    out = []
    for m in modes:
        if m.label not in JOINT_LABELS.values():
            continue
        s = next((x for x in sets if x.run == m.run), None)
        if s is None or s.driving is None:
            continue
        if model is not None and m.label in model.labels and not _sees(
                s.sensors, np.asarray(model.shapes)[:5, list(model.labels).index(m.label)], mass_matrix):
            continue
        k = next((i for i, (lab, f) in enumerate(zip(s.labels, s.frequencies_hz))
                  if lab == m.label and abs(f - m.frequency_hz) < 1e-6 * m.frequency_hz + 1e-9), None)
        if k is None:
            continue
        q, *_ = np.linalg.lstsq(s.sensors, s.shapes[k], rcond=1e-10)
        ratio = modal_mass_ratio(q, s.driving, mass_matrix)
        if ratio is not None and ratio < 0:
            out.append(f"mode {m.label} at {m.frequency_hz:.1f} Hz: the driving-point residue is negative (the "
                       f"carriage moves against the hammer in run '{m.run}'): the excitation_direction or every "
                       "accelerometer's direction is reversed")
            continue
        if ratio is None or ratio == 0 or 1 / MASS_TOLERANCE <= ratio <= MASS_TOLERANCE:
            continue
        out.append(f"mode {m.label} at {m.frequency_hz:.1f} Hz: modal mass from the driving-point residue "
                   f"{ratio * mass_kg:.3g} kg against the guide's M = {mass_kg:g} kg ({scale_factor_hint(ratio)})")
    return out


# --------------------------------------------------------------------------- identify glue


def shape_sets(runs, modes, hit_points: dict, band_hz=(None, None)) -> list[ShapeSet]:
    """One :class:`ShapeSet` per run result from identify's modes (``shape`` dicts, real modal constants).

    ``hit_points`` maps run name to the hit position (m) or None; ``band_hz``
    is identify's (f_min_hz, f_max_hz) setting, the top cut to 0.4 times the
    run's sample rate as identify's search band is. The sensor rows and the
    hammer's row are :func:`guidefit.modes.labels.sensor_matrix` and
    :func:`guidefit.modes.labels.driving_row`.
    """
    from guidefit.modes.labels import driving_row, sensor_matrix

    out = []
    for run in runs:
        chans = list(run.channels)
        mine = [m for m in modes if m.run == run.name]
        shapes = np.array([[m.shape.get(c.name, 0.0) for c in chans] for m in mine]).reshape(len(mine), len(chans))
        out.append(ShapeSet(run.name, tuple(c.name for c in chans), sensor_matrix(chans),
                            np.array([np.asarray(c.position_m, float) for c in chans]).reshape(-1, 3),
                            np.array([np.asarray(c.direction, float) for c in chans]).reshape(-1, 3),
                            shapes, driving_row(run.excitation_direction, hit_points.get(run.name)),
                            tuple(m.label for m in mine), tuple(m.frequency_hz for m in mine),
                            _band(run, band_hz)))
    return out


def recorded_sets(runs, hit_points: dict, band_hz=(None, None)) -> list[ShapeSet]:
    """One :class:`ShapeSet` without modes per recorded run (``guidefit.io`` ``Run``: its acceleration
    channels, hammer row and search band up to 0.4 x its sample rate): what a run that gave no FRF
    would have excited and seen (:func:`observable_modes`)."""
    from guidefit.modes.labels import driving_row, sensor_matrix

    out = []
    for run in runs:
        chans = [run.channels[i] for i in run.response_indices]
        lo, hi = band_hz
        band = (float(lo or 0.0), min(float(hi) if hi else math.inf, 0.4 * float(run.sample_rate_hz)))
        out.append(ShapeSet(run.name, tuple(c.name for c in chans), sensor_matrix(chans),
                            np.array([np.asarray(c.position_m, float) for c in chans]).reshape(-1, 3),
                            np.array([np.asarray(c.direction, float) for c in chans]).reshape(-1, 3),
                            np.zeros((0, len(chans))), driving_row(run.excitation_direction,
                                                                    hit_points.get(run.name)), band_hz=band))
    return out


def _band(run, band_hz) -> tuple:
    """The search band of a run result: identify's settings, at most 0.4 fs (0.8 of the last FRF bin)."""
    freq = np.asarray(getattr(run.frf, "frequency_hz", [np.inf]), dtype=float)
    top = 0.8 * float(freq[-1]) if freq.size else math.inf
    lo, hi = band_hz
    return (float(lo or 0.0), min(float(hi) if hi else math.inf, top))


def corrected_frf(frf, faults):
    """The FrfSet without faulty channels' errors: a scale fault's FRF divided by its factor, an axis
    fault's channel left out (group sums too, for the jackknife)."""
    scale = np.ones(len(frf.channels))
    for f in faults:
        if f.channel in frf.channels and f.kind == "scale":
            scale[frf.channels.index(f.channel)] *= f.factor
    drop = {f.channel for f in faults if f.kind == "axis"}
    keep = np.array([i for i, c in enumerate(frf.channels) if c not in drop], dtype=int)
    if np.all(scale == 1.0) and len(keep) == len(frf.channels):
        return frf
    sums = dict(frf.group_sums or {})
    for key, power in (("Sxx", 2), ("Sfx", 1)):
        if key in sums:
            sums[key] = (np.asarray(sums[key]) / scale**power)[..., keep]
    return replace(frf, H=(np.asarray(frf.H) / scale)[:, keep], coherence=np.asarray(frf.coherence)[:, keep],
                   channels=tuple(frf.channels[i] for i in keep), group_sums=sums)


def axis_fault_channels(faults, channels) -> set:
    """The names among ``channels`` of channels that read another axis (their FRFs are left out)."""
    names = {getattr(ch, "name", ch) for ch in channels}
    return {f.channel for f in faults if f.kind == "axis"} & names


@dataclass(frozen=True)
class SensorCheck:
    """What :func:`check_global` found: the faults, the shape sets behind the gate, one warning per fault."""

    faults: tuple
    sets: list
    warnings: tuple
    unresolved: str | None = None  # a sign fault the check found but cannot place (identify: exit 1)


def hit_points_of(recording) -> dict:
    """Run name -> hit point (m) or None when the file does not give it (:attr:`Run.hit_position_m`)."""
    return {r.name: r.hit_position_m for r in recording.runs}


# --------------------------------------------------------------------------- the global modal stage's glue


def check_global(runs, recording, guide, settings, faults=None, model=None) -> SensorCheck:
    """Faulty channels in the global fit's shapes (each run's view of the shared modes).

    ``runs`` are identify's RunResults whose ``modes`` are the run's views of
    the global modes (``run`` and ``shape`` of that run). With ``faults``
    given (the FRFs already corrected for them), only the shape sets are made
    again for the gate. The correction itself is a step of the identify
    pipeline (:func:`guidefit.identify.corrected_frfs`): the FRFs corrected,
    the global fit made again. When no channel breaks the rigid fit, the runs
    are checked against each other for reversed sets of channels a run's own
    rigid fit cannot see (:func:`guidefit.sensor_signs.sign_faults`, with
    ``model``, the guide's nominal modes); a set it cannot place is
    ``unresolved``.
    """
    from guidefit.model import vibration as vib
    from guidefit.sensor_signs import sign_faults

    hit_points = hit_points_of(recording)
    band = (getattr(settings, "f_min_hz", None), getattr(settings, "f_max_hz", None))
    modes = [m for r in runs for m in r.modes]
    sets = shape_sets(runs, modes, hit_points, band)
    unresolved = None
    if faults is None:
        faults = find_sensor_faults(sets, vib.carriage_mass_matrix(vib.model_from_guide(guide)))
        if not faults and model is not None:
            signs = sign_faults(sets, model)
            faults = tuple(SensorFault(n, "scale", -1.0, None, (), 0.0, 0.0, note) for n, note in signs.faults)
            unresolved = signs.unresolved
    return SensorCheck(tuple(faults), sets, tuple(dict.fromkeys(f.message for f in faults)), unresolved)


def global_mass_warnings(runs, sets: list[ShapeSet], guide, model) -> list[str]:
    """:func:`mass_warnings` for the global fit: each joint mode from the run that drives it hardest
    (largest modal constant), so a mode barely excited by the other run's hammer cannot mimic a
    scale error."""
    from guidefit.model import vibration as vib

    best = {}
    for r in runs:
        for m in r.modes:
            if m.label not in JOINT_LABELS.values() or not m.shape:
                continue
            size = max(abs(float(v)) for v in m.shape.values())
            if m.label not in best or size > best[m.label][0]:
                best[m.label] = (size, m)
    mass = vib.carriage_mass_matrix(vib.model_from_guide(guide))
    return mass_warnings([m for _, m in best.values()], sets, mass, guide.mass_kg, model)
