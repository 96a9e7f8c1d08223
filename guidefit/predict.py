"""``guidefit predict``: the analytic model of a guide at a given static load.

Combines the static contact model (Eq. 1-4, :mod:`guidefit.model.static`)
with the vibration model (Eq. 5-23, :mod:`guidefit.model.vibration`): the
static solution gives each roller's tangent stiffness at the load, which
becomes that roller's spring in the 5-DOF model.

Examples
--------
>>> from guidefit.model.guides import load_guide
>>> p = predict(load_guide("MRB35"))
>>> round(p.modes.frequency_hz("vertical"), 1)
3529.0
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Prediction:
    """Static stiffness and modal solution of a guide at one load."""

    guide: object
    load: tuple[float, float, float]
    calibration: str
    static: object  # guidefit.model.static.StaticStiffness
    modes: object  # guidefit.model.vibration.ModalSolution
    closed_form_hz: dict

    def to_dict(self) -> dict:
        """JSON-ready dictionary; names carry their SI unit."""
        st = self.static
        return {
            "guide": self.guide.name,
            "load": {"F_V_n": self.load[0], "F_H_n": self.load[1], "M_gamma_nm": self.load[2]},
            "calibration": self.calibration,
            "stiffness": {
                "K_n": {"value": float(np.mean(st.roller_stiffness_n_per_m)), "unit": "N/m"},
                "K_V": {"value": float(st.K_V), "unit": "N/m"},
                "K_H": {"value": float(st.K_H), "unit": "N/m"},
                "K_gamma": {"value": float(st.K_gamma), "unit": "N*m/rad"},
            },
            "displacement": {
                "delta_V_m": float(st.delta_V), "delta_H_m": float(st.delta_H), "gamma_rad": float(st.gamma),
            },
            "rows_lifted": [int(r) for r in st.rows_lifted],
            "modes": [
                {"label": lab, "frequency_hz": float(f)}
                for lab, f in sorted(zip(self.modes.labels, self.modes.frequencies_hz), key=lambda t: t[1])
            ],
            "closed_form_hz": {k: float(v) for k, v in self.closed_form_hz.items()},
        }

    def to_frame(self):
        """One row per mode (label, frequency_hz, energy shares)."""
        return self.modes.to_frame()


def predict(guide, load=None, calibration: str = "nominal") -> Prediction:
    """Static stiffness and natural frequencies of ``guide`` under ``load`` = (F_V, F_H, M_gamma)."""
    from guidefit.model import static
    from guidefit.model import vibration as vib

    load = (0.0, 0.0, 0.0) if load is None else tuple(float(x) for x in load)
    st = static.tangent_stiffness(guide, load, calibration=calibration)
    spec = vib.model_from_guide(guide, st.roller_stiffness_n_per_m.reshape(4, -1))
    closed = vib.closed_form_frequencies_hz(guide) if load == (0.0, 0.0, 0.0) else {}
    return Prediction(guide, load, calibration, st, vib.solve_modes(spec), closed)


def predict_sweep(guide, calibration: str = "nominal", direction_load=None, n: int = 21):
    """Static stiffness and frequencies over a load range (a pandas DataFrame).

    Without ``direction_load`` the vertical load runs from 0 to 90 % of the
    load at which the first row lifts off; with it, the load vector is scaled
    from 0 to 1 times ``direction_load``.
    """
    from guidefit.model import static

    return static.sweep(guide, direction_load=direction_load, n=n, calibration=calibration)


from guidefit._api import make_callable  # noqa: E402

make_callable(__name__, "predict")
