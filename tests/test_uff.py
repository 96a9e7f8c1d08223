"""Tests of guidefit.io.uff: UFF-58 FRF export, time-data export and import.

Every file written here is read back with pyuff itself (not with our
reader), so the fields are checked as any other UFF consumer sees them.

Tolerances. pyuff writes double-precision ASCII values with ``%20.11e``:
12 significant digits, a rounding error of at most 5e-12 of each part, so a
complex value comes back within 5e-12 |H|; the tests use ``rtol=1e-11`` (a
single-precision E13.5 write, 6 digits, would fail them). The abscissa
minimum and increment are E13.5 fields (6 digits): the FRFs here use a
50 Hz bin spacing, exact in 6 digits; the time data a sample rate whose
exact value guidefit carries in ID line 5.
"""

import json
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from guidefit.errors import RecordingError
from guidefit.frf import FrfSet
from guidefit.io import RecordingData, RunData, default_points, read_recording
from guidefit.io import write_recording as write_h5

pyuff = pytest.importorskip("pyuff")

from guidefit.io.uff import (  # noqa: E402 - after the pyuff skip
    direction_code,
    point_nodes,
    read_uff_recording,
    write_frf_uff,
    write_uff_recording,
)

SAMPLE = Path(__file__).resolve().parents[1] / "sample_data" / "mrb35_sample.h5"
RTOL_VALUE = 1e-11  # %20.11e: 12 significant digits (module docstring)


def read_sets(path) -> list[dict]:
    """All datasets of a UFF file via pyuff (a list even for one set)."""
    sets = pyuff.UFF(str(path)).read_sets()
    return [sets] if isinstance(sets, dict) else list(sets)


def sets58(path) -> list[dict]:
    return [s for s in read_sets(path) if s["type"] == 58]


# ------------------------------------------------------------------ FRF export


def accelerance(f_hz, f_n=3529.0, zeta=0.029, mass_kg=1.6):
    """SDOF accelerance -w^2 / (k - m w^2 + j c w), (m/s^2)/N: truth written by hand."""
    w, w_n = 2 * np.pi * f_hz, 2 * np.pi * f_n
    k, c = mass_kg * w_n**2, 2 * zeta * mass_kg * w_n
    return -(w**2) / (k - mass_kg * w**2 + 1j * c * w)


def make_frfset(run, channels, scale=1.0):
    f = np.arange(201) * 50.0  # 0 .. 10 kHz
    H = np.column_stack([scale * (k + 1) * accelerance(f) for k in range(len(channels))])
    coh = np.column_stack([np.linspace(0.5, 1.0, f.size) ** (k + 1) for k in range(len(channels))])
    coh[0, :] = np.nan  # undefined at 0 Hz: written as 0
    return FrfSet(
        run=run,
        frequency_hz=f,
        channels=tuple(channels),
        H=H,
        coherence=coh,
        estimator="H1",
        n_averages=4,
        group_sums={},
        exp_window_tau_s=None,
        force_window_s=None,
        sample_rate_hz=20_000.0,
    )


@pytest.fixture
def two_runs():
    return [
        make_frfset("vertical", ["acc_A_y", "acc_B_y", "acc_E_z"]),
        make_frfset("lateral", ["acc_A_x", "acc_top_x", "acc_E_x"], scale=0.3),
    ]


def test_numbering_helpers():
    assert point_nodes(["D", "E", "B", "E", "F"]) == {"D": 4, "E": 11, "B": 2, "F": 12}
    assert [direction_code(v) for v in ([1, 0, 0], [0, -1, 0], [0, 0, 1])] == [1, -2, 3]
    assert direction_code([0, -1, 0], "y") == -2
    with pytest.raises(RecordingError, match="not along the x axis"):
        direction_code([0, 1, 0], "x")
    with pytest.raises(RecordingError, match="not along an axis"):
        direction_code([0.6, 0.8, 0.0])


def test_frf_round_trip_values_and_fields(tmp_path, two_runs):
    path = tmp_path / "frf.uff"
    write_frf_uff(path, two_runs)
    all_sets = read_sets(path)
    units = all_sets[0]
    assert units["type"] == 164 and units["units_code"] == 1
    assert (units["length"], units["force"]) == (1.0, 1.0)
    frf_sets = [s for s in all_sets if s["type"] == 58 and s["func_type"] == 4]
    assert len(frf_sets) == 6 and len(all_sets) == 1 + 12
    nodes = {
        "acc_A_y": (1, 2),
        "acc_B_y": (2, 2),
        "acc_E_z": (11, 3),
        "acc_A_x": (1, 1),
        "acc_top_x": (12, 1),
        "acc_E_x": (11, 1),
    }
    for s in frf_sets:
        run_index = 0 if s["id2"] == "vertical" else 1
        frf = two_runs[run_index]
        channel = s["id1"].split()[1].split("/")[0]
        k = frf.channels.index(channel)
        assert s["id1"] == f"H1 {channel}/force"
        assert s["id5"].startswith("guidefit estimator=H1 n_averages=4")
        assert (s["rsp_node"], s["rsp_dir"]) == nodes[channel]
        assert (s["ref_node"], s["ref_dir"]) == (101 + run_index, 0)  # direction unknown
        assert s["ord_data_type"] == 6  # complex, double precision
        assert s["abscissa_spacing"] == 1
        assert (s["abscissa_spec_data_type"], s["abscissa_axis_units_lab"]) == (18, "Hz")
        assert (s["ordinate_spec_data_type"], s["ordinate_axis_units_lab"]) == (12, "m/s^2")
        assert (s["orddenom_spec_data_type"], s["orddenom_axis_units_lab"]) == (13, "N")
        np.testing.assert_array_equal(s["x"], frf.frequency_hz)  # 50 Hz: exact in E13.5
        np.testing.assert_allclose(s["data"], frf.H[:, k], rtol=RTOL_VALUE, atol=0)


def test_coherence_records(tmp_path, two_runs):
    path = tmp_path / "frf.unv"
    write_frf_uff(path, two_runs)
    coh_sets = [s for s in sets58(path) if s["func_type"] == 6]
    assert len(coh_sets) == 6
    for s in coh_sets:
        frf = two_runs[0 if s["id2"] == "vertical" else 1]
        channel = s["id1"].split()[1].split("/")[0]
        expected = np.nan_to_num(frf.coherence[:, frf.channels.index(channel)], nan=0.0)
        assert s["id1"] == f"coherence {channel}/force"
        assert s["ord_data_type"] == 4  # real, double precision
        assert (s["ordinate_spec_data_type"], s["orddenom_spec_data_type"]) == (1, 0)
        assert s["abscissa_spec_data_type"] == 18
        assert not np.iscomplexobj(s["data"])
        np.testing.assert_allclose(s["data"], expected, rtol=RTOL_VALUE, atol=0)
        assert s["data"][0] == 0.0  # NaN: the format has none


def test_frf_directions_from_the_recording(tmp_path):
    # the sensor at A points down, the hammer pushes along +z
    run = RunData(
        "axial",
        20_000.0,
        [0, 0, 1],
        ["force", "acc_A_y", "acc_B_x"],
        ["N", "m/s^2", "m/s^2"],
        [[0, 0, 0], [0.03, 0, 0.045], [-0.03, 0, 0.045]],
        [[0, 0, 1], [0, -1, 0], [1, 0, 0]],
        data=np.zeros((8, 3)),
    )
    write_h5(tmp_path / "rec.h5", run)
    path = tmp_path / "frf.uff"
    write_frf_uff(path, make_frfset("axial", ["acc_A_y", "acc_B_x"]), recording=tmp_path / "rec.h5")
    dofs = {
        (s["id1"], s["rsp_node"], s["rsp_dir"], s["ref_node"], s["ref_dir"]) for s in sets58(path)
    }
    assert ("H1 acc_A_y/force", 1, -2, 101, 3) in dofs
    assert ("H1 acc_B_x/force", 2, 1, 101, 3) in dofs
    with pytest.raises(RecordingError, match="no run of that name; have axial"):
        write_frf_uff(path, make_frfset("other", ["acc_A_y"]), recording=tmp_path / "rec.h5")


def test_frf_refusals(tmp_path, two_runs):
    with pytest.raises(RecordingError, match="channel 'ch1' is not 'acc_<point>_<axis>'"):
        write_frf_uff(tmp_path / "x.uff", make_frfset("r", ["ch1"]))
    with pytest.raises(RecordingError, match="unknown file type '.txt'"):
        write_frf_uff(tmp_path / "x.txt", two_runs)
    assert not list(tmp_path.iterdir())


def test_existing_file_is_replaced_not_appended(tmp_path, two_runs):
    path = tmp_path / "frf.uff"
    path.write_bytes(b"\x00junk\n")  # what pyuff's binary overwrite leaves behind
    write_frf_uff(path, two_runs)
    write_frf_uff(path, two_runs[:1])
    assert len(sets58(path)) == 6
    assert sorted(p.name for p in tmp_path.iterdir()) == ["frf.uff"]  # no .part left


# ------------------------------------------------------------------ time data


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    """A tiny simulated test (2 hits per run, continuous), as HDF5 and as UFF."""
    from guidefit.simulate import DEFAULT_RUNS, SimulationConfig, simulate

    folder = tmp_path_factory.mktemp("sim")
    config = SimulationConfig(hits=2, record_s=0.02, runs=DEFAULT_RUNS, layout="signals")
    recording, _truth = simulate("MRB35", config=config, seed=3)
    write_h5(folder / "sim.h5", recording)
    write_uff_recording(folder / "sim.uff", recording)
    return recording, folder / "sim.h5", folder / "sim.uff"


def test_time_fields_as_pyuff_reads_them(simulated):
    recording, _, uff_path = simulated
    sets = sets58(uff_path)
    assert len(sets) == sum(run.n_channels for run in recording.runs)
    for s in sets:
        assert s["func_type"] == 1 and s["ord_data_type"] == 4
        assert (s["abscissa_spec_data_type"], s["abscissa_axis_units_lab"]) == (17, "s")
        assert s["abscissa_inc"] == 5e-6 and s["abscissa_min"] == 0.0
        assert s["orddenom_spec_data_type"] == 0
        assert s["id5"] == "guidefit sample_rate_hz=200000.0 guide=MRB35"
    force = [s for s in sets if s["id1"] == "force"]
    assert [
        (
            s["id2"],
            s["rsp_node"],
            s["rsp_dir"],
            s["ref_node"],
            s["ref_dir"],
            s["ordinate_spec_data_type"],
        )
        for s in force
    ] == [("vertical", 101, -2, 101, -2, 13), ("lateral", 102, -1, 102, -1, 13)]
    acc_c_y = next(s for s in sets if s["id1"] == "acc_C_y" and s["id2"] == "vertical")
    assert (acc_c_y["rsp_node"], acc_c_y["rsp_dir"], acc_c_y["ordinate_spec_data_type"]) == (
        3,
        2,
        12,
    )


def test_time_round_trip_and_frfs(simulated):
    from guidefit.identify import IdentifySettings, frf_of_recording

    recording, h5_path, uff_path = simulated
    back = read_uff_recording(uff_path)
    assert back.guide == "MRB35"
    assert [run.name for run in back.runs] == ["vertical", "lateral"]
    points = default_points("MRB35")
    for original, run in zip(recording.runs, back.runs):
        assert run.layout == "signals" and run.sample_rate_hz == 200_000.0
        assert run.channel_names == original.channel_names
        assert [ch.unit for ch in run.channels] == list(original.units)
        np.testing.assert_array_equal(run.excitation_direction, original.excitation_direction)
        np.testing.assert_array_equal([ch.direction for ch in run.channels], original.directions)
        for ch in run.channels[1:]:
            np.testing.assert_array_equal(ch.position_m, points[ch.point])
        np.testing.assert_array_equal(run.force_channel.position_m, [0.0, 0.0, 0.0])
        assert run.excitation_position_m is None
        np.testing.assert_allclose(run.read_block(), original.data, rtol=RTOL_VALUE, atol=0)

    via_dispatch = read_recording(uff_path)
    assert [run.channel_names for run in via_dispatch.runs] == [r.channel_names for r in back.runs]

    # the same samples (float32 in the HDF5 file, float64 in the UFF): the same FFT precision
    double = IdentifySettings(fft_precision="double")
    frf_h5, _ = frf_of_recording(h5_path, double)
    frf_uff, _ = frf_of_recording(uff_path)
    assert frf_h5[0].fft_precision == frf_uff[0].fft_precision == "double"
    assert [f.run for f in frf_uff] == [f.run for f in frf_h5]
    for a, b in zip(frf_h5, frf_uff):
        assert b.channels == a.channels and b.n_averages == a.n_averages == 2
        np.testing.assert_array_equal(b.frequency_hz, a.frequency_hz)
        scale = np.abs(a.H).max()
        np.testing.assert_allclose(b.H, a.H, rtol=1e-9, atol=1e-9 * scale)
        np.testing.assert_allclose(b.coherence, a.coherence, rtol=1e-9, atol=1e-9)


def test_hits_layout_written_back_to_back(tmp_path):
    from guidefit.simulate import DEFAULT_RUNS, SimulationConfig, simulate

    config = SimulationConfig(hits=2, record_s=0.005, runs=DEFAULT_RUNS[:1], layout="hits")
    recording, _ = simulate("MRB35", config=config, seed=4)
    write_uff_recording(tmp_path / "hits.uff", recording)
    run = read_uff_recording(tmp_path / "hits.uff").runs[0]
    hits = recording.runs[0].data
    assert run.layout == "signals" and run.n_samples == hits.shape[0] * hits.shape[1]
    np.testing.assert_allclose(
        run.read_block(), hits.reshape(-1, hits.shape[2]), rtol=RTOL_VALUE, atol=0
    )


def make_run(rate=51_200.0, units=("N", "g"), n=16):
    data = np.column_stack([np.sin(np.arange(n)), np.cos(np.arange(n)) / 3]) * 7.0
    return RunData(
        "run 1",
        rate,
        [0, 0, -1],
        ["force", "acc_D_z"],
        list(units),
        [[0, 0, 0], [0.03, 0, -0.045]],
        [[0, 0, -1], [0, 0, -1]],
        data=data,
    )


@pytest.mark.parametrize("rate", [51_200.0, 300_000.0 / 7.0, 1.0e6, 12.5])
def test_exact_sample_rate_and_si(tmp_path, rate):
    run = make_run(rate)
    write_uff_recording(tmp_path / "r.uff", RecordingData([run]))
    back = read_uff_recording(tmp_path / "r.uff").runs[0]
    assert back.sample_rate_hz == rate  # E13.5 cannot carry it; ID line 5 does
    assert back.name == "run 1" and [ch.unit for ch in back.channels] == ["N", "m/s^2"]
    np.testing.assert_array_equal(back.force_channel.direction, [0, 0, -1])
    np.testing.assert_array_equal(back.channels[1].direction, [0, 0, -1])
    expected = run.data * [1.0, 9.80665]  # g written as m/s^2
    np.testing.assert_allclose(back.read_block(), expected, rtol=RTOL_VALUE, atol=0)


# ------------------------------------------------------ files of other programs


def foreign_set(data, rsp, ref, spec, label="NONE", rate=51_200.0, func_type=1, **kw):
    """A dataset 58 as another program writes it: no guidefit ID lines."""
    x = np.arange(len(data)) / rate
    return pyuff.prepare_58(
        binary=0,
        func_type=func_type,
        rsp_node=rsp[0],
        rsp_dir=rsp[1],
        ref_node=ref[0],
        ref_dir=ref[1],
        data=data,
        x=x,
        abscissa_spacing=1,
        abscissa_spec_data_type=17,
        ordinate_spec_data_type=spec,
        orddenom_spec_data_type=0,
        ordinate_axis_units_lab=label,
        id1="NONE",
        **kw,
    )


def write_foreign(path, sets):
    pyuff.UFF(str(path)).write_sets(sets, mode="overwrite")
    return path


def test_foreign_time_file_conventions(tmp_path):
    rng = np.random.default_rng(0)
    sig = [rng.normal(size=64) for _ in range(6)]
    path = write_foreign(
        tmp_path / "testlab.uff",
        [
            foreign_set(sig[0], (7, -2), (7, -2), 13, "N"),
            foreign_set(sig[1], (1, 2), (7, -2), 12, "m/s^2"),
            foreign_set(sig[2], (3, -1), (7, -2), 12),
            foreign_set(sig[3], (25, 3), (7, -2), 12, "g"),
            foreign_set(sig[4], (8, 1), (8, 1), 0),  # force found at the reference DOF
            foreign_set(sig[5], (2, 1), (8, 1), 12),
        ],
    )
    rec = read_uff_recording(path)
    assert rec.guide is None
    vertical, lateral = rec.runs
    assert (vertical.name, lateral.name) == ("ref7-Y", "ref8+X")
    assert vertical.channel_names == ("force", "acc_A_y", "acc_C_x", "acc_N25_z")
    assert lateral.channel_names == ("force", "acc_B_x")
    assert vertical.sample_rate_hz == 51_200.0  # the whole number of Hz of 1.95312e-05 s
    assert [ch.unit for ch in vertical.channels] == ["N", "m/s^2", "m/s^2", "g"]
    np.testing.assert_array_equal(vertical.excitation_direction, [0, -1, 0])
    np.testing.assert_array_equal(lateral.excitation_direction, [1, 0, 0])
    np.testing.assert_array_equal(vertical.channels[2].direction, [-1, 0, 0])
    pts = default_points()
    np.testing.assert_array_equal(vertical.channels[1].position_m, pts["A"])
    np.testing.assert_array_equal(vertical.channels[2].position_m, pts["C"])
    np.testing.assert_array_equal(vertical.channels[3].position_m, [0, 0, 0])
    block = vertical.read_block()
    np.testing.assert_allclose(block[:, :3], np.column_stack(sig[:3]), rtol=RTOL_VALUE, atol=0)
    np.testing.assert_allclose(block[:, 3], sig[3] * 9.80665, rtol=RTOL_VALUE, atol=0)


# ------------------------------------------------------------------ bad files


def _valid(tmp_path):
    return [
        foreign_set(np.ones(32), (9, 2), (9, 2), 13),
        foreign_set(np.ones(32), (1, 2), (9, 2), 12),
    ]


def _truncated(tmp_path):
    path = write_foreign(tmp_path / "bad.uff", _valid(tmp_path))
    raw = path.read_bytes()
    path.write_bytes(raw[: len(raw) - 300])


def _text(content: bytes):
    def make(tmp_path):
        (tmp_path / "bad.uff").write_bytes(content)

    return make


def _short_data(tmp_path):
    path = write_foreign(tmp_path / "bad.uff", _valid(tmp_path))
    lines = path.read_text().splitlines(keepends=True)
    del lines[-3]  # one data line of the last set
    path.write_text("".join(lines))


BAD = {
    "garbage": (_text(b"hello\nworld\n"), "no UFF datasets"),
    "frf only": (
        lambda t: write_frf_uff(t / "bad.uff", make_frfset("r", ["acc_A_y"])),
        r"no time data .*function type 4 \(FRF\)",
    ),
    "complex": (
        lambda t: [foreign_set(np.ones(8) * 1j, (9, 2), (9, 2), 13)],
        "set 1: complex time data",
    ),
    "lengths": (
        lambda t: [
            foreign_set(np.ones(32), (9, 2), (9, 2), 13),
            foreign_set(np.ones(31), (1, 2), (9, 2), 12),
        ],
        "set 2: 31 samples, set 1 of the same run",
    ),
    "rates": (
        lambda t: [
            foreign_set(np.ones(32), (9, 2), (9, 2), 13),
            foreign_set(np.ones(32), (1, 2), (9, 2), 12, rate=1000.0),
        ],
        "set 2: time step",
    ),
    "no force": (
        lambda t: [
            foreign_set(np.ones(8), (1, 2), (9, 2), 12),
            foreign_set(np.ones(8), (2, 2), (9, 2), 12),
        ],
        "no force record",
    ),
    "two forces": (
        lambda t: [
            foreign_set(np.ones(8), (9, 2), (9, 2), 13),
            foreign_set(np.ones(8), (1, 2), (9, 2), 13),
        ],
        "sets 1, 2: 2 force records",
    ),
    "displacement": (
        lambda t: [
            foreign_set(np.ones(8), (9, 2), (9, 2), 13),
            foreign_set(np.ones(8), (1, 2), (9, 2), 8),
        ],
        r"set 2: ordinate is displacement \(8\)",
    ),
    "rotation": (
        lambda t: [
            foreign_set(np.ones(8), (9, 2), (9, 2), 13),
            foreign_set(np.ones(8), (1, 5), (9, 2), 12),
        ],
        "set 2: response direction 5",
    ),
    "unit": (
        lambda t: [
            foreign_set(np.ones(8), (9, 2), (9, 2), 13),
            foreign_set(np.ones(8), (1, 2), (9, 2), 12, "mm/s^2"),
        ],
        "set 2: acceleration unit 'mm/s\\^2' unsupported",
    ),
    "not SI": (
        lambda t: (
            [
                pyuff.prepare_164(
                    units_code=5,
                    units_description="mm (newton)",
                    temp_mode=1,
                    length=1000.0,
                    force=1.0,
                    temp=1.0,
                    temp_offset=273.15,
                )
            ]
            + _valid(t)
        ),
        "set 1 \\(units, dataset 164\\).*guidefit reads SI",
    ),
    "truncated": (_truncated, "set 2 is truncated"),
    "short data": (_short_data, "set 2: 28 values for the 32 its header gives"),
    "empty": (_text(b""), "file is empty"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_malformed_uff_is_one_line_error(tmp_path, case):
    make, message = BAD[case]
    sets = make(tmp_path)
    path = tmp_path / "bad.uff"
    if sets is not None:
        write_foreign(path, sets)
    with pytest.raises(RecordingError, match=message) as info:
        read_recording(path)
    text = str(info.value)
    assert text.startswith(str(path)) and "\n" not in text


def test_missing_file(tmp_path):
    with pytest.raises(RecordingError, match="no such file"):
        read_uff_recording(tmp_path / "none.uff")


def test_without_pyuff_one_line_hint(tmp_path, monkeypatch, two_runs):
    write_frf_uff(tmp_path / "ok.uff", two_runs)
    monkeypatch.setitem(sys.modules, "pyuff", None)  # import pyuff -> ImportError
    for call in (
        lambda: write_frf_uff(tmp_path / "x.uff", two_runs),
        lambda: read_recording(tmp_path / "ok.uff"),
    ):
        with pytest.raises(RecordingError, match=r"pip install 'guidefit\[uff\]'") as info:
            call()
        assert "\n" not in str(info.value)


# ------------------------------------------------------- CLI and other readers


@pytest.fixture(scope="module")
def sample_frf_uff(tmp_path_factory):
    """``guidefit frf sample_data/mrb35_sample.h5 --out frf.uff`` through click."""
    from guidefit.cli import main

    path = tmp_path_factory.mktemp("cli") / "frf.uff"
    result = CliRunner().invoke(main, ["frf", str(SAMPLE), "--out", str(path)])
    assert result.exit_code == 0, result.output
    assert "written to" in result.output
    return path


def test_cli_frf_writes_uff(sample_frf_uff):
    sets = sets58(sample_frf_uff)
    assert len(sets) == 2 * 8 * 2
    assert sorted({(s["func_type"], s["ref_node"]) for s in sets}) == [
        (4, 101),
        (4, 102),
        (6, 101),
        (6, 102),
    ]
    assert {s["rsp_node"] for s in sets} == {1, 2, 3, 4}


def test_cli_reads_uff_time_data(simulated):
    from guidefit.cli import main

    _, _, uff_path = simulated
    result = CliRunner().invoke(main, ["identify", str(uff_path), "--json"])
    assert result.exit_code == 0, result.output
    out = json.loads(result.stdout.strip().splitlines()[-1])
    assert out["guide"] == "MRB35"
    assert out["parameters"]["f_V"]["value"] == pytest.approx(3529.0, rel=2e-3)


def test_sdypy_ema_reads_the_frf_file(sample_frf_uff):
    EMA = pytest.importorskip("sdypy.EMA")
    model = EMA.Model(lower=2000, upper=6000, pol_order_high=40)
    model.read_uff(str(sample_frf_uff))  # sdypy-EMA's own UFF reader (FRFs, type 4)
    assert model.frf.shape[0] == 16 and model.frf_form == "accelerance"
    model.get_poles(show_progress=False)
    model.select_closest_poles([3500.0])
    # the nominal MRB35 vertical mode (sample_data/README.md: truth 3529.03 Hz)
    assert model.nat_freq[0] == pytest.approx(3529.03, rel=1e-3)


def test_convert_refuses_uff_time_data_whose_hit_point_is_unknown(simulated, tmp_path):
    """Without the reference node's coordinates the hit point is unknown; a recording written from it
    would state the force channel's position as the hit (read back as known): refused in one line."""
    import pyuff

    from guidefit.cli import main

    _, _, uff_path = simulated
    sets = [s for s in pyuff.UFF(str(uff_path)).read_sets() if s["type"] not in (15, 2411)]
    bare = tmp_path / "bare.uff"
    pyuff.UFF(str(bare)).write_sets(sets, mode="add")
    assert read_recording(bare).runs[0].hit_position_m is None
    out = tmp_path / "bare.h5"
    result = CliRunner().invoke(main, ["convert", str(bare), "-o", str(out)])
    assert result.exit_code == 2, result.output
    line = result.output.strip().splitlines()[-1]
    assert "the hit point is unknown" in line and "excitation_position_m" in line
    assert not out.exists()
