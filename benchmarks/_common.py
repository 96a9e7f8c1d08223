"""Shared helpers of the benchmark scripts (not part of the guidefit package).

Machine description, child processes measured with ``/usr/bin/time -v``
(wall time and peak RSS), markdown tables, rich progress bars, and test data:
hits simulated once with :mod:`guidefit.simulate` (cached under
``BENCH_DIR``) and tiled with varying gains into large recordings.
"""

from __future__ import annotations

import json
import os
import platform
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
#: Scratch folder for generated recordings (override with GUIDEFIT_BENCH_DIR).
BENCH_DIR = Path(os.environ.get("GUIDEFIT_BENCH_DIR", "/tmp/guidefit-bench"))
TIME_BIN = "/usr/bin/time"


# --------------------------------------------------------------------------- machine


def machine_info() -> dict:
    """nproc, CPU model, RAM, versions, git commit, load average."""
    import h5py
    import scipy

    cpu = "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    mem_gb = None
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal"):
                mem_gb = round(int(line.split()[1]) / 2**20, 1)
    except OSError:
        pass
    try:
        commit = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short", "HEAD"],
                                capture_output=True, text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(REPO), "status", "--porcelain", "guidefit"],
                               capture_output=True, text=True, check=True).stdout.strip()
        if dirty:
            commit += " (guidefit/ has uncommitted changes)"
    except (OSError, subprocess.CalledProcessError):
        commit = "unknown"
    return {
        "nproc": os.cpu_count(),
        "cpu": cpu,
        "mem_gb": mem_gb,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "h5py": h5py.__version__,
        "commit": commit,
        "load": os.getloadavg(),
    }


def print_machine(extra: str = "") -> dict:
    info = machine_info()
    load = ", ".join(f"{x:.2f}" for x in info["load"])
    print(f"machine: nproc {info['nproc']}, {info['cpu']}, {info['mem_gb']} GB RAM; "
          f"Python {info['python']}, numpy {info['numpy']}, scipy {info['scipy']}, "
          f"h5py {info['h5py']}; guidefit {info['commit']}; load average {load} at start"
          + (f"; {extra}" if extra else ""))
    print()
    return info


def print_load(label: str = "at end") -> None:
    print(f"\nload average {label}: {', '.join(f'{x:.2f}' for x in os.getloadavg())}")


# --------------------------------------------------------------------------- output


def md_table(headers: list[str], rows: list[list]) -> str:
    """A markdown table; floats are printed as given (format them before)."""
    out = ["| " + " | ".join(headers) + " |",
           "|" + "|".join("---" if i == 0 else "---:" for i in range(len(headers))) + "|"]
    for row in rows:
        out.append("| " + " | ".join(str(c) for c in row) + " |")
    return "\n".join(out)


def progress():
    """A rich progress bar on stderr (the tables go to stdout)."""
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    return Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                    TimeElapsedColumn(), console=Console(stderr=True), transient=True)


def fmt(x, digits=3) -> str:
    if x is None or (isinstance(x, float) and not np.isfinite(x)):
        return "-"
    return f"{x:.{digits}g}"


# --------------------------------------------------------------------------- child processes


def measure(cmd: list[str], env: dict | None = None, timeout: float | None = None) -> dict:
    """Run ``cmd`` under ``/usr/bin/time -v``; wall s, user+sys CPU s, peak RSS MB, exit code.

    The child's stdout is returned; if its last line is a JSON object it is
    parsed into ``"child"`` (the scripts' workers print their own timings).
    """
    with tempfile.NamedTemporaryFile("r", suffix=".time") as tf:
        full = [TIME_BIN, "-v", "-o", tf.name, *cmd]
        t0 = time.perf_counter()
        proc = subprocess.run(full, check=False, capture_output=True, text=True, env=env, timeout=timeout)
        wall = time.perf_counter() - t0
        report = Path(tf.name).read_text()
    rss_kb = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", report).group(1))
    user = float(re.search(r"User time \(seconds\): ([\d.]+)", report).group(1))
    system = float(re.search(r"System time \(seconds\): ([\d.]+)", report).group(1))
    child = None
    lines = proc.stdout.strip().splitlines()
    if lines and lines[-1].startswith("{"):
        try:
            child = json.loads(lines[-1])
        except json.JSONDecodeError:
            child = None
    return {"wall_s": wall, "cpu_s": user + system, "rss_mb": rss_kb / 1024.0,
            "returncode": proc.returncode, "stdout": proc.stdout, "stderr": proc.stderr,
            "child": child}


def python_cmd(script: Path, *args: str) -> list[str]:
    return [sys.executable, str(script), *args]


def emit(result: dict) -> None:
    """Worker side: print the result as the last stdout line (JSON)."""
    print(json.dumps(result), flush=True)


def cpu_times() -> float:
    t = os.times()
    return t.user + t.system


# --------------------------------------------------------------------------- data


def channel_names(sensors="ABCD", axes="y") -> list[str]:
    return ["force"] + [f"acc_{p}_{a}" for p in sensors for a in axes]


def simulated_hits(n_hits: int, record_s: float, seed: int = 0, run: str = "vertical",
                   axes: str = "y"):
    """(records float32 (n_hits, n, 1 + 4 len(axes)), RunData header, truth) of a guidefit simulation.

    Cached as ``.npz`` + ``.json`` under BENCH_DIR (simulating costs ~1 s per 0.5 s hit).
    """
    from dataclasses import replace

    from guidefit.simulate import DEFAULT_RUNS, SimulationConfig, simulate

    BENCH_DIR.mkdir(parents=True, exist_ok=True)
    key = f"sim_{run}_{axes}_{n_hits}x{record_s:g}s_seed{seed}"
    npz, meta = BENCH_DIR / f"{key}.npz", BENCH_DIR / f"{key}.json"
    runs = tuple(r for r in DEFAULT_RUNS if r.name == run)
    cfg = SimulationConfig(runs=runs, hits=n_hits, record_s=record_s, axes=axes)
    if npz.exists() and meta.exists():
        records = np.load(npz)["records"]
        truth = json.loads(meta.read_text())
    else:
        data, truth = simulate("MRB35", config=cfg, seed=seed, progress=True)
        records = data.runs[0].data
        np.savez(npz, records=records)
        meta.write_text(json.dumps(truth, default=float))
    # the header (geometry, units, pretrigger) from a tiny simulation of the same set-up
    tiny, _ = simulate("MRB35", config=replace(cfg, hits=1, record_s=0.002), seed=seed)
    header = replace(tiny.runs[0], data=None, pretrigger_samples=tiny.runs[0].pretrigger_samples)
    return records, header, truth


def gains(n: int, seed: int = 7) -> np.ndarray:
    """Per-copy gains in [0.6, 1.4]: force and responses scaled alike (the FRF is unchanged)."""
    return np.random.default_rng(seed).uniform(0.6, 1.4, n).astype(np.float32)


def write_hits_file(path: Path, records: np.ndarray, header, n_hits: int, bar=None) -> Path:
    """A ``hits``-layout recording of ``n_hits`` records, tiling ``records`` with gains.

    Written with guidefit's writer for the first copy (so the layout, chunking
    and attributes are guidefit's own), then grown with h5py one hit at a time
    (bounded memory, any size).
    """
    from dataclasses import replace

    import h5py

    from guidefit.io import RecordingData, write_recording

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    n_src = records.shape[0]
    g = gains(n_hits)
    first = min(n_src, n_hits)
    write_recording(path, RecordingData((replace(header, data=records[:first] * g[:first, None, None],
                                                 layout="hits"),), guide="MRB35",
                                        description="guidefit benchmark (tiled simulated hits)"))
    if n_hits > first:
        with h5py.File(path, "r+") as f:
            ds = f["runs"][header.name]["hits"]
            # hits datasets are fixed-size: copy into a bigger one with the same chunks and attrs
            attrs = [(k, ds.attrs[k], ds.attrs.get_id(k).dtype) for k in ds.attrs]
            chunks = ds.chunks
            del f["runs"][header.name]["hits"]
            big = f["runs"][header.name].create_dataset(
                "hits", shape=(n_hits,) + records.shape[1:], dtype=np.float32, chunks=chunks)
            for k, v, dtype in attrs:
                big.attrs.create(k, v, dtype=dtype)
            task = bar.add_task(f"writing {path.name}", total=n_hits) if bar else None
            for i in range(n_hits):
                big[i] = records[i % n_src] * g[i]
                if bar:
                    bar.advance(task)
            if bar:
                bar.remove_task(task)
    return path


def free_disk_gb(path: Path) -> float:
    st = os.statvfs(path)
    return st.f_bavail * st.f_frsize / 1e9
