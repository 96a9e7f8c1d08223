"""Check that identify's results are unchanged by a change of the modal stage (speed work).

Runs :func:`guidefit.identify.identify` on a fixed set of recordings and
writes every number of its JSON object (``Identification.to_dict``: modes
with frequency, damping, their std and ``std_parts``, labels, ``estimates``,
``run_modes``, ``force_levels``, the joint parameters K and c with their std,
warnings, gate, ...) to a JSON file; with ``--reference`` it compares them
with a file written before the change:

* strings (labels, warnings, gate, methods) and the structure: identical;
* frequencies (keys that name a frequency, not its std): relative
  difference <= 1e-9;
* every other number (damping, std, K, c, shapes, ...): <= 1e-7.

A relative difference is ``|a - b| / max(|a|, |b|, scale)``; ``scale`` is 0
for a number on its own, the largest magnitude of its vector for the entries
of a vector (``motion``, ``energy``, ``shape``: a component 1e-7 of the
vector's largest is a rounding residue of a projection, and its own relative
difference says nothing), and the mode's reported std of the same quantity
for the entries of ``std_parts`` (a selection spread of 1e-13 next to a std
of 1e-4 is the rounding noise of two fits that end at the same optimum).
Every ``std_parts`` entry is a std (1e-7). The largest relative difference
of each kind is printed, with where it occurred.

Recordings: ``sample_data/mrb35_sample.h5`` (also with force levels), the
other two sample files, the 100-hit 0.5 s benchmark recording of issue 13
(``--e2e``, default /work/e2e_100hits.h5; skipped when absent) and one seed
of the coupled cases of ``bench_global.py`` (corner mass, damaged row, heavy
base, close modes; 8 hits of 0.05 s per run, simulated once into
``GUIDEFIT_CHECK_DIR``, default /tmp/guidefit-check-modal).

Run::

    python benchmarks/check_modal_same.py --out /tmp/ref.json                 # before the change
    python benchmarks/check_modal_same.py --out /tmp/new.json --reference /tmp/ref.json
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import json
import math
import sys
import time
import warnings
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # this tree's guidefit, not an installed one (run from a worktree)
SCRATCH = Path(os.environ.get("GUIDEFIT_CHECK_DIR", "/tmp/guidefit-check-modal"))
#: the coupled cases of bench_global.py, one seed each
COUPLED = {
    "corner": ["added_mass:mass_kg=0.3,at=A"],
    "row": ["row_damage:row=1,factor=0.5"],
    "base": ["base_mode:mass_kg=3,lateral_n_per_m=3e8,vertical_n_per_m=1e9"],
    "close": ["base_mode:mass_kg=1,vertical_n_per_m=1.022e9"],
}
FREQUENCY_TOL = 1e-9
OTHER_TOL = 1e-7


def simulated(case: str, seed: int = 1, hits: int = 8, record_s: float = 0.05) -> Path:
    """One coupled case of bench_global.py (simulated once, then read from the cache)."""
    from guidefit.io import write_recording
    from guidefit.model.effects import parse_effect
    from guidefit.simulate import SimulationConfig, simulate

    SCRATCH.mkdir(parents=True, exist_ok=True)
    path = SCRATCH / f"global_{case}_s{seed}_h{hits}_r{record_s:g}.h5"
    if not path.exists():
        data, _ = simulate("MRB35", effects=[parse_effect(e) for e in COUPLED[case]],
                           config=SimulationConfig(hits=hits, record_s=record_s), seed=seed)
        tmp = path.with_name(path.stem + f".tmp{os.getpid()}.h5")
        write_recording(tmp, data)
        os.replace(tmp, path)
    return path


def cases(e2e: Path) -> dict:
    """name -> (path, settings overrides)."""
    out = {
        "sample": (ROOT / "sample_data/mrb35_sample.h5", {}),
        "sample_force_levels": (ROOT / "sample_data/mrb35_sample.h5", {"force_levels": True}),
        "paper_like": (ROOT / "sample_data/mrb35_paper_like.h5", {}),
        "vertical_csv": (ROOT / "sample_data/mrb35_vertical.csv", {}),
    }
    if e2e.exists():
        out["e2e_100hits"] = (e2e, {})
    else:
        print(f"skipped: {e2e} (absent; --e2e names the 100-hit recording)", file=sys.stderr)
    for case in COUPLED:
        out[case] = (simulated(case), {})
    return out


def run_all(e2e: Path) -> dict:
    from guidefit.errors import GuidefitError
    from guidefit.identify import IdentifySettings, identify

    results = {}
    for name, (path, overrides) in cases(e2e).items():
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                res = identify(path, settings=replace(IdentifySettings(), **overrides))
                out = res.to_dict()
                out.pop("file", None)  # the path, not a result
            except GuidefitError as exc:  # a failure is a result too
                out = {"error": f"{type(exc).__name__}: {exc}"}
        print(f"{name}: {time.perf_counter() - t0:.2f} s", file=sys.stderr)
        results[name] = out
    return results


def _is_frequency(key: str) -> bool:
    k = key.lower()
    return ("frequency" in k or k.startswith("f_") or k.endswith("_hz")) and "std" not in k


def _numbers(values) -> list:
    return [v for v in values if isinstance(v, (int, float)) and not isinstance(v, bool)]


#: entries that are components of one vector (a mode's motion, energy shares, shape at the sensors)
VECTOR_KEYS = ("motion", "energy", "shape")


def _vector_scale(node, key: str, parent: str) -> float:
    """Largest magnitude of a vector's entries (``VECTOR_KEYS``, or a run's entry of ``shapes``), else 0."""
    if key not in VECTOR_KEYS and parent != "shapes":
        return 0.0
    values = list(node.values()) if isinstance(node, dict) else list(node)
    nums = _numbers(values)
    if len(nums) < 2 or len(nums) != len(values):
        return 0.0
    return max((abs(v) for v in nums if math.isfinite(v)), default=0.0)


def compare(ref, new) -> tuple[list, dict]:
    """(differences in structure or text, {kind: (max rel diff, where)}) of two JSON trees."""
    problems: list = []
    worst = {"frequency": (0.0, ""), "other": (0.0, "")}

    def number(a, b, where, key, scale, kind):
        if math.isnan(a) or math.isnan(b):
            if not (math.isnan(a) and math.isnan(b)):
                problems.append(f"{where}: {a!r} -> {b!r}")
            return
        den = max(abs(a), abs(b), scale)
        rel = 0.0 if den < 1e-300 else abs(a - b) / den
        kind = kind or ("frequency" if _is_frequency(key) else "other")
        if rel > worst[kind][0]:
            worst[kind] = (rel, where)

    def walk(a, b, where, key, scale=0.0, kind=None, parent=""):
        if isinstance(a, dict) and isinstance(b, dict):
            if set(a) != set(b):
                problems.append(f"{where}: keys differ: {sorted(set(a) ^ set(b))}")
            inner = _vector_scale(a, key, parent)
            for k in a.keys() & b.keys():
                if k == "std_parts" and isinstance(a[k], dict):  # a std part against the mode's std
                    stds = {"frequency_hz": a.get("frequency_std_hz") or 0.0, "damping_ratio": a.get("damping_std") or 0.0}
                    for part, va in a[k].items():
                        vb = b[k].get(part)
                        for q in (va or {}).keys() | (vb or {}).keys():
                            walk((va or {}).get(q), (vb or {}).get(q), f"{where}.{k}.{part}.{q}", q,
                                 stds.get(q, 0.0), "other")
                    continue
                walk(a[k], b[k], f"{where}.{k}", k, inner or scale, kind, key)
        elif isinstance(a, list) and isinstance(b, list):
            if len(a) != len(b):
                problems.append(f"{where}: {len(a)} entries, now {len(b)}")
            inner = _vector_scale(a, key, parent)
            for i, (x, y) in enumerate(zip(a, b)):
                walk(x, y, f"{where}[{i}]", key, inner or scale, kind)
        elif isinstance(a, bool) or isinstance(b, bool) or isinstance(a, str) or isinstance(b, str) or \
                a is None or b is None:
            if a != b:
                problems.append(f"{where}: {a!r} -> {b!r}")
        elif isinstance(a, (int, float)) and isinstance(b, (int, float)):
            number(a, b, where, key, scale, kind)
        elif a != b:
            problems.append(f"{where}: {a!r} -> {b!r}")

    walk(ref, new, "", "")
    return problems, worst


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True, help="JSON file written with this code's results")
    ap.add_argument("--reference", help="JSON file of the unmodified code to compare with")
    ap.add_argument("--e2e", default="/work/e2e_100hits.h5", help="the 100-hit benchmark recording")
    args = ap.parse_args(argv)
    results = run_all(Path(args.e2e))
    out = Path(args.out)
    tmp = out.with_name(out.name + ".tmp")
    tmp.write_text(json.dumps(results, indent=1, sort_keys=True, default=str))
    os.replace(tmp, out)
    if not args.reference:
        return 0
    ref = json.loads(Path(args.reference).read_text())
    new = json.loads(out.read_text())  # the same JSON round trip as the reference
    problems, worst = compare(ref, new)
    for p in problems[:40]:
        print("DIFF", p)
    ok = not problems
    for kind, tol in (("frequency", FREQUENCY_TOL), ("other", OTHER_TOL)):
        rel, where = worst[kind]
        ok &= rel <= tol
        print(f"max relative difference, {kind}: {rel:.2e} (allowed {tol:g}) at {where or '-'}")
    print("SAME" if ok else "DIFFERENT")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
