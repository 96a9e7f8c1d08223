"""Tests of guidefit.io: the recording contract, read and write.

Bad files are written with h5py directly (or as text for CSV), each breaking
one rule of ``shared/recording-format.md``; every one must give a one-line
RecordingError that names the file and what is wrong.
"""

import os
import tempfile
import tracemalloc

import h5py
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from guidefit.errors import GuidefitError, RecordingError
from guidefit.io import (
    STANDARD_GRAVITY,
    RecordingData,
    RunData,
    default_channel_geometry,
    default_points,
    open_signals_writer,
    read_block,
    read_hit,
    read_recording,
    write_recording,
)

NAMES = ["force", "acc_A_y", "acc_B_y"]
POSITIONS = [[0.0, 0.01, 0.0], [0.03, 0.0, 0.045], [-0.03, 0.0, 0.045]]
DIRECTIONS = [[0.0, -1.0, 0.0], [0.0, 1.0, 0.0], [0.0, 1.0, 0.0]]


_DEFAULT = object()


def make_run(name="vertical", data=_DEFAULT, units=("N", "m/s^2", "g"), **kw):
    if data is _DEFAULT:
        data = np.arange(30.0).reshape(10, 3)
    return RunData(
        name=name,
        sample_rate_hz=kw.pop("sample_rate_hz", 200_000.0),
        excitation_direction=kw.pop("excitation_direction", [0.0, -1.0, 0.0]),
        channel_names=kw.pop("channel_names", NAMES),
        units=list(units),
        positions_m=kw.pop("positions_m", POSITIONS),
        directions=kw.pop("directions", DIRECTIONS),
        data=data,
        **kw,
    )


# ---------------------------------------------------------------- raw writers


def good_spec(layout="signals"):
    """A valid file as nested dicts; tests break one entry at a time."""
    shape = (8, 3) if layout == "signals" else (2, 8, 3)
    data = np.arange(np.prod(shape), dtype=np.float64).reshape(shape)
    return {
        "root": {"format": "guidefit-recording", "format_version": 1, "guide": "MRB35"},
        "runs": {
            "vertical": {
                "attrs": {
                    "sample_rate_hz": 200_000.0,
                    "excitation_direction": np.array([0.0, -1.0, 0.0]),
                },
                "datasets": {
                    layout: {
                        "data": data,
                        "attrs": {
                            "channel_names": NAMES,
                            "units": ["N", "m/s^2", "g"],
                            "positions_m": np.array(POSITIONS),
                            "directions": np.array(DIRECTIONS),
                        },
                    }
                },
            }
        },
    }


def write_raw(path, spec):
    """Write ``spec`` with h5py exactly as given (no validation)."""
    with h5py.File(path, "w") as f:
        for key, value in spec["root"].items():
            f.attrs[key] = value
        if spec.get("runs") is None:
            return path
        runs = f.create_group("runs")
        for name, run in spec["runs"].items():
            if run is None:  # a dataset where a run group belongs
                runs.create_dataset(name, data=np.zeros(3))
                continue
            group = runs.create_group(name)
            for key, value in run["attrs"].items():
                group.attrs[key] = value
            for dname, ds_spec in run["datasets"].items():
                ds = group.create_dataset(dname, data=ds_spec["data"])
                for key, value in ds_spec["attrs"].items():
                    if isinstance(value, list) and value and isinstance(value[0], str):
                        ds.attrs.create(key, value, dtype=h5py.string_dtype())
                    else:
                        ds.attrs[key] = value
    return path


def run_spec(spec):
    return spec["runs"]["vertical"]


def ds_spec(spec):
    datasets = run_spec(spec)["datasets"]
    return next(iter(datasets.values()))


def expect_error(path, *fragments):
    with pytest.raises(RecordingError) as info:
        read_recording(path)
    message = str(info.value)
    assert "\n" not in message, message
    assert message.startswith(os.fspath(path)), message
    for fragment in fragments:
        assert fragment in message, message
    return message


# ------------------------------------------------------------- reading HDF5


def test_read_hdf5_metadata_and_si_blocks(tmp_path):
    path = write_raw(tmp_path / "rec.h5", good_spec())
    rec = read_recording(path)
    assert rec.guide == "MRB35" and rec.description == ""
    (run,) = rec.runs
    assert run.name == "vertical" and run.layout == "signals"
    assert (run.n_samples, run.n_hits_stored, run.n_channels) == (8, 0, 3)
    assert run.force_index == 0 and run.response_indices == (1, 2)
    assert run.channels[2].unit == "g" and run.channels[2].scale_to_si == STANDARD_GRAVITY
    assert run.channels[1].point == "A" and run.channels[1].axis == "y"
    block = read_block(run, 2, 4)
    raw = np.arange(24.0).reshape(8, 3)[2:4]
    np.testing.assert_array_equal(block, raw * [1.0, 1.0, STANDARD_GRAVITY])
    assert block.dtype == np.float64 and block.flags.writeable
    # a subset of channels, in the order asked for
    np.testing.assert_array_equal(
        read_block(run, 0, 8, [2, 0]),
        np.arange(24.0).reshape(8, 3)[:, [2, 0]] * [STANDARD_GRAVITY, 1],
    )
    np.testing.assert_array_equal(run.read_block(0, 8, [0])[:, 0], np.arange(0.0, 24.0, 3.0))
    assert read_block(run, 5, 5).shape == (0, 3)


def test_read_hits_layout(tmp_path):
    spec = good_spec("hits")
    ds_spec(spec)["attrs"]["pretrigger_samples"] = 2
    run = read_recording(write_raw(tmp_path / "rec.h5", spec)).runs[0]
    assert run.layout == "hits" and run.n_hits_stored == 2 and run.n_samples == 8
    assert run.pretrigger_samples == 2
    expected = np.arange(48.0).reshape(2, 8, 3)[1] * [1.0, 1.0, STANDARD_GRAVITY]
    np.testing.assert_array_equal(read_hit(run, 1), expected)
    np.testing.assert_array_equal(run.read_hit(1, [2])[:, 0], expected[:, 2])
    with pytest.raises(ValueError, match="index=2"):
        read_hit(run, 2)
    with pytest.raises(ValueError, match="read_hit"):
        read_block(run, 0, 1)


def test_block_range_and_layout_errors(tmp_path):
    run = read_recording(write_raw(tmp_path / "rec.h5", good_spec())).runs[0]
    with pytest.raises(ValueError, match="stop=9"):
        read_block(run, 0, 9)
    with pytest.raises(ValueError, match="start=-1"):
        read_block(run, -1, 2)
    with pytest.raises(ValueError, match="channels"):
        read_block(run, 0, 2, [3])
    with pytest.raises(ValueError, match="read_block"):
        read_hit(run, 0)


@pytest.mark.parametrize(
    "encode",
    [
        pytest.param(lambda items: np.array([s.encode() for s in items]), id="fixed-length bytes"),
        pytest.param(lambda items: np.array(items, dtype=object), id="object array"),
        pytest.param(lambda items: [s.encode() for s in items], id="list of bytes"),
    ],
)
def test_string_attributes_in_any_h5py_form(tmp_path, encode):
    spec = good_spec()
    attrs = ds_spec(spec)["attrs"]
    attrs["channel_names"] = encode(NAMES)
    attrs["units"] = encode(["N", "m/s^2", "g"])
    spec["root"]["format"] = np.bytes_(b"guidefit-recording")
    spec["root"]["guide"] = np.bytes_(b"MRB35")
    run = read_recording(write_raw(tmp_path / "rec.h5", spec)).runs[0]
    assert run.channel_names == tuple(NAMES)
    assert [ch.unit for ch in run.channels] == ["N", "m/s^2", "g"]


def test_integer_samples_need_an_explicit_scale(tmp_path):
    """The contract says float32 or float64: integer counts read as values would be
    wrong by the ADC's step, so they are refused in one line unless the dataset gives
    'sample_scale' (the value of one count in each channel's unit)."""
    spec = good_spec()
    ds_spec(spec)["data"] = np.arange(24, dtype=np.int16).reshape(8, 3)
    with pytest.raises(RecordingError, match="integer dtype int16; expected float32 or float64, or .*'sample_scale'"):
        read_recording(write_raw(tmp_path / "rec.h5", spec))
    ds_spec(spec)["attrs"]["sample_scale"] = [0.0625, 0.5, 0.25]
    run = read_recording(write_raw(tmp_path / "scaled.h5", spec)).runs[0]
    block = read_block(run, 1, 2)
    assert block.dtype == np.float64 and run.sample_dtype == np.int16
    np.testing.assert_allclose(block, [[3 * 0.0625, 4 * 0.5, 5 * 0.25 * STANDARD_GRAVITY]], rtol=1e-15)
    # copied or loaded: values in the declared units, so a rewrite reads the same
    data = run.to_data()
    np.testing.assert_allclose(data.data[1], [3 * 0.0625, 4 * 0.5, 5 * 0.25], rtol=1e-15)
    write_recording(tmp_path / "copy.h5", read_recording(tmp_path / "scaled.h5"))
    np.testing.assert_allclose(read_block(read_recording(tmp_path / "copy.h5").runs[0], 1, 2), block, rtol=1e-15)
    for bad in ([1.0, 2.0], [1.0, 0.0, 1.0], "x"):
        ds_spec(spec)["attrs"]["sample_scale"] = bad
        with pytest.raises(RecordingError, match="sample_scale"):
            read_recording(write_raw(tmp_path / "bad.h5", spec))


def test_nan_samples_are_not_a_reading_error(tmp_path):
    spec = good_spec()
    ds_spec(spec)["data"][3, 1] = np.nan
    ds_spec(spec)["data"][4, 2] = np.inf
    run = read_recording(write_raw(tmp_path / "rec.h5", spec)).runs[0]
    block = read_block(run, 3, 5)
    assert np.isnan(block[0, 1]) and np.isinf(block[1, 2])


def test_direction_within_tolerance_is_accepted(tmp_path):
    spec = good_spec()
    ds_spec(spec)["attrs"]["directions"] = np.array(DIRECTIONS) * (1 + 5e-4)
    run_spec(spec)["attrs"]["excitation_direction"] = np.array([0, -1 + 9e-4, 0])
    run = read_recording(write_raw(tmp_path / "rec.h5", spec)).runs[0]
    assert run.channels[1].direction[1] == pytest.approx(1 + 5e-4)


def test_run_lookup_and_tables(tmp_path):
    rec = read_recording(write_raw(tmp_path / "rec.h5", good_spec()))
    assert rec.run("vertical") is rec.runs[0]
    with pytest.raises(RecordingError, match="no run 'lateral'; have vertical"):
        rec.run("lateral")
    channels = rec.runs[0].to_frame()
    assert list(channels["name"]) == NAMES
    assert channels.loc[2, "scale_to_si"] == STANDARD_GRAVITY
    assert channels.loc[1, "x_m"] == 0.03
    runs = rec.to_frame()
    assert runs.loc[0, "run"] == "vertical" and runs.loc[0, "n_samples"] == 8


def test_file_removed_after_reading_is_a_recording_error(tmp_path):
    path = write_raw(tmp_path / "rec.h5", good_spec())
    run = read_recording(path).runs[0]
    os.remove(path)
    with pytest.raises(RecordingError, match="run 'vertical': cannot read samples"):
        read_block(run, 0, 2)


def test_reader_holds_no_samples_and_reads_in_bounded_memory(tmp_path):
    n = 2_000_000  # 48 MB of float64 on disk
    header = make_run(data=None)
    path = tmp_path / "big.h5"
    block = np.ones((100_000, 3))
    tracemalloc.start()
    with open_signals_writer(path, header) as writer:
        for _ in range(n // len(block)):
            writer.append(block)
    _, peak_write = tracemalloc.get_traced_memory()
    tracemalloc.reset_peak()
    run = read_recording(path).runs[0]
    total = 0.0
    for start in range(0, n, 250_000):
        total += read_block(run, start, min(n, start + 250_000), [0]).sum()
    _, peak_read = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert run.n_samples == n and total == n
    assert peak_write < 12e6, peak_write  # a few blocks, never the 48 MB
    assert peak_read < 12e6, peak_read


# -------------------------------------------------------- malformed HDF5 files


def _mutate(change):
    def build(path):
        spec = good_spec()
        change(spec)
        return write_raw(path, spec)

    return build


def _raw_bytes(content):
    def build(path):
        path.write_bytes(content)
        return path

    return build


def _truncated(path):
    write_raw(path, good_spec())
    content = path.read_bytes()
    path.write_bytes(content[: len(content) // 2])
    return path


def _set(where, key, value):
    def change(spec):
        where(spec)[key] = value

    return change


def _delete(where, key):
    def change(spec):
        del where(spec)[key]

    return change


def _root(spec):
    return spec["root"]


def _run_attrs(spec):
    return run_spec(spec)["attrs"]


def _ds_attrs(spec):
    return ds_spec(spec)["attrs"]


def _two_datasets(spec):
    run_spec(spec)["datasets"]["hits"] = {"data": np.zeros((1, 8, 3)), "attrs": {}}


def _no_dataset(spec):
    run_spec(spec)["datasets"] = {}


def _names(*names):
    return _set(_ds_attrs, "channel_names", list(names))


def _data(value):
    def change(spec):
        ds_spec(spec)["data"] = value

    return change


def _no_runs(spec):
    spec["runs"] = None


def _empty_runs(spec):
    spec["runs"] = {}


def _run_is_dataset(spec):
    spec["runs"] = {"vertical": None}


BAD_HDF5 = {
    "empty file": (_raw_bytes(b""), ["file is empty"]),
    "not HDF5": (_raw_bytes(b"time,force\n0,1\n"), ["not an HDF5 file", ".csv suffix"]),
    "binary junk": (_raw_bytes(bytes(range(256)) * 4), ["not an HDF5 file"]),
    "truncated": (_truncated, ["truncated HDF5 file"]),
    "format missing": (
        _delete(_root, "format"),
        ["root attribute 'format' missing", "guidefit-recording"],
    ),
    "wrong format": (
        _set(_root, "format", "other-format"),
        ["'other-format'", "expected 'guidefit-recording'"],
    ),
    "version missing": (_delete(_root, "format_version"), ["'format_version' missing"]),
    "version 2": (
        _set(_root, "format_version", 2),
        ["format_version 2 is not supported", "version 1"],
    ),
    "version as text": (_set(_root, "format_version", "1"), ["format_version", "expected 1"]),
    "no /runs": (_no_runs, ["group '/runs' missing"]),
    "empty /runs": (_empty_runs, ["'/runs' holds no runs"]),
    "run is a dataset": (_run_is_dataset, ["run 'vertical': not a group"]),
    "no dataset": (_no_dataset, ["run 'vertical': no dataset 'signals' or 'hits'; have nothing"]),
    "both datasets": (_two_datasets, ["run 'vertical': has both 'signals' and 'hits'"]),
    "sample rate missing": (_delete(_run_attrs, "sample_rate_hz"), ["'sample_rate_hz' missing"]),
    "sample rate zero": (
        _set(_run_attrs, "sample_rate_hz", 0.0),
        ["sample_rate_hz is 0", "positive"],
    ),
    "sample rate negative": (_set(_run_attrs, "sample_rate_hz", -5.0), ["sample_rate_hz is -5"]),
    "sample rate NaN": (_set(_run_attrs, "sample_rate_hz", np.nan), ["sample_rate_hz is nan"]),
    "sample rate text": (_set(_run_attrs, "sample_rate_hz", "fast"), ["sample_rate_hz is 'fast'"]),
    "excitation direction missing": (
        _delete(_run_attrs, "excitation_direction"),
        ["'excitation_direction' missing"],
    ),
    "excitation direction not unit": (
        _set(_run_attrs, "excitation_direction", np.array([0.0, -2.0, 0.0])),
        ["excitation_direction (0, -2, 0) has length 2", "unit vector"],
    ),
    "excitation direction 2 numbers": (
        _set(_run_attrs, "excitation_direction", np.array([0.0, -1.0])),
        ["excitation_direction", "expected 3 numbers"],
    ),
    "excitation position NaN": (
        _set(_run_attrs, "excitation_position_m", np.array([0.0, np.nan, 0.0])),
        ["excitation_position_m", "finite"],
    ),
    "channel_names missing": (
        _delete(_ds_attrs, "channel_names"),
        ["dataset 'signals': attribute 'channel_names' missing"],
    ),
    "units missing": (_delete(_ds_attrs, "units"), ["attribute 'units' missing"]),
    "positions missing": (
        _delete(_ds_attrs, "positions_m"),
        ["attribute 'positions_m' missing", "(3, 3)"],
    ),
    "directions missing": (_delete(_ds_attrs, "directions"), ["attribute 'directions' missing"]),
    "channel_names numbers": (
        _set(_ds_attrs, "channel_names", np.arange(3)),
        ["'channel_names' is [0, 1, 2]"],
    ),
    "names/columns mismatch": (_names("force", "acc_A_y"), ["2 channel_names for 3 data columns"]),
    "units/columns mismatch": (
        _set(_ds_attrs, "units", ["N", "g"]),
        ["2 units for 3 data columns"],
    ),
    "no force": (
        _names("acc_A_y", "acc_B_y", "acc_C_y"),
        ["channel 'force' missing; have acc_A_y, acc_B_y, acc_C_y"],
    ),
    "two forces": (
        _names("force", "force", "acc_B_y"),
        ["2 channels named 'force'; expected exactly one"],
    ),
    "duplicate acc": (_names("force", "acc_A_y", "acc_A_y"), ["channel 'acc_A_y' appears 2 times"]),
    "unknown name": (
        _names("force", "temperature", "acc_B_y"),
        ["channel 'temperature' not recognised", "acc_<point>_<axis>"],
    ),
    "bad axis": (_names("force", "acc_A_w", "acc_B_y"), ["channel 'acc_A_w' not recognised"]),
    "case": (
        _names("Force", "acc_A_y", "acc_B_y"),
        ["channel 'Force' not recognised", "case-sensitive"],
    ),
    "unknown acc unit": (
        _set(_ds_attrs, "units", ["N", "mm/s^2", "g"]),
        ["channel 'acc_A_y': unit 'mm/s^2' unknown; expected 'm/s^2' or 'g'"],
    ),
    "unknown force unit": (
        _set(_ds_attrs, "units", ["kN", "g", "g"]),
        ["channel 'force': unit 'kN' unknown; expected 'N'"],
    ),
    "positions shape": (
        _set(_ds_attrs, "positions_m", np.zeros((3, 2))),
        ["positions_m has shape (3, 2); expected (3, 3)"],
    ),
    "positions NaN": (
        _set(_ds_attrs, "positions_m", np.array([[0, 0, 0], [np.nan, 0, 0], [0, 0, 0]])),
        ["positions_m row 1"],
    ),
    "direction not unit": (
        _set(_ds_attrs, "directions", np.array([[0, -1, 0], [0, 2, 0], [0, 1, 0]], dtype=float)),
        ["channel 'acc_A_y': direction (0, 2, 0) has length 2"],
    ),
    "direction zero": (
        _set(_ds_attrs, "directions", np.array([[0, -1, 0], [0, 1, 0], [0, 0, 0]], dtype=float)),
        ["channel 'acc_B_y': direction (0, 0, 0) has length 0"],
    ),
    "signals 3-D": (
        _data(np.zeros((2, 8, 3))),
        ["dataset 'signals' has shape (2, 8, 3); expected (n_samples, n_channels)"],
    ),
    "signals 1-D": (_data(np.zeros(8)), ["has shape (8,)"]),
    "no samples": (_data(np.zeros((0, 3))), ["holds no samples"]),
    "complex": (_data(np.zeros((8, 3), dtype=complex)), ["dtype complex128", "float32 or float64"]),
    "strings": (_data(np.array([["a", "b", "c"]] * 8, dtype="S1")), ["dtype |S1"]),
    "booleans": (_data(np.zeros((8, 3), dtype=bool)), ["dtype bool"]),
    "pretrigger too long": (
        _set(_ds_attrs, "pretrigger_samples", 8),
        ["pretrigger_samples is 8", "below 8"],
    ),
    "pretrigger fraction": (
        _set(_ds_attrs, "pretrigger_samples", 2.5),
        ["pretrigger_samples is 2.5"],
    ),
}


_RAW_CASES = {"empty file", "not HDF5", "binary junk", "truncated"}


@pytest.mark.parametrize("case", list(BAD_HDF5), ids=list(BAD_HDF5))
def test_malformed_hdf5_is_one_line_error(tmp_path, case):
    build, fragments = BAD_HDF5[case]
    if case not in _RAW_CASES:
        build = _mutate(build)
    path = build(tmp_path / "rec.h5")
    message = expect_error(path, *fragments)
    if case not in _RAW_CASES and "root" not in message:
        assert "run 'vertical'" in message or "/runs" in message or "format" in message, message


def test_hits_layout_needs_three_dimensions(tmp_path):
    spec = good_spec("hits")
    ds_spec(spec)["data"] = np.zeros((8, 3))
    expect_error(
        write_raw(tmp_path / "rec.h5", spec),
        "dataset 'hits' has shape (8, 3)",
        "(n_hits, n_samples, n_channels)",
    )


def test_missing_file_directory_and_suffix(tmp_path):
    expect_error(tmp_path / "nothing.h5", "no such file")
    (tmp_path / "folder.h5").mkdir()
    expect_error(tmp_path / "folder.h5", "is a directory")
    (tmp_path / "rec.txt").write_text("x")
    expect_error(tmp_path / "rec.txt", "unknown file type '.txt'")


def test_recording_error_is_value_error_and_exit_2():
    err = RecordingError("x")
    assert isinstance(err, ValueError) and isinstance(err, GuidefitError) and err.exit_code == 2


# -------------------------------------------------------------------- CSV


CSV_GOOD = """\
# guide: MRB35
# description: bench test, carriage 2
# sample_rate_hz: 1000
# excitation_direction: 0 -1 0
# excitation_position_m: 0 0.01 0
# operator: somebody else's key, ignored
# just a comment
time,force,acc_A_y,acc_C_y
0.000,1.0,0.5,0.25
0.001,2.0,1.5,-0.25
0.002,3.0,nan,0.75
"""


def write_text(tmp_path, text, name="rec.csv"):
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def test_csv_reader_defaults(tmp_path):
    rec = read_recording(write_text(tmp_path, CSV_GOOD))
    assert rec.guide == "MRB35" and rec.description == "bench test, carriage 2"
    (run,) = rec.runs
    assert run.name == "rec" and run.sample_rate_hz == 1000.0 and run.layout == "signals"
    assert run.channel_names == ("force", "acc_A_y", "acc_C_y")
    assert [ch.unit for ch in run.channels] == ["N", "m/s^2", "m/s^2"]
    np.testing.assert_allclose(run.channels[1].position_m, [0.030, 0.0, 0.045])
    np.testing.assert_allclose(run.channels[2].position_m, [-0.030, 0.0, -0.045])
    np.testing.assert_array_equal(run.channels[2].direction, [0.0, 1.0, 0.0])
    np.testing.assert_array_equal(run.force_channel.position_m, [0.0, 0.01, 0.0])
    np.testing.assert_array_equal(run.force_channel.direction, [0.0, -1.0, 0.0])
    block = read_block(run)
    assert block.shape == (3, 3) and np.isnan(block[2, 1])
    np.testing.assert_array_equal(block[:, 0], [1.0, 2.0, 3.0])


def test_csv_time_column_gives_rate_and_units_line(tmp_path):
    text = "# excitation_direction: 1 0 0\n# units: s N g\ntime,force,acc_B_x\n"
    text += "".join(f"{k / 25600:.6f},{k},{0.5 * k}\n" for k in range(2000))
    run = read_recording(write_text(tmp_path, text)).runs[0]
    assert run.sample_rate_hz == pytest.approx(25600, rel=1e-5)  # times rounded to 1 us
    assert run.channels[1].unit == "g"
    assert read_block(run, 2, 3)[0, 1] == pytest.approx(1.0 * STANDARD_GRAVITY)
    np.testing.assert_array_equal(run.force_channel.position_m, [0, 0, 0])  # no excitation position


def test_csv_without_hit_point_leaves_it_unknown(tmp_path):
    """The contract gives no default hit point: a CSV with neither excitation_position_m nor positions_m
    does not say where the hammer hit (identify warns; the force channel is only placed at the origin)."""
    text = "# sample_rate_hz: 1000\n# excitation_direction: 0 -1 0\nforce,acc_A_y\n1,2\n3,4\n"
    run = read_recording(write_text(tmp_path, text)).runs[0]
    assert run.hit_position_m is None
    from guidefit.consistency import unknown_hit_warnings

    (line,) = unknown_hit_warnings(read_recording(write_text(tmp_path, text)))
    assert "the hit point is unknown" in line
    given = text.replace("force,", "# positions_m: 0.01 0 0; 0.03 0 0.045\nforce,")
    np.testing.assert_allclose(read_recording(write_text(tmp_path, given)).runs[0].hit_position_m, [0.01, 0, 0])
    declared = text.replace("force,", "# excitation_position_m: 0 0.01 0\nforce,")
    np.testing.assert_allclose(read_recording(write_text(tmp_path, declared)).runs[0].hit_position_m, [0, 0.01, 0])


def test_csv_crlf_bom_and_no_time_column(tmp_path):
    text = "\ufeff# sample_rate_hz: 2e5\r\n# excitation_direction: 0,-1,0\r\nforce,acc_D_z\r\n1,2\r\n3,4\r\n\r\n"
    path = tmp_path / "rec.csv"
    path.write_bytes(text.encode("utf-8"))
    run = read_recording(path).runs[0]
    assert run.sample_rate_hz == 200_000.0 and run.n_samples == 2
    np.testing.assert_allclose(run.channels[1].position_m, [0.030, 0.0, -0.045])
    np.testing.assert_array_equal(run.channels[1].direction, [0, 0, 1])


def csv_with(header="time,force,acc_A_y", rows=("0,1.5,2.5", "0.001,1.5,2.5"), meta=None):
    meta = ["# sample_rate_hz: 1000", "# excitation_direction: 0 -1 0"] if meta is None else meta
    return "\n".join([*meta, header, *rows]) + "\n"


BAD_CSV = {
    "empty": ("", ["file is empty"]),
    "only metadata": (
        "# sample_rate_hz: 1000\n# excitation_direction: 0 -1 0\n",
        ["no header row"],
    ),
    "no header": (
        csv_with(header="0,1.5,2.5"),
        ["line 3 (header): starts with a number", "header row"],
    ),
    "no data": (csv_with(rows=()), ["no data rows after the header (line 3)"]),
    "semicolon header": (
        csv_with(header="time;force;acc_A_y", rows=("0;1,5;2,5",)),
        ["line 3 (header): fields separated by ';'"],
    ),
    "tab header": (
        csv_with(header="time\tforce\tacc_A_y", rows=("0\t1\t2",)),
        ["separated by tabs"],
    ),
    "decimal commas": (
        csv_with(rows=("0,1,5,2,5", "0,001,1,5,2,5")),
        ["line 4: 5 fields, header has 3", "decimal commas"],
    ),
    "semicolon rows": (csv_with(rows=("0;1.5;2.5",)), ["line 4: fields separated by ';'"]),
    "missing value": (
        csv_with(rows=("0,1.5,2.5", "0.001,,2.5")),
        ["line 5, column 'force': missing value"],
    ),
    "too few fields": (
        csv_with(rows=("0,1.5,2.5", "0.001,2.5")),
        ["line 5: 2 fields, header has 3"],
    ),
    "text in column": (
        csv_with(rows=("0,1.5,2.5", "0.001,1.5,overload")),
        ["line 5, column 'acc_A_y': 'overload' is not a number"],
    ),
    "quoted number": (csv_with(rows=('0,"1,5",2.5',)), ["line 4"]),
    "comment in data": (
        csv_with(rows=("0,1,2", "# pause", "0.002,1,2")),
        ["line 5: '#' line after the header"],
    ),
    "empty column name": (csv_with(header="time,force,", rows=("0,1,",)), ["column 3 has no name"]),
    "unknown channel": (csv_with(header="time,force,strain"), ["channel 'strain' not recognised"]),
    "no force": (
        csv_with(header="time,acc_A_y,acc_B_y"),
        ["channel 'force' missing; have acc_A_y, acc_B_y"],
    ),
    "unknown point": (
        csv_with(header="time,force,acc_E_y"),
        ["channel 'acc_E_y': point 'E' has no default position", "positions_m"],
    ),
    "no sample rate": (
        csv_with(header="force,acc_A_y", rows=("1,2",), meta=["# excitation_direction: 0 -1 0"]),
        ["sample rate unknown"],
    ),
    "rate with decimal comma": (
        csv_with(meta=["# sample_rate_hz: 1000,5", "# excitation_direction: 0 -1 0"]),
        ["line 1 'sample_rate_hz'", "decimal comma"],
    ),
    "rate negative": (
        csv_with(meta=["# sample_rate_hz: -1", "# excitation_direction: 0 -1 0"]),
        ["sample_rate_hz is -1"],
    ),
    "rate disagrees with time": (
        csv_with(rows=("0,1,2", "0.002,1,2", "0.004,1,2")),
        ["spacing gives 500 Hz but sample_rate_hz says 1000 Hz"],
    ),
    "time not uniform": (
        csv_with(
            rows=("0,1,2", "0.001,1,2", "0.0035,1,2", "0.004,1,2"),
            meta=["# excitation_direction: 0 -1 0"],
        ),
        ["column 'time': spacing not uniform"],
    ),
    "time decreasing": (csv_with(rows=("0.001,1,2", "0,1,2")), ["column 'time': not increasing"]),
    "no direction": (
        csv_with(meta=["# sample_rate_hz: 1000"]),
        ["excitation_direction missing", "0 -1 0"],
    ),
    "direction not unit": (
        csv_with(meta=["# sample_rate_hz: 1000", "# excitation_direction: 0 -2 0"]),
        ["line 2 'excitation_direction'", "has length 2"],
    ),
    "direction decimal commas": (
        csv_with(meta=["# sample_rate_hz: 1000", "# excitation_direction: 0,7071 -0,7071 0"]),
        ["line 2 'excitation_direction': 5 numbers; expected 3", "decimal commas"],
    ),
    "units count": (
        csv_with(meta=["# sample_rate_hz: 1000", "# excitation_direction: 0 -1 0", "# units: N"]),
        ["line 3 'units': 1 units for 2 channels"],
    ),
    "unknown unit": (
        csv_with(
            meta=["# sample_rate_hz: 1000", "# excitation_direction: 0 -1 0", "# units: N m/s2"]
        ),
        ["channel 'acc_A_y': unit 'm/s2' unknown"],
    ),
    "wrong format": (
        csv_with(
            meta=["# format: something", "# sample_rate_hz: 1000", "# excitation_direction: 0 -1 0"]
        ),
        ["line 1 'format'"],
    ),
    "wrong version": (
        csv_with(
            meta=["# format_version: 3", "# sample_rate_hz: 1000", "# excitation_direction: 0 -1 0"]
        ),
        ["'3' is not supported"],
    ),
    "positions count": (
        csv_with(
            meta=[
                "# sample_rate_hz: 1000",
                "# excitation_direction: 0 -1 0",
                "# positions_m: 0 0 0",
            ]
        ),
        ["line 3 'positions_m': 3 numbers; expected 6"],
    ),
}


@pytest.mark.parametrize("case", list(BAD_CSV), ids=list(BAD_CSV))
def test_malformed_csv_is_one_line_error(tmp_path, case):
    text, fragments = BAD_CSV[case]
    expect_error(write_text(tmp_path, text), *fragments)


def test_csv_binary_and_non_utf8(tmp_path):
    path = tmp_path / "rec.csv"
    path.write_bytes(b"force\n\xff\xfe1\n")
    expect_error(path, "not UTF-8 text")
    write_raw(tmp_path / "real.h5", good_spec())
    os.replace(tmp_path / "real.h5", path)
    expect_error(path, "expected a CSV text file")


# ----------------------------------------------------------- write and round trip


def test_write_read_round_trip_both_formats(tmp_path):
    signals = make_run(
        data=np.random.default_rng(0).normal(size=(50, 3)), excitation_position_m=[0, 0.01, 0]
    )
    hits = make_run(
        "lateral",
        data=np.random.default_rng(1).normal(size=(3, 40, 3)).astype(np.float32),
        pretrigger_samples=5,
    )
    recording = RecordingData([signals, hits], guide="MRB35", description="two runs\nsecond line")
    write_recording(tmp_path / "rec.h5", recording)
    back = read_recording(tmp_path / "rec.h5")
    assert [r.name for r in back.runs] == ["vertical", "lateral"]  # file order kept
    assert back.to_data() == recording
    assert back.to_data().runs[1].data.dtype == np.float32
    write_recording(tmp_path / "rec.csv", signals)
    assert read_recording(tmp_path / "rec.csv").to_data().runs[0] == signals
    assert not list(tmp_path.glob("*.part"))


def test_round_trip_detects_a_difference(tmp_path):
    run = make_run()
    write_recording(tmp_path / "rec.h5", run)
    back = read_recording(tmp_path / "rec.h5").to_data().runs[0]
    changed = make_run(data=run.data + np.eye(10, 3))
    assert back == run and back != changed
    assert back != make_run(units=("N", "g", "g"))


def test_to_data_si(tmp_path):
    write_recording(tmp_path / "rec.h5", make_run())
    si = read_recording(tmp_path / "rec.h5").to_data(si=True).runs[0]
    assert si.units == ("N", "m/s^2", "m/s^2")
    np.testing.assert_allclose(si.data[:, 2], np.arange(2.0, 30.0, 3.0) * STANDARD_GRAVITY)


def test_copy_a_read_recording_between_formats(tmp_path):
    original = RecordingData(
        [make_run(data=np.random.default_rng(2).normal(size=(20, 3)))], guide="MRB35"
    )
    write_recording(tmp_path / "a.csv", original)
    write_recording(tmp_path / "b.h5", read_recording(tmp_path / "a.csv"))
    write_recording(tmp_path / "c.h5", read_recording(tmp_path / "b.h5"))
    write_recording(tmp_path / "d.csv", read_recording(tmp_path / "c.h5"))
    assert read_recording(tmp_path / "d.csv").to_data() == original


def test_write_errors(tmp_path):
    two = RecordingData([make_run("a"), make_run("b")])
    with pytest.raises(RecordingError, match="CSV file holds one run, the recording has 2"):
        write_recording(tmp_path / "rec.csv", two)
    with pytest.raises(RecordingError, match="write 'hits' runs to .h5"):
        write_recording(tmp_path / "rec.csv", make_run(data=np.zeros((2, 4, 3))))
    with pytest.raises(RecordingError, match="description contains a line break"):
        write_recording(tmp_path / "rec.csv", RecordingData([make_run()], description="a\nb"))
    with pytest.raises(RecordingError, match="unknown file type '.mat'"):
        write_recording(tmp_path / "rec.mat", make_run())
    with pytest.raises(RecordingError, match="no data to write"):
        write_recording(tmp_path / "rec.h5", make_run(data=None))
    assert not list(tmp_path.iterdir())  # nothing half-written


def test_run_data_validation():
    with pytest.raises(RecordingError, match="run 'v': data has dtype complex128"):
        make_run("v", data=np.zeros((4, 3), dtype=complex))
    with pytest.raises(
        RecordingError, match="run 'v': signals data has 2 columns for 3 channel names"
    ):
        make_run("v", data=np.zeros((4, 2)))
    with pytest.raises(RecordingError, match="run name 'a/b'"):
        make_run("a/b")
    with pytest.raises(RecordingError, match="channel 'force' missing"):
        make_run(channel_names=["acc_A_y", "acc_B_y", "acc_C_y"])
    with pytest.raises(RecordingError, match="2 runs named 'x'"):
        RecordingData([make_run("x"), make_run("x")])
    with pytest.raises(RecordingError, match="pretrigger_samples is 10"):
        make_run(pretrigger_samples=10)
    assert make_run(data=np.zeros((2, 4, 3))).layout == "hits"


def test_signals_writer_blocks_equal_one_write(tmp_path):
    data = np.random.default_rng(3).normal(size=(1000, 3)).astype(np.float32)
    header = make_run(data=data[:10])
    with open_signals_writer(
        tmp_path / "w.h5", header, guide="MRB35", description="streamed"
    ) as writer:
        for start in range(10, 1000, 330):
            writer.append(data[start : start + 330])
        assert writer.n_samples == 1000
    rec = read_recording(tmp_path / "w.h5")
    assert rec.guide == "MRB35" and rec.description == "streamed"
    assert rec.runs[0].to_data() == make_run(data=data)
    # mode "a" adds a second run to the same file
    with open_signals_writer(tmp_path / "w.h5", make_run("lateral", data=None), mode="a") as writer:
        writer.append(np.ones((5, 3)))
    rec = read_recording(tmp_path / "w.h5")
    assert [r.name for r in rec.runs] == ["vertical", "lateral"] and rec.runs[1].n_samples == 5
    assert rec.runs[0].n_samples == 1000


def test_signals_writer_failures_leave_no_partial_run(tmp_path):
    path = tmp_path / "w.h5"
    with (
        pytest.raises(RecordingError, match="no samples were appended"),
        open_signals_writer(path, make_run(data=None)),
    ):
        pass
    assert not path.exists() and not list(tmp_path.iterdir())
    with (
        pytest.raises(RecordingError, match=r"block has shape \(4, 2\); expected \(n, 3\)"),
        open_signals_writer(path, make_run(data=None)) as writer,
    ):
        writer.append(np.zeros((4, 2)))
    assert not list(tmp_path.iterdir())
    write_recording(path, make_run())
    with (
        pytest.raises(RuntimeError, match="simulator failed"),
        open_signals_writer(path, make_run("second", data=None), mode="a") as writer,
    ):
        writer.append(np.zeros((4, 3)))
        raise RuntimeError("simulator failed")
    assert [r.name for r in read_recording(path).runs] == ["vertical"]
    with (
        pytest.raises(RecordingError, match="run 'vertical' already exists"),
        open_signals_writer(path, make_run(data=None), mode="a"),
    ):
        pass
    with (
        pytest.raises(RecordingError, match="writes HDF5"),
        open_signals_writer(tmp_path / "w.csv", make_run(data=None)),
    ):
        pass


# ------------------------------------------------------------------ hypothesis

_unit_vectors = (
    st.tuples(*[st.floats(-1, 1)] * 3)
    .filter(lambda v: np.linalg.norm(v) > 0.1)
    .map(lambda v: tuple(np.asarray(v) / np.linalg.norm(v)))
)
_finite = st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False)
# positions are metres in the carriage frame: within MAX_POSITION_M (1 m) of its origin (farther: mm read as m)
_coord = st.floats(-0.5, 0.5, allow_nan=False, allow_infinity=False)
_sample = st.one_of(st.floats(allow_nan=True, allow_infinity=True, width=64), _finite)


@st.composite
def run_data(draw, layout=None, csv=False):
    acc = draw(
        st.lists(
            st.tuples(st.sampled_from("ABCDE"), st.sampled_from("xyz")).map(
                lambda t: f"acc_{t[0]}_{t[1]}"
            ),
            unique=True,
            max_size=4,
        )
    )
    names = acc[:]
    names.insert(draw(st.integers(0, len(acc))), "force")
    n = len(names)
    units = [("N" if name == "force" else draw(st.sampled_from(["m/s^2", "g"]))) for name in names]
    layout = layout or draw(st.sampled_from(["signals", "hits"]))
    n_samples = draw(st.integers(1, 12))
    shape = (n_samples, n) if layout == "signals" else (draw(st.integers(1, 3)), n_samples, n)
    dtype = draw(st.sampled_from([np.float64, np.float32]))
    values = draw(st.lists(_sample, min_size=int(np.prod(shape)), max_size=int(np.prod(shape))))
    with np.errstate(over="ignore"):
        data = np.array(values, dtype=np.float64).astype(dtype).reshape(shape)
    name = draw(
        st.text(
            st.characters(whitelist_categories=("L", "N"), whitelist_characters="_-"),
            min_size=1,
            max_size=12,
        )
    )
    hit = draw(_unit_vectors)
    sign = draw(st.sampled_from([1.0, -1.0]))  # the force channel along the hit (either sign of its axis)
    return RunData(
        name=name,
        sample_rate_hz=draw(st.floats(1.0, 1e7)),
        excitation_direction=hit,
        channel_names=names,
        units=units,
        positions_m=[draw(st.tuples(_coord, _coord, _coord)) for _ in range(n)],
        directions=[tuple(sign * np.asarray(hit, float)) if c == "force" else draw(_unit_vectors) for c in names],
        data=data,
        excitation_position_m=draw(st.none() | st.tuples(_coord, _coord, _coord)),
        pretrigger_samples=draw(st.none() | st.integers(0, n_samples - 1)),
    )


_text = st.text(st.characters(blacklist_categories=("Cs", "Cc", "Zl", "Zp")), max_size=20).map(
    str.strip
)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    runs=st.lists(run_data(), min_size=1, max_size=3, unique_by=lambda r: r.name),
    guide=_text,
    description=_text,
)
def test_hdf5_round_trip_property(runs, guide, description):
    recording = RecordingData(runs, guide=guide or None, description=description)
    with tempfile.TemporaryDirectory() as folder:
        path = os.path.join(folder, "rec.h5")
        write_recording(path, recording)
        assert read_recording(path).to_data() == recording


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(run=run_data(layout="signals"), guide=_text, description=_text)
def test_csv_round_trip_property(run, guide, description):
    recording = RecordingData([run], guide=guide or None, description=description)
    with tempfile.TemporaryDirectory() as folder:
        path = os.path.join(folder, "rec.csv")
        write_recording(path, recording)
        assert read_recording(path).to_data() == recording


# ------------------------------------------------------------- default layout


def test_default_points_are_the_mrb35_layout():
    for guide in (None, "MRB35"):
        points = default_points(guide)
        assert set(points) >= {"A", "B", "C", "D"}
        np.testing.assert_allclose(points["A"], [0.030, 0.0, 0.045])
        np.testing.assert_allclose(points["B"], [-0.030, 0.0, 0.045])
        np.testing.assert_allclose(points["C"], [-0.030, 0.0, -0.045])
        np.testing.assert_allclose(points["D"], [0.030, 0.0, -0.045])


def test_default_channel_geometry():
    pos, dirs = default_channel_geometry(["acc_C_z", "force"], [1, 0, 0], [0.01, 0.02, 0.03])
    np.testing.assert_allclose(pos, [[-0.030, 0.0, -0.045], [0.01, 0.02, 0.03]])
    np.testing.assert_array_equal(dirs, [[0, 0, 1], [1, 0, 0]])
    pos, _ = default_channel_geometry(["acc_P1_x"], [1, 0, 0], points={"P1": (1, 2, 3)})
    np.testing.assert_array_equal(pos, [[1, 2, 3]])
    with pytest.raises(RecordingError, match="point 'Q'"):
        default_channel_geometry(["acc_Q_x"], [1, 0, 0])


def test_importing_reads_no_heavy_modules():
    import subprocess
    import sys

    code = "import sys, guidefit.io, guidefit.hits; print(sorted({'h5py', 'pandas', 'scipy'} & set(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_csv_with_a_guide_the_catalogue_does_not_know(tmp_path):
    text = csv_with(
        meta=["# guide: NOSUCH99", "# sample_rate_hz: 1000", "# excitation_direction: 0 -1 0"]
    )
    message = expect_error(write_text(tmp_path, text), "NOSUCH99")
    assert "positions" in message or "guide" in message
    # with positions given, the guide is not needed for reading
    text = csv_with(
        meta=[
            "# guide: NOSUCH99",
            "# sample_rate_hz: 1000",
            "# excitation_direction: 0 -1 0",
            "# positions_m: 0 0 0; 0.01 0.02 0.03",
        ]
    )
    run = read_recording(write_text(tmp_path, text, "ok.csv")).runs[0]
    np.testing.assert_array_equal(run.channels[1].position_m, [0.01, 0.02, 0.03])
    np.testing.assert_array_equal(run.channels[1].direction, [0, 1, 0])
