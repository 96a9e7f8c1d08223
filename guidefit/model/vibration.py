"""Vibration model of the carriage on its roller springs (paper Eq. 5-23).

The carriage is a rigid body with the five generalised coordinates of the
paper, ``q = (u, v, theta, psi, phi)``: lateral and vertical translation and
rotations about x (pitch), y (yaw) and z (roll); the axial translation w is
not constrained by the rollers and is left out. A carriage point ``r = (x, y, z)``
moves by (small rotations)::

    d_x = u + psi z - phi y
    d_y = v + phi x - theta z
    d_z = theta y - psi x

Each roller is a linear spring ``K_n`` along its contact normal ``n = (n_x, n_y, 0)``
(the roller mass is neglected, as in the paper). Its deflection is
``delta = g . q`` with ``g = (n_x, n_y, -n_y z, n_x z, n_y x - n_x y)``, and the
stiffness matrix is the sum of ``K_n g g^T`` over all rollers. This is
Lagrange's equations, Eq. (10)-(14), assembled from the individual springs of
Eq. (9) instead of written out term by term, so that every roller may have its
own stiffness (damage, load-dependent contacts) without new algebra.

The model is a :class:`ModelSpec`; extensions are pure functions that return a
new spec (:func:`with_point_masses`, :func:`with_roller_stiffness`,
:func:`with_support`), so effects plug in without touching the core. A support
body (rail or base) is a second rigid body with the same five coordinates
about a reference point, carried by springs to the ground; the rollers then act
between carriage and body. A massless support DOF is condensed statically; an
infinitely stiff one is removed.

Closed forms Eq. (15)-(23) hold for the uniform model and are implemented
beside the assembled solution; the tests check one against the other.

Examples
--------
>>> from guidefit.model.guides import load_guide
>>> from guidefit.model.vibration import model_from_guide, solve_modes
>>> sol = solve_modes(model_from_guide(load_guide("MRB35")))
>>> [f"{lab} {f:.1f}" for lab, f in zip(sol.labels, sol.frequencies_hz)]
['yaw 1879.1', 'pitch 2275.9', 'roll_low 2496.5', 'vertical 3529.0', 'roll_high 5563.6']
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from guidefit.errors import ModelError

CARRIAGE_DOFS = ("u", "v", "theta", "psi", "phi")
# the labels and the label lists of guidefit, one home: every module imports them from here
#: The carriage modes of the model, by the motion that dominates each (:func:`solve_modes` names them).
MODE_LABELS = ("vertical", "pitch", "yaw", "roll_low", "roll_high")
#: The joint parameters' modes (Eq. 24-29): K_V, c_V from the vertical mode, K_H, c_H from roll_low.
JOINT_LABELS = {"V": "vertical", "H": "roll_low"}
#: Labels of identified modes that name no model mode: a peak the model does not predict (``extra``) and a
#: mode the layout cannot tell between two or more model modes (``ambiguous``, with ``candidates``).
UNNAMED_LABELS = ("extra", "ambiguous")


@dataclass(frozen=True)
class RollerSet:
    """Individual roller springs: contact point, normal, stiffness and row number (1-4)."""

    position_m: np.ndarray  # (N, 3)
    normal: np.ndarray  # (N, 3), unit, n_z = 0
    stiffness_n_per_m: np.ndarray  # (N,)
    row: np.ndarray  # (N,) int, 1..4


@dataclass(frozen=True)
class PointMass:
    """A point mass rigidly attached to the carriage at ``position_m``."""

    mass_kg: float
    position_m: tuple[float, float, float]


@dataclass(frozen=True)
class SupportBody:
    """A rigid body between the rollers and the ground (a rail on a compliant mounting, a base).

    ``stiffness_to_ground`` holds the five support stiffnesses at the body's
    reference point, for (u, v, theta, psi, phi): N/m for translations, N m/rad
    for rotations; ``math.inf`` marks a rigid (removed) coordinate.
    ``mass_kg`` and ``inertia_kg_m2`` (Jx, Jy, Jz about the reference point) may be
    zero: a massless support is condensed statically (pure series compliance).
    """

    stiffness_to_ground: tuple[float, float, float, float, float]
    mass_kg: float = 0.0
    inertia_kg_m2: tuple[float, float, float] = (0.0, 0.0, 0.0)
    reference_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    name: str = "support"


@dataclass(frozen=True)
class ModelSpec:
    """Everything the eigen-solution needs; build with :func:`model_from_guide`."""

    mass_kg: float
    inertia_kg_m2: tuple[float, float, float]
    center_of_mass_m: tuple[float, float, float]
    rollers: RollerSet
    point_masses: tuple[PointMass, ...] = ()
    support: SupportBody | None = None
    measuring_points_m: dict = field(default_factory=dict)
    name: str = ""


@dataclass(frozen=True)
class ModalSolution:
    """Undamped natural frequencies and mass-normalised mode shapes.

    ``shapes[:, k]`` is mode k over ``dof_names`` (carriage first, then any
    support-body DOFs); ``point_motion[name]`` is (n_modes, 3): the translation
    of each measuring point per unit modal coordinate.
    """

    frequencies_hz: np.ndarray
    labels: tuple[str, ...]
    shapes: np.ndarray
    dof_names: tuple[str, ...]
    point_motion: dict
    energy_fractions: np.ndarray  # (n_modes, 5): v, theta, psi, u+phi, support body

    def frequency_hz(self, label: str) -> float:
        """Natural frequency of the mode with this label."""
        try:
            return float(self.frequencies_hz[self.labels.index(label)])
        except ValueError:
            raise ModelError(f"no mode labelled '{label}'; have {', '.join(self.labels)}") from None

    def to_frame(self):
        """One row per mode: label, frequency_hz and the energy fractions."""
        import pandas as pd

        frame = pd.DataFrame({"label": self.labels, "frequency_hz": self.frequencies_hz})
        for i, name in enumerate(("v", "theta", "psi", "u_phi", "support")):
            frame[f"energy_{name}"] = self.energy_fractions[:, i]
        return frame


# --------------------------------------------------------------------------- geometry


def rigid_body_map(point_m) -> np.ndarray:
    """(3, 5) matrix mapping (u, v, theta, psi, phi) to the translation of a carriage point.

    >>> rigid_body_map((0.0, 0.0, 1.0)) @ [0, 0, 0, 1.0, 0]   # yaw moves z=1 laterally
    array([1., 0., 0.])
    """
    x, y, z = (float(c) for c in point_m)
    return np.array(
        [
            [1.0, 0.0, 0.0, z, -y],
            [0.0, 1.0, -z, 0.0, x],
            [0.0, 0.0, y, -x, 0.0],
        ]
    )


def row_geometry(guide) -> list[tuple[float, float, float, float]]:
    """Rows 1-4 of Eq. (9) as (x, y, n_x, n_y): position in the x-y plane and contact normal.

    Row 1 at (-e, -h1) with normal (cos b, sin b), row 2 at (+e, -h1) with
    (-cos b, sin b), row 3 at (-e, -h3) with (cos b, -sin b), row 4 at (+e, -h3)
    with (-cos b, -sin b). ``arrangement = "X"`` mirrors the lateral normal
    components (the opposite arrangement of the lines of action).
    """
    e = guide.row_offset_m
    c, s = math.cos(guide.contact_angle_rad), math.sin(guide.contact_angle_rad)
    mirror = -1.0 if guide.arrangement == "X" else 1.0
    return [
        (-e, -guide.h1_m, mirror * c, s),
        (+e, -guide.h1_m, -mirror * c, s),
        (-e, -guide.h3_m, mirror * c, -s),
        (+e, -guide.h3_m, -mirror * c, -s),
    ]


def rollers_from_guide(guide, roller_stiffness_n_per_m=None) -> RollerSet:
    """Individual rollers of Eq. (9): Z_L per row at z = l_i, each a spring K_n along its normal.

    ``roller_stiffness_n_per_m`` may be a scalar, a (4,) per-row or a (4, Z_L)
    per-roller array; default the guide's K_n times its effective roller fraction.
    """
    z = guide.roller_positions_z_m()
    n_z = z.size
    if roller_stiffness_n_per_m is None:
        roller_stiffness_n_per_m = guide.roller_stiffness_n_per_m * guide.effective_roller_fraction
    k = np.asarray(roller_stiffness_n_per_m, dtype=float)
    if k.ndim == 0:
        k = np.full((4, n_z), float(k))
    elif k.shape == (4,):
        k = np.repeat(k[:, None], n_z, axis=1)
    if k.shape != (4, n_z):
        raise ModelError(f"roller stiffness: expected a scalar, 4 rows or (4, {n_z}) rollers, got shape {k.shape}")
    if np.any(~np.isfinite(k)) or np.any(k < 0):
        raise ModelError("roller stiffness: every value must be finite and non-negative")
    positions, normals, rows = [], [], []
    for row, (x, y, nx, ny) in enumerate(row_geometry(guide), start=1):
        for zi in z:
            positions.append((x, y, zi))
            normals.append((nx, ny, 0.0))
            rows.append(row)
    return RollerSet(
        position_m=np.array(positions),
        normal=np.array(normals),
        stiffness_n_per_m=k.reshape(-1).copy(),
        row=np.array(rows),
    )


def model_from_guide(guide, roller_stiffness_n_per_m=None) -> ModelSpec:
    """The nominal vibration model of a guide (uniform K_n unless given)."""
    return ModelSpec(
        mass_kg=guide.mass_kg,
        inertia_kg_m2=tuple(guide.inertia_kg_m2),
        center_of_mass_m=tuple(guide.center_of_mass_m),
        rollers=rollers_from_guide(guide, roller_stiffness_n_per_m),
        measuring_points_m=dict(guide.measuring_points_m),
        name=guide.name,
    )


# --------------------------------------------------------------------------- extensions


def with_point_masses(spec: ModelSpec, masses) -> ModelSpec:
    """Add point masses, an iterable of (mass_kg, (x, y, z)) or :class:`PointMass`."""
    extra = tuple(m if isinstance(m, PointMass) else PointMass(float(m[0]), tuple(m[1])) for m in masses)
    for m in extra:
        if not m.mass_kg >= 0:
            raise ModelError(f"point mass: mass_kg must be non-negative, got {m.mass_kg}")
    return replace(spec, point_masses=spec.point_masses + extra)


def with_roller_stiffness(spec: ModelSpec, stiffness_n_per_m) -> ModelSpec:
    """Replace the roller stiffnesses: scalar factor arrays of shape (N,) or a scalar for all."""
    k = np.broadcast_to(np.asarray(stiffness_n_per_m, dtype=float), spec.rollers.stiffness_n_per_m.shape)
    if np.any(~np.isfinite(k)) or np.any(k < 0):
        raise ModelError("roller stiffness: every value must be finite and non-negative")
    return replace(spec, rollers=replace(spec.rollers, stiffness_n_per_m=k.copy()))


def scale_roller_stiffness(spec: ModelSpec, factor) -> ModelSpec:
    """Multiply every roller stiffness by ``factor`` (scalar, per row (4,) or per roller (N,))."""
    f = np.asarray(factor, dtype=float)
    if f.shape == (4,):
        f = f[spec.rollers.row - 1]
    return with_roller_stiffness(spec, spec.rollers.stiffness_n_per_m * f)


def roller_index_in_row(rollers: RollerSet) -> np.ndarray:
    """(N,) 1-based position of each roller in its row, counted along +z (roller 1 at the -z end)."""
    index = np.zeros(rollers.row.size, dtype=int)
    for row in np.unique(rollers.row):
        sel = np.flatnonzero(rollers.row == row)
        index[sel[np.argsort(rollers.position_m[sel, 2], kind="stable")]] = np.arange(1, sel.size + 1)
    return index


def segment_weights(rollers: RollerSet, row: int, first: float, last: float) -> np.ndarray:
    """(N,) share of each roller inside the segment ``first``-``last`` of row ``row`` (0 to 1).

    Roller i (1-based along +z) spans ``[i - 1/2, i + 1/2]`` and the segment
    ``[first - 1/2, last + 1/2]``: whole numbers select rollers first..last
    exactly; fractional ends take part of a roller, so a fit can move an end
    smoothly.

    >>> from guidefit.model.guides import load_guide
    >>> w = segment_weights(rollers_from_guide(load_guide("MRB35")), 2, 1, 10)
    >>> float(w.sum()), float(w[21:31].min())
    (10.0, 1.0)
    """
    index = roller_index_in_row(rollers)
    overlap = np.minimum(index + 0.5, last + 0.5) - np.maximum(index - 0.5, first - 0.5)
    return np.where(rollers.row == row, np.clip(overlap, 0.0, 1.0), 0.0)


def scale_roller_segment(spec: ModelSpec, row: int, first: float, last: float, factor: float) -> ModelSpec:
    """Rollers ``first``-``last`` of row ``row`` (see :func:`segment_weights`) times ``factor``."""
    w = segment_weights(spec.rollers, row, first, last)
    return scale_roller_stiffness(spec, 1.0 - (1.0 - float(factor)) * w)


def with_support(spec: ModelSpec, support: SupportBody) -> ModelSpec:
    """Put a support body (rail, base) between the rollers and the ground."""
    k = np.asarray(support.stiffness_to_ground, dtype=float)
    if k.shape != (5,) or np.any(np.isnan(k)) or np.any(k <= 0):
        raise ModelError("support: stiffness_to_ground needs 5 positive values (inf for rigid)")
    if support.mass_kg < 0 or min(support.inertia_kg_m2) < 0:
        raise ModelError("support: mass and inertia must be non-negative")
    return replace(spec, support=support)


# --------------------------------------------------------------------------- assembly


def roller_gradients(rollers: RollerSet) -> np.ndarray:
    """(N, 5) rows g with delta = g . q for each roller (the geometry of Eq. 9-14)."""
    x, y, z = rollers.position_m.T
    nx, ny = rollers.normal[:, 0], rollers.normal[:, 1]
    return np.column_stack([nx, ny, -ny * z, nx * z, ny * x - nx * y])


def carriage_stiffness_matrix(rollers: RollerSet) -> np.ndarray:
    """5x5 stiffness matrix of the carriage on rigid ground, Eq. (10)-(14).

    K = sum_i K_n,i g_i g_i^T over all rollers; this reproduces the
    coefficients of Lagrange's equations (10)-(14) of the paper, including the
    u-phi coupling.
    """
    g = roller_gradients(rollers)
    return (g * rollers.stiffness_n_per_m[:, None]).T @ g


def carriage_mass_matrix(spec: ModelSpec) -> np.ndarray:
    """5x5 mass matrix about the origin, Eq. (5)-(8) generalised.

    Eq. (8) puts the centre of mass at the origin (diagonal M, Jx, Jy, Jz).
    With a centre-of-mass offset c the translational mass couples to the
    rotations (e.g. -M y_c between u and phi); point masses add m G^T G.
    """
    m = spec.mass_kg
    jx, jy, jz = spec.inertia_kg_m2
    g_c = rigid_body_map(spec.center_of_mass_m)
    mass = m * g_c.T @ g_c
    mass[2, 2] += jx
    mass[3, 3] += jy
    mass[4, 4] += jz
    for pm in spec.point_masses:
        g = rigid_body_map(pm.position_m)
        mass += pm.mass_kg * g.T @ g
    return mass


def assemble(spec: ModelSpec) -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
    """Full stiffness and mass matrices and DOF names, support body included.

    Returns (K, M, dof_names). Rigid support coordinates are removed;
    massless ones are kept (condensed later by :func:`solve_modes`).
    """
    g = roller_gradients(spec.rollers)
    k_r = spec.rollers.stiffness_n_per_m
    m_c = carriage_mass_matrix(spec)
    if spec.support is None:
        return (g * k_r[:, None]).T @ g, m_c, CARRIAGE_DOFS
    sup = spec.support
    ref = np.asarray(sup.reference_m, dtype=float)
    # roller deflection = n . (d_carriage(p) - d_body(p)); body map about its reference point
    rel = spec.rollers.position_m - ref
    g_body = roller_gradients(replace(spec.rollers, position_m=rel))
    g_full = np.hstack([g, -g_body])
    k = (g_full * k_r[:, None]).T @ g_full
    k_ground = np.asarray(sup.stiffness_to_ground, dtype=float)
    free = np.isfinite(k_ground)
    k[5:, 5:] += np.diag(np.where(free, k_ground, 0.0))
    m = np.zeros((10, 10))
    m[:5, :5] = m_c
    m[5:, 5:] = np.diag([sup.mass_kg, sup.mass_kg, *sup.inertia_kg_m2])
    keep = np.concatenate([np.ones(5, bool), free])
    names = CARRIAGE_DOFS + tuple(f"{sup.name}_{d}" for d in CARRIAGE_DOFS)
    return k[np.ix_(keep, keep)], m[np.ix_(keep, keep)], tuple(n for n, f in zip(names, keep) if f)


def solve_modes(spec: ModelSpec) -> ModalSolution:
    """Natural frequencies and mode shapes, labelled by dominant motion.

    Massless coordinates are condensed statically (Guyan, exact for zero mass)
    before the generalised eigenproblem K phi = w^2 M phi is solved, by the
    Cholesky reduction M = L L^T to the standard symmetric problem
    (L^-1 K L^-T) y = w^2 y, phi = L^-T y (what LAPACK's sygv does; numpy.linalg
    for a matrix of 5 to 10 rows instead of importing scipy.linalg, 50-80 ms).
    The shapes are mass-normalised: phi^T M phi = I.
    """
    k, m, names = assemble(spec)
    massless = np.isclose(np.diag(m), 0.0) & np.all(np.isclose(m, 0.0), axis=1)
    keep = ~massless
    if np.any(massless):
        k_ss = k[np.ix_(massless, massless)]
        k_sm = k[np.ix_(massless, keep)]
        try:
            t_s = -np.linalg.solve(k_ss, k_sm)
        except np.linalg.LinAlgError:
            raise ModelError("support: massless coordinates are unrestrained (singular stiffness)") from None
        t = np.zeros((len(names), int(keep.sum())))
        t[keep] = np.eye(int(keep.sum()))
        t[massless] = t_s
        k_red, m_red = t.T @ k @ t, t.T @ m @ t
    else:
        t = np.eye(len(names))
        k_red, m_red = k, m
    eigval, vec = _generalised_eigh(k_red, m_red)
    if eigval[0] <= 0:
        raise ModelError(
            "stiffness matrix is singular: the rollers do not restrain every DOF (check rows and stiffness)"
        )
    shapes = t @ vec
    freqs = np.sqrt(eigval) / (2 * math.pi)
    energy = _energy_fractions(shapes, m, len(names))
    labels = _label_modes(energy)
    motion = {
        name: (rigid_body_map(p) @ shapes[:5]).T for name, p in spec.measuring_points_m.items()
    }
    return ModalSolution(freqs, labels, shapes, names, motion, energy)


def _generalised_eigh(k: np.ndarray, m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues (ascending) and M-orthonormal eigenvectors of K phi = lambda M phi (K, M symmetric,
    M positive definite), by the Cholesky reduction of :func:`solve_modes`."""
    try:
        factor = np.linalg.cholesky(m)
    except np.linalg.LinAlgError:
        raise ModelError("mass matrix is not positive definite (check masses and inertias)") from None
    factor_inverse = np.linalg.solve(factor, np.eye(m.shape[0]))
    reduced = factor_inverse @ k @ factor_inverse.T
    eigval, y = np.linalg.eigh((reduced + reduced.T) / 2)
    return eigval, factor_inverse.T @ y


def _energy_fractions(shapes: np.ndarray, m: np.ndarray, n_dof: int) -> np.ndarray:
    """Kinetic-energy share per mode: v, theta, psi, u+phi and support body (rows sum to 1)."""
    contrib = shapes * (m @ shapes) if m.shape[0] == shapes.shape[0] else shapes**2
    contrib = np.abs(contrib)
    total = contrib.sum(axis=0)
    groups = [contrib[1], contrib[2], contrib[3], contrib[0] + contrib[4], contrib[5:].sum(axis=0)]
    return (np.vstack(groups) / total).T


#: assignments tried one by one at most (beyond: scipy's Hungarian method)
_MAX_ASSIGNMENTS = 200_000


def _best_assignment(score: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(rows, cols) giving each column of ``score`` (n, k), k <= n, its own row with the largest
    total score; rows ascending, as :func:`scipy.optimize.linear_sum_assignment` of ``-score``.

    Every assignment is tried (at most 5 labels over the few modes of a carriage, about 100 to
    7000 of them): the same optimum as the Hungarian method, without the 0.2 s import of
    :mod:`scipy.optimize` that identify would otherwise pay for it (the first of its 0.2-1 s).
    """
    import itertools
    import math

    n, k = score.shape
    if math.perm(n, k) > _MAX_ASSIGNMENTS:
        from scipy.optimize import linear_sum_assignment

        return linear_sum_assignment(-score)
    perms = np.array(list(itertools.permutations(range(n), k)), dtype=int).reshape(-1, k)
    totals = score[perms, np.arange(k)].sum(axis=1)
    best = perms[int(np.argmax(totals))]  # row of each column
    order = np.argsort(best)
    return best[order], np.arange(k)[order]


def _label_modes(energy: np.ndarray) -> tuple[str, ...]:
    """Assign vertical/pitch/yaw/roll_low/roll_high to the modes that carry each motion most.

    One mode per label (the assignment of largest total energy share,
    :func:`_best_assignment`); the two u-phi labels go in frequency order; any
    further modes are ``support_<n>``.
    """
    n = energy.shape[0]
    # columns: vertical, pitch, yaw, uphi, uphi
    score = np.column_stack([energy[:, 0], energy[:, 1], energy[:, 2], energy[:, 3], energy[:, 3]])
    n_lab = min(n, 5)
    rows, cols = _best_assignment(score[:, :n_lab])
    labels = [""] * n
    uphi_modes = sorted(r for r, c in zip(rows, cols) if c >= 3)
    for r, c in zip(rows, cols):
        if c < 3:
            labels[r] = MODE_LABELS[c]
    for name, r in zip(("roll_low", "roll_high"), uphi_modes):
        labels[r] = name
    extra = 0
    for i in range(n):
        if not labels[i]:
            extra += 1
            labels[i] = f"support_{extra}"
    return tuple(labels)


# --------------------------------------------------------------------------- frequency response


def point_maps(spec: ModelSpec, solution: ModalSolution, points_m) -> np.ndarray:
    """(n_points, 3, n_modes): translation of carriage points per unit modal coordinate."""
    return np.stack([rigid_body_map(p) @ solution.shapes[:5] for p in points_m])


def accelerance(solution: ModalSolution, spec: ModelSpec, frequency_hz, damping_ratios,
                force_point_m, force_direction, response_points_m, response_directions) -> np.ndarray:
    """Accelerance FRFs (m/s^2)/N by modal superposition with viscous modal damping.

    H_r(w) = -w^2 sum_k (a_rk b_k) / (w_k^2 - w^2 + 2 j zeta_k w_k w), with
    mass-normalised shapes, a_rk the response direction's modal displacement
    at point r and b_k the force direction's at the hit point.
    Returns (n_freq, n_responses) complex.
    """
    w = 2 * math.pi * np.asarray(frequency_hz, dtype=float)[:, None]
    wk = 2 * math.pi * solution.frequencies_hz[None, :]
    zeta = np.broadcast_to(np.asarray(damping_ratios, float), solution.frequencies_hz.shape)[None, :]
    b = np.asarray(force_direction, float) @ (rigid_body_map(force_point_m) @ solution.shapes[:5])
    out = []
    for p, d in zip(response_points_m, response_directions):
        a = np.asarray(d, float) @ (rigid_body_map(p) @ solution.shapes[:5])
        out.append((-(w**2) * (a * b)[None, :] / (wk**2 - w**2 + 2j * zeta * wk * w)).sum(axis=1))
    return np.column_stack(out)


# --------------------------------------------------------------------------- closed forms


def row_stiffness_sum(guide) -> float:
    """Z_L K_n: the stiffness of one row's rollers in parallel (N/m)."""
    return guide.rollers_per_row * guide.roller_stiffness_n_per_m * guide.effective_roller_fraction


def f_vertical_hz(guide) -> float:
    """Vertical natural frequency, Eq. (15): f_V = sqrt(4 Z K_n sin^2(b) / M) / 2 pi."""
    k_v = 4 * row_stiffness_sum(guide) * math.sin(guide.contact_angle_rad) ** 2
    return math.sqrt(k_v / guide.mass_kg) / (2 * math.pi)


def _sum_z2(guide) -> float:
    z = guide.roller_positions_z_m()
    return float(np.sum(z**2)) * guide.roller_stiffness_n_per_m * guide.effective_roller_fraction


def f_pitch_hz(guide) -> float:
    """Pitch frequency f_XP, Eq. (16): sqrt(4 sin^2(b) K_n sum l_i^2 / Jx) / 2 pi."""
    k = 4 * math.sin(guide.contact_angle_rad) ** 2 * _sum_z2(guide)
    return math.sqrt(k / guide.inertia_kg_m2[0]) / (2 * math.pi)


def f_yaw_hz(guide) -> float:
    """Yaw frequency f_YY, Eq. (13) and (17): sqrt(4 cos^2(b) K_n sum l_i^2 / Jy) / 2 pi."""
    k = 4 * math.cos(guide.contact_angle_rad) ** 2 * _sum_z2(guide)
    return math.sqrt(k / guide.inertia_kg_m2[1]) / (2 * math.pi)


def roll_pair_hz(guide) -> tuple[float, float]:
    """Coupled u-phi frequencies (f_RL, f_RH), Eq. (18)-(23).

    With K_uu = 4 Z K_n cos^2 b, K_uphi = 2 Z K_n cos^2 b (h1 + h3) and
    K_phiphi = 2 Z K_n [(h1 cos b - e sin b)^2 + (h3 cos b + e sin b)^2] (Eq. 10, 14
    for the arrangement of Eq. 9), the characteristic equation
    (K_uu - w^2 M)(K_phiphi - w^2 Jz) = K_uphi^2 gives
    w^2 = [a + d -/+ sqrt((a - d)^2 + 4 K_uphi^2 / (M Jz))] / 2, a = K_uu/M, d = K_phiphi/Jz.
    The centre of mass is at the origin (Eq. 8).
    """
    zk = row_stiffness_sum(guide)
    b = guide.contact_angle_rad
    c, s = math.cos(b), math.sin(b)
    e = guide.row_offset_m
    sign = -1.0 if guide.arrangement == "X" else 1.0
    h1, h3 = guide.h1_m, guide.h3_m
    k_uu = 4 * zk * c**2
    k_up = 2 * zk * c**2 * (h1 + h3) * sign
    k_pp = 2 * zk * ((sign * c * h1 - s * e) ** 2 + (sign * c * h3 + s * e) ** 2)
    a = k_uu / guide.mass_kg
    d = k_pp / guide.inertia_kg_m2[2]
    root = math.sqrt((a - d) ** 2 + 4 * k_up**2 / (guide.mass_kg * guide.inertia_kg_m2[2]))
    return (
        math.sqrt((a + d - root) / 2) / (2 * math.pi),
        math.sqrt((a + d + root) / 2) / (2 * math.pi),
    )


def closed_form_frequencies_hz(guide) -> dict[str, float]:
    """All five closed-form frequencies, Eq. (15)-(23), keyed by mode label."""
    low, high = roll_pair_hz(guide)
    return {
        "vertical": f_vertical_hz(guide),
        "pitch": f_pitch_hz(guide),
        "yaw": f_yaw_hz(guide),
        "roll_low": low,
        "roll_high": high,
    }
