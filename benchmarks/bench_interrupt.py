"""Ctrl-C latency: how long ``guidefit`` takes to end after SIGINT, and what it prints.

``guidefit identify f1 f2 f3 --jobs 2`` (three copies of ``sample_data/mrb35_sample.h5``)
and ``guidefit frf`` of one copy are started N times each; SIGINT goes to the whole process
group (as a terminal's Ctrl-C does, so the workers get it too) at a random moment between
0.2 and 2.0 s (seeded). A run that finished before the signal is not counted. Reported:
exit statuses (exit 0 with nothing on stderr: the signal came while the finished command was
shutting down; its output is complete), time from the signal to the end of the process, the
most stderr lines of a run and the runs that printed a traceback.

Run: ``python benchmarks/bench_interrupt.py [--quick] [--tries N]`` (default 20; --quick 6).
"""

from __future__ import annotations

import argparse
import os
import random
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _common as C
from bench_startup import SAMPLE, guidefit_cmd


def _interrupt_once(cmd: list[str], delay_s: float, cwd: Path):
    proc = subprocess.Popen(cmd, cwd=cwd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    time.sleep(delay_s)
    if proc.poll() is not None:
        proc.communicate()
        return None
    sent = time.monotonic()
    os.killpg(proc.pid, signal.SIGINT)
    try:
        _, err = proc.communicate(timeout=120)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        _, err = proc.communicate()
    return proc.returncode, time.monotonic() - sent, len(err.splitlines()), "Traceback" in err


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--tries", type=int, default=None)
    ap.add_argument("--python-m", action="store_true",
                    help="run 'python -m guidefit' (with PYTHONPATH=<other checkout>: measure another version)")
    args = ap.parse_args()
    tries = args.tries or (6 if args.quick else 20)
    C.print_machine()
    folder = C.BENCH_DIR / "interrupt"
    folder.mkdir(parents=True, exist_ok=True)
    files = []
    for i in range(3):
        target = folder / f"rec{i}.h5"
        shutil.copyfile(SAMPLE, target)
        files.append(str(target))
    exe = [sys.executable, "-m", "guidefit"] if args.python_m else guidefit_cmd()
    commands = {
        "identify 3 files --jobs 2": [*exe, "identify", *files, "--jobs", "2", "--csv", "rows.csv"],
        "frf --out frf.csv": [*exe, "frf", files[0], "--out", "frf.csv"],
    }
    rng = random.Random(1)
    rows = []
    for name, cmd in commands.items():
        samples = [s for s in (_interrupt_once(cmd, rng.uniform(0.2, 2.0), folder) for _ in range(tries)) if s]
        times = sorted(s[1] for s in samples)
        finished = sum(s[0] == 0 and s[2] == 0 for s in samples)  # the signal came as it shut down
        rows.append([name, len(samples), sum(s[0] == 130 for s in samples), finished,
                     C.fmt(times[len(times) // 2]), C.fmt(times[-1]), max(s[2] for s in samples),
                     sum(s[3] for s in samples)])
    print(C.md_table(["command", "interrupts", "exit 130", "exit 0 (had finished)", "median s", "max s",
                      "max stderr lines", "tracebacks"], rows))
    C.print_load()


if __name__ == "__main__":
    main()
