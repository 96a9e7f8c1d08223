"""``row_segment``: part of one roller row at its own stiffness (local raceway damage, a dent, a chip).

Rollers ``first`` to ``last`` (1-based along +z, roller 1 at the -z end;
``rollers_per_row`` of the guide in all) of row ``row`` (1-4 of Eq. 9) carry
``factor`` of their stiffness. Whole numbers select whole rollers;
fractional ends take part of a roller (:func:`guidefit.model.vibration.segment_weights`),
which is how explain finds the basin with continuous ends before profiling
them over whole rollers (``Variant.whole``; a roller sits on the damage or
not, and fractional ends traded off against the factor). Whole-row loss
is ``row_damage`` (the two never combine; for a segment spanning the row
model selection prefers ``row_damage``, which has two parameters fewer).

What the data see: a segment changes the stiffness matrix by
``(1 - factor) sum_i K_n g_i g_i^T`` over its rollers, i.e. by the row's
number of rollers in it and their first and second moments in z; five
frequencies and the mode shapes at A-D determine these three numbers, so
``first``, ``last`` and ``factor`` are identifiable together (the row
from the shapes: rows 1 and 2, like the corners of ``added_mass``, are
mirror images, as are the two ends of a row).
"""

from __future__ import annotations

from guidefit.errors import ModelError
from guidefit.model import vibration as vib
from guidefit.model.effects.base import DocRow, EffectDef, Free, Parameter, Variant, log_free


def apply(spec, guide, p):
    """Rollers first..last of the row times factor."""
    row = int(round(p["row"]))
    if row not in (1, 2, 3, 4):
        raise ModelError(f"effect row_segment: parameter 'row' must be 1-4, got {p['row']}")
    n = guide.rollers_per_row
    first, last = float(p["first"]), float(p["last"])
    if not 1 <= first <= last <= n:
        raise ModelError(f"effect row_segment: need 1 <= first <= last <= {n} (rollers per row of {guide.name}), "
                         f"got first={first:g}, last={last:g}")
    return vib.scale_roller_segment(spec, row, first, last, p["factor"])


def variants(ctx) -> list[Variant]:
    """Rows 1-4; first, last and factor fitted, then the ends profiled over whole rollers.

    Each row's variant stands for its n (n + 1) / 2 whole-roller end pairs
    (``choices``, counted in the BIC). Starts: segments whose ends sit at 0, 1/4, 1/2, 3/4 and the whole of the
    row (at least a quarter long), factors 0.05, 0.3 and 0.7.
    """
    n = ctx.guide.rollers_per_row
    if n < 2:
        return []
    first = Free("first", "roller", "lin", 1.0, float(n), scale=1.0, bound_is_value=True)
    last = Free("last", "roller", "lin", 1.0, float(n), scale=1.0, bound_is_value=True)
    factor = log_free("factor", "1", 1e-3, 1.0)
    ends = (0.0, 0.25, 0.5, 0.75, 1.0)
    starts = []
    for a in ends:
        for b in ends:
            if b - a < 0.25:
                continue
            lo, hi = 1 + round(a * (n - 1)), 1 + round(b * (n - 1))
            lo, hi = (lo + 1 if a > 0 else lo), hi  # adjoining segments do not share a roller
            for f in (0.05, 0.3, 0.7):
                starts.append((float(lo), float(hi), f))
    n_ends = n * (n + 1) // 2  # whole-roller segments first <= last: the discrete choices of one row
    return [Variant("row_segment", f"row {r}", {"row": r}, (first, last, factor), tuple(starts),
                    whole=("first", "last"), choices=n_ends) for r in (1, 2, 3, 4)]


def ambiguity(tags) -> str | None:
    """Several rows equally good: mirror images that only the mode shapes tell apart."""
    if len(tags) > 1:
        return ("rows 1 and 2 (and 3 and 4) are mirror images, as are the two ends of a row: only mode shapes "
                "at A-D tell them apart")
    return None


EFFECT = EffectDef(
    name="row_segment",
    meaning="part of one roller row at its own stiffness (local raceway damage)",
    parameters={"row": Parameter("1", None, "row number 1-4 of Eq. (9)", 1, 4, integer=True),
                "first": Parameter("roller", None, "first roller of the segment (1 at the -z end)", 1, 1000),
                "last": Parameter("roller", None, "last roller of the segment", 1, 1000),
                "factor": Parameter("1", None, "remaining stiffness of the segment's rollers", 0.0, 1.0)},
    apply=apply,
    variants=variants,
    doc=DocRow("rows 1, 2, 3, 4",
               "`first`, `last` (whole rollers 1 - Z_L, profiled: 231 end pairs per row), `factor` (1e-3 - 1)",
               "local raceway damage: part of one row softer; the segment's size and place along z from the "
               "frequencies and shapes"),
    order=65,
    excludes=frozenset({"row_damage"}),
    ambiguity=ambiguity,
)
