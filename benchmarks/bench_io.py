"""Peak memory and time of the streaming readers against file size.

For each reader (contract HDF5, contract CSV, and the DAQ formats a test
setup reads: NI TDMS, ASAM MDF 4, WAV, a European text export, MATLAB 7.3)
a recording of each size is written once, then read in a fresh process
measured with ``/usr/bin/time -v``: ``read_recording`` (for a DAQ format:
of a ``.toml`` setup beside the DAQ file) plus every sample of every run
through ``open_reader`` (``read_block`` in blocks of 1 000 000 samples, or
``read_hits`` in blocks of 8 hits: what hit detection does). The table gives
wall and CPU time, peak RSS, and peak RSS over the file size (the DAQ
file's size, not the setup's); the baseline (``python -c "import
guidefit.io, numpy, h5py"``) is measured too, so the reader's own share can
be told.

    python benchmarks/bench_io.py [--quick] [--format csv,h5] [--sizes-mb 50,200,800]
    python benchmarks/bench_io.py --format tdms,mdf,wav,text,mat73 --sizes-mb 25,100,300
    python benchmarks/bench_io.py --worker FILE      # one measured read (internal)

``--old DIR`` also measures the readers of another checkout (``DIR`` holds
its ``guidefit`` package), e.g. the commit before the CSV reader streamed.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import (
    BENCH_DIR,
    cpu_times,
    emit,
    md_table,
    measure,
    print_load,
    print_machine,
    progress,
    simulated_hits,
)

BLOCK_SAMPLES = 1_000_000
BLOCK_HITS = 8


# --------------------------------------------------------------------------- worker


def worker(path: str) -> None:
    """Read ``path`` whole through the public API; print timings as JSON."""
    t0, c0 = time.perf_counter(), cpu_times()
    old = os.environ.get("GUIDEFIT_BENCH_OLD")
    if old:  # another checkout: ahead of the editable install's finder
        sys.meta_path[:] = [f for f in sys.meta_path if "editable" not in getattr(f, "__name__", type(f).__name__).lower()]
        sys.path.insert(0, old)
    import guidefit

    if old:
        assert guidefit.__file__.startswith(old), guidefit.__file__
    try:
        from guidefit.io import open_reader, read_recording
    except ImportError:  # before guidefit.io
        from guidefit.io import open_reader, read_recording

    rec = read_recording(path)
    t_open = time.perf_counter() - t0
    total = 0.0
    samples = 0
    anon = file_mb = 0.0
    for run in rec.runs:
        with open_reader(run) as reader:
            if run.layout == "signals":
                for start in range(0, run.n_samples, BLOCK_SAMPLES):
                    block = reader.read_block(start, min(run.n_samples, start + BLOCK_SAMPLES))
                    total += float(block[:, run.force_index].sum())
                    samples += block.shape[0]
                    now = _rss_parts()
                    anon, file_mb = max(anon, now[0]), max(file_mb, now[1])
            else:
                for first in range(0, run.n_hits_stored, BLOCK_HITS):
                    block = reader.read_hits(first, min(run.n_hits_stored, first + BLOCK_HITS))
                    total += float(block[..., run.force_index].sum())
                    samples += block.shape[0] * block.shape[1]
    emit({"open_s": t_open, "total_s": time.perf_counter() - t0, "cpu_s": cpu_times() - c0,
          "samples": samples, "checksum": total, "anon_mb": anon, "file_mb": file_mb})


def _rss_parts() -> tuple[float, float]:
    """(anonymous, file-backed) resident MB now (Linux /proc): a memory-mapped file's pages
    (asammdf maps the MDF file) are file-backed and the kernel can drop them."""
    import re

    try:
        text = Path("/proc/self/status").read_text()
        return tuple(int(re.search(rf"{key}:\s+(\d+)", text).group(1)) / 1024 for key in ("RssAnon", "RssFile"))
    except (OSError, AttributeError):
        return (0.0, 0.0)


# --------------------------------------------------------------------------- data


def _header_and_rows(target_rows: int, quantised: bool = False):
    """A signals RunData header and a generator of float32 blocks (simulated hits, tiled;
    each copy scaled by a random gain, or, ``quantised``, as the simulated ADC gave them:
    short decimal numbers such as -0.03125)."""
    from dataclasses import replace

    records, header, _ = simulated_hits(8, 0.1)
    records = records.reshape(-1, records.shape[-1])  # hits back to back: one continuous record
    header = replace(header, layout="signals", pretrigger_samples=None)

    def blocks():
        done, k = 0, 0
        rng = np.random.default_rng(1)
        while done < target_rows:
            gain = np.float32(1.0 if quantised else rng.uniform(0.6, 1.4))
            block = records[: target_rows - done] * gain
            done += block.shape[0]
            k += 1
            yield block

    return header, blocks


def write_csv_of_size(path: Path, size_mb: float, quantised: bool = False) -> None:
    """A contract CSV of about ``size_mb`` MB, written block by block."""
    from dataclasses import replace

    from guidefit.io import write_recording

    header, blocks = _header_and_rows(20000, quantised)
    probe = path.with_suffix(".probe.csv")
    write_recording(probe, replace(header, data=next(blocks())))
    bytes_per_row = (probe.stat().st_size - 800) / 20000
    probe.unlink()
    rows = int(size_mb * 1e6 / bytes_per_row)
    header, blocks = _header_and_rows(rows, quantised)
    fs = header.sample_rate_hz
    gen = blocks()
    write_recording(path, replace(header, data=next(gen)))
    with open(path, encoding="utf-8") as fh:
        done = sum(1 for line in fh if line[:1].isdigit() or line[:1] == "-")
    with open(path, "a", encoding="utf-8") as fh:
        for block in gen:
            time_s = (done + np.arange(block.shape[0])) / fs
            np.savetxt(fh, np.column_stack([time_s, block.astype(np.float64)]), delimiter=",",
                       fmt=["%.10g"] + ["%.17g"] * block.shape[1])
            done += block.shape[0]


def write_h5_of_size(path: Path, size_mb: float) -> None:
    """A contract HDF5 signals run of about ``size_mb`` MB (float32, uncompressed)."""
    from guidefit.io import open_signals_writer

    header, _ = _header_and_rows(1)
    rows = int(size_mb * 1e6 / (4 * header.n_channels))
    header, blocks = _header_and_rows(rows)
    with open_signals_writer(path, header, dtype=np.float32) as writer:
        for block in blocks():
            writer.append(block)


WRITERS = {
    "csv": write_csv_of_size,
    "csv-adc": lambda path, size: write_csv_of_size(path, size, quantised=True),
    "h5": write_h5_of_size,
}


# ------------------------------------------------------------- DAQ files + setups


def _daq_rows(size_mb: float, bytes_per_row: float):
    rows = int(size_mb * 1e6 / bytes_per_row)
    return _header_and_rows(rows)


def _write_setup(path: Path, daq_name: str, header, sources, extra_run: str = "") -> None:
    """The test setup beside a DAQ file (``scale = 1``: the file holds N and m/s^2)."""
    lines = ['format = "guidefit-setup"', "format_version = 1"]
    for name, source in zip(header.channel_names, sources):
        unit = "N" if name == "force" else "m/s^2"
        lines += [f"[channels.{name}]", f"source = {source!r}".replace("'", '"'), f'unit = "{unit}"', "scale = 1.0"]
    d = header.excitation_direction
    lines += [f"[runs.{header.name}]", f'file = "{daq_name}"',
              f"excitation_direction = [{d[0]!r}, {d[1]!r}, {d[2]!r}]", extra_run]
    path.write_text("\n".join(lines) + "\n")


def write_tdms_of_size(path: Path, size_mb: float) -> Path:
    """NI TDMS, float32, one segment per block (as a DAQ streams); returns the DAQ file."""
    from nptdms import ChannelObject, TdmsWriter

    header, blocks = _daq_rows(size_mb, 4 * 5)
    daq = path.with_suffix(".tdms")
    names = [f"Ch{k}" for k in range(header.n_channels)]
    with TdmsWriter(daq) as writer:
        for block in blocks():
            writer.write_segment([
                ChannelObject("run", name, np.ascontiguousarray(block[:, k]),
                              properties={"wf_increment": 1.0 / header.sample_rate_hz, "unit_string": "N"
                                          if k == 0 else "m/s^2"})
                for k, name in enumerate(names)
            ])
    _write_setup(path, daq.name, header, names)
    return daq


def write_mdf_of_size(path: Path, size_mb: float) -> Path:
    """ASAM MDF 4.10, float32 channels and a float64 time channel, extended block by block."""
    from asammdf import MDF, Signal

    header, blocks = _daq_rows(size_mb, 4 * 5 + 8)
    daq = path.with_suffix(".mf4")
    names = [f"Ch{k}" for k in range(header.n_channels)]
    done = 0
    with MDF(version="4.10") as mdf:
        for block in blocks():
            t = (done + np.arange(block.shape[0])) / header.sample_rate_hz
            if done == 0:
                mdf.append([Signal(np.ascontiguousarray(block[:, k]), t, name=n) for k, n in enumerate(names)])
            else:
                mdf.extend(0, [(t, None)] + [(np.ascontiguousarray(block[:, k]), None) for k in range(len(names))])
            done += block.shape[0]
        mdf.save(daq, overwrite=True)
    _write_setup(path, daq.name, header, names)
    return daq


def write_wav_of_size(path: Path, size_mb: float) -> Path:
    """WAV, 32-bit float samples written block by block."""
    import soundfile

    header, blocks = _daq_rows(size_mb, 4 * 5)
    daq = path.with_suffix(".wav")
    with soundfile.SoundFile(daq, "w", samplerate=int(header.sample_rate_hz), channels=header.n_channels,
                             subtype="FLOAT") as f:
        for block in blocks():
            f.write(block)
    _write_setup(path, daq.name, header, list(range(header.n_channels)))
    return daq


def write_text_of_size(path: Path, size_mb: float) -> Path:
    """A European text export: preamble, ';' between fields, decimal commas, a unit row, time column."""
    import io

    header, blocks = _daq_rows(size_mb, 6 * 12)
    daq = path.with_suffix(".csv")
    names = [f"Ch{k}" for k in range(header.n_channels)]
    done = 0
    with open(daq, "w", encoding="utf-8") as fh:
        fh.write("Messung;Hammertest\nDatum;20.11.2026\n\n")
        fh.write(";".join(["Zeit"] + names) + "\n" + ";".join(["s"] + ["N"] + ["m/s^2"] * (len(names) - 1)) + "\n")
        for block in blocks():
            t = (done + np.arange(block.shape[0])) / header.sample_rate_hz
            buf = io.StringIO()
            np.savetxt(buf, np.column_stack([t, block.astype(np.float64)]), delimiter=";", fmt="%.7g")
            fh.write(buf.getvalue().replace(".", ","))
            done += block.shape[0]
    _write_setup(path, daq.name, header, names)
    return daq


def write_mat73_of_size(path: Path, size_mb: float) -> Path:
    """MATLAB 7.3 (HDF5 after a 512-byte header): a samples x channels single array, transposed as
    MATLAB stores it, and fs."""
    import h5py

    header, blocks = _daq_rows(size_mb, 4 * 5)
    daq = path.with_suffix(".mat")
    n = sum(block.shape[0] for block in blocks())
    with h5py.File(daq, "w", userblock_size=512) as f:
        ds = f.create_dataset("data", shape=(header.n_channels, n), dtype=np.float32)
        ds.attrs["MATLAB_class"] = np.bytes_("single")
        fs = f.create_dataset("fs", data=np.array([[header.sample_rate_hz]]))
        fs.attrs["MATLAB_class"] = np.bytes_("double")
        done = 0
        for block in blocks():
            ds[:, done:done + block.shape[0]] = block.T
            done += block.shape[0]
    with open(daq, "r+b") as fh:
        fh.write(b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created by guidefit bench_io. HDF5 schema 1.00 .")
    _write_setup(path, daq.name, header, [f"data:{k}" for k in range(header.n_channels)])
    return daq


DAQ_LIBRARIES = {"tdms": "nptdms", "mdf": "asammdf", "wav": "soundfile", "text": "scipy", "mat73": "scipy.io"}

DAQ_WRITERS = {
    "tdms": write_tdms_of_size,
    "mdf": write_mdf_of_size,
    "wav": write_wav_of_size,
    "text": write_text_of_size,
    "mat73": write_mat73_of_size,
}


# --------------------------------------------------------------------------- main


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--worker")
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--format", default="csv,csv-adc,h5")
    parser.add_argument("--sizes-mb", default=None)
    parser.add_argument("--old", default=None, help="folder holding another checkout's guidefit package")
    args = parser.parse_args()
    if args.worker:
        worker(args.worker)
        return
    sizes = [float(s) for s in (args.sizes_mb or ("20,80" if args.quick else "50,200,800")).split(",")]
    formats = args.format.split(",")
    print_machine()
    base = measure([sys.executable, "-c", "import guidefit.io, numpy, h5py"])
    print(f"baseline (import guidefit.io, numpy, h5py): peak RSS {base['rss_mb']:.0f} MB")
    bases = {fmt: base for fmt in formats}
    for fmt in formats:  # a DAQ reader's library is part of its baseline (asammdf alone is ~50 MB)
        library = DAQ_LIBRARIES.get(fmt)
        if library:
            bases[fmt] = measure([sys.executable, "-c", f"import guidefit.io.setup, numpy, h5py, {library}"])
            print(f"baseline of {fmt} (import guidefit.io.setup, numpy, h5py, {library}): "
                  f"peak RSS {bases[fmt]['rss_mb']:.0f} MB")
    print()
    BENCH_DIR.mkdir(parents=True, exist_ok=True)
    rows = []
    variants = [("this checkout", None)] + ([("--old", args.old)] if args.old else [])
    with progress() as bar:
        task = bar.add_task("reading", total=len(sizes) * len(formats) * len(variants))
        for fmt in formats:
            for size in sizes:
                path = BENCH_DIR / f"io_{size:g}MB_{fmt}.{'toml' if fmt in DAQ_WRITERS else fmt.split('-')[0]}"
                daq = path
                if fmt in DAQ_WRITERS:
                    bar.update(task, description=f"writing {path.name}")
                    daq = DAQ_WRITERS[fmt](path, size)
                elif not path.exists():
                    bar.update(task, description=f"writing {path.name}")
                    WRITERS[fmt](path, size)
                file_mb = daq.stat().st_size / 1e6
                for label, old in variants:
                    bar.update(task, description=f"reading {path.name} ({label})")
                    env = dict(os.environ)
                    if old:
                        env["GUIDEFIT_BENCH_OLD"] = str(Path(old).resolve())
                    m = measure([sys.executable, __file__, "--worker", str(path)], env=env)
                    if m["returncode"] != 0:
                        raise SystemExit(f"worker failed on {path}: {m['stderr'][-500:]}")
                    child = m["child"]
                    rows.append([fmt, label, f"{file_mb:.0f}", f"{child['samples'] / 1e6:.1f}",
                                 f"{child['open_s']:.2f}", f"{m['wall_s']:.2f}", f"{m['cpu_s']:.2f}",
                                 f"{m['rss_mb']:.0f}", f"{m['rss_mb'] / file_mb:.2f}",
                                 f"{(m['rss_mb'] - bases[fmt]['rss_mb']) / file_mb:.2f}",
                                 f"{child.get('anon_mb', 0):.0f} / {child.get('file_mb', 0):.0f}"])
                    bar.advance(task)
                if size > 100 or daq is not path:
                    path.unlink()
                    if daq is not path:
                        daq.unlink()
    print(md_table(["format", "reader", "file MB", "rows (M)", "read_recording s", "wall s",
                    "CPU s", "peak RSS MB", "RSS / file", "(RSS - baseline) / file",
                    "anon / file-backed MB (sampled)"], rows))
    print_load()


if __name__ == "__main__":
    main()
