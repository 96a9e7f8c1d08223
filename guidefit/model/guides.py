"""Guide catalogue: the geometry, inertia and contact data of a guideway carriage.

A guide is read from a TOML file with the sections ``[carriage]``, ``[rows]``,
``[contact]`` and ``[points]`` (see ``data/MRB35.toml`` for the built-in MR 35
roller carriage of the paper's Table 1). Field names carry their SI unit
(``mass_kg``, ``h1_m``, ``contact_angle_deg``); a value may be a number in that
unit or a string with an explicit unit (``"32 mm"``, ``"2200 g"``), which is
converted. A field with no unit in its name and no unit in its value, a
missing or negative field, and an unknown field are errors that name the field.

Examples
--------
>>> from guidefit.model.guides import load_guide
>>> guide = load_guide("MRB35")
>>> guide.mass_kg, guide.rollers_per_row
(2.2, 21)
>>> round(guide.h3_m, 4)
0.0342
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path

import numpy as np

from guidefit.errors import GuideError

# Unit conversions to SI for string values such as "32 mm".
_UNIT_FACTORS = {
    "m": {"m": 1.0, "mm": 1e-3, "um": 1e-6, "µm": 1e-6, "cm": 1e-2},
    "kg": {"kg": 1.0, "g": 1e-3},
    "kg_m2": {"kg m^2": 1.0, "kg*m^2": 1.0, "kg m2": 1.0, "kg mm^2": 1e-6, "g mm^2": 1e-9},
    "deg": {"deg": 1.0, "rad": 180.0 / math.pi},
    "n_per_m": {"N/m": 1.0, "N/um": 1e6, "N/µm": 1e6, "N/mm": 1e3},
    "n": {"N": 1.0, "kN": 1e3},
    "pa": {"Pa": 1.0, "MPa": 1e6, "GPa": 1e9},
}

# Field specification: section -> field -> (unit key or None, kind, required).
# kind: "pos" > 0, "nonneg" >= 0, "vec3" 3 finite numbers, "pos3" 3 positive numbers,
# "int" positive integer, "frac" in (0, 1], or a tuple of allowed strings.
_SPEC: dict[str, dict[str, tuple]] = {
    "carriage": {
        "mass_kg": ("kg", "pos", True),
        "inertia_kg_m2": ("kg_m2", "pos3", True),
        "center_of_mass_m": ("m", "vec3", False),
    },
    "rows": {
        "e_m": ("m", "pos", True),
        "e_convention": (None, ("half", "full"), False),
        "h1_m": ("m", "nonneg", True),
        "h0_m": ("m", "pos", True),
        "contact_angle_deg": ("deg", "pos", True),
        "arrangement": (None, ("O", "X"), False),
        "rollers_per_row": (None, "int", True),
        "roller_span_m": ("m", "nonneg", True),
        "effective_roller_fraction": (None, "frac", False),
        "row_count": (None, "int", False),
        "groove": (None, ("circular_arc", "gothic_arch"), False),
    },
    "contact": {
        "contact_type": (None, ("roller", "ball"), False),
        "roller_stiffness_n_per_m": ("n_per_m", "pos", True),
        "roller_diameter_m": ("m", "pos", False),
        "roller_length_m": ("m", "pos", False),
        "ball_diameter_m": ("m", "pos", False),
        "conformity_rail": (None, "pos", False),
        "conformity_carriage": (None, "pos", False),
        "element_modulus_pa": ("pa", "pos", False),
        "element_poisson": (None, "pos", False),
        "raceway_modulus_pa": ("pa", "pos", False),
        "raceway_poisson": (None, "pos", False),
        "preload_m": ("m", "nonneg", False),
        "preload_n": ("n", "nonneg", False),
        "preload_class": (None, ("Z0", "ZA", "ZB"), False),
        "dynamic_load_rating_n": ("n", "pos", False),
        "contact_law": (None, ("palmgren", "hertz_point"), False),
    },
}
# Keys a ball guide may spell by the element: [rows] elements_per_row / element_span_m are
# rollers_per_row / roller_span_m (the count and span of the rolling elements, balls or rollers).
_ALIASES = {"rows": {"elements_per_row": "rollers_per_row", "element_span_m": "roller_span_m"}}
#: Preload classes as fractions of the dynamic load rating C: the middle of HIWIN's ranges
#: (Z0 very light 0-0.02 C, ZA medium 0.05-0.07 C, ZB heavy 0.10-0.12 C).
PRELOAD_CLASSES = {"Z0": 0.01, "ZA": 0.06, "ZB": 0.11}
#: Steel (balls, rollers and raceways): Young's modulus (Pa) and Poisson's ratio.
STEEL = (2.1e11, 0.3)
_TOP_LEVEL = {"name", "description", "carriage", "rows", "contact", "points"}
_DEFAULTS = {
    "center_of_mass_m": (0.0, 0.0, 0.0),
    "e_convention": "half",
    "arrangement": "O",
    "effective_roller_fraction": 1.0,
    "roller_diameter_m": None,
    "roller_length_m": None,
    "preload_m": 0.0,
    "contact_law": None,
    "row_count": 4,
    "groove": None,
    "contact_type": "roller",
    "ball_diameter_m": None,
    "conformity_rail": None,
    "conformity_carriage": None,
    "element_modulus_pa": STEEL[0],
    "element_poisson": STEEL[1],
    "raceway_modulus_pa": STEEL[0],
    "raceway_poisson": STEEL[1],
    "preload_n": None,
    "preload_class": None,
    "dynamic_load_rating_n": None,
}


@dataclass(frozen=True)
class Guide:
    """A guideway carriage: inertia, roller-row geometry, contact data, measuring points.

    All quantities SI. Row geometry follows the paper's Eq. (9): rows 1, 2 at
    depth ``h1_m`` below the load point, rows 3, 4 at ``h3_m = h1_m + h0_m``,
    laterally at ``-/+ row_offset_m``. A two-row ball guide (``row_count`` 2,
    gothic-arch grooves, four contact points per ball) is the same four contact
    lines with ``h0_m = 0``: rows 1 and 3 are the upper and lower contacts of the
    left ball row, rows 2 and 4 of the right one. For ball guides the
    ``roller_*`` fields hold the balls (``rollers_per_row`` balls per row,
    ``roller_diameter_m`` the ball diameter) and ``roller_stiffness_n_per_m`` is
    the ball's K_n at the preload from Eq. (3) unless the file gives it.
    See docs/guide-toml.md.
    """

    name: str
    description: str
    mass_kg: float
    inertia_kg_m2: tuple[float, float, float]
    center_of_mass_m: tuple[float, float, float]
    e_m: float
    e_convention: str
    h1_m: float
    h0_m: float
    contact_angle_deg: float
    arrangement: str
    rollers_per_row: int
    roller_span_m: float
    effective_roller_fraction: float
    roller_stiffness_n_per_m: float
    roller_diameter_m: float | None
    roller_length_m: float | None
    preload_m: float
    contact_law: str
    measuring_points_m: dict[str, tuple[float, float, float]] = field(default_factory=dict)
    source: str = "builtin"
    contact_type: str = "roller"
    row_count: int = 4
    groove: str | None = None
    conformity_rail: float | None = None
    conformity_carriage: float | None = None
    element_modulus_pa: float = STEEL[0]
    element_poisson: float = STEEL[1]
    raceway_modulus_pa: float = STEEL[0]
    raceway_poisson: float = STEEL[1]
    preload_n: float | None = None
    preload_class: str | None = None
    dynamic_load_rating_n: float | None = None

    @property
    def is_ball(self) -> bool:
        """True for a ball guide (Hertz point contact, Eq. 3), False for rollers (Eq. 4)."""
        return self.contact_type == "ball"

    @property
    def element_diameter_m(self) -> float | None:
        """Diameter of the rolling element (m): the ball or the roller."""
        return self.roller_diameter_m

    @property
    def h3_m(self) -> float:
        """Depth of the lower rows below the load point, h3 = h1 + h0 (m)."""
        return self.h1_m + self.h0_m

    @property
    def row_offset_m(self) -> float:
        """Lateral distance of each row from the centre line (m), per ``e_convention``."""
        return self.e_m if self.e_convention == "half" else 0.5 * self.e_m

    @property
    def contact_angle_rad(self) -> float:
        """Contact angle beta in radians."""
        return math.radians(self.contact_angle_deg)

    @property
    def effective_rollers_per_row(self) -> float:
        """Z_L times the effective fraction (rollers that carry load)."""
        return self.rollers_per_row * self.effective_roller_fraction

    def roller_positions_z_m(self) -> np.ndarray:
        """Axial positions l_i of the rollers of one row (m), centred on z = 0 (Eq. 9)."""
        n = self.rollers_per_row
        if n == 1:
            return np.zeros(1)
        return np.linspace(-0.5 * self.roller_span_m, 0.5 * self.roller_span_m, n)

    def with_changes(self, **changes) -> Guide:
        """Return a copy with some fields replaced (validated like a file)."""
        new = replace(self, **changes)
        _check_physical(new, new.source)
        return new

    def to_frame(self):
        """The guide's fields as a two-column table (field, value)."""
        import pandas as pd

        rows = [(k, v) for k, v in self.__dict__.items() if k != "measuring_points_m"]
        rows += [(f"point_{k}_m", v) for k, v in self.measuring_points_m.items()]
        return pd.DataFrame(rows, columns=["field", "value"])


def guide_reference(guide: Guide) -> str:
    """How a file names its guide: its name (the recording contract's ``guide`` is a catalogue
    name; a user's TOML is named by its ``name`` key, and ``--guide FILE.toml`` finds it again:
    a path would not travel with the file, and other readers expect a name).

    >>> guide_reference(load_guide("MRB35"))
    'MRB35'
    """
    return guide.name


def builtin_guides() -> list[str]:
    """Names of the guides shipped with guidefit.

    >>> "MRB35" in builtin_guides()
    True
    """
    folder = resources.files("guidefit.model") / "data"
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".toml"))


# Bounds that keep every model of a guide small. The models are dense in the rollers: the
# static contact model and the effects hold (4 Z_L)-square matrices, so 10^4 rollers per row
# asked for ~24 GB and was killed. Catalogue roller carriages carry 10-60 rollers per row
# (full complement, sizes 15-100); 1,000 leaves room for any real guide at < 0.5 GB.
MAX_ROLLERS_PER_ROW = 1_000
"""Largest ``rows.rollers_per_row`` a guide may have (the model has four rows)."""
MAX_POINTS = 100
"""Largest number of ``[points]`` (measuring points A-D and any others)."""
MAX_GUIDE_FILE_BYTES = 1_000_000
"""Largest guide TOML read (the built-in one is ~2 kB): a bigger file is not a guide."""
MAX_LENGTH_M = 1.0
"""Largest length (row offsets, depths, spans, diameters, points) a guide gives, m: more is mm given as m."""


def load_guide(name_or_path: str | Path) -> Guide:
    """Load a built-in guide by name (``"MRB35"``) or a user's guide TOML file.

    Raises
    ------
    GuideError
        One line naming the file and the field at fault.
    """
    text_path = str(name_or_path)
    if text_path.upper() in {g.upper() for g in builtin_guides()} and not Path(text_path).is_file():
        canonical = next(g for g in builtin_guides() if g.upper() == text_path.upper())
        resource = resources.files("guidefit.model") / "data" / f"{canonical}.toml"
        return _parse(resource.read_text(encoding="utf-8"), f"builtin guide {canonical}", "builtin")
    path = Path(text_path)
    if not path.is_file():
        known = ", ".join(builtin_guides())
        raise GuideError(f"guide '{text_path}': not a built-in guide ({known}) and no such file; "
                         "give the guide's TOML file: --guide FILE.toml")
    try:
        with path.open("rb") as handle:
            raw = handle.read(MAX_GUIDE_FILE_BYTES + 1)
        if len(raw) > MAX_GUIDE_FILE_BYTES:
            raise GuideError(f"{path}: guide file larger than {MAX_GUIDE_FILE_BYTES // 1000} kB; not a guide TOML")
        text = raw.decode("utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise GuideError(f"{path}: cannot read guide file ({exc.__class__.__name__})") from None
    return _parse(text, str(path), str(path))


def as_guide(guide) -> Guide:
    """A :class:`Guide` from a guide or its name or file (:func:`load_guide`); a guide is returned as is.

    >>> as_guide("MRB35").name == as_guide(as_guide("MRB35")).name
    True
    """
    return load_guide(guide) if isinstance(guide, str | Path) else guide


def _parse(text: str, where: str, source: str) -> Guide:
    import tomllib

    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise GuideError(f"{where}: not valid TOML ({exc})") from None
    except RecursionError:  # tomllib reads nested arrays and tables recursively
        raise GuideError(f"{where}: not a guide TOML (arrays or tables nested too deeply)") from None
    unknown = sorted(set(data) - _TOP_LEVEL)
    if unknown:
        raise GuideError(f"{where}: unknown field '{unknown[0]}'; allowed: {', '.join(sorted(_TOP_LEVEL))}")
    values: dict = {"name": str(data.get("name", Path(where).stem)),
                    "description": str(data.get("description", ""))}
    for section, spec in _SPEC.items():
        content = data.get(section)
        if content is None:
            raise GuideError(f"{where}: section [{section}] missing")
        if not isinstance(content, dict):
            raise GuideError(f"{where}: [{section}] must be a table")
        content = _unalias(content, section, where)
        for key in content:
            if key not in spec:
                hint = _suggest(key, spec)
                raise GuideError(f"{where}: unknown field '{section}.{key}'{hint}")
        for key, (unit, kind, required) in spec.items():
            if key not in content:
                if required and not _optional_here(key, data):
                    raise GuideError(f"{where}: field '{section}.{key}' missing")
                values[key] = _DEFAULTS.get(key)
                continue
            if key == "h0_m" and _two_rows(data):
                kind = "nonneg"
            values[key] = _convert(content[key], unit, kind, f"{where}: field '{section}.{key}'")
    points = data.get("points", {})
    if not isinstance(points, dict):
        raise GuideError(f"{where}: [points] must be a table of name = [x, y, z]")
    if len(points) > MAX_POINTS:
        raise GuideError(f"{where}: {len(points)} measuring points in [points]; at most {MAX_POINTS}")
    values["measuring_points_m"] = {
        str(k): tuple(_convert(v, "m", "vec3", f"{where}: field 'points.{k}'")) for k, v in points.items()
    }
    if values["h0_m"] is None:
        values["h0_m"] = 0.0
    _check_ball_fields(values, where)
    ball_diameter = values.pop("ball_diameter_m")
    if values["contact_type"] == "ball":
        values["roller_diameter_m"] = ball_diameter
        if values["roller_stiffness_n_per_m"] is None:
            values["roller_stiffness_n_per_m"] = math.nan  # filled from Eq. (3) below
    guide = Guide(source=source, **values)
    if guide.is_ball:
        guide = _resolve_ball(guide, where)
    _check_physical(guide, where)
    return guide


def _unalias(content: dict, section: str, where: str) -> dict:
    aliases = _ALIASES.get(section, {})
    out = dict(content)
    for alias, key in aliases.items():
        if alias in out:
            if key in out:
                raise GuideError(f"{where}: fields '{section}.{alias}' and '{section}.{key}' are the same; give one")
            out[key] = out.pop(alias)
    return out


def _contact_type(data: dict) -> str:
    contact = data.get("contact")
    return contact.get("contact_type", "roller") if isinstance(contact, dict) else "roller"


def _two_rows(data: dict) -> bool:
    rows = data.get("rows")
    return isinstance(rows, dict) and rows.get("row_count") == 2


def _optional_here(key: str, data: dict) -> bool:
    """Fields required of a roller guide that a ball guide (or a two-row guide) may leave out."""
    if key == "roller_stiffness_n_per_m":
        return _contact_type(data) == "ball"  # computed from Eq. (3) at the preload
    if key == "h0_m":
        return _two_rows(data)  # both contact lines of a ball row at one depth
    return False


_BALL_ONLY = ("ball_diameter_m", "conformity_rail", "conformity_carriage", "preload_n", "preload_class",
              "dynamic_load_rating_n")


def _check_ball_fields(values: dict, where: str) -> None:
    """One-line errors for a ball or roller guide's contact fields that do not fit together."""
    ball = values["contact_type"] == "ball"
    rows = values["row_count"]
    if rows not in (2, 4):
        raise GuideError(f"{where}: field 'rows.row_count' must be 2 or 4, got {rows}")
    if rows == 2 and not ball:
        raise GuideError(f"{where}: field 'rows.row_count' = 2 needs contact.contact_type = \"ball\" "
                         "(two gothic-arch ball rows); roller guides have four rows")
    if rows == 2 and values["h0_m"] not in (None, 0.0):
        raise GuideError(f"{where}: field 'rows.h0_m' must be 0 or absent for row_count = 2 "
                         "(both contacts of a ball row sit at depth h1)")
    groove = values["groove"] or ("gothic_arch" if rows == 2 else "circular_arc")
    if (rows == 2) != (groove == "gothic_arch"):
        raise GuideError(f"{where}: field 'rows.groove' = '{groove}' does not fit row_count = {rows} "
                         "(two rows: gothic_arch, four contact points per ball; four rows: circular_arc)")
    values["groove"] = groove if ball else values["groove"]
    law = values["contact_law"] or ("hertz_point" if ball else "palmgren")
    if law != ("hertz_point" if ball else "palmgren"):
        raise GuideError(f"{where}: field 'contact.contact_law' = '{law}' does not fit contact_type = "
                         f"'{values['contact_type']}' (ball: hertz_point, Eq. 3; roller: palmgren, Eq. 4)")
    values["contact_law"] = law
    if not ball:
        given = [k for k in _BALL_ONLY if values.get(k) is not None]
        if given:
            raise GuideError(f"{where}: field 'contact.{given[0]}' is for ball guides; set "
                             "contact.contact_type = \"ball\" or remove it")
        return
    for key in ("ball_diameter_m", "conformity_rail", "conformity_carriage"):
        if values[key] is None:
            raise GuideError(f"{where}: field 'contact.{key}' missing (needed by a ball guide)")
    for key in ("conformity_rail", "conformity_carriage"):
        if not 0.5 < values[key] < 1.0:
            raise GuideError(f"{where}: field 'contact.{key}' must be in (0.5, 1) (groove radius / ball "
                             f"diameter; typically 0.51-0.54), got {values[key]}")
    if values["roller_length_m"] is not None:
        raise GuideError(f"{where}: field 'contact.roller_length_m' is for roller guides; a ball has no length")
    if values["roller_diameter_m"] is not None:
        raise GuideError(f"{where}: field 'contact.roller_diameter_m' is for roller guides; "
                         "give a ball guide's 'contact.ball_diameter_m'")
    for key in ("element_poisson", "raceway_poisson"):
        if not 0 < values[key] < 0.5:
            raise GuideError(f"{where}: field 'contact.{key}' must be in (0, 0.5), got {values[key]}")
    ways = [k for k in ("preload_m", "preload_n", "preload_class") if values[k] not in (None, 0.0)]
    if len(ways) > 1:
        raise GuideError(f"{where}: fields 'contact.{ways[0]}' and 'contact.{ways[1]}' both set the preload; give one")
    if values["preload_class"] is not None and values["dynamic_load_rating_n"] is None:
        raise GuideError(f"{where}: field 'contact.preload_class' needs 'contact.dynamic_load_rating_n' "
                         "(the class is a fraction of the dynamic load rating C)")


def _resolve_ball(guide: Guide, where: str) -> Guide:
    """A ball guide's preload as an interference (m) and, unless given, K_n at it from Eq. (3)."""
    from guidefit.errors import ModelError
    from guidefit.model import contact

    try:
        k_h = contact.ball_law_constant(guide)
    except ModelError as exc:
        raise GuideError(f"{where}: {exc}") from None
    sin_b = math.sin(guide.contact_angle_rad)
    preload_m = guide.preload_m
    force = guide.preload_n
    if guide.preload_class is not None:
        force = PRELOAD_CLASSES[guide.preload_class] * guide.dynamic_load_rating_n
    if force is not None:
        # F_pre = 2 Z Q0 sin b: the vertical force with which the upper rows press against the lower ones
        q0 = force / (2.0 * guide.effective_rollers_per_row * sin_b)
        preload_m = (q0 / k_h) ** (2.0 / 3.0)
    if not preload_m > 0 and math.isnan(guide.roller_stiffness_n_per_m):
        raise GuideError(f"{where}: a ball guide without preload has no stiffness at zero load; give "
                         "'contact.preload_m', 'contact.preload_n' or 'contact.preload_class' "
                         "(or 'contact.roller_stiffness_n_per_m')")
    k_n = guide.roller_stiffness_n_per_m
    if math.isnan(k_n):
        k_n = contact.BALL_EXPONENT * k_h * preload_m ** (contact.BALL_EXPONENT - 1.0)
    return replace(guide, preload_m=preload_m, roller_stiffness_n_per_m=k_n)


def _suggest(key: str, spec: dict) -> str:
    close = [k for k in spec if k.split("_")[0] == key.split("_")[0]]
    return f"; did you mean '{close[0]}'?" if close else f"; allowed: {', '.join(spec)}"


_QUANTITY = re.compile(r"^\s*([-+0-9.eE]+)\s*(.*?)\s*$")


def _scalar(value, unit: str | None, what: str) -> float:
    if isinstance(value, bool):
        raise GuideError(f"{what}: expected a number, got {value!r}")
    if isinstance(value, int | float):
        number = float(value)
    elif isinstance(value, str) and unit is not None:
        match = _QUANTITY.match(value)
        if not match:
            raise GuideError(f"{what}: cannot read '{value}' as a number with a unit")
        try:
            number = float(match.group(1))
        except ValueError:
            raise GuideError(f"{what}: cannot read '{value}' as a number with a unit") from None
        unit_text = match.group(2)
        factors = _UNIT_FACTORS[unit]
        if unit_text not in factors:
            raise GuideError(f"{what}: unit '{unit_text}' not allowed here; use one of {', '.join(factors)}")
        number *= factors[unit_text]
    else:
        raise GuideError(f"{what}: expected a number, got {value!r}")
    if not math.isfinite(number):
        raise GuideError(f"{what}: must be finite, got {value!r}")
    return number


def _length_checked(number: float, unit, what: str, value) -> float:
    """A length of a carriage (m) within :data:`MAX_LENGTH_M`: ``e_m = "5.5 m"`` or ``e_m = 5.5`` meant mm
    and gave roll_high at 5.5 MHz with exit 0."""
    if unit == "m" and abs(number) > MAX_LENGTH_M:
        raise GuideError(f"{what}: {value!r} is {abs(number):g} m; a carriage's lengths are at most "
                         f"{MAX_LENGTH_M:g} m (millimetres given? write \"5.5 mm\" or 0.0055)")
    return number


def _convert(value, unit, kind, what):
    if isinstance(kind, tuple):
        if value not in kind:
            raise GuideError(f"{what}: got {value!r}; allowed: {', '.join(kind)}")
        return value
    if kind in ("vec3", "pos3"):
        if not isinstance(value, list) or len(value) != 3:
            raise GuideError(f"{what}: expected a list of 3 numbers, got {value!r}")
        vec = tuple(_length_checked(_scalar(v, unit, what), unit, what, value) for v in value)
        if kind == "pos3" and min(vec) <= 0:
            raise GuideError(f"{what}: all three values must be positive, got {value!r}")
        return vec
    if kind == "int":
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise GuideError(f"{what}: expected a positive integer, got {value!r}")
        return value
    number = _length_checked(_scalar(value, unit, what), unit, what, value)
    if kind == "pos" and number <= 0:
        raise GuideError(f"{what}: must be positive, got {value!r}")
    if kind == "nonneg" and number < 0:
        raise GuideError(f"{what}: must not be negative, got {value!r}")
    if kind == "frac" and not 0 < number <= 1:
        raise GuideError(f"{what}: must be in (0, 1], got {value!r}")
    return number


def _check_physical(guide: Guide, where: str) -> None:
    if guide.rollers_per_row > MAX_ROLLERS_PER_ROW:
        raise GuideError(f"{where}: field 'rows.rollers_per_row' is {guide.rollers_per_row}; at most "
                         f"{MAX_ROLLERS_PER_ROW} (real carriages have 10-60; the model is dense in the rollers)")
    if not 0 < guide.contact_angle_deg < 90:
        raise GuideError(f"{where}: field 'rows.contact_angle_deg' must be in (0, 90), got {guide.contact_angle_deg}")
    if guide.rollers_per_row > 1 and guide.roller_span_m <= 0:
        raise GuideError(f"{where}: field 'rows.roller_span_m' must be positive for more than one roller")
