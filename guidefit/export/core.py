r"""Export identified joints to a machine FEM model (paper Section 4, Figure 10).

What is exported
----------------
A hammer test measures the carriage on its test rig: the accelerometers add
mass, the rail sits on the rig's own (often soft) support. The paper's
Eq. (24)-(29) turn two measured frequencies into *apparent* single-DOF values
K = 4 pi^2 M f^2, c = 4 pi M f zeta; when ``guidefit explain`` attributes a
residual to the rig (``support_compliance``, ``base_mode``, ``added_mass``,
``com_offset``), those values are the rig's, not the joint's. The paper's own
K_H = 1.00e8 N/m is such a case: a lateral rail support of about 1.2e8 N/m,
while the rollers' lateral stiffness is about 1.1e9 N/m.

So the default (``joint="explained"``) exports the joint of the *explained*
model with the rig removed: the fitted effects are applied to the guide's
vibration model (Eq. 5-23), and only what they do to the roller contacts is
kept (``contact_stiffness``, ``row_damage``, the small-amplitude stiffness of
``amplitude_dependence``); masses, supports and centre-of-mass offsets are
the rig's or the carriage's and are dropped (each one named in the output).
The joint is then the rollers' full stiffness matrix at the carriage origin
(the centre of the top mounting face, ``recording-format.md``),
K = sum_i K_n,i g_i g_i^T (Eq. 10-14, :func:`guidefit.model.vibration.carriage_stiffness_matrix`),
embedded in 6x6 over (x, y, z, rx, ry, rz): the rollers give no stiffness
along the rail (z, the drive's job). The damping matrix is the modal damping
of the rig-free carriage on that joint, C = M Phi diag(2 zeta_j w_j) Phi^T M,
with Phi, w its mass-normalised modes and zeta_j the identified damping ratio
of the mode with the same label (modes the test did not show: the mean
identified ratio, said in the output). For an uncoupled vertical mode this is
exactly Eq. (27), c_V = 4 pi M f_V zeta_V, at the rig-free frequency. The
damping the test measured is assumed to be the joint's: explain fits
frequencies and shapes, it cannot separate joint damping from rig damping.

The raw Eq. (24)-(29) values are written beside it, labelled "apparent";
``joint="apparent"`` exports them instead (diagonal: x = K_H, c_H; y = K_V, c_V).

Elements (``element``)
----------------------
``matrix``  the full 6x6 K and C between a carriage node and a rail node at the
            same place: Nastran ``DMIG`` (K2GG/B2GG, 12x12 per carriage),
            ANSYS ``MATRIX27`` (stiffness and damping types), Abaqus
            ``CONN3D2`` BUSHING with coupled ``*CONNECTOR ELASTICITY`` and
            ``*CONNECTOR DAMPING``.
``bush``    one 6-DOF element with the diagonal of K and C (couplings dropped;
            the output says how large they are): Nastran ``PBUSH``/``CBUSH``
            K1-K6/B1-B6, ANSYS six ``COMBIN14`` (KEYOPT(2) = 1-6), Abaqus
            BUSHING with uncoupled components.
``springs`` the paper's Figure 10: ``n_vertical`` 1-D elements with K_yy/n and
            ``n_horizontal`` with K_xx/n per carriage, element i between nodes
            carriage + i and rail + i (Nastran CBUSH, ANSYS COMBIN14, Abaqus
            SPRING2/DASHPOT2).

Units, axes and numbering
-------------------------
``units``: ``si`` (N, m, s), ``mm-N-s`` or ``mm-t-s`` (N, mm, s; mass in t:
for springs and dampers the two are the same numbers). Translational
stiffness N/m -> N/mm (x 1e-3), rotational N m/rad -> N mm/rad (x 1e3),
the force-rotation couplings (N/rad) are unchanged; damping alike.
``axis_map`` (``"x=X,y=Z,z=-Y"``: the model's lateral x along machine +X, its
vertical y along machine +Z, ...) rotates K and C into the machine frame,
K' = T K T^T with T = diag(R, R); it must be a rotation (no mirror).
Nodes: ``carriage_nodes``/``rail_nodes`` (one id per carriage, the model's
real nodes; default 10001 + 100 j, 20001 + 100 j); elements ``first_element``
+ ``id_step`` j (+ i for springs). Nastran ids above 99999999, repeated ids
and more elements per carriage than ``id_step`` are errors, never wrapped.

Numbers are written in full: Nastran in large field (16 characters: 13-14
significant digits, no ``2.704+8``; 12 for negative numbers below 1e-3 in
magnitude and 11 below 1e-9, far below any matrix entry's scale), ANSYS and Abaqus as the shortest text
that reads back to the same double. Text from the input (file names, guide
names) appears only in comment lines, reduced to printable ASCII, so it
cannot start a card. Non-finite values are errors.

Examples
--------
>>> joint = apparent_joint({"file": "a.h5", "parameters": {
...     "K_V": {"value": 1.0e9}, "c_V": {"value": 2000.0},
...     "K_H": {"value": 8.0e7}, "c_H": {"value": 3200.0}}})
>>> float(joint.stiffness[0, 0]), float(joint.stiffness[1, 1]), float(joint.damping[1, 1])
(80000000.0, 1000000000.0, 2000.0)
>>> _nastran_real(2.704123456789e8)   # not 2.704+8
'2.704123456789+8'
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

import numpy as np

from guidefit.errors import GuidefitError, IdentificationError

FORMATS = ("nastran", "ansys", "abaqus", "json", "calculix")
ELEMENTS = ("matrix", "bush", "springs")
JOINTS = ("explained", "apparent")
#: length scale (model metres -> output unit) and the labels of each unit system
UNIT_SYSTEMS = {
    "si": (1.0, "SI: N, m, s, kg; K N/m and N m/rad, C N s/m and N m s/rad"),
    "mm-N-s": (1.0e3, "mm-N-s: N, mm, s, t; K N/mm and N mm/rad, C N s/mm and N mm s/rad"),
    "mm-t-s": (1.0e3, "mm-t-s: t, mm, s, N; K N/mm and N mm/rad, C N s/mm and N mm s/rad"),
}
DOF_NAMES = ("x", "y", "z", "rx", "ry", "rz")
NASTRAN_MAX_ID = 99_999_999
OTHER_MAX_ID = 2**31 - 1
#: carriage DOFs (u, v, theta, psi, phi) of the vibration model in the 6-DOF order (x, y, z, rx, ry, rz)
_CARRIAGE_TO_6 = (0, 1, 3, 4, 5)


class ExportError(GuidefitError, ValueError):
    """Input or options that cannot give a correct deck (exit 2, one line)."""


@dataclass(frozen=True)
class Joint:
    """One carriage-rail joint: 6x6 stiffness and damping at the carriage origin, SI, model frame.

    ``basis`` is ``"explained"`` or ``"apparent"``; ``apparent`` holds the
    raw Eq. (24)-(29) values of the test, ``explained`` the same quantities of
    the explained joint (None for ``basis="apparent"``); ``removed`` names the
    rig effects left out, ``kept`` the joint effects applied; ``notes`` says
    what else the reader must know.
    """

    source: str
    guide: str
    basis: str
    stiffness: np.ndarray
    damping: np.ndarray
    apparent: dict
    explained: dict | None = None
    removed: tuple = ()
    kept: tuple = ()
    verdict: str | None = None
    notes: tuple = ()
    entry: int | None = None  # index of its line in the results (export keeps node ids per line)


@dataclass(frozen=True)
class Element:
    """One element of the deck: ids, nodes and its 6x6 K and C in output units and axes."""

    element_id: int
    carriage_node: int
    rail_node: int
    stiffness: np.ndarray
    damping: np.ndarray
    kind: str  # matrix, bush, spring
    carriage: int  # index of the joint it belongs to
    dof: int | None = None  # springs: 1-6
    meta: dict = field(default_factory=dict)


# --------------------------------------------------------------------------- reading


def read_results(path) -> list[dict]:
    """Results of ``identify --json`` (JSON Lines, or one JSON object / list)."""
    from guidefit.jsonio import read_json_documents

    docs = read_json_documents(path)
    if len(docs) == 1 and isinstance(docs[0], list):
        return docs[0]
    return docs


def _finite(value, what: str) -> float:
    if isinstance(value, bool):
        raise ExportError(f"{what}: expected a number, got {value!r}")
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ExportError(f"{what}: expected a number, got {value!r}") from None
    except OverflowError:  # an integer beyond the float range (a caller's dict; files: guidefit.jsonio)
        raise ExportError(f"{what}: an integer of {len(str(value))} digits is not a finite number; "
                          "cannot export") from None
    if not math.isfinite(number):
        raise ExportError(f"{what}: {number} is not a finite number; cannot export")
    return number


def _value(result: dict, name: str, where: str) -> float:
    from guidefit.jsonio import parameter_factor

    try:
        param = result["parameters"][name]
        value = None if param is None else param["value"]
    except (KeyError, TypeError):
        raise ExportError(f"{where}: parameter '{name}' missing") from None
    if value is None:  # a valid result of an incomplete identification: exit 1, as identify's
        raise IdentificationError(f"{where}: parameter '{name}' was not identified (null); cannot export "
                                  "(identification incomplete)")
    value = _finite(value, f"{where}: parameter '{name}'") * parameter_factor(name, param, where)
    if not value > 0:
        raise ExportError(f"{where}: parameter '{name}' must be positive, got {value:g}")
    return value


def _label(result: dict, j: int, where: str) -> str:
    return f"{where}: entry {j + 1} ({_safe(str(result.get('file', '?')), 60)})"


# --------------------------------------------------------------------------- joints


def apparent_joint(result: dict, where: str = "results") -> Joint:
    """The raw Eq. (24)-(29) joint of one ``identify`` result: x = K_H, c_H; y = K_V, c_V."""
    values = {k: _value(result, k, where) for k in ("K_V", "K_H", "c_V", "c_H")}
    k6, c6 = np.zeros((6, 6)), np.zeros((6, 6))
    k6[0, 0], k6[1, 1] = values["K_H"], values["K_V"]
    c6[0, 0], c6[1, 1] = values["c_H"], values["c_V"]
    return Joint(str(result.get("file", "")), str(result.get("guide") or ""), "apparent", k6, c6, values)


def _effects_of(explanation: dict, where: str) -> list:
    from guidefit.model.effects import make_effect

    effects = []
    for k, entry in enumerate(explanation.get("effects") or []):
        if not isinstance(entry, dict) or not isinstance(entry.get("name"), str):
            raise ExportError(f"{where}: explanation effects entry {k}: expected an object with a name")
        params = {}
        for key, p in (entry.get("parameters") or {}).items():
            value = p.get("value") if isinstance(p, dict) else p
            if value is not None and not isinstance(value, str):
                value = _finite(value, f"{where}: effect {entry['name']} parameter '{key}'")
            params[key] = value
        try:
            effects.append(make_effect(entry["name"], params))
        except GuidefitError as exc:
            raise ExportError(f"{where}: explanation: {exc}") from None
    return effects


def _describe(effect) -> str:
    params = ", ".join(f"{k} = {v:.6g}" if isinstance(v, float) else f"{k} = {v}"
                       for k, v in effect.parameters.items() if v is not None and v != math.inf)
    return f"{effect.name} ({params})" if params else effect.name


def _damping_by_label(result: dict) -> dict:
    """Model mode label -> identified damping ratio. Labels are read as explain reads them
    (``Vertical``, ``V``, ``f_V``: vertical); before, such a label's damping was 'not measured' and the
    mean of the other modes replaced it (C_yy +42 %, exit 0)."""
    from guidefit.explain.settings import canonical_label

    out = {}
    for m in list(result.get("modes") or []):
        if isinstance(m, dict) and m.get("level") is not None:
            continue  # one force level's estimate: the mode's own entry carries the test's damping
        label = canonical_label(m.get("label")) if isinstance(m, dict) else None
        if label and m.get("damping_ratio") is not None:
            zeta = float(m["damping_ratio"])
            if math.isfinite(zeta) and zeta >= 0:
                out.setdefault(label, zeta)
    return out


def explained_joint(result: dict, explanation: dict, guide=None, where: str = "results") -> Joint:
    """The joint of the explained model with the rig removed (see the module docstring).

    Parameters
    ----------
    result : dict
        One ``identify --json`` object (its modes give the damping ratios, its
        parameters the apparent values).
    explanation : dict
        The ``explain --json`` object of the same test.
    guide : str, Path or Guide, optional
        Default: the guide the result names.
    """
    from dataclasses import replace

    from guidefit.model import vibration as vib
    from guidefit.model.effects import apply_effects
    from guidefit.model.guides import Guide, load_guide

    verdict = explanation.get("verdict")
    if verdict not in ("adequate", "explained"):
        raise IdentificationError(
            f"{where}: explain found no model that fits (verdict {verdict!r}); the joint cannot be told apart "
            "from the rig: export --joint apparent writes the Eq. 24-29 values")
    g = guide if isinstance(guide, Guide) else load_guide(guide or explanation.get("guide")
                                                          or result.get("guide") or "MRB35")
    fitted_on = explanation.get("guide")
    if isinstance(fitted_on, str) and fitted_on and fitted_on.upper() != g.name.upper():
        raise ExportError(f"{where}: the explanation was fitted on guide {_safe(fitted_on, 40)!r}, the joint "
                          f"would be built on {_safe(g.name, 40)!r}; explain with --guide {_safe(g.name, 40)} "
                          "or export without --guide")
    effects = _effects_of(explanation, where)
    nominal = vib.model_from_guide(g)
    fitted = apply_effects(nominal, g, effects)
    kept, removed = [], []
    for effect in effects:  # an effect that changes the rollers is the joint's; anything else is the rig's
        alone = apply_effects(nominal, g, [effect])
        changed = not np.array_equal(alone.rollers.stiffness_n_per_m, nominal.rollers.stiffness_n_per_m)
        (kept if changed else removed).append(_describe(effect))
    joint_spec = replace(nominal, rollers=fitted.rollers)
    k5 = vib.carriage_stiffness_matrix(joint_spec.rollers)
    sol = vib.solve_modes(joint_spec)
    measured = _damping_by_label(result)
    notes = []
    known = [measured[lab] for lab in sol.labels if lab in measured]
    if not known:
        raise ExportError(f"{where}: no identified damping ratio of any carriage mode; cannot build the "
                          "damping matrix (use --joint apparent)")
    fill = float(np.mean(known))
    missing = [lab for lab in sol.labels if lab not in measured]
    if missing:
        notes.append(f"damping of {', '.join(missing)} not measured: mean identified ratio {fill:.6g} used")
    zeta = np.array([measured.get(lab, fill) for lab in sol.labels])
    omega = 2 * np.pi * np.asarray(sol.frequencies_hz, float)
    phi = np.asarray(sol.shapes, float)[:5, :5]
    mass = vib.carriage_mass_matrix(joint_spec)
    c5 = mass @ phi @ np.diag(2 * zeta * omega) @ phi.T @ mass
    c5 = _clean_roundoff(0.5 * (c5 + c5.T))
    k5 = _clean_roundoff(k5)
    k6, c6 = np.zeros((6, 6)), np.zeros((6, 6))
    idx = np.array(_CARRIAGE_TO_6)
    k6[np.ix_(idx, idx)] = k5
    c6[np.ix_(idx, idx)] = c5
    apparent = apparent_joint(result, where)
    explained = {"K_V": k6[1, 1], "K_H": k6[0, 0], "c_V": c6[1, 1], "c_H": c6[0, 0],
                 "f_V": sol.frequency_hz("vertical"), "f_H": sol.frequency_hz("roll_low")}
    if removed:
        notes.append("rig effects removed: " + "; ".join(removed))
    return Joint(str(result.get("file", "")), g.name, "explained", k6, c6, apparent.apparent, explained,
                 tuple(removed), tuple(kept), verdict, tuple(notes))


def _clean_roundoff(m: np.ndarray) -> np.ndarray:
    """Entries below 1e-12 of their diagonal scale set to zero: sums over symmetric rollers leave ~1e-17."""
    d = np.sqrt(np.abs(np.diag(m)))
    out = m.copy()
    out[np.abs(m) < 1e-12 * np.outer(d, d)] = 0.0
    return out


def _explain_result(result: dict, where: str, guide=None) -> dict:
    """``explain --modes`` of one identify result (the same call, with ``--guide`` when given), as its JSON
    object. The guide is the one the joint is built on: ``export --guide X`` explained on the result's
    guide and built X's joint with effects fitted to another guide (exit 0)."""
    from guidefit.explain import explain_modes, modes_from_result
    from guidefit.model.guides import Guide, load_guide

    modes, guide_name, sensors, levels = modes_from_result(result, where)
    g = guide if isinstance(guide, Guide) else load_guide(guide or guide_name or "MRB35")
    explanation = explain_modes(modes, g, sensors, levels, source=str(result.get("file", where)))
    return explanation.to_dict()


def _same_file(a: str, b: str) -> bool:
    """Two ``file`` entries name one recording: the same text, or the same path once resolved."""
    from pathlib import Path

    if a == b:
        return True
    try:
        return Path(a).resolve() == Path(b).resolve()
    except (OSError, ValueError, RuntimeError):
        return False


def match_explanations(results: list, explanations: list[dict], where: str = "results") -> dict[int, dict]:
    """Which explanation belongs to which result (index into ``results``), by ``file``.

    A ``file`` matches by its text, else by its resolved path, else by its base
    name when that is unique on both sides (identify and explain run from
    different directories: ``/data/c1.h5`` and ``c1.h5``); an explanation
    naming the results file ``where`` itself (``explain --modes r.json``
    names ``r.json``) belongs to its one result. An explanation that matches no result, or two that
    match one, is an error: ignoring it would export another joint than the
    one the user gave (before: a given 'unexplained' explanation was dropped
    and the result explained anew, exit 0).
    """
    from pathlib import PurePath

    if not explanations:
        return {}
    files = [str(r.get("file", "")) if isinstance(r, dict) else "" for r in results]
    out: dict[int, dict] = {}

    def base(name: str) -> str:
        return PurePath(name.replace("\\", "/")).name

    for k, e in enumerate(explanations):
        name = str(e.get("file", ""))
        hits = [j for j, f in enumerate(files) if f == name]
        hits = hits or [j for j, f in enumerate(files) if _same_file(f, name)]
        if not hits and sum(base(str(x.get("file", ""))) == base(name) for x in explanations) == 1:
            hits = [j for j, f in enumerate(files) if base(f) == base(name)]
        if not hits and len(results) == 1 and _same_file(where, name):
            hits = [0]  # explain --modes RESULTS --json names the results file
        if len(hits) != 1:
            found = "matches no result" if not hits else f"matches {len(hits)} results"
            raise ExportError(f"{where}: explanation {k + 1} (file {_safe(name, 60)!r}) {found} by file; "
                              f"the results hold {', '.join(_safe(f, 40) for f in files[:5])}")
        if hits[0] in out:
            raise ExportError(f"{where}: two explanations for {_safe(files[hits[0]], 60)}")
        out[hits[0]] = e
    return out


def joints_from_results(results: list[dict], joint: str = "explained", explanations=(), guide=None,
                        where: str = "results", progress=None, skipped: list | None = None) -> list[Joint]:
    """One :class:`Joint` per carriage of ``results``.

    An entry with an ``error`` (identify failed on that file) is an
    :class:`IdentificationError`, or, given a ``skipped`` list, left out with
    a line appended to it (``guidefit export`` writes the other carriages,
    prints the lines and exits 1; before, it was left out in silence, exit 0).

    ``explanations``: ``explain --json`` objects, matched to results by ``file``;
    a result without one is explained from its modes (as ``explain --modes``).
    ``progress(done, total, name)`` is called after each carriage.
    """
    from dataclasses import replace

    if joint not in JOINTS:
        raise ExportError(f"export: joint '{joint}' unknown; use one of {', '.join(JOINTS)}")
    for k, e in enumerate(explanations):
        if not isinstance(e, dict) or "verdict" not in e:
            raise ExportError(f"explanations entry {k + 1}: not an explain --json object (no verdict)")
    matched = match_explanations(results, list(explanations), where)
    joints = []
    for j, result in enumerate(results):
        if not isinstance(result, dict):
            raise ExportError(f"{where}: entry {j + 1}: expected a JSON object, got {type(result).__name__}")
        label = _label(result, j, where)
        if result.get("error") is not None:  # left out, but said: the caller exits 1 (export_cmd)
            line = f"{label}: identify gave no result ({_safe(str(result['error']), 120)}); carriage not exported"
            if skipped is None:
                raise IdentificationError(line)
            skipped.append(line)
            continue
        if joint == "apparent":
            joints.append(replace(apparent_joint(result, label), entry=j))
            continue
        explanation = matched.get(j)
        if explanation is None:
            if not result.get("modes"):
                raise ExportError(f"{label}: no modes to explain; give its explain --json with --explain "
                                  "or use --joint apparent")
            explanation = _explain_result(result, label, guide)
        joints.append(replace(explained_joint(result, explanation, guide, label), entry=j))
        if progress is not None:
            progress(j + 1, len(results), _safe(str(result.get("file", "")), 40))
    if not joints and skipped:
        raise IdentificationError(f"{where}: no identified carriage to export; {skipped[0]}")
    if not joints:
        raise ExportError(f"{where}: no identified carriage to export")
    return joints


# --------------------------------------------------------------------------- units, axes, ids


def unit_transform(units: str) -> np.ndarray:
    """Factors F (6x6) with X_out = F * X_SI elementwise for a 6x6 K or C.

    >>> f = unit_transform("mm-N-s")
    >>> float(f[0, 0]), float(f[0, 5]), float(f[5, 0]), float(f[5, 5])
    (0.001, 1.0, 1.0, 1000.0)
    """
    if units not in UNIT_SYSTEMS:
        raise ExportError(f"export: unit system '{units}' unknown; use one of {', '.join(UNIT_SYSTEMS)}")
    s = UNIT_SYSTEMS[units][0]
    force = np.array([1.0, 1.0, 1.0, s, s, s])  # force N, moment N*length
    motion = np.array([s, s, s, 1.0, 1.0, 1.0])  # translation in length, rotation rad
    return force[:, None] / motion[None, :]


def parse_axis_map(text: str | None) -> np.ndarray:
    """``"x=X,y=Z,z=-Y"`` -> R (3x3) with machine vector = R @ model vector; a proper rotation
    (:func:`guidefit.io.axes.parse_axis_map`, the one parser of every ``--axis-map``).

    >>> parse_axis_map("x=X,y=Z,z=-Y") @ [0.0, 1.0, 0.0]   # model vertical is machine +Z
    array([0., 0., 1.])
    """
    from guidefit.io.axes import parse_axis_map as parse

    return parse(text, error=ExportError)


def transform(matrix: np.ndarray, rot: np.ndarray, factors: np.ndarray) -> np.ndarray:
    """A 6x6 K or C rotated into the machine axes (T M T^T, T = diag(R, R)) and converted to units."""
    t = np.zeros((6, 6))
    t[:3, :3] = rot
    t[3:, 3:] = rot
    out = t @ matrix @ t.T * factors
    return 0.5 * (out + out.T)


def _ids(values, n: int, default_start: int, what: str) -> list[int]:
    if values is None or (not isinstance(values, int) and len(values) == 0):
        return [default_start + 100 * j for j in range(n)]
    if isinstance(values, int):
        values = [values]
    values = [int(v) for v in values]
    if len(values) != n:
        raise ExportError(f"export: {len(values)} {what} id(s) given for {n} carriage(s); give one per carriage")
    return values


def build_elements(joints: list[Joint], element: str = "matrix", *, units: str = "si", axis_map=None,
                   carriage_nodes=None, rail_nodes=None, first_element: int = 30001, id_step: int = 100,
                   n_vertical: int = 4, n_horizontal: int = 8, max_id: int = OTHER_MAX_ID,
                   ids_per_element: int = 1) -> list[Element]:
    """The deck's elements: joints converted to ``units`` and the machine axes, with checked ids.

    Element i of carriage j has the ids ``first_element + id_step j + ids_per_element i``
    and the next ``ids_per_element - 1`` (a format that writes stiffness and
    damping, or each direction, as separate elements uses them).
    """
    if element not in ELEMENTS:
        raise ExportError(f"export: element '{element}' unknown; use one of {', '.join(ELEMENTS)}")
    if element == "springs" and (n_vertical < 1 or n_horizontal < 1):
        raise ExportError("export: --vertical and --horizontal need at least one element each")
    rot = axis_map if isinstance(axis_map, np.ndarray) else parse_axis_map(axis_map)
    factors = unit_transform(units)
    n = len(joints)
    cnodes = _ids(carriage_nodes, n, 10001, "carriage node")
    rnodes = _ids(rail_nodes, n, 20001, "rail node")
    per_carriage = n_vertical + n_horizontal if element == "springs" else 1
    if id_step < 1:
        raise ExportError(f"export: --id-step must be at least 1, got {id_step}")
    if per_carriage * ids_per_element > id_step:
        raise ExportError(f"export: {per_carriage * ids_per_element} element ids per carriage but --id-step "
                          f"{id_step}: element ids would repeat; raise --id-step")
    elements = []
    for j, jt in enumerate(joints):
        k, c = (transform(m, rot, factors) for m in (jt.stiffness, jt.damping))
        for what, m in (("stiffness", k), ("damping", c)):
            if not np.all(np.isfinite(m)):
                raise ExportError(f"{_safe(jt.source, 60)}: {what} matrix is not finite; cannot export")
        base = first_element + id_step * j
        if element != "springs":
            elements.append(Element(base, cnodes[j], rnodes[j], k, c, element, j))
            continue
        # Figure 10: the model's vertical (y) and lateral (x) directions, wherever the axis map puts them
        vert = int(np.argmax(np.abs(rot[:, 1])))
        lat = int(np.argmax(np.abs(rot[:, 0])))
        split = [(vert, n_vertical)] * n_vertical + [(lat, n_horizontal)] * n_horizontal
        for i, (dof, count) in enumerate(split):
            ks, cs = np.zeros((6, 6)), np.zeros((6, 6))
            ks[dof, dof], cs[dof, dof] = k[dof, dof] / count, c[dof, dof] / count
            elements.append(Element(base + ids_per_element * i, cnodes[j] + i, rnodes[j] + i, ks, cs, "spring", j,
                                    dof + 1))
    ids = [e.element_id + k for e in elements for k in range(ids_per_element)]
    nodes = [x for e in elements for x in (e.carriage_node, e.rail_node)]
    for what, values in (("element", ids), ("node", nodes)):
        bad = [v for v in values if not 0 < v <= max_id]
        if bad:
            raise ExportError(f"export: {what} id {bad[0]} outside 1..{max_id}; choose smaller ids")
    if len(set(ids)) != len(ids):
        dup = next(v for v in ids if ids.count(v) > 1)
        raise ExportError(f"export: element id {dup} would be used twice; change --first-element/--id-step")
    for e in elements:
        if e.carriage_node == e.rail_node:
            raise ExportError(f"export: element {e.element_id}: carriage and rail node are both {e.carriage_node}")
    return elements


# --------------------------------------------------------------------------- text


def _safe(text: str, limit: int | None = None) -> str:
    """Printable ASCII only (control characters, line breaks, non-ASCII -> '?'): safe in a comment line.

    >>> _safe("a.h5\\nENDDATA\\r\\u2028x")
    'a.h5?ENDDATA??x'
    """
    out = "".join(ch if " " <= ch <= "~" else "?" for ch in str(text))
    return out if limit is None or len(out) <= limit else out[:limit - 3] + "..."


def _comment_lines(prefix: str, text: str, width: int = 72) -> list[str]:
    """``text`` as comment lines, each starting with ``prefix`` and at most ``width`` characters."""
    import textwrap

    room = width - len(prefix) - 1
    return [f"{prefix} {line}" for line in textwrap.wrap(_safe(text), room) or [""]]


def _fmt(x: float) -> str:
    """Shortest text that reads back to the same double (free-format decks)."""
    x = float(x)
    if not math.isfinite(x):
        raise ExportError(f"value {x} is not finite; cannot export")
    return repr(x + 0.0)  # no "-0.0"


def _nastran_float(text: str) -> float:
    """Read a Nastran real (``1.5+8``, ``-2.-3``, ``1.5E+8``, ``1.5D+8``)."""
    t = text.strip().upper().replace("D", "E")
    if "E" not in t:
        for k in range(len(t) - 1, 0, -1):
            if t[k] in "+-":
                t = t[:k] + "E" + t[k:]
                break
    return float(t)


def _nastran_real(x: float, width: int = 16) -> str:
    """The most precise text of ``x`` in a Nastran field of ``width`` characters (left-justified).

    Hand-written (pyNastran's writers are not a runtime dependency): fixed and
    exponent forms are tried and the one that reads back closest is kept.

    >>> _nastran_real(-1.234567890123456e-7)
    '-1.23456789012-7'
    """
    x = float(x)
    if not math.isfinite(x):
        raise ExportError(f"value {x} is not finite; cannot export")
    if x == 0.0:
        return f"{'0.':<{width}s}"
    candidates = []
    for prec in range(width, -1, -1):
        mant, _, exp = f"{x:.{prec}e}".partition("e")
        e = int(exp)
        text = f"{mant}{'+' if e >= 0 else '-'}{abs(e)}"
        if "." not in mant:
            text = f"{mant}.{'+' if e >= 0 else '-'}{abs(e)}"
        if len(text) <= width:
            candidates.append(text)
            break
    for prec in range(width, -1, -1):
        text = f"{x:.{prec}f}"
        if text.startswith("0."):
            text = text[1:]
        elif text.startswith("-0."):
            text = "-" + text[2:]
        if "." not in text:
            text += "."
        if len(text) <= width:
            candidates.append(text)
            break
    best = min(candidates, key=lambda t: abs(_nastran_float(t) - x))
    return f"{best:<{width}s}"


def _nastran_int(value: int, width: int = 16) -> str:
    return f"{int(value):<{width}d}"


def _large_card(name: str, fields: list) -> list[str]:
    """A card in large-field format: 4 fields of 16 characters per line, ``*`` continuations."""
    cells = [f + " " * (16 - len(f)) if isinstance(f, str) else (_nastran_int(f) if isinstance(f, int)
                                                                  else _nastran_real(f)) for f in fields]
    lines = []
    for i in range(0, max(len(cells), 1), 4):
        head = f"{name + '*':<8s}" if i == 0 else "*       "
        lines.append((head + "".join(cells[i:i + 4])).rstrip())
    return lines


def _header(joints: list[Joint], prefix: str, units: str, axis_map_text: str | None, element: str) -> list[str]:
    from guidefit import __version__

    out = _comment_lines(prefix, f"guidefit {__version__} joint export; element {element}")
    out += _comment_lines(prefix, f"units {UNIT_SYSTEMS[units][1]}")
    out += _comment_lines(prefix, f"axes: machine = R * model (model x lateral, y vertical up, z along the rail); "
                                  f"map {axis_map_text or 'x=X,y=Y,z=Z'}")
    out += _comment_lines(prefix, "each joint acts between a carriage node and a rail node at the carriage origin "
                                  "(centre of the top mounting face); DOF order x, y, z, rx, ry, rz")
    for j, jt in enumerate(joints):
        out += _comment_lines(prefix, f"carriage {j + 1}: {jt.source} (guide {jt.guide})")
        a = jt.apparent
        out += _comment_lines(prefix, "  apparent (raw Eq. 24-29 of the test, SI): K_V = {:.10g} N/m, K_H = {:.10g} "
                                      "N/m, c_V = {:.10g} N s/m, c_H = {:.10g} N s/m".format(
                                          a["K_V"], a["K_H"], a["c_V"], a["c_H"]))
        if jt.explained is not None:
            e = jt.explained
            out += _comment_lines(prefix, f"  explained joint, rig removed (explain verdict {jt.verdict}, SI): "
                                          f"K_yy = {e['K_V']:.10g} N/m, K_xx = {e['K_H']:.10g} N/m, C_yy = "
                                          f"{e['c_V']:.10g} N s/m, C_xx = {e['c_H']:.10g} N s/m; rig-free f_V = "
                                          f"{e['f_V']:.6g} Hz, f_H = {e['f_H']:.6g} Hz")
            out += _comment_lines(prefix, "  joint effects kept: " + ("; ".join(jt.kept) or "none (nominal K_n)"))
        out += _comment_lines(prefix, f"  exported: {jt.basis}")
        for note in jt.notes:
            out += _comment_lines(prefix, "  note: " + note)
    return out


def _coupling_note(elements: list[Element]) -> str | None:
    worst = 0.0
    for e in elements:
        for m in (e.stiffness,):
            d = np.sqrt(np.abs(np.diag(m)))
            scale = np.outer(d, d)
            off = np.where(scale > 0, np.abs(m) / np.where(scale > 0, scale, 1.0), 0.0)
            np.fill_diagonal(off, 0.0)
            worst = max(worst, float(off.max()))
    if worst > 1e-9:
        return (f"off-diagonal couplings dropped (largest |K_ij|/sqrt(K_ii K_jj) = {worst:.3g}); "
                "--element matrix keeps them")
    return None


def _pairs(e: Element):
    """Upper-triangle (row, col, value) of the 12x12 [[K, -K], [-K, K]] of a two-node element."""
    for name, m in (("K", e.stiffness), ("B", e.damping)):
        big = np.block([[m, -m], [-m, m]])
        yield name, big


# --------------------------------------------------------------------------- writers


def to_nastran(joints: list[Joint], elements: list[Element], units: str = "si", axis_map_text=None,
               element: str = "matrix") -> str:
    """Bulk data: PBUSH/CBUSH (bush, springs) or DMIG K2GG/B2GG (matrix), large field."""
    lines = _header(joints, "$", units, axis_map_text, element)
    if element == "matrix":
        lines += _comment_lines("$", "full matrices as DMIG: add 'K2GG = GFJK' and 'B2GG = GFJB' to the case "
                                     "control; the grids must exist in the model")
        for name, which in (("GFJK", "K"), ("GFJB", "B")):
            lines += _large_card("DMIG", [name, 0, 6, 2, 0, "", "", 12 * len(elements)])
            columns: dict = {}
            for e in elements:
                big = dict(_pairs(e))[which]
                dofs = [(e.carriage_node, c) for c in range(1, 7)] + [(e.rail_node, c) for c in range(1, 7)]
                for col in range(12):
                    for row in range(col + 1):
                        value = float(big[row, col])
                        if value != 0.0:
                            columns.setdefault(dofs[col], []).append((*dofs[row], value))
            for (gj, cj), entries in sorted(columns.items()):
                fields = [name, gj, cj, ""]
                for g, c, v in entries:
                    fields += [g, c, v, ""]
                lines += _large_card("DMIG", fields)
    else:
        note = _coupling_note(elements) if element == "bush" else None
        if note:
            lines += _comment_lines("$", note)
        for e in elements:
            k = [float(e.stiffness[i, i]) for i in range(6)]
            b = [float(e.damping[i, i]) for i in range(6)]
            kf = [v if v != 0.0 else "" for v in k]
            bf = [v if v != 0.0 else "" for v in b]
            lines += _large_card("PBUSH", [e.element_id, "K", *kf, "", "B", *bf, ""])
            lines += _large_card("CBUSH", [e.element_id, e.element_id, e.carriage_node, e.rail_node, "", "", "", 0])
    return "\n".join(lines) + "\n"


def to_ansys(joints: list[Joint], elements: list[Element], units: str = "si", axis_map_text=None,
             element: str = "matrix") -> str:
    """APDL: MATRIX27 stiffness and damping pairs (matrix) or COMBIN14 per DOF (bush, springs)."""
    lines = _header(joints, "!", units, axis_map_text, element)
    lines = [line.replace("$", "?") for line in lines]  # '$' separates APDL commands, even after '!'
    lines.append("/PREP7")
    if element == "matrix":
        lines += ["ET,901,MATRIX27", "KEYOPT,901,2,0", "KEYOPT,901,3,4   ! symmetric stiffness",
                  "ET,902,MATRIX27", "KEYOPT,902,2,0", "KEYOPT,902,3,5   ! symmetric damping"]
        for e in elements:
            for etype, (_, big) in zip((901, 902), _pairs(e)):
                consts = [_fmt(big[r, c]) for r in range(12) for c in range(r, 12)]  # C1..C78, upper by rows
                eid = e.element_id + (etype - 901)
                lines.append(f"R,{eid}," + ",".join(consts[:6]))
                lines += ["RMORE," + ",".join(consts[i:i + 6]) for i in range(6, 78, 6)]
                lines += [f"TYPE,{etype}", f"REAL,{eid}", f"EN,{eid},{e.carriage_node},{e.rail_node}"]
        lines.append("! element (and real set) id: stiffness, id + 1: damping")
    else:
        note = _coupling_note(elements) if element == "bush" else None
        if note:
            lines += _comment_lines("!", note)
        for dof in range(1, 7):
            lines += [f"ET,{910 + dof},COMBIN14", f"KEYOPT,{910 + dof},2,{dof}   ! 1-D along {DOF_NAMES[dof - 1]}"]
        for e in elements:
            dofs = [e.dof] if e.dof else [d for d in range(1, 7)
                                          if e.stiffness[d - 1, d - 1] != 0 or e.damping[d - 1, d - 1] != 0]
            for d in dofs:
                eid = e.element_id + d - 1 if e.kind == "bush" else e.element_id
                lines += [f"R,{eid},{_fmt(e.stiffness[d - 1, d - 1])},{_fmt(e.damping[d - 1, d - 1])}",
                          f"TYPE,{910 + d}", f"REAL,{eid}", f"EN,{eid},{e.carriage_node},{e.rail_node}"]
        if any(e.kind == "bush" for e in elements):
            lines.append("! bush: element and real set id + DOF - 1 per direction (DOF 1-6)")
    return "\n".join(lines) + "\n"


def _upper_columns(m: np.ndarray) -> list[str]:
    """D11, D12, D22, D13, D23, D33, ... (Abaqus coupled connector order), 8 per data line."""
    values = [_fmt(m[r, c]) for c in range(6) for r in range(c + 1)]
    return [", ".join(values[i:i + 8]) for i in range(0, len(values), 8)]


def to_abaqus(joints: list[Joint], elements: list[Element], units: str = "si", axis_map_text=None,
              element: str = "matrix") -> str:
    """Abaqus input: CONN3D2 BUSHING connectors (matrix: coupled; bush: uncoupled) or SPRING2/DASHPOT2."""
    lines = _header(joints, "**", units, axis_map_text, element)
    if element == "springs":
        for e in elements:
            d = e.dof
            k_set, c_set = f"GF_K{e.element_id}", f"GF_C{e.element_id}"
            lines += [f"*ELEMENT, TYPE=SPRING2, ELSET={k_set}", f"{e.element_id}, {e.carriage_node}, {e.rail_node}",
                      f"*SPRING, ELSET={k_set}", f"{d}, {d}", _fmt(e.stiffness[d - 1, d - 1]),
                      f"*ELEMENT, TYPE=DASHPOT2, ELSET={c_set}",
                      f"{e.element_id + 1}, {e.carriage_node}, {e.rail_node}",
                      f"*DASHPOT, ELSET={c_set}", f"{d}, {d}", _fmt(e.damping[d - 1, d - 1])]
        lines.append("** dashpot element id: spring id + 1")
        return "\n".join(lines) + "\n"
    note = _coupling_note(elements) if element == "bush" else None
    if note:
        lines += _comment_lines("**", note)
    for e in elements:
        eset, beh = f"GF_J{e.element_id}", f"GF_B{e.element_id}"
        lines += [f"*ELEMENT, TYPE=CONN3D2, ELSET={eset}", f"{e.element_id}, {e.carriage_node}, {e.rail_node}",
                  f"*CONNECTOR SECTION, ELSET={eset}, BEHAVIOR={beh}", "BUSHING,",
                  f"*CONNECTOR BEHAVIOR, NAME={beh}"]
        if element == "matrix":
            lines.append("*CONNECTOR ELASTICITY")
            lines += _upper_columns(e.stiffness)
            lines.append("*CONNECTOR DAMPING, TYPE=VISCOUS")
            lines += _upper_columns(e.damping)
        else:
            for d in range(1, 7):
                if e.stiffness[d - 1, d - 1] != 0:
                    lines += [f"*CONNECTOR ELASTICITY, COMPONENT={d}", _fmt(e.stiffness[d - 1, d - 1])]
                if e.damping[d - 1, d - 1] != 0:
                    lines += [f"*CONNECTOR DAMPING, COMPONENT={d}", _fmt(e.damping[d - 1, d - 1])]
    return "\n".join(lines) + "\n"


def to_json(joints: list[Joint], elements: list[Element], units: str = "si", axis_map_text=None,
            element: str = "matrix") -> str:
    """Every joint (both value sets, labelled) and every element with its matrices in output units."""
    def joint_dict(j):
        return {"file": j.source, "guide": j.guide, "exported": j.basis,
                "apparent_eq24_29_si": {"K_V_n_per_m": j.apparent["K_V"], "K_H_n_per_m": j.apparent["K_H"],
                                        "c_V_ns_per_m": j.apparent["c_V"], "c_H_ns_per_m": j.apparent["c_H"]},
                "explained_joint_si": None if j.explained is None else {
                    "K_yy_n_per_m": j.explained["K_V"], "K_xx_n_per_m": j.explained["K_H"],
                    "C_yy_ns_per_m": j.explained["c_V"], "C_xx_ns_per_m": j.explained["c_H"],
                    "f_V_rig_free_hz": j.explained["f_V"], "f_H_rig_free_hz": j.explained["f_H"],
                    "verdict": j.verdict, "rig_effects_removed": list(j.removed), "joint_effects_kept": list(j.kept)},
                "stiffness_si_model_axes": j.stiffness.tolist(), "damping_si_model_axes": j.damping.tolist(),
                "notes": list(j.notes)}

    doc = {"units": units, "unit_note": UNIT_SYSTEMS[units][1], "axis_map": axis_map_text or "x=X,y=Y,z=Z",
           "element": element, "dofs": list(DOF_NAMES), "joints": [joint_dict(j) for j in joints],
           "elements": [{"element_id": e.element_id, "carriage_node": e.carriage_node, "rail_node": e.rail_node,
                         "kind": e.kind, "dof": e.dof, "carriage": e.carriage + 1,
                         "stiffness": e.stiffness.tolist(), "damping": e.damping.tolist()} for e in elements]}
    return json.dumps(doc, indent=1, allow_nan=False) + "\n"
