"""Batch throughput: ``guidefit identify f1 .. fN --jobs 1`` against ``--jobs 2``.

The N files are copies of ``sample_data/mrb35_sample.h5`` (2 runs x 8 hits x
0.05 s x 9 channels) under /tmp. Each command runs once in a fresh process
(``--csv`` to a temporary file, tables to /dev/null); wall time includes the
interpreter start and imports (once per command for --jobs 1, once per worker
process more for --jobs 2). Every variant is run with the command line's
default BLAS threading (one thread since commit ed436ee) and with
``OPENBLAS_NUM_THREADS=2``: with two worker processes on two cores, BLAS
threads oversubscribe the machine.

Run: ``python benchmarks/bench_batch.py [--quick] [--files N]`` (default 8
files; --quick: 4).
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _common as C
from bench_startup import SAMPLE, guidefit_cmd


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--files", type=int, default=None)
    args = ap.parse_args()
    n = args.files or (4 if args.quick else 8)
    C.print_machine()
    folder = C.BENCH_DIR / "batch"
    folder.mkdir(parents=True, exist_ok=True)
    files = []
    for i in range(n):
        target = folder / f"copy_{i:02d}.h5"
        shutil.copyfile(SAMPLE, target)
        files.append(str(target))
    g = guidefit_cmd()
    clean = {k: v for k, v in os.environ.items()
             if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")}
    two = dict(clean, OPENBLAS_NUM_THREADS="2")
    variants = [
        ("--jobs 1", ["--jobs", "1"], clean),
        ("--jobs 2", ["--jobs", "2"], clean),
        ("--jobs 1, OPENBLAS_NUM_THREADS=2", ["--jobs", "1"], two),
        ("--jobs 2, OPENBLAS_NUM_THREADS=2", ["--jobs", "2"], two),
    ]
    rows = []
    base = {}
    with C.progress() as bar:
        task = bar.add_task("batches", total=len(variants))
        for label, opts, env in variants:
            bar.update(task, description=label)
            csv = folder / "summary.csv"
            m = C.measure([*g, "identify", *files, *opts, "--csv", str(csv)], env=env)
            if m["returncode"] != 0:
                raise RuntimeError(f"{label}: exit {m['returncode']}: {m['stderr'][-1500:]}")
            lines = csv.read_text().strip().splitlines()
            assert len(lines) == n + 1, f"{label}: {len(lines) - 1} rows for {n} files"
            key = "two" if env is two else "default"
            if opts[-1] == "1":
                base[key] = m["wall_s"]
            speed = f"{base[key] / m['wall_s']:.2f}" if opts[-1] == "2" else "1.00"
            rows.append([label, n, f"{m['wall_s']:.1f}", f"{m['cpu_s']:.1f}",
                         f"{n / m['wall_s']:.2f}", speed, f"{m['rss_mb']:.0f}"])
            bar.advance(task)
    print(f"{n} copies of mrb35_sample.h5, one fresh `guidefit identify ... --csv` process per row\n")
    print(C.md_table(["variant", "files", "wall s", "CPU s (user+sys, all processes)", "files/s",
                      "speed-up vs --jobs 1", "peak RSS MB (largest process)"], rows))
    C.print_load()
    shutil.rmtree(folder, ignore_errors=True)


if __name__ == "__main__":
    main()
