"""``contact_stiffness``: every roller's K_n multiplied by ``factor`` (lost or higher preload)."""

from __future__ import annotations

from guidefit.model import vibration as vib
from guidefit.model.effects.base import DocRow, EffectDef, Parameter, Variant, log_free


def apply(spec, guide, p):
    """Every roller stiffness times ``factor``."""
    return vib.scale_roller_stiffness(spec, p["factor"])


def variants(ctx) -> list[Variant]:
    """One variant: the factor."""
    return [Variant("contact_stiffness", "", {}, (log_free("factor", "1", 0.05, 5.0, (0.3, 0.6, 0.9, 1.1, 1.5, 3.0)),))]


EFFECT = EffectDef(
    name="contact_stiffness",
    meaning="roller contact stiffness different from nominal (lost or higher preload)",
    parameters={"factor": Parameter("1", None, "K_n relative to nominal", 0.05, 5.0)},
    apply=apply,
    variants=variants,
    doc=DocRow("-", "`factor` on every K_n (0.05 - 5)",
               "lost or higher preload, a different contact law calibration"),
    order=30,
)
