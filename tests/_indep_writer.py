"""A second, independent writer of contract recordings (shared/recording-format.md, version 1).

It writes with h5py and the csv module directly (never guidefit's writer), and
every choice the contract leaves to a writer is a keyword, so that a reader
path that only works with guidefit's own choices shows up. The samples come from
a :class:`guidefit.io.RecordingData` (the simulator's), as plain arrays.
"""

from __future__ import annotations

import csv

import h5py
import numpy as np

TEXT_ENCODINGS = ("vlen_str", "fixed_bytes", "vlen_bytes", "object_str")


def _text(values, encoding):
    """A list of text as one of the encodings an HDF5 writer may choose."""
    values = list(values)
    if encoding == "vlen_str":
        return np.array(values, dtype=h5py.string_dtype("utf-8"))
    if encoding == "vlen_bytes":
        return np.array([v.encode() for v in values], dtype=h5py.string_dtype("ascii"))
    if encoding == "fixed_bytes":
        return np.array([v.encode() for v in values], dtype=f"S{max(len(v) for v in values)}")
    if encoding == "object_str":
        return values  # a Python list: h5py picks the dtype
    raise ValueError(encoding)


def _scalar_text(value, encoding):
    if encoding == "fixed_bytes":
        return np.bytes_(value.encode())
    if encoding == "vlen_bytes":
        return value.encode()
    return value


def _number(value, kind):
    """A number as a writer may store it: numpy float, int, 1-element array, Python float."""
    if kind == "np_float":
        return np.float64(value)
    if kind == "int":
        return np.int64(round(value))
    if kind == "array1":
        return np.array([value], dtype=np.float64)
    if kind == "float32":
        return np.float32(value)
    return float(value)


def _vector(value, kind):
    if kind == "list":
        return [float(v) for v in np.asarray(value).ravel()]
    if kind == "float32":
        return np.asarray(value, np.float32)
    if kind == "int":
        return np.asarray(np.rint(value), np.int64)
    return np.asarray(value, np.float64)


def _run_order(run, channel_order, flip):
    names = list(run.channel_names)
    order = list(range(len(names))) if channel_order is None else list(channel_order(names))
    data = np.asarray(run.data, np.float64)[..., order]
    pos = np.asarray(run.positions_m, float)[order]
    dirs = np.asarray(run.directions, float)[order].copy()
    out_names = [names[i] for i in order]
    units = [run.units[i] for i in order]
    for j, n in enumerate(out_names):
        if n in flip:
            dirs[j] *= -1.0
            data[..., j] *= -1.0
    return out_names, units, pos, dirs, data


def write_h5(path, recording, *, text="vlen_str", rate="np_float", vector="array", omit=(),
             channel_order=None, flip=(), rename=None, run_names=None, run_order=None,
             dtype="float64", storage="contiguous", layout=None, extra=False, units_g=(),
             force_sign=1.0):
    """Write ``recording`` (a RecordingData) as a contract HDF5 file with the given choices.

    ``omit``: optional attributes left out ('guide', 'description', 'excitation_position_m',
    'pretrigger_samples'). ``channel_order``: names -> index order. ``flip``: channels whose
    direction and samples are both negated. ``rename``: name -> name. ``run_names``: old -> new.
    ``run_order``: run names in the order written. ``dtype``: 'float32' or 'float64'.
    ``storage``: 'contiguous', 'chunked', 'gzip'. ``layout``: None (as given), 'signals' or 'hits'.
    ``extra``: unknown attributes and datasets everywhere. ``units_g``: channels written in g.
    ``force_sign``: -1 negates the excitation direction and the force samples (same physics).
    """
    with h5py.File(path, "w") as f:
        f.attrs["format"] = _scalar_text("guidefit-recording", text)
        f.attrs["format_version"] = np.int64(1)
        if recording.guide and "guide" not in omit:
            f.attrs["guide"] = _scalar_text(recording.guide, text)
        if "description" not in omit:
            f.attrs["description"] = _scalar_text("independent writer", text)
        if extra:
            f.attrs["operator"] = "someone"
            f.attrs["temperature_c"] = 21.5
            f.create_dataset("notes", data=np.arange(3))
        runs = f.create_group("runs")
        by_name = {r.name: r for r in recording.runs}
        order = run_order or [r.name for r in recording.runs]
        for rname in order:
            run = by_name[rname]
            g = runs.create_group((run_names or {}).get(rname, rname))
            g.attrs["sample_rate_hz"] = _number(run.sample_rate_hz, rate)
            g.attrs["excitation_direction"] = _vector(np.asarray(run.excitation_direction) * force_sign, vector)
            if run.excitation_position_m is not None and "excitation_position_m" not in omit:
                g.attrs["excitation_position_m"] = _vector(run.excitation_position_m, vector)
            if extra:
                g.attrs["hammer_tip"] = "steel"
                g.create_dataset("photo", data=np.zeros(4, np.uint8))
            names, units, pos, dirs, data = _run_order(run, channel_order, flip)
            data[..., names.index("force")] *= force_sign
            for j, n in enumerate(names):
                if n in units_g:
                    units[j] = "g"
                    data[..., j] /= 9.80665
            if force_sign < 0:
                dirs[names.index("force")] *= -1.0
            if rename:
                names = [rename.get(n, n) for n in names]
            kind = layout or run.layout
            pre = run.pretrigger_samples
            if kind == "signals" and data.ndim == 3:
                data = data.reshape(-1, data.shape[-1])
            kw = {}
            if storage == "chunked":
                kw["chunks"] = True
            elif storage == "gzip":
                kw.update(chunks=True, compression="gzip", compression_opts=4, shuffle=True)
            ds = g.create_dataset(kind, data=data.astype(dtype), **kw)
            ds.attrs["channel_names"] = _text(names, text)
            ds.attrs["units"] = _text(units, text)
            ds.attrs["positions_m"] = pos.tolist() if vector == "list" else _vector(pos, vector)
            ds.attrs["directions"] = dirs.tolist() if vector == "list" else _vector(dirs, vector)
            if kind == "hits" and pre is not None and "pretrigger_samples" not in omit:
                ds.attrs["pretrigger_samples"] = (np.array([pre]) if rate == "array1" else
                                                  float(pre) if rate == "py_float" else np.int32(pre))
            if extra:
                ds.attrs["daq_serial"] = "X123"
                ds.attrs["calibration_mv_per_unit"] = np.ones(len(names))


def write_csv(path, run, *, guide="MRB35", meta=True, time=False, delimiter=",", comments=(),
              channel_order=None, with_position=True, fmt="%.9g", decimal="."):
    """One run (signals layout: hits concatenated) as a contract CSV file with the given choices."""
    names, _units, _pos, _dirs, data = _run_order(run, channel_order, ())
    if data.ndim == 3:
        data = data.reshape(-1, data.shape[-1])
    fs = float(run.sample_rate_hz)
    with open(path, "w", newline="") as fh:
        for c in comments:
            fh.write(f"# {c}\n")
        if meta:
            fh.write(f"# sample_rate_hz: {fs:g}\n")
        fh.write("# excitation_direction: " + " ".join(f"{v:g}" for v in run.excitation_direction) + "\n")
        if guide:
            fh.write(f"# guide: {guide}\n")
        if with_position and run.excitation_position_m is not None:
            fh.write("# excitation_position_m: " + " ".join(f"{v:g}" for v in run.excitation_position_m) + "\n")
        w = csv.writer(fh, delimiter=delimiter, lineterminator="\n")
        w.writerow((["time"] if time else []) + names)
        t = np.arange(len(data)) / fs
        for i, row in enumerate(data):
            cells = ([f"{t[i]:.9g}"] if time else []) + [fmt % v for v in row]
            if decimal != ".":
                cells = [c.replace(".", decimal) for c in cells]
            w.writerow(cells)
