"""Property tests of guidefit's ``frf.h5`` reader (issue 21: a value guidefit cannot verify makes it
refuse, never guess): one run's attributes and datasets made hostile, a few at a time.

The promise: :func:`guidefit.io.frf_files.read_frf_file` either refuses the file with guidefit's input
error in one line, or gives FRFs whose frequency axis, values, channels, geometry and window settings
are exactly what the file holds. Any other exception (an internal error) fails the test.
"""

from __future__ import annotations

import math
import shutil

import h5py
import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from guidefit.errors import GuidefitError

RUN = "frf/vertical"

#: hostile values per attribute of a run (NaN, infinities, wrong shapes and types, out of range)
ATTRIBUTES = {
    "sample_rate_hz": [0.0, -200_000.0, math.nan, math.inf, 5e-324, "fast", [200_000.0, 1.0]],
    "exp_window_tau_s": [0.0, -0.01, math.inf, "x", [0.01, 0.02]],
    "force_window_s": [0.0, -1e-3, math.nan, math.inf, "x", [1e-3, 2e-3]],
    "estimator": ["H3", "", "h1", 1.0],
    "excitation_direction": [[0.0, 0.0, 0.0], [math.nan, -1.0, 0.0], [0.0, -1.0], [0.0, -2.0, 0.0], "down"],
    "excitation_position_m": [[math.nan, 0.0, 0.0], [0.0, 0.0], [math.inf, 0.0, 0.0]],
    "n_averages": [0, -3, 1.5, math.nan],
    "channels": [["acc_A_y"] * 4, ["acc_A_y", "acc_B_y", "acc_C_y"], ["", "b", "c", "d"], ["a\nb", "b", "c", "d"]],
    "directions": ["NAN", "SHAPE", "ZERO"],
    "positions_m": ["NAN", "SHAPE"],
}
#: hostile datasets: (name, what is done to it)
DATASETS = [("frequency_hz", "reverse"), ("frequency_hz", "nan"), ("frequency_hz", "negative"),
            ("frequency_hz", "repeat"), ("frequency_hz", "short"), ("H", "nan"), ("H", "inf"), ("H", "short"),
            ("H", "real"), ("coherence", "above_one"), ("coherence", "nan"), ("coherence", "short")]


@pytest.fixture(scope="module")
def frf_file(tmp_path_factory):
    from guidefit.frf import compute_frf
    from guidefit.hits import iter_hits
    from guidefit.io import write_recording
    from guidefit.io.frf_files import write_frf_h5_file
    from guidefit.simulate import SimulationConfig, simulate

    folder = tmp_path_factory.mktemp("frf_props")
    data, _ = simulate("MRB35", config=SimulationConfig(hits=3, record_s=0.02, sensor_layout="default"), seed=2)
    rec = folder / "rec.h5"
    write_recording(rec, data)
    from guidefit.io import read_recording

    recording = read_recording(rec)
    frfs = [compute_frf(run, iter_hits(run)) for run in recording.runs]
    path = folder / "frf.h5"
    write_frf_h5_file(path, frfs, recording=recording)
    return path


def _array_attr(value, like: np.ndarray, kind: str) -> np.ndarray:
    if kind == "NAN":
        out = np.array(like, float)
        out.flat[0] = math.nan
        return out
    if kind == "ZERO":
        out = np.array(like, float)
        out[0] = 0.0
        return out
    return np.array(like, float)[:, :2]  # SHAPE


def _mutate_dataset(group, name: str, how: str) -> None:
    data = group[name][...]
    del group[name]
    if how == "reverse":
        data = data[::-1]
    elif how == "nan":
        data = np.array(data)
        data.flat[len(data) // 2] = np.nan
    elif how == "inf":
        data = np.array(data)
        data.flat[len(data) // 2] = np.inf
    elif how == "negative":
        data = data - data[-1] / 2
    elif how == "repeat":
        data = np.array(data)
        data[5] = data[4]
    elif how == "short":
        data = data[:-3]
    elif how == "real":
        data = np.real(data)
    elif how == "above_one":
        data = np.array(data)
        data.flat[3] = 1.5
    group[name] = data


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(attrs=st.dictionaries(st.sampled_from(sorted(ATTRIBUTES)), st.integers(0, 6), max_size=2),
       sets=st.lists(st.sampled_from(DATASETS), max_size=2, unique=True))
@example(attrs={"exp_window_tau_s": 4}, sets=[])  # two numbers where one belongs: the first was used
@example(attrs={"estimator": 0}, sets=[])  # 'H3' was accepted
def test_frf_file_is_read_as_written_or_refused_in_one_line(frf_file, tmp_path_factory, attrs, sets):
    from guidefit.io.frf_files import read_frf_file

    path = tmp_path_factory.mktemp("case") / "frf.h5"
    shutil.copy(frf_file, path)
    with h5py.File(path, "r+") as f:
        group = f[RUN]
        for key, pick in attrs.items():
            options = ATTRIBUTES[key]
            value = options[pick % len(options)]
            if key in ("directions", "positions_m"):
                value = _array_attr(value, group.attrs[key], value)
            elif key == "channels":
                value = np.array(value, dtype=object)
                group.attrs.create(key, value, dtype=h5py.string_dtype())
                continue
            group.attrs[key] = value
        for name, how in sets:
            _mutate_dataset(group, name, how)
        stored = {k: group.attrs[k] for k in group.attrs}
        freq, H = group["frequency_hz"][...], group["H"][...]
    try:
        got = read_frf_file(path)
    except GuidefitError as exc:  # refused: one line
        assert "\n" not in str(exc) and str(exc)
        return
    frf = next(fs for run, fs in zip(got.recording.runs, got.frfsets) if run.name == "vertical")
    # read: exactly what the file holds, and only what can be true of an FRF set
    f_read = np.asarray(frf.frequency_hz, float)
    assert f_read.shape == freq.shape and np.array_equal(f_read, freq)
    assert np.all(np.isfinite(f_read)) and np.all(np.diff(f_read) > 0) and f_read[0] >= 0
    assert np.asarray(frf.H).shape == H.shape and np.all(np.isfinite(frf.H))
    assert np.allclose(np.asarray(frf.H), H, rtol=0, atol=0)
    assert np.all(np.isfinite(frf.coherence)) and np.all((frf.coherence >= 0) & (frf.coherence <= 1 + 1e-12))
    assert len(set(frf.channels)) == len(frf.channels) == H.shape[1]
    assert frf.estimator in ("H1", "H2", "Hv")
    for key in ("exp_window_tau_s", "force_window_s"):  # a single number (NaN: none), read as written
        written = np.asarray(stored[key], float)
        assert written.size == 1, (key, written)
        expected = None if math.isnan(written.item()) else written.item()
        assert getattr(frf, key) == (None if expected is None else pytest.approx(expected)), key
    run = next(r for r in got.recording.runs if r.name == "vertical")
    assert run.sample_rate_hz > 0 and math.isfinite(run.sample_rate_hz)
    d = np.asarray(run.excitation_direction, float)
    assert d.shape == (3,) and abs(np.linalg.norm(d) - 1) < 1e-6
