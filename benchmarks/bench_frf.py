"""Throughput and memory of the FRF engine against a floor, a naive H1 and pyFRF.

Data: a 200 kHz hits-layout recording, force + 4 accelerometers (acc_A..D_y),
float32, 0.5 s per hit (100 000 samples x 5 channels). The hits are simulated
once with ``guidefit.simulate`` (vertical run, default measurement chain) and
tiled with a random gain per copy (0.6-1.4, same on force and responses, so
the FRF is unchanged) to 100 hits (full) or 20 hits (--quick); the file is
written with guidefit's writer (first copies) and grown with h5py.

Each variant runs in its own child process under ``/usr/bin/time -v`` (peak
RSS of the whole process, imports included); the child times its own work
(file open to FRF, imports excluded) and reports it as JSON. The variants
run round after round (5 rounds; the median is shown), so that a change in
the load of a shared machine falls on all of them alike. The file is
read once before the runs, so every variant reads from the page cache.

Variants:

floor (float32)
    h5py, file opened once, ``ds[i]`` per hit + ``scipy.fft.rfft(x, axis=0,
    workers=2)`` on the stored float32: one FFT pass over every sample.
floor (float64)
    the same with the record converted to float64 first (the precision every
    guidefit path computes in).
guidefit
    ``compute_frf(run, iter_hits(run))`` on ``read_recording(path)``: what
    ``identify`` and ``guidefit frf`` do (default windows, hit checks; the
    file is float32, so the FFTs are single precision, ``precision="auto"``).
guidefit, double precision
    the same with ``compute_frf(..., precision="double")``: float64 FFTs.
guidefit, one thread
    the same with ``compute_frf(..., workers=1)``: no FFT threads, everything
    on the calling thread (what a machine without a free core gets).
guidefit, no hit checks
    ``spectral_sums`` over the h5py float32 records (the FFT/accumulation core
    alone, no windows chosen, no quality checks).
iter_hits only
    reading and checking every hit, no FFT (where the rest of the time goes).
naive scipy.signal
    per hit ``welch(f)`` and ``csd(f, x_r)`` for each response (boxcar window,
    one segment), summed, H1 = Sfx / Sff.
pyFRF 1.5
    ``pyFRF.FRF(fs, fft_len=n, window='none', resp_type='a')``, ``add_data``
    per hit, ``get_H1()``. (pyFRF 1.5 removed ``exc_window``; ``window='none'``
    is the same "no window" setting.)

Then guidefit alone on 1000 hits (full; 200 with --quick) for peak RSS.

Run: ``python benchmarks/bench_frf.py [--quick] [--repeat N]``.
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _common as C

FS = 200_000
RECORD_S = 0.5
SCRIPT = Path(__file__).resolve()


# --------------------------------------------------------------------------- workers


def _open(path):
    import h5py

    f = h5py.File(path, "r")
    return f, f["runs"]["vertical"]["hits"]


def w_imports(path):
    import h5py  # noqa: F401
    import scipy.fft
    import scipy.signal  # noqa: F401

    from guidefit import frf, hits  # noqa: F401

    return {"seconds": 0.0, "n_samples": 0}


def w_floor32(path):
    import scipy.fft

    t = time.perf_counter()
    f, ds = _open(path)
    n = ds.shape[0]
    acc = 0.0
    for i in range(n):
        Z = scipy.fft.rfft(ds[i], axis=0, workers=2)
        acc += float(abs(Z[1, 0]))
    f.close()
    return {"seconds": time.perf_counter() - t, "n_samples": int(np.prod(ds.shape)), "check": acc}


def w_floor64(path):
    import scipy.fft

    t = time.perf_counter()
    f, ds = _open(path)
    n = ds.shape[0]
    acc = 0.0
    for i in range(n):
        x = np.array(ds[i].T, dtype=np.float64)
        Z = scipy.fft.rfft(x, axis=-1, workers=2)
        acc += float(abs(Z[0, 1]))
    f.close()
    return {"seconds": time.perf_counter() - t, "n_samples": int(np.prod(ds.shape)), "check": acc}


def _guidefit(path, **options):
    """``compute_frf(run, iter_hits(run), **options)`` on the file's first run, timed."""
    from guidefit.frf import compute_frf
    from guidefit.hits import iter_hits
    from guidefit.io import read_recording

    t = time.perf_counter()
    run = read_recording(path).runs[0]
    frf = compute_frf(run, iter_hits(run), **options)
    dt = time.perf_counter() - t
    return {"seconds": dt, "n_samples": run.n_hits_stored * run.n_samples * run.n_channels,
            "n_averages": frf.n_averages}


def w_guidefit(path):
    return _guidefit(path)


def w_guidefit_double(path):
    return _guidefit(path, precision="double")


def w_guidefit_one_thread(path):
    return _guidefit(path, workers=1)


def w_guidefit_core(path):
    from guidefit.frf import spectral_sums

    t = time.perf_counter()
    f, ds = _open(path)
    n_hits, n = ds.shape[0], ds.shape[1]
    records = (ds[i] for i in range(n_hits))  # float32 as stored: single-precision FFTs
    s = spectral_sums(records, 0, np.ones(n), np.ones(n))
    f.close()
    return {"seconds": time.perf_counter() - t, "n_samples": int(np.prod(ds.shape)),
            "n_hits": int(s["n_hits"].sum())}


def w_iter_hits(path):
    from guidefit.hits import iter_hits
    from guidefit.io import read_recording

    t = time.perf_counter()
    run = read_recording(path).runs[0]
    n_ok = sum(h.accepted for h in iter_hits(run))
    return {"seconds": time.perf_counter() - t,
            "n_samples": run.n_hits_stored * run.n_samples * run.n_channels, "accepted": n_ok}


def w_naive(path):
    import scipy.signal

    t = time.perf_counter()
    f, ds = _open(path)
    n_hits, n, c = ds.shape
    sff = 0.0
    sfx = 0.0
    for i in range(n_hits):
        x = np.asarray(ds[i], dtype=np.float64)
        _, pff = scipy.signal.welch(x[:, 0], FS, window="boxcar", nperseg=n)
        cols = []
        for r in range(1, c):
            _, pfx = scipy.signal.csd(x[:, 0], x[:, r], FS, window="boxcar", nperseg=n)
            cols.append(pfx)
        sff = sff + pff
        sfx = sfx + np.stack(cols, axis=1)
    H = sfx / sff[:, None]
    f.close()
    np.save(Path(path).with_suffix(".naive.npy"), H[:2001])
    return {"seconds": time.perf_counter() - t, "n_samples": int(np.prod(ds.shape))}


def w_pyfrf(path):
    import pyFRF

    t = time.perf_counter()
    f, ds = _open(path)
    n_hits, n, _ = ds.shape
    frf = pyFRF.FRF(FS, fft_len=n, window="none", resp_type="a")
    for i in range(n_hits):
        x = np.asarray(ds[i], dtype=np.float64)
        frf.add_data(x[None, None, :, 0], np.ascontiguousarray(x[:, 1:].T)[None])
    H = frf.get_H1()
    f.close()
    return {"seconds": time.perf_counter() - t, "n_samples": int(np.prod(ds.shape)),
            "shape": list(H.shape)}


WORKERS = {
    "imports": w_imports,
    "floor32": w_floor32,
    "floor64": w_floor64,
    "guidefit": w_guidefit,
    "guidefit64": w_guidefit_double,
    "guidefit1": w_guidefit_one_thread,
    "core": w_guidefit_core,
    "iter_hits": w_iter_hits,
    "naive": w_naive,
    "pyfrf": w_pyfrf,
}

LABELS = {
    "imports": "(imports only: numpy, scipy, h5py, guidefit)",
    "floor32": "floor: h5py read + rfft, float32",
    "floor64": "floor: h5py read + rfft, float64",
    "guidefit": "**guidefit** compute_frf(iter_hits(read_recording))",
    "guidefit64": "guidefit, double precision (compute_frf(..., precision=\"double\"))",
    "guidefit1": "guidefit, one thread (compute_frf(..., workers=1))",
    "core": "guidefit spectral_sums only (h5py reads, no checks, no windows)",
    "iter_hits": "guidefit iter_hits only (read + hit checks, no FFT)",
    "naive": "naive per-hit scipy.signal welch + csd",
    "pyfrf": "pyFRF 1.5 add_data per hit + get_H1",
}


# --------------------------------------------------------------------------- agreement


def agreement(path: Path, n_check: int = 10) -> str:
    """Max relative difference of |H1| (bins up to 8 kHz) between guidefit (no windows),
    the naive scipy.signal H1 and pyFRF on the first ``n_check`` hits."""
    import pyFRF
    import scipy.signal

    from guidefit.frf import WindowSettings, frf_from_records

    f, ds = _open(path)
    recs = np.asarray(ds[:n_check], dtype=np.float64)
    f.close()
    n = recs.shape[1]
    g = frf_from_records(recs, FS, window=WindowSettings(none=True), precision="double").H
    g32 = frf_from_records(recs.astype(np.float32), FS, window=WindowSettings(none=True)).H
    band = slice(1, int(8000 * n / FS) + 1)
    sff = sum(scipy.signal.welch(r[:, 0], FS, window="boxcar", nperseg=n)[1] for r in recs)
    sfx = sum(np.stack([scipy.signal.csd(r[:, 0], r[:, k], FS, window="boxcar", nperseg=n)[1]
                        for k in range(1, r.shape[1])], axis=1) for r in recs)
    naive = sfx / sff[:, None]
    p = pyFRF.FRF(FS, fft_len=n, window="none", resp_type="a")
    for r in recs:
        p.add_data(r[None, None, :, 0], np.ascontiguousarray(r[:, 1:].T)[None])
    with np.errstate(divide="ignore", invalid="ignore"):
        py = (p.get_H1()[:, 0, :] / p.frf_conversion).T   # receptance -> accelerance

    def rel(a, b):
        return float(np.max(np.abs(a[band] - b[band]) / np.abs(b[band])))

    return (f"agreement on {n_check} hits, 1 Hz-8 kHz (guidefit with no windows, double precision): "
            f"max |H_naive - H_guidefit|/|H_guidefit| = {rel(naive, g):.1e}, "
            f"max |H_pyFRF - H_guidefit|/|H_guidefit| = {rel(py, g):.1e}; "
            f"guidefit single vs double precision: {rel(g32, g):.1e}")


# --------------------------------------------------------------------------- main


def run_once(name: str, path: Path) -> dict:
    m = C.measure(C.python_cmd(SCRIPT, "--worker", name, str(path)))
    if m["returncode"] != 0 or m["child"] is None:
        raise RuntimeError(f"variant {name} failed:\n{m['stderr'][-2000:]}")
    return m


def median_run(results: list[dict]) -> dict:
    """The run with the median time, with every run's time in ``all_seconds``."""
    best = sorted(results, key=lambda m: m["child"]["seconds"])[len(results) // 2]
    best["all_seconds"] = [m["child"]["seconds"] for m in results]
    return best


def run_variant(name: str, path: Path, repeat: int) -> dict:
    return median_run([run_once(name, path) for _ in range(repeat)])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="20 hits (200 for the memory run)")
    ap.add_argument("--repeat", type=int, default=None,
                    help="rounds of every variant (median shown; default 5, 1 with --quick)")
    ap.add_argument("--worker", nargs=2, metavar=("VARIANT", "FILE"), help=argparse.SUPPRESS)
    ap.add_argument("--keep", action="store_true", help="keep the generated files")
    args = ap.parse_args()
    if args.worker:
        name, path = args.worker
        w_imports(path)
        if name == "pyfrf":
            import pyFRF  # noqa: F401
        cpu0 = C.cpu_times()
        out = WORKERS[name](path)
        out["cpu_s"] = C.cpu_times() - cpu0
        C.emit(out)
        return

    n_sim, n_hits, n_big = (4, 20, 200) if args.quick else (10, 100, 1000)
    repeat = args.repeat or (1 if args.quick else 5)
    C.print_machine()
    need_gb = n_big * RECORD_S * FS * 5 * 4 / 1e9 * 1.05
    C.BENCH_DIR.mkdir(parents=True, exist_ok=True)
    if C.free_disk_gb(C.BENCH_DIR) < need_gb + 1:
        sys.exit(f"need {need_gb:.1f} GB free in {C.BENCH_DIR}")
    records, header, _ = C.simulated_hits(n_sim, RECORD_S)
    path = C.BENCH_DIR / f"frf_{n_hits}hits.h5"
    big = C.BENCH_DIR / f"frf_{n_big}hits.h5"
    with C.progress() as bar:
        if not path.exists():
            C.write_hits_file(path, records, header, n_hits, bar)
        if not big.exists():
            C.write_hits_file(big, records, header, n_big, bar)
        for p in (path, big):   # into the page cache
            with open(p, "rb") as fh:
                while fh.read(1 << 24):
                    pass
        names = ["imports", "floor32", "floor64", "guidefit", "guidefit64", "guidefit1", "core",
                 "iter_hits", "naive", "pyfrf"]
        if importlib.util.find_spec("pyFRF") is None:
            print("pyFRF is not installed (`pip install pyFRF==1.5.0`): its row is skipped\n")
            names.remove("pyfrf")
        # round after round of every variant, so that a change in the load of
        # a shared machine falls on all variants alike
        task = bar.add_task("variants", total=len(names) * repeat + 1)
        runs = {name: [] for name in names}
        for k in range(repeat):
            for name in names:
                bar.update(task, description=f"{name}, round {k + 1}/{repeat}")
                runs[name].append(run_once(name, path))
                bar.advance(task)
        res = {name: median_run(runs[name]) for name in names}
        bar.update(task, description=f"guidefit, {n_big} hits")
        res_big = run_variant("guidefit", big, 1)
        bar.advance(task)

    n_samples = res["floor32"]["child"]["n_samples"]
    print(f"{n_hits} hits x {RECORD_S} s x 5 channels at {FS / 1e3:.0f} kHz = "
          f"{n_samples / 1e6:.0f} Msamples ({path.stat().st_size / 1e6:.0f} MB float32), "
          f"page cache warm; seconds = median of {repeat} run(s) in a fresh process, variants interleaved, "
          "work only (imports excluded); RSS = peak of the whole process\n")
    f32 = res["floor32"]["child"]["seconds"]
    f64 = res["floor64"]["child"]["seconds"]
    rows = []
    for name in names:
        m = res[name]
        s = m["child"]["seconds"]
        if name == "imports":
            rows.append([LABELS[name], "-", "-", "-", "-", "-", "-", f"{m['rss_mb']:.0f}"])
            continue
        runs = ", ".join(f"{x:.2f}" for x in m["all_seconds"])
        rows.append([LABELS[name], f"{s:.2f}", runs, f"{m['child']['cpu_s']:.2f}",
                     f"{n_samples / s / 1e6:.0f}", f"{s / f32:.2f}", f"{s / f64:.2f}",
                     f"{m['rss_mb']:.0f}"])
    print(C.md_table(["variant", "s", "runs (s)", "CPU s", "Msamples/s", "x floor f32",
                      "x floor f64", "peak RSS MB"], rows))
    print()
    if "pyfrf" in names:
        print(agreement(path))
    print()
    gb = res_big
    print(C.md_table(
        ["guidefit compute_frf(iter_hits)", "hits", "file GB", "s", "Msamples/s", "peak RSS MB"],
        [[f"{n_hits} hits", n_hits, f"{path.stat().st_size / 1e9:.2f}",
          f"{res['guidefit']['child']['seconds']:.2f}",
          f"{n_samples / res['guidefit']['child']['seconds'] / 1e6:.0f}",
          f"{res['guidefit']['rss_mb']:.0f}"],
         [f"{n_big} hits", n_big, f"{big.stat().st_size / 1e9:.2f}", f"{gb['child']['seconds']:.2f}",
          f"{gb['child']['n_samples'] / gb['child']['seconds'] / 1e6:.0f}", f"{gb['rss_mb']:.0f}"]]))
    g = res["guidefit"]["child"]["seconds"]
    p = res["pyfrf"]["child"]["seconds"] if "pyfrf" in res else float("nan")
    print()
    g64 = res["guidefit64"]["child"]["seconds"]
    print("targets: guidefit within 1.3x of the floor (the file read as stored, float32, plus "
          f"scipy.fft): {g / f32:.2f}x -> {'met' if g / f32 <= 1.3 else 'NOT met'} "
          f"(double precision: {g64 / f32:.2f}x the float32 floor, {g64 / f64:.2f}x the float64 one); "
          f">= 3x faster than pyFRF: {p / g:.2f}x -> {'met' if p / g >= 3 else 'NOT met'} "
          f"(double precision: {p / g64:.2f}x); "
          f"peak RSS < 300 MB and flat: {res['guidefit']['rss_mb']:.0f} MB at {n_hits} hits, "
          f"{gb['rss_mb']:.0f} MB at {n_big} hits -> "
          f"{'met' if gb['rss_mb'] < 300 and gb['rss_mb'] < 1.2 * res['guidefit']['rss_mb'] else 'NOT met'}")
    core = res["core"]["child"]["seconds"]
    print(f"(the FFT/accumulation core alone, spectral_sums: {core / f32:.2f}x float32 floor, "
          f"{core / f64:.2f}x float64 floor, {p / core:.2f}x faster than pyFRF; reading and "
          f"checking the hits, iter_hits alone: {res['iter_hits']['child']['seconds']:.2f} s)")
    C.print_load()
    if not args.keep:
        for p_ in (path, big, path.with_suffix(".naive.npy")):
            p_.unlink(missing_ok=True)


if __name__ == "__main__":
    main()
