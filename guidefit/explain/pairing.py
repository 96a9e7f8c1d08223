"""Stage 1 of explain: pair the measured modes with the modes of a model (:class:`Pairing`).

Measured modes are assigned to model modes by the Hungarian method
(:func:`scipy.optimize.linear_sum_assignment`), separately per run, with the
cost ``10 |ln(f_i / f_j)| + label + 5 (1 - MAC)``. The label term is
``10 (1 - share)``, ``share`` the model mode's kinetic-energy share (carriage
only) of the motion the measured label names (v for ``vertical``, theta for
``pitch``, psi for ``yaw``, u+phi for the roll modes), plus 3 between
``roll_low`` and ``roll_high``. A labelled mode may so pair with a mode far
off in frequency (the paper's f_H = 1075 Hz pairs with the model's roll_low at
2496 Hz), while an unlabelled one (``extra``) pairs only within about 35 %
(dummy cost 3; labelled 20). Model modes left over are "not observed" and
carry no residual. The pairing is redone at every model evaluation, since an
effect may reorder modes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Pairing:
    """Measured-to-model assignment of one model evaluation.

    ``model``: (n,) model mode per measured mode, -1 unpaired;
    ``model_shapes``: per shape set, the model's unit shapes at its sensors
    (n_ch, n_model); ``mac``: (n, n_model) MAC of every measured mode with
    every model mode (0 without a shape); ``level_model``: per force level
    the model mode it refers to (-1 none).
    """

    model: np.ndarray
    model_shapes: tuple
    mac: np.ndarray
    level_model: np.ndarray


def _level_mode(data, model: np.ndarray, sol, label: str) -> int:
    """Model mode that a force level of this label refers to: its measured mode's partner, else by label."""
    for i, lab in enumerate(data.labels):
        if lab == label and model[i] >= 0:
            return int(model[i])
    if label in sol.labels:
        return sol.labels.index(label)
    return -1


def pair(data, sol) -> Pairing:
    """Hungarian pairing of measured with model modes, per run (see the module docstring)."""
    from scipy.optimize import linear_sum_assignment

    fm = sol.frequencies_hz
    nm = fm.size
    energy = np.asarray(sol.energy_fractions)[:, :4]
    share = energy / np.maximum(energy.sum(axis=1, keepdims=True), 1e-300)
    model_labels = np.array(sol.labels, dtype=object)
    model_roll = (model_labels == "roll_low") | (model_labels == "roll_high")
    proj = []
    mac_full = np.zeros((data.f.size, nm))
    for s in data.shapes:
        a = s.rigid_map @ sol.shapes[:5]
        norm = np.linalg.norm(a, axis=0)
        a = a / np.where(norm > 0, norm, 1.0)
        mac_full[s.index] = (s.unit @ a) ** 2
        proj.append(a)
    model = np.full(data.f.size, -1)
    for idx in data.runs:
        n = idx.size
        cost = 10.0 * np.abs(np.log(data.f[idx, None] / fm[None, :]))
        g = data.group[idx]
        has = g >= 0
        if np.any(has):
            cost[has] += 10.0 * (1.0 - share[:, g[has]].T)
            roll = np.flatnonzero(g == 3)
            if roll.size:
                own = data.label_arr[idx[roll]]
                cost[roll] += 3.0 * (model_roll[None, :] & (model_labels[None, :] != own[:, None]))
        cost += 5.0 * (1.0 - mac_full[idx]) * data.has_shape[idx, None]
        dummy = np.full((n, n), 1e9)
        dummy[np.arange(n), np.arange(n)] = np.where(has, 20.0, 3.0)
        rows, cols = linear_sum_assignment(np.hstack([cost, dummy]))
        ok = cols < nm
        model[idx[rows[ok]]] = cols[ok]
    level_model = np.array([_level_mode(data, model, sol, lab) for lab in data.lv_label], dtype=int)
    return Pairing(model, tuple(proj), mac_full, level_model)
