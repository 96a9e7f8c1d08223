"""Geometry of a UFF file: node coordinates and the nodes' displacement coordinate systems.

A UFF file may give its nodes' coordinates (dataset 15 or 2411) and define
coordinate systems (dataset 18 or 2420). Each node names two of them: the
*definition* system its coordinates are written in, and the *displacement*
system its response directions (``+X`` = code 1, ...) are measured in.
Simcenter Testlab writes every measuring point with a displacement system of
its own, turned to the sensor's mounting face, so a dataset 58's ``+Y`` at
such a node is that system's y axis, not the global one.

:func:`read_geometry` collects them and :meth:`UffGeometry.global_code` turns a
node's direction code into a global one; the UFF readers
(:mod:`guidefit.io.uff`, :mod:`guidefit.io.uff_frf`) use them for every
response and reference DOF, and the node coordinates for the sensor
positions and the hit point (the reference node's coordinates).

Conventions (those of I-DEAS, which defines the datasets; SDynPy reads them
alike):

* dataset 2420: per system a 4x3 matrix; rows 1-3 are the system's x, y, z
  axes in the global frame, row 4 its origin: ``global = M[:3].T @ local + M[3]``;
* dataset 18: per system its origin, a point on its +x axis and a point in its
  +xz plane (on the +z side), written in its reference system (``ref_cs_num``,
  0 the global frame); x = the direction to the x point, y = (xz point -
  origin) cross x, z = x cross y;
* a system number that no dataset defines is the global frame when it is 0 or
  1 (the global and the default part system of I-DEAS files); any other is an
  error.

Refused, one line each: a cylindrical or spherical system (type 1 or 2) that
a node uses, a 2420 matrix whose axes are not orthonormal (within
:data:`ORTHONORMAL_TOLERANCE`), a dataset 18 system whose points do not span
a plane, a reference chain that loops, and a response or reference direction
that, turned into the global frame, is not along X, Y or Z (within
:data:`DIRECTION_TOLERANCE`): guidefit's sensors lie along the
carriage axes.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from guidefit.errors import RecordingError

__all__ = ["ORTHONORMAL_TOLERANCE", "UffGeometry", "read_geometry"]

DIRECTION_TOLERANCE = 1e-3
"""A direction is along axis k when its k-component is within this of +-1."""

_DIRECTION_LABELS = {1: "X", 2: "Y", 3: "Z"}


def _direction_label(code: int) -> str:
    if abs(code) in _DIRECTION_LABELS:
        return ("+" if code > 0 else "-") + _DIRECTION_LABELS[abs(code)]
    return str(code)


ORTHONORMAL_TOLERANCE = 1e-4
"""Largest |R R^T - I| entry of a dataset 2420 rotation (its values have 16 digits)."""
GLOBAL_SYSTEMS = (0, 1)
"""System numbers that are the global frame when no dataset defines them."""
_MAX_CHAIN = 32
_TYPES = {0: "Cartesian", 1: "cylindrical", 2: "spherical"}


@dataclass(frozen=True)
class _System:
    label: int
    kind: int
    matrix: np.ndarray  # (4, 3): rows x, y, z axes and origin, in the reference system
    reference: int  # 0: global
    where: str


@dataclass(frozen=True)
class UffGeometry:
    """Node coordinates (global frame, m) and each node's displacement frame.

    ``frames[node]`` is (3, 3), row k the node's local axis k in the global
    frame; a node without an entry measures along the global axes.
    """

    nodes: dict = field(default_factory=dict)
    frames: dict = field(default_factory=dict)
    display: str = ""
    axis_map: np.ndarray | None = None  # an input axis map (guidefit.io.axes): file = R @ guidefit

    @property
    def rotated(self) -> bool:
        """Whether any node's displacement frame is not the global one."""
        return any(not np.allclose(r, np.eye(3)) for r in self.frames.values())

    def global_code(self, node: int, code: int, where: str) -> int:
        """The global direction code (+-1, +-2, +-3) of ``code`` at ``node``; 0 and rotations unchanged.

        Raises
        ------
        RecordingError
            The direction, turned into the global frame, is not along X, Y or Z.
        """
        from guidefit.io.axes import turn_code

        frame = self.frames.get(int(node))
        if frame is None or abs(int(code)) not in (1, 2, 3):
            return turn_code(code, self.axis_map)
        vec = np.sign(code) * frame[abs(int(code)) - 1]
        k = int(np.argmax(np.abs(vec)))
        if abs(vec[k]) < 1.0 - DIRECTION_TOLERANCE:
            shown = ", ".join(f"{v:.4g}" for v in vec)
            raise RecordingError(
                f"{where}: node {node} direction {_direction_label(code)} of its displacement coordinate "
                f"system is ({shown}) in the global frame, not along X, Y or Z; guidefit reads sensors and "
                "hammers along the carriage axes"
            )
        return turn_code((k + 1) if vec[k] > 0 else -(k + 1), self.axis_map)


def _orthonormal(rows: np.ndarray) -> bool:
    return bool(np.all(np.isfinite(rows)) and np.abs(rows @ rows.T - np.eye(3)).max() <= ORTHONORMAL_TOLERANCE)


def _systems_2420(dset: dict, where: str) -> list[_System]:
    labels = list(dset.get("CS_sys_labels", []))
    kinds = list(dset.get("CS_types", [0] * len(labels)))
    mats = list(dset.get("CS_matrices", []))
    if not (len(labels) == len(kinds) == len(mats)):
        raise RecordingError(f"{where}: {len(labels)} coordinate systems but {len(mats)} matrices")
    out = []
    for label, kind, m in zip(labels, kinds, mats):
        m = np.asarray(m, dtype=float)
        if m.shape != (4, 3):
            raise RecordingError(f"{where}: coordinate system {label}: matrix of shape {m.shape}; expected 4x3")
        out.append(_System(int(label), int(kind), m, 0, where))
    return out


def _systems_18(dset: dict, where: str) -> list[_System]:
    labels = np.asarray(dset.get("cs_num", []), dtype=float).reshape(-1)
    n = labels.size
    kinds = np.asarray(dset.get("cs_type", np.zeros(n)), dtype=float).reshape(-1)
    refs = np.asarray(dset.get("ref_cs_num", np.zeros(n)), dtype=float).reshape(-1)
    pts = [np.asarray(dset.get(k, np.zeros((n, 3))), dtype=float).reshape(-1, 3) for k in ("ref_o", "x_point", "xz_point")]
    if not (kinds.size == refs.size == n and all(p.shape[0] == n for p in pts)):
        raise RecordingError(f"{where}: coordinate system records of unequal length")
    out = []
    for i in range(n):
        origin, xp, xzp = (p[i] for p in pts)
        x, xz = xp - origin, xzp - origin
        y = np.cross(xz, x)  # the normal of the xz plane, on the side that puts the xz point at +z
        if not (np.linalg.norm(x) > 0 and np.linalg.norm(y) > 1e-9 * np.linalg.norm(x) * np.linalg.norm(xz)):
            raise RecordingError(f"{where}: coordinate system {int(labels[i])}: its origin, +x point and +xz point "
                                 "do not span a plane")
        x, y = x / np.linalg.norm(x), y / np.linalg.norm(y)
        m = np.vstack([x, y, np.cross(x, y), origin])
        out.append(_System(int(labels[i]), int(kinds[i]), m, int(refs[i]), where))
    return out


def _resolve(systems: dict, label: int, display: str, what: str) -> np.ndarray | None:
    """The (4, 3) global matrix of system ``label``; None for the global frame."""
    chain = []
    rows = None
    while True:
        if label in chain or len(chain) > _MAX_CHAIN:
            raise RecordingError(f"{display}: coordinate systems {', '.join(map(str, chain))}: their reference "
                                 "systems loop")
        system = systems.get(label)
        if system is None:
            if label in GLOBAL_SYSTEMS:
                return rows
            raise RecordingError(f"{display}: {what} uses coordinate system {label}, which no dataset 18 or 2420 "
                                 "in the file defines")
        chain.append(label)
        if system.kind != 0:
            raise RecordingError(f"{system.where}: coordinate system {label} is {_TYPES.get(system.kind, 'of type')} "
                                 f"({system.kind}); guidefit reads Cartesian systems (type 0)")
        if not _orthonormal(system.matrix[:3]):
            raise RecordingError(f"{system.where}: coordinate system {label}: its axes are not orthonormal "
                                 f"(tolerance {ORTHONORMAL_TOLERANCE:g})")
        m = system.matrix
        # rows = the previous (inner) system expressed in this system; carry it out one level
        rows = m.copy() if rows is None else np.vstack([rows[:3] @ m[:3], rows[3] @ m[:3] + m[3]])
        if system.reference == 0 or system.reference == label:
            return rows
        label = system.reference


def read_geometry(uff, kinds: list[int], display: str, read_set) -> UffGeometry:
    """Nodes (datasets 15, 2411) and coordinate systems (18, 2420) of an open UFF file.

    Parameters
    ----------
    uff : pyuff.UFF
    kinds : list of int
        The file's dataset types, in order.
    display : str
        The file name for messages.
    read_set : callable (uff, i, kind, display) -> dict
        Reads the 1-based set ``i`` (:func:`guidefit.io.uff._read_set`).

    Returns
    -------
    UffGeometry

    Raises
    ------
    RecordingError
        A node uses a coordinate system that is undefined, not Cartesian, not
        orthonormal, or whose references loop (one line naming the file and set).
    """
    systems: dict[int, _System] = {}
    raw_nodes: dict[int, tuple] = {}
    for i, kind in enumerate(kinds, start=1):
        if kind not in (15, 18, 2411, 2420):
            continue
        dset = read_set(uff, i, kind, display)
        where = f"{display}: set {i} (dataset {kind})"
        if kind in (18, 2420):
            for s in (_systems_18 if kind == 18 else _systems_2420)(dset, where):
                systems[s.label] = s
            continue
        nums = np.asarray(dset.get("node_nums", []), dtype=float).reshape(-1)
        cols = [np.asarray(dset.get(k, np.zeros(nums.size)), dtype=float).reshape(-1)
                for k in ("def_cs", "disp_cs", "x", "y", "z")]
        if not all(c.size == nums.size for c in cols):
            raise RecordingError(f"{where}: node records of unequal length")
        for n, dcs, pcs, x, y, z in zip(nums, *cols):
            if np.all(np.isfinite([x, y, z])):
                raw_nodes[int(n)] = (int(dcs), int(pcs), np.array([x, y, z]))
    from guidefit.io.axes import active

    rot = active()  # an input axis map: the file's global frame into guidefit's
    nodes, frames = {}, {}
    for n, (dcs, pcs, xyz) in raw_nodes.items():
        m = _resolve(systems, dcs, display, f"node {n} (its coordinates)")
        nodes[n] = xyz if m is None else m[:3].T @ xyz + m[3]
        if rot is not None:
            nodes[n] = rot.T @ nodes[n]
        m = _resolve(systems, pcs, display, f"node {n} (its displacement directions)")
        if m is not None:
            frames[n] = m[:3].copy()
    return UffGeometry(nodes, frames, display, rot)
