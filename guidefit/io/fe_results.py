"""Natural frequencies (and mode shapes) from FE solvers' result files, for ``guidefit correlate``.

Readers
-------
``.dat``  CalculiX: the ``E I G E N V A L U E   O U T P U T`` table of a
          ``*FREQUENCY`` step (mode number, eigenvalue, rad/time, cycles/time);
          shapes where ``*NODE PRINT ... U`` printed them for the modes
          (``displacements (vx,vy,vz) for set ... and time`` blocks, one per
          mode in mode order); the complex response of a ``*STEADY STATE
          DYNAMICS`` step (a real and an imaginary block per frequency).
``.frd``  CalculiX: the ``DISP`` blocks of each mode (their ``1PSTEP``/``100CL``
          headers carry the frequency); shapes at every node.
``.f06``  Nastran: the ``R E A L   E I G E N V A L U E S`` table (cycles column).
``.op2``  Nastran, through pyNastran when it is installed.
``.csv``  ``mode,frequency_hz`` and optional shape columns ``<point>:<x|y|z>``.

Every reader returns an :class:`FEModes`; a file that holds none of it is an
:class:`FEResultError` (one line, exit 2).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from guidefit.errors import GuidefitError


class FEResultError(GuidefitError, ValueError):
    """An FE result file without the frequencies it should hold, or unreadable (exit 2)."""


@dataclass
class FEModes:
    """Natural frequencies and, where known, shapes: ``shapes[point] = (n_modes, 3)`` translations."""

    frequencies_hz: np.ndarray
    shapes: dict = field(default_factory=dict)
    source: str = ""
    labels: tuple = ()

    def __len__(self) -> int:
        return int(self.frequencies_hz.size)


_EIGEN = "E I G E N V A L U E   O U T P U T"
_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[EeDd][-+]?\d+)?"


def _text(path) -> str:
    try:
        return Path(path).read_text(encoding="latin-1")
    except OSError as exc:
        raise FEResultError(f"{path}: cannot read: {exc.strerror or exc}") from None


def ccx_eigen_table(text: str, where: str = "ccx .dat") -> np.ndarray:
    """Frequencies (Hz) of the first ``E I G E N V A L U E   O U T P U T`` table of a ccx ``.dat``."""
    at = text.find(_EIGEN)
    if at < 0:
        raise FEResultError(f"{where}: no '{_EIGEN}' table (not a *FREQUENCY step's .dat)")
    freqs = []
    for line in text[at + len(_EIGEN):].splitlines()[1:]:
        parts = line.split()
        if not parts:
            if freqs:
                break
            continue
        if parts[0].isdigit() and len(parts) >= 4:
            freqs.append(float(parts[3]))
        elif freqs or parts[0] in ("P", "E"):
            break
    if not freqs:
        raise FEResultError(f"{where}: the eigenvalue table is empty (did ccx fail? see its output)")
    return np.array(freqs)


def _blocks(text: str) -> list[tuple[float, dict]]:
    """(time, {node: (3,) values}) of each ``displacements (vx,vy,vz)`` block of a ccx ``.dat``."""
    out = []
    pattern = re.compile(r"displacements \(vx,vy,vz\) for set \S+ and time\s+(" + _NUMBER + r")")
    for m in pattern.finditer(text):
        values = {}
        for line in text[m.end():].splitlines()[1:]:
            parts = line.split()
            if not parts:
                if values:
                    break
                continue
            if not parts[0].isdigit() or len(parts) < 4:
                break
            values[int(parts[0])] = np.array([float(v) for v in parts[1:4]])
        out.append((float(m.group(1)), values))
    return out


def ccx_steady_state(text: str) -> list[tuple[float, dict]]:
    """(frequency Hz, {node: complex (3,)}) of a ccx ``*STEADY STATE DYNAMICS`` ``.dat`` (real, then imaginary block)."""
    blocks = _blocks(text[text.find("P A R T I C I P A T I O N   F A C T O R S   F O R"):]) \
        if "F O R   F R E Q U E N C Y" in text else []
    out = []
    for (f_re, re_part), (_, im_part) in zip(blocks[0::2], blocks[1::2]):
        out.append((f_re, {n: re_part[n] + 1j * im_part.get(n, 0.0) for n in re_part}))
    return out


def read_ccx_dat(path) -> FEModes:
    """A ccx ``.dat``: the frequencies; shapes where ``*NODE PRINT`` printed one block per mode."""
    text = _text(path)
    freqs = ccx_eigen_table(text, str(path))
    head = text[:text.find("F O R   F R E Q U E N C Y")] if "F O R   F R E Q U E N C Y" in text else text
    blocks = _blocks(head)
    shapes = {}
    if len(blocks) >= freqs.size:
        nodes = sorted(set.intersection(*(set(b) for _, b in blocks[:freqs.size])))
        for node in nodes:
            shapes[str(node)] = np.vstack([b[node] for _, b in blocks[:freqs.size]])
    return FEModes(freqs, shapes, str(path))


def _frd_blocks(lines: list[str], where: str) -> list[tuple[int, float, dict]]:
    """(step, frequency Hz, {node: (3,) D1-D3}) of each ``DISP`` block of a ``*FREQUENCY`` step (ictype 2)."""
    out, step, k = [], 0, 0
    while k < len(lines):
        line = lines[k]
        if line.startswith("    1PSTEP"):
            fields = line[10:].split()
            step = int(fields[2]) if len(fields) >= 3 and fields[2].isdigit() else step
        elif line.startswith("  100C") and k + 1 < len(lines):
            head = lines[k + 1].split()
            try:
                value, ictype, fmt = float(line[12:24]), int(line[56:58]), int(line[73:75] or 0)
            except ValueError:
                raise FEResultError(f"{where}:{k + 1}: not a CalculiX .frd result header: '{line.strip()[:60]}'") \
                    from None
            if ictype == 2 and head[:2] == ["-4", "DISP"]:
                if fmt not in (0, 1):
                    raise FEResultError(f"{where}: a binary .frd (format {fmt}); write it in ASCII (the default)")
                width = 5 if fmt == 0 else 10
                values, k = {}, k + 2
                while k < len(lines) and not lines[k].startswith(" -3"):
                    row = lines[k]
                    if row.startswith(" -1"):
                        try:
                            node = int(row[3:3 + width])
                            values[node] = np.array([float(row[3 + width + 12 * i:3 + width + 12 * (i + 1)])
                                                     for i in range(3)])
                        except ValueError:
                            raise FEResultError(f"{where}:{k + 1}: not a DISP record: '{row.strip()[:60]}'") \
                                from None
                    k += 1
                out.append((step, value, values))
        k += 1
    return out


def read_ccx_frd(path) -> FEModes:
    """A ccx ``.frd`` (ASCII): frequencies and shapes from the ``DISP`` blocks of the first ``*FREQUENCY`` step.

    Each mode's block starts with a ``1PSTEP`` record (its third field is the
    step) and a ``100CL`` header whose value is the frequency (cycles/time)
    and whose ``ictype`` 2 marks a frequency step; its ``-1`` records hold
    the node id and D1, D2, D3 in fixed columns (``I5`` or ``I10``, then
    ``E12.5``: neighbouring numbers may touch, so no whitespace split).
    Beam and shell models need ``*NODE FILE,OUTPUT=2D`` for the results to be
    at the model's own nodes rather than at ccx's expanded ones.
    """
    where = str(path)
    blocks = _frd_blocks(_text(path).splitlines(), where)
    if not blocks:
        raise FEResultError(f"{where}: no mode shapes (no DISP block of a *FREQUENCY step: add *NODE FILE with U "
                            "to the step, or give the .dat)")
    first = blocks[0][0]
    blocks = [b for b in blocks if b[0] == first]
    freqs = np.array([f for _, f, _ in blocks])
    if not np.all(np.isfinite(freqs)):
        raise FEResultError(f"{where}: a mode's frequency is not a number")
    nodes = sorted(set.intersection(*(set(b) for _, _, b in blocks)))
    shapes = {str(n): np.vstack([b[n] for _, _, b in blocks]) for n in nodes}
    return FEModes(freqs, shapes, where)


_F06 = "R E A L   E I G E N V A L U E S"


def read_f06(path) -> FEModes:
    """Nastran ``.f06``: the cycles column of each ``R E A L   E I G E N V A L U E S`` table (SOL 103)."""
    text = _text(path)
    freqs = []
    row = re.compile(r"^\s*\d+\s+\d+\s+(" + _NUMBER + r")\s+(" + _NUMBER + r")\s+(" + _NUMBER + r")")
    for m in re.finditer(re.escape(_F06), text):
        started = False
        for line in text[m.end():].splitlines()[1:]:
            hit = row.match(line)
            if hit:
                freqs.append(float(hit.group(3).replace("D", "E").replace("d", "e")))
                started = True
            elif started:
                break
    if not freqs:
        raise FEResultError(f"{path}: no '{_F06}' table (not a Nastran SOL 103 .f06)")
    return FEModes(np.array(freqs), {}, str(path))


def read_op2(path) -> FEModes:
    """Nastran ``.op2`` through pyNastran (optional: it pins numpy < 2), frequencies and grid shapes."""
    try:
        from pyNastran.op2.op2 import read_op2 as _read
    except Exception as exc:  # noqa: BLE001 - not installed, or an install that cannot import with this numpy
        raise FEResultError(f"{path}: reading .op2 needs pyNastran ({type(exc).__name__}); write an .f06 "
                            "(ECHO/PARAM,POST) or a CSV instead") from None
    try:
        op2 = _read(str(path), debug=None)
    except Exception as exc:  # noqa: BLE001 - pyNastran raises many types for a bad file
        raise FEResultError(f"{path}: pyNastran cannot read it: {str(exc).splitlines()[0] if str(exc) else exc}") \
            from None
    if not op2.eigenvectors:
        raise FEResultError(f"{path}: no real eigenvectors (not a SOL 103 .op2)")
    vec = next(iter(op2.eigenvectors.values()))
    freqs = np.sqrt(np.abs(np.asarray(vec.eigns, float))) / (2 * np.pi)
    shapes = {str(int(node)): np.asarray(vec.data[:, k, :3], float) for k, (node, _) in enumerate(vec.node_gridtype)}
    return FEModes(freqs, shapes, str(path))


def read_modes_csv(path, what: str = "FE") -> FEModes:
    """``frequency_hz`` (required), optional ``mode``/``label``, shape columns ``<point>:<x|y|z>``."""
    import pandas as pd

    try:
        frame = pd.read_csv(path, comment="#")
    except (OSError, ValueError) as exc:
        raise FEResultError(f"{path}: cannot read as CSV: {str(exc).splitlines()[0]}") from None
    cols = {c.strip().lower(): c for c in frame.columns}
    if "frequency_hz" not in cols:
        raise FEResultError(f"{path}: no 'frequency_hz' column ({what} modes CSV: frequency_hz[,label][,P:x,...])")
    try:
        freqs = frame[cols["frequency_hz"]].to_numpy(float)
    except (TypeError, ValueError):
        raise FEResultError(f"{path}: 'frequency_hz' holds text that is not a number") from None
    if freqs.size == 0 or not np.all(np.isfinite(freqs)) or np.any(freqs <= 0):
        raise FEResultError(f"{path}: every frequency_hz must be a positive number (and there must be one)")
    shapes: dict = {}
    for c in frame.columns:
        point, sep, axis = str(c).strip().rpartition(":")
        if sep and axis.lower() in ("x", "y", "z") and point:
            col = shapes.setdefault(point, np.zeros((freqs.size, 3)))
            try:
                col[:, "xyz".index(axis.lower())] = frame[c].to_numpy(float)
            except (TypeError, ValueError):
                raise FEResultError(f"{path}: shape column '{c}' holds text that is not a number") from None
    labels = tuple(str(v) for v in frame[cols["label"]]) if "label" in cols else ()
    return FEModes(freqs, shapes, str(path), labels)


def read_fe(path) -> FEModes:
    """The FE side of ``correlate``, by suffix: ``.dat``/``.frd`` (ccx), ``.f06``/``.op2`` (Nastran), ``.csv``."""
    suffix = Path(path).suffix.lower()
    readers = {".dat": read_ccx_dat, ".frd": read_ccx_frd, ".f06": read_f06, ".op2": read_op2,
               ".csv": read_modes_csv}
    if suffix not in readers:
        raise FEResultError(f"{path}: FE results are read from .dat or .frd (CalculiX), .f06 or .op2 (Nastran) or "
                            f".csv; not '{suffix or 'no suffix'}'")
    return readers[suffix](path)
