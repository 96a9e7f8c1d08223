r"""CalculiX (``ccx``) decks of the identified joints: an include file, or a reference assembly.

CalculiX has no Nastran ``DMIG``, no ``MATRIX27`` and no Abaqus connector,
and its springs and dashpots act on translations only. A rigid body's
rotations are the translations of its ``ROT NODE``
(``*RIGID BODY, NSET=..., REF NODE=n, ROT NODE=n + 50``), so the joint acts on
twelve translational DOFs per carriage: the carriage node and its rotation
node, the rail node and its rotation node (``rot_offset``, default 50, gives
the rotation node's id: node + 50).

How each element kind is written
--------------------------------
``matrix``  the full 6x6 K and C, couplings included, exactly: with
            K = sum_k lambda_k v_k v_k^T (its eigen-decomposition, lambda_k > 0)
            each term is a ``SPRING1`` of stiffness lambda_k on an auxiliary
            node whose DOF 1 is tied by ``*EQUATION`` to the relative motion
            v_k . (q_carriage - q_rail); the energy sum_k lambda_k (v_k . dq)^2 / 2
            is dq^T K dq / 2. C alike, each term a ``DASHPOTA`` from its
            auxiliary node to a fixed ground node along x. Ids of carriage j,
            base = first element + id step * j: K terms elements and auxiliary
            nodes base..base+5, C terms base+6..base+11, ground node base+12.
``bush``    the diagonal: ``SPRING2`` between DOF d of the carriage and rail
            (rotation) nodes, elements base+d-1; damping terms as for matrix.
``springs`` the paper's Figure 10: ``SPRING2`` between DOF d of nodes carriage + i
            and rail + i (element base + 2 i), each with a ``DASHPOTA`` term
            (element and auxiliary node base + 2 i + 1, ground node
            base + 2 n). Where those nodes sit sets the rotational stiffness:
            the reference assembly puts them at the roller rows (x = -/+ e,
            vertical springs on rows 1-2, horizontal ones on rows 1-4) at
            z = -/+ the rollers' RMS position, where the springs' pitch and yaw
            stiffness equal the rollers'.

Auxiliary DOFs 2 and 3 and the ground node are held by ``*BOUNDARY`` in the
include; they add no free DOF. Units and axes are those of
:func:`guidefit.export.core.build_elements`.

Reference assembly (``assembly="reference"``)
---------------------------------------------
One runnable deck: per carriage the joint, the carriage as a ``*RIGID BODY``
(reference node = carriage node at the carriage origin) carrying the guide's
mass, centre of mass and inertia as seven ``MASS`` elements (half the mass at
the centre of mass, the rest at +/- a along each axis, chosen so that the
body's mass matrix is the guide's exactly), the rail nodes fixed, and a
``*FREQUENCY`` step for the carriage modes. DOFs the joint does not restrain
(z along the rail, the drive's; for the apparent joint also the rotations)
are fixed there and named in a comment. ccx's eigen solver (ARPACK) needs
about five free DOFs per requested mode, more than one rigid body has: the
deck adds independent padding oscillators (point masses on springs to
ground, 1000 times above the highest joint mode), named as such; they do not
touch the carriage. A second step (``*STEADY STATE DYNAMICS``) drives the
carriage with a unit load on each restrained DOF at the joint's natural
frequencies, so the dashpots' damping shows in the response.
"""

from __future__ import annotations

import math

import numpy as np

from guidefit.export.core import (
    DOF_NAMES,
    UNIT_SYSTEMS,
    Element,
    ExportError,
    Joint,
    _comment_lines,
    _coupling_note,
    _fmt,
    _header,
)

#: ids per element of each kind: matrix and bush 6 K + 6 C terms and a ground node, springs spring + dashpot
IDS_PER_ELEMENT = {"matrix": 13, "bush": 13, "springs": 2}
DEFAULT_ROT_OFFSET = 50
#: relative size below which an eigen-term of K or C is dropped (the z direction's exact zero and roundoff)
_TERM_TOL = 1e-12
#: mass nodes of the reference carriage: ids carriage node + rot_offset + 1 ...
_N_MASS_NODES = 7
PAD_FACTOR = 1000.0


def _ccx(x: float) -> str:
    """A real as ccx reads it: ccx takes at most 20 characters of a number (``f20.0``), so the
    shortest round-trip text when it fits, else 13-14 significant digits in exponent form.

    >>> _ccx(2.866280773293728e-05)
    '2.866280773293728E-5'
    >>> len(_ccx(-1.2345678901234567e-300)) <= 20
    True
    """
    text = _fmt(x)
    if len(text) <= 20:
        return text
    for prec in range(16, 0, -1):
        mant, _, exp = f"{float(x):.{prec}e}".partition("e")
        text = f"{mant}E{int(exp)}"
        if len(text) <= 20:
            return text
    raise ExportError(f"value {x!r} does not fit a CalculiX field")  # pragma: no cover - 1 digit always fits


def _terms(m: np.ndarray) -> list[tuple[float, np.ndarray]]:
    """Eigen-terms (lambda, v) of a symmetric PSD 6x6 with lambda > 0 (relative tolerance)."""
    if not np.any(m):
        return []
    lam, vec = np.linalg.eigh(0.5 * (m + m.T))
    top = float(np.max(np.abs(lam)))
    if lam.min() < -1e-9 * top:
        raise ExportError(f"a joint matrix is not positive semi-definite (eigenvalue {lam.min():.3g} of "
                          f"{top:.3g}); CalculiX springs cannot represent it")
    out = []
    for k in range(6):
        if lam[k] > _TERM_TOL * top:
            v = vec[:, k].copy()
            v[np.abs(v) < 1e-14] = 0.0
            out.append((float(lam[k]), v))
    return out


def _dof_node(node: int, rot_node: int, d: int) -> tuple[int, int]:
    """(node, ccx DOF) of joint DOF d = 0..5: translations on the node, rotations on its rotation node."""
    return (node, d + 1) if d < 3 else (rot_node, d - 2)


def _equation(aux: int, v: np.ndarray, cn: tuple[int, int], rn: tuple[int, int]) -> list[str]:
    """``*EQUATION`` aux_1 - v . q_carriage + v . q_rail = 0 (aux DOF 1 dependent)."""
    terms = [(aux, 1, 1.0)]
    for d in range(6):
        if v[d] != 0.0:
            terms.append((*_dof_node(cn[0], cn[1], d), -float(v[d])))
            terms.append((*_dof_node(rn[0], rn[1], d), float(v[d])))
    lines = ["*EQUATION", str(len(terms))]
    cells = [f"{n},{dof},{_ccx(c)}" for n, dof, c in terms]
    return lines + [",".join(cells[i:i + 3]) for i in range(0, len(cells), 3)]  # ccx: lines of <= 132 characters


def _term_lines(base: int, terms, cn, rn, comment: str, ground: int | None = None) -> tuple[list[str], list[str]]:
    """Auxiliary-node elements of the terms (lambda, v) of a joint matrix: (node lines, element and
    equation lines). ``ground`` None: springs (SPRING1 on the auxiliary node), else dashpots (DASHPOTA
    from the auxiliary node to ``ground``); each auxiliary node's DOF 1 is tied to v . (carriage - rail)."""
    nodes, body = [], []
    for k, (lam, v) in enumerate(terms):
        aux = base + k
        nodes.append(f"{aux},0.,0.,0.")
        head = f"** {comment} term {k + 1}: {'k' if ground is None else 'c'} = {lam:.6g} on v = ({', '.join(f'{x:.6g}' for x in v)})"
        if ground is None:
            body += [head, f"*ELEMENT,TYPE=SPRING1,ELSET=GFK{aux}", f"{aux},{aux}", f"*SPRING,ELSET=GFK{aux}", "1",
                     _ccx(lam)]
        else:
            body += [head, f"*ELEMENT,TYPE=DASHPOTA,ELSET=GFD{aux}", f"{aux},{aux},{ground}",
                     f"*DASHPOT,ELSET=GFD{aux}", "", _ccx(lam)]
        body += _equation(aux, v, cn, rn)
    return nodes, body


def _carriage_cards(elements: list[Element], element: str, rot_offset: int) -> tuple[list[str], list[str], list[int]]:
    """(node lines, element/equation lines, auxiliary node ids) of one carriage's elements."""
    nodes, body, aux_nodes, grounds = [], [], [], []
    if element in ("matrix", "bush"):
        e = elements[0]
        cn, rn = (e.carriage_node, e.carriage_node + rot_offset), (e.rail_node, e.rail_node + rot_offset)
        ground = e.element_id + 12
        if element == "matrix":
            n, b = _term_lines(e.element_id, _terms(e.stiffness), cn, rn, "K")
            nodes += n
            body += b
            aux_nodes += [e.element_id + k for k in range(len(n))]
        else:
            for d in range(6):
                k = float(e.stiffness[d, d])
                if k != 0.0:
                    (na, da), (nb, db) = _dof_node(*cn, d), _dof_node(*rn, d)
                    eid = e.element_id + d
                    body += [f"** bush {DOF_NAMES[d]}", f"*ELEMENT,TYPE=SPRING2,ELSET=GFK{eid}", f"{eid},{na},{nb}",
                             f"*SPRING,ELSET=GFK{eid}", f"{da},{db}", _ccx(k)]
        c_terms = _terms(e.damping) if element == "matrix" else [
            (float(e.damping[d, d]), np.eye(6)[d]) for d in range(6) if e.damping[d, d] != 0.0]
        n, b = _term_lines(e.element_id + 6, c_terms, cn, rn, "C", ground)
        nodes += n
        body += b
        aux_nodes += [e.element_id + 6 + k for k in range(len(n))]
        if c_terms:
            grounds.append(ground)
    else:
        ground = elements[0].element_id + 2 * len(elements)
        for i, e in enumerate(elements):
            d = e.dof
            body += [f"** spring {i + 1}: {DOF_NAMES[d - 1]}", f"*ELEMENT,TYPE=SPRING2,ELSET=GFK{e.element_id}",
                     f"{e.element_id},{e.carriage_node},{e.rail_node}", f"*SPRING,ELSET=GFK{e.element_id}",
                     f"{d},{d}", _ccx(e.stiffness[d - 1, d - 1])]
            c = float(e.damping[d - 1, d - 1])
            if c != 0.0:
                n, b = _term_lines(e.element_id + 1, [(c, np.eye(6)[d - 1])],
                                   (e.carriage_node, e.carriage_node), (e.rail_node, e.rail_node),
                                   f"spring {i + 1} C", ground)
                nodes += n
                body += b
                aux_nodes.append(e.element_id + 1)
        if aux_nodes:
            grounds.append(ground)
    nodes += [f"{g},1.,0.,0." for g in grounds]
    fixed = [f"{a},2,3" for a in aux_nodes] + [f"{g},1,3" for g in grounds]
    if fixed:
        body += ["** auxiliary nodes: DOF 1 is the term's relative motion; DOFs 2-3 and the ground node held",
                 "*BOUNDARY", *fixed]
    return nodes, body, aux_nodes + grounds


def to_calculix(joints: list[Joint], elements: list[Element], units: str = "si", axis_map_text=None,
                element: str = "matrix", rot_offset: int = DEFAULT_ROT_OFFSET) -> str:
    """The joints as a CalculiX include file (model data: nodes, elements, equations; no step)."""
    lines = _header(joints, "**", units, axis_map_text, element)
    lines += _comment_lines("**", f"CalculiX: rotations are the translations of each node's rotation node "
                                  f"(node + {rot_offset}; *RIGID BODY ROT NODE); *INCLUDE this file in the "
                                  "model data before the first *STEP")
    note = _coupling_note(elements) if element == "bush" else None
    if note:
        lines += _comment_lines("**", note)
    for j in range(len(joints)):
        mine = [e for e in elements if e.carriage == j]
        nodes, body, _ = _carriage_cards(mine, element, rot_offset)
        lines += _comment_lines("**", f"carriage {j + 1}")
        if nodes:
            lines += ["*NODE", *nodes]
        lines += body
    return "\n".join(lines) + "\n"


def check_ids(elements: list[Element], element: str, id_step: int, rot_offset: int) -> None:
    """Refuse numbering where the ground node or rotation nodes would collide (one line)."""
    if rot_offset < 1:
        raise ExportError(f"export: --rot-node-offset must be at least 1, got {rot_offset}")
    by_carriage: dict = {}
    for e in elements:
        by_carriage.setdefault(e.carriage, []).append(e)
    for els in by_carriage.values():
        need = 13 if element != "springs" else 2 * len(els) + 1
        if need > id_step:
            raise ExportError(f"export: calculix needs {need} ids per carriage but --id-step {id_step}; raise it")
        if element == "springs" and len(els) > rot_offset - 1:
            raise ExportError(f"export: {len(els)} springs per carriage reach the rotation nodes (node + "
                              f"{rot_offset}); raise --rot-node-offset")


def length_and_mass_scale(units: str) -> tuple[float, float]:
    """(length, mass) factors from SI to ``units`` (mm systems: mm and t)."""
    s = UNIT_SYSTEMS[units][0]
    return s, (1.0 if s == 1.0 else 1.0e-3)


def pad_frequency(k: np.ndarray, m: np.ndarray) -> float:
    """PAD_FACTOR times the highest natural frequency of (K, M) (restrained DOFs only), Hz."""
    lam = np.linalg.eigvals(np.linalg.solve(m, k)).real
    return PAD_FACTOR * math.sqrt(max(float(lam.max()), 1.0)) / (2 * math.pi)
