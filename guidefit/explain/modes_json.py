"""Read identified modes: ``identify --json`` output or a hand-written list (:func:`read_modes_json`)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from guidefit.errors import RecordingError
from guidefit.explain.inputs import ForceLevel, MeasuredMode, Sensor
from guidefit.explain.settings import CARRIAGE_LABELS, canonical_label
from guidefit.modeshapes import UNNAMED_LABELS


def _number(value, what: str, positive: bool = True, allow_none: bool = False):
    if value is None and allow_none:
        return None
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value) \
            or (positive and value <= 0):
        kind = "a positive number" if positive else "a finite number"
        raise RecordingError(f"{what} must be {kind}{' or null' if allow_none else ''}, got {value!r}")
    return float(value)


def _vector3(value, what: str) -> tuple:
    if not isinstance(value, list | tuple) or len(value) != 3:
        raise RecordingError(f"{what} must be a list of 3 numbers, got {value!r}")
    return tuple(_number(v, what, positive=False) for v in value)


def _shape(value, what: str) -> dict | None:
    if value is None:
        return None
    if not isinstance(value, dict):
        raise RecordingError(f"{what} must be an object of channel: amplitude, got {type(value).__name__}")
    out = {}
    for name, v in value.items():
        if isinstance(v, list | tuple) and len(v) == 2:
            out[str(name)] = complex(_number(v[0], f"{what} '{name}'", positive=False),
                                     _number(v[1], f"{what} '{name}'", positive=False))
        elif isinstance(v, dict) and set(v) <= {"re", "im"}:
            out[str(name)] = complex(_number(v.get("re", 0.0), f"{what} '{name}'", positive=False),
                                     _number(v.get("im", 0.0), f"{what} '{name}'", positive=False))
        else:
            out[str(name)] = complex(_number(v, f"{what} '{name}'", positive=False))
    return out


def _std_of(entry: dict, what: str):
    for key in ("frequency_std_hz", "std_hz", "std"):
        if key in entry:
            return _number(entry[key], f"{what}: '{key}'", allow_none=True)
    return None


def _mode_from(entry, what: str, default_label: str | None = None) -> MeasuredMode:
    if not isinstance(entry, dict):
        raise RecordingError(f"{what}: expected an object, got {type(entry).__name__}")
    if "frequency_hz" not in entry:
        raise RecordingError(f"{what}: 'frequency_hz' missing")
    label = entry.get("label", default_label)
    if label is not None and not isinstance(label, str):
        raise RecordingError(f"{what}: 'label' must be a string, got {label!r}")
    run = entry.get("run")
    return MeasuredMode(
        frequency_hz=_number(entry["frequency_hz"], f"{what}: 'frequency_hz'"),
        frequency_std_hz=_std_of(entry, what),
        damping_ratio=_number(entry.get("damping_ratio"), f"{what}: 'damping_ratio'", positive=False,
                              allow_none=True),
        label=label,
        shape=_shape(entry.get("shape"), f"{what}: 'shape'"),
        run=None if run is None else str(run),
        shape_std=_number(entry.get("shape_std"), f"{what}: 'shape_std'", allow_none=True),
    )


def is_unnamed_level(entry) -> bool:
    """True for a force-level entry of an ``extra`` or ``ambiguous`` mode (left out, not an error).

    >>> is_unnamed_level({"label": "ambiguous"}), is_unnamed_level({"label": "vertical"})
    (True, False)
    """
    return isinstance(entry, dict) and isinstance(entry.get("label"), str) \
        and entry["label"].strip().lower() in UNNAMED_LABELS


def level_from(entry, what: str) -> ForceLevel:
    if not isinstance(entry, dict):
        raise RecordingError(f"{what}: expected an object, got {type(entry).__name__}")
    for key in ("peak_force_n", "label", "frequency_hz"):
        if key not in entry:
            raise RecordingError(f"{what}: '{key}' missing")
    if canonical_label(entry["label"]) is None:
        raise RecordingError(f"{what}: 'label' must be one of {', '.join(CARRIAGE_LABELS)}, got {entry['label']!r}")
    pos, direction = entry.get("hit_position_m"), entry.get("hit_direction")
    forces, band = entry.get("hit_forces_n"), entry.get("band_hz")
    if forces is not None and (not isinstance(forces, list) or not forces):
        raise RecordingError(f"{what}: 'hit_forces_n' must be a list of positive numbers, got {forces!r}")
    if band is not None and (not isinstance(band, list) or len(band) != 2):
        raise RecordingError(f"{what}: 'band_hz' must be [low, high], got {band!r}")
    # frequency_hz null: identify's refit of the bin's hits did not reproduce the mode
    return ForceLevel(
        peak_force_n=_number(entry["peak_force_n"], f"{what}: 'peak_force_n'"),
        label=str(entry["label"]),
        frequency_hz=_number(entry["frequency_hz"], f"{what}: 'frequency_hz'", allow_none=True),
        frequency_std_hz=None if entry["frequency_hz"] is None else _std_of(entry, what),
        hit_forces_n=None if forces is None else tuple(_number(x, f"{what}: 'hit_forces_n'") for x in forces),
        band_hz=None if band is None else tuple(_number(x, f"{what}: 'band_hz'") for x in band),
        shape=_shape(entry.get("shape"), f"{what}: 'shape'"),
        hit_position_m=None if pos is None else _vector3(pos, f"{what}: 'hit_position_m'"),
        hit_direction=None if direction is None else _vector3(direction, f"{what}: 'hit_direction'"),
        pulse_s=_number(entry.get("pulse_s"), f"{what}: 'pulse_s'", allow_none=True),
        run=None if entry.get("run") is None else str(entry["run"]),
    )


def modes_from_result(obj, where: str = "modes"):
    """Measured modes, guide name, sensors and force levels from a parsed result.

    ``obj`` is an ``identify --json`` object (``modes`` with label,
    frequency_hz, damping_ratio and optional frequency_std_hz, shape, run;
    optional ``extra_modes``, ``sensors``, ``force_levels`` and
    ``parameters`` f_V/f_H, whose value and std complete the vertical and
    roll_low modes), an object with just ``modes``, or a plain list of modes.
    Modes labelled ``ambiguous`` or ``extra`` (in ``modes`` or
    ``extra_modes``) are kept as unnamed modes that explain pairs by
    frequency; force levels labelled so are left out (a level must name a
    model mode; any other unknown label is an error).
    Standard deviations may be named ``frequency_std_hz``, ``std_hz`` or ``std``.

    Examples
    --------
    >>> modes, guide, sensors, levels = modes_from_result(
    ...     [{"label": "vertical", "frequency_hz": 3450.0, "std_hz": 0.8}])
    >>> modes[0].frequency_std_hz, guide
    (0.8, None)
    """
    if isinstance(obj, list):
        root, entries = {}, obj
    elif isinstance(obj, dict):
        root, entries = obj, obj.get("modes", [])
        if not isinstance(entries, list):
            raise RecordingError(f"{where}: 'modes' must be a list")
    else:
        raise RecordingError(f"{where}: expected a list of modes or an object with 'modes', got {type(obj).__name__}")
    modes = [_mode_from(e, f"{where}: modes entry {k}") for k, e in enumerate(entries)]
    extras = root.get("extra_modes") or []
    if not isinstance(extras, list):
        raise RecordingError(f"{where}: 'extra_modes' must be a list")
    modes += [_mode_from(e, f"{where}: extra_modes entry {k}", "extra") for k, e in enumerate(extras)]
    params = root.get("parameters") or {}
    if not isinstance(params, dict):
        raise RecordingError(f"{where}: 'parameters' must be an object")
    for key, label in (("f_V", "vertical"), ("f_H", "roll_low")):
        p = params.get(key)
        if not isinstance(p, dict) or p.get("value") is None:
            continue
        value = _number(p["value"], f"{where}: parameters '{key}' value")
        std = _number(p.get("std"), f"{where}: parameters '{key}' std", allow_none=True)
        same = [k for k, m in enumerate(modes) if canonical_label(m.label) == label]
        if not same:
            modes.append(MeasuredMode(value, std, label=label))
        elif std is not None:
            for k in same:
                if modes[k].frequency_std_hz is None and abs(modes[k].frequency_hz - value) <= 1e-6 * value:
                    m = modes[k]
                    modes[k] = MeasuredMode(m.frequency_hz, std, m.damping_ratio, m.label, m.shape, m.run,
                                            m.shape_std)
    if not modes:
        raise RecordingError(f"{where}: no modes")
    guide = root.get("guide")
    if guide is not None and not isinstance(guide, str):
        raise RecordingError(f"{where}: 'guide' must be a string, got {guide!r}")
    sensors = []
    for k, s in enumerate(root.get("sensors") or []):
        what = f"{where}: sensors entry {k}"
        if not isinstance(s, dict) or "name" not in s:
            raise RecordingError(f"{what}: expected an object with name, position_m, direction")
        d = np.asarray(_vector3(s.get("direction"), f"{what}: 'direction'"))
        if not np.linalg.norm(d) > 0:
            raise RecordingError(f"{what}: 'direction' must not be zero")
        sensors.append(Sensor(str(s["name"]), _vector3(s.get("position_m"), f"{what}: 'position_m'"),
                              tuple(d / np.linalg.norm(d))))
    raw_levels = root.get("force_levels") or []
    if not isinstance(raw_levels, list):
        raise RecordingError(f"{where}: 'force_levels' must be a list")
    levels = [level_from(e, f"{where}: force_levels entry {k}") for k, e in enumerate(raw_levels)
              if not is_unnamed_level(e)]
    return modes, guide, sensors, levels


def read_modes_json(path):
    """Read identified modes from JSON: ``identify --json`` output or a hand-written list.

    Accepts one JSON document (a list of modes, or an object with ``modes``)
    or JSON Lines holding exactly one object (``identify FILE --json``).

    Returns
    -------
    (list of MeasuredMode, guide name or None, list of Sensor, list of ForceLevel)

    Raises
    ------
    RecordingError
        One line naming the file and the entry at fault.
    IdentificationError
        The result is of an identification the plausibility gate rejected (its ``gate``
        says why): its modes are not those of a carriage on the guide, nothing to explain.

    Examples
    --------
    >>> import json, tempfile, os
    >>> with tempfile.NamedTemporaryFile("w", suffix=".json", delete=False) as fh:
    ...     json.dump([{"label": "vertical", "frequency_hz": 3450.0, "std_hz": 0.8},
    ...                {"label": "roll_low", "frequency_hz": 1075.0, "std_hz": 0.9}], fh)
    >>> modes, guide, sensors, levels = read_modes_json(fh.name)
    >>> [(m.label, m.frequency_hz) for m in modes]
    [('vertical', 3450.0), ('roll_low', 1075.0)]
    >>> os.remove(fh.name)
    """
    from guidefit.jsonio import read_json_documents

    p = Path(path)
    docs = read_json_documents(p)
    if len(docs) != 1:
        raise RecordingError(f"{p}: {len(docs)} JSON lines (one per recording); explain takes one")
    obj = docs[0]
    gate = obj.get("gate") if isinstance(obj, dict) else None
    if isinstance(gate, str) and gate:  # as identify said it (exit 1)
        from guidefit.errors import IdentificationError

        raise IdentificationError(f"identification rejected: {obj.get('file', p)}: {gate}")
    return modes_from_result(obj, str(p))


