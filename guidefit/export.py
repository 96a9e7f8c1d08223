"""Export identified joints as spring-damper elements of a machine FEM model.

The paper's Section 4 (Figure 10) models each carriage-rail joint by
spring-dampers: ``n_vertical`` (default 4) along y and ``n_horizontal``
(default 8) along x per carriage, in parallel. The identified carriage
stiffness and damping are shared equally: each vertical element has
``k = K_V / n_vertical``, ``c = c_V / n_vertical``, each horizontal one
``k = K_H / n_horizontal``, ``c = c_H / n_horizontal``, so that the elements
together reproduce K_V, K_H, c_V, c_H.

Node numbering (the cards only reference nodes; the user's model owns them):
element ``i`` of carriage ``j`` (both from 0) connects carriage node
``carriage_node + 100 j + i`` to rail node ``rail_node + 100 j + i``; element
ids are ``first_element + 100 j + i``. Units: SI (N, m, s), so the FEM
model must be in N-m-s units; stiffness in N/m, damping in N s/m.

Formats: Nastran ``PBUSH``/``CBUSH`` (K and B fields of the element's
translational DOF 1 = x, 2 = y), ANSYS ``COMBIN14`` (KEYOPT(2) = 1 or 2 for a
1-D spring-damper along UX or UY; real constants K, CV1), Abaqus ``SPRING2``
and ``DASHPOT2`` elements with ``*SPRING``/``*DASHPOT`` on DOF 1 or 2, and JSON.

Examples
--------
>>> els = joint_elements([{"file": "a.h5", "parameters": {
...     "K_V": {"value": 1.0e9}, "c_V": {"value": 2000.0},
...     "K_H": {"value": 8.0e7}, "c_H": {"value": 3200.0}}}])
>>> len(els), els[0].stiffness_n_per_m, els[4].damping_ns_per_m
(12, 250000000.0, 400.0)
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass

from guidefit.errors import RecordingError

FORMATS = ("nastran", "ansys", "abaqus", "json")


@dataclass(frozen=True)
class SpringDamper:
    """One 1-D spring-damper element between a carriage node and a rail node."""

    element_id: int
    carriage_node: int
    rail_node: int
    dof: int  # 1 = x (horizontal), 2 = y (vertical)
    stiffness_n_per_m: float
    damping_ns_per_m: float
    source: str


def read_results(path) -> list[dict]:
    """Results of ``identify --json`` (JSON Lines, or one JSON object / list)."""
    from guidefit.jsonio import read_json_documents

    docs = read_json_documents(path)
    if len(docs) == 1 and isinstance(docs[0], list):
        return docs[0]
    return docs


def _value(result: dict, name: str, where: str) -> float:
    try:
        value = result["parameters"][name]["value"]
    except (KeyError, TypeError):
        raise RecordingError(f"{where}: parameter '{name}' missing") from None
    if value is None:
        raise RecordingError(f"{where}: parameter '{name}' was not identified (null); cannot export")
    value = float(value)
    if not value > 0:
        raise RecordingError(f"{where}: parameter '{name}' must be positive, got {value:g}")
    return value


def joint_elements(results: list[dict], n_vertical: int = 4, n_horizontal: int = 8,
                   carriage_node: int = 10001, rail_node: int = 20001, first_element: int = 30001,
                   where: str = "results") -> list[SpringDamper]:
    """Spring-damper elements of every carriage in ``results`` (one identify object per carriage)."""
    if n_vertical < 1 or n_horizontal < 1:
        raise RecordingError("export: --vertical and --horizontal need at least one element each")
    elements = []
    for j, result in enumerate(results):
        if not isinstance(result, dict) or "error" in result:
            continue
        label = f"{where}: entry {j + 1} ({result.get('file', '?')})"
        kv, cv = _value(result, "K_V", label), _value(result, "c_V", label)
        kh, ch = _value(result, "K_H", label), _value(result, "c_H", label)
        split = [(2, kv / n_vertical, cv / n_vertical)] * n_vertical + \
                [(1, kh / n_horizontal, ch / n_horizontal)] * n_horizontal
        for i, (dof, k, c) in enumerate(split):
            off = 100 * j + i
            elements.append(SpringDamper(first_element + off, carriage_node + off, rail_node + off, dof, k, c,
                                         str(result.get("file", ""))))
    if not elements:
        raise RecordingError(f"{where}: no identified carriage to export")
    return elements


def _f8(value) -> str:
    """A Nastran small-field (8 characters) value."""
    if isinstance(value, int):
        return f"{value:<8d}"
    text = f"{value:.3E}".replace("E+0", "+").replace("E-0", "-").replace("E+", "+").replace("E-", "-")
    return f"{text:<8s}"[:8]


def to_nastran(elements: list[SpringDamper]) -> str:
    """PBUSH (one property per element: K and B on its DOF) and CBUSH cards, small field format."""
    lines = ["$ guidefit joint spring-dampers (SI: N, m, s). DOF 1 = x horizontal, 2 = y vertical"]
    for e in elements:
        k_fields = ["" for _ in range(6)]
        b_fields = ["" for _ in range(6)]
        k_fields[e.dof - 1] = _f8(e.stiffness_n_per_m)
        b_fields[e.dof - 1] = _f8(e.damping_ns_per_m)
        lines.append("$ from " + e.source)
        lines.append("PBUSH   " + _f8(e.element_id) + "K       " + "".join(f"{f:<8s}" for f in k_fields))
        lines.append("        " + "B       " + "".join(f"{f:<8s}" for f in b_fields))
        lines.append("CBUSH   " + _f8(e.element_id) + _f8(e.element_id) + _f8(e.carriage_node) + _f8(e.rail_node)
                     + "        " * 3 + _f8(0))
    return "\n".join(line.rstrip() for line in lines) + "\n"


def to_ansys(elements: list[SpringDamper]) -> str:
    """APDL: COMBIN14 types per direction, one real constant set (K, CV1) per element."""
    lines = ["! guidefit joint spring-dampers (SI: N, m, s)",
             "ET,1,COMBIN14", "KEYOPT,1,2,1   ! 1-D along UX (horizontal)",
             "ET,2,COMBIN14", "KEYOPT,2,2,2   ! 1-D along UY (vertical)"]
    for e in elements:
        lines.append(f"R,{e.element_id},{e.stiffness_n_per_m:.6e},{e.damping_ns_per_m:.6e}")
        lines.append(f"TYPE,{e.dof}")
        lines.append(f"REAL,{e.element_id}")
        lines.append(f"EN,{e.element_id},{e.carriage_node},{e.rail_node}")
    return "\n".join(lines) + "\n"


def to_abaqus(elements: list[SpringDamper]) -> str:
    """Abaqus input: SPRING2 and DASHPOT2 elements acting on DOF 1 (x) or 2 (y)."""
    lines = ["** guidefit joint spring-dampers (SI: N, m, s)"]
    for e in elements:
        k_set, c_set = f"GF_K{e.element_id}", f"GF_C{e.element_id}"
        lines += [f"*ELEMENT, TYPE=SPRING2, ELSET={k_set}", f"{e.element_id}, {e.carriage_node}, {e.rail_node}",
                  f"*SPRING, ELSET={k_set}", f"{e.dof}, {e.dof}", f"{e.stiffness_n_per_m:.6e}",
                  f"*ELEMENT, TYPE=DASHPOT2, ELSET={c_set}",
                  f"{e.element_id + 50}, {e.carriage_node}, {e.rail_node}",
                  f"*DASHPOT, ELSET={c_set}", f"{e.dof}, {e.dof}", f"{e.damping_ns_per_m:.6e}"]
    return "\n".join(lines) + "\n"


def to_json(elements: list[SpringDamper]) -> str:
    """The elements as a JSON list (fields with units in their names)."""
    return json.dumps([asdict(e) for e in elements], indent=1) + "\n"


def export(results_path, fmt: str, **options) -> str:
    """Read identify results and render them in ``fmt`` (one of :data:`FORMATS`)."""
    if fmt not in FORMATS:
        raise RecordingError(f"export: format '{fmt}' unknown; use one of {', '.join(FORMATS)}")
    elements = joint_elements(read_results(results_path), where=str(results_path), **options)
    return {"nastran": to_nastran, "ansys": to_ansys, "abaqus": to_abaqus, "json": to_json}[fmt](elements)
