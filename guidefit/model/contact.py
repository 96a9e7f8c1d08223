"""Hertz point contact of a ball between two grooves: the paper's Eq. (3).

A ball of diameter D runs in a groove of the rail and a groove of the carriage.
Each groove is straight along the rail (no curvature in the rolling direction)
and a circular arc of radius r = f D across it, f the groove's conformity
(0.52 for a typical circular-arc groove, slightly above 0.5). Each contact is a
Hertz point contact with an elliptical contact area (Harris & Kotzalas,
*Rolling Bearing Analysis*, 5th ed., vol. 1, ch. 6; Hamrock, *Fundamentals of
Fluid Film Lubrication*, NASA RP-1255, 1991, ch. 6).

Curvatures (convex positive, 1/m) of body I (ball) and body II (groove) in the
rolling direction (1) and across it (2)::

    rho_I1 = rho_I2 = 2 / D,   rho_II1 = race curvature along the rolling direction (0 on a rail),
    rho_II2 = -1 / (f D)
    sum_rho = rho_I1 + rho_I2 + rho_II1 + rho_II2
    F(rho)  = (rho_I1 - rho_I2 + rho_II1 - rho_II2) / sum_rho       (= 1 / (4 f - 1) on a rail)

The ellipticity k = a / b >= 1 (a across the groove) solves exactly::

    F(rho) = ((k^2 + 1) E(m) - 2 K(m)) / ((k^2 - 1) E(m)),    m = 1 - 1/k^2

with K, E the complete elliptic integrals of the first and second kind
(``scipy.special.ellipk``, ``ellipe``, parameter m). With
E' = 2 / ((1 - nu_I^2)/E_I + (1 - nu_II^2)/E_II) and R = 1 / sum_rho::

    a     = (6 k^2 E Q R / (pi E'))^(1/3)
    b     = (6 E Q R / (pi k E'))^(1/3)
    delta = K (9 / (2 E R) (Q / (pi k E'))^2)^(1/3)                 (approach of the two bodies)
    p0    = 3 Q / (2 pi a b)

(Hamrock's form; Harris's a = a* (3 Q / (E' sum_rho))^(1/3),
delta = delta* (3 Q / (2 E'))^(2/3) (sum_rho / 2)^(1/3) is the same.) Hence
``delta = c Q^(2/3)`` and ``Q = c^(-3/2) delta^(3/2)``. The ball's two contacts
(rail, carriage) carry the same Q, so their approaches add::

    alpha = (c_rail + c_carriage) Q^(2/3)
    Q     = k_h alpha^(3/2),     k_h = (c_rail + c_carriage)^(-3/2)           Eq. (3)
    K_n   = dQ/d alpha = (3/2) k_h alpha^(1/2)

For a circular contact (k = 1: F(rho) = 0, e.g. a ball on a flat) these reduce
to the classic a = (3 Q r / (4 E*))^(1/3), delta = a^2 / r, E* = E'/2.

Examples
--------
>>> round(float(ellipticity(1.0 / (4 * 0.52 - 1))), 3)
8.136
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from guidefit.errors import ModelError

#: Exponent of the point-contact law, Q ~ alpha^(3/2) (Eq. 3).
BALL_EXPONENT = 1.5
#: Contact stress at the static load rating of ball contacts (ISO 76, ISO 14728-1), Pa.
BALL_STATIC_RATING_STRESS_PA = 4.2e9
_K_MAX = 1e4  # ellipticity bracket: conformity 0.5 + 1e-7 still inside


def _f_of_k(k: float) -> float:
    from scipy.special import ellipe, ellipk

    m = 1.0 - 1.0 / (k * k)
    e, kk = float(ellipe(m)), float(ellipk(m))
    return ((k * k + 1.0) * e - 2.0 * kk) / ((k * k - 1.0) * e)


def ellipticity(f_rho: float) -> float:
    """Ellipticity k = a/b of a Hertz point contact from its curvature difference F(rho).

    Solves ``F(rho) = ((k^2+1) E - 2 K) / ((k^2-1) E)`` exactly (complete elliptic
    integrals of parameter ``m = 1 - 1/k^2``, Harris & Kotzalas ch. 6) by Brent's
    method in ln k. ``F(rho) = 0`` is a circular contact, k = 1.

    >>> round(float(ellipticity(0.0)), 6)
    1.0
    """
    from scipy.optimize import brentq

    f_rho = float(f_rho)
    if not 0.0 <= f_rho < 1.0:
        raise ModelError(f"point contact: curvature difference F(rho) must be in [0, 1), got {f_rho:g}")
    if f_rho < 1e-7:  # F ~ (k - 1) near k = 1: the circle, to 1e-7 in k
        return 1.0
    lo = 1e-6
    if _f_of_k(math.exp(lo)) >= f_rho:
        return math.exp(lo)
    if _f_of_k(_K_MAX) <= f_rho:
        raise ModelError(f"point contact: F(rho) = {f_rho:.9g} too close to 1 (conformity too close to 0.5)")
    t = brentq(lambda t: _f_of_k(math.exp(t)) - f_rho, lo, math.log(_K_MAX), xtol=1e-14, rtol=1e-13)
    return math.exp(t)


def effective_modulus(e1_pa: float, nu1: float, e2_pa: float, nu2: float) -> float:
    """E' = 2 / ((1 - nu1^2)/E1 + (1 - nu2^2)/E2) (Pa), Hamrock's and Harris's effective modulus.

    >>> f"{effective_modulus(2.1e11, 0.3, 2.1e11, 0.3):.4e}"
    '2.3077e+11'
    """
    return 2.0 / ((1.0 - nu1**2) / e1_pa + (1.0 - nu2**2) / e2_pa)


@dataclass(frozen=True)
class PointContact:
    """One Hertz point contact: curvature sum (1/m), F(rho), E' (Pa) and the ellipse solution.

    ``k``, ``K``, ``E``: ellipticity and the complete elliptic integrals at
    ``m = 1 - 1/k^2``. ``deflection_constant`` c (m N^(-2/3)): delta = c Q^(2/3).
    """

    sum_rho: float
    f_rho: float
    e_prime_pa: float
    k: float
    K: float
    E: float

    @property
    def radius_m(self) -> float:
        """Effective radius R = 1 / sum_rho (m)."""
        return 1.0 / self.sum_rho

    @property
    def deflection_constant(self) -> float:
        """c of delta = c Q^(2/3) (m N^(-2/3))."""
        return self.K * (9.0 / (2.0 * self.E * self.radius_m) / (math.pi * self.k * self.e_prime_pa) ** 2) ** (1 / 3)

    def semi_axes_m(self, load_n):
        """(a, b): semi-axes of the contact ellipse (m), a across the groove."""
        q = np.maximum(np.asarray(load_n, dtype=float), 0.0)
        base = 6.0 * self.E * q * self.radius_m / (math.pi * self.e_prime_pa)
        return (self.k**2 * base) ** (1 / 3), (base / self.k) ** (1 / 3)

    def approach_m(self, load_n):
        """Approach delta (m) of the two bodies under the load Q (N): delta = c Q^(2/3)."""
        return self.deflection_constant * np.maximum(np.asarray(load_n, dtype=float), 0.0) ** (2 / 3)

    def max_pressure_pa(self, load_n):
        """Peak contact pressure p0 = 3 Q / (2 pi a b) (Pa)."""
        a, b = self.semi_axes_m(load_n)
        q = np.asarray(load_n, dtype=float)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(q > 0, 1.5 * q / (math.pi * a * b), 0.0)

    def load_at_pressure_n(self, p0_pa: float) -> float:
        """The load Q (N) at which the peak pressure reaches ``p0_pa`` (p0 ~ Q^(1/3))."""
        return float(p0_pa**3 / float(self.max_pressure_pa(1.0)) ** 3)


def point_contact(sum_rho: float, f_rho: float, e_prime_pa: float) -> PointContact:
    """Solve the contact ellipse of a Hertz point contact (exact elliptic integrals).

    Parameters
    ----------
    sum_rho : float
        Curvature sum (1/m), positive.
    f_rho : float
        Curvature difference F(rho) in [0, 1).
    e_prime_pa : float
        Effective modulus E' (Pa), :func:`effective_modulus`.
    """
    from scipy.special import ellipe, ellipk

    if not (sum_rho > 0 and math.isfinite(sum_rho)):
        raise ModelError(f"point contact: curvature sum must be positive, got {sum_rho:g} 1/m")
    k = ellipticity(f_rho)
    m = 1.0 - 1.0 / (k * k)
    return PointContact(sum_rho=float(sum_rho), f_rho=float(f_rho), e_prime_pa=float(e_prime_pa), k=k,
                        K=float(ellipk(m)), E=float(ellipe(m)))


def groove_contact(ball_diameter_m: float, conformity: float, e_prime_pa: float,
                   race_curvature_per_m: float = 0.0) -> PointContact:
    """A ball of diameter D in a groove of radius f D (conformity f > 0.5).

    ``race_curvature_per_m`` is the race's curvature in the rolling direction:
    0 for a straight rail or carriage groove, +2/d for the inner ring of a
    bearing at raceway diameter d, -2/d for an outer ring.

    >>> c = groove_contact(0.00635, 0.52, 2.3077e11)
    >>> round(c.f_rho, 6), round(c.sum_rho * 1e-3, 2)
    (0.925926, 0.33)
    """
    d = float(ball_diameter_m)
    if not conformity > 0.5:
        raise ModelError(f"point contact: groove conformity must exceed 0.5 (groove wider than the ball), got {conformity}")
    rho_ball = 2.0 / d
    rho_groove = -1.0 / (conformity * d)
    sum_rho = 2.0 * rho_ball + race_curvature_per_m + rho_groove
    f_rho = (race_curvature_per_m - rho_groove) / sum_rho
    return point_contact(sum_rho, f_rho, e_prime_pa)


def ball_constant(contacts) -> float:
    """k_h of Eq. (3), Q = k_h alpha^(3/2), for contacts in series carrying the same load (N m^(-3/2)).

    ``alpha = sum_j c_j Q^(2/3)``, so ``k_h = (sum_j c_j)^(-3/2)``
    (Harris & Kotzalas ch. 7: K_n = (K_i^(-2/3) + K_o^(-2/3))^(-3/2)).
    """
    return float(sum(c.deflection_constant for c in contacts)) ** (-1.5)


def hamrock_brewe(ry_over_rx: float) -> tuple[float, float, float]:
    """Hamrock & Brewe's closed-form (k, K, E) for a radius ratio Ry/Rx >= 1.

    ``k = 1.0339 (Ry/Rx)^0.6360``, ``E = 1.0003 + 0.5968 Rx/Ry``,
    ``K = 1.5277 + 0.6023 ln(Ry/Rx)`` (B. J. Hamrock, D. E. Brewe, "Simplified
    solution for stresses and deformations", J. Lubr. Technol. 105 (1983)
    171-177; Hamrock, NASA RP-1255, ch. 6). Kept for comparison only: the
    model uses the exact :func:`point_contact`; the tests show their error
    (k within 3.5 % for conformity >= 0.51, 6 % off at 0.505, where Ry/Rx > 100).
    """
    r = float(ry_over_rx)
    return 1.0339 * r**0.6360, 1.5277 + 0.6023 * math.log(r), 1.0003 + 0.5968 / r


# --------------------------------------------------------------------------- a guide's balls


def guide_contacts(guide) -> tuple[PointContact, PointContact]:
    """The rail-side and carriage-side contacts of one ball of a ball guide (straight grooves)."""
    e_prime = effective_modulus(guide.element_modulus_pa, guide.element_poisson,
                                guide.raceway_modulus_pa, guide.raceway_poisson)
    d = guide.roller_diameter_m
    return (groove_contact(d, guide.conformity_rail, e_prime),
            groove_contact(d, guide.conformity_carriage, e_prime))


def ball_law_constant(guide) -> float:
    """k_h of Eq. (3) for one ball of a guide, both contacts in series (N m^(-3/2)).

    Not scaled by the guide's effective fraction (:func:`guidefit.model.static.law_constant` is).
    """
    return ball_constant(guide_contacts(guide))


def ball_capacity_n(guide) -> float:
    """Static capacity of one ball (N): the load at which its more stressed contact reaches 4200 MPa.

    4200 MPa is the contact stress of the static load rating of ball contacts
    (ISO 76; ISO 14728-2 for linear guides).
    """
    return min(c.load_at_pressure_n(BALL_STATIC_RATING_STRESS_PA) for c in guide_contacts(guide))
