"""Export identified joints to a machine FE model (paper Section 4, Figure 10).

The package, from the bottom up:

- :mod:`guidefit.export.core`: the joints (apparent and explained, what is
  exported and why: see its docstring), the elements, units and axis maps,
  and the Nastran, ANSYS, Abaqus and JSON writers;
- :mod:`guidefit.export.calculix`: the CalculiX include file;
- :mod:`guidefit.export.reference`: CalculiX's runnable reference assembly;
- this module: :func:`export`, reading results and choosing the writer.

The names below are the public API (``from guidefit.export import export``).
"""

from __future__ import annotations

from guidefit.export.calculix import DEFAULT_ROT_OFFSET, IDS_PER_ELEMENT, check_ids, to_calculix
from guidefit.export.core import (
    DOF_NAMES,
    ELEMENTS,
    FORMATS,
    JOINTS,
    NASTRAN_MAX_ID,
    OTHER_MAX_ID,
    UNIT_SYSTEMS,
    Element,
    ExportError,
    Joint,
    _safe,
    apparent_joint,
    build_elements,
    explained_joint,
    joints_from_results,
    parse_axis_map,
    read_results,
    to_abaqus,
    to_ansys,
    to_json,
    to_nastran,
    transform,
    unit_transform,
)
from guidefit.export.reference import reference_deck

__all__ = [
    "DOF_NAMES", "ELEMENTS", "FORMATS", "JOINTS", "UNIT_SYSTEMS", "Element", "ExportError", "Joint",
    "apparent_joint", "build_elements", "explained_joint", "export", "joints_from_results", "parse_axis_map",
    "read_results", "to_abaqus", "to_ansys", "to_calculix", "to_json", "to_nastran", "transform", "unit_transform",
]


def export(results_path, fmt: str, *, joint: str = "explained", explanations=(), guide=None,
           element: str = "matrix", units: str = "si", axis_map: str | None = None, progress=None,
           assembly: str = "include", skipped: list | None = None, **numbering) -> str:
    """Read identify results (and optional explain results) and render them in ``fmt``.

    ``explanations`` are paths of ``explain --json`` output; ``numbering``:
    ``carriage_nodes``, ``rail_nodes``, ``first_element``, ``id_step``,
    ``n_vertical``, ``n_horizontal`` of :func:`build_elements` (calculix also
    ``rot_offset``); ``assembly="reference"``: calculix's runnable reference deck
    (:mod:`guidefit.export.calculix`). ``skipped``: a list that gets one line
    per result left out because identify failed on it (without it, such a
    result is an error).
    """
    from guidefit.jsonio import read_json_documents

    if fmt not in FORMATS:
        raise ExportError(f"export: format '{fmt}' unknown; use one of {', '.join(FORMATS)}")
    docs = []
    for path in explanations:
        for d in read_json_documents(path):
            docs.extend(d if isinstance(d, list) else [d])
    if assembly != "include" and fmt != "calculix":
        raise ExportError(f"export: --assembly {_safe(assembly, 20)} is for --format calculix only")
    rot = parse_axis_map(axis_map)
    unit_transform(units)
    results = read_results(results_path)
    joints = joints_from_results(results, joint, docs, guide, where=_safe(str(results_path)),
                                 progress=progress, skipped=skipped)
    for key in ("carriage_nodes", "rail_nodes"):  # ids given per results line: those of left-out lines go
        ids = numbering.get(key)
        if ids is not None and len(ids) == len(results) != len(joints):
            numbering[key] = [ids[j.entry] for j in joints]
    if fmt == "calculix":
        return _render_calculix(joints, element=element, units=units, axis_map=rot, axis_map_text=axis_map,
                      assembly=assembly, guide=guide, **numbering)
    numbering.pop("rot_offset", None)
    max_id = NASTRAN_MAX_ID if fmt == "nastran" else OTHER_MAX_ID
    per = {("ansys", "matrix"): 2, ("ansys", "bush"): 6, ("abaqus", "springs"): 2}.get((fmt, element), 1)
    elements = build_elements(joints, element, units=units, axis_map=rot, max_id=max_id, ids_per_element=per,
                              **numbering)
    writer = {"nastran": to_nastran, "ansys": to_ansys, "abaqus": to_abaqus, "json": to_json}[fmt]
    return writer(joints, elements, units=units, axis_map_text=axis_map, element=element)


def _render_calculix(joints: list[Joint], *, element: str = "matrix", units: str = "si", axis_map=None,
           axis_map_text=None, assembly: str = "include", guide=None, **numbering) -> str:
    """``export --format calculix``: the include file, or the reference assembly deck."""
    rot_offset = int(numbering.pop("rot_offset", None) or DEFAULT_ROT_OFFSET)
    elements = build_elements(joints, element, units=units, axis_map=axis_map,
                              ids_per_element=IDS_PER_ELEMENT[element], **numbering)
    check_ids(elements, element, numbering.get("id_step", 100), rot_offset)
    if assembly == "include":
        return to_calculix(joints, elements, units, axis_map_text, element, rot_offset)
    if assembly != "reference":
        raise ExportError(f"export: assembly '{assembly}' unknown; use include or reference")
    n_v, n_h = numbering.get("n_vertical", 4), numbering.get("n_horizontal", 8)
    if element == "springs" and (n_v % 4 or n_h % 8):  # springs at some corners only: a joint it is not
        raise ExportError(f"export: --assembly reference puts the springs at the 4 (vertical) and 8 (horizontal) "
                          f"corners of the roller rows; --vertical {n_v} --horizontal {n_h} would leave corners "
                          "empty and couple the modes (vertical 3529 -> 3644 Hz for 3 and 5): give multiples "
                          "of 4 and 8")
    return reference_deck(joints, elements, units=units, axis_map=axis_map, axis_map_text=axis_map_text,
                          element=element, rot_offset=rot_offset, guide=guide,
                          n_vertical=numbering.get("n_vertical", 4))
