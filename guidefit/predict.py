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

#: The three stiffnesses ``predict`` reports, by key: what each one is.
STIFFNESS_KINDS = {
    "static_zero_load": "static tangent stiffness at zero load (Eq. 2 with the preloaded rollers)",
    "static_at_load": "static tangent stiffness at the given load (Eq. 1-4: rollers unloaded or lifted soften it)",
    "apparent_single_dof": "apparent single-DOF stiffness 4 pi^2 M f^2 of the predicted vertical and roll_low "
                           "modes (Eq. 24-25): what identify reports for this guide at this load",
}


@dataclass(frozen=True)
class Prediction:
    """Static stiffness and modal solution of a guide at one load.

    Three stiffnesses, never under one name (:data:`STIFFNESS_KINDS`):
    ``static_zero`` (Eq. 2 at zero load), ``static`` (at ``load``) and the
    apparent single-DOF values (:meth:`apparent_stiffness_n_per_m`, Eq. 24-25
    of the predicted frequencies), which differ from the static ones because
    the vertical and roll modes are not single-DOF motions of the carriage.
    """

    guide: object
    load: tuple[float, float, float]
    calibration: str
    static: object  # guidefit.model.static.StaticStiffness at ``load``
    modes: object  # guidefit.model.vibration.ModalSolution
    closed_form_hz: dict
    static_zero: object = None  # guidefit.model.static.StaticStiffness at zero load

    def apparent_stiffness_n_per_m(self) -> dict:
        """``{"K_V": ..., "K_H": ...}``: Eq. (24)-(25) of the predicted vertical and roll_low frequencies."""
        return apparent_stiffness_n_per_m(self.guide.mass_kg, dict(zip(self.modes.labels, self.modes.frequencies_hz)))

    def to_dict(self) -> dict:
        """JSON-ready dictionary; names carry their SI unit; each stiffness says what it is."""
        st = self.static
        zero = self.static_zero if self.static_zero is not None else st
        apparent = self.apparent_stiffness_n_per_m()

        def static_block(s):
            return {"K_V": {"value": float(s.K_V), "unit": "N/m"}, "K_H": {"value": float(s.K_H), "unit": "N/m"},
                    "K_gamma": {"value": float(s.K_gamma), "unit": "N*m/rad"}}

        return {
            "guide": self.guide.name,
            "load": {"F_V_n": self.load[0], "F_H_n": self.load[1], "M_gamma_nm": self.load[2]},
            "calibration": self.calibration,
            "stiffness": {
                "K_n": {"value": float(np.mean(st.roller_stiffness_n_per_m)), "unit": "N/m",
                        "meaning": "mean roller contact stiffness at the given load (Eq. 3-4)"},
                "static_zero_load": {**static_block(zero), "meaning": STIFFNESS_KINDS["static_zero_load"]},
                "static_at_load": {**static_block(st), "meaning": STIFFNESS_KINDS["static_at_load"]},
                "apparent_single_dof": {"K_V": {"value": apparent["K_V"], "unit": "N/m"},
                                        "K_H": {"value": apparent["K_H"], "unit": "N/m"},
                                        "meaning": STIFFNESS_KINDS["apparent_single_dof"]},
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


def apparent_stiffness_n_per_m(mass_kg: float, frequencies_hz: dict) -> dict:
    """Apparent single-DOF stiffness of the vertical and roll_low modes, Eq. (24)-(25).

    The value ``identify`` reports: K = 4 pi^2 M f^2 with the carriage mass M,
    computed by :func:`guidefit.identify.stiffness_from_frequency` (the one
    implementation of the equation). NaN for a mode the model lacks.

    >>> k = apparent_stiffness_n_per_m(2.2, {"vertical": 3529.0, "roll_low": 2496.5})
    >>> f"{k['K_V']:.4g} {k['K_H']:.4g}"
    '1.082e+09 5.413e+08'
    """
    from guidefit.identify import stiffness_from_frequency

    out = {}
    for key, label in (("K_V", "vertical"), ("K_H", "roll_low")):
        f = frequencies_hz.get(label)
        out[key] = float("nan") if f is None else float(stiffness_from_frequency(mass_kg, float(f)))
    return out


def predict(guide, load=None, calibration: str = "nominal") -> Prediction:
    """Static stiffness and natural frequencies of ``guide`` under ``load`` = (F_V, F_H, M_gamma)."""
    from guidefit.model import static
    from guidefit.model import vibration as vib

    load = (0.0, 0.0, 0.0) if load is None else tuple(float(x) for x in load)
    st = static.tangent_stiffness(guide, load, calibration=calibration)
    zero = st if load == (0.0, 0.0, 0.0) else static.tangent_stiffness(guide, (0.0, 0.0, 0.0),
                                                                           calibration=calibration)
    spec = vib.model_from_guide(guide, st.roller_stiffness_n_per_m.reshape(4, -1))
    closed = vib.closed_form_frequencies_hz(guide) if load == (0.0, 0.0, 0.0) else {}
    return Prediction(guide, load, calibration, st, vib.solve_modes(spec), closed, zero)


#: ``--sweep`` quantities: option name -> (index in the load vector, column, unit).
SWEEP_QUANTITIES = {"FV": (0, "F_V_n", "N"), "FH": (1, "F_H_n", "N"), "M": (2, "M_gamma_nm", "N m")}
SWEEP_QUANTITIES_COLUMNS = tuple(column for _, column, _ in SWEEP_QUANTITIES.values())
MAX_SWEEP_POINTS = 1000
"""Largest number of loads in a sweep (each is a static solution and an eigenproblem)."""


def parse_sweep(text: str) -> tuple[str, float, float, int]:
    """``"FV:0:5000:21"`` -> ("FV", 0.0, 5000.0, 21): quantity, first and last load, number of loads.

    Quantities: FV (vertical force, N), FH (lateral force, N), M (roll moment, N m).

    >>> parse_sweep("FV:0:5000:21")
    ('FV', 0.0, 5000.0, 21)
    >>> parse_sweep("fh:-500:500:5")
    ('FH', -500.0, 500.0, 5)
    >>> parse_sweep("FV:0:5000")
    Traceback (most recent call last):
    ...
    ValueError: 'FV:0:5000': expected QUANTITY:FROM:TO:N, e.g. FV:0:900:10 (QUANTITY: FV, FH or M)
    """
    import math

    parts = text.split(":")
    usage = f"'{text}': expected QUANTITY:FROM:TO:N, e.g. FV:0:900:10 (QUANTITY: FV, FH or M)"
    if len(parts) != 4 or parts[0].strip().upper() not in SWEEP_QUANTITIES:
        raise ValueError(usage)
    try:
        start, stop, n = float(parts[1]), float(parts[2]), int(parts[3])
    except ValueError:
        raise ValueError(usage) from None
    if not (math.isfinite(start) and math.isfinite(stop)):
        raise ValueError(f"'{text}': FROM and TO must be finite numbers")
    if not 2 <= n <= MAX_SWEEP_POINTS:
        raise ValueError(f"'{text}': N must be 2 to {MAX_SWEEP_POINTS}, got {n}")
    return parts[0].strip().upper(), start, stop, n


def predict_sweep(guide, calibration: str = "nominal", direction_load=None, n: int = 21, sweep=None):
    """Static and apparent stiffness and frequencies over a load range (a pandas DataFrame).

    ``sweep`` = (quantity, from, to, n) of :func:`parse_sweep`: that load
    component runs from ``from`` to ``to`` in ``n`` steps, the others stay at
    ``direction_load`` (zero when not given). Without ``sweep``: with
    ``direction_load`` the load vector is scaled from 0 to 1 times it; without
    it the vertical load runs from 0 to 90 % of the load at which the first
    row lifts off.

    Columns: those of :func:`guidefit.model.static.sweep` with the static
    tangent stiffnesses named ``K_V_static_n_per_m``, ``K_H_static_n_per_m``,
    ``K_gamma_static_nm_per_rad``, plus ``K_V_apparent_n_per_m`` and
    ``K_H_apparent_n_per_m`` (Eq. 24-25 of the predicted frequencies, what
    identify reports). ``frame.attrs["sweep"]`` says what was swept.

    >>> from guidefit.model.guides import load_guide
    >>> frame = predict_sweep(load_guide("MRB35"), sweep=("FV", 0.0, 800.0, 2))
    >>> frame["f_vertical_hz"].round(1).tolist()
    [3529.0, 3463.3]
    >>> [f"{k:.3e}" for k in frame["K_V_apparent_n_per_m"]]
    ['1.082e+09', '1.042e+09']
    """
    from guidefit.model import static

    base = np.zeros(3) if direction_load is None else np.asarray(direction_load, dtype=float).reshape(3)
    if sweep is not None:
        quantity, start, stop, n = sweep
        index, column, unit = SWEEP_QUANTITIES[quantity]
        loads = []
        for value in np.linspace(start, stop, n):
            load = base.copy()
            load[index] = value
            loads.append(load)
        frame = static.sweep(guide, loads, calibration=calibration, stop_at_limit=True)
        described = {"quantity": column, "unit": unit, "from": float(start), "to": float(stop), "n": int(n)}
    else:
        frame = static.sweep(guide, direction_load=direction_load, n=n, calibration=calibration, stop_at_limit=True)
        stopped = frame.attrs.get("stopped_at")
        last = stopped["value"] * (n - 1) / stopped["index"] if stopped else float(frame.iloc[-1, 0])
        described = {"quantity": frame.columns[0], "unit": "N m" if frame.columns[0] == "load_nm" else "N",
                     "from": float(frame.iloc[0, 0]), "to": last, "n": int(n)}
        column = frame.columns[0]
    frame = frame.rename(columns={"K_V_n_per_m": "K_V_static_n_per_m", "K_H_n_per_m": "K_H_static_n_per_m",
                                  "K_gamma_nm_per_rad": "K_gamma_static_nm_per_rad"})
    apparent = [apparent_stiffness_n_per_m(guide.mass_kg, {"vertical": fv, "roll_low": fh})
                for fv, fh in zip(frame["f_vertical_hz"], frame["f_roll_low_hz"])]
    frame["K_V_apparent_n_per_m"] = [a["K_V"] for a in apparent]
    frame["K_H_apparent_n_per_m"] = [a["K_H"] for a in apparent]
    frame.attrs["sweep"] = {**described, "column": column}
    frame.attrs["limit"] = None
    if "stopped_at" in frame.attrs:
        frame.attrs["limit"] = sweep_limit(guide, frame, calibration)
    return frame


#: Names of the swept load in the lift-off message (column -> name).
_LOAD_NAMES = {"F_V_n": "F_V", "F_H_n": "F_H", "M_gamma_nm": "M_gamma", "load_n": "load", "load_nm": "moment"}


def sweep_limit(guide, frame, calibration: str = "nominal", rtol: float = 1e-7) -> dict:
    """Where and why a sweep ended early: the largest load the static model can hold.

    ``frame`` is a sweep that stopped (``frame.attrs["stopped_at"]`` of
    :func:`guidefit.model.static.sweep`): between its last load and the one it
    could not hold, bisection on the straight path finds the limit to ``rtol``
    of that step. Returns a JSON-ready dictionary: ``value`` (the limit along
    the sweep, in ``unit``), ``quantity`` (the column swept), ``load``
    (F_V_n, F_H_n, M_gamma_nm there), ``rows_lifted`` just past it, ``reason``,
    ``message`` (one line), ``points_computed``, ``points_requested``.

    >>> from guidefit.model.guides import load_guide
    >>> frame = predict_sweep(load_guide("MRB35"), sweep=("FV", 0.0, 3000.0, 4))
    >>> len(frame), round(frame.attrs["limit"]["value"])
    (2, 1071)
    """
    from guidefit.errors import ModelError
    from guidefit.model import static

    stopped = frame.attrs["stopped_at"]
    sweep = frame.attrs.get("sweep", {})
    column = sweep.get("column", frame.columns[0])
    last = frame.iloc[-1]
    good = np.array([last["F_V_n"], last["F_H_n"], last["M_gamma_nm"]], dtype=float)
    bad = np.asarray(stopped["load"], dtype=float)
    lo, hi = 0.0, 1.0

    def holds(t):
        try:
            static.tangent_stiffness(guide, good + t * (bad - good), calibration)
        except ModelError:
            return False
        return True

    while hi - lo > rtol:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if holds(mid) else (lo, mid)
    limit, beyond = good + lo * (bad - good), good + hi * (bad - good)
    if column in SWEEP_QUANTITIES_COLUMNS:  # --sweep Q:FROM:TO:N: the swept component
        i = SWEEP_QUANTITIES_COLUMNS.index(column)
        v_good, v_bad = good[i], bad[i]
    else:  # bare --sweep: the load along the sweep, the frame's first column
        v_good, v_bad = float(last.iloc[0]), stopped["value"]
    value = float(v_good + lo * (v_bad - v_good))
    unit = sweep.get("unit", "N m" if column.endswith("_nm") else "N")
    name = _LOAD_NAMES.get(column, column)
    where = f"{name} = {value:.4g} {unit}"
    if name in ("load", "moment") and np.count_nonzero(limit) > 1:
        where += f" (F_V = {limit[0]:.4g} N, F_H = {limit[1]:.4g} N, M_gamma = {limit[2]:.4g} N m)"
    computed, requested = len(frame), int(sweep.get("n", stopped["index"] + 1))
    try:
        rows = list(static.solve_equilibrium(guide, beyond, calibration).rows_lifted)
    except ModelError as exc:  # capacity or no equilibrium: the static model's own reason
        rows, reason = [], str(exc).split(": ", 1)[-1]
        message = f"the contacts cannot carry the load above {where} ({reason}): the sweep ends there"
    else:
        lifted = ("rollers lift off" if not rows else f"row {rows[0]} lifts off" if len(rows) == 1
                  else f"rows {', '.join(map(str, rows))} lift off")
        reason = f"{lifted}: the rollers left in contact cannot hold the carriage (tangent stiffness singular)"
        message = f"{lifted} above {where} and the rest cannot hold the carriage: the sweep ends there"
    message += f" ({computed} of {requested} loads computed)"
    return {"value": value, "quantity": column, "unit": unit,
            "load": {"F_V_n": float(limit[0]), "F_H_n": float(limit[1]), "M_gamma_nm": float(limit[2])},
            "rows_lifted": rows, "reason": reason, "message": message,
            "points_computed": computed, "points_requested": requested}


def sweep_document(frame, guide_name: str, calibration: str) -> dict:
    """The one JSON document of ``predict --sweep --json``: what was swept, the meaning of each
    stiffness, and one object per load."""
    return {"guide": guide_name, "calibration": calibration, "sweep": frame.attrs.get("sweep", {}),
            "stiffness_meaning": {"K_*_static": STIFFNESS_KINDS["static_at_load"],
                                  "K_*_apparent": STIFFNESS_KINDS["apparent_single_dof"]},
            "rows": frame.to_dict(orient="records"), "limit": frame.attrs.get("limit")}


from guidefit._api import make_callable  # noqa: E402

make_callable(__name__, "predict")
