"""Test setups (shared/test-setup-format.md): every malformed setup is exit 2 and one line naming
the setup file, the table and the key; what a setup may leave out has the documented default;
the commands take a setup wherever they take a recording."""

from __future__ import annotations

import json
import re
import subprocess
import sys

import numpy as np
import pytest
from click.testing import CliRunner

from guidefit.cli import main
from guidefit.io import read_recording
from guidefit.io.setup import SetupError, load_setup

RATE = 51200.0
N = 2048


def tdms(path, groups=None, unit="V", rate=RATE, extra=()):
    """A small TDMS file with the contract's example channel names (Hammer, AccA_Y, AccB_Y)."""
    from nptdms import ChannelObject, TdmsWriter

    t = np.arange(N) / rate
    signals = {"Hammer": np.exp(-((t - 0.005) / 1e-4) ** 2), "AccA_Y": np.sin(2e3 * t), "AccB_Y": np.cos(2e3 * t)}
    signals.update({name: np.sin(1e3 * t) for name in extra})
    with TdmsWriter(path) as writer:
        for group in groups or ["Untitled"]:
            writer.write_segment([
                ChannelObject(group, name, x, properties={"wf_increment": 1 / rate, "unit_string": unit})
                for name, x in signals.items()
            ])


GOOD = """\
format = "guidefit-setup"
format_version = 1
guide = "MRB35"
description = "MR 35 carriage, steel tip"

[channels.force]
source = "Hammer"
unit = "N"
sensitivity_mv = 2.25

[channels.acc_A_y]
source = "AccA_Y"
unit = "g"
sensitivity_mv = 10.2

[channels.acc_B_y]
source = "AccB_Y"
unit = "m/s^2"
sensitivity_mv = 1.04

[runs.vertical]
file = "vertical.tdms"
excitation_direction = [0.0, -1.0, 0.0]
excitation_position_m = [0.020, 0.0, 0.035]

[runs.lateral]
file = "lateral.tdms"
excitation_direction = [-1.0, 0.0, 0.0]
"""


@pytest.fixture
def folder(tmp_path, monkeypatch):
    tdms(tmp_path / "vertical.tdms")
    tdms(tmp_path / "lateral.tdms")
    monkeypatch.chdir(tmp_path)
    return tmp_path


def edit(text: str, old: str, new: str) -> str:
    assert old in text, old
    return text.replace(old, new, 1)


def test_the_example_setup_reads_as_a_recording(folder):
    (folder / "test.toml").write_text(GOOD)
    rec = read_recording("test.toml")
    assert rec.guide == "MRB35" and rec.description.startswith("MR 35")
    vertical, lateral = rec.runs
    assert vertical.channel_names == ("force", "acc_A_y", "acc_B_y")
    assert vertical.sample_rate_hz == RATE and vertical.n_samples == N and vertical.layout == "signals"
    # defaults: force at the hit point along the excitation; accelerometers at the guide's points, +axis
    np.testing.assert_allclose(vertical.channels[0].position_m, [0.020, 0.0, 0.035])
    np.testing.assert_allclose(lateral.channels[0].direction, [-1.0, 0.0, 0.0])
    np.testing.assert_allclose(vertical.channels[1].position_m, [0.030, 0.0, 0.045])
    np.testing.assert_allclose(vertical.channels[2].direction, [0.0, 1.0, 0.0])
    assert lateral.excitation_position_m is None
    # value in unit = volts x 1000 / sensitivity_mv; g -> m/s^2 by 9.80665
    from nptdms import TdmsFile

    volts = TdmsFile.read("vertical.tdms")["Untitled"]
    block = vertical.read_block(0, N)
    np.testing.assert_allclose(block[:, 0], volts["Hammer"][:] * 1000 / 2.25, rtol=1e-12)
    np.testing.assert_allclose(block[:, 1], volts["AccA_Y"][:] * 1000 / 10.2 * 9.80665, rtol=1e-12)
    np.testing.assert_allclose(block[:, 2], volts["AccB_Y"][:] * 1000 / 1.04, rtol=1e-12)
    assert [ch.unit for ch in vertical.channels] == ["N", "g", "m/s^2"]


def test_a_run_without_hit_point_has_it_unknown(folder):
    """Neither the run's excitation_position_m nor the force channel's position_m: the contract gives no
    default, so the hit point is unknown (not the origin the force channel is placed at); either one
    declares it."""
    (folder / "test.toml").write_text(GOOD)
    vertical, lateral = read_recording("test.toml").runs
    np.testing.assert_allclose(vertical.hit_position_m, [0.020, 0.0, 0.035])
    assert lateral.hit_position_m is None
    text = edit(GOOD, "sensitivity_mv = 2.25", "sensitivity_mv = 2.25\nposition_m = [0.05, -0.012, 0.006]")
    (folder / "test.toml").write_text(text)
    vertical, lateral = read_recording("test.toml").runs
    np.testing.assert_allclose(lateral.hit_position_m, [0.05, -0.012, 0.006])
    np.testing.assert_allclose(vertical.hit_position_m, [0.020, 0.0, 0.035])


def test_positions_directions_channels_and_scale_as_given(folder):
    text = edit(GOOD, "sensitivity_mv = 1.04", "scale = -2.0\nposition_m = [0.01, 0.02, 0.03]\n"
                                                "direction = [0.0, -1.0, 0.0]")
    text = edit(text, 'file = "lateral.tdms"', 'file = "lateral.tdms"\nchannels = ["force", "acc_B_y"]\n'
                                                "sample_rate_hz = 51200.0")
    (folder / "test.toml").write_text(text)
    lateral = read_recording("test.toml").runs[1]
    assert lateral.channel_names == ("force", "acc_B_y")
    np.testing.assert_allclose(lateral.channels[1].position_m, [0.01, 0.02, 0.03])
    np.testing.assert_allclose(lateral.channels[1].direction, [0.0, -1.0, 0.0])
    from nptdms import TdmsFile

    b = TdmsFile.read("lateral.tdms")["Untitled"]["AccB_Y"][:]
    np.testing.assert_allclose(lateral.read_block(0, N)[:, 1], -2.0 * b, rtol=1e-12)


def test_a_run_uses_the_channels_its_file_has(folder):
    """Default `channels`: every channel whose source the file has (a sensor moved between runs);
    a source that no run's file has is a typo: one line naming it and the file."""
    tdms(folder / "lateral.tdms", extra=("AccC_Y",))
    text = edit(GOOD, "[runs.vertical]", '[channels.acc_C_y]\nsource = "AccC_Y"\nunit = "g"\nscale = 1.0\n\n'
                                         "[runs.vertical]")
    (folder / "test.toml").write_text(text)
    vertical, lateral = read_recording("test.toml").runs
    assert vertical.channel_names == ("force", "acc_A_y", "acc_B_y")
    assert lateral.channel_names == ("force", "acc_A_y", "acc_B_y", "acc_C_y")
    (folder / "test.toml").write_text(text.replace('"AccC_Y"', '"AccC_y"'))
    with pytest.raises(ValueError, match=r"^vertical\.tdms: no channel 'AccC_y'; the file has Hammer, AccA_Y, "
                                         r"AccB_Y$"):
        read_recording("test.toml")


def test_two_group_tdms_file_with_group_per_run(folder):
    tdms(folder / "both.tdms", groups=["vertical", "lateral"])
    text = edit(GOOD, 'file = "vertical.tdms"', 'file = "both.tdms"\ngroup = "vertical"')
    text = edit(text, 'file = "lateral.tdms"', 'file = "both.tdms"\ngroup = "lateral"')
    (folder / "test.toml").write_text(text)
    rec = read_recording("test.toml")
    assert [r.n_samples for r in rec.runs] == [N, N]
    # `group/channel` as source works without `group`
    text = edit(GOOD, 'source = "Hammer"', 'source = "vertical/Hammer"')
    text = edit(text, 'source = "AccA_Y"', 'source = "vertical/AccA_Y"')
    text = edit(text, 'source = "AccB_Y"', 'source = "vertical/AccB_Y"')
    text = text.replace('file = "vertical.tdms"', 'file = "both.tdms"').split("[runs.lateral]")[0]
    (folder / "test.toml").write_text(text)  # one run: two on one hammer channel are refused (below)
    assert read_recording("test.toml").runs[0].n_samples == N


def _lines(result):
    return [line for line in result.stderr.splitlines() if line.strip()]


def test_the_html_report_hashes_the_daq_files_a_setup_reads(folder):
    """The report's provenance names each DAQ file once, with its SHA-256 and size: the
    setup's own hash says nothing of the data."""
    import hashlib

    from guidefit.report.html import _daq_rows

    (folder / "test.toml").write_text(GOOD)
    rows = _daq_rows("test.toml")
    assert [r[0] for r in rows] == ["DAQ file (vertical)", "DAQ file (lateral)"]
    for (_, text), name in zip(rows, ("vertical.tdms", "lateral.tdms")):
        data = (folder / name).read_bytes()
        assert text == f"{name}: SHA-256 {hashlib.sha256(data).hexdigest()}, {len(data)} bytes"
    tdms(folder / "both.tdms", groups=["vertical", "lateral"])
    text = edit(GOOD, 'file = "vertical.tdms"', 'file = "both.tdms"\ngroup = "vertical"')
    (folder / "test.toml").write_text(edit(text, 'file = "lateral.tdms"', 'file = "both.tdms"\ngroup = "lateral"'))
    assert [r[0] for r in _daq_rows("test.toml")] == ["DAQ file (vertical)"]  # one file, hashed once
    assert _daq_rows(folder / "x.h5") == []


# (name, edit of GOOD or a callable on the folder, expected message (regex, after "guidefit: error: "))
MALFORMED = [
    ("negative sensitivity", ("sensitivity_mv = 10.2", "sensitivity_mv = -10.2"),
     r"test\.toml: channels\.acc_A_y: sensitivity_mv must be a positive number, got -10\.2$"),
    ("sensitivity as text", ("sensitivity_mv = 10.2", 'sensitivity_mv = "10.2"'),
     r"test\.toml: channels\.acc_A_y: sensitivity_mv must be a positive number, got '10\.2'$"),
    ("file not found", ('file = "lateral.tdms"', 'file = "lateral2.tdms"'),
     r"test\.toml: runs\.lateral: file 'lateral2\.tdms' not found next to the setup$"),
    ("source not in the file", ('source = "AccA_Y"', 'source = "A_Y"'),
     r"vertical\.tdms: no channel 'A_Y'; the file has Hammer, AccA_Y, AccB_Y$"),
    ("format", ('format = "guidefit-setup"', 'format = "guidefit-recording"'),
     r"test\.toml: format must be \"guidefit-setup\", got 'guidefit-recording'$"),
    ("format missing", ('format = "guidefit-setup"\n', ""), r"test\.toml: format missing"),
    ("format_version", ("format_version = 1", "format_version = 2"),
     r"test\.toml: format_version 2 is not supported; this guidefit reads version 1$"),
    ("unit volts", ('unit = "N"', 'unit = "V"'),
     r"test\.toml: channels\.force: unit must be 'N', got 'V' \(the engineering unit"),
    ("acceleration unit", ('unit = "g"', 'unit = "mm/s^2"'),
     r"test\.toml: channels\.acc_A_y: unit must be 'm/s\^2' or 'g', got 'mm/s\^2'$"),
    ("unit missing", ('unit = "g"\n', ""), r"test\.toml: channels\.acc_A_y: unit missing"),
    ("source missing", ('source = "AccA_Y"\n', ""), r"test\.toml: channels\.acc_A_y: source missing"),
    ("both scalings", ("sensitivity_mv = 10.2", "sensitivity_mv = 10.2\nscale = 2.0"),
     r"test\.toml: channels\.acc_A_y: sensitivity_mv and scale both given; expected at most one$"),
    ("zero scale", ("sensitivity_mv = 10.2", "scale = 0.0"),
     r"test\.toml: channels\.acc_A_y: scale must be a finite, non-zero number, got 0\.0$"),
    ("misspelt key", ("sensitivity_mv = 10.2", "sensitivity_mV = 10.2"),
     r"test\.toml: channels\.acc_A_y: unknown key 'sensitivity_mV' \(did you mean 'sensitivity_mv'\?\)"),
    ("position of two numbers", ("sensitivity_mv = 10.2", "sensitivity_mv = 10.2\nposition_m = [0.03, 0.0]"),
     r"test\.toml: channels\.acc_A_y: position_m must be 3 numbers \(m\), got \[0\.03, 0\.0\]$"),
    ("position in millimetres", ("sensitivity_mv = 10.2", "sensitivity_mv = 10.2\nposition_m = [30.0, 0.0, 45.0]"),
     r"test\.toml: channels\.acc_A_y: position_m must be metres within 1 m of the carriage origin, got "
     r"\[30\.0, 0\.0, 45\.0\] \(54\.1 m; millimetres given\?\)$"),
    ("direction not unit", ("sensitivity_mv = 10.2", "sensitivity_mv = 10.2\ndirection = [0.0, 2.0, 0.0]"),
     r"test\.toml: channels\.acc_A_y: direction must be a unit vector of 3 numbers, got \[0\.0, 2\.0, 0\.0\]"),
    ("channel name", ("[channels.acc_A_y]", "[channels.acc_A_q]"),
     r"test\.toml: channels\.acc_A_q: not a guidefit channel name"),
    ("no force", ('[channels.force]\nsource = "Hammer"\nunit = "N"\nsensitivity_mv = 2.25\n', ""),
     r"test\.toml: channels: no \[channels\.force\]"),
    ("run file missing", ('file = "lateral.tdms"\n', ""), r"test\.toml: runs\.lateral: file missing"),
    ("file of another type", ('file = "lateral.tdms"', 'file = "lateral.h5"'),
     r"test\.toml: runs\.lateral: file 'lateral\.h5' has suffix '\.h5', not a DAQ file type"),
    ("excitation missing", ("excitation_direction = [-1.0, 0.0, 0.0]\n", ""),
     r"test\.toml: runs\.lateral: excitation_direction missing"),
    ("excitation not unit", ("excitation_direction = [-1.0, 0.0, 0.0]", "excitation_direction = [-1.0, 1.0, 0.0]"),
     r"test\.toml: runs\.lateral: excitation_direction must be a unit vector of 3 numbers, got \[-1\.0, 1\.0, 0\.0\]"),
    ("excitation position", ("excitation_position_m = [0.020, 0.0, 0.035]", "excitation_position_m = 0.02"),
     r"test\.toml: runs\.vertical: excitation_position_m must be 3 numbers \(m\), got 0\.02$"),
    ("negative rate", ('file = "lateral.tdms"', 'file = "lateral.tdms"\nsample_rate_hz = -1.0'),
     r"test\.toml: runs\.lateral: sample_rate_hz must be a positive number \(Hz\), got -1\.0$"),
    ("rate disagrees", ('file = "lateral.tdms"', 'file = "lateral.tdms"\nsample_rate_hz = 50000.0'),
     r"test\.toml: runs\.lateral: sample_rate_hz 50000 disagrees with 51200 Hz from lateral\.tdms \(wf_increment\)"),
    ("run channels unknown", ('file = "lateral.tdms"', 'file = "lateral.tdms"\nchannels = ["force", "acc_Z_y"]'),
     r"test\.toml: runs\.lateral: channels: 'acc_Z_y' has no \[channels\.acc_Z_y\] table"),
    ("run channels without force", ('file = "lateral.tdms"', 'file = "lateral.tdms"\nchannels = ["acc_A_y"]'),
     r"test\.toml: runs\.lateral: channels must include 'force'"),
    ("unknown group", ('file = "lateral.tdms"', 'file = "lateral.tdms"\ngroup = "run7"'),
     r"test\.toml: runs\.lateral: group 'run7' is not in lateral\.tdms; the file has groups Untitled$"),
    ("delimiter on TDMS", ('file = "lateral.tdms"', 'file = "lateral.tdms"\ndelimiter = ";"'),
     r"test\.toml: runs\.lateral: delimiter applies to text exports \(\.csv, \.txt, \.tsv\)"),
    ("unknown run key", ('file = "lateral.tdms"', 'file = "lateral.tdms"\nexcitation = [1.0, 0.0, 0.0]'),
     r"test\.toml: runs\.lateral: unknown key 'excitation'"),
    ("no runs", ("[runs.vertical]", "[old.vertical]"), r"test\.toml: unknown key 'old'"),
    ("runs missing", (None, None), r"test\.toml: runs missing"),
    ("not TOML", ("[channels.force]", "[channels.force"), r"test\.toml: not valid TOML \("),
    ("volts without sensitivity", ("sensitivity_mv = 2.25\n", ""),
     r"test\.toml: channels\.force: vertical\.tdms gives 'Hammer' in 'V'; give sensitivity_mv \(mV per N\) or scale$"),
]


@pytest.mark.parametrize("change, message", [m[1:] for m in MALFORMED], ids=[m[0] for m in MALFORMED])
def test_malformed_setup_is_exit_2_and_one_line(folder, change, message):
    old, new = change
    text = GOOD.split("[runs.vertical]")[0] if old is None else edit(GOOD, old, new)
    (folder / "test.toml").write_text(text)
    result = CliRunner().invoke(main, ["identify", "test.toml"])
    lines = _lines(result)
    assert result.exit_code == 2, result.output
    assert len(lines) == 1, lines
    assert re.search(message, lines[0].removeprefix("guidefit: error: ")), lines[0]
    assert "Traceback" not in result.output


def test_setup_is_checked_whole_before_any_file_is_opened(folder):
    """A broken vertical.tdms does not hide a typo in the lateral run's table."""
    (folder / "vertical.tdms").write_bytes(b"not a tdms file at all")
    (folder / "test.toml").write_text(edit(GOOD, "excitation_direction = [-1.0, 0.0, 0.0]",
                                           "excitation_direction = [-1.0, 0.0]"))
    with pytest.raises(SetupError, match=r"runs\.lateral: excitation_direction"):
        load_setup("test.toml")
    with pytest.raises(SetupError, match=r"runs\.lateral: excitation_direction"):
        read_recording("test.toml")


def test_file_units_must_fit_the_setup(folder):
    tdms(folder / "vertical.tdms", unit="N")
    (folder / "test.toml").write_text(GOOD)
    with pytest.raises(SetupError, match=r"channels\.force: sensitivity_mv expects the file in volts, but "
                                         r"vertical\.tdms gives 'Hammer' in 'N'"):
        read_recording("test.toml")
    tdms(folder / "vertical.tdms", unit="g")
    text = GOOD.replace("sensitivity_mv = 2.25\n", "scale = 1.0\n").replace("sensitivity_mv = 10.2\n", "")
    text = text.replace("sensitivity_mv = 1.04\n", "")
    (folder / "test.toml").write_text(text)
    with pytest.raises(SetupError, match=r"channels\.acc_B_y: unit is 'm/s\^2' but vertical\.tdms gives "
                                         r"'AccB_Y' in 'g'"):
        read_recording("test.toml")


def european(path, rows=N, unit_row=True, preamble=True):
    t = np.arange(rows) / RATE
    x = np.column_stack([t, np.sin(3e3 * t), np.cos(3e3 * t), 0.5 * np.sin(5e3 * t)])
    head = ["Project;MR35", "Operator;T. Test", ""] if preamble else []
    head.append("Time [s];Hammer [V];AccA_Y [V];AccB_Y [V]" if not unit_row else "Time;Hammer;AccA_Y;AccB_Y")
    if unit_row:
        head.append("s;V;V;V")
    body = [";".join(f"{v:.9g}" for v in row).replace(".", ",") for row in x]
    path.write_text("\n".join(head + body) + "\n", encoding="utf-8")
    return x


@pytest.mark.parametrize("unit_row", [True, False])
def test_european_text_export_detected(folder, unit_row):
    x = european(folder / "vertical.csv", unit_row=unit_row)
    text = GOOD.replace("vertical.tdms", "vertical.csv").split("[runs.lateral]")[0]
    (folder / "test.toml").write_text(text)
    run = read_recording("test.toml").runs[0]
    assert run.sample_rate_hz == RATE and run.n_samples == N
    np.testing.assert_allclose(run.read_block(0, N)[:, 0], x[:, 1] * 1000 / 2.25, rtol=1e-8)
    np.testing.assert_allclose(run.read_block(0, N)[:, 2], x[:, 3] * 1000 / 1.04, rtol=1e-8)


def test_text_export_that_cannot_be_told_names_the_keys(folder):
    """Header with ';' over data with ',': which is it? The error names delimiter / decimal."""
    t = np.arange(100) / RATE
    rows = [f"{a:.6f},{b:.6f},{c:.6f},{d:.6f}" for a, b, c, d in zip(t, t, t, t)]
    (folder / "vertical.csv").write_text("Time;Hammer;AccA_Y;AccB_Y\n" + "\n".join(rows) + "\n")
    text = GOOD.replace("vertical.tdms", "vertical.csv").split("[runs.lateral]")[0]
    (folder / "test.toml").write_text(text)
    result = CliRunner().invoke(main, ["identify", "test.toml"])
    lines = _lines(result)
    assert result.exit_code == 2 and len(lines) == 1, lines
    assert "vertical.csv: no channel 'Hammer'" in lines[0]
    assert "delimiter" in lines[0] and "decimal" in lines[0] and "runs.vertical" in lines[0]
    # the key settles it: with delimiter = ";" no rows of numbers are found, said in one line
    (folder / "test.toml").write_text(edit(text, 'file = "vertical.csv"', 'file = "vertical.csv"\ndelimiter = ";"'))
    result = CliRunner().invoke(main, ["identify", "test.toml"])
    assert result.exit_code == 2 and len(_lines(result)) == 1
    assert "no rows of two or more numbers found with delimiter ';'" in _lines(result)[0]


def test_text_without_time_needs_sample_rate(folder):
    x = european(folder / "vertical.txt")
    lines = (folder / "vertical.txt").read_text().splitlines()
    lines = [";".join(line.split(";")[1:]) for line in lines[3:]]  # drop preamble and the time column
    (folder / "vertical.txt").write_text("\n".join(lines) + "\n")
    text = GOOD.replace("vertical.tdms", "vertical.txt").split("[runs.lateral]")[0]
    (folder / "test.toml").write_text(text)
    with pytest.raises(SetupError, match=r"test\.toml: runs\.vertical: sample_rate_hz missing; vertical\.txt has "
                                         r"neither a sample rate nor a time axis"):
        read_recording("test.toml")
    (folder / "test.toml").write_text(edit(text, 'file = "vertical.txt"', 'file = "vertical.txt"\n'
                                                                           "sample_rate_hz = 51200"))
    run = read_recording("test.toml").runs[0]
    assert run.sample_rate_hz == RATE
    np.testing.assert_allclose(run.read_block(5, 6)[0, 1], x[5, 2] * 1000 / 10.2 * 9.80665, rtol=1e-8)


def test_text_time_column_with_a_gap_is_exit_2_and_one_line(folder):
    """Times written ``%g`` (the last row ``0.1``) with a 20 ms gap: refused in one line that says
    where, exit 2 (before: the last row's step, 0.1 s, let it through with a rate 11 % off, exit 0)."""
    k = np.arange(int(0.1 * RATE) + 1 - 1024)
    k[2000:] += 1024
    t = k / RATE
    rows = [f"{a:g};{np.sin(3e3 * a):.6f};{np.cos(3e3 * a):.6f};{0.5 * np.sin(5e3 * a):.6f}" for a in t]
    assert rows[-1].startswith("0.1;")
    (folder / "vertical.csv").write_text("Time;Hammer;AccA_Y;AccB_Y\n" + "\n".join(rows) + "\n")
    (folder / "test.toml").write_text(GOOD.replace("vertical.tdms", "vertical.csv").split("[runs.lateral]")[0])
    result = CliRunner().invoke(main, ["identify", "test.toml"])
    lines = _lines(result)
    assert result.exit_code == 2 and len(lines) == 1, lines
    assert ("vertical.csv: time column 'Time': times jump by 0.0200195 s, from 0.039043 s to 0.0590625 s "
            "between samples 2000 and 2001") in lines[0]


def test_mat_wide_array_is_explained(folder):
    import scipy.io

    scipy.io.savemat(folder / "vertical.mat", {"data": np.zeros((3, 500)), "fs": RATE})
    text = GOOD.replace("vertical.tdms", "vertical.mat").split("[runs.lateral]")[0]
    text = text.replace('"Hammer"', '"data:0"').replace('"AccA_Y"', '"data:1"').replace('"AccB_Y"', '"data:2"')
    (folder / "test.toml").write_text(text)
    with pytest.raises(ValueError, match=r"vertical\.mat: variable 'data' is 3 x 500; 'data:k' is column k .* "
                                         r"transpose it"):
        read_recording("test.toml")


@pytest.mark.parametrize("n_time", [1000, 4096])
def test_mat_time_vector_of_another_length_is_exit_2_and_one_line(folder, n_time):
    """``savemat(f, {"data": n x 3, "t": 1000 times})``: the rate of a time vector that is not the
    channels' is not theirs (before: used, K_V -9.8 % / +21 % with exit 0)."""
    import scipy.io

    t = np.arange(N) / RATE
    data = np.column_stack([np.exp(-((t - 0.005) / 1e-4) ** 2), np.sin(2e3 * t), np.cos(2e3 * t)])
    scipy.io.savemat(folder / "vertical.mat", {"data": data, "t": np.arange(n_time) / 19000.0,
                                               "unused": np.zeros((2, 3, 4))})
    text = GOOD.replace("vertical.tdms", "vertical.mat").split("[runs.lateral]")[0]
    text = text.replace('"Hammer"', '"data:0"').replace('"AccA_Y"', '"data:1"').replace('"AccB_Y"', '"data:2"')
    (folder / "test.toml").write_text(text)
    result = CliRunner().invoke(main, ["identify", "test.toml"])
    lines = _lines(result)
    assert result.exit_code == 2 and len(lines) == 1, lines
    assert f"vertical.mat: time variable 't' holds {n_time} times but channel 'data:0' {N} samples" in lines[0]
    scipy.io.savemat(folder / "vertical.mat", {"data": data, "t": t, "unused": np.zeros((2, 3, 4))})
    run = read_recording("test.toml").runs[0]  # the 3-D variable no channel names is not read
    assert run.sample_rate_hz == pytest.approx(RATE, rel=1e-12) and run.n_samples == N


def test_mat_complex_channels_are_exit_2_and_one_line(folder):
    """A v5 variable of complex numbers (whosmat calls it 'double'): refused where it is read,
    not cast to its real part with a numpy warning."""
    import scipy.io

    t = np.arange(N) / RATE
    data = np.column_stack([np.exp(-((t - 0.005) / 1e-4) ** 2), np.sin(2e3 * t), np.cos(2e3 * t)])
    scipy.io.savemat(folder / "vertical.mat", {"data": data * (1 + 0.5j), "fs": RATE})
    text = GOOD.replace("vertical.tdms", "vertical.mat").split("[runs.lateral]")[0]
    text = text.replace('"Hammer"', '"data:0"').replace('"AccA_Y"', '"data:1"').replace('"AccB_Y"', '"data:2"')
    (folder / "test.toml").write_text(text)
    result = CliRunner().invoke(main, ["identify", "test.toml"])
    lines = _lines(result)
    assert result.exit_code == 2 and len(lines) == 1, lines
    assert "vertical.mat: variable 'data' holds complex128 numbers; expected real samples" in lines[0]


@pytest.fixture(scope="module")
def simulated_setup(tmp_path_factory):
    """A simulated vertical run in volts as a European text export with its setup, and the contract file."""
    from dataclasses import replace

    from guidefit.io import write_recording
    from guidefit.simulate import DEFAULT_RUNS, SimulationConfig, simulate

    config = replace(SimulationConfig(), runs=(DEFAULT_RUNS[0],), hits=3, record_s=0.03, layout="signals",
                     gap_s=0.005, sensors="AB", axes="y")
    data, _ = simulate("MRB35", config=config, seed=5)
    folder = tmp_path_factory.mktemp("setup_cli")
    write_recording(folder / "contract.h5", data)
    run = data.runs[0]
    sens = {"force": 2.25, "acc_A_y": 10.2, "acc_B_y": 10.0}
    cols = [np.asarray(run.data[:, run.channel_names.index(n)], float) * mv / 1000 for n, mv in sens.items()]
    cols = [c / 9.80665 if n != "force" else c for c, n in zip(cols, sens)]  # accelerometers in mV/g
    t = np.arange(run.data.shape[0]) / run.sample_rate_hz
    body = [";".join(f"{v:.10g}" for v in row).replace(".", ",") for row in np.column_stack([t] + cols)]
    (folder / "vertical.csv").write_text("Zeit [s];Kraft [V];A_Y [V];B_Y [V]\n" + "\n".join(body) + "\n")
    lines = ['format = "guidefit-setup"', "format_version = 1", 'guide = "MRB35"']
    for (name, mv), source in zip(sens.items(), ("Kraft", "A_Y", "B_Y")):
        unit = "N" if name == "force" else "g"
        lines += [f"[channels.{name}]", f'source = "{source}"', f'unit = "{unit}"', f"sensitivity_mv = {mv}"]
    lines += ["[runs.vertical]", 'file = "vertical.csv"',
              f"excitation_direction = {json.dumps(run.excitation_direction.tolist())}",
              f"excitation_position_m = {json.dumps(run.excitation_position_m.tolist())}"]
    (folder / "test.toml").write_text("\n".join(lines) + "\n")
    return folder


def test_cli_identify_frf_and_convert_take_a_setup(simulated_setup, monkeypatch):
    folder = simulated_setup
    monkeypatch.chdir(folder)
    runner = CliRunner()
    a = runner.invoke(main, ["identify", "test.toml", "--json", "--no-jackknife"])
    b = runner.invoke(main, ["identify", "contract.h5", "--json", "--no-jackknife"])
    assert a.exit_code == 0 and b.exit_code == 0, (a.output, b.output)
    pa, pb = json.loads(a.stdout)["parameters"], json.loads(b.stdout)["parameters"]
    assert json.loads(a.stdout)["file"] == "test.toml"
    assert abs(pa["K_V"]["value"] - pb["K_V"]["value"]) < 0.1 * pb["K_V"]["std"]
    assert abs(pa["c_V"]["value"] - pb["c_V"]["value"]) < 0.1 * pb["c_V"]["std"]
    frf = runner.invoke(main, ["frf", "test.toml"])
    assert frf.exit_code == 0, frf.output
    # the simulated carriage is the nominal model: explain finds nothing to explain
    explained = runner.invoke(main, ["explain", "test.toml", "--json", "--no-jackknife"])
    assert explained.exit_code == 0, explained.output
    assert json.loads(explained.stdout)["verdict"] == "adequate"
    out = runner.invoke(main, ["convert", "test.toml", "-o", "converted.h5"])
    assert out.exit_code == 0, out.output
    assert "wrote converted.h5: vertical" in out.stdout
    conv = read_recording("converted.h5").runs[0]
    assert [ch.unit for ch in conv.channels] == ["N", "g", "g"]
    np.testing.assert_allclose(conv.read_block(0, 100), read_recording("test.toml").runs[0].read_block(0, 100),
                               rtol=1e-12)


@pytest.mark.parametrize("target", ["test.toml", "vertical.csv"])
def test_convert_refuses_to_write_onto_an_input(simulated_setup, monkeypatch, target):
    monkeypatch.chdir(simulated_setup)
    before = (simulated_setup / target).read_bytes()
    result = CliRunner().invoke(main, ["convert", "test.toml", "-o", target])
    assert result.exit_code == 2
    lines = _lines(result)
    via = "" if target == "test.toml" else ", read through test.toml"
    assert len(lines) == 1 and f"{target}: is an input of this command ({target}{via})" in lines[0], lines
    assert (simulated_setup / target).read_bytes() == before


def test_convert_refuses_an_input_under_another_name(simulated_setup, monkeypatch):
    """A .h5 symlink to a run's DAQ file is still that file."""
    monkeypatch.chdir(simulated_setup)
    (simulated_setup / "alias.csv").unlink(missing_ok=True)
    (simulated_setup / "alias.csv").symlink_to(simulated_setup / "vertical.csv")
    before = (simulated_setup / "vertical.csv").read_bytes()
    result = CliRunner().invoke(main, ["convert", "test.toml", "-o", "alias.csv"])
    assert result.exit_code == 2 and "is an input of this command (vertical.csv, read through test.toml)" in result.stderr
    assert (simulated_setup / "vertical.csv").read_bytes() == before


@pytest.mark.parametrize("damage", ["truncated", "junk"])
def test_damaged_daq_file_is_one_line_without_library_logs(folder, damage):
    """npTDMS logs warnings about a short last segment; the command line shows one line only."""
    from nptdms import ChannelObject, TdmsWriter

    t = np.arange(20000) / RATE
    with TdmsWriter(folder / "long.tdms") as writer:
        for k in range(4):
            part = slice(5000 * k, 5000 * (k + 1))
            writer.write_segment([ChannelObject("g", name, x[part], properties={"wf_increment": 1 / RATE})
                                  for name, x in (("Hammer", np.sin(t)), ("AccA_Y", np.cos(t)),
                                                  ("AccB_Y", np.sin(2 * t)))])
    raw = (folder / "long.tdms").read_bytes()
    (folder / "vertical.tdms").write_bytes(raw[: len(raw) // 2 + 7] if damage == "truncated" else b"junk" * 50)
    text = GOOD.replace("sensitivity_mv", "scale").split("[runs.lateral]")[0]
    (folder / "test.toml").write_text(text)
    # a real process: the libraries' log handlers write to the process's stderr
    result = subprocess.run([sys.executable, "-m", "guidefit", "identify", "test.toml"], capture_output=True,
                            text=True, cwd=folder, timeout=120, check=False)
    assert result.returncode == 2
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, lines
    assert lines[0].startswith("guidefit: error: vertical.tdms: ")


def test_unknown_point_and_unknown_guide_name_the_key(folder):
    text = GOOD.replace("[channels.acc_B_y]", "[channels.acc_E_y]")
    (folder / "test.toml").write_text(text)
    with pytest.raises(SetupError, match=r"^test\.toml: channels\.acc_E_y: .*point 'E' has no default position .*"
                                         r"give position_m$"):
        read_recording("test.toml")
    rec_e = text.replace('source = "AccB_Y"', 'source = "AccB_Y"\nposition_m = [0.0, 0.01, 0.0]')
    (folder / "test.toml").write_text(rec_e)  # a position given: only the axis comes from the name
    np.testing.assert_allclose(read_recording("test.toml").runs[0].channels[2].direction, [0.0, 1.0, 0.0])
    (folder / "test.toml").write_text(GOOD.replace('guide = "MRB35"', 'guide = "NOSUCH99"'))
    with pytest.raises(SetupError, match=r"^test\.toml: guide: "):
        read_recording("test.toml")


def test_tdms_channels_that_start_apart_are_refused(folder):
    """Two channels of one group with different wf_start_offset are not one time base."""
    from nptdms import ChannelObject, TdmsWriter

    t = np.arange(N) / RATE
    with TdmsWriter(folder / "vertical.tdms") as writer:
        writer.write_segment([
            ChannelObject("g", name, np.sin(t), properties={"wf_increment": 1 / RATE, "wf_start_offset": start,
                                                            "unit_string": "V"})
            for name, start in (("Hammer", 0.0), ("AccA_Y", 0.0), ("AccB_Y", 0.002))
        ])
    (folder / "test.toml").write_text(GOOD.split("[runs.lateral]")[0])
    with pytest.raises(SetupError, match=r"^vertical\.tdms: channels 'Hammer' and 'AccB_Y' start 2 ms apart"):
        read_recording("test.toml")


def test_docs_setup_examples_are_valid(tmp_path):
    """Every TOML block of docs/recordings.md parses; the full example passes the setup check."""
    import tomllib
    from pathlib import Path

    doc = (Path(__file__).resolve().parents[1] / "docs" / "recordings.md").read_text()
    blocks = re.findall(r"```toml\n(.*?)```", doc, re.S)
    assert len(blocks) >= 7  # the full example, TDMS, MDF, MAT, WAV, text, UFF
    for block in blocks:
        tomllib.loads(block)
    full = next(b for b in blocks if b.startswith('format = "guidefit-setup"'))
    for name in ("vertical.tdms", "lateral.tdms"):
        (tmp_path / name).write_bytes(b"placeholder")
    (tmp_path / "test.toml").write_text(full)
    setup = load_setup(tmp_path / "test.toml")
    assert list(setup.channels) == ["force", "acc_A_y", "acc_B_y"] and [r.name for r in setup.runs] == [
        "vertical", "lateral"]


def _quick_start_setup() -> str:
    """The TOML of docs/recordings.md's quick start (the block that starts with '# setup.toml')."""
    from pathlib import Path

    doc = (Path(__file__).resolve().parents[1] / "docs" / "recordings.md").read_text()
    return next(b for b in re.findall(r"```toml\n(.*?)```", doc, re.S) if b.startswith("# setup.toml"))


@pytest.fixture(scope="module")
def quick_start(tmp_path_factory):
    """The quick start's DAQ files: a simulated paper's test (A-D, y in the vertical run, x in the
    lateral one) in volts as two TDMS files with the DAQ names Hammer, Acc1-Acc4; the contract file."""
    from dataclasses import replace

    from nptdms import ChannelObject, TdmsWriter

    from guidefit.io import write_recording
    from guidefit.simulate import SimulationConfig, simulate

    config = replace(SimulationConfig(), hits=3, record_s=0.03, layout="signals", gap_s=0.005,
                     sensor_layout="default")
    data, _ = simulate("MRB35", config=config, seed=7)
    folder = tmp_path_factory.mktemp("quick_start")
    write_recording(folder / "contract.h5", data)
    for run in data.runs:
        names = {"force": "Hammer", **{n: f"Acc{'ABCD'.index(n.split('_')[1]) + 1}" for n in run.channel_names[1:]}}
        volts = {names[n]: np.asarray(run.data[:, k], float) * (2.25 if n == "force" else 10.2 / 9.80665) / 1000
                 for k, n in enumerate(run.channel_names)}
        with TdmsWriter(folder / f"{run.name}.tdms") as writer:
            writer.write_segment([ChannelObject("Untitled", name, x, properties={
                "wf_increment": 1 / run.sample_rate_hz, "unit_string": "V"}) for name, x in volts.items()])
    (folder / "setup.toml").write_text(_quick_start_setup())
    return folder


def test_docs_quick_start_setup_identifies_the_paper_test(quick_start, monkeypatch):
    """Issue 21, item 15: the quick start's setup, as printed, reads two DAQ files of the paper's test
    (the same four sensors turned between runs) and gives the contract file's K and c."""
    monkeypatch.chdir(quick_start)
    setup = load_setup("setup.toml")
    assert [r.name for r in setup.runs] == ["vertical", "lateral"]
    rec = read_recording("setup.toml")
    assert [[ch.name for ch in r.channels] for r in rec.runs] == [
        ["force", "acc_A_y", "acc_B_y", "acc_C_y", "acc_D_y"], ["force", "acc_A_x", "acc_B_x", "acc_C_x", "acc_D_x"]]
    runner = CliRunner()
    a = runner.invoke(main, ["identify", "setup.toml", "--json", "--no-jackknife"])
    b = runner.invoke(main, ["identify", "contract.h5", "--json", "--no-jackknife"])
    assert a.exit_code == 0 and b.exit_code == 0, (a.output, b.output)
    pa, pb = json.loads(a.stdout)["parameters"], json.loads(b.stdout)["parameters"]
    for key in ("K_V", "K_H", "c_V", "c_H"):
        assert abs(pa[key]["value"] - pb[key]["value"]) < 0.1 * pb[key]["std"], key


def test_quick_start_sensitivity_per_m_s2_with_unit_g_is_named(quick_start, monkeypatch):
    """Issue 21, item 13: 1.04 mV/(m/s^2) entered where unit = "g" wants mV/g: every acceleration
    9.81x high; the warning says which factor and which key, K and c stay (they use f, zeta, M)."""
    monkeypatch.chdir(quick_start)
    (quick_start / "wrong.toml").write_text(_quick_start_setup().replace("sensitivity_mv = 10.2", "sensitivity_mv = 1.04"))
    result = CliRunner().invoke(main, ["identify", "wrong.toml", "--json", "--no-jackknife"])
    assert result.exit_code == 0, result.output
    warnings = json.loads(result.stdout)["warnings"]
    assert any('factor 9.81: accelerations read 9.81x high' in w and 'mV/(m/s^2) entered with unit = "g"' in w
               for w in warnings), warnings


@pytest.mark.parametrize("command", ["identify", "explain", "report", "frf", "convert"])
def test_help_names_test_setups(command):
    """Issue 21, item 15: a user with DAQ files learns from --help that a .toml test setup reads them."""
    out = CliRunner().invoke(main, [command, "--help"]).output
    assert "test setup (.toml)" in " ".join(out.split()) or "test setups (.toml)" in " ".join(out.split()), out
    assert "quick start" in out


@pytest.mark.parametrize("group", [None, '"Untitled"'])
def test_two_runs_on_the_same_file_are_refused(folder, group):
    """Was: a setup whose lateral run names the vertical run's file read the same hits twice under two
    excitation directions (exit 1 with unpaired modes on a 'both' layout, or numbers from one run
    counted twice); a run is one file or one group: one line naming both runs, exit 2."""
    from guidefit.io.setup import SetupError

    text = edit(GOOD, 'file = "lateral.tdms"', 'file = "vertical.tdms"')
    if group:
        text = text.replace("excitation_direction = [-1.0", f"group = {group}\nexcitation_direction = [-1.0")
        text = text.replace('file = "vertical.tdms"\n', f'file = "vertical.tdms"\ngroup = {group}\n', 1)
    (folder / "test.toml").write_text(text)
    with pytest.raises(SetupError, match=r"^test.toml: runs.lateral: reads the hammer 'Hammer' of vertical.tdms as "
                                         r"runs.vertical does; each run is its own hammer run"):
        read_recording("test.toml")
    result = CliRunner().invoke(main, ["identify", "test.toml"])
    assert result.exit_code == 2 and len(result.output.strip().splitlines()) == 1, result.output


@pytest.mark.parametrize("source, meant", [("hammer", "Hammer"), ("Hammer ", "Hammer"), ("accA_y", "AccA_Y")])
def test_a_source_that_differs_in_case_or_spaces_names_the_channel_meant(folder, source, meant):
    """Was: 'vertical.tdms: no channel 'AY'; the file has Hammer, AY , BY' (a trailing space in the DAQ's name
    invisible in the list). Names still match exactly (exit 2); the line now names the channel meant."""
    old = 'source = "AccA_Y"' if meant == "AccA_Y" else 'source = "Hammer"'
    (folder / "test.toml").write_text(edit(GOOD, old, f"source = {json.dumps(source)}"))
    result = CliRunner().invoke(main, ["identify", "test.toml"])
    assert result.exit_code == 2
    assert result.output.strip().endswith(f"did you mean '{meant}' (names are matched exactly: case and spaces count)?")
