"""The effect library: physical effects that the nominal model lacks.

Each effect is a named model extension with physical parameters. It is used
twice: ``guidefit simulate --effect NAME:param=value`` puts it into a
synthetic hammer test, and ``guidefit explain`` fits it to measured modes.
Every effect maps (nominal :class:`~guidefit.model.vibration.ModelSpec`,
guide, parameters) to a new spec through the extension points of
:mod:`guidefit.model.vibration`; none of them touches the core.

=====================  ==========================================================
effect                 parameters (SI)
=====================  ==========================================================
added_mass             ``mass_kg`` total, spread equally over ``at`` (point names
                       such as ``ABCD`` or ``A``, or ``centre``)
support_compliance     ``lateral_n_per_m``, ``vertical_n_per_m``, ``roll_nm_per_rad``
                       (omitted = rigid), ``depth_m`` of the spring point below the
                       load point (default h3), ``mass_kg`` of the rail (default 0)
contact_stiffness      ``factor``: every roller's K_n multiplied (lost or higher preload)
amplitude_dependence   ``preload_factor``: preload Delta scaled; contacts are nonlinear
                       preloaded Hertz springs, so frequencies fall with hit force
base_mode              a base body with ``mass_kg``, ``lateral_n_per_m``,
                       ``vertical_n_per_m`` (omitted = rigid), ``depth_m``
row_damage             ``row`` (1-4) and ``factor`` (its rollers' remaining stiffness)
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
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from guidefit.errors import ModelError
from guidefit.model import vibration as vib


@dataclass(frozen=True)
class Effect:
    """One effect: its name and parameters (floats in SI, or strings such as point names)."""

    name: str
    parameters: dict = field(default_factory=dict)

    def __str__(self) -> str:
        body = ",".join(f"{k}={v}" for k, v in self.parameters.items())
        return f"{self.name}:{body}" if body else self.name


@dataclass(frozen=True)
class Parameter:
    """A parameter of an effect: unit, default (None = required, inf = rigid) and meaning."""

    unit: str
    default: float | str | None
    meaning: str
    lower: float = 0.0
    upper: float = math.inf


@dataclass(frozen=True)
class EffectInfo:
    """Description and model transform of an effect."""

    name: str
    meaning: str
    parameters: dict
    apply: Callable
    nonlinear: bool = False


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


def _added_mass(spec, guide, p):
    pts = _points(spec, guide, str(p["at"]))
    return vib.with_point_masses(spec, [(p["mass_kg"] / len(pts), pt) for pt in pts])


def _support_body(guide, p, mass_kg):
    depth = guide.h3_m if p.get("depth_m") is None else p["depth_m"]
    return vib.SupportBody(
        stiffness_to_ground=(p["lateral_n_per_m"], p["vertical_n_per_m"], math.inf, math.inf,
                             p.get("roll_nm_per_rad", math.inf)),
        mass_kg=mass_kg,
        inertia_kg_m2=(0.0, 0.0, 0.0),
        reference_m=(0.0, -depth, 0.0),
        name="rail" if mass_kg == 0 else "base",
    )


def _support_compliance(spec, guide, p):
    return vib.with_support(spec, _support_body(guide, p, p["mass_kg"]))


def _base_mode(spec, guide, p):
    return vib.with_support(spec, _support_body(guide, p, p["mass_kg"]))


def _contact_stiffness(spec, guide, p):
    return vib.scale_roller_stiffness(spec, p["factor"])


def _amplitude_dependence(spec, guide, p):
    # small-amplitude (linearised) model: Hertz line contact K_n ~ Delta^(1/9), Eq. (4)
    return vib.scale_roller_stiffness(spec, p["preload_factor"] ** (1.0 / 9.0))


def _row_damage(spec, guide, p):
    row = int(round(p["row"]))
    if row not in (1, 2, 3, 4):
        raise ModelError(f"effect row_damage: parameter 'row' must be 1-4, got {p['row']}")
    factors = np.ones(4)
    factors[row - 1] = p["factor"]
    return vib.scale_roller_stiffness(spec, factors)


def _com_offset(spec, guide, p):
    from dataclasses import replace

    centre = np.asarray(spec.center_of_mass_m) + [p["x_m"], p["y_m"], p["z_m"]]
    return replace(spec, center_of_mass_m=tuple(float(c) for c in centre))


_INF = math.inf
EFFECTS: dict[str, EffectInfo] = {
    info.name: info
    for info in (
        EffectInfo(
            "added_mass",
            "unmodelled mass on the carriage (undeclared accelerometers, fixtures, bolts)",
            {"mass_kg": Parameter("kg", None, "total added mass", 0.0, 5.0),
             "at": Parameter("", "ABCD", "points carrying it (names of measuring points) or 'centre'")},
            _added_mass,
        ),
        EffectInfo(
            "support_compliance",
            "compliant rail mounting in series with the roller contacts",
            {"lateral_n_per_m": Parameter("N/m", _INF, "lateral spring rail-ground", 1e5, _INF),
             "vertical_n_per_m": Parameter("N/m", _INF, "vertical spring rail-ground", 1e5, _INF),
             "roll_nm_per_rad": Parameter("N m/rad", _INF, "roll spring rail-ground", 1e2, _INF),
             "depth_m": Parameter("m", None, "depth of the spring point below the load point (default h3)",
                                  0.0, 1.0),
             "mass_kg": Parameter("kg", 0.0, "moving mass of the rail", 0.0, 100.0)},
            _support_compliance,
        ),
        EffectInfo(
            "contact_stiffness",
            "roller contact stiffness different from nominal (lost or higher preload)",
            {"factor": Parameter("1", None, "K_n relative to nominal", 0.05, 5.0)},
            _contact_stiffness,
        ),
        EffectInfo(
            "amplitude_dependence",
            "nonlinear preloaded Hertz contacts: stiffness falls as hits unload the rows",
            {"preload_factor": Parameter("1", 1.0, "preload Delta relative to the guide's", 0.01, 10.0)},
            _amplitude_dependence,
            nonlinear=True,
        ),
        EffectInfo(
            "base_mode",
            "a base or rail body with its own mass and stiffness (an extra mode)",
            {"mass_kg": Parameter("kg", None, "moving mass of the base", 1e-3, 1e4),
             "lateral_n_per_m": Parameter("N/m", _INF, "lateral spring base-ground", 1e4, _INF),
             "vertical_n_per_m": Parameter("N/m", _INF, "vertical spring base-ground", 1e4, _INF),
             "depth_m": Parameter("m", None, "depth of the base's reference point (default h3)", 0.0, 1.0)},
            _base_mode,
        ),
        EffectInfo(
            "row_damage",
            "one roller row stiffer or softer than the others (raceway damage, uneven preload)",
            {"row": Parameter("1", None, "row number 1-4 of Eq. (9)", 1, 4),
             "factor": Parameter("1", None, "remaining stiffness of that row", 0.0, 1.0)},
            _row_damage,
        ),
        EffectInfo(
            "com_offset",
            "centre of mass away from the load point (Eq. 8 assumes it there)",
            {"x_m": Parameter("m", 0.0, "lateral offset", -0.1, 0.1),
             "y_m": Parameter("m", 0.0, "vertical offset", -0.1, 0.1),
             "z_m": Parameter("m", 0.0, "axial offset", -0.1, 0.1)},
            _com_offset,
        ),
    )
}


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
    """
    return make_effect(*split_named_parameters(text, "effect"))


def make_effect(name: str, parameters: dict) -> Effect:
    """Validate an effect's name and parameters; fill defaults; convert numbers.

    Raises :class:`~guidefit.errors.ModelError` naming the effect and parameter.
    """
    if name not in EFFECTS:
        raise ModelError(f"unknown effect '{name}'; have {', '.join(EFFECTS)}")
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
        out[key] = number
    return Effect(name, out)


def apply_effects(spec, guide, effects) -> vib.ModelSpec:
    """Apply effects in order to a model spec (linear, small-amplitude model).

    Two support-type effects (``support_compliance``, ``base_mode``) cannot be
    combined: both are the one body between rail and ground.
    """
    kinds = [e.name for e in effects if e.name in ("support_compliance", "base_mode")]
    if len(kinds) > 1:
        raise ModelError("effects support_compliance and base_mode describe the same body; use one")
    for effect in effects:
        checked = make_effect(effect.name, effect.parameters)
        spec = EFFECTS[effect.name].apply(spec, guide, checked.parameters)
    return spec
