"""Build the machine example of docs/machine.md: a carriage table on two rails on a flexible base.

Writes, beside this script:

* ``results.jsonl``, ``explain.jsonl``: four MRB35 carriages as ``identify`` /
  ``explain --json`` give them (the paper's test values, verdict adequate);
* ``joints.inp``: their joints, ``guidefit export --format calculix`` (full
  6x6 matrix, SI, carriage nodes 10001 + 100 j, rail nodes 20001 + 100 j);
* ``machine.inp``: the machine (CalculiX, SI: m, kg, N), B31 beams: a base
  frame (two 1.2 m longitudinal beams under the rails, three cross beams,
  held at five points), a table frame (0.6 m x 0.6 m) on the four carriages,
  a 60 kg motor
  off the table's centre, a ball-screw spring along the rails; the joints ``*INCLUDE``\\ d; a
  ``*FREQUENCY`` step (12 modes) printing the shapes at 16 nodes;
* ``measured.csv``: the "measured" modes: the same deck with K_V x 0.8 on
  joint2 and joint3 (the truth, in ``truth.json``), frequencies with 0.1 %
  seeded noise, shapes at the 16 nodes.

Run: ``python examples/machine/make_example.py`` (needs ccx). The committed
files are its output; ``tests/test_update.py`` checks the joints are still
what ``export`` writes.
"""

from __future__ import annotations

import itertools
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
TRUTH = {"joint2:K_V": 0.8, "joint3:K_V": 0.8}
NOISE = 0.001  # relative std of the measured frequencies
SEED = 23
RESULT = {"guide": "MRB35", "parameters": {"K_V": {"value": 1.03e9}, "c_V": {"value": 2750.0},
                                          "K_H": {"value": 1.00e8}, "c_H": {"value": 3109.0}},
          "modes": [{"label": "vertical", "frequency_hz": 3450.0, "damping_ratio": 0.0288},
                    {"label": "roll_low", "frequency_hz": 1075.0, "damping_ratio": 0.105}]}
#: carriages: (x, z) on the rails, base beam node under it, table node above it
CARRIAGES = [(-0.3, -0.15, 4, 102), (-0.3, 0.15, 6, 104), (0.3, -0.15, 14, 112), (0.3, 0.15, 16, 114)]
BASE_SECTION = "0.20,0.30"  # width x height of the base beams, m
N_MODES = 12
MOTOR_NODE = 127  # table cross beam at z = +0.3, x = -0.15
SUPPORTS = (1, 9, 11, 19, 5)  # base nodes held: the four corners and the left rail's middle
MEASURED_NODES = (101, 103, 105, 111, 113, 115, 122, 125, 128, 3, 5, 7, 13, 15, 17, 25)


def _chain(lines, nodes, elset, first):
    lines.append(f"*ELEMENT,TYPE=B31,ELSET={elset}")
    for k, (a, b) in enumerate(itertools.pairwise(nodes)):
        lines.append(f"{first + k},{a},{b}")
    return first + len(nodes) - 1


def _frame(first_node, x, y, zs, cross_z):
    """Nodes of two longitudinal beams at +/-x and cross beams at cross_z (three inner nodes each)."""
    nodes = [(first_node + i, (-x, y, z)) for i, z in enumerate(zs)]
    nodes += [(first_node + 10 + i, (x, y, z)) for i, z in enumerate(zs)]
    chains = [list(range(first_node, first_node + len(zs))), list(range(first_node + 10, first_node + 10 + len(zs)))]
    for k, z in enumerate(cross_z):
        i = zs.index(z)
        inner = [first_node + 20 + 3 * k + m for m in range(3)]
        nodes += [(n, (xx, y, z)) for n, xx in zip(inner, (-x / 2, 0.0, x / 2))]
        chains.append([first_node + i, *inner, first_node + 10 + i])
    return nodes, chains


def _tie(ref: int, beam: int, dy: float) -> list[str]:
    """``*EQUATION`` s: node ``ref`` (dy above the beam node) moves with the beam node as a rigid arm;
    its rotation node ref + 50 carries the beam node's rotations (DOFs 4-6)."""
    lines = ["*EQUATION", "3", f"{ref},1,1.,{beam},1,-1.,{beam},6,{dy!r}",
             "*EQUATION", "2", f"{ref},2,1.,{beam},2,-1.",
             "*EQUATION", "3", f"{ref},3,1.,{beam},3,-1.,{beam},4,{-dy!r}"]
    for k in range(3):
        lines += ["*EQUATION", "2", f"{ref + 50},{k + 1},1.,{beam},{k + 4},-1."]
    return lines


def machine_deck() -> str:
    """The machine deck (SI), including joints.inp."""
    zs_base = [round(-0.6 + 0.15 * i, 4) for i in range(9)]
    zs_table = [round(-0.3 + 0.15 * i, 4) for i in range(5)]
    base, base_chains = _frame(1, 0.3, -0.05, zs_base, (-0.6, 0.0, 0.6))
    table, table_chains = _frame(101, 0.3, 0.05, zs_table, (-0.3, 0.0, 0.3))
    joint_nodes = []
    for j, (x, z, _, _) in enumerate(CARRIAGES):
        for n in (10001 + 100 * j, 10051 + 100 * j, 20001 + 100 * j, 20051 + 100 * j):
            joint_nodes.append((n, (x, 0.0, z)))
    lines = ["** guidefit machine example: a carriage table on two rails on a flexible base (SI: m, kg, N)",
             "** built by examples/machine/make_example.py; see docs/machine.md", "*NODE"]
    lines += [f"{n},{x!r},{y!r},{z!r}" for n, (x, y, z) in base + table + joint_nodes]
    lines += ["900,0.,0.05,-0.3"]
    eid = 1
    for k, c in enumerate(base_chains):
        eid = _chain(lines, c, "BASEL" if k < 2 else "BASEX", eid)
    for k, c in enumerate(table_chains):
        eid = _chain(lines, c, "TABLEL" if k < 2 else "TABLEX", eid)
    lines += ["*MATERIAL,NAME=STEEL", "*ELASTIC", "210.E9,0.3", "*DENSITY", "7850."]
    for elset, size, n1 in (("BASEL", BASE_SECTION, "1.,0.,0."), ("BASEX", BASE_SECTION, "0.,0.,1."),
                            ("TABLEL", "0.12,0.08", "1.,0.,0."), ("TABLEX", "0.12,0.08", "0.,0.,1.")):
        lines += [f"*BEAM SECTION,ELSET={elset},MATERIAL=STEEL,SECTION=RECT", size, n1]
    lines += ["** the joints' rail nodes ride on the base beams, the carriage nodes carry the table"]
    for j, (_, _, beam, top) in enumerate(CARRIAGES):
        lines += _tie(20001 + 100 * j, beam, 0.05) + _tie(10001 + 100 * j, top, -0.05)
    lines += ["** ball screw along the rails: table centre to ground", "*ELEMENT,TYPE=SPRINGA,ELSET=DRIVE",
              f"{eid},125,900", "*SPRING,ELSET=DRIVE", "", "2.E8"]
    lines += ["** a motor (60 kg) on the table, off its centre", "*ELEMENT,TYPE=MASS,ELSET=MOTOR",
              f"{eid + 1},{MOTOR_NODE}", "*MASS,ELSET=MOTOR", "60."]
    lines += ["** the four joints, as guidefit export --format calculix wrote them", "*INCLUDE,INPUT=joints.inp"]
    lines += ["** the base stands on five feet", "*BOUNDARY", "900,1,3", *[f"{n},1,3" for n in SUPPORTS]]
    lines += ["*NSET,NSET=MEASURED", ",".join(str(n) for n in MEASURED_NODES)]
    lines += ["*STEP", "*FREQUENCY", str(N_MODES), "*NODE PRINT,NSET=MEASURED", "U", "*END STEP"]
    return "\n".join(lines) + "\n"


def write_inputs() -> None:
    """results.jsonl, explain.jsonl, joints.inp (through guidefit export), machine.inp."""
    results = [dict(RESULT, file=f"carriage{j + 1}.h5") for j in range(4)]
    (HERE / "results.jsonl").write_text("".join(json.dumps(r) + "\n" for r in results))
    (HERE / "explain.jsonl").write_text("".join(json.dumps({"file": f"carriage{j + 1}.h5", "verdict": "adequate",
                                                            "guide": "MRB35", "effects": []}) + "\n"
                                                for j in range(4)))
    args = [sys.executable, "-m", "guidefit", "export", "results.jsonl", "--format", "calculix", "-o", "joints.inp"]
    args += [a for j in range(4) for a in ("--explain", f"explain{j + 1}.json")]
    for j in range(4):  # export --explain takes one explain object per file
        (HERE / f"explain{j + 1}.json").write_text(
            (HERE / "explain.jsonl").read_text().splitlines()[j] + "\n")
    subprocess.run(args, cwd=HERE, check=True)
    for j in range(4):
        (HERE / f"explain{j + 1}.json").unlink()
    (HERE / "explain.jsonl").unlink()
    (HERE / "machine.inp").write_text(machine_deck())


def write_measured() -> None:
    """measured.csv and truth.json from the deck with the TRUTH factors."""
    from guidefit.machine.ccx_deck import find_ccx, load_deck, run_ccx, stage
    from guidefit.machine.update import joint_factors, parse_params

    deck = load_deck(HERE / "machine.inp")
    params = parse_params(list(TRUTH), len(deck.joints))
    with tempfile.TemporaryDirectory() as tmp:
        stage(deck, Path(tmp), joint_factors(deck, params, np.array(list(TRUTH.values()))))
        fe, _ = run_ccx(find_ccx(), Path(tmp))
    rng = np.random.default_rng(SEED)
    freqs = fe.frequencies_hz * (1 + NOISE * rng.standard_normal(fe.frequencies_hz.size))
    cols = ["mode", "frequency_hz"] + [f"{n}:{a}" for n in MEASURED_NODES for a in "xyz"]
    rows = [",".join(cols)]
    for k, f in enumerate(freqs):
        vals = [str(k + 1), f"{f:.6g}"] + [f"{fe.shapes[str(n)][k, i]:.5g}" for n in MEASURED_NODES for i in range(3)]
        rows.append(",".join(vals))
    (HERE / "measured.csv").write_text(
        f"# guidefit machine example: the deck with {', '.join(f'{k} x {v}' for k, v in TRUTH.items())}; "
        f"frequencies with {NOISE * 100:g} % noise (seed {SEED})\n" + "\n".join(rows) + "\n")
    (HERE / "truth.json").write_text(json.dumps({"factors": TRUTH, "frequency_noise_pct": NOISE * 100,
                                                 "seed": SEED}, indent=1) + "\n")


if __name__ == "__main__":
    write_inputs()
    write_measured()
