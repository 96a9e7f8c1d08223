"""The measured modes explain starts from: an Identification's objects (:func:`modes_from_identification`), or
``identify --json`` output or a hand-written list (:func:`read_modes_json`, :func:`modes_from_result`)."""

from __future__ import annotations

from pathlib import Path

from guidefit.errors import RecordingError
from guidefit.explain.settings import canonical_label
from guidefit.jsonio import parameter_factor
from guidefit.model.measured import (
    ForceLevel,
    MeasuredMode,
    checked_number,
    checked_sensor,
    checked_shape,
    checked_vector3,
    measured_mode,
)
from guidefit.model.vibration import MODE_LABELS, UNNAMED_LABELS


def _std_of(entry: dict, what: str):
    for key in ("frequency_std_hz", "std_hz", "std"):
        if key in entry:
            return checked_number(entry[key], f"{what}: '{key}'", allow_none=True)
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
        frequency_hz=checked_number(entry["frequency_hz"], f"{what}: 'frequency_hz'"),
        frequency_std_hz=_std_of(entry, what),
        damping_ratio=checked_number(entry.get("damping_ratio"), f"{what}: 'damping_ratio'", positive=False,
                              allow_none=True),
        label=label,
        shape=checked_shape(entry.get("shape"), f"{what}: 'shape'"),
        run=None if run is None else str(run),
        shape_std=checked_number(entry.get("shape_std"), f"{what}: 'shape_std'", allow_none=True),
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
        raise RecordingError(f"{what}: 'label' must be one of {', '.join(MODE_LABELS)}, got {entry['label']!r}")
    pos, direction = entry.get("hit_position_m"), entry.get("hit_direction")
    forces, band = entry.get("hit_forces_n"), entry.get("band_hz")
    if forces is not None and (not isinstance(forces, list) or not forces):
        raise RecordingError(f"{what}: 'hit_forces_n' must be a list of positive numbers, got {forces!r}")
    if band is not None and (not isinstance(band, list) or len(band) != 2):
        raise RecordingError(f"{what}: 'band_hz' must be [low, high], got {band!r}")
    # frequency_hz null: identify's refit of the bin's hits did not reproduce the mode
    return ForceLevel(
        peak_force_n=checked_number(entry["peak_force_n"], f"{what}: 'peak_force_n'"),
        label=str(entry["label"]),
        frequency_hz=checked_number(entry["frequency_hz"], f"{what}: 'frequency_hz'", allow_none=True),
        frequency_std_hz=None if entry["frequency_hz"] is None else _std_of(entry, what),
        hit_forces_n=None if forces is None else tuple(checked_number(x, f"{what}: 'hit_forces_n'") for x in forces),
        band_hz=None if band is None else tuple(checked_number(x, f"{what}: 'band_hz'") for x in band),
        shape=checked_shape(entry.get("shape"), f"{what}: 'shape'"),
        hit_position_m=None if pos is None else checked_vector3(pos, f"{what}: 'hit_position_m'"),
        hit_direction=None if direction is None else checked_vector3(direction, f"{what}: 'hit_direction'"),
        pulse_s=checked_number(entry.get("pulse_s"), f"{what}: 'pulse_s'", allow_none=True),
        run=None if entry.get("run") is None else str(entry["run"]),
    )


def _with_joint_parameters(modes: list, params: dict, where: str) -> list:
    """The modes completed by the joint parameters f_V and f_H (value and std) of an identification.

    A vertical or roll_low mode that is missing is added from its parameter,
    or, where an unlabelled mode has the parameter's frequency, that mode is
    named by it (before: a list without labels had each joint mode twice, one
    measurement counted twice in chi2); one of the same frequency without a
    standard deviation takes the parameter's.
    """
    modes = list(modes)
    for key, label in (("f_V", "vertical"), ("f_H", "roll_low")):
        p = params.get(key)
        if not isinstance(p, dict) or p.get("value") is None:
            continue
        scale = parameter_factor(key, p, where)
        value = checked_number(p["value"], f"{where}: parameters '{key}' value") * scale
        std = checked_number(p.get("std"), f"{where}: parameters '{key}' std", allow_none=True)
        std = None if std is None else std * scale
        same = [k for k, m in enumerate(modes) if canonical_label(m.label) == label]
        unnamed = [k for k, m in enumerate(modes) if (m.label is None or m.label.strip().lower() in UNNAMED_LABELS)
                   and abs(m.frequency_hz - value) <= 1e-6 * value]
        if not same and unnamed:  # the parameter names that mode: one measurement, not two
            from dataclasses import replace

            m = modes[unnamed[0]]
            modes[unnamed[0]] = replace(m, label=label, frequency_std_hz=m.frequency_std_hz if std is None else std)
        elif not same:
            modes.append(MeasuredMode(value, std, label=label))
        elif std is not None:
            for k in same:
                if modes[k].frequency_std_hz is None and abs(modes[k].frequency_hz - value) <= 1e-6 * value:
                    m = modes[k]
                    modes[k] = MeasuredMode(m.frequency_hz, std, m.damping_ratio, m.label, m.shape, m.run,
                                            m.shape_std)
    return modes


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
    modes = _with_joint_parameters(modes, params, where)
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
        sensors.append(checked_sensor(s["name"], s.get("position_m"), s.get("direction"), what))
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
    results = [e for e in obj if isinstance(e, dict) and ("parameters" in e or "modes" in e)] \
        if isinstance(obj, list) else []
    if results and len(obj) == 1:  # [result]: a one-result array (export's input form) is that result
        obj = obj[0]
    elif results:  # was read as a list of modes: "modes entry 0: 'frequency_hz' missing"
        raise RecordingError(f"{p}: a JSON array of {len(obj)} identify results; explain takes one")
    gate = obj.get("gate") if isinstance(obj, dict) else None
    if isinstance(gate, str) and gate:  # as identify said it (exit 1)
        from guidefit.errors import IdentificationError

        raise IdentificationError(f"identification rejected: {obj.get('file', p)}: {gate}")
    return modes_from_result(obj, str(p))




def modes_from_identification(identification) -> tuple[list, list]:
    """Measured modes and sensors of an :class:`~guidefit.identify.Identification`, from its objects.

    The same modes and sensors as :func:`modes_from_result` gives for its
    ``identify --json`` object (``tests/test_explain.py`` compares the two):
    its modes and extra modes (:func:`guidefit.model.measured.measured_mode`),
    completed by the joint parameters f_V and f_H, and the response channels
    of its runs, first occurrence of each name. Its force levels are the
    caller's (:func:`guidefit.explain.entry.explain_identification`).
    """
    where = str(identification.file)
    modes = [measured_mode(m, f"{where}: modes entry {k}") for k, m in enumerate(identification.modes)]
    modes += [measured_mode(m, f"{where}: extra_modes entry {k}") for k, m in enumerate(identification.extra_modes)]
    modes = _with_joint_parameters(modes, identification.parameters or {}, where)
    if not modes:
        raise RecordingError(f"{where}: no modes")
    channels: dict = {}
    for run in identification.runs:
        for ch in run.channels:
            channels.setdefault(ch.name, ch)
    sensors = [checked_sensor(ch.name, [float(x) for x in ch.position_m], [float(x) for x in ch.direction],
                              f"{where}: sensors entry {k}") for k, ch in enumerate(channels.values())]
    return modes, sensors
