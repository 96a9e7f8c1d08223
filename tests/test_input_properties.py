"""Property tests: whatever a file holds, the readers and identify raise guidefit's own errors only."""

import contextlib
import os
import shutil
import sys
import tempfile
import time
import warnings
from pathlib import Path

import h5py
import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from guidefit.errors import GuidefitError
from guidefit.hits import iter_hits
from guidefit.identify import IdentifySettings, identify
from guidefit.io import read_recording

SAMPLE = Path(__file__).resolve().parents[1] / "sample_data"
FS = 200_000.0

# values an attribute might wrongly hold
odd_values = st.one_of(
    st.none(), st.booleans(), st.integers(-5, 5), st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=8), st.lists(st.floats(-2, 2), max_size=5),
    st.lists(st.lists(st.floats(-2, 2), min_size=3, max_size=3), max_size=4),
    st.lists(st.text(max_size=6), max_size=4),
)
ATTRS = [("", "format"), ("", "format_version"), ("", "guide"), ("runs/vertical", "sample_rate_hz"),
         ("runs/vertical", "excitation_direction"), ("runs/vertical", "excitation_position_m"),
         ("runs/vertical/hits", "channel_names"), ("runs/vertical/hits", "units"),
         ("runs/vertical/hits", "positions_m"), ("runs/vertical/hits", "directions"),
         ("runs/vertical/hits", "pretrigger_samples")]


def _small_recording(path):
    t = np.arange(1000) / FS
    force = np.where(t < 1e-4, 300 * np.sin(np.pi * t / 1e-4), 0.0)
    acc = 50 * np.exp(-900 * t) * np.sin(2 * np.pi * 3500 * t)
    one = np.stack([force, acc, -acc], axis=1)
    with h5py.File(path, "w") as f:
        f.attrs["format"] = "guidefit-recording"
        f.attrs["format_version"] = 1
        run = f.create_group("runs/vertical")
        run.attrs["sample_rate_hz"] = FS
        run.attrs["excitation_direction"] = [0.0, -1.0, 0.0]
        ds = run.create_dataset("hits", data=np.stack([one, 0.8 * one, 1.1 * one]))
        ds.attrs["channel_names"] = ["force", "acc_A_y", "acc_B_y"]
        ds.attrs["units"] = ["N", "m/s^2", "m/s^2"]
        ds.attrs["positions_m"] = [[0, 0, 0], [0.03, 0, 0.045], [-0.03, 0, 0.045]]
        ds.attrs["directions"] = [[0, -1, 0], [0, 1, 0], [0, 1, 0]]


def _consume(path):
    """Read, iterate every hit and identify; only guidefit errors may escape."""
    try:
        recording = read_recording(path)
        for run in recording.runs:
            for _ in iter_hits(run):
                pass
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            identify(path, settings=IdentifySettings(jackknife=False))
    except GuidefitError as exc:
        assert "\n" not in str(exc)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(where=st.sampled_from(ATTRS), value=odd_values)
# every sensor at one point: no run's readings follow the motion (was a ValueError from np.vstack)
@example(where=("runs/vertical/hits", "positions_m"), value=[[0.0, 0.0, 0.0]] * 3)
def test_any_attribute_value_gives_own_error(where, value):
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "rec.h5"
        _small_recording(path)
        with h5py.File(path, "a") as f:
            obj = f[where[0]] if where[0] else f
            if value is None:
                if where[1] in obj.attrs:
                    del obj.attrs[where[1]]
            else:
                try:
                    obj.attrs[where[1]] = value
                except (TypeError, ValueError):
                    return  # h5py cannot store it: no such file exists
        _consume(path)


@contextlib.contextmanager
def _hdf5_timeout(seconds):
    """Give the HDF5 library ``seconds`` to read a file's metadata (guidefit.io)."""
    old = os.environ.get("GUIDEFIT_HDF5_TIMEOUT_S")
    os.environ["GUIDEFIT_HDF5_TIMEOUT_S"] = str(seconds)
    try:
        yield
    finally:
        if old is None:
            del os.environ["GUIDEFIT_HDF5_TIMEOUT_S"]
        else:
            os.environ["GUIDEFIT_HDF5_TIMEOUT_S"] = old


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(offsets=st.lists(st.integers(0, 10**6), min_size=1, max_size=20), byte=st.integers(0, 255),
       cut=st.none() | st.floats(0.05, 0.99))
def test_corrupted_bytes_give_own_error(offsets, byte, cut):
    with tempfile.TemporaryDirectory() as folder, _hdf5_timeout(5):
        path = Path(folder) / "rec.h5"
        _small_recording(path)
        data = bytearray(path.read_bytes())
        for off in offsets:
            data[off % len(data)] = byte
        if cut is not None:
            data = data[: int(len(data) * cut)]
        path.write_bytes(bytes(data))
        _consume(path)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(edits=st.lists(st.tuples(st.integers(0, 5000), st.sampled_from(
    [",", ";", "\n", "#", " ", "nan", "x", "1,5", "", "-", "e", "inf", "force", "\t"])), max_size=8))
def test_mutated_csv_gives_own_error(edits):
    text = (SAMPLE / "mrb35_vertical.csv").read_text()[:20000]
    text = text[: text.rfind("\n") + 1]
    for pos, insert in edits:
        pos = pos % max(len(text), 1)
        text = text[:pos] + insert + text[pos + 1:]
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "rec.csv"
        path.write_text(text)
        _consume(path)


def test_sample_survives_a_copy_with_other_suffix(tmp_path):
    # a valid HDF5 file named .csv is bad input, reported as such
    target = tmp_path / "really_h5.csv"
    shutil.copy(SAMPLE / "mrb35_sample.h5", target)
    try:
        read_recording(target)
    except GuidefitError as exc:
        assert "really_h5.csv" in str(exc)
    else:
        raise AssertionError("an HDF5 file read as CSV must be refused")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the guard forks (Linux)")
def test_metadata_the_hdf5_library_cannot_finish_reading_is_a_damaged_file(tmp_path):
    """One byte of 0xff in the global heap that holds the root attributes makes
    libhdf5 2.0 loop (holding the GIL) when it reads them: guidefit must give
    up after its timeout with one RecordingError line, not hang. (With another
    HDF5 the same byte may give an ordinary error: also a RecordingError.)"""
    from guidefit.errors import RecordingError

    path = tmp_path / "rec.h5"
    _small_recording(path)
    data = bytearray(path.read_bytes())
    data[2056] = 0xFF
    path.write_bytes(bytes(data))
    start = time.monotonic()
    with _hdf5_timeout(2), pytest.raises(RecordingError) as info:
        read_recording(path)
    assert time.monotonic() - start < 15
    assert "\n" not in str(info.value) and "damaged HDF5 file" in str(info.value)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the guard forks (Linux)")
def test_command_line_gives_up_on_metadata_hdf5_cannot_read(tmp_path):
    """The command line guards the metadata read by default: exit 2, one line."""
    import subprocess

    path = tmp_path / "rec.h5"
    _small_recording(path)
    data = bytearray(path.read_bytes())
    data[2056] = 0xFF
    path.write_bytes(bytes(data))
    env = {**os.environ, "GUIDEFIT_HDF5_TIMEOUT_S": "2"}
    done = subprocess.run([sys.executable, "-m", "guidefit", "identify", str(path)], check=False, env=env,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "damaged HDF5 file" in lines[0]
