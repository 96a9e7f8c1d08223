"""What a failed or rejected identification says (issue 21, items 13 and 14): one short line on
stderr with every warning behind it in ``--verbose`` and ``--json``; a scale error of a known
factor (9.81: g and m/s^2, 1000: a prefix) named as such; explain and report exit as identify does
on a file the plausibility gate rejected; frf speaks of windows only when given some."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from click.testing import CliRunner

from guidefit.cli import main
from guidefit.io import write_recording
from guidefit.simulate import SimulationConfig, simulate

SMALL = {"hits": 2, "record_s": 0.02}


def _recording(path, points="", factor=1.0, **config):
    """A small simulated recording (x and y at A-D in both runs) whose accelerations at ``points``
    (``all``: every one) read ``factor`` times the truth."""
    data, _ = simulate("MRB35", config=replace(SimulationConfig(), **{**SMALL, **config}), seed=3)
    runs = []
    for run in data.runs:
        d = np.array(run.data, dtype=float)
        for j, name in enumerate(run.channel_names):
            if name != "force" and (points == "all" or name.split("_")[1] in points):
                d[..., j] *= factor
        runs.append(replace(run, data=d))
    write_recording(path, replace(data, runs=tuple(runs)))
    return path


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("rejections")
    return {
        # every hit clipped: no run gives an FRF (the error joined all 2.6 kB of hit warnings)
        "clipped": _recording(folder / "clipped.h5", hits=3,
                              faults=tuple(f"overload:hit={k}" for k in range(3))),
        # A and B in m/s^2 read as g, C and D right: not a rigid carriage, the gate rejects
        "gated": _recording(folder / "gated.h5", "AB", 9.80665),
        # every accelerometer's sensitivity per m/s^2 entered with unit = "g": 9.81x high
        "g_for_ms2": _recording(folder / "g_for_ms2.h5", "all", 9.80665),
        "good": _recording(folder / "good.h5"),
    }


def _stderr_lines(result) -> list[str]:
    return [line for line in result.stderr.splitlines() if line]


def test_identify_error_is_one_short_line_with_details_on_request(files):
    runner = CliRunner()
    plain = runner.invoke(main, ["identify", str(files["clipped"]), "--no-jackknife"])
    assert plain.exit_code == 1, plain.output
    lines = _stderr_lines(plain)
    assert len(lines) == 1 and lines[0].startswith("guidefit: error: "), lines
    assert len(lines[0]) < 300, len(lines[0])
    assert "no run gave an FRF" in lines[0] and "clipped x3" in lines[0] and "--verbose" in lines[0]
    verbose = runner.invoke(main, ["identify", str(files["clipped"]), "--no-jackknife", "--verbose"])
    detail = _stderr_lines(verbose)[1:]
    assert verbose.exit_code == 1 and len(detail) == 8, detail  # 3 hits and the run's line, per run
    assert sum("hit 0: rejected: clipped: force" in line for line in detail) == 2
    as_json = runner.invoke(main, ["identify", str(files["clipped"]), "--no-jackknife", "--json"])
    data = json.loads(as_json.stdout)
    assert len(_stderr_lines(as_json)) == 1 and data["error"] == lines[0].removeprefix("guidefit: error: ")
    assert [line.removeprefix("guidefit:   ") for line in detail] == data["warnings"]


def test_identify_error_details_survive_the_worker_processes(files):
    result = CliRunner().invoke(main, ["identify", str(files["clipped"]), str(files["good"]), "--no-jackknife",
                                       "--jobs", "2", "--json"])
    first = json.loads(result.stdout.splitlines()[0])
    assert result.exit_code == 1 and len(first["warnings"]) == 8, first["warnings"]


def test_accelerations_in_ms2_declared_as_g_are_named(files):
    """Factor 9.81 gets as precise a hint as 1000, naming the setup's unit key; K and c are those
    of the frequencies and damping (unaffected by the scale): exit 0."""
    result = CliRunner().invoke(main, ["identify", str(files["g_for_ms2"]), "--no-jackknife", "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    scale = [w for w in data["warnings"] if w.startswith("the modal constants are 9.81 times")]
    assert scale and "factor 9.81: accelerations read 9.81x high" in scale[0], data["warnings"]
    assert 'mV/(m/s^2) entered with unit = "g"' in scale[0]
    good = json.loads(CliRunner().invoke(main, ["identify", str(files["good"]), "--no-jackknife", "--json"]).stdout)
    k, k0 = data["parameters"]["K_V"], good["parameters"]["K_V"]
    assert abs(k["value"] - k0["value"]) < 3 * k0["std"]


def test_explain_exits_as_identify_on_a_rejected_file(files, tmp_path):
    runner = CliRunner()
    ident = runner.invoke(main, ["identify", str(files["gated"]), "--no-jackknife", "--json"])
    assert ident.exit_code == 1
    rejected = [line for line in _stderr_lines(ident) if line.startswith("guidefit: identification rejected:")]
    assert len(rejected) == 1
    explained = runner.invoke(main, ["explain", str(files["gated"]), "--no-jackknife"])
    assert explained.exit_code == 1, explained.output
    assert _stderr_lines(explained) == rejected
    results = tmp_path / "gated.jsonl"
    results.write_text(ident.stdout)
    from_modes = runner.invoke(main, ["explain", "--modes", str(results)])
    assert from_modes.exit_code == 1
    assert _stderr_lines(from_modes) == [rejected[0].replace("guidefit: ", "guidefit: error: ", 1)]


def test_report_says_the_rejection_at_its_top(files, tmp_path):
    out = tmp_path / "report.html"
    result = CliRunner().invoke(main, ["report", str(files["gated"]), "-o", str(out), "--no-jackknife"])
    assert result.exit_code == 1
    html = out.read_text()
    assert html.index("Identification rejected") < html.index("<h2>Provenance</h2>")
    assert "explain gave no result: identification rejected" in html


@pytest.fixture(scope="module")
def frf_file(files, tmp_path_factory):
    path = tmp_path_factory.mktemp("frf") / "frf.h5"
    assert CliRunner().invoke(main, ["frf", str(files["good"]), "--out", str(path)]).exit_code == 0
    return path


@pytest.mark.parametrize("window, said", [(None, False), ("auto", True), ("none", True)])
def test_frf_of_frfs_speaks_of_windows_only_when_given(frf_file, window, said):
    args = ["frf", str(frf_file)] + ([] if window is None else ["--window", window])
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    assert ("window settings do not apply" in result.stderr) == said, result.stderr


def test_frf_of_a_recording_with_a_run_of_no_accepted_hit_is_incomplete(tmp_path):
    """Was: frf of a recording whose vertical run had every hit clipped showed (or wrote) the lateral
    run's FRFs only, with exit 0 beside a warning: a run's FRFs missing with exit 0. Now the others are
    still shown or written, the run's own reason is one line and the exit status is 1."""
    data, _ = simulate("MRB35", config=replace(SimulationConfig(), **SMALL), seed=3)
    runs = []
    for run in data.runs:
        d = np.array(run.data, dtype=float)
        if run.name == "vertical":
            top = 0.5 * np.max(np.abs(d[..., 0]), axis=-1, keepdims=True)
            d[..., 0] = np.clip(d[..., 0], -top, top)
        runs.append(replace(run, data=d))
    path = tmp_path / "clipped_v.h5"
    write_recording(path, replace(data, runs=tuple(runs)))
    out = tmp_path / "frf.h5"
    for args in ([], ["--out", str(out)]):
        result = CliRunner().invoke(main, ["frf", str(path), *args])
        assert result.exit_code == 1, result.output
        (line,) = [x for x in _stderr_lines(result) if "frf incomplete" in x]
        assert "run 'vertical': no accepted hit to average" in line
    from guidefit.io.frf_files import read_input

    assert [r.name for r in read_input(out).recording.runs] == ["lateral"]


@pytest.mark.parametrize("factor", [0.5, 2.0])
def test_a_sample_rate_wrong_by_a_factor_is_named(tmp_path, factor):
    """Was: a recording whose sample rate is stated 2x too low (a MAT fs of 100 kHz for 200 kHz) gave f_V,
    f_H half the truth, K_V, K_H a quarter, c half, exit 0 and no warning: shapes, labels and modal
    masses come out as on the right rate. Every mode at one factor from the model's frequency is now
    named with the rate that would put them there; the right rate gives no such warning."""
    from guidefit.identify import identify

    data, truth = simulate("MRB35", config=replace(SimulationConfig(), **SMALL), seed=3)
    good = tmp_path / "good.h5"
    write_recording(good, data)
    wrong = tmp_path / "wrong.h5"
    write_recording(wrong, replace(data, runs=tuple(replace(r, sample_rate_hz=r.sample_rate_hz * factor)
                                                   for r in data.runs)))
    assert not any("times the model's frequency" in w for w in identify(good).warnings)
    result = identify(wrong)
    assert result.parameters["K_V"]["value"] == pytest.approx(truth["parameters"]["K_V"]["value"] * factor**2,
                                                              rel=1e-2)
    (line,) = [w for w in result.warnings if "times the model's frequency" in w]
    assert f"every mode found is {factor:.3g} times the model's frequency" in line
    assert f"the recording says {200000 * factor:.9g} Hz" in line and "check the DAQ's sample rate" in line
