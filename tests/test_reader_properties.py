"""Property tests: the DAQ readers' metadata (time vectors, rates, lengths, units, names).

Small text exports and MAT files (v5 and v7.3) with random time vectors
(length, start, rate, print format, unit, gaps, dropped or repeated samples,
jitter) are read through a test setup, as a user's files are. Whatever the
file, the reader either refuses it with guidefit's input-error class
(:class:`~guidefit.errors.GuidefitError`, exit 2, one line) or gives a run
whose length is the file's number of samples and whose rate is consistent
with every time the file writes: one offset ``c`` exists with every time
``t_i`` within half its printed step plus 0.1 sample period of ``c + i / fs``
(the oracle is computed here from the text, independently of the reader). A
time vector written exactly and uniformly must be read, at its rate. Never a
run whose rate or length the file's own times contradict.
"""

from __future__ import annotations

import re
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, event, example, given, settings
from hypothesis import strategies as st

from guidefit.errors import GuidefitError
from guidefit.io import read_recording

RATES = (1000.0, 2048.0, 10000.0, 51200.0, 190000.0, 200000.0)
DEFECTS = (None, None, None, "gap", "drop", "repeat", "jitter", "joined")
SETTINGS = settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow])
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6}


def _setup(folder: Path, file: str, hammer: str, acc: str) -> Path:
    text = "\n".join([
        'format = "guidefit-setup"', "format_version = 1",
        "[channels.force]", f'source = "{hammer}"', 'unit = "N"', "sensitivity_mv = 2.0",
        "[channels.acc_A_y]", f'source = "{acc}"', 'unit = "g"', "sensitivity_mv = 10.0",
        "[runs.vertical]", f'file = "{file}"', "excitation_direction = [0.0, -1.0, 0.0]",
    ]) + "\n"
    (folder / "test.toml").write_text(text)
    return folder / "test.toml"


def _true_times(n: int, fs: float, t0: float, defect, where: int, size: int, rng) -> np.ndarray:
    """``n`` times at ``fs`` from ``t0`` with one defect after sample ``where`` (``size`` samples)."""
    k = np.arange(n, dtype=np.float64)
    if defect == "gap":
        k[where:] += size  # samples missing
    elif defect == "drop":
        k[where:] += 1
    elif defect == "repeat":
        k[where:] -= 1  # a sample written twice
    elif defect == "joined":
        k[where:] -= min(size, where)  # a second record from an earlier time
    t = t0 + k / fs
    if defect == "jitter":
        t = t + rng.uniform(-1, 1, n) * size * 1e-3 / fs  # up to 3 periods
    return t


def _printed_step(text: str) -> float:
    """The step a number is written to (``0.5``: 0.1; ``1.25e-03``: 1e-5; ``7``: 1), from its text."""
    mantissa, _, exponent = text.strip().lower().partition("e")
    decimals = len(mantissa.partition(".")[2])
    return 10.0 ** (int(exponent or 0) - decimals)


def _format_step(values: np.ndarray, fmt: str) -> np.ndarray:
    """The step ``fmt`` rounds each value to, trailing zeros or not (``%g``: 6 significant digits)."""
    if fmt == "repr":
        return np.zeros(values.size)
    if fmt.endswith("f"):
        return np.full(values.size, 10.0 ** -int(fmt[1:-1]))
    digits = 6 if fmt == "g" else int(fmt[1:-1]) + (fmt.endswith("e"))
    magnitude = np.floor(np.log10(np.maximum(np.abs(values), 1e-300)))
    return np.where(values == 0, 0.0, 10.0 ** (magnitude - digits + 1))


def _consistent(times: np.ndarray, steps: np.ndarray, rate: float) -> bool:
    """Whether one offset c puts every time within half its printed step plus 0.1 period of c + i/rate."""
    i = np.arange(times.size)
    resid = times - i / rate
    slack = 0.5 * steps + 0.1 / rate + 1e-9 / rate + 1e-12 * np.max(np.abs(times))
    return bool(np.max(resid - slack) <= np.min(resid + slack))


def _read(setup: Path):
    """(rate, n_samples) of the setup's run, or None when refused with guidefit's own one-line error."""
    try:
        run = read_recording(setup).runs[0]
    except GuidefitError as exc:
        assert "\n" not in str(exc)
        event("refused: " + re.sub(r"'[^']*'|\S*/\S*|(?<![A-Za-z_])[-+]?\d[\d.eE+-]*", "_", str(exc))[:70])
        return None
    event("read")
    return run.sample_rate_hz, run.n_samples


# ------------------------------------------------------------------ text exports


@st.composite
def text_exports(draw):
    n = draw(st.integers(2, 300))
    return dict(
        n=n,
        fs=draw(st.sampled_from(RATES)),
        t0=draw(st.sampled_from([0.0, 0.5, 1.0, 9.99, 12.0]) | st.floats(0, 100, allow_subnormal=False)),
        last=draw(st.sampled_from([None, None, 0.5, 1.0, 20.0])),  # the last time round: '%g' writes '0.5'
        fmt=draw(st.sampled_from(["g", ".6f", ".5f", ".8f", ".3e", ".7e", ".9g", ".12g", "repr"])),
        unit=draw(st.sampled_from(["s", "ms", "us"])),
        defect=draw(st.sampled_from(DEFECTS)),
        where=draw(st.integers(1, max(1, n - 1))),
        size=draw(st.integers(1, 3000)),
        decimal=draw(st.sampled_from([".", ","])),
        name=draw(st.sampled_from(["Time", "t", "Zeit", "time_s"])),
    )


def _write_text(folder: Path, e: dict, seed: int):
    rng = np.random.default_rng(seed)
    t = _true_times(e["n"], e["fs"], e["t0"], e["defect"], e["where"], e["size"], rng)
    if e.get("last") is not None:
        t = t - t[-1] + e["last"]
    scale = TIME_UNITS[e["unit"]]
    fields = [repr(float(v)) if e["fmt"] == "repr" else format(v, e["fmt"]) for v in t / scale]
    x = np.sin(np.arange(e["n"]) * 0.3)
    delimiter = ";" if e["decimal"] == "," else ","
    rows = [delimiter.join([f, f"{a:.6f}", f"{-a:.6f}"]).replace(".", e["decimal"]) if e["decimal"] == "," else
            delimiter.join([f, f"{a:.6f}", f"{-a:.6f}"]) for f, a in zip(fields, x)]
    header = delimiter.join([f"{e['name']} [{e['unit']}]", "Hammer [V]", "A_Y [V]"])
    (folder / "run.csv").write_text(header + "\n" + "\n".join(rows) + "\n")
    times = np.array([float(f) for f in fields]) * scale
    steps = np.array([_printed_step(f) for f in fields]) * scale
    return times, steps, _format_step(t / scale, e["fmt"]) * scale


@SETTINGS
@given(e=text_exports(), seed=st.integers(0, 2**16))
# the file (scaled down): %g times, the last row '0.5', a 40 ms gap (2048 samples at 51.2 kHz)
@example(e=dict(n=25601 - 2048, fs=51200.0, t0=0.0, fmt="g", unit="s", defect="gap", where=12000, size=2048,
                decimal=".", name="Time"), seed=0)
def test_text_time_column_gives_its_rate_and_length_or_is_refused(e, seed):
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        times, steps, rounding = _write_text(folder, e, seed)
        got = _read(_setup(folder, "run.csv", "Hammer", "A_Y"))
    if got is None:
        # rounded to at most one sample period (%.5f at 51.2 kHz: half a period)
        uniform = e["defect"] is None and np.max(rounding) * e["fs"] <= 1.0
        assert not uniform, "times written exactly and uniformly were refused"
        return
    rate, n = got
    assert n == e["n"]
    assert _consistent(times, steps, rate), (rate, e)
    if e["defect"] is None:  # rounding of at most half the coarsest step: the slope is off by little
        bound = 4 * 0.5 * np.max(steps) * e["fs"] / (e["n"] - 1) + 1e-9
        assert abs(rate / e["fs"] - 1) <= bound, (rate, e)


@pytest.mark.parametrize("unit", ["min", "h", "V"])
def test_text_time_column_in_another_unit_is_refused(tmp_path, unit):
    rows = "".join(f"{k / 1000:.3f};{k};{-k}\n" for k in range(20))
    (tmp_path / "run.csv").write_text(f"Time [{unit}];Hammer [V];A_Y [V]\n" + rows)
    with pytest.raises(GuidefitError, match=rf"run.csv: time column 'Time' in '{unit}'; expected s, ms or us"):
        read_recording(_setup(tmp_path, "run.csv", "Hammer", "A_Y"))


# ------------------------------------------------------------------ MAT files


@st.composite
def mat_files(draw):
    n = draw(st.integers(2, 200))
    return dict(
        n=n,
        n_time=draw(st.sampled_from([None, n, n, n]) | st.integers(1, 2 * n + 2)),
        fs=draw(st.sampled_from(RATES)),
        fs_variable=draw(st.sampled_from([None, "same", "other"])),
        rate_name=draw(st.sampled_from(["fs", "Fs", "sample_rate_hz"])),
        time_name=draw(st.sampled_from(["t", "time"])),
        t0=draw(st.sampled_from([0.0, 1.5, 1.7e9])),  # 1.7e9: epoch seconds
        defect=draw(st.sampled_from(DEFECTS)),
        where=draw(st.integers(1, max(1, n - 1))),
        size=draw(st.integers(1, 3000)),
        version=draw(st.sampled_from(["v5", "v73"])),
        group=draw(st.sampled_from([None, "rec"])),
        column=draw(st.booleans()),
        extra=draw(st.sampled_from([None, (3, 2, 2), (1, 7), (5, 1, 1, 2)])),
    )


def _write_mat(folder: Path, e: dict, seed: int):
    import scipy.io
    from test_daq_formats import write_mat73

    rng = np.random.default_rng(seed)
    variables = {"data": np.column_stack([np.sin(np.arange(e["n"]) * 0.3), np.cos(np.arange(e["n"]) * 0.3)])}
    if e["column"]:
        variables["data"] = np.asfortranarray(variables["data"])
    times = None
    if e["n_time"] is not None:
        times = _true_times(e["n_time"], e["fs"], e["t0"], e["defect"], min(e["where"], e["n_time"] - 1),
                            e["size"], rng)
        variables[e["time_name"]] = times
    if e["fs_variable"] is not None:
        variables[e["rate_name"]] = e["fs"] * (1 if e["fs_variable"] == "same" else 1.01)
    if e["extra"] is not None:
        variables["extra"] = np.zeros(e["extra"])
    path = folder / "run.mat"
    if e["version"] == "v5":
        scipy.io.savemat(path, {e["group"]: variables} if e["group"] else variables)
    else:
        write_mat73(path, variables, group=e["group"])
    return times


@SETTINGS
@given(e=mat_files(), seed=st.integers(0, 2**16))
# the file (scaled down): t of 1000 times beside 1600 samples
@example(e=dict(n=1600, n_time=1000, fs=190000.0, fs_variable=None, rate_name="fs", time_name="t", t0=0.0,
                defect=None, where=1, size=1, version="v5", group=None, column=False, extra=(3, 2, 2)), seed=0)
def test_mat_time_vector_and_rate_give_the_rate_and_length_or_are_refused(e, seed):
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        times = _write_mat(folder, e, seed)
        setup = _setup(folder, "run.mat", "data:0", "data:1")
        if e["group"] is not None:
            setup.write_text(setup.read_text().replace('file = "run.mat"', 'file = "run.mat"\ngroup = "rec"'))
        got = _read(setup)
    stated = None if e["fs_variable"] is None else e["fs"] * (1 if e["fs_variable"] == "same" else 1.01)
    # times written as float64: each off by at most half its spacing (epoch seconds: 1.2e-7 s)
    bound = 1e-9 if times is None else 4 * 0.5 * np.spacing(np.max(np.abs(times))) * e["fs"] / (e["n"] - 1) + 1e-9
    fine = (e["n_time"] in (None, e["n"]) and e["defect"] is None and (times is None or e["fs_variable"] != "other")
            and (times is not None or stated is not None)
            and (stated is None or bound < 1e-5))  # else the times cannot confirm the rate variable
    if got is None:
        assert not fine, "a consistent file was refused"
        return
    rate, n = got
    assert n == e["n"]
    if times is not None:
        assert times.size == e["n"], "a time vector of another length gave the channels a rate"
        assert _consistent(times - times[0], np.zeros(times.size), rate), (rate, e)
    if stated is not None:
        assert abs(rate / stated - 1) <= 1e-5, (rate, e)
    if fine:
        assert abs(rate / (stated or e["fs"]) - 1) <= bound, (rate, e)
