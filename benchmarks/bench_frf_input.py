"""FRFs as input: how honest is the std of a joint identified from FRF files?

For seeded simulations (known truth), the joint is identified from the
recording (std: modal fit + hit jackknife), from ``frf.h5`` written from it
(the jackknife group sums travel with it: the same std) and from ``frf.uff``
(no hits in UFF-58: the std is the modal fit's own). Printed: per source the
median ratio of the std to the recording's, and the largest |estimate -
truth| / std over the seeds for f_V, zeta_V, f_H, zeta_H (a std that keeps
its promise gives values of a few at most).

    python benchmarks/bench_frf_input.py [--quick]
"""

from __future__ import annotations

import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

from guidefit.identify import frf_of_recording, identify
from guidefit.io import write_frfs, write_recording
from guidefit.simulate import SimulationConfig, simulate

NAMES = ("f_V", "zeta_V", "f_H", "zeta_H")


def main(quick: bool) -> None:
    seeds = range(1, 4) if quick else range(1, 9)
    folder = Path(tempfile.mkdtemp(prefix="guidefit-frf-input-"))
    z = {src: {n: [] for n in NAMES} for src in ("recording", "frf.h5", "frf.uff")}
    ratio = {src: {n: [] for n in NAMES} for src in ("frf.h5", "frf.uff")}
    for seed in seeds:
        data, truth = simulate("MRB35", config=replace(SimulationConfig(), hits=4, record_s=0.05), seed=seed)
        rec = folder / f"rec{seed}.h5"
        write_recording(rec, data)
        frfsets, _ = frf_of_recording(rec)
        paths = {"recording": rec, "frf.h5": folder / f"frf{seed}.h5", "frf.uff": folder / f"frf{seed}.uff"}
        write_frfs(paths["frf.h5"], frfsets, recording=rec)
        write_frfs(paths["frf.uff"], frfsets, recording=rec)
        results = {src: identify(p) for src, p in paths.items()}
        for src, r in results.items():
            for n in NAMES:
                p = r.parameters[n]
                z[src][n].append(abs(p["value"] - truth["parameters"][n]["value"]) / p["std"])
                if src != "recording":
                    ratio[src][n].append(p["std"] / results["recording"].parameters[n]["std"])
        print(f"seed {seed} done", file=sys.stderr)
    print(f"{len(seeds)} seeds, 2 runs of 4 hits of 50 ms each (MRB35)\n")
    print("| source | " + " | ".join(f"std / recording's std, {n}" for n in NAMES) + " |")
    print("|---|" + "---|" * len(NAMES))
    for src, by in ratio.items():
        print(f"| {src} | " + " | ".join(f"{np.median(by[n]):.2f}" for n in NAMES) + " |")
    print("\n| source | " + " | ".join(f"max abs(est - truth) / std, {n}" for n in NAMES) + " |")
    print("|---|" + "---|" * len(NAMES))
    for src, by in z.items():
        print(f"| {src} | " + " | ".join(f"{max(by[n]):.1f}" for n in NAMES) + " |")


if __name__ == "__main__":
    main("--quick" in sys.argv)
