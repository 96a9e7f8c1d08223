"""Property tests: the metadata of the contract CSV and HDF5 readers, TDMS, WAV and UFF-58 time data.

The companion of ``tests/test_reader_properties.py`` (text exports and MAT
files). Each test writes a small file in a temporary folder with random,
often hostile, metadata (rates of 0, NaN or infinity, time columns with
gaps, jitter and repeated samples, a stated rate that disagrees with the
times, unknown units, odd or repeated channel names, directions that are not
unit vectors or not 3 numbers, start offsets, abscissa fields that disagree
with the data) and reads it as a user's file is read. Whatever the file, the
reader either refuses it with guidefit's input error (a
:class:`~guidefit.errors.GuidefitError` of exit code 2 whose message is one
line) or gives a run whose rate, length, units, names and directions are the
ones the file states (and the contract allows). Never another exception, and
never a value the file does not say.
"""

from __future__ import annotations

import math
import re
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, event, example, given, settings
from hypothesis import strategies as st
from test_reader_properties import DEFECTS, RATES, _consistent, _printed_step, _true_times

from guidefit.errors import GuidefitError
from guidefit.io import read_recording

SETTINGS = settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow])
AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}
NAME_RE = re.compile(r"^(force|acc_[A-Za-z0-9]+_[xyz])\Z")
HOSTILE_FLOATS = (0.0, -1.0, math.nan, math.inf, -math.inf, 1e300, 5e-324)


def _refused(exc: GuidefitError) -> None:
    """A refusal must be guidefit's input error: one line, exit 2; counted by its text's shape."""
    assert exc.exit_code == 2, exc
    assert "\n" not in str(exc) and "\r" not in str(exc), str(exc)
    event("refused: " + re.sub(r"'[^']*'|\S*/\S*|(?<![A-Za-z_])[-+]?\d[\d.eE+-]*", "_", str(exc))[:60])


def _read(path: Path):
    """The file's first run, or None when refused with guidefit's own one-line error (and no numpy
    warning before it: the command line would print it as a line of its own)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", RuntimeWarning)
        try:
            run = read_recording(path).runs[0]
        except GuidefitError as exc:
            run = exc
    assert not [w for w in caught if issubclass(w.category, RuntimeWarning)], [str(w.message) for w in caught]
    if isinstance(run, GuidefitError):
        _refused(run)
        return None
    event("read")
    return run


def _vector_text(v) -> str:
    return " ".join(repr(float(x)) for x in np.asarray(v, dtype=float).reshape(-1))


# ------------------------------------------------------------------ contract CSV

ODD_NAMES = ("acc_A_y ", " acc_B_x", '"acc_C_y"', "Acc_A_y", "acc_A_w", "acc A y", "acc_Ä_y", "acc_A_y\t",
             "time", "acc_A_y;x", "acc_A_", "", "acc_A_y\x0b", "force", "acc_E_y", "acc_N12_z")


@st.composite
def csv_files(draw):
    n = draw(st.integers(2, 150))
    fs = draw(st.sampled_from(RATES) | st.floats(1.0, 1e6, allow_nan=False, allow_subnormal=False))
    n_acc = draw(st.integers(1, 3))
    names = ["force"] + [f"acc_{p}_{a}" for p, a in zip("ABCD", draw(st.lists(st.sampled_from("xyz"), min_size=n_acc,
                                                                          max_size=n_acc)))]
    if draw(st.integers(0, 3)) == 3:
        names[draw(st.integers(0, len(names) - 1))] = draw(st.sampled_from(ODD_NAMES))
    return dict(
        n=n, fs=fs, names=names,
        time=draw(st.sampled_from([".10g", "repr", ".10g", None, ".6f", "g"])),
        defect=draw(st.sampled_from(DEFECTS + (None, None, None, "duplicate"))),
        where=draw(st.integers(1, max(1, n - 1))),
        size=draw(st.integers(1, 300)),
        t0=draw(st.sampled_from([0.0, 0.25, 1e3])),
        stated=draw(st.sampled_from(["same", None, "same", None, "1.0001", "1.01", "0.5"]) | st.sampled_from(
            ["same", "0", "-51200", "nan", "inf", "1e400", "abc", "51,2", "5e-324"])),
        units=draw(st.sampled_from([None, None, "default", "with_time", "bad_time", "odd", "short"])),
        odd_unit=draw(st.sampled_from(["V", "mV", "G", "m/s2", "kN", "N", "g", "m/s^2"])),
        positions=draw(st.sampled_from([None, "good", None, "good", "nan", "short"])),
        directions=draw(st.sampled_from([None, "good", "flip", None, "good", "non_unit", "nan", "short"])),
        excitation=draw(st.sampled_from(["0 -1 0", "0 -1 0", "-1 0 0", "0 -1 0", "-1 0 0", "0 0 0", "0 -2 0", "nan 1 0", "0 1",
                                         "0.6 0.8 0", "0 -1.0004 0"])),
    )


def _csv_text(e: dict, seed: int):
    """The file's text and what it states: (text, times or None, printed steps, units, directions)."""
    rng = np.random.default_rng(seed)
    n, fs = e["n"], e["fs"]
    names = e["names"]
    lines = [f"# excitation_direction: {e['excitation']}"]
    rate_line = None
    if e["stated"] in ("same", "1.0001", "1.01", "0.5"):
        rate_line = repr(fs * (1.0 if e["stated"] == "same" else float(e["stated"])))
    elif e["stated"] is not None:
        rate_line = e["stated"]
    if rate_line is not None:
        lines.append(f"# sample_rate_hz: {rate_line}")
    units = ["N" if name == "force" else "m/s^2" for name in names]
    if e["units"] == "odd":
        units[-1] = e["odd_unit"]
    if e["units"] in ("default", "odd"):
        lines.append("# units: " + " ".join(units))
    elif e["units"] == "with_time" and e["time"]:
        lines.append("# units: s " + " ".join(units))
    elif e["units"] == "bad_time" and e["time"]:
        lines.append("# units: ms " + " ".join(units))
    elif e["units"] == "short":
        lines.append("# units: " + " ".join(units[:-1]))
    pos = rng.uniform(-0.05, 0.05, (len(names), 3))
    if e["positions"] == "nan":
        pos[0, 1] = np.nan
    if e["positions"] is not None:
        rows = pos[:-1] if e["positions"] == "short" else pos
        lines.append("# positions_m: " + "; ".join(_vector_text(r) for r in rows))
    try:  # the force row along the hit: a force channel across excitation_direction is refused
        hit = tuple(float(v) for v in e["excitation"].split())
    except ValueError:
        hit = ()
    hit = hit if len(hit) == 3 else (1.0, 0, 0)
    dirs = np.array([AXES[name.strip().strip('"')[-1]] if name.strip().strip('"')[-1:] in AXES
                     else hit if name.strip().strip('"') == "force" else (1.0, 0, 0) for name in names])
    if e["directions"] == "flip":
        dirs = -dirs
    elif e["directions"] == "non_unit":
        dirs[-1] = dirs[-1] * 1.01
    elif e["directions"] == "nan":
        dirs[-1, 0] = np.nan
    if e["directions"] is not None:
        rows = dirs[:-1] if e["directions"] == "short" else dirs
        lines.append("# directions: " + "; ".join(_vector_text(r) for r in rows))
    times = steps = None
    header = list(names)
    columns = [np.sin(np.arange(n) * 0.3 + k) for k in range(len(names))]
    if e["time"]:
        defect = "repeat" if e["defect"] == "duplicate" else e["defect"]
        t = _true_times(n, fs, e["t0"], defect, e["where"], e["size"], rng)
        fields = [repr(float(v)) if e["time"] == "repr" else format(v, e["time"]) for v in t]
        times = np.array([float(f) for f in fields])
        steps = np.array([_printed_step(f) for f in fields])
        header = ["time"] + header
    rows = []
    for i in range(n):
        values = [f"{c[i]:.6f}" for c in columns]
        rows.append(",".join(([fields[i]] if e["time"] else []) + values))
    text = "\n".join(lines + [",".join(header)] + rows) + "\n"
    stated = e["stated"] is not None and rate_line
    return text, times, steps, units, (pos if e["positions"] == "good" else None), \
        (dirs if e["directions"] in ("good", "flip") else None), stated


def _csv_clean(e: dict) -> bool:
    """Whether the file follows the contract, its times (if any) written to 1e-10 of the largest or exactly."""
    names = [n.strip().strip('"').strip() for n in e["names"]]
    exact_times = e["time"] == "repr" or (e["time"] == ".10g" and e["t0"] < 1e3)
    return ((exact_times or (e["time"] is None and e["stated"] == "same"))
            and e["defect"] is None and e["stated"] in (None, "same")
            and (e["units"] in (None, "default", "with_time") or (e["units"] == "bad_time" and not e["time"]))
            and e["positions"] in (None, "good") and e["directions"] in (None, "good", "flip")
            and e["excitation"] in ("0 -1 0", "-1 0 0", "0.6 0.8 0", "0 -1.0004 0")
            and all(NAME_RE.match(n) for n in names) and len(set(names)) == len(names) and "force" in names
            and (e["positions"] == "good" or all(n == "force" or n[4] in "ABCD" for n in names)))


CSV_VALID = dict(n=40, fs=51200.0, names=["force", "acc_A_y"], time=".10g", defect=None, where=1, size=1, t0=0.0,
                 stated="same", units=None, odd_unit="V", positions=None, directions=None, excitation="0 -1 0")


@SETTINGS
@given(e=csv_files(), seed=st.integers(0, 2**16))
@example(e=CSV_VALID, seed=0)
@example(e=dict(CSV_VALID, stated=None, time="repr", units="with_time", positions="good", directions="flip"), seed=1)
# a stated rate of 5e-324 Hz beside a time column: 'overflow encountered in divide' on stderr before the refusal
@example(e=dict(CSV_VALID, n=2, fs=1000.0, stated="5e-324"), seed=0)
def test_csv_recording_metadata_as_the_file_states_or_refused(e, seed):
    text, times, steps, units, pos, dirs, stated = _csv_text(e, seed)
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "run.csv"
        path.write_text(text, encoding="utf-8")
        run = _read(path)
    if run is None:
        assert not _csv_clean(e), "a file the contract allows, with exact uniform times, was refused"
        return
    names = [name.strip().strip('"').strip() for name in e["names"]]
    assert list(run.channel_names) == names
    assert all(NAME_RE.match(name) for name in run.channel_names)
    assert run.n_samples == e["n"]
    assert [ch.unit for ch in run.channels] == units
    rate = run.sample_rate_hz
    assert math.isfinite(rate) and rate > 0
    if stated:
        assert rate == float(stated), (rate, stated)
    if times is not None:
        # every time within half its printed step plus half a period (a stated rate) or 0.1 (the times' own)
        slack = 0.5 if stated else 0.1
        i = np.arange(times.size)
        resid = (times - times[0]) - i / rate
        assert np.max(np.abs(resid)) <= slack / rate + 0.5 * np.max(steps) + 1e-9 / rate, (rate, e)
        assert _consistent(times, steps, rate) or stated, (rate, e)
    else:
        assert stated, "a rate without a time column or a sample_rate_hz line"
    exc_dir = np.array([float(v) for v in e["excitation"].split()])
    np.testing.assert_array_equal(run.excitation_direction, exc_dir)
    assert abs(np.linalg.norm(exc_dir) - 1) <= 1e-3
    got_dirs = np.array([ch.direction for ch in run.channels])
    if dirs is not None:
        np.testing.assert_array_equal(got_dirs, dirs)
    else:  # from the name's axis (the force: along the hit)
        expect = np.array([exc_dir if name == "force" else AXES[name[-1]] for name in names])
        np.testing.assert_array_equal(got_dirs, expect)
    if pos is not None:
        np.testing.assert_array_equal(np.array([ch.position_m for ch in run.channels]), pos)


# ------------------------------------------------------------------ contract HDF5

BAD_VECTORS = ([0.0, 0.0, 0.0], [0.0, -2.0, 0.0], [math.nan, -1.0, 0.0], [0.0, -1.0], [0.0, -1.0, 0.0, 0.0],
               [[0.0, -1.0, 0.0]], [0.6, 0.8, 0.0], [0.0, -1.0004, 0.0], [math.inf, 0.0, 0.0], "0 -1 0", [True, False, False])


H5_HOSTILE = dict(
    hits=st.sampled_from([1, 3]),
    rate=st.sampled_from(RATES + HOSTILE_FLOATS + ("51200", np.array([1.0, 2.0]), np.int32(51200), np.float16(2048)))
    | st.floats(allow_nan=True, allow_infinity=True),
    excitation=st.sampled_from(BAD_VECTORS),
    directions=st.sampled_from(["shape", "nan", "non_unit", "flip", "text", "ints"]),
    positions=st.sampled_from(["shape", "nan", "inf", "text", "1d"]),
    units=st.sampled_from(["g", "G", "V", "m/s2", "", "N ", "short", "bytes", "number"]),
    pretrigger=st.sampled_from([0, 1, -1, "n", "n-1", 2.5, math.nan, "text", (1, 2)]),
    names=st.sampled_from(["dup", "empty", "odd", "newline", "two_force", "no_force", "short", "bytes", "latin1"]),
    dtype=st.sampled_from(["<f2", "<i2", "<i4", "<c16", "|b1", ">f8", "<f4"]),
    scale=st.sampled_from([0.001, 0.0, math.nan, [1.0, 2.0]]),
)
H5_VALID = dict(hits=None, rate=51200.0, excitation=None, directions=None, positions=None, units=None, pretrigger=None,
                names=None, dtype="<f8", scale=None)


@st.composite
def h5_files(draw):
    """A valid file's fields with up to three made hostile."""
    n_acc = draw(st.integers(1, 3))
    hostile = draw(st.sets(st.sampled_from(sorted(H5_HOSTILE)), max_size=3))
    e = dict(H5_VALID, n=draw(st.integers(1, 60)), axes=draw(st.lists(st.sampled_from("xyz"), min_size=n_acc,
                                                                       max_size=n_acc)),
             rate=draw(st.sampled_from(RATES)))
    e.update({key: draw(H5_HOSTILE[key]) for key in sorted(hostile)})
    return e


def _h5_write(path: Path, e: dict, seed: int):
    import h5py

    rng = np.random.default_rng(seed)
    names = ["force"] + [f"acc_{p}_{a}" for p, a in zip("ABCD", e["axes"])]
    n_ch = len(names)
    units = ["N"] + ["m/s^2"] * (n_ch - 1)
    dirs = np.array([(0.0, -1.0, 0.0)] + [AXES[a] for a in e["axes"]])
    pos = rng.uniform(-0.05, 0.05, (n_ch, 3))
    shape = (e["n"], n_ch) if e["hits"] is None else (e["hits"], e["n"], n_ch)
    data = rng.normal(size=shape) * 100
    dtype = np.dtype(e["dtype"])
    stored = data.astype(dtype) if dtype.kind in "fc" else (data > 0 if dtype.kind == "b" else data.astype(dtype))
    attrs = {"channel_names": names, "units": units, "positions_m": pos, "directions": dirs}
    if e["names"] is not None:
        odd = {"dup": names[:-1] + [names[1]] if n_ch > 2 else ["force", "force"],
               "empty": names[:-1] + [""], "odd": names[:-1] + ["acc_A-y"], "newline": names[:-1] + [names[-1] + "\n"],
               "two_force": ["force"] * n_ch, "no_force": ["acc_Z_y"] + names[1:], "short": names[:-1],
               "bytes": [n.encode() for n in names], "latin1": names[:-1] + ["acc_\xe4_y".encode("latin-1")]}
        attrs["channel_names"] = odd[e["names"]]
    if e["units"] is not None:
        attrs["units"] = {"short": units[:-1], "bytes": [u.encode() for u in units],
                          "number": [1.0] * n_ch}.get(e["units"], units[:-1] + [e["units"]])
    if e["directions"] is not None:
        d = dirs.copy()
        if e["directions"] == "nan":
            d[-1, 0] = np.nan
        elif e["directions"] == "non_unit":
            d[-1] *= 1.01
        elif e["directions"] == "flip":
            d = -d
        odd = {"shape": d[:, :2], "text": "y", "ints": dirs.astype(np.int64)}
        attrs["directions"] = odd.get(e["directions"], d)
    if e["positions"] is not None:
        p = pos.copy()
        p[0, 2] = {"nan": np.nan, "inf": np.inf}.get(e["positions"], p[0, 2])
        attrs["positions_m"] = {"shape": p.T, "text": "A", "1d": p.reshape(-1)}.get(e["positions"], p)
    if e["pretrigger"] is not None:
        attrs["pretrigger_samples"] = {"n": e["n"], "n-1": e["n"] - 1}.get(e["pretrigger"], e["pretrigger"])
    if e["scale"] is not None:
        attrs["sample_scale"] = e["scale"]
    with h5py.File(path, "w") as f:
        f.attrs["format"] = "guidefit-recording"
        f.attrs["format_version"] = 1
        g = f.create_group("runs/vertical")
        g.attrs["sample_rate_hz"] = e["rate"]
        g.attrs["excitation_direction"] = np.array([0.0, -1.0, 0.0]) if e["excitation"] is None else e["excitation"]
        ds = g.create_dataset("signals" if e["hits"] is None else "hits", data=stored)
        for key, value in attrs.items():
            if isinstance(value, list) and value and isinstance(value[0], str):
                ds.attrs.create(key, value, dtype=h5py.string_dtype())
            else:
                ds.attrs[key] = value
    return stored, attrs


@SETTINGS
@given(e=h5_files(), seed=st.integers(0, 2**16))
@example(e=dict(n=8, hits=None, axes=["y"], rate=51200.0, excitation=None, directions=None, positions=None,
                units=None, pretrigger=None, names=None, dtype="<f8", scale=None), seed=0)
def test_hdf5_recording_metadata_as_the_file_states_or_refused(e, seed):
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "run.h5"
        stored, attrs = _h5_write(path, e, seed)
        run = _read(path)
        if run is None:
            return
        block = run.read_block() if e["hits"] is None else run.read_hit(0)
    names = [n.decode() if isinstance(n, bytes) else n for n in attrs["channel_names"]]
    assert list(run.channel_names) == names
    assert all(NAME_RE.match(name) for name in names) and len(set(names)) == len(names)
    units = [u.decode() if isinstance(u, bytes) else u for u in attrs["units"]]
    assert [ch.unit for ch in run.channels] == units and set(units) <= {"N", "m/s^2", "g"}
    rate = float(np.asarray(e["rate"]).reshape(-1)[0])
    assert run.sample_rate_hz == rate and math.isfinite(rate) and rate > 0
    assert run.n_samples == e["n"] and run.layout == ("signals" if e["hits"] is None else "hits")
    exc = np.array([0.0, -1.0, 0.0]) if e["excitation"] is None else np.asarray(e["excitation"], float)
    np.testing.assert_array_equal(run.excitation_direction, exc.reshape(3))
    dirs = np.array([ch.direction for ch in run.channels])
    np.testing.assert_array_equal(dirs, np.asarray(attrs["directions"], float))
    assert np.all(np.abs(np.linalg.norm(dirs, axis=1) - 1) <= 1e-3)
    np.testing.assert_array_equal(np.array([ch.position_m for ch in run.channels]), attrs["positions_m"])
    if "pretrigger_samples" in attrs:
        assert run.pretrigger_samples == attrs["pretrigger_samples"] and 0 <= run.pretrigger_samples < e["n"]
    assert np.dtype(e["dtype"]).kind in "fiu", "samples that are not real numbers were read"
    scale = (1.0 if e["scale"] is None else e["scale"]) * np.array([9.80665 if u == "g" else 1.0 for u in units])
    assert np.dtype(e["dtype"]).kind == "f" or e["scale"] is not None, "integer counts read without a scale"
    expected = np.asarray(stored if e["hits"] is None else stored[0], np.float64) * scale
    np.testing.assert_allclose(block, expected, rtol=1e-12, atol=0)


# ------------------------------------------------------------------ DAQ files through a setup

CONVERSIONS = {None: "", "mv": "sensitivity_mv = 2.0", "scale": "scale = 0.5"}


def _daq_setup(folder: Path, file: str, hammer: str, acc: str, conv: tuple, rate: float | None) -> Path:
    """A setup TOML reading ``hammer`` as force (N) and ``acc`` as acc_A_y (g)."""
    lines = ['format = "guidefit-setup"', "format_version = 1",
             "[channels.force]", f'source = "{hammer}"', 'unit = "N"', CONVERSIONS[conv[0]],
             "[channels.acc_A_y]", f'source = "{acc}"', 'unit = "g"', CONVERSIONS[conv[1]],
             "[runs.vertical]", f'file = "{file}"', "excitation_direction = [0.0, -1.0, 0.0]"]
    if rate is not None:
        lines.append(f"sample_rate_hz = {rate!r}")
    (folder / "test.toml").write_text("\n".join(lines) + "\n")
    return folder / "test.toml"


def _unit_allowed(file_unit, conv, unit: str) -> bool:
    """Whether a channel the file states in ``file_unit`` may be read as ``unit`` with conversion ``conv``."""
    if file_unit is None or not str(file_unit).strip() or conv == "scale":
        return True
    text = str(file_unit).strip().lower()
    if conv == "mv":
        return text in ("v", "volt", "volts")
    return text in ({"n", "newton", "newtons"} if unit == "N" else {"g", "gn", "g0"})


TDMS_INCREMENTS = ("valid", "valid", "valid", "missing", "zero", "negative", "nan", "inf", "tiny", "subnormal", "huge",
                   "text", "other")
TDMS_OFFSETS = (None, None, 0.0, 0.0, 0.3, 0.7, 2.0, math.nan, math.inf, "text")


TDMS_VALID = dict(n=8, n_acc=None, fs=51200.0, inc=("valid", "valid"), offset=(None, None), unit=("V", "V"),
                  conv=("mv", "mv"), stated=None)


@st.composite
def tdms_files(draw):
    """A valid file and setup with up to two of their fields drawn from hostile values."""
    hostile = {
        "n_acc": st.sampled_from([1, 3]),
        "inc": st.tuples(st.sampled_from(TDMS_INCREMENTS), st.sampled_from(TDMS_INCREMENTS)),
        "offset": st.tuples(st.sampled_from(TDMS_OFFSETS), st.sampled_from(TDMS_OFFSETS)),
        "unit": st.tuples(*[st.sampled_from(["V", None, "mV", "N", "g", "m/s^2", "", "Pa", "volts", 5.0])] * 2),
        "conv": st.tuples(st.sampled_from(["mv", None, "scale"]), st.sampled_from(["mv", None, "scale"])),
        "stated": st.sampled_from(["same", "other", "close"]),
    }
    keys = draw(st.sets(st.sampled_from(sorted(hostile)), max_size=2))
    e = dict(TDMS_VALID, n=draw(st.integers(2, 60)), fs=draw(st.sampled_from(RATES)))
    e.update({key: draw(hostile[key]) for key in sorted(keys)})
    return e


def _increment(kind: str, fs: float):
    return {"valid": 1 / fs, "zero": 0.0, "negative": -1 / fs, "nan": math.nan, "inf": math.inf, "tiny": 1e-300,
            "subnormal": 5e-324, "huge": 1e300, "text": "abc", "other": 1 / (fs * 1.001)}.get(kind)


@SETTINGS
@given(e=tdms_files(), seed=st.integers(0, 2**16))
@example(e=TDMS_VALID, seed=0)
# wf_increment 5e-324 s: OverflowError (an internal error, exit 1) from the rate's whole-Hz rounding
@example(e=dict(TDMS_VALID, inc=("subnormal", "valid")), seed=0)
# wf_increment 0 (or NaN, text) on one channel: ignored, the other channel's (or the setup's) rate used
@example(e=dict(TDMS_VALID, inc=("valid", "zero")), seed=0)
@example(e=dict(TDMS_VALID, inc=("nan", "nan"), stated="same"), seed=0)
# wf_start_offset NaN or text on one channel: the start times were never compared
@example(e=dict(TDMS_VALID, offset=(0.0, math.nan)), seed=0)
@example(e=dict(TDMS_VALID, offset=(0.0, "text")), seed=0)
def test_tdms_metadata_as_the_file_states_or_refused(e, seed):
    from nptdms import ChannelObject, TdmsWriter

    rng = np.random.default_rng(seed)
    fs = e["fs"]
    stated = {None: None, "same": fs, "other": fs * 1.01, "close": fs * (1 + 1e-7)}[e["stated"]]
    objects, props = [], []
    for k, name in enumerate(("Hammer", "AccA_Y")):
        p = {}
        if e["inc"][k] != "missing":
            p["wf_increment"] = _increment(e["inc"][k], fs)
        if e["offset"][k] is not None:
            p["wf_start_offset"] = e["offset"][k] / fs if isinstance(e["offset"][k], float) else e["offset"][k]
        if e["unit"][k] is not None:
            p["unit_string"] = e["unit"][k]
        n = e["n_acc"] if (k == 1 and e["n_acc"] is not None) else e["n"]
        objects.append(ChannelObject("run", name, rng.normal(size=n), properties=p))
        props.append(p)
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        with TdmsWriter(folder / "run.tdms") as writer:
            writer.write_segment(objects)
        run = _read(_daq_setup(folder, "run.tdms", "Hammer", "AccA_Y", e["conv"], stated))
    if run is None:
        return
    lengths = {e["n"], e["n"] if e["n_acc"] is None else e["n_acc"]}
    assert lengths == {run.n_samples}, "channels of different lengths read as one run"
    assert run.n_samples >= 2
    for k, unit in enumerate(("N", "g")):
        assert _unit_allowed(props[k].get("unit_string"), e["conv"][k], unit), (props[k], e["conv"][k])
    increments = [p["wf_increment"] for p in props if "wf_increment" in p]
    for inc in increments:  # every increment the file states is a time step the run's rate agrees with
        assert isinstance(inc, float) and math.isfinite(inc) and inc > 0, f"wf_increment {inc!r} ignored"
        assert abs(run.sample_rate_hz * inc - 1) <= 1e-5, (run.sample_rate_hz, inc)
    if stated is not None:
        assert abs(run.sample_rate_hz / stated - 1) <= 1e-5
    if not increments:
        assert run.sample_rate_hz == stated
    offsets = [p["wf_start_offset"] for p in props if "wf_start_offset" in p]
    if len(offsets) == 2:  # both say when they started: within half a sample of each other
        assert all(isinstance(x, float) for x in offsets), f"wf_start_offset {offsets} not checked"
        assert abs(offsets[0] - offsets[1]) * run.sample_rate_hz <= 0.5, offsets
    assert run.channel_names == ("force", "acc_A_y")
    assert [ch.unit for ch in run.channels] == ["N", "g"]


WAV_SUBTYPES = ("PCM_16", "PCM_24", "PCM_32", "FLOAT", "DOUBLE", "PCM_U8")


@st.composite
def wav_files(draw):
    return dict(
        frames=draw(st.integers(1, 60)),
        channels=draw(st.sampled_from([2, 2, 3, 1])),
        rate=draw(st.sampled_from([51200, 48000, 8000, 1, 192000, 384000, 1000000]) | st.integers(1, 2**20)),
        subtype=draw(st.sampled_from(WAV_SUBTYPES)),
        stated=draw(st.sampled_from([None, None, "same", "other"])),
        conv=draw(st.tuples(st.sampled_from(["scale", "mv", None]), st.sampled_from(["scale", "mv", None]))),
        header_rate=draw(st.sampled_from([None] * 8 + [0, 2**32 - 1, 2**31])),
    )


@SETTINGS
@given(e=wav_files(), seed=st.integers(0, 2**16))
@example(e=dict(frames=16, channels=2, rate=51200, subtype="PCM_24", stated=None, conv=("scale", "mv"), header_rate=None),
         seed=0)
def test_wav_rate_length_and_samples_as_the_file_states_or_refused(e, seed):
    import soundfile

    rng = np.random.default_rng(seed)
    data = rng.uniform(-0.9, 0.9, (e["frames"], e["channels"]))
    stated = {None: None, "same": float(e["rate"]), "other": e["rate"] * 1.01}[e["stated"]]
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        path = folder / "run.wav"
        soundfile.write(path, data, e["rate"], subtype=e["subtype"])
        if e["header_rate"] is not None:  # the fmt chunk's sample rate, after 'RIFF....WAVEfmt ....' and 4 bytes
            raw = bytearray(path.read_bytes())
            assert raw[12:16] == b"fmt "
            raw[24:28] = int(e["header_rate"]).to_bytes(4, "little")
            path.write_bytes(bytes(raw))
        run = _read(_daq_setup(folder, "run.wav", "0", "1", e["conv"], stated))
        if run is None:
            return
        block = run.read_block()
        on_disk, rate = soundfile.read(path, dtype="float64", always_2d=True)
    assert rate > 0 and run.sample_rate_hz == float(rate), (run.sample_rate_hz, rate)
    assert e["header_rate"] is None or e["header_rate"] == rate
    if stated is not None:
        assert abs(run.sample_rate_hz / stated - 1) <= 1e-5
    assert run.n_samples == e["frames"] == on_disk.shape[0] and run.n_samples >= 2
    factor = np.array([{"scale": 0.5, "mv": 500.0, None: 1.0}[c] for c in e["conv"]]) * [1.0, 9.80665]
    exact = 1e-12 if e["subtype"] in ("PCM_32", "DOUBLE") else 1e-6  # float32 holds 24 bits
    np.testing.assert_allclose(block, on_disk[:, :2] * factor, rtol=exact, atol=1e-300)


# ------------------------------------------------------------------ UFF-58 time data

UFF_INCREMENTS = ("valid", "valid", "valid", "0", "-1.95313e-05", "nan", "inf", "1.00000e-320", "1.00000e+300",
                  "other")
UFF_STARTS = (0.0, 0.0, 0.0, 0.3, 0.7, 1e6, math.nan, math.inf)


@st.composite
def uff_files(draw):
    """Two datasets 58 (force at the reference DOF, an acceleration) with up to two hostile fields."""
    hostile = {
        "inc": st.tuples(st.sampled_from(UFF_INCREMENTS), st.sampled_from(UFF_INCREMENTS)),
        "start": st.tuples(st.sampled_from(UFF_STARTS), st.sampled_from(UFF_STARTS)),
        "num_pts": st.tuples(st.sampled_from([0, -1, 1, 0, 5]), st.sampled_from([0, -1, 1, 0, 5])),
        "labels": st.tuples(st.sampled_from(["N", "NONE", "lbf", "kN", "g"]),
                            st.sampled_from(["m/s^2", "g", "NONE", "mm/s^2", "G", "m/s2", "N", ""])),
        "spec": st.tuples(st.sampled_from([13, 13, 0, 1, 12, 9, 8, 11]), st.sampled_from([12, 12, 0, 13, 8, 11])),
        "units164": st.sampled_from([1.0, 1e-3, math.nan, 4.448]),
    }
    keys = draw(st.sets(st.sampled_from(sorted(hostile)), max_size=2))
    e = dict(UFF_VALID, n=draw(st.integers(2, 40)), fs=draw(st.sampled_from(RATES + (1e6, 3.0))))
    e.update({key: draw(hostile[key]) for key in sorted(keys)})
    return e


UFF_VALID = dict(n=16, fs=51200.0, inc=("valid", "valid"), start=(0.0, 0.0), num_pts=(0, 0), labels=("N", "m/s^2"),
                 spec=(13, 12), units164=None)
UFF_ACC_UNITS = {"m/s^2": "m/s^2", "m/s2": "m/s^2", "none": "m/s^2", "": "m/s^2", "g": "g"}


def _uff_write(path: Path, e: dict, seed: int) -> list[dict]:
    """Write the two sets with pyuff, then put the drawn fields into their header lines (record 7)."""
    import pyuff

    rng = np.random.default_rng(seed)
    fs, n = e["fs"], e["n"]
    sets, stated = [], []
    for k, (node, spec, label) in enumerate(zip((9, 1), e["spec"], e["labels"])):
        data = rng.normal(size=n)
        sets.append(pyuff.prepare_58(
            binary=0, func_type=1, rsp_node=node, rsp_dir=2, ref_node=9, ref_dir=2, data=data, x=np.arange(n) / fs,
            abscissa_spacing=1, abscissa_spec_data_type=17, ordinate_spec_data_type=spec, orddenom_spec_data_type=0,
            ordinate_axis_units_lab=label, id1="NONE"))
        inc = e["inc"][k]
        inc = format(1 / fs, "13.5e") if inc == "valid" else (format(1 / (fs * 1.001), "13.5e") if inc == "other"
                                                              else f"{inc:>13s}")
        start = format(e["start"][k] / fs, "13.5e")
        num_pts = n + e["num_pts"][k]
        stated.append(dict(data=data, inc=float(inc), start=float(start), num_pts=num_pts, label=label, spec=spec))
    if e["units164"] is not None:
        sets.insert(0, pyuff.prepare_164(units_code=1, units_description="SI", temp_mode=1, length=e["units164"],
                                         force=1.0, temp=1.0, temp_offset=273.15))
    pyuff.UFF(str(path)).write_sets(sets, mode="overwrite")
    lines = path.read_text().splitlines()
    k = 0
    for i, line in enumerate(lines):
        if line.strip() == "58" and lines[i - 1].strip() == "-1":
            s = stated[k]
            lines[i + 7] = f"{4:10d}{s['num_pts']:10d}{1:10d}{format(s['start'], '13.5e'):>13s}" \
                           f"{format(s['inc'], '13.5e'):>13s}{0.0:13.5e}"
            k += 1
    assert k == 2
    path.write_text("\n".join(lines) + "\n")
    return stated


@SETTINGS
@given(e=uff_files(), seed=st.integers(0, 2**16))
@example(e=UFF_VALID, seed=0)
# an abscissa increment of 1e-320 s: OverflowError, an internal error (exit 1)
@example(e=dict(UFF_VALID, inc=("1.00000e-320", "1.00000e-320")), seed=0)
# an abscissa minimum of NaN: the records' start times never compared (any comparison with NaN passes)
@example(e=dict(UFF_VALID, start=(0.0, math.nan)), seed=0)
# a displacement (8) at the reference DOF: read as the hammer force, in N
@example(e=dict(UFF_VALID, spec=(8, 12), labels=("NONE", "m/s^2")), seed=0)
# an increment of inf: pyuff's 'invalid value encountered in multiply' on stderr before the refusal
@example(e=dict(UFF_VALID, inc=("inf", "valid")), seed=0)
def test_uff58_time_metadata_as_the_file_states_or_refused(e, seed):
    pytest.importorskip("pyuff")
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "run.uff"
        stated = _uff_write(path, e, seed)
        run = _read(path)
        if run is None:
            return
        block = run.read_block()
    force, acc = stated
    assert force["num_pts"] == acc["num_pts"] == e["n"] == run.n_samples, "header and data lengths differ"
    for s in stated:
        assert math.isfinite(s["inc"]) and s["inc"] > 0
        assert abs(run.sample_rate_hz * s["inc"] - 1) <= 5.1e-6, (run.sample_rate_hz, s["inc"])
        assert math.isfinite(s["start"]), f"abscissa minimum {s['start']} never checked"
    assert abs(force["start"] - acc["start"]) <= 0.5 * force["inc"], "records not simultaneous"
    assert e["units164"] in (None, 1.0)
    assert force["label"].lower() in ("n", "none", "") and force["spec"] in (13, 0, 1, 9)
    assert acc["spec"] == 12
    assert [ch.unit for ch in run.channels] == ["N", UFF_ACC_UNITS[acc["label"].lower()]]
    np.testing.assert_array_equal(run.excitation_direction, [0.0, 1.0, 0.0])
    np.testing.assert_array_equal(run.channels[1].direction, [0.0, 1.0, 0.0])
    assert run.channel_names == ("force", "acc_A_y")
    factor = np.array([1.0, 9.80665 if acc["label"].lower() == "g" else 1.0])
    np.testing.assert_allclose(block, np.column_stack([force["data"], acc["data"]]) * factor, rtol=1e-11, atol=1e-300)


# ------------------------------------------------------------------ ASAM MDF 4 through a setup


MDF_VALID = dict(n=20, fs=51200.0, t0=0.0, defect=None, where=1, size=1, unit=("V", "V"), conv=("mv", "mv"),
                 stated=None, two_groups=False)


@st.composite
def mdf_files(draw):
    """A valid file and setup with its time channel's defect drawn, and up to two other fields hostile."""
    hostile = {
        "t0": st.sampled_from([2.5, 1.7e9]),
        "unit": st.tuples(*[st.sampled_from(["V", "", "mV", "N", "g", "Pa"])] * 2),
        "conv": st.sampled_from([("scale", None), (None, None), ("mv", "scale"), ("scale", "scale")]),
        "stated": st.sampled_from(["same", "other"]),
        "two_groups": st.just(True),
    }
    keys = draw(st.sets(st.sampled_from(sorted(hostile)), max_size=2))
    n = draw(st.integers(2, 80))
    e = dict(MDF_VALID, n=n, fs=draw(st.sampled_from(RATES)), defect=draw(st.sampled_from(DEFECTS + ("nan",))),
             where=draw(st.integers(1, max(1, n - 1))), size=draw(st.integers(1, 3000)))
    e.update({key: draw(hostile[key]) for key in sorted(keys)})
    return e


@SETTINGS
@given(e=mdf_files(), seed=st.integers(0, 2**16))
@example(e=MDF_VALID, seed=0)
def test_mdf_time_channel_and_units_as_the_file_states_or_refused(e, seed):
    pytest.importorskip("asammdf")
    from asammdf import MDF, Signal

    rng = np.random.default_rng(seed)
    defect = None if e["defect"] == "nan" else e["defect"]
    t = _true_times(e["n"], e["fs"], e["t0"], defect, e["where"], e["size"], rng)
    if e["defect"] == "nan":
        t[e["where"]] = np.nan
    stated = {None: None, "same": e["fs"], "other": e["fs"] * 1.01}[e["stated"]]
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        with MDF(version="4.10") as mdf:
            signals = [Signal(rng.normal(size=e["n"]), t, name=name, unit=unit)
                       for name, unit in zip(("Hammer", "AccA_Y"), e["unit"])]
            if e["two_groups"]:  # the accelerometer in a second channel group, with its own time channel
                mdf.append(signals[:1])
                mdf.append(signals[1:])
            else:
                mdf.append(signals)
            mdf.save(folder / "run.mf4", overwrite=True)
        run = _read(_daq_setup(folder, "run.mf4", "Hammer", "AccA_Y", e["conv"], stated))
    if run is None:
        return
    assert not e["two_groups"], "channels of two channel groups read as one run"
    assert run.n_samples == e["n"] and np.all(np.isfinite(t))
    assert _consistent(t - t[0], np.zeros(t.size), run.sample_rate_hz), (run.sample_rate_hz, e)
    if stated is not None:
        assert abs(run.sample_rate_hz / stated - 1) <= 1e-5
    for k, unit in enumerate(("N", "g")):
        assert _unit_allowed(e["unit"][k] or None, e["conv"][k], unit), (e["unit"][k], e["conv"][k])
