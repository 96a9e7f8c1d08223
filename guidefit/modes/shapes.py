r"""Mode shapes at the sensors: rigid-body motion of the carriage, kinetic-energy shares, IdentifiedMode.

Shared by :mod:`guidefit.identify` and :mod:`guidefit.modal_stage`: the
least-squares carriage motion (u, v, theta, psi, phi) behind a shape at the
sensors (whose matrix is :func:`guidefit.modes.labels.sensor_matrix`), the
kinetic-energy shares of a motion, and :class:`IdentifiedMode`, the labelled
mode of an identification (the labels come from :mod:`guidefit.modes.labels`).

Examples
--------
>>> import numpy as np
>>> round(float(real_shape(np.array([1j, -2j]))[1] / real_shape(np.array([1j, -2j]))[0]), 6)
-2.0
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from guidefit.errors import IdentificationError


@dataclass(frozen=True)
class IdentifiedMode:
    """A measured mode with its label, uncertainty and motion at the sensors."""

    label: str
    run: str
    frequency_hz: float
    damping_ratio: float
    frequency_std_hz: float | None
    damping_std: float | None
    model_frequency_hz: float | None
    shape: dict  # channel -> modal constant (1/kg), real for normal modes
    motion: tuple  # rigid-body motion (u, v, theta, psi, phi), unit norm
    energy: dict  # kinetic-energy shares v, theta, psi, u_phi
    coherence: float
    half_power: dict | None = None
    raw_damping_ratio: float | None = None
    fit: object = field(default=None, repr=False, compare=False)  # the guidefit.modes.Mode behind it
    estimates: tuple = ()  # every run's own estimate: dicts run, level, frequency_hz, damping_ratio, stds
    candidates: tuple = ()  # ambiguous label: ((label, energy share), ...)
    shapes: dict = field(default_factory=dict)  # run -> channel -> modal constant (global fit: every run)
    std_parts: dict = field(default_factory=dict)  # fit / jackknife / selection std of f and zeta
    global_index: int | None = field(default=None, compare=False)  # index into the GlobalFit's modes
    carriage_energy: float | None = None  # share of the mode's kinetic energy in the carriage (q^T M q)
    label_basis: str | None = None  # what decided the label: "shape", "frequency", "shape+frequency"
    label_note: str = ""  # the labeller's plain sentence (guidefit.modes.labels)
    label_mac: float | None = None  # MAC with the model mode's predicted readings at the sensors
    label_scale: float | None = None  # driving-point scale against the model mode (1: as predicted)

    def to_dict(self) -> dict:
        """JSON-ready; the contract's label/frequency_hz/damping_ratio plus extras."""
        return {
            "label": self.label,
            "frequency_hz": self.frequency_hz,
            "damping_ratio": self.damping_ratio,
            "frequency_std_hz": self.frequency_std_hz,
            "damping_std": self.damping_std,
            "run": self.run,
            "model_frequency_hz": self.model_frequency_hz,
            "coherence": self.coherence,
            "method": "curve_fit" if self.global_index is None else "global_fit",
            "damping_ratio_before_window_correction": self.raw_damping_ratio,
            "half_power": self.half_power,
            "shape": {k: float(np.real(v)) for k, v in self.shape.items()},
            "level": None,  # the all-hits estimate (force bins: force_levels, level 0, 1, ...)
            "estimates": [dict(e) for e in self.estimates],
            "candidates": [{"label": lab, "probability": share if math.isfinite(share) else None,
                            "energy_share": None} for lab, share in self.candidates],
            "label_basis": self.label_basis,
            "label_note": self.label_note,
            "label_mac": self.label_mac,
            "label_scale": self.label_scale,
            "shapes": {r: dict(v) for r, v in self.shapes.items()},
            "std_parts": {k: dict(v) for k, v in self.std_parts.items()},
            "motion": [float(v) for v in self.motion],
            "carriage_energy_share": self.carriage_energy,
            "energy": dict(self.energy),
        }


def real_shape(values) -> np.ndarray:
    """Rotate complex modal constants to the real axis (best single phase) and return the real part."""
    v = np.asarray(values, dtype=complex)
    if not np.any(v):
        return np.zeros(v.shape)
    angle = 0.5 * np.angle(np.sum(v**2))
    r = np.real(v * np.exp(-1j * angle))
    return r


def rigid_body_motion(shape, sensors: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares carriage motion q (5,) behind a shape at the sensors, and which DOFs are observed."""
    q, *_ = np.linalg.lstsq(sensors, shape, rcond=1e-8)
    observed = np.linalg.norm(sensors, axis=0) > 0
    rank_ok = np.linalg.matrix_rank(sensors) == 5
    if not rank_ok:
        # null-space DOFs are not observed: min-norm solution sets them to zero
        _, s, vt = np.linalg.svd(sensors)
        null = vt[np.sum(s > 1e-8 * s[0]):]
        observed = np.abs(null).sum(axis=0) < 1e-8
    return q, observed


def energy_shares(q: np.ndarray, mass_matrix: np.ndarray) -> dict:
    """Kinetic-energy shares of v, theta, psi and u+phi in a carriage motion."""
    contrib = np.abs(q * (mass_matrix @ q))
    total = contrib.sum() or 1.0
    return {"v": contrib[1] / total, "theta": contrib[2] / total, "psi": contrib[3] / total,
            "u_phi": (contrib[0] + contrib[4]) / total}


def _coherence_at(frf, frequency_hz: float, weights) -> float:
    i = int(np.argmin(np.abs(frf.frequency_hz - frequency_hz)))
    w = np.abs(weights)
    if not np.any(w):
        return float(np.mean(frf.coherence[i]))
    return float(np.sum(frf.coherence[i] * w) / np.sum(w))


def _half_power_entry(frf, mode) -> dict | None:
    """Eq. (26)/(28) on the channel that shows the mode most, with the correction of the FrfSet's window."""
    import warnings as _w

    from guidefit.frf.windows import undo_window_damping
    from guidefit.modes import halfpower

    channel = int(np.argmax(np.abs(mode.residues)))
    peak = int(np.argmin(np.abs(frf.frequency_hz - mode.peak_frequency_hz)))
    try:
        with _w.catch_warnings():
            _w.simplefilter("ignore")
            hp = halfpower.half_power(frf.frequency_hz, frf.H[:, channel], peak)
    except (IdentificationError, ValueError):
        return None
    # Eq. (26)/(28) as printed divide by the |H| peak; the exact SDOF accelerance relation gives f_n
    sdof = halfpower.sdof_from_half_power(hp.f1_hz, hp.f2_hz)
    f_n, zeta = undo_window_damping(sdof.f_n_hz, sdof.zeta, frf)
    return {"f_peak_hz": hp.f_peak_hz, "f1_hz": hp.f1_hz, "f2_hz": hp.f2_hz, "zeta": hp.zeta,
            "f_n_hz": f_n, "zeta_window_corrected": zeta, "channel": frf.channels[channel],
            # counted in resolution cells: zero-padded records have finer bins, not a finer resolution
            "bins_in_band": int(round((hp.f2_hz - hp.f1_hz) / frf.resolution_hz))}
