"""``row_damage``: one whole roller row stiffer or softer than the others (raceway damage, uneven preload).

It breaks the mirror symmetry of the four rows of Eq. (9) in a way no
uniform effect reproduces. A damaged part of a row is ``row_segment``.
"""

from __future__ import annotations

import numpy as np

from guidefit.errors import ModelError
from guidefit.model import vibration as vib
from guidefit.model.effects.base import DocRow, EffectDef, Parameter, Variant, log_free


def apply(spec, guide, p):
    """The rollers of row ``row`` times ``factor``."""
    row = int(round(p["row"]))
    if row not in (1, 2, 3, 4):
        raise ModelError(f"effect row_damage: parameter 'row' must be 1-4, got {p['row']}")
    factors = np.ones(4)
    factors[row - 1] = p["factor"]
    return vib.scale_roller_stiffness(spec, factors)


def variants(ctx) -> list[Variant]:
    """Rows 1, 2, 3 and 4."""
    fac = log_free("factor", "1", 1e-3, 1.0, (0.01, 0.1, 0.4, 0.8))
    return [Variant("row_damage", f"row {r}", {"row": r}, (fac,)) for r in (1, 2, 3, 4)]


EFFECT = EffectDef(
    name="row_damage",
    meaning="one roller row stiffer or softer than the others (raceway damage, uneven preload)",
    parameters={"row": Parameter("1", None, "row number 1-4 of Eq. (9)", 1, 4, integer=True),
                "factor": Parameter("1", None, "remaining stiffness of that row", 0.0, 1.0)},
    apply=apply,
    variants=variants,
    doc=DocRow("rows 1, 2, 3, 4", "`factor` of that row's rollers (1e-3 - 1)",
               "raceway damage, uneven preload: breaks the mirror symmetry"),
    order=60,
    excludes=frozenset({"row_segment"}),
)
