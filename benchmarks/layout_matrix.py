"""Sensor layout x rig effect matrix: identify (and optionally explain) on simulated recordings.

    python benchmarks/layout_matrix.py [--seeds 1,2,3] [--layouts default,pair] [--effects nominal,base]
                                       [--explain] [--hits 8] [--record 0.05]

Each cell simulates the MRB35 carriage with the effect (guidefit.simulate, the
layout's sensors), runs ``identify`` (global fit, jackknife on) and compares
with the truth file: every labelled mode within 0.2 % of the truth mode of that
label, f_V and f_H within 0.1 %, zeta within 5 %, every |error| <= 3 std. With
``--explain`` the verdict and the best effect are listed too. The table is
printed in Markdown (benchmarks/README.md keeps the last run).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
import time
import warnings

EFFECTS = {
    "nominal": [],
    "mass_at_A": ["added_mass:mass_kg=0.1,at=A"],
    "soft_lateral": ["support_compliance:lateral_n_per_m=1.2e8"],
    "contact_0.8": ["contact_stiffness:factor=0.8"],
    "heavy_base": ["base_mode:mass_kg=3,lateral_n_per_m=3e8,vertical_n_per_m=1e9"],
}
EXPECTED = {"nominal": "adequate", "mass_at_A": "added_mass", "soft_lateral": "support_compliance",
            "contact_0.8": "contact_stiffness", "heavy_base": "base_mode"}
LAYOUTS = ("default", "both", "side", "triax:A,C", "pair", "single")
TOL = {"f": 1e-3, "zeta": 0.05}


def cell(effect: str, layout: str, seed: int, hits: int, record_s: float, folder: str, do_explain: bool) -> dict:
    from guidefit.errors import GuidefitError
    from guidefit.identify import IdentifySettings, identify
    from guidefit.io import write_recording
    from guidefit.model.effects import parse_effect
    from guidefit.simulate import SimulationConfig, simulate

    cfg = SimulationConfig(hits=hits, record_s=record_s, sensor_layout=layout)
    data, truth = simulate("MRB35", effects=[parse_effect(e) for e in EFFECTS[effect]], config=cfg, seed=seed)
    path = os.path.join(folder, f"{effect}_{layout.replace(':', '_').replace(',', '')}_{seed}.h5")
    write_recording(path, data)
    t = {m["label"]: m for m in truth["modes"]}
    out = {"effect": effect, "layout": layout, "seed": seed, "problems": []}
    start = time.perf_counter()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            result = identify(path, settings=IdentifySettings())
    except GuidefitError as exc:
        out["problems"].append(f"identify failed: {str(exc)[:120]}")
        out["seconds"] = time.perf_counter() - start
        return out
    out["seconds"] = time.perf_counter() - start
    for m in result.modes:
        tm = t.get(m.label)
        if tm is None or abs(m.frequency_hz / tm["frequency_hz"] - 1) > 2e-3:
            out["problems"].append(f"{m.label} at {m.frequency_hz:.0f} Hz is not the truth's")
    out["bases"] = {m.label: m.label_basis for m in result.modes}
    worst = 0.0
    for key, label, kind in (("f_V", "vertical", "f"), ("f_H", "roll_low", "f"), ("zeta_V", "vertical", "zeta"),
                             ("zeta_H", "roll_low", "zeta")):
        p = result.parameters[key]
        true = t[label]["frequency_hz"] if kind == "f" else t[label]["damping_ratio"]
        if p["value"] is None:
            out["problems"].append(f"no {key}")
            continue
        err = p["value"] - true
        out[key] = err / true
        if abs(err) > TOL[kind] * abs(true):
            out["problems"].append(f"{key} {100 * err / true:+.3f} %")
        if not p["std"] or abs(err) > 3 * p["std"]:
            out["problems"].append(f"{key} error {abs(err) / (p['std'] or math.nan):.1f} std")
        if p["std"]:
            worst = max(worst, abs(err) / p["std"])
    out["worst_std"] = worst
    if result.gate:
        out["problems"].append(f"gate: {result.gate[:80]}")
    if result.sensor_faults:
        out["problems"].append("false sensor fault: " + ", ".join(f.channel for f in result.sensor_faults))
    if do_explain:
        from guidefit.explain import explain

        try:
            ex = explain(result)
            best = ex.effects[0]["name"] if ex.effects else ex.verdict
        except GuidefitError as exc:
            best = f"failed: {str(exc)[:60]}"
        out["explain"] = best
        if best != EXPECTED[effect]:
            out["problems"].append(f"explain: {best} (expected {EXPECTED[effect]})")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="1")
    ap.add_argument("--layouts", default=",".join(LAYOUTS))
    ap.add_argument("--effects", default=",".join(EFFECTS))
    ap.add_argument("--explain", action="store_true")
    ap.add_argument("--hits", type=int, default=8)
    ap.add_argument("--record", type=float, default=0.05)
    a = ap.parse_args(argv)
    layouts = [x for x in a.layouts.split(";" if ";" in a.layouts else ",") if x]
    layouts = _join_triax(layouts)
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for effect in a.effects.split(","):
            for layout in layouts:
                for seed in (int(s) for s in a.seeds.split(",")):
                    r = cell(effect, layout, seed, a.hits, a.record, folder, a.explain)
                    rows.append(r)
                    print(f"{effect:13s} {layout:10s} s{seed} {r.get('seconds', 0):5.2f}s "
                          f"f_V {_pct(r.get('f_V'))} f_H {_pct(r.get('f_H'))} zV {_pct(r.get('zeta_V'))} "
                          f"zH {_pct(r.get('zeta_H'))} worst {r.get('worst_std', math.nan):.1f} std "
                          f"{r.get('explain', '')} {'OK' if not r['problems'] else '; '.join(r['problems'])}",
                          file=sys.stderr, flush=True)
    print(table(rows, layouts, list(a.effects.split(",")), a.explain))
    return 1 if any(r["problems"] for r in rows) else 0


def _join_triax(parts):
    out = []
    for p in parts:  # "triax:A,C" was split at its comma
        if out and out[-1].startswith("triax:") and len(p) == 1 and p.isalpha():
            out[-1] += "," + p
        else:
            out.append(p)
    return out


def _pct(x) -> str:
    return "    -   " if x is None else f"{100 * x:+.3f}%"


def table(rows, layouts, effects, with_explain) -> str:
    head = "| effect | " + " | ".join(layouts) + " |"
    lines = [head, "|" + "---|" * (len(layouts) + 1)]
    for effect in effects:
        cells = []
        for layout in layouts:
            mine = [r for r in rows if r["effect"] == effect and r["layout"] == layout]
            ok = sum(1 for r in mine if not r["problems"])
            worst = max((r.get("worst_std", 0.0) for r in mine), default=0.0)
            text = f"{ok}/{len(mine)}, {worst:.1f} std"
            if with_explain:
                names = sorted({r.get("explain", "") for r in mine})
                text += ", " + "/".join(names)
            cells.append(text)
        lines.append(f"| {effect} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
