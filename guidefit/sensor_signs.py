r"""Sign-reversed sensor sets that a run's own rigid fit cannot see, found by the runs' disagreement.

:func:`guidefit.consistency.find_sensor_faults` finds a channel whose
reading breaks the rigid motion of the carriage. Some sets of reversed
channels do not break it: the side-face x sensors E, F, G, H all sit at one
height, so their readings of any rigid motion are ``a + b z`` at two heights
``z``, and reversing the two at one height (E and G) gives readings of
another rigid motion (the lateral translation and the yaw trade places).
The run alone looks perfect; its modes are simply labelled wrong (yaw as
roll_low: f_H, K_H and c_H from the wrong mode).

Two facts of a correctly signed test tell:

* **the run's scale** (:func:`guidefit.modes.labels.run_scale`, the
  driving-point residue of its modes against the model): positive for any
  correctly signed force and accelerations, and near the other runs' (one
  carriage, one mass);
* **the runs agree on each shared mode**: a mode of the global fit that two
  runs both show strongly is, through each run's own sensors and hit, the
  same model mode (within ties: the vertical run cannot tell roll_low from
  roll_high, but it can tell either from yaw).

A run whose scale is negative, or off from the others' by more than
:data:`~guidefit.modes.labels.COMMON_SCALE_FACTOR` while its modes disagree
with another run's, is tested with every sign-reversed set of its channels
that its own rigid fit cannot see (:func:`undetectable_flips`). A set is
accepted when, reversed back, the run's scale is positive and within that
factor of the others' and its modes agree with theirs. Every channel of the
run reversed is the hammer's direction (or every sensor's) reversed: the
labeller already reads each run at its own sign, so when that explains the
data nothing is corrected. One accepted set is corrected like any sensor
fault; when no set or several explain a negative scale, the check cannot
decide and identify refuses the joint parameters with a line naming the
suspects (exit 1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from itertools import combinations

import numpy as np

#: runs with more channels than this are not searched (2^n sign sets)
MAX_CHANNELS = 12
#: a mode whose modal constants in a run reach this fraction of the run's strongest is compared with the
#: other runs' view of it (a weakly driven mode is still read precisely; the noise constants that shared
#: poles give a mode a run does not excite are ~1e-3 of its modes)
MATCH_STRONG = 0.01


@dataclass(frozen=True)
class SignCheck:
    """What :func:`sign_faults` found: channels to correct by a factor -1, as ``(channel, warning)``
    pairs (:func:`guidefit.consistency.check_global` makes them SensorFaults), or a line why it
    cannot decide (``unresolved``), or neither."""

    faults: tuple = ()
    unresolved: str | None = None


@dataclass(frozen=True)
class _View:
    sensors: np.ndarray
    drive: np.ndarray


def undetectable_flips(sensors: np.ndarray) -> list[tuple[int, ...]]:
    """Proper, non-empty sets of channels whose reversal maps every rigid reading to another rigid
    reading (the sign matrix keeps the column space of ``sensors``): the run's rigid fit cannot see them.

    >>> z = [0.04, -0.04, 0.04, -0.04]                     # side-face x sensors E, F, G, H
    >>> undetectable_flips(np.array([[1.0, 0, 0, zi, 0.015] for zi in z]))
    [(0, 2), (1, 3)]
    """
    n = sensors.shape[0]
    if n < 2 or n > MAX_CHANNELS:
        return []
    u, sv, _ = np.linalg.svd(sensors, full_matrices=False)
    rank = int(np.sum(sv > 1e-8 * sv[0])) if sv.size and sv[0] > 0 else 0
    if rank == 0:
        return []
    basis = u[:, :rank]
    out = []
    for k in range(1, n):
        for sub in combinations(range(n), k):
            d = np.ones(n)
            d[list(sub)] = -1.0
            flipped = d[:, None] * basis
            leak = flipped - basis @ (basis.T @ flipped)
            if np.linalg.norm(leak) < 1e-6 * math.sqrt(rank):
                out.append(sub)
    return out


def _scale(s, model) -> float | None:
    from guidefit.modes.labels import run_scale

    phi = np.asarray(model.shapes)[:5]
    freqs = np.asarray(model.frequencies_hz, float)[:phi.shape[1]]
    return run_scale(list(s.shapes), _View(s.sensors, s.driving), phi, np.asarray(s.frequencies_hz, float), freqs)


def _matches(s, model) -> dict:
    """Frequency -> the set of model modes each mode of the run (at least :data:`MATCH_STRONG` of its
    strongest) matches (MAC >= SCALE_MAC, ties within SCALE_MAC_TIE), through the run's sensors and hit."""
    from guidefit.modes.labels import SCALE_MAC, SCALE_MAC_TIE, mac_with_model, predicted_readings

    R, rr, seen = predicted_readings(_View(s.sensors, s.driving), np.asarray(model.shapes)[:5])
    top = max((float(m @ m) for m in s.shapes), default=0.0)
    out = {}
    for f, m in zip(s.frequencies_hz, s.shapes):
        mm = float(m @ m)
        if mm <= 0 or not np.any(seen) or mm < MATCH_STRONG**2 * top:
            continue
        mac = mac_with_model(m, R, rr, seen)
        best = float(mac.max())
        if best >= SCALE_MAC:
            out[float(f)] = set(np.flatnonzero(mac >= best - SCALE_MAC_TIE).tolist())
    return out


def _disagreements(run: str, matches: dict) -> list[tuple]:
    """(frequency, other run, labels here, labels there) of each mode ``run`` and another run both show
    strongly but match to different model modes."""
    out = []
    for other, theirs in matches.items():
        if other == run:
            continue
        for f, mine in matches[run].items():
            there = next((v for g, v in theirs.items() if abs(g - f) <= 1e-6 * abs(f)), None)
            if there is not None and not (mine & there):
                out.append((f, other, mine, there))
    return out


def sign_faults(sets: list, model) -> SignCheck:
    """Sign-reversed channel sets that only the runs' disagreement reveals (see the module docstring).

    Parameters
    ----------
    sets : list of guidefit.consistency.ShapeSet
        One per run, unnormalised (the runs' scales are compared), with labels and frequencies.
    model : ModalSolution
        The guide's nominal modes.
    """
    sets = [s for s in sets if s.shapes.size and s.driving is not None]
    if len(sets) < 2:
        return SignCheck()
    scales = {s.run: _scale(s, model) for s in sets}
    matches = {s.run: _matches(s, model) for s in sets}
    found, unresolved = [], []
    for s in sets:
        scale = scales[s.run]
        if scale is None:
            continue
        others = [v for r, v in scales.items() if r != s.run and v is not None and v > 0]
        ref = float(np.median(others)) if others else 1.0
        disagree = _disagreements(s.run, matches)
        if not (scale < 0 or (_off(scale, ref) and disagree)):
            continue
        flips = undetectable_flips(s.sensors)
        if not flips:
            continue
        accepted = [sub for sub in [*flips, tuple(range(len(s.channels)))] if _explains(s, sub, ref, matches, model)]
        if len(s.channels) in {len(sub) for sub in accepted}:
            continue  # the hammer's (or every sensor's) direction reversed: read at the run's own sign
        if len(accepted) == 1:
            found.append((s, accepted[0], scale, ref, disagree))
        elif scale < 0:
            unresolved.append(_unresolved(s, accepted or flips, scale, ref, disagree, model, several=bool(accepted)))
    if unresolved or len(found) > 1:
        lines = unresolved + [_unresolved(s, [sub], scale, ref, dis, model, several=True)
                              for s, sub, scale, ref, dis in found if len(found) > 1]
        return SignCheck((), "; ".join(lines))
    if not found:
        return SignCheck()
    return SignCheck(_faults(*found[0], model))


def _off(scale: float, ref: float) -> bool:
    from guidefit.modes.labels import COMMON_SCALE_FACTOR

    return scale <= 0 or ref <= 0 or abs(math.log(scale / ref)) > math.log(COMMON_SCALE_FACTOR)


def _explains(s, sub, ref: float, matches: dict, model) -> bool:
    """Reversing channels ``sub`` of run ``s`` back gives a positive scale near ``ref`` (any positive scale when
    ``sub`` is every channel: the hammer reversed, beside a unit error the labeller reads as the run's
    factor) and modes that agree with the other runs'."""
    d = np.ones(len(s.channels))
    d[list(sub)] = -1.0
    flipped = replace(s, shapes=s.shapes * d)
    scale = _scale(flipped, model)
    whole = len(sub) == len(s.channels)  # the hammer reversed: a unit error beside it is the run factor's
    if scale is None or scale <= 0 or (not whole and _off(scale, ref)):
        return False
    return not _disagreements(s.run, {**matches, s.run: _matches(flipped, model)})


def _why(s, scale: float, ref: float, disagree: list, model) -> str:
    labels = list(model.labels)
    text = f"run '{s.run}' reads {scale / ref:.3g} times the other runs' modal constants"
    if disagree:
        f, other, mine, there = disagree[0]
        text += (f" and its mode at {f:.0f} Hz as {'/'.join(labels[i] for i in sorted(mine))} where run "
                 f"'{other}' reads {'/'.join(labels[i] for i in sorted(there))}")
    return text


def _faults(s, sub, scale: float, ref: float, disagree: list, model) -> tuple:
    names = [s.channels[i] for i in sub]
    d = np.ones(len(s.channels))
    d[list(sub)] = -1.0
    after = _scale(replace(s, shapes=s.shapes * d), model)
    note = (f"{' and '.join(names)}: sign reversed together (mounted upside down, or declared along the "
            f"opposite axis?): {_why(s, scale, ref, disagree, model)}; its own rigid fit cannot see these "
            f"reversed together, and with them reversed back it agrees with the others ({after / ref:.2f} times "
            "their modal constants); modes fitted with them corrected")
    return tuple((n, note) for n in names)


def _unresolved(s, flips, scale: float, ref: float, disagree: list, model, several: bool = False) -> str:
    sets = " or ".join("+".join(s.channels[i] for i in sub) for sub in flips)
    which = ("more than one of them, reversed back, makes the runs agree (the sensor check cannot tell which)"
             if several else "reversing none of them back makes the runs agree")
    return (f"{_why(s, scale, ref, disagree, model)}: a sign no correctly signed test gives; a reversed set of its "
            f"sensors that the run's own rigid fit cannot see may be the cause ({sets}), and {which}: check these "
            "sensors' mounting and declared direction")
