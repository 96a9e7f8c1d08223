"""identify end to end on a 100-hit, 0.5 s, 200 kHz recording against the read + one-FFT floor.

Issue 13's budget: ``guidefit.identify`` on a 100-hit, 0.5 s, 200 kHz
recording (force + 4 accelerometers, float32, one vertical run) within 1.5x
the time of a process that only reads the hits and makes one real FFT pass
(``floor32`` of bench_frf.py). The file is the one bench_frf.py writes
(simulated hits tiled with random gains). Each variant runs in its own
child process, round after round (median shown); imports are excluded from
the timed work, the page cache is warm.

Variants:

floor (float32)
    bench_frf.py's ``w_floor32``: h5py ``ds[i]`` per hit + ``scipy.fft.rfft``.
guidefit FRF only
    ``compute_frf(run, iter_hits(run))`` (bench_frf.py's ``w_guidefit``).
identify
    ``guidefit.identify(path)``: hits, checks, FRFs with the jackknife sums,
    the global modal fit (LSCF diagram, refinement, jackknife over hit
    groups), shapes, labels, sensor check, gate, Eq. (24)-(29).

The same comparison as whole processes (interpreter start and imports
included, timed from outside): a minimal floor script (``python -c``:
imports h5py and scipy.fft, reads every hit, one rfft each) against the
command ``guidefit identify FILE`` (its imports, the work, the rich table).

The default file is the paper's own test as most labs record it (issue 20):
two runs of 50 hits each, 0.5 s at 200 kHz, force + four accelerometers
along one axis per run (y at A-D hit vertically, x at A-D hit laterally),
simulated by ``guidefit simulate --sensors default`` (all five carriage
modes in it, float32, uncompressed). ``--file single-run`` keeps issue 13's
file (one vertical run of 100 hits tiled from simulated ones). The floor
reads every run's hits.

Run: ``python benchmarks/bench_identify_e2e.py [--quick] [--repeat N] [--file one-axis|single-run]``.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import _common as C
import bench_frf as F

SCRIPT = Path(__file__).resolve()


def w_identify(path):
    from guidefit.identify import IdentifySettings, identify
    from guidefit.model.guides import load_guide

    guide = load_guide("MRB35")
    t = time.perf_counter()
    result = identify(path, guide=guide, settings=IdentifySettings())
    dt = time.perf_counter() - t
    f_v = next((m.frequency_hz for m in result.modes if m.label == "vertical"), float("nan"))
    return {"seconds": dt, "f_V_hz": f_v, "n_modes": len(result.modes), "gate": result.gate}


def w_floor_all(path):
    """bench_frf.py's float32 floor over every run of the file: h5py ``ds[i]`` per hit + ``scipy.fft.rfft``."""
    import h5py
    import scipy.fft

    t = time.perf_counter()
    acc, n = 0.0, 0
    with h5py.File(path, "r") as f:
        for run in f["runs"].values():
            ds = run["hits"]
            n += int(ds.size)
            for i in range(ds.shape[0]):
                acc += float(abs(scipy.fft.rfft(ds[i], axis=0, workers=2)[1, 0]))
    return {"seconds": time.perf_counter() - t, "n_samples": n, "check": acc}


def w_frf_all(path):
    """``compute_frf(run, iter_hits(run))`` of every run, timed."""
    from guidefit.frf import compute_frf
    from guidefit.hits import iter_hits
    from guidefit.io import read_recording

    t = time.perf_counter()
    n = 0
    for run in read_recording(path).runs:
        n += compute_frf(run, iter_hits(run)).n_averages
    return {"seconds": time.perf_counter() - t, "n_averages": n}


WORKERS = {"floor32": w_floor_all, "frf": w_frf_all, "identify": w_identify}
LABELS = {"floor32": "floor (float32): read + one rfft pass", "frf": "guidefit FRF only (compute_frf)",
          "identify": "guidefit identify, end to end"}


#: the floor as a whole process: nothing imported but what reading and one FFT need
FLOOR_PROCESS = """
import sys
import h5py
import scipy.fft
with h5py.File(sys.argv[1], "r") as f:
    acc = 0.0
    for run in f["runs"].values():
        ds = run["hits"]
        for i in range(ds.shape[0]):
            acc += float(abs(scipy.fft.rfft(ds[i], axis=0, workers=2)[1, 0]))
print(acc)
"""


def one_axis_file(path: Path, hits_per_run: int, bar=None) -> None:
    """The paper's two runs, one axis per run (guidefit.simulate, --sensors default), float32, uncompressed."""
    from guidefit.io import write_recording
    from guidefit.simulate import SimulationConfig, simulate

    cfg = SimulationConfig(hits=hits_per_run, record_s=F.RECORD_S, sensor_layout="default")
    data, _ = simulate("MRB35", config=cfg, seed=20)
    write_recording(path, data)


def process_cmd(name: str, path: Path) -> list[str]:
    """The whole-process variants: the floor script, or ``guidefit identify FILE``."""
    if name == "floor_process":
        return [sys.executable, "-c", FLOOR_PROCESS, str(path)]
    exe = shutil.which("guidefit")
    return ([exe] if exe else [sys.executable, "-m", "guidefit"]) + ["identify", str(path)]


PROCESSES = {"floor_process": "floor as a process: python -c (h5py, scipy.fft; read + one rfft pass)",
             "cli": "guidefit identify FILE (the command, whole process)"}


def run_process(name: str, path: Path) -> dict:
    m = C.measure(process_cmd(name, path))
    if m["returncode"] not in (0, 1):  # 1: a gate or check, still a whole run
        raise RuntimeError(f"{name} failed:\n{m['stderr'][-2000:]}")
    return m


def run_once(name: str, path: Path) -> dict:
    m = C.measure(C.python_cmd(SCRIPT, "--worker", name, str(path)))
    if m["returncode"] != 0 or m["child"] is None:
        raise RuntimeError(f"variant {name} failed:\n{m['stderr'][-2000:]}")
    return m


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="20 hits")
    ap.add_argument("--repeat", type=int, default=None, help="rounds (median shown; default 3, 1 with --quick)")
    ap.add_argument("--file", choices=("one-axis", "single-run"), default="one-axis",
                    help="one-axis: two runs of 50 hits, one axis per run (default); single-run: issue 13's file")
    ap.add_argument("--worker", nargs=2, metavar=("VARIANT", "FILE"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        name, path = args.worker
        F.w_imports(path)

        cpu0 = C.cpu_times()
        out = WORKERS[name](path)
        out["cpu_s"] = C.cpu_times() - cpu0
        C.emit(out)
        return
    n_sim, n_hits = (4, 20) if args.quick else (10, 100)
    repeat = args.repeat or (1 if args.quick else 3)
    C.print_machine()
    C.BENCH_DIR.mkdir(parents=True, exist_ok=True)
    path = C.BENCH_DIR / f"e2e_{n_hits}hits_{args.file}.h5"
    with C.progress() as bar:
        if not path.exists() and args.file == "one-axis":
            one_axis_file(path, n_hits // 2, bar)
        elif not path.exists():
            records, header, _ = C.simulated_hits(n_sim, F.RECORD_S)
            C.write_hits_file(path, records, header, n_hits, bar)
        with open(path, "rb") as fh:  # into the page cache
            while fh.read(1 << 24):
                pass
        task = bar.add_task("variants", total=(len(WORKERS) + len(PROCESSES)) * repeat)
        runs = {name: [] for name in WORKERS}
        procs = {name: [] for name in PROCESSES}
        for k in range(repeat):
            for name in WORKERS:
                bar.update(task, description=f"{name}, round {k + 1}/{repeat}")
                runs[name].append(run_once(name, path))
                bar.advance(task)
            for name in PROCESSES:
                bar.update(task, description=f"{name}, round {k + 1}/{repeat}")
                procs[name].append(run_process(name, path))
                bar.advance(task)
    res = {name: sorted(ms, key=lambda m: m["child"]["seconds"])[len(ms) // 2] for name, ms in runs.items()}
    floor = res["floor32"]["child"]["seconds"]
    rows = []
    for name, m in res.items():
        s = m["child"]["seconds"]
        rows.append([LABELS[name], f"{s:.2f}", ", ".join(f"{x['child']['seconds']:.2f}" for x in runs[name]),
                     f"{m['child']['cpu_s']:.2f}", f"{s / floor:.2f}", f"{m['rss_mb']:.0f}"])
    kind = "two runs, one axis per run" if args.file == "one-axis" else "one vertical run"
    print(f"{n_hits} hits ({kind}) x {F.RECORD_S} s x 5 channels at {F.FS / 1e3:.0f} kHz, float32, page cache warm; "
          f"median of {repeat} round(s), variants interleaved\n")
    print(C.md_table(["variant", "s", "runs (s)", "CPU s", "x floor", "peak RSS MB"], rows))
    ident = res["identify"]["child"]
    ratio = ident["seconds"] / floor
    print(f"\nidentify: f_V = {ident['f_V_hz']:.2f} Hz, {ident['n_modes']} modes, gate: {ident['gate']}")
    print(f"target: identify within 1.5x the floor: {ratio:.2f}x -> {'met' if ratio <= 1.5 else 'NOT met'}")
    walls = {name: sorted(m["wall_s"] for m in ms) for name, ms in procs.items()}
    floor_p = walls["floor_process"][len(walls["floor_process"]) // 2]
    prow = []
    for name, w in walls.items():
        med = w[len(w) // 2]
        cpu = sorted(m["cpu_s"] for m in procs[name])[len(w) // 2]
        rss = max(m["rss_mb"] for m in procs[name])
        prow.append([PROCESSES[name], f"{med:.2f}", ", ".join(f"{x:.2f}" for x in w), f"{cpu:.2f}",
                     f"{med / floor_p:.2f}", f"{rss:.0f}"])
    print("\nwhole processes (interpreter start and imports included), median:\n")
    print(C.md_table(["process", "wall s", "runs (s, sorted)", "CPU s", "x floor process", "peak RSS MB"], prow))
    C.print_load()
    path.unlink(missing_ok=True)


if __name__ == "__main__":
    main()
