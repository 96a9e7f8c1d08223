"""guidefit update on the machine example: is its time the solver's?

Runs ``update`` (the library call the CLI makes) on examples/machine with
``each:K_V`` (4 parameters) and ``all:K_V`` (1), with ``--jobs 1`` and
``--jobs 2``, and prints per case: ccx runs, solver time (summed over the
runs), wall time, time outside ccx per run (serial runs only), and the
recovered factors (truth: 1, 0.8, 0.8, 1).

    python benchmarks/bench_update.py [--quick]
"""

from __future__ import annotations

import shutil
import sys
import tempfile
import time
from pathlib import Path

from _common import md_table, print_load, print_machine

from guidefit.machine.update import update

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "machine"


def main(quick: bool) -> None:
    if shutil.which("ccx") is None:
        print("ccx not installed (apt-get install calculix-ccx): nothing to measure")
        return
    print_machine()
    cases = [("each:K_V=0.5..2", 2), ("all:K_V", 1)] if quick else \
        [("each:K_V=0.5..2", 1), ("each:K_V=0.5..2", 2), ("all:K_V", 1), ("all:K_V", 2)]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in ("machine.inp", "joints.inp", "measured.csv"):
            shutil.copy(EXAMPLE / name, Path(tmp) / name)
        for param, jobs in cases:
            t0 = time.perf_counter()
            r = update(Path(tmp) / "machine.inp", Path(tmp) / "measured.csv", [param], jobs=jobs)
            wall = time.perf_counter() - t0
            serial = jobs == 1  # with parallel runs the solver's share of the wall time is not a sum
            rows.append([f"`{param}`", jobs, r.runs, f"{r.ccx_seconds:.2f}", f"{wall:.2f}",
                         f"{r.ccx_seconds / r.runs * 1000:.0f}",
                         f"{(wall - r.ccx_seconds) / r.runs * 1000:.0f}" if serial else "-",
                         f"{100 * r.ccx_seconds / wall:.0f} %" if serial else "-",
                         ", ".join(f"{f:.3f}" for f in r.factors)])
    print(md_table(["--param", "jobs", "ccx runs", "ccx s (sum of runs)", "wall s", "ms per ccx run",
                    "ms outside ccx per run", "ccx share of wall", "factors"], rows))
    print_load()


if __name__ == "__main__":
    main("--quick" in sys.argv)
