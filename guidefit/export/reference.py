"""The CalculiX reference assembly: a joint, the guide's carriage as a rigid body, the rail fixed.

See :mod:`guidefit.export.calculix` ("Reference assembly"). :func:`reference_models`
gives, per carriage, what the deck contains as matrices (machine axes, output
units): the joint's K and C at the carriage node, the carriage's mass matrix,
the restrained DOFs; guidefit's own frequencies of that joint come from them
and are written into the deck as comments, so one ``ccx`` call checks them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from guidefit.export.calculix import (
    _N_MASS_NODES,
    PAD_FACTOR,
    _carriage_cards,
    _ccx,
    length_and_mass_scale,
)
from guidefit.export.core import DOF_NAMES, Element, ExportError, Joint, _comment_lines, _header


@dataclass(frozen=True)
class ReferenceModel:
    """One carriage of the reference assembly (machine axes, output units)."""

    ref_node: int
    rot_node: int
    mass_points: tuple  # ((node, mass, (x, y, z)), ...)
    spring_points: tuple  # ((carriage node, rail node, (x, y, z)), ...) for springs
    rail_nodes: tuple
    stiffness: np.ndarray  # 6x6 about the reference node
    damping: np.ndarray
    mass: np.ndarray  # 6x6 rigid-body mass matrix about the reference node
    free: np.ndarray  # bool (6,): DOFs the joint restrains

    def frequencies_hz(self) -> np.ndarray:
        """guidefit's natural frequencies of the carriage on this joint (restrained DOFs), ascending."""
        f = self.free
        k, m = self.stiffness[np.ix_(f, f)], self.mass[np.ix_(f, f)]
        lam = np.linalg.eigvals(np.linalg.solve(m, k)).real
        return np.sort(np.sqrt(np.clip(lam, 0.0, None))) / (2 * math.pi)

    def response(self, frequency_hz: float, load: np.ndarray) -> np.ndarray:
        """Complex displacement (restrained DOFs) for a harmonic ``load`` on them: (K - w^2 M + i w C)^-1 f."""
        f = self.free
        w = 2 * math.pi * frequency_hz
        z = self.stiffness[np.ix_(f, f)] - w**2 * self.mass[np.ix_(f, f)] + 1j * w * self.damping[np.ix_(f, f)]
        return np.linalg.solve(z, load)


def _load_guide(guide, joint: Joint):
    from guidefit.model.guides import Guide, load_guide

    if isinstance(guide, Guide):
        return guide
    return load_guide(guide or joint.guide or "MRB35")


def point_gradient(p: np.ndarray) -> np.ndarray:
    """(3, 6): translation of point p per (t, theta) of a rigid body about the origin (t + theta x p)."""
    x, y, z = p
    return np.array([[1.0, 0, 0, 0, z, -y], [0, 1.0, 0, -z, 0, x], [0, 0, 1.0, y, -x, 0]])


def mass_points(guide) -> list[tuple[float, np.ndarray]]:
    """(mass kg, position m, model frame) of seven point masses with the guide's mass, centre and inertia.

    Half the mass at the centre of mass, m_i = s_i / (2 a^2) at +/- a along
    axis i with s_x = (Jy + Jz - Jx)/2 (and cyclic), a large enough that the
    six sum to half the mass: sum m r r^T gives the inertia about the centre.
    """
    jx, jy, jz = (float(v) for v in guide.inertia_kg_m2)
    s = np.array([(jy + jz - jx) / 2, (jx + jz - jy) / 2, (jx + jy - jz) / 2])
    if np.any(s < -1e-12 * max(jx, jy, jz)):
        raise ExportError(f"guide {guide.name}: inertias {jx:g}, {jy:g}, {jz:g} kg m^2 violate the triangle "
                          "inequality; no rigid body has them")
    s = np.clip(s, 0.0, None)
    mass = float(guide.mass_kg)
    a = math.sqrt(2 * s.sum() / mass) if s.sum() > 0 else 0.0
    centre = np.asarray(guide.center_of_mass_m, float)
    points = [(mass - (s.sum() / a**2 if a else 0.0), centre)]
    for i in range(3):
        for sign in (1.0, -1.0):
            points.append((s[i] / (2 * a**2) if a else 0.0, centre + sign * a * np.eye(3)[i]))
    return points


def spring_positions(guide, n_vertical: int, n_horizontal: int) -> list[np.ndarray]:
    """Model-frame positions of the Figure 10 springs: at the roller rows, z = -/+ the rollers' RMS z."""
    z = float(np.sqrt(np.mean(np.asarray(guide.roller_positions_z_m(), float) ** 2)))
    e, h1, h3 = guide.row_offset_m, guide.h1_m, guide.h3_m
    vertical = [np.array([sx * e, -h1, sz * z]) for sz in (-1, 1) for sx in (-1, 1)]
    horizontal = [np.array([sx * e, -h, sz * z]) for h in (h1, h3) for sz in (-1, 1) for sx in (-1, 1)]
    return [vertical[i % 4] for i in range(n_vertical)] + [horizontal[i % 8] for i in range(n_horizontal)]


def reference_models(joints: list[Joint], elements: list[Element], *, units: str, axis_map: np.ndarray,
                     element: str, rot_offset: int, guide=None, n_vertical: int = 4) -> list[ReferenceModel]:
    """One :class:`ReferenceModel` per carriage (see the module docstring)."""
    ls, ms = length_and_mass_scale(units)
    rot = axis_map
    models = []
    for j, jt in enumerate(joints):
        g = _load_guide(guide, jt)
        mine = [e for e in elements if e.carriage == j]
        cnode = mine[0].carriage_node
        ref = cnode if element != "springs" else cnode + rot_offset + _N_MASS_NODES + 1
        masses = tuple((cnode + rot_offset + 1 + k, m * ms, rot @ p * ls) for k, (m, p) in enumerate(mass_points(g)))
        mass = np.zeros((6, 6))
        for _, m, p in masses:
            gp = point_gradient(p)
            mass += m * gp.T @ gp
        springs = ()
        if element == "springs":
            pos = spring_positions(g, n_vertical, len(mine) - n_vertical)
            springs = tuple((e.carriage_node, e.rail_node, rot @ p * ls) for e, p in zip(mine, pos))
            k6, c6 = np.zeros((6, 6)), np.zeros((6, 6))
            for e, (_, _, p) in zip(mine, springs):
                gp = point_gradient(p)
                k6 += gp.T @ e.stiffness[:3, :3] @ gp
                c6 += gp.T @ e.damping[:3, :3] @ gp
            rails = tuple(e.rail_node for e in mine)
        else:
            k6, c6 = mine[0].stiffness, mine[0].damping
            if element == "bush":  # what the deck holds: the diagonal
                k6, c6 = np.diag(np.diag(k6)), np.diag(np.diag(c6))
            rails = (mine[0].rail_node, mine[0].rail_node + rot_offset)
        diag = np.abs(np.diag(k6))
        free = diag > 1e-9 * diag.max()
        models.append(ReferenceModel(ref, ref + rot_offset if element != "springs" else cnode + rot_offset,
                                     masses, springs, rails, k6, c6, mass, free))
    return models


def _rigid_equations(ref: int, rot: int, points) -> list[str]:
    """Linear ``*EQUATION`` s tying each point to the body: u_p = u_ref + theta x p (theta: rot node's DOFs).

    The same kinematics as ``*RIGID BODY, REF NODE, ROT NODE`` for small motion, written out:
    ccx 2.20 leaves entries of a rigid body's mass out of the matrix structure unless
    other elements couple the reference and rotation DOFs ("coefficient should be 0").
    """
    lines = _comment_lines("**", f"the carriage: a rigid body, reference node {ref}, rotation node {rot} "
                                 "(its DOFs 1-3 are the rotations)")
    for node, p in points:
        gp = point_gradient(np.asarray(p, float))
        for i in range(3):
            terms = [(node, i + 1, 1.0), (ref, i + 1, -1.0)]
            terms += [(rot, k + 1, -float(gp[i, 3 + k])) for k in range(3) if gp[i, 3 + k] != 0.0]
            cells = [f"{n},{d},{_ccx(c)}" for n, d, c in terms]
            lines += ["*EQUATION", str(len(terms))] + [",".join(cells[a:a + 3]) for a in range(0, len(cells), 3)]
    return lines


def _coupler_cards(node: int, model: ReferenceModel) -> list[str]:
    """A zero-stiffness ``SPRING1`` tied to all the carriage's free DOFs: only so that ccx's matrix
    structure couples them. ccx 2.20 otherwise drops the body's mass couplings between the
    reference and rotation nodes ("coefficient should be 0") when no element joins them (bush)."""
    dofs = [(model.ref_node, d + 1) if d < 3 else (model.rot_node, d - 2) for d in range(6) if model.free[d]]
    cells = [f"{node},1,1."] + [f"{n},{d},1." for n, d in dofs]
    lines = _comment_lines("**", "matrix-structure coupler (zero stiffness; see the guidefit docs)")
    lines += ["*NODE", f"{node},0.,0.,0.", f"*ELEMENT,TYPE=SPRING1,ELSET=GFX{node}", f"{node},{node}",
              f"*SPRING,ELSET=GFX{node}", "1", "0."]
    return lines + ["*EQUATION", str(len(cells))] + [",".join(cells[a:a + 3]) for a in range(0, len(cells), 3)]


def _pad_cards(first: int, count: int, mass: float, k: float) -> list[str]:
    nodes = [first + i for i in range(count)]
    lines = _comment_lines("**", f"ARPACK padding: {count} independent oscillators (point mass {mass:.6g} on "
                                 f"springs to ground, {PAD_FACTOR:g} x the highest carriage mode); ccx's eigen "
                                 "solver needs about 5 free DOFs per requested mode. They touch nothing else.")
    lines += ["*NODE,NSET=GFPAD", *[f"{n},0.,0.,0." for n in nodes]]
    lines += ["*ELEMENT,TYPE=MASS,ELSET=GFPADM", *[f"{n},{n}" for n in nodes], "*MASS,ELSET=GFPADM", _ccx(mass)]
    for d in (1, 2, 3):
        lines += [f"*ELEMENT,TYPE=SPRING1,ELSET=GFPADK{d}", *[f"{n + count * d},{n}" for n in nodes],
                  f"*SPRING,ELSET=GFPADK{d}", str(d), _ccx(k)]
    return lines


def reference_deck(joints: list[Joint], elements: list[Element], *, units: str, axis_map: np.ndarray,
                   axis_map_text, element: str, rot_offset: int, guide=None, n_vertical: int = 4) -> str:
    """The complete runnable deck (see the module docstring of :mod:`guidefit.export.calculix`)."""
    models = reference_models(joints, elements, units=units, axis_map=axis_map, element=element,
                              rot_offset=rot_offset, guide=guide, n_vertical=n_vertical)
    lines = _header(joints, "**", units, axis_map_text, element)
    lines += _comment_lines("**", "guidefit reference assembly: the joint, the carriage as a rigid body with "
                                  "the guide's mass, centre of mass and inertia, the rail fixed. Run: ccx -i "
                                  "<name without .inp>; the frequencies are in <name>.dat")
    n_modes, top, used = 0, 0.0, []
    body, bc, loads = [], [], []
    for j, model in enumerate(models):
        mine = [e for e in elements if e.carriage == j]
        nodes, cards, aux = _carriage_cards(mine, element, rot_offset)
        freqs = model.frequencies_hz()
        n_modes += int(model.free.sum())
        top = max(top, float(freqs.max()))
        lines += _comment_lines("**", f"carriage {j + 1}: guidefit's natural frequencies of this joint and body, "
                                      "Hz: " + ", ".join(f"{f:.8g}" for f in freqs))
        held = [DOF_NAMES[d] for d in range(6) if not model.free[d]]
        if held:
            lines += _comment_lines("**", f"carriage {j + 1}: DOFs the joint does not restrain, held fixed "
                                          f"here: {', '.join(held)}")
        members = [n for n, _, _ in model.mass_points] + [c for c, _, _ in model.spring_points]
        body += ["*NODE", f"{model.ref_node},0.,0.,0.", f"{model.rot_node},0.,0.,0."]
        body += [f"{n},{_ccx(p[0])},{_ccx(p[1])},{_ccx(p[2])}" for n, _, p in model.mass_points]
        body += [f"{c},{_ccx(p[0])},{_ccx(p[1])},{_ccx(p[2])}" for c, _, p in model.spring_points]
        body += [f"{r},{_ccx(p[0])},{_ccx(p[1])},{_ccx(p[2])}" for _, r, p in model.spring_points]
        if element != "springs":
            body += [f"{r},0.,0.,0." for r in model.rail_nodes]
        body += nodes
        points = [(n, p) for n, _, p in model.mass_points] + [(c, p) for c, _, p in model.spring_points]
        body += _rigid_equations(model.ref_node, model.rot_node, points)
        coupler = model.rot_node + _N_MASS_NODES + 9 if element != "springs" else model.ref_node + 1
        body += _coupler_cards(coupler, model)
        bc.append(f"{coupler},2,3")
        members.append(coupler)
        for n, m, _ in model.mass_points:
            if m > 0:
                body += [f"*ELEMENT,TYPE=MASS,ELSET=GFM{n}", f"{n},{n}", f"*MASS,ELSET=GFM{n}", _ccx(m)]
        body += cards
        bc += [f"{r},1,3" for r in model.rail_nodes]
        for d in range(6):
            node, dof = (model.ref_node, d + 1) if d < 3 else (model.rot_node, d - 2)
            (loads if model.free[d] else bc).append(f"{node},{dof}" + (",1." if model.free[d] else f",{dof}"))
        used += [model.ref_node, model.rot_node, *members, *model.rail_nodes, *aux]
        used += [e.element_id + k for e in mine for k in range(13)]
    lines += body
    lines += ["*BOUNDARY", *bc]
    free_dofs = n_modes
    n_pad = max(0, math.ceil((5 * n_modes + 6 - free_dofs) / 3))
    k_pad = (2 * math.pi * PAD_FACTOR * top) ** 2 * 1.0
    lines += _pad_cards(max(used) + 1, n_pad, 1.0, k_pad)
    shape_nodes = sorted(n for model in models for n, m, _ in model.mass_points if m > 0)
    lines += ["*NSET,NSET=GFSHAPE", *[str(n) for n in shape_nodes]]
    lines += ["*STEP", "*FREQUENCY,STORAGE=YES", str(n_modes), "*NODE PRINT,NSET=GFSHAPE", "U", "*END STEP"]
    f_hi = 2.0 * top
    lines += ["*STEP", "*STEADY STATE DYNAMICS", f"{_ccx(f_hi / 1000)},{_ccx(f_hi)},3,1.", "*CLOAD", *loads,
              "*NODE PRINT,NSET=GFLOADED", "U", "*END STEP"]
    loaded = sorted({int(s.split(",")[0]) for s in loads})
    at = lines.index("*BOUNDARY")
    lines[at:at] = ["*NSET,NSET=GFLOADED", *[str(n) for n in loaded]]
    return "\n".join(lines) + "\n"
