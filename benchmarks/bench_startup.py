"""Start-up and single-file latency of the ``guidefit`` command line.

1. Wall time (median of N fresh processes) of ``guidefit --help``,
   ``guidefit identify --help``, ``guidefit identify sample_data/mrb35_sample.h5``
   and the same with ``--no-jackknife``; the identify commands also with
   ``OPENBLAS_NUM_THREADS=2`` (multi-threaded BLAS; since commit ed436ee the
   command line defaults to one BLAS thread unless the variable is set).
2. Where the identify time goes, in one fresh process: the import of
   ``guidefit.cli``, then ``identify()`` cold (first call: pays the lazy
   imports of scipy.optimize, h5py, ...) and warm (second call), called as a
   library (so with the library's BLAS threading, not the command line's),
   split into FRFs (read + hit checks + spectra: ``compute_frf``), the global
   modal stage (``modal_stage.identify_frfs``: LSCF diagram, refinement,
   jackknife and selection spread, shapes, labels), the sensor check and the
   gate (``consistency``), force levels, and the rest (reading the file's
   metadata, the model, warnings), plus rendering the rich tables. The phases
   are timed by wrapping those functions (no library change).
3. ``python -X importtime`` of ``guidefit identify --no-jackknife`` on the
   sample: the heaviest imports (cumulative, as nested by the importer).

Run: ``python benchmarks/bench_startup.py [--quick]`` (--quick: 3 runs per
command instead of 5, no OPENBLAS_NUM_THREADS=1 repetition of --help).
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _common as C

SAMPLE = C.REPO / "sample_data" / "mrb35_sample.h5"
SCRIPT = Path(__file__).resolve()


def guidefit_cmd() -> list[str]:
    exe = shutil.which("guidefit")
    return [exe] if exe else [sys.executable, "-m", "guidefit"]


# --------------------------------------------------------------------------- phases (child)


def phases_worker(path: str) -> dict:
    t0 = time.perf_counter()
    import guidefit.cli  # noqa: F401

    t_cli = time.perf_counter() - t0

    import guidefit.consistency as cons
    import guidefit.frf as frf_mod
    import guidefit.identify as ident
    import guidefit.modal_stage as stage

    clock = {}

    def timed(key, fn):
        def wrapper(*a, **k):
            t = time.perf_counter()
            try:
                return fn(*a, **k)
            finally:
                clock[key] = clock.get(key, 0.0) + time.perf_counter() - t
        return wrapper

    frf_mod.compute_frf = timed("frf", frf_mod.compute_frf)
    stage.identify_frfs = timed("modal", stage.identify_frfs)
    for name in ("check_global", "plausibility", "global_mass_warnings"):
        setattr(cons, name, timed("consistency", getattr(cons, name)))
    ident._force_levels = timed("levels", ident._force_levels)

    from rich.console import Console

    from guidefit import report

    out = {"cli_import": t_cli}
    for label in ("cold", "warm"):
        clock.clear()
        t = time.perf_counter()
        result = ident.identify(path)
        total = time.perf_counter() - t
        with open(os.devnull, "w") as null:
            t = time.perf_counter()
            report.render_identification(result, Console(file=null, width=100))
            render = time.perf_counter() - t
        phases = dict(clock)
        phases["rest"] = total - sum(clock.values())
        phases["total"] = total
        phases["render"] = render
        out[label] = phases
    return out


# --------------------------------------------------------------------------- importtime


def importtime(cmd: list[str], top: int = 12) -> list[tuple[str, float, float, int]]:
    """(module, self s, cumulative s, depth) of the heaviest imports of ``cmd``."""
    proc = subprocess.run([sys.executable, "-X", "importtime", *cmd], capture_output=True,
                          text=True, check=False)
    rows = []
    for line in proc.stderr.splitlines():
        m = re.match(r"import time:\s+(\d+) \|\s+(\d+) \|( *)(\S+)", line)
        if m:
            rows.append((m.group(4), int(m.group(1)) / 1e6, int(m.group(2)) / 1e6,
                         len(m.group(3)) // 2))
    total = sum(r[2] for r in rows if r[3] == 0)
    rows.sort(key=lambda r: -r[2])
    return rows[:top], total


# --------------------------------------------------------------------------- main


def wall_median(cmd, n, env=None) -> tuple[float, float, float, list[float]]:
    runs = [C.measure(cmd, env=env) for _ in range(n)]
    bad = [r for r in runs if r["returncode"] not in (0,)]
    if bad:
        raise RuntimeError(f"{' '.join(cmd)} failed: {bad[0]['stderr'][-1500:]}")
    walls = [r["wall_s"] for r in runs]
    return (statistics.median(walls), statistics.median(r["cpu_s"] for r in runs),
            max(r["rss_mb"] for r in runs), walls)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--worker", metavar="FILE", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        C.emit(phases_worker(args.worker))
        return
    n = 3 if args.quick else 5
    C.print_machine()
    g = guidefit_cmd()
    clean = {k: v for k, v in os.environ.items()
             if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")}
    one = dict(clean, OPENBLAS_NUM_THREADS="1")
    two = dict(clean, OPENBLAS_NUM_THREADS="2")
    cases = [
        ("guidefit --help", [*g, "--help"], clean),
        ("guidefit identify --help", [*g, "identify", "--help"], clean),
        ("guidefit identify sample", [*g, "identify", str(SAMPLE)], clean),
        ("guidefit identify sample --no-jackknife", [*g, "identify", str(SAMPLE), "--no-jackknife"],
         clean),
        ("OPENBLAS_NUM_THREADS=2 guidefit identify sample", [*g, "identify", str(SAMPLE)], two),
        ("OPENBLAS_NUM_THREADS=2 guidefit identify sample --no-jackknife",
         [*g, "identify", str(SAMPLE), "--no-jackknife"], two),
    ]
    rows = []
    phase_runs = {}
    with C.progress() as bar:
        task = bar.add_task("commands", total=len(cases) + 2)
        for label, cmd, env in cases:
            bar.update(task, description=label)
            med, cpu, rss, walls = wall_median(cmd, n, env)
            target = ""
            if "identify sample" in label:
                target = "met" if med < 1.0 else f"NOT met ({med:.2f} s)"
            rows.append([label, f"{med:.2f}", ", ".join(f"{w:.2f}" for w in walls), f"{cpu:.2f}",
                         f"{rss:.0f}", target])
            bar.advance(task)
        for label, env in (("library default (BLAS threads = cores)", clean),
                           ("OPENBLAS_NUM_THREADS=1", one)):
            bar.update(task, description=f"phases, {label}")
            m = C.measure(C.python_cmd(SCRIPT, "--worker", str(SAMPLE)), env=env)
            if m["child"] is None:
                raise RuntimeError(m["stderr"][-2000:])
            phase_runs[label] = m["child"]
            bar.advance(task)
        imp, imp_total = importtime(["-m", "guidefit", "identify", str(SAMPLE), "--no-jackknife"])

    print(f"wall time of a fresh process, median of {n} (all runs listed); CPU = user + sys; "
          "target for identify on the sample: < 1 s\n")
    print(C.md_table(["command", "wall s (median)", "runs (s)", "CPU s", "peak RSS MB",
                      "target < 1 s"], rows))
    print()
    print("identify() on the sample (2 runs x 8 hits x 10 000 samples x 9 channels) by phase, "
          "one fresh process each; cold = first call in the process (includes the lazy imports), "
          "warm = second call\n")
    keys = [("frf", "FRFs: read + hit checks + spectra (compute_frf)"),
            ("modal", "global modal stage (modal_stage.identify_frfs)"),
            ("consistency", "sensor check and gate (consistency)"),
            ("levels", "force levels (identify._force_levels)"),
            ("rest", "rest (metadata, model, warnings)"),
            ("total", "**identify() total**"),
            ("render", "render rich tables")]
    head = ["phase"]
    for label in phase_runs:
        head += [f"cold s, {label}", f"warm s, {label}"]
    first = ["import guidefit.cli"]
    for r in phase_runs.values():
        first += [f"{r['cli_import']:.2f}", "-"]
    prow = [first]
    for key, text in keys:
        row = [text]
        for r in phase_runs.values():
            row += [f"{r['cold'].get(key, 0.0):.3f}", f"{r['warm'].get(key, 0.0):.3f}"]
        prow.append(row)
    print(C.md_table(head, prow))
    print()
    print(f"`python -X importtime -m guidefit identify sample --no-jackknife`: top-level imports "
          f"sum to {imp_total:.2f} s (importtime inflates them somewhat); heaviest by cumulative "
          "time (depth 0 = imported by guidefit or the interpreter itself)\n")
    print(C.md_table(["module", "depth", "self s", "cumulative s"],
                     [[m, d, f"{s:.3f}", f"{c:.3f}"] for m, s, c, d in imp]))
    C.print_load()


if __name__ == "__main__":
    main()
