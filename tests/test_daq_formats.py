"""DAQ files through test setups: each format written with its own library, identified like the contract file.

One seeded simulated hammer test (two runs, a few hits in one continuous
record each, float32 in N and m/s^2) is written as the recording contract
(HDF5) and, in volts with known sensitivities, as NI TDMS (npTDMS), ASAM MDF 4
(asammdf), MATLAB v5 (scipy.io) and v7.3 (HDF5 laid out as MATLAB writes it,
h5py), WAV (soundfile, 24-bit PCM with a full-scale calibration), a
European text export (``;`` and decimal commas, preamble, unit row) and a
two-group TDMS file. Each is read through a setup and must give the same
samples in SI (to the precision of the file's numbers) and identify the same
joint as the contract file: K_V, K_H, c_V, c_H within a tenth of the
reported std (the std is what identify promises; the DAQ path adds only
rounding far below it).
"""

from __future__ import annotations

import json
import os
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from guidefit.io import read_recording, write_recording
from guidefit.simulate import SimulationConfig, simulate

G = 9.80665
# mV per unit of each guidefit channel, and the unit the setup states
SENSORS = {
    "force": ("N", 2.25),
    "acc_A_x": ("g", 10.2),
    "acc_A_y": ("g", 10.4),
    "acc_B_x": ("m/s^2", 1.01),
    "acc_B_y": ("m/s^2", 0.98),
    "acc_C_x": ("g", 9.9),
    "acc_C_y": ("g", 10.1),
    "acc_D_x": ("m/s^2", 1.03),
    "acc_D_y": ("m/s^2", 1.0),
}
DAQ_NAMES = {name: ("Hammer" if name == "force" else name[4:].replace("_", "").upper()) for name in SENSORS}
PARAMS = ("K_V", "K_H", "c_V", "c_H")


@pytest.fixture(scope="module")
def sim(tmp_path_factory):
    """The simulated test, its contract file and its identification."""
    from guidefit.identify import identify

    config = replace(SimulationConfig(), hits=3, record_s=0.04, layout="signals", gap_s=0.005)
    data, _ = simulate("MRB35", config=config, seed=11)
    folder = tmp_path_factory.mktemp("daq")
    write_recording(folder / "contract.h5", data)
    ident = identify(folder / "contract.h5")
    return data, folder, ident


def volts(run) -> np.ndarray:
    """(n, channels) float64 volts of a simulated run, column order of SENSORS."""
    index = {n: k for k, n in enumerate(run.channel_names)}
    cols = []
    for name, (unit, mv) in SENSORS.items():
        x = np.asarray(run.data[:, index[name]], dtype=np.float64)
        if unit == "g":
            x = x / G
        cols.append(x * mv / 1000.0)
    return np.column_stack(cols)


def setup_text(runs: dict, sources=None, extra_channel=None, root="") -> str:
    """A setup TOML: ``runs`` maps run name -> dict of run keys (TOML literals)."""
    lines = ['format = "guidefit-setup"', "format_version = 1", 'guide = "MRB35"', root]
    for name, (unit, mv) in SENSORS.items():
        source = DAQ_NAMES[name] if sources is None else sources[name]
        lines += [f"[channels.{name}]", f"source = {json.dumps(source)}", f'unit = "{unit}"']
        lines += [extra_channel(name, mv)] if extra_channel else [f"sensitivity_mv = {mv}"]
    for run, keys in runs.items():
        lines.append(f"[runs.{run}]")
        lines += [f"{k} = {v}" for k, v in keys.items()]
    return "\n".join(lines) + "\n"


def run_keys(data, file, **more) -> dict:
    out = {}
    for run in data.runs:
        keys = {"file": json.dumps(file(run.name)),
                "excitation_direction": json.dumps(run.excitation_direction.tolist()),
                "excitation_position_m": json.dumps(run.excitation_position_m.tolist())}
        keys.update({k: json.dumps(v(run.name) if callable(v) else v) for k, v in more.items()})
        out[run.name] = keys
    return out


def check_same(folder: Path, setup: str, data, ident, rtol_samples: float):
    """The setup's recording: same samples in SI as the simulation; same joint as the contract file."""
    from guidefit.identify import identify

    path = folder / "test.toml"
    path.write_text(setup)
    rec = read_recording(path)
    assert [r.name for r in rec.runs] == [r.name for r in data.runs]
    for run, truth in zip(rec.runs, data.runs):
        assert run.sample_rate_hz == pytest.approx(truth.sample_rate_hz, rel=1e-9)
        assert run.n_samples == truth.data.shape[0]
        got = run.read_block(0, run.n_samples, [run.channel_names.index(n) for n in truth.channel_names])
        scale = np.max(np.abs(truth.data), axis=0)
        assert np.max(np.abs(got - truth.data) / scale) < rtol_samples
        np.testing.assert_allclose([ch.position_m for ch in run.channels],
                                   [truth.positions_m[truth.channel_names.index(n)] for n in run.channel_names])
    result = identify(path).to_dict()["parameters"]
    for key in PARAMS:
        ref = ident.to_dict()["parameters"][key]
        assert abs(result[key]["value"] - ref["value"]) < 0.1 * ref["std"], (key, result[key], ref)
    return rec


def test_tdms_one_file_per_run(sim):
    from nptdms import ChannelObject, TdmsWriter

    data, folder, ident = sim
    for run in data.runs:
        v = volts(run)
        with TdmsWriter(folder / f"{run.name}.tdms") as writer:
            for start in range(0, v.shape[0], 20000):  # several segments, as a DAQ streams them
                writer.write_segment([
                    ChannelObject("Untitled", DAQ_NAMES[name], v[start:start + 20000, k],
                                  properties={"wf_increment": 1.0 / run.sample_rate_hz, "unit_string": "V"})
                    for k, name in enumerate(SENSORS)
                ])
    check_same(folder, setup_text(run_keys(data, lambda r: f"{r}.tdms")), data, ident, 1e-12)


def test_tdms_two_groups_one_file(sim):
    from nptdms import ChannelObject, TdmsWriter

    data, folder, ident = sim
    with TdmsWriter(folder / "both.tdms") as writer:
        for run in data.runs:
            v = volts(run).astype(np.float32)
            writer.write_segment([
                ChannelObject(run.name, DAQ_NAMES[name], v[:, k],
                              properties={"wf_increment": 1.0 / run.sample_rate_hz, "unit_string": "V"})
                for k, name in enumerate(SENSORS)
            ])
    text = setup_text(run_keys(data, lambda r: "both.tdms", group=lambda r: r))
    rec = check_same(folder, text, data, ident, 1e-6)
    assert rec.runs[0].sample_dtype == np.float32  # float32 volts stay float32 (single-precision FFTs)
    # without `group` the names are in both groups: one line naming them
    with pytest.raises(ValueError, match=r"both.tdms: channel 'Hammer' is in groups vertical, lateral; give"):
        check_same(folder, setup_text(run_keys(data, lambda r: "both.tdms")), data, ident, 1e-6)


def test_mdf_two_channel_groups(sim):
    from asammdf import MDF, Signal

    data, folder, ident = sim
    with MDF(version="4.10") as mdf:
        for run in data.runs:
            v = volts(run)
            t = np.arange(v.shape[0]) / run.sample_rate_hz
            mdf.append([Signal(v[:, k], t, name=DAQ_NAMES[n], unit="V") for k, n in enumerate(SENSORS)],
                       comment=run.name)
        mdf.save(folder / "test.mf4", overwrite=True)
    groups = {r.name: k for k, r in enumerate(data.runs)}
    check_same(folder, setup_text(run_keys(data, lambda r: "test.mf4", group=lambda r: groups[r])), data, ident,
               1e-12)


def test_mat_v5_columns_and_rate_variable(sim):
    import scipy.io

    data, folder, ident = sim
    for run in data.runs:
        scipy.io.savemat(folder / f"{run.name}.mat", {"data": volts(run), "fs": run.sample_rate_hz,
                                                      "info": "exported by a DAQ"})
    sources = {name: f"data:{k}" for k, name in enumerate(SENSORS)}
    check_same(folder, setup_text(run_keys(data, lambda r: f"{r}.mat"), sources=sources), data, ident, 1e-12)


def write_mat73(path: Path, variables: dict, group: str | None = None) -> None:
    """A MAT 7.3 file as MATLAB writes it: HDF5 after a 512-byte header, arrays transposed."""
    import h5py

    with h5py.File(path, "w", userblock_size=512) as f:
        node = f if group is None else f.create_group(group)
        if group is not None:
            node.attrs["MATLAB_class"] = np.bytes_("struct")
        for name, value in variables.items():
            arr = np.atleast_2d(np.asarray(value))
            if arr.shape[0] == 1 and np.ndim(value) == 1:
                arr = arr.T  # a MATLAB column vector (n x 1)
            ds = node.create_dataset(name, data=arr.T)  # MATLAB is column-major
            ds.attrs["MATLAB_class"] = np.bytes_("double" if arr.dtype == np.float64 else "single")
    with open(path, "r+b") as fh:
        fh.write(b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Fri Nov 20 10:00:00 2026 HDF5 schema 1.00 .")


def test_mat_v73_struct_time_vector_and_vectors(sim):
    data, folder, ident = sim
    for run in data.runs:
        v = volts(run)
        t = np.arange(v.shape[0]) / run.sample_rate_hz
        variables = {"t": t, "Hammer": v[:, 0], "acc": v[:, 1:]}
        write_mat73(folder / f"{run.name}_73.mat", variables, group="rec")
    sources = {name: ("Hammer" if name == "force" else f"acc:{k - 1}") for k, name in enumerate(SENSORS)}
    check_same(folder, setup_text(run_keys(data, lambda r: f"{r}_73.mat", group="rec"), sources=sources),
               data, ident, 1e-12)


def test_wav_pcm24_with_full_scale(sim):
    import soundfile

    data, folder, ident = sim
    # one calibration per channel for both runs: full scale 1.25 x the largest volts
    fs_v = 1.25 * np.max([np.max(np.abs(volts(run)), axis=0) for run in data.runs], axis=0)
    for run in data.runs:
        soundfile.write(folder / f"{run.name}.wav", volts(run) / fs_v, int(run.sample_rate_hz), subtype="PCM_24")
    sources = {name: k for k, name in enumerate(SENSORS)}
    scales = {name: fs_v[k] * 1000.0 / SENSORS[name][1] for k, name in enumerate(SENSORS)}  # unit per full scale
    text = setup_text(run_keys(data, lambda r: f"{r}.wav"), sources=sources,
                      extra_channel=lambda name, mv: f"scale = {float(scales[name])!r}")
    check_same(folder, text, data, ident, 1e-5)  # 24 bits of a full scale above both runs' peaks


def european_csv(run, v: np.ndarray) -> str:
    head = ["Messung;Hammertest MR35", "Datum;20.11.2026", "Abtastrate;200000 Hz", ""]
    names = ["Zeit"] + [DAQ_NAMES[n] for n in SENSORS]
    head.append(";".join(names))
    head.append(";".join(["s"] + ["V"] * len(SENSORS)))
    t = np.arange(v.shape[0]) / run.sample_rate_hz
    body = np.column_stack([t, v])
    rows = [";".join(f"{x:.10g}" for x in row).replace(".", ",") for row in body]
    return "\r\n".join(head + rows) + "\r\n"


def test_european_text_export(sim):
    data, folder, ident = sim
    for run in data.runs:
        (folder / f"{run.name}.csv").write_bytes(european_csv(run, volts(run)).encode("cp1252"))
    check_same(folder, setup_text(run_keys(data, lambda r: f"{r}.csv")), data, ident, 1e-8)


def test_uff58_time_data_through_a_setup(sim, tmp_path):
    pytest.importorskip("pyuff")
    data = sim[0]
    short = data.runs[0]
    cut = replace_data(short, short.data[:4000])
    write_recording(tmp_path / "v.uff", cut)
    text = "\n".join([
        'format = "guidefit-setup"', "format_version = 1",
        "[channels.force]", 'source = "force"', 'unit = "N"',
        "[channels.acc_A_y]", 'source = "acc_A_y"', 'unit = "m/s^2"',
        "[runs.vertical]", 'file = "v.uff"', "excitation_direction = [0.0, -1.0, 0.0]",
        "sample_rate_hz = 200000.0",
    ])
    (tmp_path / "test.toml").write_text(text)
    run = read_recording(tmp_path / "test.toml").runs[0]
    assert run.channel_names == ("force", "acc_A_y")
    k = short.channel_names.index("acc_A_y")
    np.testing.assert_allclose(run.read_block(0, 4000)[:, 1], short.data[:4000, k], rtol=1e-6, atol=1e-6)


def replace_data(run, data):
    from guidefit.io import RunData

    return RunData(run.name, run.sample_rate_hz, run.excitation_direction, run.channel_names, run.units,
                   run.positions_m, run.directions, data=data, excitation_position_m=run.excitation_position_m)


def test_convert_setup_to_contract_h5_identifies_the_same(sim):
    from guidefit.identify import identify
    from guidefit.io.setup import convert

    data, folder, ident = sim
    if not (folder / "vertical.csv").exists():
        for run in data.runs:
            (folder / f"{run.name}.csv").write_bytes(european_csv(run, volts(run)).encode("cp1252"))
    (folder / "conv.toml").write_text(setup_text(run_keys(data, lambda r: f"{r}.csv")))
    convert(folder / "conv.toml", folder / "converted.h5")
    back = read_recording(folder / "converted.h5")
    assert [ch.unit for ch in back.runs[0].channels] == [SENSORS[n][0] for n in SENSORS]  # g stays g
    result = identify(folder / "converted.h5").to_dict()["parameters"]
    for key in PARAMS:
        ref = ident.to_dict()["parameters"][key]
        assert abs(result[key]["value"] - ref["value"]) < 0.1 * ref["std"], key
    os.remove(folder / "converted.h5")


TEXT_DIALECTS = [
    ("semicolon, decimal comma, units in header", "Time [s];Hammer [V];A_Y [V]\n0,0;1,5;2\n0,1;2,5;3\n0,2;3,5;4\n",
     [("Hammer", "V"), ("A_Y", "V")], 10.0),
    ("spaces", "Time Hammer A_Y\n0.0 1.5 2\n0.1 2.5 3\n0.2 3.5 4\n", [("Hammer", None), ("A_Y", None)], 10.0),
    ("tab, decimal comma, parenthesised unit", "t (ms)\tHammer (V)\tA_Y\n0\t1,5\t2\n100\t2,5\t3\n200\t3,5\t4\n",
     [("Hammer", "V"), ("A_Y", None)], 10.0),
    ("comma and space, comments, quotes", '# DAQ export\n# 3 channels\n"Time","Hammer","A_Y"\n'
     '"0.0", "1.5", "2"\n"0.1", "2.5", "3"\n"0.2", "3.5", "4"\n', [("Hammer", None), ("A_Y", None)], 10.0),
    ("integers only: either decimal mark reads them alike", "Time;Hammer;A_Y\n0;1;2\n1;2;3\n2;3;4\n",
     [("Hammer", None), ("A_Y", None)], 1.0),
]


@pytest.mark.parametrize("text, channels, rate", [d[1:] for d in TEXT_DIALECTS], ids=[d[0] for d in TEXT_DIALECTS])
def test_text_dialects(tmp_path, text, channels, rate):
    from guidefit.io._daq import RunOptions
    from guidefit.io.text import open_daq

    (tmp_path / "x.txt").write_text(text)
    daq = open_daq(tmp_path / "x.txt", "x.txt", RunOptions("t.toml: runs.a"))
    assert [(c.name, c.unit) for c in daq.channels] == channels
    assert daq.rate_for(daq.channels) == pytest.approx(rate, rel=1e-12)
    block = daq.make_source(daq.channels, np.float64).read((slice(0, 3), slice(None)))
    np.testing.assert_allclose(block, [[1.5, 2], [2.5, 3], [3.5, 4]] if rate == 10.0 else [[1, 2], [2, 3], [3, 4]])


@pytest.mark.parametrize("text, message", [
    ("Time\tHammer\tA_Y\n0.0\t1,5\t2\n0,1\t2,5\t3\n0,2\t3,5\t4\n", r"line 2 above the data rows is numbers too"),
    ("Time;Hammer;A_Y\n0,0;1;2\n0,1;2;3\n0,2;3;4\nEND\n", r"x.txt: line 5, column 'Time': 'END' is not a number"),
    ("x\n1\n2\n", r"no rows of two or more numbers found .* give delimiter = .* decimal = .* in t.toml: runs.a"),
])
def test_text_that_cannot_be_read_is_one_line(tmp_path, text, message):
    from guidefit.io._daq import RunOptions
    from guidefit.io.text import open_daq

    (tmp_path / "x.txt").write_text(text)
    with pytest.raises(ValueError, match=message):
        daq = open_daq(tmp_path / "x.txt", "x.txt", RunOptions("t.toml: runs.a"))
        daq.make_source(daq.channels, np.float64)


def test_text_time_column_written_with_few_digits(tmp_path):
    """Times written to 1e-5 s at 51.2 kHz (a quarter sample period) still give the rate; a dropped
    sample (a gap of one period) is refused."""
    from guidefit.io._daq import RunOptions
    from guidefit.io.text import open_daq

    n, fs = 20000, 51200.0
    t = np.arange(n) / fs
    rows = [f"{a:.5f};{np.sin(a * 1e3):.6f};{np.cos(a * 1e3):.6f}".replace(".", ",") for a in t]
    (tmp_path / "x.csv").write_text("Time [s];Hammer;A_Y\n" + "\n".join(rows) + "\n")
    daq = open_daq(tmp_path / "x.csv", "x.csv", RunOptions("t.toml: runs.a"))
    assert daq.rate_for(daq.channels) == pytest.approx(fs, rel=1e-7)
    (tmp_path / "x.csv").write_text("Time [s];Hammer;A_Y\n" + "\n".join(rows[:10000] + rows[10001:]) + "\n")
    daq = open_daq(tmp_path / "x.csv", "x.csv", RunOptions("t.toml: runs.a"))
    with pytest.raises(ValueError, match=r"x.csv: time column 'Time': times jump by 4e-05 s, from 0.19529 s to "
                                         r"0.19533 s between samples 10000 and 10001"):
        daq.rate_for(daq.channels)


def _g_time_export(path, gap_at=None, gap_s=0.04, fs=51200.0, last_s=0.5):
    """A text export whose time column is written ``%g`` (6 significant digits, trailing zeros
    dropped: the last row is ``0.5``), with a gap of ``gap_s`` after sample ``gap_at``."""
    n = int(round(last_s * fs)) + 1
    k = np.arange(n)
    if gap_at is not None:
        k = k[: n - int(round(gap_s * fs))]
        k[gap_at:] += int(round(gap_s * fs))
    t = k / fs
    path.write_text("Time;Hammer\n" + "".join(f"{a:g};{np.sin(a * 1e3):.6f}\n" for a in t))
    return t


def test_text_time_column_written_g_with_a_gap_is_refused(tmp_path):
    """``%g`` times: each row's own printed step bounds its rounding (``0.5`` 0.1 s, ``0.234355`` 1e-6 s).
    Before, the last row's step alone (0.1 s, 2560 periods) let a 40 ms gap through: 45294 Hz for
    51200 (K -13.5 % in the issue's case), exit 0."""
    from guidefit.io._daq import RunOptions
    from guidefit.io.text import open_daq

    t = _g_time_export(tmp_path / "x.csv")
    assert (tmp_path / "x.csv").read_text().endswith("\n0.5;-0.467772\n")
    daq = open_daq(tmp_path / "x.csv", "x.csv", RunOptions("t.toml: runs.a"))
    # the times are off by up to half a microsecond over half a second
    assert daq.rate_for(daq.channels) == pytest.approx(51200.0, rel=2e-6)
    assert daq.count_rows(daq.channels) == t.size
    _g_time_export(tmp_path / "x.csv", gap_at=12000)
    daq = open_daq(tmp_path / "x.csv", "x.csv", RunOptions("t.toml: runs.a"))
    with pytest.raises(ValueError, match=r"^x.csv: time column 'Time': times jump by 0.04002 s, from 0.234355 s to "
                                         r"0.274375 s between samples 12000 and 12001; expected equally spaced"):
        daq.rate_for(daq.channels)


def test_text_utf16_with_bom(tmp_path):
    """Windows 'Unicode text' (UTF-16 LE with BOM, tabs): read like any other export."""
    from guidefit.io._daq import RunOptions
    from guidefit.io.text import open_daq

    rows = "".join(f"{k / 1000:.3f}\t{k}.5\t-{k}.25\r\n".replace(".", ",") for k in range(50))
    (tmp_path / "x.txt").write_bytes(("Zeit [s]\tKraft [V]\tBeschl. µ [V]\r\n" + rows).encode("utf-16"))
    daq = open_daq(tmp_path / "x.txt", "x.txt", RunOptions("t.toml: runs.a"))
    assert [(c.name, c.unit) for c in daq.channels] == [("Kraft", "V"), ("Beschl. µ", "V")]
    assert daq.rate_for(daq.channels) == pytest.approx(1000.0, rel=1e-12)
    np.testing.assert_allclose(daq.make_source(daq.channels, np.float64).read((slice(48, 50), slice(None))),
                               [[48.5, -48.25], [49.5, -49.25]])


@pytest.mark.parametrize("version", ["v5", "v73"])
@pytest.mark.parametrize("in_struct", [False, True])
def test_mat_vectors_columns_rate_and_time(tmp_path, version, in_struct):
    """A vector, columns of a samples x channels array, and Fs or t, at the root or in a struct."""
    import scipy.io

    from guidefit.io._daq import RunOptions
    from guidefit.io.mat import open_daq

    n = 300
    t = np.arange(n) / 2048.0
    hammer, acc = np.sin(t * 50), np.column_stack([np.cos(t * 50), t])
    variables = {"Hammer": hammer, "acc": acc, ("t" if in_struct else "Fs"): t if in_struct else 2048.0}
    path = tmp_path / "x.mat"
    if version == "v5":
        scipy.io.savemat(path, {"rec": variables} if in_struct else variables)
    else:
        write_mat73(path, variables, group="rec" if in_struct else None)
    daq = open_daq(path, "x.mat", RunOptions("t.toml: runs.a", group="rec" if in_struct else None))
    assert sorted(c.name for c in daq.channels) == ["Hammer", "acc:0", "acc:1"]
    assert daq.sample_rate_hz == pytest.approx(2048.0, rel=1e-12)
    if not (version == "v5" and not in_struct):  # savemat writes a 1-D array as 1 x n
        assert daq.find("Hammer:0") is daq.find("Hammer")  # column 0 of an n x 1 column vector
    chans = (daq.find("Hammer"), daq.find("acc:1"))
    block = daq.make_source(chans, np.float64).read((slice(10, 20), slice(None)))
    np.testing.assert_allclose(block, np.column_stack([hammer[10:20], acc[10:20, 1]]), rtol=1e-15)


def _write_mat(path, version, variables, group=None):
    import scipy.io

    if version == "v5":
        scipy.io.savemat(path, {group: variables} if group else variables)
    else:
        write_mat73(path, variables, group=group)


@pytest.mark.parametrize("version", ["v5", "v73"])
@pytest.mark.parametrize("group", [None, "rec"])
@pytest.mark.parametrize("n_time", [100, 299, 301, 2000])
def test_mat_time_vector_of_another_length_is_refused(tmp_path, version, group, n_time):
    """A time vector ``t`` shorter or longer than the channels describes other samples: refused
    when a run uses them (before: its rate was used, lengths never compared; K_V -9.8 % / +21 %
    with exit 0). A time vector of the channels' length gives the rate."""
    from guidefit.io._daq import RunOptions
    from guidefit.io.mat import open_daq

    data = np.random.default_rng(1).normal(size=(300, 3))
    _write_mat(tmp_path / "x.mat", version, {"data": data, "t": np.arange(n_time) / 1900.0}, group)
    daq = open_daq(tmp_path / "x.mat", "x.mat", RunOptions("t.toml: runs.a", group=group))
    with pytest.raises(ValueError, match=rf"^x.mat: time variable 't' holds {n_time} times but channel 'data:0' "
                                         r"300 samples; a time vector needs one time per sample$"):
        daq.rate_for(daq.channels)
    _write_mat(tmp_path / "x.mat", version, {"data": data, "t": np.arange(300) / 1900.0}, group)
    daq = open_daq(tmp_path / "x.mat", "x.mat", RunOptions("t.toml: runs.a", group=group))
    assert daq.rate_for(daq.channels) == pytest.approx(1900.0, rel=1e-12)


@pytest.mark.parametrize("version", ["v5", "v73"])
@pytest.mark.parametrize("t", [np.r_[np.arange(150), np.arange(150) + 170] / 1900.0,  # a gap of 20 samples
                               np.r_[np.arange(150), np.arange(150)] / 1900.0,  # two records joined
                               np.arange(300) ** 1.01 / 1900.0],  # not one rate
                         ids=["gap", "joined", "drift"])
def test_mat_time_vector_not_uniform_is_refused(tmp_path, version, t):
    from guidefit.io._daq import RunOptions
    from guidefit.io.mat import open_daq

    _write_mat(tmp_path / "x.mat", version, {"data": np.ones((300, 2)), "t": t})
    with pytest.raises(ValueError, match=r"^x.mat: time variable 't': (times jump|times not increasing|spacing not)"):
        open_daq(tmp_path / "x.mat", "x.mat", RunOptions("t.toml: runs.a"))


@pytest.mark.parametrize("version", ["v5", "v73"])
@pytest.mark.parametrize("group", [None, "rec"])
def test_mat_variable_of_three_dimensions(tmp_path, version, group):
    """A 3-D variable is no channel: the others are read (before, in v5: an internal error, exit 1);
    a source that names it, or a 3-D time vector, is told why in one line."""
    from guidefit.io._daq import RunOptions
    from guidefit.io.mat import open_daq

    data = np.arange(600.0).reshape(300, 2)
    variables = {"data": data, "fs": 1900.0, "cube": np.zeros((4, 3, 2))}
    _write_mat(tmp_path / "x.mat", version, variables, group)
    daq = open_daq(tmp_path / "x.mat", "x.mat", RunOptions("t.toml: runs.a", group=group))
    assert [c.name for c in daq.channels] == ["data:0", "data:1"]
    assert daq.rate_for(daq.channels) == pytest.approx(1900.0)
    block = daq.make_source(daq.channels, np.float64).read((slice(0, 300), slice(None)))
    np.testing.assert_array_equal(block, data)
    for source in ("cube", "cube:1"):
        with pytest.raises(ValueError, match=r"^x.mat: variable 'cube' is 4 x 3 x 2; a channel is a vector or a "
                                             r"column of a 2-D array whose rows are samples$"):
            daq.find(source)
    _write_mat(tmp_path / "x.mat", version, {"data": data, "t": np.zeros((300, 2, 2))}, group)
    with pytest.raises(ValueError, match=r"^x.mat: time variable 't' is 300 x 2 x 2; expected a vector$"):
        open_daq(tmp_path / "x.mat", "x.mat", RunOptions("t.toml: runs.a", group=group))


@pytest.mark.parametrize("version", ["v5", "v73"])
@pytest.mark.parametrize("variables, message", [
    ({"fs": 1900.0, "Fs": 1000.0}, r"variable 'fs' says 1900 Hz but variable 'Fs' 1000 Hz"),
    ({"Fs": 1900.0, "t": np.arange(300) / 1000.0}, r"time variable 't' gives 1000 Hz but variable 'Fs' says 1900 Hz"),
    ({"t": np.arange(300) / 1900.0, "time": np.arange(299) / 1900.0},
     r"time variables 't' \(300 times\) and 'time' \(299\) differ in length"),
    ({"t": np.arange(300) / 1900.0, "time": np.arange(300) / 1000.0},
     r"time variable 'time' gives 1000 Hz but time variable 't' says 1900 Hz"),
], ids=["fs-Fs", "Fs-t", "t-time-length", "t-time-rate"])
def test_mat_every_rate_and_time_variable_must_agree(tmp_path, version, variables, message):
    """Each way a .mat file states its rate is checked, not only the first found (before: ``Fs``
    beside a disagreeing ``fs``, or ``time`` beside ``t``, was ignored)."""
    from guidefit.io._daq import RunOptions
    from guidefit.io.mat import open_daq

    _write_mat(tmp_path / "x.mat", version, {"data": np.ones((300, 2)), **variables})
    with pytest.raises(ValueError, match="^x.mat: " + message):
        open_daq(tmp_path / "x.mat", "x.mat", RunOptions("t.toml: runs.a"))


@pytest.fixture(scope="module")
def default_layout_setup(tmp_path_factory):
    """The default layout (vertical run: y at A-D; lateral run: x at A-D) as MAT files in SI, and a
    function that writes a setup with some runs' excitation_direction replaced and identifies it."""
    import scipy.io

    from guidefit.identify import identify

    config = replace(SimulationConfig(), sensor_layout="default", hits=3, record_s=0.04, layout="signals",
                     gap_s=0.005)
    data, truth = simulate("MRB35", config=config, seed=11)
    folder = tmp_path_factory.mktemp("hammer")
    for run in data.runs:
        scipy.io.savemat(folder / f"{run.name}.mat", {**{n: np.asarray(run.data[:, k], float)
                                                         for k, n in enumerate(run.channel_names)},
                                                      "fs": run.sample_rate_hz})

    def identify_with(name: str, directions: dict, sensor_directions: dict | None = None):
        lines = ['format = "guidefit-setup"', "format_version = 1", 'guide = "MRB35"']
        for ch in dict.fromkeys(n for r in data.runs for n in r.channel_names):
            lines += [f"[channels.{ch}]", f'source = "{ch}"', f'unit = "{"N" if ch == "force" else "m/s^2"}"']
            if ch in (sensor_directions or {}):
                lines.append(f"direction = {json.dumps(sensor_directions[ch])}")
        for run in data.runs:
            lines += [f"[runs.{run.name}]", f'file = "{run.name}.mat"',
                      f"excitation_direction = {json.dumps(directions.get(run.name, run.excitation_direction.tolist()))}",
                      f"excitation_position_m = {json.dumps(run.excitation_position_m.tolist())}"]
        (folder / f"{name}.toml").write_text("\n".join(lines) + "\n")
        return identify(folder / f"{name}.toml"), folder / f"{name}.toml"

    return identify_with, truth


@pytest.mark.parametrize("direction", [[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
def test_setup_with_the_hammer_along_the_wrong_axis_is_incomplete_and_says_so(default_layout_setup, direction):
    """Was: the vertical run declared along x (a hit along x drives no vertical mode) gave K_V null
    with exit 0: its vertical and pitch modes were 'extra' and the vertical mode 'not excited on this
    layout'. Its strong modes are modes a hit along x cannot excite: the hammer direction is named,
    f_V, K_V, c_V 'not identified', exit 1; K_H as before."""
    from click.testing import CliRunner

    from guidefit.cli import main

    identify_with, truth = default_layout_setup
    result, path = identify_with("vertical_x", {"vertical": direction})
    assert result.parameters["K_V"]["value"] is None
    (line,) = [u for u in result.unidentified if u.startswith("f_V")]
    assert "runs.vertical.excitation_direction in vertical_x.toml" in line and "3529 Hz (vertical)" in line
    assert result.parameters["K_H"]["value"] == pytest.approx(truth["parameters"]["K_H"]["value"], rel=5e-3)
    out = CliRunner().invoke(main, ["identify", str(path)])
    assert out.exit_code == 1
    assert "identification incomplete" in out.output and "hammer direction may be entered wrong" in out.output


def test_setup_with_the_hammer_sign_reversed_keeps_k_and_names_it(default_layout_setup):
    """A vertical hit entered as +y (it was -y): every modal constant of the run reversed, no mode's drive
    changed; the labeller reads the run at its own sign, K and c do not depend on it, and a warning names
    the reversed excitation_direction."""
    identify_with, truth = default_layout_setup
    result, _ = identify_with("vertical_up", {"vertical": [0.0, 1.0, 0.0]})
    assert result.unidentified == () and result.gate is None
    for key in ("K_V", "K_H"):
        assert result.parameters[key]["value"] == pytest.approx(truth["parameters"][key]["value"], rel=5e-3)
    assert any("run 'vertical'" in w and "excitation_direction" in w and "reversed" in w for w in result.warnings)


@pytest.mark.parametrize("axis, along, key", [("y", [1.0, 0.0, 0.0], "V"), ("x", [0.0, 0.0, 1.0], "H")])
def test_setup_with_a_run_of_sensors_along_the_wrong_axis_is_incomplete_and_says_so(default_layout_setup, axis,
                                                                                     along, key):
    """Was: the vertical run's four y sensors entered with direction x (or the lateral run's x sensors with
    z) made the declared layout one that 'cannot see' the vertical (roll_low) mode: K_V (K_H) null, exit 0,
    while the run's strongest mode at 3529 Hz was 'a mode the model does not predict'. A joint mode the
    declared layout cannot see beside strong modes the model cannot place is not decided: exit 1, the line
    names the modes and what may be entered wrong; the other joint parameter as before."""
    from click.testing import CliRunner

    from guidefit.cli import main

    identify_with, truth = default_layout_setup
    wrong = {f"acc_{p}_{axis}": along for p in "ABCD"}
    result, path = identify_with(f"sensors_{axis}", {}, wrong)
    other = "H" if key == "V" else "V"
    assert result.parameters[f"K_{key}"]["value"] is None
    assert result.parameters[f"K_{other}"]["value"] == pytest.approx(truth["parameters"][f"K_{other}"]["value"],
                                                                     rel=5e-3)
    (line,) = [u for u in result.unidentified if u.startswith(f"f_{key}")]
    assert "the model does not predict" in line and "direction or position" in line
    out = CliRunner().invoke(main, ["identify", str(path)])
    assert out.exit_code == 1 and "identification incomplete" in out.output


@pytest.mark.parametrize("bad", ["OVL", "#N/A", "Hammer,A_Y"])
@pytest.mark.parametrize("header", ["", "Hammer,A_Y\n"])
def test_text_cell_that_is_not_a_number_early_in_the_data_is_named(tmp_path, bad, header):
    """Was: a text cell in row 300 of 2000 (a DAQ's 'OVL', a spreadsheet's '#N/A', a second export's header)
    made the longer block below it 'the data' and that row its header: every row above was dropped
    without a word (a setup with column indices and sample_rate_hz: 45699 of 46000 samples, hit 0 lost,
    exit 0). Now one line naming the row; a header above the data is still a header."""
    from guidefit.io._daq import RunOptions
    from guidefit.io.text import open_daq

    rows = [f"{k * 0.5:g},{k % 7 - 3:g}" for k in range(2000)]
    rows[300] = bad if "," in bad else f"{bad},1"
    (tmp_path / "x.csv").write_text(header + "\n".join(rows) + "\n")
    with pytest.raises(ValueError, match=rf"^x.csv: line {302 if header else 301}: '{bad.split(',')[0]}' \(field 0\) "
                                         r"is not a number, between rows of numbers above and below"):
        open_daq(tmp_path / "x.csv", "x.csv", RunOptions("t.toml: runs.a"))
    rows[300] = "150,1"
    (tmp_path / "x.csv").write_text(header + "\n".join(rows) + "\n")
    daq = open_daq(tmp_path / "x.csv", "x.csv", RunOptions("t.toml: runs.a"))
    assert daq.make_source(daq.channels, np.float64).read((slice(None), 0)).size == 2000
