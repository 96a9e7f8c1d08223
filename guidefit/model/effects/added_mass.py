"""``added_mass``: unmodelled mass on the carriage (undeclared accelerometers, fixtures, bolts).

The total ``mass_kg`` is spread equally over the points named by ``at``
(measuring points such as ``ABCD`` or ``A``, or ``centre``). Masses at the
measuring points add rotational inertia; a mass at the centre does not. A
mass at A, B, C or D gives identical frequencies (mirror symmetry): only
mode shapes tell the corner.
"""

from __future__ import annotations

from guidefit.errors import ModelError
from guidefit.model import vibration as vib
from guidefit.model.effects.base import DocRow, EffectDef, Parameter, Variant, log_free


def _points(spec, guide, at: str) -> list[tuple[float, float, float]]:
    if at.lower() in ("centre", "center", "origin"):
        return [(0.0, 0.0, 0.0)]
    pts = []
    for name in at:
        if name not in spec.measuring_points_m:
            have = "".join(spec.measuring_points_m)
            raise ModelError(f"effect added_mass: point '{name}' not defined by guide {guide.name}; have {have}")
        pts.append(tuple(spec.measuring_points_m[name]))
    if not pts:
        raise ModelError("effect added_mass: parameter 'at' names no point")
    return pts


def apply(spec, guide, p):
    """Point masses ``mass_kg / len(at)`` at each named point."""
    pts = _points(spec, guide, str(p["at"]))
    return vib.with_point_masses(spec, [(p["mass_kg"] / len(pts), pt) for pt in pts])


def variants(ctx) -> list[Variant]:
    """All measuring points together, each point alone, the centre."""
    mass = log_free("mass_kg", "kg", 1e-4, 5.0, (0.003, 0.03, 0.3, 2.0))
    points = "".join(ctx.guide.measuring_points_m)
    tags = ([points] if len(points) > 1 else []) + list(points) + ["centre"]
    return [Variant("added_mass", f"at {t}", {"at": t}, (mass,)) for t in tags]


def ambiguity(tags) -> str | None:
    """Two or more single corners equally good: only the mode shapes tell them apart."""
    corners = [t for t in tags if t.startswith("at ") and len(t) == 4]
    if len(corners) > 1:
        return ("a mass at A, B, C or D gives identical frequencies (mirror symmetry); "
                "only mode shapes at A-D tell which corner")
    return None


EFFECT = EffectDef(
    name="added_mass",
    meaning="unmodelled mass on the carriage (undeclared accelerometers, fixtures, bolts)",
    parameters={"mass_kg": Parameter("kg", None, "total added mass", 0.0, 5.0),
                "at": Parameter("", "ABCD", "points carrying it (names of measuring points) or 'centre'")},
    apply=apply,
    variants=variants,
    doc=DocRow("at ABCD (equal shares), at A, B, C or D, at the centre", "`mass_kg` (1e-4 - 5 kg)",
               "undeclared accelerometers, cables, fixtures; masses at the measuring points add rotational "
               "inertia, a mass at the centre does not"),
    order=10,
    ambiguity=ambiguity,
)
