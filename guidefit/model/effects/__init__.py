"""The effect library: physical effects that the nominal model lacks, one module per effect.

Each effect is a named model extension with physical parameters. It is used
twice: ``guidefit simulate --effect NAME:param=value`` puts it into a
synthetic hammer test, and ``guidefit explain`` fits it to measured modes.
Every effect maps (nominal :class:`~guidefit.model.vibration.ModelSpec`,
guide, parameters) to a new spec through the extension points of
:mod:`guidefit.model.vibration`; none of them touches the core.

The registry
------------
:data:`EFFECTS` maps each name to its :class:`~guidefit.model.effects.base.EffectDef`,
which declares in one place the parameters and bounds, the model transform,
the variants explain tries (discrete options, fit bounds, start grids), when
it is tried (``gate``), what it combines with (``structure``, ``excludes``),
how its model is evaluated (``forward``, for effects whose prediction is
not the linear eigen-solution) and its row of the table in docs/explain.md.
``explain`` iterates over the registry and has no rule of its own for any
effect.

Adding an effect
----------------
Write one module in this package that defines ``EFFECT`` (or ``EFFECTS``, a
tuple) as an :class:`~guidefit.model.effects.base.EffectDef`; it is found
by name (every module here but ``base``). Then add its test (the registry
test fails for an effect that no test under ``tests/`` names) and its row
in docs/explain.md (the registry test compares the table with
:func:`doc_table`). Nothing else changes.

=====================  ==========================================================
effect                 parameters (SI)
=====================  ==========================================================
added_mass             ``mass_kg`` total, spread equally over ``at`` (point names
                       such as ``ABCD`` or ``A``, or ``centre``)
support_compliance     ``lateral_n_per_m``, ``vertical_n_per_m``, ``roll_nm_per_rad``
                       (omitted = rigid), ``depth_m`` of the spring point below the
                       load point (default h3), ``mass_kg`` of the body (default 0:
                       the massless limit of the support body)
base_mode              the same support body with its ``mass_kg`` (required)
contact_stiffness      ``factor``: every roller's K_n multiplied (lost or higher preload)
amplitude_dependence   ``preload_factor``: preload Delta scaled; contacts are nonlinear
                       preloaded Hertz springs, so frequencies fall with hit force
row_damage             ``row`` (1-4) and ``factor`` (its rollers' remaining stiffness)
row_segment            ``row`` (1-4), ``first`` and ``last`` roller (1 at the -z end),
                       ``factor`` (the segment's remaining stiffness)
com_offset             ``x_m``, ``y_m``, ``z_m``: centre of mass away from the load point
=====================  ==========================================================

Examples
--------
>>> from guidefit.model.guides import load_guide
>>> from guidefit.model.effects import parse_effect, apply_effects
>>> from guidefit.model.vibration import model_from_guide, solve_modes
>>> guide = load_guide("MRB35")
>>> spec = apply_effects(model_from_guide(guide), guide, [parse_effect("contact_stiffness:factor=0.81")])
>>> round(solve_modes(spec).frequency_hz("vertical"))
3176
>>> parse_effect("support_massless:lateral_n_per_m=1.2e8").name   # an alias
'support_compliance'
"""

from __future__ import annotations

import importlib
import math
import pkgutil

from guidefit.errors import ModelError
from guidefit.model import vibration as vib
from guidefit.model.effects.base import (  # noqa: F401 - the registry's public types
    DocRow,
    Effect,
    EffectDef,
    FitContext,
    Forward,
    ForwardRequest,
    Free,
    LevelData,
    Parameter,
    Variant,
    log_free,
)


def _discover() -> dict:
    found = []
    for info in pkgutil.iter_modules(__path__):
        if info.name == "base" or info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{__name__}.{info.name}")
        defs = getattr(module, "EFFECTS", None) or ((module.EFFECT,) if hasattr(module, "EFFECT") else ())
        found += list(defs)
    found.sort(key=lambda d: (d.order, d.name))
    out: dict = {}
    for d in found:
        if d.name in out:
            raise ModelError(f"effect library: '{d.name}' defined twice")
        out[d.name] = d
    return out


#: The registry: effect name -> :class:`EffectDef`, in library order.
EFFECTS: dict[str, EffectDef] = _discover()
#: Other names accepted for an effect (``--effect``, :func:`make_effect`, JSON readers) -> its name.
ALIASES: dict[str, str] = {alias: d.name for d in EFFECTS.values() for alias in d.aliases}


def resolve_name(name: str) -> str:
    """The registry name of an effect name or alias.

    >>> resolve_name("support_body")
    'base_mode'
    """
    if name in EFFECTS:
        return name
    if name in ALIASES:
        return ALIASES[name]
    raise ModelError(f"unknown effect '{name}'; have {', '.join(EFFECTS)}")


def combinable(a: str, b: str) -> bool:
    """Whether two effects may be fitted together (different, not one structure, not excluded, not two nonlinear).

    >>> combinable("support_compliance", "base_mode"), combinable("support_compliance", "added_mass")
    (False, True)
    """
    da, db = EFFECTS[resolve_name(a)], EFFECTS[resolve_name(b)]
    if da.name == db.name or db.name in da.excludes or da.name in db.excludes:
        return False
    if da.structure is not None and da.structure == db.structure:
        return False
    return not (da.nonlinear and db.nonlinear)


def doc_table() -> str:
    """The library table of docs/explain.md, generated from the registry (a test compares the two)."""
    lines = ["| effect | variants tried | fitted parameters (bounds) | physical meaning |", "|---|---|---|---|"]
    for d in EFFECTS.values():
        lines.append(f"| `{d.name}` | {d.doc.variants} | {d.doc.fitted} | {d.doc.meaning} |")
    return "\n".join(lines)


def split_named_parameters(text: str, kind: str) -> tuple[str, dict]:
    """``NAME[:param=value,...]`` -> (name, {param: value text}); the syntax of ``--effect`` and ``--fault``.

    >>> split_named_parameters("added_mass:mass_kg=0.04, at=AB", "effect")
    ('added_mass', {'mass_kg': '0.04', 'at': 'AB'})
    """
    name, _, body = text.partition(":")
    params: dict = {}
    for item in filter(None, (s.strip() for s in body.split(","))):
        key, eq, value = item.partition("=")
        if not eq:
            raise ModelError(f"{kind} '{text}': expected param=value, got '{item}'")
        params[key.strip()] = value.strip()
    return name.strip(), params


def parse_effect(text: str) -> Effect:
    """Parse ``NAME:param=value,param=value`` (the ``--effect`` syntax) into a checked Effect.

    >>> parse_effect("added_mass:mass_kg=0.04,at=AB")
    Effect(name='added_mass', parameters={'mass_kg': 0.04, 'at': 'AB'})
    >>> parse_effect("row_segment:row=2,first=1,last=10,factor=0.3").parameters["last"]
    10.0
    """
    return make_effect(*split_named_parameters(text, "effect"))


def make_effect(name: str, parameters: dict) -> Effect:
    """Validate an effect's name (or alias) and parameters; fill defaults; convert numbers.

    Raises :class:`~guidefit.errors.ModelError` naming the effect and parameter.
    """
    name = resolve_name(name)
    info = EFFECTS[name]
    out: dict = {}
    for key in parameters:
        if key not in info.parameters:
            raise ModelError(f"effect {name}: unknown parameter '{key}'; have {', '.join(info.parameters)}")
    for key, spec in info.parameters.items():
        if parameters.get(key) is None:
            if spec.default is None and key != "depth_m":
                raise ModelError(f"effect {name}: parameter '{key}' ({spec.unit}) missing")
            out[key] = spec.default
            continue
        value = parameters[key]
        if spec.unit == "":
            out[key] = str(value)
            continue
        try:
            number = float(value)
        except (TypeError, ValueError):
            raise ModelError(f"effect {name}: parameter '{key}' must be a number in {spec.unit}, got {value!r}") from None
        if not (spec.lower <= number <= spec.upper) or math.isnan(number):
            raise ModelError(
                f"effect {name}: parameter '{key}' = {number:g} {spec.unit} outside [{spec.lower:g}, {spec.upper:g}]"
            )
        if spec.integer and number != round(number):
            raise ModelError(f"effect {name}: parameter '{key}' must be a whole number, got {number:g}")
        out[key] = number
    return Effect(name, out)


def apply_effects(spec, guide, effects) -> vib.ModelSpec:
    """Apply effects in order to a model spec (linear, small-amplitude model).

    Effects that cannot be combined (:func:`combinable`: the one support
    body of ``support_compliance`` and ``base_mode``, a row and a segment of
    rows) are refused; the same effect twice is allowed (two masses).
    """
    names = [resolve_name(e.name) for e in effects]
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            if a != b and not combinable(a, b):
                raise ModelError(f"effects {a} and {b} describe the same structure; use one")
    for effect, name in zip(effects, names):
        checked = make_effect(name, effect.parameters)
        spec = EFFECTS[name].apply(spec, guide, checked.parameters)
    return spec
