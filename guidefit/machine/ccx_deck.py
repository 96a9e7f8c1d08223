r"""A CalculiX deck that ``*INCLUDE``\ s guidefit joints: find the joints, scale them, run ``ccx``.

Used by ``guidefit update`` (:mod:`guidefit.machine.update`).

Finding the joints
------------------
The deck and the files it ``*INCLUDE``\ s (``*INCLUDE, INPUT=name``, any
depth; relative names are relative to the deck's folder, where one runs
``ccx``) are read. A file is a guidefit joint when its first line is the
header ``guidefit export --format calculix`` writes
(``** guidefit <version> joint export; element <kind>``) and it carries
the include's note (``CalculiX: rotations are the translations of each
node's rotation node (node + N; ...``). From the header come the element
kind, the unit system and the axis map; from each ``** carriage N`` block the
stiffness terms. Joints are numbered ``joint1``, ``joint2``, ... over the
carriages of all joint files, in the order the deck includes them.

Scaling a joint along a direction
---------------------------------
A factor f_d per model direction d (x lateral, y vertical, z along the
rail, rx pitch, ry yaw, rz roll) scales the joint as K' = D K D with
D = diag(sqrt f_d): the diagonal entry K_dd by f_d, a coupling K_de by
sqrt(f_d f_e); K' stays positive semi-definite and its couplings keep
their correlation. In the machine frame D is diagonal too (an axis map
permutes axes and flips signs). In the file that is, per stiffness term:

* ``SPRING2`` (``bush``, ``springs``) on DOF d: k' = f_d k.
* ``SPRING1`` with its ``*EQUATION`` aux = v . (q_carriage - q_rail)
  (``matrix``): the term lambda v v^T becomes lambda (Dv)(Dv)^T, written as
  lambda' = lambda |Dv|^2 on the unit vector Dv / |Dv| (the equation's
  coefficients).

Nothing else changes (ids, nodes, damping), so the updated file is again a
guidefit joint and can be updated again.

Running ccx
-----------
Each run is staged in its own folder: the deck as ``job.inp``, the joint
files rendered with their factors, included files that include others
rewritten to the staged names, the others linked. ``ccx -i job`` runs there
(one thread); its ``.dat`` is read by :func:`guidefit.io.fe_results.read_ccx_dat`.
ccx 2.20 exits 0 after some errors: its output is searched for ``ERROR``.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from guidefit.errors import GuidefitError

#: model directions a factor can scale, in the joint's DOF order
DIRECTIONS = ("x", "y", "z", "rx", "ry", "rz")
MAX_INCLUDE_DEPTH = 16
_HEADER = re.compile(r"^\*\* guidefit (\S+) joint export; element (matrix|bush|springs)\s*$")
_INCLUDE = re.compile(r"^\s*\*include\s*,\s*input\s*=\s*(.+?)\s*$", re.IGNORECASE)
_UNITS = re.compile(r"\bunits (SI|mm-N-s|mm-t-s):")
_MAP = re.compile(r"\bmap (x=\S+?,y=\S+?,z=\S+?)(?:\s|$)")
_ROT = re.compile(r"rotation node \(node \+ (\d+);")
_CARRIAGE = re.compile(r"^\*\* carriage (\d+)\s*$")
_SOURCE = re.compile(r"^\*\* carriage (\d+): (.*)$")
UNITS = {"SI": "si", "mm-N-s": "mm-N-s", "mm-t-s": "mm-t-s"}


class DeckError(GuidefitError, ValueError):
    """A deck, joint file or solver run ``update`` cannot use (exit 2, one line)."""


@dataclass
class Term:
    """One stiffness term of a joint file: its value line and, for ``SPRING1``, its equation."""

    value_line: int
    value: float
    dofs: dict  # machine DOF index (0-5) -> v_d (unit vector components; SPRING2: {d: 1.0})
    equation: tuple | None = None  # (first line, last line + 1, [(node, dof, coefficient)], {(node, dof): d})


@dataclass
class JointFile:
    """A guidefit CalculiX joint include: its lines, header facts and stiffness terms per carriage."""

    path: Path
    lines: list
    element: str
    units: str
    axis_map: str
    rot_offset: int
    carriages: list  # [[Term, ...], ...]
    sources: list  # per carriage: the header's "carriage N: <source>" text
    machine_of_model: np.ndarray = field(default=None)  # (6,) machine DOF of each model DOF

    def stiffness(self, j: int) -> np.ndarray:
        """Carriage j's 6x6 stiffness in the file's (machine) axes and units: sum of k v v^T."""
        k = np.zeros((6, 6))
        for t in self.carriages[j]:
            v = np.zeros(6)
            for d, c in t.dofs.items():
                v[d] = c
            k += t.value * np.outer(v, v)
        return k

    def model_diagonal(self, j: int) -> np.ndarray:
        """Carriage j's stiffness diagonal in the model directions (x, y, z, rx, ry, rz)."""
        return np.diag(self.stiffness(j))[self.machine_of_model]


def _header_text(lines: list) -> str:
    out = []
    for line in lines:
        if not line.startswith("**"):
            break
        out.append(line[2:].strip())
    return " ".join(out)


def _machine_of_model(axis_map: str, where: str) -> np.ndarray:
    from guidefit.io.axes import parse_axis_map

    rot = parse_axis_map(axis_map, error=DeckError)
    idx = [int(np.argmax(np.abs(rot[:, j]))) for j in range(3)]  # machine axis of model axis j
    return np.array(idx + [i + 3 for i in idx])


def is_joint_file(lines: list) -> bool:
    """The first line is guidefit's joint-export header (:func:`parse_joint_file` checks the rest)."""
    return bool(lines) and bool(_HEADER.match(lines[0]))


def _cells(lines: list, start: int, count: int) -> tuple[list, int]:
    """``count`` (node, dof, coefficient) triples of an ``*EQUATION`` from line ``start``; (terms, end)."""
    cells, k = [], start
    while len(cells) < 3 * count:
        if k >= len(lines):
            raise IndexError
        cells += [c.strip() for c in lines[k].split(",") if c.strip()]
        k += 1
    return [(int(cells[a]), int(cells[a + 1]), float(cells[a + 2])) for a in range(0, 3 * count, 3)], k


def _terms_of_block(lines: list, first: int, last: int) -> tuple[list, list]:
    """Raw stiffness terms of lines[first:last]: ('s1', aux, value line) and ('s2', nodes, dofs, value line);
    and the equations {aux: (start, end, terms)}."""
    raw, eqs = [], {}
    i = first
    while i < last:
        line = lines[i].strip().upper()
        if line.startswith("*SPRING,"):
            kind_line = lines[i - 2] if i >= 2 else ""
            elem = lines[i - 1].split(",")
            if "SPRING2" in kind_line.upper():
                na, nb = int(elem[1]), int(elem[2])
                da, db = (int(v) for v in lines[i + 1].split(",")[:2])
                raw.append(("s2", (na, nb), (da, db), i + 2))
            elif "SPRING1" in kind_line.upper():
                raw.append(("s1", int(elem[0]), i + 2))
            i += 3
            continue
        if line == "*EQUATION":
            n = int(lines[i + 1])
            terms, end = _cells(lines, i + 2, n)
            eqs[terms[0][0]] = (i + 2, end, terms)
            i = end
            continue
        i += 1
    return raw, eqs


def _build_terms(raw: list, eqs: dict, rot_offset: int, where: str) -> list:
    """Terms with their machine DOFs: a node is a rotation node when node - offset is one of the carriage's."""
    nodes = set()
    for r in raw:
        if r[0] == "s2":
            nodes.update(r[1])
        else:
            nodes.update(n for n, _, _ in eqs[r[1]][2][1:])

    def dof(node: int, d: int) -> int:
        return d - 1 + (3 if node - rot_offset in nodes else 0)

    out = []
    for r in raw:
        if r[0] == "s2":
            (na, _), (da, _), at = r[1], r[2], r[3]
            out.append(Term(at, 0.0, {dof(na, da): 1.0}))
        else:
            aux, at = r[1], r[2]
            if aux not in eqs:
                raise DeckError(f"{where}: SPRING1 term {aux} has no *EQUATION (not as guidefit writes it)")
            start, end, terms = eqs[aux]
            mapping = {(n, d): dof(n, d) for n, d, _ in terms[1:]}
            v = {}
            for n, d, c in terms[1:]:
                v.setdefault(mapping[(n, d)], abs(c))
            out.append(Term(at, 0.0, v, (start, end, terms, mapping)))
    return out


def parse_joint_file(path: Path, lines: list) -> JointFile:
    """A :class:`JointFile` of a guidefit include (see the module docstring); DeckError when malformed."""
    where = str(path)
    head = _header_text(lines)
    element = _HEADER.match(lines[0]).group(2)
    units_m, map_m, rot_m = _UNITS.search(head), _MAP.search(head), _ROT.search(head)
    if "guidefit reference assembly" in head:
        raise DeckError(f"{where}: a guidefit reference assembly (a complete deck), not a joint to *INCLUDE; "
                        "export the joint without --assembly reference")
    if units_m is None or map_m is None or rot_m is None:
        raise DeckError(f"{where}: guidefit joint header without its units or axis map (edited?)")
    starts = [(i, int(m.group(1))) for i, line in enumerate(lines) if (m := _CARRIAGE.match(line))]
    if not starts:
        raise DeckError(f"{where}: guidefit joint file without a '** carriage N' block")
    sources = {int(m.group(1)): m.group(2) for line in lines if (m := _SOURCE.match(line))}
    rot_offset = int(rot_m.group(1))
    carriages = []
    try:
        for k, (first, _) in enumerate(starts):
            last = starts[k + 1][0] if k + 1 < len(starts) else len(lines)
            raw, eqs = _terms_of_block(lines, first, last)
            terms = _build_terms(raw, eqs, rot_offset, where)
            for t in terms:
                t.value = float(lines[t.value_line].strip().rstrip(","))
            if not terms:
                raise DeckError(f"{where}: carriage {k + 1} has no stiffness term")
            carriages.append(terms)
    except (ValueError, IndexError):
        raise DeckError(f"{where}: a joint card is not as guidefit writes it (edited by hand?)") from None
    jf = JointFile(path, lines, element, UNITS[units_m.group(1)], map_m.group(1), rot_offset, carriages,
                   [sources.get(n, "") for _, n in starts])
    jf.machine_of_model = _machine_of_model(jf.axis_map, where)
    return jf


def _fmt(x: float) -> str:
    from guidefit.export.calculix import _ccx

    return _ccx(x)


def render_joint_file(jf: JointFile, factors: np.ndarray, header: list | None = None) -> str:
    """The joint file with carriage j scaled by model-direction factors ``factors[j]`` (K' = D K D)."""
    lines = list(jf.lines)
    for j, terms in enumerate(jf.carriages):
        f_machine = np.ones(6)
        f_machine[jf.machine_of_model] = np.asarray(factors[j], float)
        for t in terms:
            norm0 = sum(c * c for c in t.dofs.values())
            norm = sum(c * c * f_machine[d] for d, c in t.dofs.items())
            lines[t.value_line] = _fmt(t.value * norm / norm0)
            if t.equation is not None:
                start, end, eq_terms, mapping = t.equation
                scale = np.sqrt(norm / norm0)
                cells = [f"{eq_terms[0][0]},{eq_terms[0][1]},{_fmt(eq_terms[0][2])}"]
                cells += [f"{n},{d},{_fmt(c * np.sqrt(f_machine[mapping[(n, d)]]) / scale)}"
                          for n, d, c in eq_terms[1:]]
                new = [",".join(cells[a:a + 3]) for a in range(0, len(cells), 3)]
                if len(new) != end - start:  # pragma: no cover - guidefit writes three terms a line
                    raise DeckError(f"{jf.path}: *EQUATION layout not as guidefit writes it")
                lines[start:end] = new
    if header:
        at = next(i for i, line in enumerate(lines) if _CARRIAGE.match(line))
        lines[at:at] = header
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------- the deck


@dataclass
class Deck:
    """The deck, what it includes (in order), and the joint files and joints among them."""

    path: Path
    files: dict  # resolved path -> lines (every text file read)
    includes: dict  # resolved path -> [(line index, resolved target)]
    joint_files: list  # [JointFile] in include order
    joints: list  # [(JointFile index, carriage index)] = joint1, joint2, ...

    @property
    def units(self) -> str:
        return self.joint_files[0].units


def _read_lines(path: Path, where: str) -> list:
    try:
        return path.read_text(encoding="latin-1").splitlines()
    except OSError as exc:
        raise DeckError(f"{where}: cannot read: {exc.strerror or exc}") from None


def load_deck(path) -> Deck:
    """Read the deck and its includes; refuse one that includes no guidefit joint (DeckError)."""
    top = Path(path)
    base = top.resolve().parent
    files, includes, order = {}, {}, []

    def visit(p: Path, depth: int, chain: tuple) -> None:
        key = p.resolve()
        if key in chain:
            raise DeckError(f"{top}: {p} includes itself (an *INCLUDE cycle)")
        if depth > MAX_INCLUDE_DEPTH:
            raise DeckError(f"{top}: *INCLUDE nested deeper than {MAX_INCLUDE_DEPTH}")
        if key in files:
            return
        lines = _read_lines(p, str(p))
        files[key] = lines
        order.append(key)
        if is_joint_file(lines):
            includes[key] = []
            return
        found = []
        for i, line in enumerate(lines):
            m = _INCLUDE.match(line)
            if m:
                name = m.group(1).strip().strip("\"'")
                target = Path(name) if os.path.isabs(name) else base / name
                if not target.is_file():
                    raise DeckError(f"{p}:{i + 1}: *INCLUDE '{name}' not found (relative to {base})")
                found.append((i, target.resolve()))
        includes[key] = found
        for _, target in found:
            visit(target, depth + 1, (*chain, key))

    visit(top, 0, ())
    joint_files = [parse_joint_file(k, files[k]) for k in order if k != top.resolve() and is_joint_file(files[k])]
    if is_joint_file(files[top.resolve()]):
        raise DeckError(f"{top}: is a guidefit joint file itself; give the machine deck that *INCLUDEs it")
    if not joint_files:
        raise DeckError(f"{top}: includes no joint written by guidefit export --format calculix (no *INCLUDE "
                        "of a file starting '** guidefit ... joint export'); nothing to update")
    if not any(re.match(r"^\s*\*frequency\b", line, re.IGNORECASE) for lines in files.values() for line in lines):
        raise DeckError(f"{top}: no *FREQUENCY step; update compares natural frequencies")
    units = {jf.units for jf in joint_files}
    if len(units) > 1:
        names = ", ".join(f"{jf.path.name} ({jf.units})" for jf in joint_files)
        raise DeckError(f"{top}: its guidefit joints are in different units ({names}); export them in one system")
    joints = [(k, j) for k, jf in enumerate(joint_files) for j in range(len(jf.carriages))]
    return Deck(top, files, includes, joint_files, joints)


def stage(deck: Deck, folder: Path, factors: list) -> Path:
    """Write the deck into ``folder`` with joint file k scaled by ``factors[k]`` ((n_carriages, 6)); job.inp."""
    names, joint_index = {}, {jf.path: k for k, jf in enumerate(deck.joint_files)}
    top = deck.path.resolve()
    for n, key in enumerate(deck.files):
        names[key] = "job.inp" if key == top else f"gf{n}.inp"
    for key, lines in deck.files.items():
        target = folder / names[key]
        if key in joint_index:
            k = joint_index[key]
            target.write_text(render_joint_file(deck.joint_files[k], factors[k]), encoding="latin-1")
        elif deck.includes.get(key) or key == top:
            out = list(lines)
            for i, inc in deck.includes.get(key, []):
                out[i] = f"*INCLUDE,INPUT={names[inc]}"
            target.write_text("\n".join(out) + "\n", encoding="latin-1")
        else:
            os.symlink(key, target)
    return folder / "job.inp"


def find_ccx(ccx: str | None = None) -> str:
    """The ccx program: ``ccx`` (a path or a name on PATH); DeckError when absent."""
    name = ccx or os.environ.get("GUIDEFIT_CCX") or "ccx"
    found = shutil.which(name)
    if found is None:
        raise DeckError(f"CalculiX '{name}' not found (install calculix-ccx, e.g. apt-get install calculix-ccx, "
                        "or give --ccx PATH)")
    return found


def run_ccx(ccx: str, folder: Path, timeout_s: float = 600.0):
    """Run ``ccx -i job`` in ``folder``; (FEModes of job.dat, seconds). DeckError on a failed run."""
    from guidefit.io.fe_results import FEResultError, read_ccx_dat

    env = dict(os.environ, OMP_NUM_THREADS="1", CCX_NPROC_STIFFNESS="1", CCX_NPROC_EQUATION_SOLVER="1")
    t0 = time.perf_counter()
    try:
        run = subprocess.run([ccx, "-i", "job"], cwd=folder, capture_output=True, text=True, errors="replace",
                             timeout=timeout_s, env=env, check=False)
    except subprocess.TimeoutExpired:
        raise DeckError(f"ccx did not finish within {timeout_s:g} s") from None
    except OSError as exc:
        raise DeckError(f"cannot run ccx ({ccx}): {exc.strerror or exc}") from None
    seconds = time.perf_counter() - t0
    text = run.stdout + "\n" + run.stderr
    bad = [line.strip() for line in text.splitlines() if "ERROR" in line.upper() or "singular" in line]
    if run.returncode != 0 or bad:
        said = bad[0] if bad else f"exit status {run.returncode}"
        raise DeckError(f"ccx failed on the deck: {' '.join(said.split())[:160]}")
    try:
        return read_ccx_dat(folder / "job.dat"), seconds
    except FEResultError as exc:
        raise DeckError(f"ccx ran but gave no frequencies ({exc})") from None
