"""Identification accuracy on simulated recordings with known truth.

1. Seeds: ``guidefit.simulate`` with the sample data's settings (MRB35,
   vertical + lateral runs, 8 hits of 0.05 s per run, sensors A-D x/y, default
   measurement chain: anti-alias filter, noise 1e-4 of range, 16-bit ADC),
   seeds 1..N (N = 8; --quick 2). Each recording is written to /tmp and
   identified with ``guidefit.identify`` (defaults: curve fit, exponential
   window corrected, jackknife). Relative errors of f_V, f_H, zeta_V,
   zeta_H, K_V, K_H, c_V, c_H against the truth file's values; mean and
   largest |error| over the seeds, the mean signed error (bias), and how
   often the truth lies within 2 reported standard deviations.
2. Damping sweep: the same set-up (one seed per level, three with the full
   run) with the vertical and roll_low modal damping both set to 1 % ... 15 %
   (``SimulationConfig(damping={"vertical": z, "roll_low": z})``). For each
   mode: the curve fit's f_n and zeta (what ``parameters`` reports) against
   the half-power values of the same identify result (the mode's
   ``half_power`` entry: Eq. (26)/(28) half-power points, exact SDOF
   accelerance relation for f_n, exponential-window correction), both
   against the truth.

Targets: f within 0.1 %, zeta within 5 %, K within 0.2 %, c within 5 %.

BLAS is limited to one thread (``OPENBLAS_NUM_THREADS=1``, set before numpy is
imported) to keep the run short; results do not depend on it.

Run: ``python benchmarks/bench_accuracy.py [--quick] [--seeds N]``.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import sys
import time
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _common as C

TARGETS = {"f": 1e-3, "zeta": 0.05, "K": 2e-3, "c": 0.05}
PARAMS = ["f_V", "f_H", "zeta_V", "zeta_H", "K_V", "K_H", "c_V", "c_H"]
LABEL = {"V": "vertical", "H": "roll_low"}


def sample_config():
    from guidefit.simulate import SimulationConfig

    return SimulationConfig(hits=8, record_s=0.05)   # as sample_data/mrb35_sample.h5


def simulate_and_identify(config, seed: int):
    from guidefit.identify import identify
    from guidefit.io import write_recording
    from guidefit.simulate import simulate

    data, truth = simulate("MRB35", config=config, seed=seed)
    path = C.BENCH_DIR / f"accuracy_seed{seed}.h5"
    write_recording(path, data)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            result = identify(path)
    finally:
        path.unlink(missing_ok=True)
    return result, truth


def rel(a, b):
    return (a - b) / b if a is not None else float("nan")


def seeds_table(seeds: list[int], bar) -> str:
    errs = {p: [] for p in PARAMS}
    within = {p: 0 for p in PARAMS}
    task = bar.add_task("seeds", total=len(seeds))
    times = []
    for seed in seeds:
        t = time.perf_counter()
        result, truth = simulate_and_identify(sample_config(), seed)
        times.append(time.perf_counter() - t)
        for p in PARAMS:
            est = result.parameters[p]
            true = truth["parameters"][p]["value"]
            e = rel(est["value"], true)
            errs[p].append(e)
            if est["std"] is not None and abs(est["value"] - true) <= 2 * est["std"]:
                within[p] += 1
        bar.advance(task)
    bar.remove_task(task)
    rows = []
    for p in PARAMS:
        e = np.abs(np.array(errs[p]))
        target = TARGETS[p.split("_")[0]]
        worst = float(np.nanmax(e))
        verdict = "met" if worst <= target else f"NOT met ({worst / target:.1f}x the limit)"
        rows.append([p, f"{target * 100:g} %", f"{np.nanmean(e) * 100:.4f} %",
                     f"{worst * 100:.4f} %", f"{np.nanmean(errs[p]) * 100:+.4f} %",
                     f"{within[p]}/{len(seeds)}", verdict])
    head = (f"seeds {seeds[0]}..{seeds[-1]} ({len(seeds)} recordings, sample settings); "
            f"simulate + identify {np.mean(times):.1f} s per recording\n\n")
    return head + C.md_table(["parameter", "target", "mean abs rel. error", "max abs rel. error",
                              "bias (mean signed)", "truth within 2 std", "verdict"], rows)


def sweep_table(levels: list[float], seeds: list[int], bar) -> str:
    rows = []
    task = bar.add_task("damping sweep", total=len(levels) * len(seeds))
    for z in levels:
        cfg = replace(sample_config(), damping={"vertical": z, "roll_low": z})
        acc = {k: {"fit_f": [], "fit_z": [], "hp_f": [], "hp_z": [], "bins": [], "missing": 0}
               for k in LABEL}
        for seed in seeds:
            result, truth = simulate_and_identify(cfg, seed)
            modes = {m.label: m for m in result.modes}
            for key, label in LABEL.items():
                tf = truth["parameters"][f"f_{key}"]["value"]
                tz = truth["parameters"][f"zeta_{key}"]["value"]
                m = modes.get(label)
                a = acc[key]
                if m is None:
                    a["missing"] += 1
                    continue
                a["fit_f"].append(rel(m.frequency_hz, tf))
                a["fit_z"].append(rel(m.damping_ratio, tz))
                hp = m.half_power
                if hp is None:
                    a["hp_f"].append(np.nan)
                    a["hp_z"].append(np.nan)
                    continue
                a["hp_f"].append(rel(hp["f_n_hz"], tf))
                a["hp_z"].append(rel(hp["zeta_window_corrected"], tz))
                a["bins"].append(hp["bins_in_band"])
            bar.advance(task)
        for key, label in LABEL.items():
            a = acc[key]

            def worst(v):
                v = np.asarray(v, dtype=float)
                if v.size == 0 or np.all(np.isnan(v)):
                    return "-"
                return f"{v[np.nanargmax(np.abs(v))] * 100:+.3f} %"

            rows.append([f"{z * 100:g} %", label, worst(a["fit_f"]), worst(a["fit_z"]),
                         worst(a["hp_f"]), worst(a["hp_z"]),
                         f"{np.mean(a['bins']):.0f}" if a["bins"] else "-",
                         a["missing"] or ""])
    bar.remove_task(task)
    head = (f"vertical and roll_low damping set to each level; seeds {seeds}; "
            "worst signed relative error over the seeds\n\n")
    return head + C.md_table(["zeta (true)", "mode", "curve fit: f_n err", "curve fit: zeta err",
                              "half-power: f_n err", "half-power: zeta err",
                              "half-power band (bins)", "mode not found"], rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--seeds", type=int, default=None, help="number of seeds (default 8; --quick 2)")
    args = ap.parse_args()
    n = args.seeds or (2 if args.quick else 8)
    levels = [0.01, 0.05, 0.15] if args.quick else [0.01, 0.02, 0.03, 0.05, 0.075, 0.10, 0.125, 0.15]
    sweep_seeds = [1] if args.quick else [1, 2, 3]
    C.print_machine("OPENBLAS_NUM_THREADS=" + os.environ["OPENBLAS_NUM_THREADS"])
    C.BENCH_DIR.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    with C.progress() as bar:
        first = seeds_table(list(range(1, n + 1)), bar)
        second = sweep_table(levels, sweep_seeds, bar)
    print(first)
    print()
    print(second)
    print(f"\ntotal {time.perf_counter() - t0:.0f} s")
    C.print_load()


if __name__ == "__main__":
    main()
