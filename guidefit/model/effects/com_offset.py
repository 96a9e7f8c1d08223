"""``com_offset``: the centre of mass away from the load point (Eq. 8 puts it there)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from guidefit.model.effects.base import DocRow, EffectDef, Free, Parameter, Variant


def apply(spec, guide, p):
    """Centre of mass moved by (x_m, y_m, z_m)."""
    centre = np.asarray(spec.center_of_mass_m) + [p["x_m"], p["y_m"], p["z_m"]]
    return replace(spec, center_of_mass_m=tuple(float(c) for c in centre))


def variants(ctx) -> list[Variant]:
    """A vertical offset alone, or all three; bounds keep the centre inside the carriage.

    |x| <= row offset e, -h3 <= y <= 5 mm, |z| <= roller span / 4.
    """
    guide = ctx.guide
    e, h3, zl = guide.row_offset_m, guide.h3_m, max(guide.roller_span_m / 4, 1e-3)
    fy = Free("y_m", "m", "lin", -h3, 0.005, tuple(np.linspace(-h3, 0.0, 5)[1:-1]) + (-0.002,))
    fx = Free("x_m", "m", "lin", -e, e, (-e / 2, 0.0, e / 2))
    fz = Free("z_m", "m", "lin", -zl, zl, (-zl / 2, 0.0, zl / 2))
    return [Variant("com_offset", "y", {}, (fy,)), Variant("com_offset", "xyz", {}, (fx, fy, fz))]


EFFECT = EffectDef(
    name="com_offset",
    meaning="centre of mass away from the load point (Eq. 8 assumes it there)",
    parameters={"x_m": Parameter("m", 0.0, "lateral offset", -0.1, 0.1),
                "y_m": Parameter("m", 0.0, "vertical offset", -0.1, 0.1),
                "z_m": Parameter("m", 0.0, "axial offset", -0.1, 0.1)},
    apply=apply,
    variants=variants,
    doc=DocRow("y, xyz", "`x_m` (+/- e), `y_m` (-h3 - +5 mm), `z_m` (+/- l_L/4)",
               "the centre of mass away from the load point (Eq. 8 puts it there); the bounds keep it inside "
               "the carriage"),
    order=70,
)
