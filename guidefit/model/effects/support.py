"""The support body: a rail (or base) on springs between the rollers and the ground.

One structure (physics notes: "a compliant rail support and a base with its
own mode are one structure"), defined once here and fitted under two names
that say what differs:

* ``support_compliance``: the massless limit (``mass_kg`` 0, the default): the
  rail mounting's springs act in series with the rollers and add no mode of
  their own;
* ``base_mode``: the same body with its own ``mass_kg`` fitted: it adds a
  mode (an extra peak) and splits the carriage mode it couples with.

Both accept the same parameters (``--effect support_compliance:...,mass_kg=3``
is the same body as ``base_mode``); they never combine (one body has one
mass). Model selection tells them apart by the mass: a body whose mass the
data do not resolve is ``support_compliance``.
"""

from __future__ import annotations

import math

from guidefit.model import vibration as vib
from guidefit.model.effects.base import DocRow, EffectDef, Parameter, Variant, log_free

_INF = math.inf
STRUCTURE = "support_body"


def _body(guide, p) -> vib.SupportBody:
    mass = float(p.get("mass_kg") or 0.0)
    depth = guide.h3_m if p.get("depth_m") is None else p["depth_m"]
    return vib.SupportBody(
        stiffness_to_ground=(p["lateral_n_per_m"], p["vertical_n_per_m"], _INF, _INF,
                             p.get("roll_nm_per_rad", _INF)),
        mass_kg=mass,
        inertia_kg_m2=(0.0, 0.0, 0.0),
        reference_m=(0.0, -depth, 0.0),
        name="rail" if mass == 0 else "base",
    )


def apply(spec, guide, p):
    """The support body with springs to ground at depth ``depth_m`` (default h3) below the load point."""
    return vib.with_support(spec, _body(guide, p))


def _springs() -> dict:
    out = {"lateral_n_per_m": Parameter("N/m", _INF, "lateral spring body-ground", 1e4, _INF),
           "vertical_n_per_m": Parameter("N/m", _INF, "vertical spring body-ground", 1e4, _INF),
           "roll_nm_per_rad": Parameter("N m/rad", _INF, "roll spring body-ground", 1e2, _INF),
           "depth_m": Parameter("m", None, "depth of the spring point below the load point (default h3)",
                                0.0, 1.0)}
    return out


def massless_variants(ctx) -> list[Variant]:
    """Lateral, vertical, roll, lateral+vertical springs; the mass stays 0."""
    lat = log_free("lateral_n_per_m", "N/m", 1e5, 1e13, (1e6, 1e7, 1e8, 1e9, 1e10, 1e11))
    ver = log_free("vertical_n_per_m", "N/m", 1e5, 1e13, (1e7, 1e8, 1e9, 1e10, 1e11))
    rol = log_free("roll_nm_per_rad", "N m/rad", 1e2, 1e11, (1e3, 1e4, 1e5, 1e6, 1e7, 1e8))
    name = "support_compliance"
    return [Variant(name, "lateral", {}, (lat,)), Variant(name, "vertical", {}, (ver,)),
            Variant(name, "roll", {}, (rol,)),
            Variant(name, "lateral+vertical", {},
                    (log_free(lat.name, "N/m", 1e5, 1e13, (1e7, 1e8, 1e9, 1e11)),
                     log_free(ver.name, "N/m", 1e5, 1e13, (1e8, 1e9, 1e10, 1e12))),
                    reduces=(("lateral_n_per_m", "vertical"), ("vertical_n_per_m", "lateral")))]


def massive_variants(ctx) -> list[Variant]:
    """Vertical, lateral, lateral+vertical springs with the body's mass fitted.

    Starts: masses from 0.1 to 50 kg, each with the stiffness that puts the
    body's own frequency at an unpaired measured peak or at 1.5, 3 or 6 kHz.
    """
    m = log_free("mass_kg", "kg", 1e-3, 1e4)
    kl = log_free("lateral_n_per_m", "N/m", 1e4, 1e13)
    kv = log_free("vertical_n_per_m", "N/m", 1e4, 1e13)
    f_try = sorted(set(list(ctx.extra_frequencies_hz) + [1500.0, 3000.0, 6000.0]))
    masses = (0.1, 0.5, 2.0, 10.0, 50.0)

    def k_of(mass, f_hz):
        return min(max(mass * (2 * math.pi * f_hz) ** 2, 1.1e4), 0.9e13)

    two = tuple((mm, k_of(mm, ff)) for mm in masses for ff in f_try)
    three = tuple((mm, k_of(mm, fa), k_of(mm, fb)) for mm in (0.3, 2.0, 10.0)
                  for fa in f_try[-3:] + [9000.0] for fb in f_try[-3:] + [9000.0])
    name = "base_mode"
    return [Variant(name, "vertical", {}, (m, kv), two), Variant(name, "lateral", {}, (m, kl), two),
            Variant(name, "lateral+vertical", {}, (m, kl, kv), three,
                    reduces=(("lateral_n_per_m", "vertical"), ("vertical_n_per_m", "lateral")))]


SUPPORT_COMPLIANCE = EffectDef(
    name="support_compliance",
    meaning="compliant rail mounting in series with the roller contacts (the support body's massless limit)",
    parameters={**_springs(), "mass_kg": Parameter("kg", 0.0, "moving mass of the body (0: massless limit)",
                                                   0.0, 1e4)},
    apply=apply,
    variants=massless_variants,
    doc=DocRow("lateral, vertical, roll, lateral+vertical",
               "`lateral_n_per_m`, `vertical_n_per_m` (1e5 - 1e13 N/m, the top is rigid), `roll_nm_per_rad` "
               "(1e2 - 1e11 N m/rad); `mass_kg` 0",
               "the support body's massless limit: a compliant rail mounting in series with the rollers (a "
               "massless rail on springs at depth h3); no mode of its own"),
    order=20,
    structure=STRUCTURE,
    aliases=("support_massless",),
)

BASE_MODE = EffectDef(
    name="base_mode",
    meaning="the support body with its own mass (a rail or base on springs): an extra mode",
    parameters={"mass_kg": Parameter("kg", None, "moving mass of the body", 1e-3, 1e4), **_springs()},
    apply=apply,
    variants=massive_variants,
    doc=DocRow("vertical, lateral, lateral+vertical",
               "`mass_kg` (1e-3 - 1e4 kg), `lateral_n_per_m`, `vertical_n_per_m` (1e4 - 1e13 N/m)",
               "the same support body with its mass fitted (a rail or base with its own mass): an extra mode, "
               "and a split of the carriage mode it couples with"),
    order=50,
    structure=STRUCTURE,
    aliases=("support_body", "support_with_mass"),
)

EFFECTS = (SUPPORT_COMPLIANCE, BASE_MODE)
