"""Static stiffness of the preloaded roller carriage (paper Eq. 1-4).

Each roller is a Hertz line contact on the rail raceway and another on the
carriage raceway, in series. Palmgren's line-contact law gives the approach of
one contact, ``delta_c [mm] = 3.84e-5 Q^0.9 / L^0.8`` (Q in N, L the effective
contact length in mm), i.e. ``Q = k_l L^(8/9) delta_c^(10/9)``; the two contacts
carry the same force, so the roller approach is ``delta = 2 delta_c`` and::

    Q(delta) = C delta^(10/9),    K_n(delta) = dQ/d delta = (10/9) C delta^(1/9)

with ``C = k_l L^(8/9) / 2^(10/9)`` (Eq. 3-4, see :func:`roller_force`). Rollers
carry compression only: ``Q = 0`` for ``delta <= 0``.

Kinematics and sign convention
------------------------------
The carriage coordinates are those of :mod:`guidefit.model.vibration`,
``q = (u, v, theta, psi, phi)``, with the gradients ``g`` of
:func:`~guidefit.model.vibration.roller_gradients` (``g . q`` is the carriage
motion along the roller's contact normal ``n`` of Eq. 9). The normal ``n`` is
the direction in which the roller pushes the carriage: rows 1 and 2
(``n_y = +sin b``, the upper rows at depth h1) carry the carriage on the rail,
rows 3 and 4 (``n_y = -sin b``) hold it against lift-off. A carriage moving
against ``n`` compresses the roller, so each roller's approach is::

    delta_i = Delta - g_i . q          (Delta = the guide's preload_m)

and the equilibrium of the carriage under the generalised external force
``f = (F_x, F_y, M_x, M_y, M_z)`` acting at the load point (the origin) is
Eq. (1)::

    f + sum_i Q_i(delta_i) g_i = 0

The paper's load ``(F_V, F_H, M_gamma)`` is ``F_V`` positive when it presses the
carriage down onto the rail (``F_y = -F_V``), ``F_H`` along +x (``F_x``) and
``M_gamma`` the roll moment about +z (``M_z``). The displacements follow the
loads: ``delta_V = -v`` (positive downward), ``delta_H = u``, ``gamma = phi``.
The tangent stiffness (Eq. 2) is ``K_t = df/dq = sum_i K_n,i g_i g_i^T``;
``K_V = dF_V/d delta_V``, ``K_H = dF_H/d delta_H`` and ``K_gamma = dM_gamma/d gamma``
are its diagonal entries (the other displacements held fixed).

The equilibrium minimises the convex potential
``sum_i W(delta_i) - f . q`` (``W = integral of Q``), which Newton's method with
the analytic Jacobian and an Armijo line search finds from ``q = 0`` for any
load the rollers can carry.

Examples
--------
>>> from guidefit.model.guides import load_guide
>>> from guidefit.model.static import tangent_stiffness
>>> st = tangent_stiffness(load_guide("MRB35"), (500.0, 0.0, 0.0))
>>> f"{st.K_V:.3e} N/m, delta_V = {st.delta_V * 1e6:.3f} um, lifted: {st.rows_lifted}"
'1.069e+09 N/m, delta_V = 0.464 um, lifted: ()'
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from guidefit.errors import ModelError

#: Palmgren's line contact: delta_c [mm] = PALMGREN_MM * Q^0.9 / L^0.8 (Q in N, L in mm).
PALMGREN_MM = 3.84e-5
#: Exponent of the load-approach law, Q ~ delta^(10/9).
EXPONENT = 10.0 / 9.0
#: k_l in SI (N m^(-19/9)): Q = k_l L^(8/9) delta_c^(10/9) with L, delta_c in m (8.06e10).
K_L_SI = PALMGREN_MM ** (-EXPONENT) * 1e6
#: Contact stress at the static load rating of roller contacts (ISO 76, ISO 14728-2), Pa.
STATIC_RATING_STRESS_PA = 4.0e9
#: Steel on steel: Young's modulus (Pa) and Poisson's ratio of rollers and raceways.
STEEL_E_PA, STEEL_NU = 2.1e11, 0.3

#: The calibrations of the contact constant, by name.
CALIBRATIONS = {
    "law": "Palmgren's law with the guide's roller length (the law's own stiffness)",
    "nominal": "the law's constant scaled so that K_n at the preload is the guide's roller_stiffness_n_per_m",
}

#: Load directions of :func:`load_deflection`: (index in (F_V, F_H, M_gamma), load column,
#: displacement column, stiffness column, q index).
DIRECTIONS = {
    "V": (0, "F_V_n", "delta_V_m", "K_V_n_per_m", 1),
    "H": (1, "F_H_n", "delta_H_m", "K_H_n_per_m", 0),
    "gamma": (2, "M_gamma_nm", "gamma_rad", "K_gamma_nm_per_rad", 4),
}

_TOL = 1e-11  # relative residual at which Newton stops
_MAX_ITER = 200


@dataclass(frozen=True)
class Equilibrium:
    """The carriage's static equilibrium under one load (Eq. 1).

    ``generalized_force`` is ``f = (F_x, F_y, M_x, M_y, M_z)`` (N, N m) acting
    at the load point; ``displacement_q`` is ``q = (u, v, theta, psi, phi)``
    (m, rad). Per roller, in the order of
    :func:`~guidefit.model.vibration.rollers_from_guide`: approach (m, negative
    when lifted off), load Q (N) and tangent stiffness K_n (N/m).
    """

    guide_name: str
    calibration: str
    load: tuple[float, ...]  # as given: (F_V, F_H, M_gamma) or the 5 generalised forces
    generalized_force: np.ndarray  # (5,)
    displacement_q: np.ndarray  # (5,)
    approach_m: np.ndarray  # (N,)
    roller_load_n: np.ndarray  # (N,)
    roller_stiffness_n_per_m: np.ndarray  # (N,)
    row: np.ndarray  # (N,) 1..4
    gradients: np.ndarray  # (N, 5) g_i of vibration.roller_gradients
    rows_lifted: tuple[int, ...]  # rows with every roller unloaded
    rows_partial: tuple[int, ...]  # rows with some rollers unloaded
    iterations: int
    residual_rel: float

    @property
    def tangent_matrix(self) -> np.ndarray:
        """Tangent stiffness df/dq = sum_i K_n,i g_i g_i^T (Eq. 2), 5x5 in (u, v, theta, psi, phi)."""
        g = self.gradients
        return (g * self.roller_stiffness_n_per_m[:, None]).T @ g

    def to_frame(self):
        """One row per roller: row, z_index, approach_m, load_n, stiffness_n_per_m."""
        import pandas as pd

        n_z = len(self.row) // 4
        return pd.DataFrame({
            "row": self.row,
            "z_index": np.tile(np.arange(n_z), 4),
            "approach_m": self.approach_m,
            "load_n": self.roller_load_n,
            "stiffness_n_per_m": self.roller_stiffness_n_per_m,
        })


@dataclass(frozen=True)
class StaticStiffness:
    """Tangent stiffness of the carriage at a static load (Eq. 2) and what it rests on.

    ``K_V`` (N/m), ``K_H`` (N/m), ``K_gamma`` (N m/rad): the paper's partial
    derivatives, the other displacements held fixed (diagonal entries of
    ``tangent_matrix``). ``K_V_free`` etc.: the same with the other four
    coordinates free to move (static condensation, 1 / (K_t^-1)_jj), i.e. the
    slope of a load-deflection curve in that direction alone.
    ``delta_V`` (m, positive downward), ``delta_H`` (m, along +x), ``gamma``
    (rad, about +z): the displacement. ``roller_stiffness_n_per_m`` (N,) plugs
    into :func:`guidefit.model.vibration.with_roller_stiffness`.
    ``K_n_law_n_per_m`` and ``K_n_nominal_n_per_m``: a roller's tangent stiffness
    at zero load (approach = preload) under each calibration (NaN when the
    guide lacks the data); ``calibration_factor``: the constant in use over the
    law's own (1 for ``law``).
    """

    guide_name: str
    calibration: str
    load: tuple[float, ...]
    K_V: float
    K_H: float
    K_gamma: float
    K_V_free: float
    K_H_free: float
    K_gamma_free: float
    tangent_matrix: np.ndarray  # (5, 5), N/m, N, N m/rad over (u, v, theta, psi, phi)
    delta_V: float
    delta_H: float
    gamma: float
    displacement_q: np.ndarray  # (5,)
    roller_stiffness_n_per_m: np.ndarray  # (N,)
    roller_load_n: np.ndarray  # (N,)
    rows_lifted: tuple[int, ...]
    rows_partial: tuple[int, ...]
    K_n_law_n_per_m: float
    K_n_nominal_n_per_m: float
    calibration_factor: float
    equilibrium: Equilibrium

    def to_frame(self):
        """The scalar results as a two-column table (quantity, value) in SI."""
        import pandas as pd

        rows = [
            ("K_V_n_per_m", self.K_V), ("K_H_n_per_m", self.K_H), ("K_gamma_nm_per_rad", self.K_gamma),
            ("K_V_free_n_per_m", self.K_V_free), ("K_H_free_n_per_m", self.K_H_free),
            ("K_gamma_free_nm_per_rad", self.K_gamma_free),
            ("delta_V_m", self.delta_V), ("delta_H_m", self.delta_H), ("gamma_rad", self.gamma),
            ("K_n_law_n_per_m", self.K_n_law_n_per_m), ("K_n_nominal_n_per_m", self.K_n_nominal_n_per_m),
            ("calibration_factor", self.calibration_factor),
            ("rows_lifted", ",".join(map(str, self.rows_lifted))),
        ]
        return pd.DataFrame(rows, columns=["quantity", "value"])


# --------------------------------------------------------------------------- contact law (Eq. 3-4)


def _check_calibration(calibration: str) -> None:
    if calibration not in CALIBRATIONS:
        raise ModelError(f"calibration '{calibration}': allowed {', '.join(CALIBRATIONS)}")


def exponent(guide) -> float:
    """Exponent e of the guide's load-approach law Q = C delta^e: 10/9 for rollers (Eq. 4), 3/2 for balls (Eq. 3).

    >>> from guidefit.model.guides import load_guide
    >>> round(exponent(load_guide("MRB35")), 4)
    1.1111
    """
    from guidefit.model.contact import BALL_EXPONENT

    return BALL_EXPONENT if getattr(guide, "is_ball", False) else EXPONENT


def law_constant(guide) -> float:
    """The contact law's own constant C of Q = C delta^e (N m^(-e)), delta the element's approach.

    Balls: ``C = k_h`` of Eq. (3), Hertz point contact on the rail and carriage
    grooves in series (:func:`guidefit.model.contact.ball_law_constant`).
    Rollers: Palmgren's constant (N m^(-10/9)), as follows.

    Two contacts of length L in series: ``C = k_l L^(8/9) / 2^(10/9)``,
    ``k_l = (3.84e-5)^(-10/9)`` in N and mm (:data:`K_L_SI` in SI). Scaled by the
    guide's effective roller fraction, like the vibration model's K_n.

    >>> from guidefit.model.guides import load_guide
    >>> f"{law_constant(load_guide('MRB35')):.4e}"
    '3.4206e+08'
    """
    if getattr(guide, "is_ball", False):
        from guidefit.model.contact import ball_law_constant

        return ball_law_constant(guide) * guide.effective_roller_fraction
    L = guide.roller_length_m
    if L is None:
        raise ModelError(f"guide '{guide.name}': calibration 'law' needs field 'contact.roller_length_m'")
    return K_L_SI * L ** (8.0 / 9.0) / 2.0**EXPONENT * guide.effective_roller_fraction


def contact_constant(guide, calibration: str = "nominal") -> float:
    """The constant C of Q = C delta^(10/9) under a calibration (N m^(-10/9)).

    ``"law"``: :func:`law_constant`. ``"nominal"``: C such that the zero-load
    roller stiffness, K_n(Delta) = (10/9) C Delta^(1/9), equals the guide's
    ``roller_stiffness_n_per_m`` times its effective roller fraction (the
    vibration model's K_n); needs a preload.

    >>> from guidefit.model.guides import load_guide
    >>> g = load_guide("MRB35")
    >>> round(contact_constant(g, "nominal") / contact_constant(g, "law"), 4)
    0.3262
    """
    _check_calibration(calibration)
    if calibration == "law":
        return law_constant(guide)
    delta = guide.preload_m
    if not delta > 0:
        raise ModelError(
            f"guide '{guide.name}': calibration 'nominal' needs field 'contact.preload_m' > 0 "
            "(a contact without preload has no stiffness at zero load)"
        )
    k_n = guide.roller_stiffness_n_per_m * guide.effective_roller_fraction
    e = exponent(guide)
    return k_n / (e * delta ** (e - 1.0))


def roller_force(approach_m, guide, calibration: str = "nominal") -> np.ndarray:
    """Element load Q (N) at an approach delta (m): Q = C delta^e, 0 when delta <= 0 (lift-off).

    Balls: e = 3/2, Eq. (3), ``Q = k_h alpha^(3/2)`` (:mod:`guidefit.model.contact`).
    Rollers: e = 10/9, as follows.

    Palmgren's line-contact law, the roller form of the paper's Eq. (3)
    (which the paper writes for balls): per contact
    ``delta_c [mm] = 3.84e-5 Q^0.9 / L^0.8``, two contacts in series
    (``delta = 2 delta_c``). ``C`` comes from :func:`contact_constant`. This is
    the single place where the load-approach law lives; its derivative is
    :func:`roller_stiffness` (Eq. 4).

    Parameters
    ----------
    approach_m : float or array
        Roller approach delta (m), the preload included; negative is a gap.
    guide : Guide
    calibration : {"nominal", "law"}

    Returns
    -------
    ndarray
        Q (N), same shape as ``approach_m``.

    Examples
    --------
    >>> from guidefit.model.guides import load_guide
    >>> g = load_guide("MRB35")
    >>> roller_force([-1e-6, 0.0, 0.72e-6], g, "law").round(2)
    array([ 0.  ,  0.  , 51.16])
    """
    c = contact_constant(guide, calibration)
    a = np.maximum(np.asarray(approach_m, dtype=float), 0.0)
    return c * a ** exponent(guide)


def roller_stiffness(approach_m, guide, calibration: str = "nominal") -> np.ndarray:
    """Element normal stiffness K_n = dQ/d delta (N/m) at an approach delta (m), Eq. (4) or (3).

    Balls: ``K_n = (3/2) k_h alpha^(1/2)``, Eq. (3). Rollers as follows.

    ``K_n = (10/9) C delta^(1/9)`` (0 when delta <= 0): the paper's first form
    of Eq. (4), ``K_n = (10/9) k_l L^(8/9) delta^(1/9)``, for the two contacts of a
    roller in series. The paper's second form of Eq. (4) is misprinted as
    ``K_n = K_V / (4 Z sin b)``; Eq. (11) requires ``K_n = K_V / (4 Z sin^2 b)``
    (at 45 degrees the printed form is 29 % low); guidefit uses sin^2 b.

    Examples
    --------
    >>> from guidefit.model.guides import load_guide
    >>> g = load_guide("MRB35")
    >>> f"{float(roller_stiffness(g.preload_m, g, 'law')):.4e}"
    '7.8949e+07'
    >>> f"{float(roller_stiffness(g.preload_m, g, 'nominal')):.4e}"
    '2.5754e+07'
    """
    c = contact_constant(guide, calibration)
    a = np.maximum(np.asarray(approach_m, dtype=float), 0.0)
    e = exponent(guide)
    return e * c * a ** (e - 1.0)


def roller_capacity_n(guide) -> float | None:
    """Static capacity of one roller (N): the load at a Hertz contact stress of 4000 MPa.

    Line contact of a roller of diameter D on a flat raceway over the length L:
    ``p0 = sqrt(Q E* / (pi R L))`` with R = D/2 and E* = E / (2 (1 - nu^2)) for
    steel on steel, so ``Q0 = pi R L p0^2 / E*`` with p0 = 4000 MPa, the stress
    of the static load rating of roller contacts (ISO 76, ISO 14728-2). Loads
    beyond it are refused: the contact deforms permanently and the elastic law
    no longer holds. None when the guide lacks D or L.

    >>> from guidefit.model.guides import load_guide
    >>> round(roller_capacity_n(load_guide("MRB35")))
    4999

    A ball: the load at 4200 MPa on its more stressed contact
    (:func:`guidefit.model.contact.ball_capacity_n`).
    """
    if getattr(guide, "is_ball", False):
        from guidefit.model.contact import ball_capacity_n

        return ball_capacity_n(guide)
    if guide.roller_diameter_m is None or guide.roller_length_m is None:
        return None
    e_star = STEEL_E_PA / (2.0 * (1.0 - STEEL_NU**2))
    return math.pi * 0.5 * guide.roller_diameter_m * guide.roller_length_m * STATIC_RATING_STRESS_PA**2 / e_star


# --------------------------------------------------------------------------- loads


def load_vector(load) -> np.ndarray:
    """The generalised force f = (F_x, F_y, M_x, M_y, M_z) of a load (N, N m).

    ``load`` of length 3 is the paper's ``(F_V, F_H, M_gamma)``: F_V positive
    pressing the carriage down onto the rail (F_y = -F_V), F_H along +x,
    M_gamma the roll moment about +z. Length 5 is taken as f itself, in the
    order of the coordinates (u, v, theta, psi, phi), F_y positive upward.

    >>> load_vector((1000.0, 200.0, 5.0)).tolist()
    [200.0, -1000.0, 0.0, 0.0, 5.0]
    """
    try:
        values = np.asarray(load, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise ModelError(f"load: expected numbers (F_V, F_H, M_gamma), got {load!r}") from None
    if values.size not in (3, 5) or not np.all(np.isfinite(values)):
        raise ModelError(
            "load: expected 3 finite numbers (F_V, F_H, M_gamma) or 5 generalised forces "
            f"(F_x, F_y, M_x, M_y, M_z), got {load!r}"
        )
    if values.size == 5:
        return values.copy()
    f_v, f_h, m_g = values
    return np.array([f_h, -f_v, 0.0, 0.0, m_g])


def _describe(load) -> str:
    values = np.asarray(load, dtype=float).reshape(-1)
    if values.size == 3:
        return f"load (F_V={values[0]:g} N, F_H={values[1]:g} N, M_gamma={values[2]:g} N m)"
    names = ("F_x", "F_y", "M_x", "M_y", "M_z")
    units = ("N", "N", "N m", "N m", "N m")
    return "load (" + ", ".join(f"{n}={v:g} {u}" for n, v, u in zip(names, values, units)) + ")"


# --------------------------------------------------------------------------- equilibrium (Eq. 1)


def _gradients(guide) -> tuple[np.ndarray, np.ndarray]:
    from guidefit.model.vibration import roller_gradients, rollers_from_guide

    rollers = rollers_from_guide(guide, 0.0)
    return roller_gradients(rollers), rollers.row


def load_at_displacement(guide, displacement_q, calibration: str = "nominal") -> np.ndarray:
    """The generalised force f (N, N m) that holds the carriage at q: f = -sum_i Q_i g_i (Eq. 1).

    The forward load-deflection map; :func:`solve_equilibrium` inverts it.

    >>> from guidefit.model.guides import load_guide
    >>> f = load_at_displacement(load_guide("MRB35"), [0.0, -1e-7, 0.0, 0.0, 0.0])
    >>> f"F_V = {-f[1]:.2f} N"
    'F_V = 108.15 N'
    """
    g, _ = _gradients(guide)
    q = np.asarray(displacement_q, dtype=float).reshape(5)
    return -(g.T @ roller_force(guide.preload_m - g @ q, guide, calibration))


def _check_carried(g, f, capacity, what: str) -> None:
    """A :class:`ModelError` when the generalised load ``f`` has a component no roller can resist
    or one beyond what all rollers at ``capacity`` (N, or None) could give."""
    # components of f that no combination of roller forces can balance: f . v for v in null(G),
    # in coordinates scaled by each column's rms lever arm so that N and N m compare
    arm = np.sqrt(np.mean(g**2, axis=0))
    arm = np.where(arm > 0, arm, 1.0)
    _, sv, vt = np.linalg.svd(g / arm, full_matrices=True)
    rank = int(np.sum(sv > 1e-12 * sv[0]))
    f_scaled = f / arm
    if rank < 5 and np.any(np.abs(vt[rank:] @ f_scaled) > 1e-9 * np.linalg.norm(f_scaled)):
        raise ModelError(f"{what}: has a component that no roller can resist (rollers span only {rank} of 5 DOFs)")
    if capacity is not None:
        # necessary: each component of f within what all rollers at capacity could give
        reach = capacity * np.abs(g).sum(axis=0)
        bad = np.abs(f) > reach
        if np.any(bad):
            j = int(np.argmax(bad))
            raise ModelError(
                f"{what}: exceeds the static capacity of the contacts (component {('F_x', 'F_y', 'M_x', 'M_y', 'M_z')[j]} "
                f"|{f[j]:.4g}| > {reach[j]:.4g} with every roller at {capacity:.4g} N)"
            )


def _newton(g, f, c, e, delta0, what: str) -> tuple[np.ndarray, float, int]:
    """Eq. (1) by damped Newton from ``q = 0`` (see :func:`solve_equilibrium`): ``(q, residual_rel,
    iterations)``; a :class:`ModelError` when the line search fails or the displacement diverges."""
    w_coef = c / (e + 1.0)

    def potential(q):
        a = np.maximum(delta0 - g @ q, 0.0)
        return float(np.sum(w_coef * a ** (e + 1.0)) - f @ q)

    # a full-contact reference tangent for regularising rows that have lifted off
    k_ref = e * c * max(delta0, 1e-6) ** (e - 1.0)
    h_ref = k_ref * (g.T @ g)
    q = np.zeros(5)
    residual_rel = math.inf
    iterations = 0
    for iterations in range(_MAX_ITER + 1):
        a = delta0 - g @ q
        a_pos = np.maximum(a, 0.0)
        load_i = c * a_pos**e
        r = f + g.T @ load_i  # = -grad of the potential
        gross = np.abs(g).T @ load_i + np.abs(f)
        residual_rel = float(np.max(np.abs(r) / np.maximum(gross, 1e-300)))
        if residual_rel < _TOL or not np.any(r):
            break
        if iterations == _MAX_ITER:
            break
        k_i = e * c * a_pos ** (e - 1.0)
        h = (g * k_i[:, None]).T @ g + 1e-10 * h_ref
        try:
            dq = np.linalg.solve(h, r)
        except np.linalg.LinAlgError:  # coordinates no roller restrains (r has no part there)
            dq = np.linalg.lstsq(h, r, rcond=None)[0]
        slope = float(r @ dq)  # = -grad . dq > 0
        p0 = potential(q)
        magnitude = np.sum(w_coef * a_pos ** (e + 1.0)) + abs(f @ q) + abs(f @ dq)
        t = 1.0
        if slope > 1e-13 * magnitude:  # below that the potential cannot resolve the decrease
            for _ in range(80):
                if potential(q + t * dq) <= p0 - 1e-4 * t * slope:
                    break
                t *= 0.5
            else:
                raise ModelError(f"{what}: no static equilibrium found (line search failed); the contacts cannot carry it")
        q = q + t * dq
        if not np.all(np.isfinite(q)) or np.max(np.abs(q)) > 1.0:
            raise ModelError(f"{what}: no static equilibrium found (displacement diverges); the contacts cannot carry it")
    return q, residual_rel, iterations


def _rows_off(a, rows) -> tuple[list[int], list[int]]:
    """The rows (1-4) whose rollers have all lifted off (approach ``a <= 0``), and those partly."""
    lifted, partial = [], []
    for row in range(1, 5):
        off = a[rows == row] <= 0.0
        if np.all(off):
            lifted.append(row)
        elif np.any(off):
            partial.append(row)
    return lifted, partial


def solve_equilibrium(guide, load, calibration: str = "nominal") -> Equilibrium:
    """Displacement of the carriage under a static load: Eq. (1) by damped Newton.

    Solves ``f + sum_i Q_i(Delta - g_i . q) g_i = 0`` from ``q = 0`` with the
    analytic Jacobian ``sum_i K_n,i g_i g_i^T`` (Eq. 2). Each step is a Newton
    step (lightly regularised where rows have lifted off) shortened by an Armijo
    line search on the convex potential ``sum_i W(delta_i) - f . q``, so it
    converges for every load the rollers can carry; it stops at a residual of
    1e-11 relative to the gross roller forces in each coordinate.

    Parameters
    ----------
    guide : Guide
    load : sequence of 3 or 5 floats
        ``(F_V, F_H, M_gamma)`` in N, N, N m (F_V positive pressing the carriage
        onto the rail) or the generalised forces (see :func:`load_vector`).
    calibration : {"nominal", "law"}

    Returns
    -------
    Equilibrium

    Raises
    ------
    ModelError
        One line naming the load: a load component no roller can resist, a
        roller load beyond :func:`roller_capacity_n`, or no convergence.

    Examples
    --------
    >>> from guidefit.model.guides import load_guide
    >>> eq = solve_equilibrium(load_guide("MRB35"), (2000.0, 0.0, 0.0))
    >>> eq.rows_lifted, round(float(-eq.displacement_q[1]) * 1e6, 3)
    ((3, 4), 2.556)
    """
    f = load_vector(load)
    c = contact_constant(guide, calibration)
    what = _describe(load)
    g, rows = _gradients(guide)
    delta0 = guide.preload_m
    capacity = roller_capacity_n(guide)

    _check_carried(g, f, capacity, what)
    e = exponent(guide)
    q, residual_rel, iterations = _newton(g, f, c, e, delta0, what)
    if residual_rel >= _TOL * 100:
        raise ModelError(
            f"{what}: no static equilibrium found (Newton stopped at residual {residual_rel:.2g} "
            f"after {iterations} iterations)"
        )
    a = delta0 - g @ q
    load_i = c * np.maximum(a, 0.0) ** e
    if capacity is not None and load_i.max() > capacity:
        i = int(np.argmax(load_i))
        raise ModelError(
            f"{what}: exceeds the static capacity of the contacts (roller load {load_i[i]:.4g} N in row "
            f"{rows[i]} > {capacity:.4g} N at {4200 if getattr(guide, 'is_ball', False) else 4000} MPa contact stress)"
        )
    lifted, partial = _rows_off(a, rows)
    return Equilibrium(
        guide_name=guide.name,
        calibration=calibration,
        load=tuple(float(x) for x in np.asarray(load, dtype=float).reshape(-1)),
        generalized_force=f,
        displacement_q=q,
        approach_m=a,
        roller_load_n=load_i,
        roller_stiffness_n_per_m=e * c * np.maximum(a, 0.0) ** (e - 1.0),
        row=rows,
        gradients=g,
        rows_lifted=tuple(lifted),
        rows_partial=tuple(partial),
        iterations=iterations,
        residual_rel=residual_rel,
    )


# --------------------------------------------------------------------------- stiffness (Eq. 2)


def _free_stiffness(k: np.ndarray) -> np.ndarray:
    """1 / (K^-1)_jj per coordinate; 0 where the coordinate can move without resistance."""
    d = 1.0 / np.sqrt(np.maximum(np.diag(k), 1e-300))
    ks = k * d[:, None] * d[None, :]
    lam, vec = np.linalg.eigh(ks)
    good = lam > 1e-10 * max(lam.max(), 1e-300)
    out = np.zeros(5)
    for j in range(5):
        if np.any(np.abs(vec[j, ~good]) > 1e-8):
            continue
        inv_jj = np.sum(vec[j, good] ** 2 / lam[good]) * d[j] ** 2
        out[j] = 1.0 / inv_jj
    return out


def _singular(k: np.ndarray) -> bool:
    diag = np.diag(k)
    if np.any(diag <= 0):
        return True
    d = 1.0 / np.sqrt(diag)
    lam = np.linalg.eigvalsh(k * d[:, None] * d[None, :])
    return bool(lam[0] <= 1e-10 * lam[-1])


def tangent_stiffness(guide, load=(0.0, 0.0, 0.0), calibration: str = "nominal") -> StaticStiffness:
    """K_V, K_H, K_gamma of the carriage at a static load (Eq. 1-2).

    Solves the equilibrium (:func:`solve_equilibrium`) and differentiates it
    analytically: ``K_t = sum_i K_n,i g_i g_i^T`` with each roller's tangent
    stiffness from :func:`roller_stiffness` (Eq. 4). ``K_V``, ``K_H`` and
    ``K_gamma`` are the paper's partial derivatives (Eq. 2, the other
    displacements held); the ``*_free`` fields let the others move.

    Parameters
    ----------
    guide : Guide
    load : sequence of 3 or 5 floats
        ``(F_V, F_H, M_gamma)``: N, N, N m; F_V positive pressing the carriage
        onto the rail, F_H along +x, M_gamma about +z. Or the 5 generalised
        forces of :func:`load_vector`.
    calibration : {"nominal", "law"}
        ``nominal`` (default) scales the contact constant so that the zero-load
        roller stiffness is the guide's K_n, so that this model and the
        vibration model agree; ``law`` uses Palmgren's constant as it stands.

    Raises
    ------
    ModelError
        As :func:`solve_equilibrium`, and when the rollers left in contact do
        not restrain every coordinate (singular tangent stiffness, e.g. rows 3
        and 4 completely lifted off by a pure vertical load: rows 1 and 2 alone
        leave the carriage free to rock about the point where their lines of
        action cross).

    Examples
    --------
    >>> from guidefit.model.guides import load_guide
    >>> g = load_guide("MRB35")
    >>> st = tangent_stiffness(g)
    >>> f"K_V {st.K_V:.4e} N/m, K_H {st.K_H:.4e} N/m, K_gamma {st.K_gamma:.4e} N m/rad"
    'K_V 1.0817e+09 N/m, K_H 1.0817e+09 N/m, K_gamma 2.4092e+06 N m/rad'
    >>> f"{tangent_stiffness(g, calibration='law').K_V:.3e}"
    '3.316e+09'
    """
    eq = solve_equilibrium(guide, load, calibration)
    k = eq.tangent_matrix
    if _singular(k):
        lifted = ", ".join(map(str, eq.rows_lifted)) or "none"
        try:
            hint = f"; the first roller unloads at {lift_off_load(guide, load, calibration):.3g} times this load"
        except ModelError:
            hint = ""
        raise ModelError(
            f"{_describe(load)}: the rollers left in contact do not restrain every DOF "
            f"(rows lifted off: {lifted}; tangent stiffness singular){hint}"
        )
    free = _free_stiffness(k)
    q = eq.displacement_q
    try:
        k_law = float(roller_stiffness(guide.preload_m, guide, "law"))
        factor = contact_constant(guide, calibration) / law_constant(guide)
    except ModelError:
        k_law, factor = math.nan, (1.0 if calibration == "law" else math.nan)
    try:
        k_nom = float(roller_stiffness(guide.preload_m, guide, "nominal"))
    except ModelError:
        k_nom = math.nan
    return StaticStiffness(
        guide_name=guide.name,
        calibration=calibration,
        load=eq.load,
        K_V=float(k[1, 1]),
        K_H=float(k[0, 0]),
        K_gamma=float(k[4, 4]),
        K_V_free=float(free[1]),
        K_H_free=float(free[0]),
        K_gamma_free=float(free[4]),
        tangent_matrix=k,
        delta_V=float(-q[1]) + 0.0,  # no negative zero
        delta_H=float(q[0]),
        gamma=float(q[4]),
        displacement_q=q,
        roller_stiffness_n_per_m=eq.roller_stiffness_n_per_m,
        roller_load_n=eq.roller_load_n,
        rows_lifted=eq.rows_lifted,
        rows_partial=eq.rows_partial,
        K_n_law_n_per_m=k_law,
        K_n_nominal_n_per_m=k_nom,
        calibration_factor=factor,
        equilibrium=eq,
    )


# --------------------------------------------------------------------------- load-deflection curves


def _unit_load(direction: str) -> np.ndarray:
    if direction not in DIRECTIONS:
        raise ModelError(f"direction '{direction}': allowed {', '.join(DIRECTIONS)}")
    unit = np.zeros(3)
    unit[DIRECTIONS[direction][0]] = 1.0
    return unit


def lift_off_load(guide, direction_load=(1.0, 0.0, 0.0), calibration: str = "nominal") -> float:
    """Scale s at which the first roller loses contact under the load s * direction_load.

    For the default unit vertical load this is the vertical load (N) at which
    rows 3 and 4 lift off, ``F = 2 Z sin(b) Q(2 Delta)`` for the symmetric
    rows of Eq. (9). Found by bracketing and bisection on the equilibrium
    (relative accuracy 1e-10).

    >>> from guidefit.model.guides import load_guide
    >>> g = load_guide("MRB35")
    >>> round(lift_off_load(g)), round(lift_off_load(g, calibration="law"))
    (1071, 3282)
    """
    d = np.asarray(direction_load, dtype=float).reshape(-1)
    f_dir = load_vector(d)
    if not np.any(f_dir):
        raise ModelError("lift_off_load: direction_load must not be zero")
    g, _ = _gradients(guide)
    k0 = (g * roller_stiffness(guide.preload_m - np.zeros(len(g)), guide, calibration)[:, None]).T @ g
    q_lin = np.linalg.lstsq(k0, f_dir, rcond=None)[0]
    drop = float(np.max(g @ q_lin))  # linearised fall of the smallest approach per unit s
    if not drop > 0:
        raise ModelError("lift_off_load: no roller unloads under this load direction")

    def min_approach(s):
        return float(np.min(solve_equilibrium(guide, s * d, calibration).approach_m))

    lo, hi = 0.0, guide.preload_m / drop
    for _ in range(60):
        if min_approach(hi) <= 0.0:
            break
        lo, hi = hi, 2.0 * hi
    else:
        raise ModelError("lift_off_load: no roller loses contact under this load direction")
    while hi - lo > 1e-10 * hi:
        mid = 0.5 * (lo + hi)
        if min_approach(mid) <= 0.0:
            hi = mid
        else:
            lo = mid
    return hi


def load_deflection(guide, direction: str = "V", max_load: float | None = None, n: int = 41,
                    calibration: str = "nominal"):
    """Load-deflection curve in one direction, the others unloaded (the paper's Figure 3).

    Parameters
    ----------
    guide : Guide
    direction : {"V", "H", "gamma"}
        Vertical force F_V (positive pressing down), lateral force F_H (+x) or
        roll moment M_gamma (about +z).
    max_load : float, optional
        Largest load (N or N m; negative to load the other way). Default twice
        the load at which the first roller lifts off.
    n : int
        Number of points from 0 to ``max_load``.
    calibration : {"nominal", "law"}

    Returns
    -------
    pandas.DataFrame
        Columns: load (``F_V_n`` / ``F_H_n`` / ``M_gamma_nm``), displacement
        (``delta_V_m`` / ``delta_H_m`` / ``gamma_rad``), the partial tangent
        stiffness of Eq. (2) (``K_V_n_per_m`` ...), the slope of this curve
        (``K_V_free_n_per_m`` ..., 0 where the carriage can move freely),
        ``n_rows_lifted`` and ``n_rollers_unloaded``. ``attrs`` holds guide,
        direction, calibration and the lift-off load.

    Examples
    --------
    >>> from guidefit.model.guides import load_guide
    >>> frame = load_deflection(load_guide("MRB35"), "V", max_load=3000.0, n=4)
    >>> frame[["F_V_n", "n_rows_lifted"]].values.tolist()
    [[0.0, 0.0], [1000.0, 0.0], [2000.0, 2.0], [3000.0, 2.0]]
    """
    import pandas as pd

    unit = _unit_load(direction)
    _, load_col, disp_col, k_col, q_index = DIRECTIONS[direction]
    if not (isinstance(n, int | np.integer) and n >= 2):
        raise ModelError(f"load_deflection: n must be an integer >= 2, got {n!r}")
    sign = 1.0 if max_load is None or max_load >= 0 else -1.0
    lift = lift_off_load(guide, sign * unit, calibration)
    if max_load is None:
        max_load = 2.0 * lift
    if not math.isfinite(max_load):
        raise ModelError(f"load_deflection: max_load must be finite, got {max_load!r}")
    loads = np.linspace(0.0, float(max_load), n)
    disp_sign = -1.0 if direction == "V" else 1.0
    rows = []
    for value in loads:
        eq = solve_equilibrium(guide, value * unit, calibration)
        k = eq.tangent_matrix
        free = _free_stiffness(k)
        rows.append((value, disp_sign * eq.displacement_q[q_index] + 0.0, k[q_index, q_index], free[q_index],
                     len(eq.rows_lifted), int(np.sum(eq.approach_m <= 0.0))))
    k_free_col = k_col.replace("K_V", "K_V_free").replace("K_H", "K_H_free").replace("K_gamma", "K_gamma_free")
    frame = pd.DataFrame(rows, columns=[load_col, disp_col, k_col, k_free_col, "n_rows_lifted",
                                        "n_rollers_unloaded"])
    frame.attrs.update(guide=guide.name, direction=direction, calibration=calibration,
                       lift_off_load=sign * lift)
    return frame


def plot_load_deflection(frames, path) -> None:
    """Write load-deflection curves (frames of :func:`load_deflection`) to a PNG.

    ``frames`` is one DataFrame, a list of them or a dict label -> frame.
    Displacements are drawn in um (mrad for roll), loads in kN (N m for a
    moment); the first point where a roller has lost contact is marked.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if isinstance(frames, dict):
        items = list(frames.items())
    elif isinstance(frames, list | tuple):
        items = [(None, fr) for fr in frames]
    else:
        items = [(None, frames)]
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for label, frame in items:
        load_col, disp_col = frame.columns[0], frame.columns[1]
        x_scale, x_unit = (1e6, "um") if disp_col.endswith("_m") else (1e3, "mrad")
        y_scale, y_unit = (1e-3, "kN") if load_col.endswith("_n") else (1.0, "N m")
        if label is None:
            label = f"{frame.attrs.get('direction', load_col)} ({frame.attrs.get('calibration', '')})"
        x = frame[disp_col].to_numpy() * x_scale
        y = frame[load_col].to_numpy() * y_scale
        (line,) = ax.plot(x, y, label=label)
        off = np.flatnonzero(frame["n_rollers_unloaded"].to_numpy() > 0)
        if off.size:
            ax.plot(x[off[0]], y[off[0]], "o", color=line.get_color())
        ax.set_xlabel(f"displacement ({x_unit})")
        ax.set_ylabel(f"load ({y_unit})")
    ax.set_title("load-deflection, Eq. (1)-(4); o: first roller unloaded")
    ax.grid(True, alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# --------------------------------------------------------------------------- sweeps for predict


def sweep(guide, loads=None, *, direction_load=None, n: int = 21, calibration: str = "nominal",
          stop_at_limit: bool = False):
    """Static stiffness and natural frequencies over a range of loads (``guidefit predict --sweep``).

    At each load the static model (:func:`tangent_stiffness`) gives every
    roller's tangent stiffness, which becomes that roller's spring in the
    vibration model (``vibration.with_roller_stiffness``, ``solve_modes``).

    Parameters
    ----------
    guide : Guide
    loads : sequence of loads, optional
        Explicit loads ``(F_V, F_H, M_gamma)``. Otherwise ``n`` loads
        ``s * direction_load`` for s from 0 to 1; without ``direction_load``,
        vertical loads from 0 to 90 % of the load at which rows lift off.
    direction_load : (F_V, F_H, M_gamma), optional
    n : int
    calibration : {"nominal", "law"}
    stop_at_limit : bool
        At the first load after the first that the model cannot hold (rows
        lifted so that the rest cannot restrain the carriage, capacity, no
        equilibrium: :func:`tangent_stiffness` raises) end the sweep there
        instead of raising: the frame holds the loads before it and
        ``frame.attrs["stopped_at"]`` = ``{"index", "load", "value", "error"}``
        (``value``: that load along the sweep, the first column). A first
        load that cannot be held raises either way.

    Returns
    -------
    pandas.DataFrame
        ``load_n`` (the load along the sweep: the signed projection of the
        force part (F_V, F_H) on the direction of the largest load; named
        ``load_nm`` for a pure moment sweep), ``F_V_n``, ``F_H_n``,
        ``M_gamma_nm``, ``K_V_n_per_m``, ``K_H_n_per_m``, ``K_gamma_nm_per_rad``,
        ``delta_V_m``, ``delta_H_m``, ``gamma_rad``, ``f_<label>_hz`` for each
        mode (vertical, pitch, yaw, roll_low, roll_high), ``rows_lifted``
        (e.g. ``"3,4"``) and ``n_rows_lifted``.

    Examples
    --------
    >>> from guidefit.model.guides import load_guide
    >>> frame = sweep(load_guide("MRB35"), [(0.0, 0.0, 0.0), (800.0, 0.0, 0.0)])
    >>> frame["f_vertical_hz"].round(1).tolist()
    [3529.0, 3463.3]
    """
    import pandas as pd

    from guidefit.model import vibration as vib

    if loads is None:
        if direction_load is None:
            direction_load = (0.9 * lift_off_load(guide, (1.0, 0.0, 0.0), calibration), 0.0, 0.0)
        d = np.asarray(direction_load, dtype=float).reshape(-1)
        if d.size != 3:
            raise ModelError(f"sweep: direction_load must be (F_V, F_H, M_gamma), got {direction_load!r}")
        loads = [s * d for s in np.linspace(0.0, 1.0, n)]
    loads = [np.asarray(x, dtype=float).reshape(-1) for x in loads]
    if not loads or any(x.size != 3 for x in loads):
        raise ModelError("sweep: loads must be a non-empty list of (F_V, F_H, M_gamma)")
    forces = np.array([x[:2] for x in loads])
    biggest = forces[np.argmax(np.linalg.norm(forces, axis=1))]
    if np.any(biggest):
        axis = biggest / np.linalg.norm(biggest)
        axis = axis if axis[np.flatnonzero(axis)[0]] > 0 else -axis
        first = ("load_n", forces @ axis)
    else:
        first = ("load_nm", np.array([x[2] for x in loads]))
    base = vib.model_from_guide(guide)
    records = []
    for i, x in enumerate(loads):
        try:
            st = tangent_stiffness(guide, x, calibration)
        except ModelError as exc:
            if not (stop_at_limit and records):
                raise
            stopped = {"index": i, "load": tuple(float(v) for v in x), "value": float(first[1][i]),
                       "error": str(exc)}
            break
        sol = vib.solve_modes(vib.with_roller_stiffness(base, st.roller_stiffness_n_per_m))
        rec = {
            "F_V_n": x[0], "F_H_n": x[1], "M_gamma_nm": x[2],
            "K_V_n_per_m": st.K_V, "K_H_n_per_m": st.K_H, "K_gamma_nm_per_rad": st.K_gamma,
            "delta_V_m": st.delta_V, "delta_H_m": st.delta_H, "gamma_rad": st.gamma,
        }
        for label in vib.MODE_LABELS:
            rec[f"f_{label}_hz"] = sol.frequency_hz(label)
        rec["rows_lifted"] = ",".join(map(str, st.rows_lifted))
        rec["n_rows_lifted"] = len(st.rows_lifted)
        records.append(rec)
    else:
        stopped = None
    frame = pd.DataFrame(records)
    frame.insert(0, first[0], first[1][: len(records)])
    frame.attrs.update(guide=guide.name, calibration=calibration)
    if stopped is not None:
        frame.attrs["stopped_at"] = stopped
    return frame
