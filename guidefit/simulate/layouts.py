r"""Accelerometer layouts and hammer hit points of a hammer test.

A *layout* says which accelerometers a run records: a channel name
``acc_<point>_<axis>`` (the recording contract), a position in the carriage
frame (x lateral, y up, z along the rail; origin at the centre of the top
mounting face) and the unit vector of the sensor's positive axis. Layouts
differ between runs: the most common test records four accelerometers at the
guide's points A-D along the hammer's axis of each run (y in the vertical
run, x in the lateral run). :func:`resolve_layout` turns a layout name or a
TOML file into each run's sensors; ``guidefit simulate --sensors`` uses it,
and so can any command that wants to know what a rig will record. No signal
processing here.

Layout names (:data:`LAYOUTS`)
------------------------------
``default`` (alias ``ad``)
    Points A-D, one axis per run: the axis of the run's hammer direction
    (its largest absolute component; a tie goes to x before y before z),
    sensors along + that axis.
``both``
    x and y at A-D in every run (8 sensors per run; what
    :class:`guidefit.simulate.SimulationConfig` records by default).
``pair``
    Points A and C only, one axis per run as ``default``.
``single``
    Point A only, one axis per run as ``default``.
``triax:A,C``
    x, y and z at the named guide points in every run (``triax`` alone: A-D).
``side``
    A run whose hammer axis is x records x along +x at four side-face points
    E, F, G, H (:func:`side_points_m`); every other run records its hammer
    axis at A-D as ``default``.
a path to a TOML file (``*.toml``)
    A list of sensors, see :func:`read_layout_file`.

Hit points
----------
``RUN:x,y,z`` (m, carriage frame) moves the hammer point of a run
(:func:`parse_hit`, :func:`apply_hits`); the direction is kept.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, replace
from pathlib import Path

from guidefit.errors import ModelError

#: Layout name -> what it records (the help text of ``--sensors``).
LAYOUTS = {
    "default": "A-D, one axis per run (the hammer's axis)",
    "ad": "alias of default",
    "both": "x and y at A-D in every run",
    "pair": "A and C, one axis per run",
    "single": "A only, one axis per run",
    "triax:A,C": "x, y, z at the named points in every run",
    "side": "x at side-face points E-H in the lateral run, y at A-D in the vertical run",
}

#: Channel names of accelerometers, as the recording reader accepts them
#: (``guidefit.io.records``).
CHANNEL_RE = re.compile(r"^acc_([A-Za-z0-9]+)_([xyz])\Z")

AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}
DEFAULT_POINTS = ("A", "B", "C", "D")

#: Side-face sensors (``side``): depth below the top face (m) and inset from the
#: ends of the A-D span along z (m). MRB35: y = -0.015 (below the lateral hammer
#: point at y = -0.012, above the upper roller rows at -h1 = -0.0235) and
#: z = +/-(0.045 - 0.005) = +/-0.040.
SIDE_DEPTH_M = 0.015
SIDE_INSET_M = 0.005
SIDE_POINTS = ("E", "F", "G", "H")

#: Bounds on a layout file (a real rig has tens of channels).
MAX_LAYOUT_FILE_BYTES = 1_000_000
MAX_SENSORS = 1_000
_SENSOR_KEYS = ("name", "position_m", "direction", "runs")


@dataclass(frozen=True)
class HammerRun:
    """One excitation set-up: run name, hit point (m, carriage frame) and force direction.

    Also ``guidefit.simulate.HammerRun``.
    """

    name: str
    position_m: tuple[float, float, float]
    direction: tuple[float, float, float]


#: 'vertical': near the top centre, slightly off-centre so that pitch and roll are
#: weakly excited too, force downwards; 'lateral': on the carriage side below the
#: top face, force along -x.
DEFAULT_RUNS = (
    HammerRun("vertical", (0.004, 0.0, 0.008), (0.0, -1.0, 0.0)),
    HammerRun("lateral", (0.05, -0.012, 0.006), (-1.0, 0.0, 0.0)),
)


@dataclass(frozen=True)
class SensorSpec:
    """One accelerometer: channel name, position (m, carriage frame), unit direction.

    Examples
    --------
    >>> s = SensorSpec("acc_A_y", (0.03, 0.0, 0.045), (0.0, 1.0, 0.0))
    >>> s.point, s.axis
    ('A', 'y')
    """

    name: str
    position_m: tuple[float, float, float]
    direction: tuple[float, float, float]

    @property
    def point(self) -> str:
        """Point name of the channel (``"A"`` of ``acc_A_y``)."""
        return CHANNEL_RE.match(self.name).group(1)

    @property
    def axis(self) -> str:
        """Axis letter of the channel name (``"y"`` of ``acc_A_y``)."""
        return CHANNEL_RE.match(self.name).group(2)

    def to_dict(self) -> dict:
        """JSON-ready dictionary."""
        return {"name": self.name, "position_m": list(self.position_m), "direction": list(self.direction)}


def run_axis(direction) -> str:
    """Axis letter of a hammer direction: its largest absolute component (ties: x, y, z in order).

    >>> run_axis((0.0, -1.0, 0.0)), run_axis((-1.0, 0.2, 0.0)), run_axis((0.0, 0.0, 2.0))
    ('y', 'x', 'z')
    """
    values = [abs(float(v)) for v in direction]
    return "xyz"[values.index(max(values))]


def side_points_m(guide) -> dict[str, tuple[float, float, float]]:
    """Side-face measuring points E, F, G, H of ``guide`` (m, carriage frame).

    Points E-H that the guide defines in its ``[points]`` are used as they
    are. Otherwise (the :class:`~guidefit.model.guides.Guide` has no
    carriage width), ``w`` is the |x| of the lateral hammer point of
    :data:`DEFAULT_RUNS` (the hammer hits the side face
    there), the depth is :data:`SIDE_DEPTH_M` below the top face and
    ``z1`` is the largest |z| of the guide's points A-D less
    :data:`SIDE_INSET_M`: E (+w, -s, +z1), F (+w, -s, -z1), G (-w, -s, +z1),
    H (-w, -s, -z1).

    Examples
    --------
    >>> from guidefit.model.guides import load_guide
    >>> {k: tuple(round(v, 3) for v in p) for k, p in side_points_m(load_guide("MRB35")).items()}
    {'E': (0.05, -0.015, 0.04), 'F': (0.05, -0.015, -0.04), 'G': (-0.05, -0.015, 0.04), 'H': (-0.05, -0.015, -0.04)}
    """
    points = guide.measuring_points_m
    if all(p in points for p in SIDE_POINTS):
        return {p: tuple(float(v) for v in points[p]) for p in SIDE_POINTS}
    w = abs(float(next(r for r in DEFAULT_RUNS if r.name == "lateral").position_m[0]))
    _points(guide, DEFAULT_POINTS, "side")
    z1 = max(abs(float(points[p][2])) for p in DEFAULT_POINTS) - SIDE_INSET_M
    s = SIDE_DEPTH_M
    return {"E": (w, -s, z1), "F": (w, -s, -z1), "G": (-w, -s, z1), "H": (-w, -s, -z1)}


def resolve_layout(guide, layout: str, runs) -> dict[str, tuple[SensorSpec, ...]]:
    """Each run's accelerometers (not the force channel) for a layout.

    Parameters
    ----------
    guide : Guide or str
        The guide (its measuring points A-D and any others), or its name / TOML path.
    layout : str or Path
        A name of :data:`LAYOUTS` (``triax:`` followed by comma-separated
        guide points) or the path of a layout TOML file (:func:`read_layout_file`).
    runs : iterable of HammerRun
        The runs (anything with ``name`` and ``direction``), e.g. :data:`DEFAULT_RUNS`.

    Returns
    -------
    dict
        Run name -> tuple of :class:`SensorSpec`, in the runs' order.

    Raises
    ------
    ModelError
        One line naming the layout, the point or the file key at fault.

    Examples
    --------
    >>> out = resolve_layout("MRB35", "default", DEFAULT_RUNS)
    >>> {run: [s.name for s in sensors] for run, sensors in out.items()}
    {'vertical': ['acc_A_y', 'acc_B_y', 'acc_C_y', 'acc_D_y'], 'lateral': ['acc_A_x', 'acc_B_x', 'acc_C_x', 'acc_D_x']}
    >>> [s.name for s in resolve_layout("MRB35", "triax:A,C", DEFAULT_RUNS)["lateral"]]
    ['acc_A_x', 'acc_A_y', 'acc_A_z', 'acc_C_x', 'acc_C_y', 'acc_C_z']
    """
    if isinstance(guide, str | Path):
        from guidefit.model.guides import load_guide

        guide = load_guide(guide)
    runs = tuple(runs)
    text = str(layout).strip()
    key = text.lower()
    if key.endswith(".toml") or (isinstance(layout, Path) and layout.suffix.lower() == ".toml"):
        return read_layout_file(text, guide, runs)
    if key in ("default", "ad", "pair", "single"):
        names = {"pair": ("A", "C"), "single": ("A",)}.get(key, DEFAULT_POINTS)
        points = _points(guide, names, key)
        return {r.name: _grid(points, run_axis(r.direction)) for r in runs}
    if key == "both":
        points = _points(guide, DEFAULT_POINTS, key)
        return {r.name: _grid(points, "xy") for r in runs}
    if key == "triax" or key.startswith("triax:"):
        names = tuple(p.strip() for p in text.partition(":")[2].split(",")) if ":" in text else DEFAULT_POINTS
        if any(not p for p in names):
            raise ModelError(f"layout '{text}': expected triax:POINT,POINT,... (e.g. triax:A,C)")
        if len(set(names)) != len(names):
            raise ModelError(f"layout '{text}': a point is named twice")
        points = _points(guide, names, text)
        return {r.name: _grid(points, "xyz") for r in runs}
    if key == "side":
        points = _points(guide, DEFAULT_POINTS, key)
        side = side_points_m(guide)
        out = {}
        for r in runs:
            axis = run_axis(r.direction)
            out[r.name] = _grid(side, "x") if axis == "x" else _grid(points, axis)
        return out
    if Path(text).is_file():
        return read_layout_file(text, guide, runs)
    raise ModelError(f"layout '{text}' unknown; have default, ad, both, pair, single, side, "
                     f"triax:POINT,... or a layout .toml file")


def _points(guide, names, layout: str) -> dict[str, tuple[float, float, float]]:
    have = guide.measuring_points_m
    for p in names:
        if p not in have:
            raise ModelError(f"layout '{layout}': point '{p}' not defined by guide {guide.name} "
                             f"(have {', '.join(have) or 'none'})")
        if not CHANNEL_RE.match(f"acc_{p}_x"):
            raise ModelError(f"layout '{layout}': point '{p}' cannot name a channel (letters and digits only)")
    return {p: tuple(float(v) for v in have[p]) for p in names}


def _grid(points: dict, axes: str) -> tuple[SensorSpec, ...]:
    return tuple(SensorSpec(f"acc_{p}_{a}", pos, AXES[a]) for p, pos in points.items() for a in axes)


def read_layout_file(path, guide, runs) -> dict[str, tuple[SensorSpec, ...]]:
    """Each run's sensors from a layout TOML file.

    The file holds a list of ``[[sensor]]`` tables with the keys

    ``name`` (required)
        Channel name ``acc_<point>_<axis>`` (e.g. ``acc_E_x``).
    ``position_m``
        ``[x, y, z]`` in m, carriage frame; default: the guide's point of
        that name (an error if the guide has none).
    ``direction``
        ``[dx, dy, dz]``, any non-zero length (normalised); default: the
        axis letter of the name.
    ``runs``
        Names of the runs that record this sensor; default: every run.

    Every run must get at least one sensor and no channel name twice.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> text = '''
    ... [[sensor]]
    ... name = "acc_A_y"
    ... [[sensor]]
    ... name = "acc_E_x"
    ... position_m = [0.05, -0.015, 0.04]
    ... direction = [1, 0, 0]
    ... runs = ["lateral"]
    ... '''
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     path = pathlib.Path(folder) / "rig.toml"
    ...     _ = path.write_text(text)
    ...     out = read_layout_file(path, "MRB35", DEFAULT_RUNS)
    >>> {run: [s.name for s in sensors] for run, sensors in out.items()}
    {'vertical': ['acc_A_y'], 'lateral': ['acc_A_y', 'acc_E_x']}
    """
    if isinstance(guide, str | Path):
        from guidefit.model.guides import load_guide

        guide = load_guide(guide)
    path = Path(path)
    where = f"layout {path}"
    sensors = _sensor_tables(path, where)
    run_names = [r.name for r in runs]
    out: dict[str, list[SensorSpec]] = {name: [] for name in run_names}
    for i, entry in enumerate(sensors):
        spec, at = _sensor_spec(entry, f"{where}: sensor[{i}]", guide)
        targets = entry.get("runs", run_names)
        if not isinstance(targets, list) or not all(isinstance(t, str) for t in targets) or not targets:
            raise ModelError(f"{at}: key 'runs' must be a non-empty list of run names")
        for t in targets:
            if t not in out:
                raise ModelError(f"{at}: key 'runs': run '{t}' not simulated; have {', '.join(run_names)}")
            if any(s.name == spec.name for s in out[t]):
                raise ModelError(f"{at}: channel '{spec.name}' twice in run '{t}'")
            out[t].append(spec)
    for name, specs in out.items():
        if not specs:
            raise ModelError(f"{where}: run '{name}' has no sensor (give it one or list it in a sensor's 'runs')")
    return {name: tuple(specs) for name, specs in out.items()}


def _sensor_tables(path: Path, where: str) -> list[dict]:
    """The ``[[sensor]]`` tables of a layout file, read and checked for shape (one-line errors)."""
    import tomllib

    if not path.is_file():
        raise ModelError(f"{where}: no such file")
    try:
        with path.open("rb") as handle:
            raw = handle.read(MAX_LAYOUT_FILE_BYTES + 1)
        if len(raw) > MAX_LAYOUT_FILE_BYTES:
            raise ModelError(f"{where}: larger than {MAX_LAYOUT_FILE_BYTES // 1000} kB; not a layout file")
        data = tomllib.loads(raw.decode("utf-8"))
    except (OSError, UnicodeDecodeError) as exc:
        raise ModelError(f"{where}: cannot read ({exc.__class__.__name__})") from None
    except tomllib.TOMLDecodeError as exc:
        raise ModelError(f"{where}: not valid TOML ({exc})") from None
    except RecursionError:
        raise ModelError(f"{where}: not a layout file (arrays or tables nested too deeply)") from None
    for key in data:
        if key != "sensor":
            raise ModelError(f"{where}: unknown key '{key}'; expected [[sensor]] tables")
    sensors = data.get("sensor")
    if not isinstance(sensors, list) or not sensors or not all(isinstance(s, dict) for s in sensors):
        raise ModelError(f"{where}: key 'sensor' must be one or more [[sensor]] tables")
    if len(sensors) > MAX_SENSORS:
        raise ModelError(f"{where}: {len(sensors)} sensors; at most {MAX_SENSORS}")
    return sensors


def _sensor_spec(entry: dict, at: str, guide) -> tuple[SensorSpec, str]:
    """One ``[[sensor]]`` table as a SensorSpec (position and direction defaulted from the guide and the
    name), and the text that names it in errors."""
    for key in entry:
        if key not in _SENSOR_KEYS:
            raise ModelError(f"{at}: unknown key '{key}'; allowed: {', '.join(_SENSOR_KEYS)}")
    name = entry.get("name")
    if not isinstance(name, str):
        raise ModelError(f"{at}: key 'name' missing or not a string; expected a channel name such as 'acc_E_x'")
    match = CHANNEL_RE.match(name)
    if not match:
        raise ModelError(f"{at}: key 'name' = {name!r}; expected 'acc_<point>_<axis>' with axis x, y or z")
    at = f"{at} ({name})"
    point, axis = match.groups()
    if "position_m" in entry:
        position = _vector(entry["position_m"], at, "position_m", nonzero=False)
    elif point in guide.measuring_points_m:
        position = tuple(float(v) for v in guide.measuring_points_m[point])
    else:
        raise ModelError(f"{at}: key 'position_m' missing and guide {guide.name} defines no point '{point}'")
    direction = _vector(entry["direction"], at, "direction", nonzero=True) if "direction" in entry else AXES[axis]
    return SensorSpec(name, position, direction), at


def _vector(value, at: str, key: str, nonzero: bool) -> tuple[float, float, float]:
    ok = isinstance(value, list) and len(value) == 3 and all(
        isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in value)
    if not ok:
        raise ModelError(f"{at}: key '{key}' = {value!r}; expected 3 finite numbers")
    v = tuple(float(x) for x in value)
    if nonzero:
        norm = math.sqrt(sum(x * x for x in v))
        if norm == 0:
            raise ModelError(f"{at}: key '{key}' = {value!r}; expected a non-zero vector")
        v = tuple(x / norm for x in v)
    return v


def parse_hit(text: str) -> tuple[str, tuple[float, float, float]]:
    """Parse ``RUN:x,y,z`` (the ``--hit`` syntax; m, carriage frame).

    Examples
    --------
    >>> parse_hit("lateral:0.05,-0.01,0")
    ('lateral', (0.05, -0.01, 0.0))
    """
    run, sep, rest = str(text).partition(":")
    run = run.strip()
    parts = [p.strip() for p in rest.split(",")]
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        values = ()
    if not sep or not run or len(values) != 3 or not all(math.isfinite(v) for v in values):
        raise ModelError(f"hit: expected RUN:x,y,z in m (e.g. lateral:0.05,-0.012,0.006), got {text!r}")
    return run, values


def _hit_text(hit) -> str:
    try:
        name, position = hit
        return f"{name}:{','.join(str(float(v)) for v in position)}"
    except (TypeError, ValueError):
        return repr(hit)


def apply_hits(runs, hits) -> tuple:
    """The runs with their hammer points moved; ``hits`` are ``RUN:x,y,z`` texts or (run, (x, y, z)).

    Examples
    --------
    >>> [r.position_m for r in apply_hits(DEFAULT_RUNS, ["vertical:0,0,0"])]
    [(0.0, 0.0, 0.0), (0.05, -0.012, 0.006)]
    """
    runs = tuple(runs)
    names = [r.name for r in runs]
    moved: dict = {}
    for hit in hits:
        name, position = parse_hit(hit if isinstance(hit, str) else _hit_text(hit))
        if name not in names:
            raise ModelError(f"hit: run '{name}' not simulated; have {', '.join(names)}")
        if name in moved:
            raise ModelError(f"hit: run '{name}' given twice")
        moved[name] = position
    return tuple(replace(r, position_m=moved[r.name]) if r.name in moved else r for r in runs)
