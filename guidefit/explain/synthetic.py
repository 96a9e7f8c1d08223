"""Measured modes with known truth: the model with effects, plus noise (the test pattern of explain)."""

from __future__ import annotations

import math

import numpy as np

from guidefit.explain.settings import DEFAULT_HITS, DEFAULT_PULSE_S
from guidefit.model.measured import ForceLevel, MeasuredMode, Sensor
from guidefit.model.vibration import JOINT_LABELS


def default_sensors(guide, axes: str = "xy") -> list:
    """Accelerometers at the guide's measuring points along the given axes (``acc_A_x``, ...).

    >>> from guidefit.model.guides import load_guide
    >>> [s.name for s in default_sensors(load_guide("MRB35"), "y")]
    ['acc_A_y', 'acc_B_y', 'acc_C_y', 'acc_D_y']
    """
    unit = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}
    return [Sensor(f"acc_{p}_{a}", tuple(pos), unit[a]) for p, pos in guide.measuring_points_m.items() for a in axes]


def synthetic_modes(guide, effects=(), sensors=None, frequency_std: float = 1e-3, shape_std: float | None = 0.01,
                    seed: int = 0, forces=(), solution=None):
    """Measured modes with known truth: the model with effects, plus noise.

    Parameters
    ----------
    guide : str or Guide
    effects : list of Effect or "NAME:param=value" strings
        Applied with :func:`guidefit.model.effects.apply_effects`;
        ``amplitude_dependence`` also makes the frequency fall with ``forces``.
    sensors : list of Sensor, optional
        Default :func:`default_sensors` (A-D, x and y).
    frequency_std : float
        Relative standard deviation of the frequency noise (and the one reported).
    shape_std : float or None
        Relative per-channel shape noise; None: no shapes.
    seed : int
    forces : sequence of float
        Peak forces (N) of force levels for the vertical and roll_low modes; none by default.
    solution : ModalSolution, optional
        Use these modes instead of solving the model (cases outside the library).

    Returns
    -------
    (list of MeasuredMode, list of Sensor, list of ForceLevel)
        Modes that the model labels ``support_*`` come unlabelled (an extra peak).

    Examples
    --------
    >>> modes, sensors, levels = synthetic_modes("MRB35", ["contact_stiffness:factor=0.81"], seed=1)
    >>> [m.label for m in modes]
    ['yaw', 'pitch', 'roll_low', 'vertical', 'roll_high']
    """
    from guidefit.model import vibration as vib
    from guidefit.model.effects import Effect, apply_effects, make_effect, parse_effect
    from guidefit.model.effects.amplitude_dependence import amplitude_frequency, roller_modal
    from guidefit.model.guides import Guide, load_guide
    from guidefit.modes.labels import sensor_matrix

    guide = guide if isinstance(guide, Guide) else load_guide(guide)
    effects = [parse_effect(e) if isinstance(e, str) else make_effect(e.name, e.parameters) if isinstance(
        e, Effect) else make_effect(*e) for e in effects]
    sensors = default_sensors(guide) if sensors is None else list(sensors)
    rng = np.random.default_rng(seed)
    spec = apply_effects(vib.model_from_guide(guide), guide, effects)
    sol = vib.solve_modes(spec) if solution is None else solution
    amp = next((e.parameters["preload_factor"] for e in effects if e.name == "amplitude_dependence"), None)
    forces = [float(f) for f in forces]
    c_all = roller_modal(spec, sol) if amp is not None and solution is None else None
    levels = []

    def freq_at(j, label, force):
        if amp is None or c_all is None:
            return float(sol.frequencies_hz[j])
        point, direction = DEFAULT_HITS[label]
        return amplitude_frequency(guide, spec, sol, j, force, (point, np.asarray(direction, float),
                                                                DEFAULT_PULSE_S), amp, c_all)

    labels = list(sol.labels)
    for lab in JOINT_LABELS.values() if forces else ():
        j = labels.index(lab)
        for force in forces:
            f = freq_at(j, lab, force)
            levels.append(ForceLevel(force, lab, f * (1 + frequency_std * rng.standard_normal()), frequency_std * f))
    w2 = np.square(forces)
    modes = []
    for j, lab in enumerate(labels):
        if forces and lab in JOINT_LABELS.values():  # H1 over all hits: the F^2-weighted mean
            f = float(np.sum(w2 * [freq_at(j, lab, force) for force in forces]) / np.sum(w2))
        else:
            f = float(sol.frequencies_hz[j])
        shape = None
        if shape_std is not None and sensors:
            a = sensor_matrix(sensors) @ sol.shapes[:5, j]
            a = a + shape_std * np.linalg.norm(a) / math.sqrt(a.size) * rng.standard_normal(a.size)
            shape = {sn.name: float(x) for sn, x in zip(sensors, a)}
        modes.append(MeasuredMode(f * (1 + frequency_std * rng.standard_normal()), frequency_std * f,
                                  label=None if lab.startswith("support") else lab, shape=shape,
                                  shape_std=shape_std))
    return modes, sensors, levels


