"""identify's modal stage alone (global fit, shapes, labels): first call and warm, this checkout vs another.

The modal stage is ``guidefit.identify._global_pass`` on the FRF sets of a
recording: LSCF stabilisation diagram, pole selection, variable-projection
refinement, jackknife over hit groups, selection spread, per-run estimates,
shapes and labels. Each process (a fresh interpreter, as identify's first
call in bench_identify_e2e.py: ``guidefit.identify`` and
``guidefit.modes.globalfit`` imported first) reads the FRFs, then times the stage
once (first call: lazy imports and one-off set-up included) and 6 more times
(warm: their median). Processes alternate between the codes compared; the
table gives the median over processes and every process's value.

Files: the 100-hit, 0.5 s, 200 kHz recording of bench_identify_e2e.py
(``--e2e``; written as that script writes it when absent) and
``sample_data/mrb35_sample.h5``.

Run::

    python benchmarks/bench_modal_stage.py [--runs 5] [--baseline DIR] [--e2e FILE]

``--baseline DIR``: a checkout (a folder holding ``guidefit/``, e.g. ``git
archive <commit> guidefit | tar -x -C DIR``) timed the same way for the
"before" rows.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import _common as C

SCRIPT = Path(__file__).resolve()
ROOT = SCRIPT.parents[1]
WARM_CALLS = 6


def worker(path: str) -> None:
    """Child: FRFs of ``path``, then the modal stage once (first) and WARM_CALLS times; JSON on stdout."""
    import guidefit.identify
    import guidefit.modes.globalfit
    from guidefit.identify import IdentifySettings, _global_pass, frf_top_hz, run_frfs
    from guidefit.io import read_recording
    from guidefit.model import vibration as vib
    from guidefit.model.guides import load_guide

    guide = load_guide("MRB35")
    model = vib.solve_modes(vib.model_from_guide(guide))
    settings = IdentifySettings()
    collected = run_frfs(read_recording(path), settings, frf_top_hz(model, settings)).collected
    wall, cpu = [], []
    for _ in range(1 + WARM_CALLS):
        t0, c0 = time.perf_counter(), time.process_time()
        res = _global_pass(collected, guide, model, settings).modal
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    C.emit({"first_s": wall[0], "warm_s": statistics.median(wall[1:]), "first_cpu_s": cpu[0],
            "warm_cpu_s": statistics.median(cpu[1:]), "n_modes": 0 if res is None else len(res.fit.modes),
            "module": guidefit.modes.globalfit.__file__})


def run_child(path: Path, code: Path | None) -> dict:
    env = dict(os.environ)
    if code is not None:
        env["PYTHONPATH"] = str(code) + os.pathsep + env.get("PYTHONPATH", "")
    proc = subprocess.run([sys.executable, str(SCRIPT), "--worker", str(path)], capture_output=True, text=True,
                          env=env, cwd="/", check=False)
    lines = proc.stdout.strip().splitlines()
    if proc.returncode != 0 or not lines:
        raise RuntimeError(f"worker failed on {path}:\n{proc.stderr[-2000:]}")
    return json.loads(lines[-1])


def e2e_file(given: str | None) -> Path:
    if given:
        return Path(given)
    import bench_frf as F

    path = C.BENCH_DIR / "e2e_100hits.h5"
    if not path.exists():
        C.BENCH_DIR.mkdir(parents=True, exist_ok=True)
        with C.progress() as bar:
            records, header, _ = C.simulated_hits(10, F.RECORD_S)
            C.write_hits_file(path, records, header, 100, bar)
    return path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=5, help="fresh processes per file and code (median shown)")
    ap.add_argument("--baseline", help="folder holding another guidefit/ to compare with")
    ap.add_argument("--e2e", help="the 100-hit recording (default: written as bench_identify_e2e.py does)")
    ap.add_argument("--worker", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        worker(args.worker)
        return
    C.print_machine()
    files = {"100 hits x 0.5 s (e2e)": e2e_file(args.e2e), "sample (2 runs x 8 hits)": ROOT / "sample_data/mrb35_sample.h5"}
    codes = {"this checkout": None}
    if args.baseline:
        codes = {f"baseline ({args.baseline})": Path(args.baseline), **codes}
    rows = []
    for label, path in files.items():
        runs: dict = {code: [] for code in codes}
        for _ in range(args.runs):
            for code, where in codes.items():  # alternate, so load changes hit both codes alike
                runs[code].append(run_child(path, where))
        for code, ms in runs.items():
            def med(key, ms=ms):
                return statistics.median(m[key] for m in ms) * 1e3

            rows.append([label, code, f"{med('first_s'):.0f}", f"{med('warm_s'):.0f}", f"{med('first_cpu_s'):.0f}",
                         f"{med('warm_cpu_s'):.0f}", ", ".join(f"{m['first_s'] * 1e3:.0f}/{m['warm_s'] * 1e3:.0f}"
                                                               for m in ms)])
    print(f"modal stage (_global_pass) per process: first call, then median of {WARM_CALLS} warm calls; "
          f"median over {args.runs} fresh processes per row, codes interleaved\n")
    print(C.md_table(["recording", "code", "first ms", "warm ms", "first CPU ms", "warm CPU ms",
                      "each process first/warm ms"], rows))
    C.print_load()


if __name__ == "__main__":
    main()
