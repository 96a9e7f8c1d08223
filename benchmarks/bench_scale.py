"""Long continuous recordings: wall time and peak RSS of ``guidefit frf`` and ``identify``.

Data: one ``signals`` run (force + acc_A..D_y, float32, 200 kHz: 4 MB/s)
written block by block with ``guidefit.io.open_signals_writer``. The
content is 1 s per hit: a 0.5 s hit record of a small guidefit simulation
(10 hits, vertical run, default measurement chain, tiled with a random gain
0.6-1.4 per copy, same on force and responses) followed by 0.5 s of quiet:
Gaussian sensor noise of the simulation's RMS (1e-4 of range), quantised to
its 16-bit LSB. So 1 GB is 250 s and 250 hits; generation is a memory copy
per hit. Sizes: 0.5, 1 and 4 GB (--quick: 0.25 and 0.5 GB); the files are
deleted afterwards (--keep keeps them).

Each command runs once in a fresh process under ``/usr/bin/time -v`` (wall
time, peak RSS of the process). The file was just written, so it is read
from the page cache (24 GB RAM): this measures the process, not the disk.

Run: ``python benchmarks/bench_scale.py [--quick] [--sizes 0.5,1,4] [--keep]``.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _common as C
from bench_startup import guidefit_cmd

FS = 200_000
HIT_S = 0.5
GAP_S = 0.5
FORCE_RANGE, ACC_RANGE, BITS, NOISE = 2048.0, 1024.0, 16, 1e-4


def quiet(n: int, n_ch: int, rng) -> np.ndarray:
    ranges = np.array([FORCE_RANGE] + [ACC_RANGE] * (n_ch - 1))
    lsb = 2 * ranges / 2**BITS
    x = rng.standard_normal((n, n_ch)) * (NOISE * ranges)
    return (np.round(x / lsb) * lsb).astype(np.float32)


def write_signals(path: Path, records: np.ndarray, header, size_gb: float, bar) -> int:
    """Write about ``size_gb`` GB; returns the number of hits."""
    from guidefit.io import open_signals_writer

    n_ch = records.shape[2]
    per_hit = int((HIT_S + GAP_S) * FS) * n_ch * 4
    n_hits = max(1, round(size_gb * 1e9 / per_hit))
    g = C.gains(n_hits)
    rng = np.random.default_rng(11)
    gap = int(GAP_S * FS)
    run = replace(header, data=None, layout="signals", pretrigger_samples=None)
    task = bar.add_task(f"writing {path.name}", total=n_hits)
    with open_signals_writer(path, run, guide="MRB35", dtype=np.float32,
                             description="guidefit benchmark: tiled simulated hits with quiet gaps") as w:
        w.append(quiet(gap // 2, n_ch, rng))
        for i in range(n_hits):
            w.append(records[i % records.shape[0]] * g[i])
            w.append(quiet(gap, n_ch, rng))
            bar.advance(task)
    bar.remove_task(task)
    return n_hits


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--sizes", help="GB, comma-separated (default 0.5,1,4; --quick 0.25,0.5)")
    ap.add_argument("--keep", action="store_true")
    args = ap.parse_args()
    sizes = ([float(s) for s in args.sizes.split(",")] if args.sizes
             else [0.25, 0.5] if args.quick else [0.5, 1.0, 4.0])
    C.print_machine()
    C.BENCH_DIR.mkdir(parents=True, exist_ok=True)
    free = C.free_disk_gb(C.BENCH_DIR)
    if free < max(sizes) + 1:
        sys.exit(f"need {max(sizes) + 1:.1f} GB free in {C.BENCH_DIR}, have {free:.1f}")
    records, header, _ = C.simulated_hits(4 if args.quick else 10, HIT_S)
    g = guidefit_cmd()
    rows = []
    with C.progress() as bar:
        task = bar.add_task("sizes", total=len(sizes))
        for size in sizes:
            path = C.BENCH_DIR / f"signals_{size:g}GB.h5"
            try:
                n_hits = write_signals(path, records, header, size, bar)
                gb = path.stat().st_size / 1e9
                for label, cmd in (
                    ("guidefit frf", [*g, "frf", str(path)]),
                    ("guidefit identify", [*g, "identify", str(path), "--json"]),
                    ("guidefit identify --no-jackknife",
                     [*g, "identify", str(path), "--json", "--no-jackknife"]),
                ):
                    bar.update(task, description=f"{size:g} GB: {label}")
                    m = C.measure(cmd)
                    ok = "ok" if m["returncode"] == 0 else f"exit {m['returncode']}"
                    rows.append([label, f"{gb:.2f}", n_hits, f"{m['wall_s']:.1f}",
                                 f"{m['wall_s'] / gb:.1f}", f"{m['cpu_s']:.1f}",
                                 f"{m['rss_mb']:.0f}", ok])
                    if m["returncode"] not in (0, 1):
                        print(f"{label} on {path.name}: {m['stderr'][-800:]}", file=sys.stderr)
            finally:
                if not args.keep:
                    path.unlink(missing_ok=True)
            bar.advance(task)
    print("one signals run, force + 4 accelerometers, float32, 200 kHz; 1 hit (0.5 s record + "
          "0.5 s quiet) per second of signal; one fresh process per row; page cache warm\n")
    print(C.md_table(["command", "file GB", "hits", "wall s", "wall s per GB", "CPU s",
                      "peak RSS MB", "exit"], rows))
    worst = max(float(r[6]) for r in rows)
    print(f"\ntarget: peak RSS < 400 MB at every size -> "
          f"{'met' if worst < 400 else 'NOT met'} (largest {worst:.0f} MB)")
    C.print_load()


if __name__ == "__main__":
    main()
