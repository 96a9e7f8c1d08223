"""row_segment on recordings: half of each row at 30 % (issue 16, "Done when").

``guidefit simulate`` (MRB35, 4 hits per run, 0.05 s) with
``row_segment:row=R,first=F,last=L,factor=0.3`` -> :func:`guidefit.explain.explain`;
per case: verdict, row found, ends, factor and its std, the factor's error in
standard deviations, pass (row right, ends within two rollers, factor within
10 %; an ``unexplained`` verdict reports the best attempt and fails). Run from the repository root::

    python benchmarks/segment_recordings.py --seeds 2
    python benchmarks/segment_recordings.py --rows 3 --halves low
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

HALVES = {"low": (1, 10), "high": (12, 21)}


def run(row: int, first: int, last: int, seed: int, folder: Path, factor: float = 0.3) -> dict:
    from guidefit.explain import explain
    from guidefit.model.effects import make_effect
    from guidefit.simulate import SimulationConfig, write_simulation

    config = replace(SimulationConfig(), hits=4, record_s=0.05)
    eff = make_effect("row_segment", {"row": row, "first": first, "last": last, "factor": factor})
    files = write_simulation(folder / f"seg_r{row}_{first}_{last}_s{seed}.h5", "MRB35", [eff], config, seed=seed)
    c0 = time.process_time()
    result = explain(files.recordings[0])
    cpu = time.process_time() - c0
    out = {"row": row, "first": first, "last": last, "seed": seed, "verdict": result.verdict, "cpu_s": cpu}
    effs = result.effects or (result.best_attempt["effects"] if result.best_attempt else [])
    seg = [e for e in effs if e["name"] == "row_segment"]
    out["others"] = [e["name"] for e in effs if e["name"] != "row_segment"]
    if seg:
        p = seg[0]["parameters"]
        out.update(found_row=p["row"]["value"], found_first=p["first"]["value"], found_last=p["last"]["value"],
                   factor=p["factor"]["value"], factor_std=p["factor"].get("std"))
        out["pass"] = (result.verdict == "explained" and not out["others"] and int(p["row"]["value"]) == row
                       and abs(p["first"]["value"] - first) <= 2 and abs(p["last"]["value"] - last) <= 2
                       and abs(p["factor"]["value"] / factor - 1) < 0.10)
    else:
        out["pass"] = False
    out["notes"] = [n for n in result.notes if "chi" in n or "within" in n][:3]
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--rows", type=int, nargs="*", default=[1, 2, 3, 4])
    ap.add_argument("--halves", nargs="*", default=["low"], choices=list(HALVES))
    args = ap.parse_args()
    rows = []
    print("| truth | seed | verdict | row | first | last | factor | error/std | pass | CPU |\n"
          "|---|---|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(args.seeds):
            for row in args.rows:
                for half in args.halves:
                    first, last = HALVES[half]
                    r = run(row, first, last, seed, Path(tmp))
                    rows.append(r)
                    if "factor" in r:
                        std = f" +/- {r['factor_std']:.4f}" if r.get("factor_std") else ""
                        z = abs(r["factor"] - 0.3) / r["factor_std"] if r.get("factor_std") else float("nan")
                        body = (f"{r['found_row']} | {r['found_first']:.2f} | {r['found_last']:.2f} | "
                                f"{r['factor']:.4f}{std} | {z:.1f}")
                    else:
                        body = "- | - | - | - | -"
                    extra = f" (+ {', '.join(r['others'])})" if r["others"] else ""
                    print(f"| row {row}, {first}-{last}, 0.3 | {seed} | {r['verdict']}{extra} | {body} | "
                          f"{'pass' if r['pass'] else 'FAIL'} | {r['cpu_s']:.0f} s |", flush=True)
    print(f"\npass {sum(r['pass'] for r in rows)} of {len(rows)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
