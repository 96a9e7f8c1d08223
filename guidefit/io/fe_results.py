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
