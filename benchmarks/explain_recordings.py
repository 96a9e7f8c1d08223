"""Full chain on recordings: ``guidefit simulate`` -> ``identify`` -> ``explain`` (issue 5, "Proof").

Each case simulates a hammer test of the MRB35 carriage with physical effects
that the recording does not declare (:func:`guidefit.simulate.write_simulation`,
the realistic measurement chain: anti-alias filter, sensor noise, 16-bit ADC),
then runs :func:`guidefit.explain.explain` on the file -- hits, FRFs, modal
fit, labels and shapes, force levels from :func:`guidefit.identify.identify`,
then the effect library -- and compares the result with the truth file.

Per case one Markdown row: the truth, the verdict, the effects named, the
largest relative parameter error, the RMS relative frequency error of the
nominal model ("before") and of the selected model ("after"), the RMS
measurement uncertainty (``rms_uncertainty_pct``: identify's standard
deviations with explain's model-form floor), CPU time and pass/fail against
the issue's targets:

* null case: ``adequate`` and no effect;
* an effect (or two) of the library: ``explained`` by exactly those effects
  (with their discrete options: corner, row, variant), every continuous
  parameter within 10 %, RMS error after below a fifth of before and not
  above the RMS uncertainty;
* a cause outside the library: no effect claimed (``effects`` empty).

Run from the repository root::

    python benchmarks/explain_recordings.py              # one seed, the table of docs/explain.md
    python benchmarks/explain_recordings.py --seeds 3    # + pass counts over seeds 0-2
    python benchmarks/explain_recordings.py --quick      # 4 hits per run (amplitude_dependence keeps 9)
    python benchmarks/explain_recordings.py --case amplitude --json rows.json --keep /tmp/rec
    python benchmarks/explain_recordings.py --noise 1e-3  # ten times the default sensor noise

Two cores: the script runs one case at a time.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
GUIDE_TOML = REPO / "guidefit" / "model" / "data" / "MRB35.toml"

#: name, effects [(name, parameters)], SimulationConfig changes, guide variant (None: MRB35), kind
CASES = [
    ("null (noise only)", [], {}, None, "null"),
    ("added_mass ABCD", [("added_mass", {"mass_kg": 0.1, "at": "ABCD"})], {}, None, "effect"),
    ("added_mass at A", [("added_mass", {"mass_kg": 0.1, "at": "A"})], {}, None, "effect"),
    ("support_compliance lateral", [("support_compliance", {"lateral_n_per_m": 1.2e8})], {}, None, "effect"),
    ("support_compliance vertical", [("support_compliance", {"vertical_n_per_m": 5e9})], {}, None, "effect"),
    ("contact_stiffness", [("contact_stiffness", {"factor": 0.8})], {}, None, "effect"),
    ("amplitude_dependence", [("amplitude_dependence", {"preload_factor": 0.6})],
     {"hits": 9, "force_n": (50.0, 600.0), "record_s": 0.03}, None, "effect"),
    ("base_mode vertical", [("base_mode", {"mass_kg": 3.0, "vertical_n_per_m": 3e9})], {}, None, "effect"),
    ("row_damage", [("row_damage", {"row": 2, "factor": 0.5})], {}, None, "effect"),
    ("com_offset y", [("com_offset", {"y_m": -0.012})], {}, None, "effect"),
    ("paper-like: support lateral + added_mass", [("support_compliance", {"lateral_n_per_m": 1.25e8}),
                                                  ("added_mass", {"mass_kg": 0.1, "at": "ABCD"})],
     {"hits": 4}, None, "effect"),
    ("contact_stiffness + row_damage", [("contact_stiffness", {"factor": 0.8}),
                                        ("row_damage", {"row": 3, "factor": 0.6})], {}, None, "effect"),
    ("outside: X arrangement", [], {}, "X", "outside"),
    ("outside: h0 + 20 %", [], {}, "h0", "outside"),
]
#: every case: 6 hits per run of 0.05 s (the sample_data length) unless it says otherwise
BASE_CONFIG = {"hits": 6, "record_s": 0.05}
QUICK_CONFIG = {"hits": 4}


def guide_file(variant: str | None, folder: Path) -> str:
    """MRB35 itself, or a TOML copy of it with the arrangement X or h0 + 20 % (causes outside the library)."""
    if variant is None:
        return "MRB35"
    text = GUIDE_TOML.read_text(encoding="utf-8")
    if variant == "X":
        new = text.replace('arrangement = "O"', 'arrangement = "X"')
    elif variant == "h0":
        new = text.replace("h0_m = 0.0107", f"h0_m = {0.0107 * 1.2:.5f}")
    else:
        raise ValueError(variant)
    assert new != text, variant
    new = new.replace('name = "MRB35"', f'name = "MRB35_{variant}"')
    path = folder / f"MRB35_{variant}.toml"
    path.write_text(new, encoding="utf-8")
    return str(path)


def run_case(name, effects, changes, variant, kind, folder: Path, seed: int = 0, quick: bool = False,
             noise: float | None = None) -> dict:
    from guidefit.explain import explain
    from guidefit.model.effects import make_effect
    from guidefit.simulate import SimulationConfig, write_simulation

    cfg = {**BASE_CONFIG, **(QUICK_CONFIG if quick else {}), **changes}
    if "hits" in changes:  # a case's own hit count (force levels need >= 6 accepted hits) wins over --quick
        cfg["hits"] = changes["hits"]
    if noise is not None:
        cfg["noise_fraction"] = noise
    config = replace(SimulationConfig(), **cfg)
    truth_effects = [make_effect(n, p) for n, p in effects]
    slug = "".join(c if c.isalnum() else "_" for c in name).strip("_")[:40]
    path = folder / f"{slug}_s{seed}.h5"
    t0 = time.perf_counter()
    files = write_simulation(path, guide_file(variant, folder), truth_effects, config, seed=seed)
    t_sim = time.perf_counter() - t0
    c0 = time.process_time()
    result = explain(files.recordings[0], guide="MRB35")
    cpu = time.process_time() - c0
    truth = json.loads(files.truth_path.read_text(encoding="utf-8"))
    row = score(name, kind, effects, result)
    row.update({
        "seed": seed, "hits": config.hits, "record_s": config.record_s, "force_n": list(config.force_n),
        "simulate_s": t_sim, "explain_cpu_s": cpu,
        "true_modes": {m["label"]: m["frequency_hz"] for m in truth["modes"]},
        "modes": [{k: m.get(k) for k in ("label", "run", "measured_hz", "measured_std_hz", "sigma_hz",
                                         "model_before_hz", "model_after_hz", "error_after_pct")}
                  for m in result.modes],
        "force_levels": len((getattr(result, "settings", {}) and []) or []),
        "notes": list(result.notes),
    })
    row["identify_rms_std_pct"] = _rms([100 * (m["measured_std_hz"] or 0) / m["measured_hz"] for m in result.modes])
    return row


def _rms(values) -> float:
    values = [v for v in values if v is not None and math.isfinite(v)]
    return math.sqrt(sum(v * v for v in values) / len(values)) if values else float("nan")


def score(name, kind, effects, result) -> dict:
    """Compare an Explanation with the true effects: right effect, parameter error, targets."""
    found = {e["name"]: e for e in result.effects}
    errors, right = [], kind == "effect" and set(found) == {n for n, _ in effects}
    for eff_name, params in effects:
        got = found.get(eff_name)
        if got is None:
            continue
        for key, value in params.items():
            fitted = got["parameters"].get(key, {}).get("value")
            if key == "row":
                right &= fitted is not None and int(fitted) == int(value)
            elif isinstance(value, str):
                right &= str(fitted) == value
            elif fitted is None:
                right = False  # e.g. a lateral support found as a roll spring
            elif value != 0 and math.isfinite(value):
                errors.append(abs(fitted / value - 1.0))
        # a fitted parameter that the truth does not have (a wrong variant)
        extra = [k for k, p in got["parameters"].items() if p.get("std") is not None and k not in params]
        right &= not extra
    before = result.error_before["rms_frequency_error_pct"]
    after = result.error_after["rms_frequency_error_pct"]
    sigma = result.error_after["rms_uncertainty_pct"]
    max_err = 100 * max(errors) if errors else None
    if kind == "null":
        ok = result.verdict == "adequate" and not result.effects
    elif kind == "outside":
        ok = not result.effects
    else:
        ok = (result.verdict == "explained" and right and (max_err is None or max_err < 10.0)
              and after < before / 5 and after <= sigma)
    best = result.best_attempt
    return {
        "case": name, "kind": kind, "truth": _truth_text(effects, name), "verdict": result.verdict,
        "found": "; ".join(_effect_text(e) for e in result.effects) or "-",
        "best_attempt": " + ".join(_effect_text(e) for e in best["effects"]) if best else None,
        "right_effect": bool(right), "max_param_error_pct": max_err,
        "rms_before_pct": before, "rms_after_pct": after, "rms_sigma_pct": sigma,
        "n_modes": len(result.modes), "pass": bool(ok),
    }


def _truth_text(effects, name) -> str:
    if not effects:
        return name.split(": ", 1)[-1] + " (not an effect)" if name.startswith("outside") else "none"
    return "; ".join(f"{n}({', '.join(f'{k}={v:g}' if isinstance(v, float) else f'{k}={v}' for k, v in p.items())})"
                     for n, p in effects)


def _effect_text(e) -> str:
    parts = []
    for k, p in e["parameters"].items():
        v = p["value"]
        parts.append(f"{k}={v:.3g}" if isinstance(v, float) else f"{k}={v}")
    return f"{e['name']}({', '.join(parts)})"


def markdown(rows) -> str:
    head = ("| case | truth | verdict | effects named | param. error | RMS before | RMS after | RMS sigma "
            "| CPU | pass |\n|---|---|---|---|---|---|---|---|---|---|")
    lines = [head]
    for r in rows:
        err = "-" if r["max_param_error_pct"] is None else f"{r['max_param_error_pct']:.2f} %"
        found = r["found"] if r["verdict"] != "unexplained" else f"none (best attempt: {r['best_attempt']})"
        lines.append(f"| {r['case']} | {r['truth']} | {r['verdict']} | {found} | {err} | "
                     f"{r['rms_before_pct']:.3f} % | {r['rms_after_pct']:.4f} % | {r['rms_sigma_pct']:.3f} % | "
                     f"{r['explain_cpu_s']:.0f} s | {'pass' if r['pass'] else '**FAIL**'} |")
    return "\n".join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=1, help="simulation seeds 0..N-1 per case")
    parser.add_argument("--quick", action="store_true", help="4 hits per run (cases with their own count keep it)")
    parser.add_argument("--case", action="append", help="only cases whose name contains this (repeatable)")
    parser.add_argument("--json", help="also write every row as JSON to this file")
    parser.add_argument("--noise", type=float, help="sensor noise RMS relative to range (default 1e-4)")
    parser.add_argument("--keep", help="write the recordings here (default: a temporary folder)")
    args = parser.parse_args()
    cases = [c for c in CASES if not args.case or any(s.lower() in c[0].lower() for s in args.case)]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(args.keep) if args.keep else Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        for seed in range(args.seeds):
            for case in cases:
                print(f"[seed {seed}] {case[0]} ...", file=sys.stderr, flush=True)
                row = run_case(*case, folder=folder, seed=seed, quick=args.quick, noise=args.noise)
                print(f"    {row['verdict']}: {row['found']}  rms {row['rms_before_pct']:.3f} -> "
                      f"{row['rms_after_pct']:.4f} % (sigma {row['rms_sigma_pct']:.3f} %)  "
                      f"{'pass' if row['pass'] else 'FAIL'}", file=sys.stderr, flush=True)
                rows.append(row)
    print(markdown([r for r in rows if r["seed"] == 0]))
    if args.seeds > 1:
        print("\n| case | seeds | pass |\n|---|---|---|")
        for case in cases:
            mine = [r for r in rows if r["case"] == case[0]]
            print(f"| {case[0]} | {len(mine)} | {sum(r['pass'] for r in mine)} |")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1, default=str), encoding="utf-8")
    return 0 if all(r["pass"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
