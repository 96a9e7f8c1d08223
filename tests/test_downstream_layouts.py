"""Downstream commands on one-axis-per-run layouts: explain, report, export, force levels, DAQ setups.

Most labs record one axis per run (y at A-D in the vertical run, x at A-D in
the lateral run; ``simulate --sensors default``). Every command downstream of
identify must work on such files, and a mode the labeller leaves
``ambiguous`` (or ``extra``) must never reach a schema that accepts only the
model's labels (it did: ``force_levels entry 1: 'label' must be one of
vertical, pitch, ..., got 'ambiguous'``).

Truth: seeded simulations of the nominal MRB35 carriage (explain: ``adequate``)
and of 0.1 kg on point A (explain: ``added_mass``, 0.1 kg). Small on purpose
(3-6 hits of 0.03 s, explain restricted to two or three candidates) so each
test takes well under 2 s.
"""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from click.testing import CliRunner

from guidefit.cli import main
from guidefit.io import write_recording
from guidefit.model.vibration import MODE_LABELS
from guidefit.simulate import SimulationConfig, simulate

CANDIDATES = "added_mass,contact_stiffness"


def _sim(path, sensors, effects=(), seed=1, **config):
    from guidefit.model.effects import make_effect

    cfg = replace(SimulationConfig(), **{"hits": 3, "record_s": 0.03, "sensor_layout": sensors, **config})
    data, _ = simulate("MRB35", [make_effect(n, p) for n, p in effects], config=cfg, seed=seed)
    write_recording(path, data)
    return data


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("layouts")
    out = {}
    for layout in ("default", "single"):
        out[layout] = folder / f"{layout}.h5"
        _sim(out[layout], layout)
    out["pair_mass"] = folder / "pair_mass.h5"
    _sim(out["pair_mass"], "pair", [("added_mass", {"mass_kg": 0.1, "at": "A"})], record_s=0.05)
    return out


def _cli(*args, code=0):
    result = CliRunner().invoke(main, [str(a) for a in args])
    assert result.exit_code == code, result.output
    return result


@pytest.mark.parametrize("layout", ["default", "single"])
def test_explain_json_on_a_one_axis_recording_is_adequate(files, layout):
    out = json.loads(_cli("explain", files[layout], "--json", "--no-jackknife", "--candidates", CANDIDATES).stdout)
    assert out["verdict"] == "adequate" and out["effects"] == []
    labels = {m["label"] for m in out["modes"]}
    assert {"vertical", "roll_low"} <= labels  # needs the labeller to name them on this layout
    assert not [n for n in out["notes"] if "must be one of" in n]


def test_explain_names_added_mass_on_a_pair_layout(files):
    out = json.loads(_cli("explain", files["pair_mass"], "--json", "--no-jackknife", "--candidates",
                          CANDIDATES).stdout)
    assert out["verdict"] == "explained"
    (effect,) = out["effects"]
    assert effect["name"] == "added_mass"
    assert effect["parameters"]["mass_kg"]["value"] == pytest.approx(0.1, rel=0.05)


def test_report_html_written_for_a_one_axis_recording(files, tmp_path):
    html = tmp_path / "r.html"
    _cli("report", files["single"], "-o", html, "--no-jackknife", "--candidates", "contact_stiffness")
    text = html.read_text(encoding="utf-8")
    assert "<h2>Modes</h2>" in text and "named by" in text and "adequate" in text
    assert "acc_A_y" in text and "acc_A_x" in text  # one sensor per run, both runs' shapes in the table


def test_export_on_a_one_axis_recording(files, tmp_path):
    results, explained, deck = tmp_path / "r.jsonl", tmp_path / "e.json", tmp_path / "joint.bdf"
    results.write_text(_cli("identify", files["default"], "--json", "--no-jackknife").stdout)
    explained.write_text(_cli("explain", files["default"], "--json", "--no-jackknife", "--candidates",
                              CANDIDATES).stdout)
    _cli("export", results, "--format", "nastran", "--explain", explained, "-o", deck)
    assert "DMIG" in deck.read_text()
    (joint,) = json.loads(_cli("export", results, "--joint", "apparent").stdout)["joints"]
    params = json.loads(results.read_text())["parameters"]
    assert joint["stiffness_si_model_axes"][1][1] == pytest.approx(params["K_V"]["value"], rel=1e-12)
    assert joint["stiffness_si_model_axes"][0][0] == pytest.approx(params["K_H"]["value"], rel=1e-12)


def _with_ambiguous_level(ident_dict: dict) -> dict:
    out = json.loads(json.dumps(ident_dict))
    named = out["force_levels"][0]
    out["force_levels"].append({**named, "label": "ambiguous"})
    out["force_levels"].append({**named, "label": "extra"})
    return out


@pytest.fixture(scope="module")
def spread(tmp_path_factory):
    """One-axis layout, hit forces spread 50-600 N over 6 hits: identify gives force levels."""
    from guidefit.identify import IdentifySettings, identify

    path = tmp_path_factory.mktemp("levels") / "spread.h5"
    _sim(path, "default", hits=6, force_n=(50.0, 600.0))
    settings = replace(IdentifySettings(), force_levels=True, jackknife=False)
    return path, identify(path, settings=settings), settings


def test_force_levels_on_a_one_axis_layout_name_model_modes_only(spread):
    _, ident, _ = spread
    levels = ident.to_dict()["force_levels"]
    assert levels, "a 50-600 N spread over 6 hits gives force levels"
    assert {lv["label"] for lv in levels} <= set(MODE_LABELS)
    assert {lv["run"] for lv in levels} == {"vertical", "lateral"}


def test_an_ambiguous_mode_gets_no_force_level(spread):
    """identify refits an ambiguous mode as a neighbour but writes no level for it."""
    from guidefit.identify_runs import _force_levels
    from guidefit.io import read_recording

    path, ident, settings = spread
    rr = next(r for r in ident.runs if r.name == "vertical")
    run = next(r for r in read_recording(path).runs if r.name == "vertical")
    target = next(m for m in rr.modes if m.label == "pitch")
    modes = [replace(m, label="ambiguous", candidates=(("pitch", 0.6), ("roll_low", 0.4))) if m is target else m
             for m in rr.modes]
    levels, _ = _force_levels(run, rr.frf, rr.hits, modes, settings)
    labels = {lv["label"] for lv in levels}
    assert "ambiguous" not in labels and "vertical" in labels


def test_levels_of_ambiguous_or_extra_modes_are_left_out_not_refused(spread):
    """The defect: explain and explain --modes refused identify output with an ambiguous mode's level."""
    from guidefit.explain import explain, modes_from_result

    _, ident, _ = spread
    data = _with_ambiguous_level(ident.to_dict())
    _, _, _, levels = modes_from_result(data, "test")
    assert len(levels) == len(data["force_levels"]) - 2
    with pytest.raises(Exception, match="must be one of"):  # a label that is no label at all is still an error
        modes_from_result({**data, "force_levels": [{**data["force_levels"][0], "label": "pitchh"}]}, "test")
    # the same levels in the Identification's objects (explain reads those, not its JSON)
    first = next(r for r in ident.runs if r.force_levels)
    named = first.force_levels[0]
    unnamed = [{**named, "label": "ambiguous"}, {**named, "label": "extra"}]
    wrapped = replace(ident, runs=tuple(replace(r, force_levels=[*r.force_levels, *unnamed]) if r is first else r
                                        for r in ident.runs))
    result = explain(wrapped, candidates=["contact_stiffness"])
    assert result.verdict == "adequate"
    assert not [n for n in result.notes if "must be one of" in n]
    assert any("ambiguous and extra modes not used" in n for n in result.notes)


def test_explain_modes_file_with_ambiguous_levels(spread, tmp_path):
    _, ident, _ = spread
    path = tmp_path / "modes.json"
    path.write_text(json.dumps(_with_ambiguous_level(ident.to_dict())))
    out = json.loads(_cli("explain", "--modes", path, "--json", "--candidates", "contact_stiffness").stdout)
    assert out["verdict"] == "adequate"


# ---------------------------------------------------------------- DAQ setups, one axis per run

G = 9.80665


def _tdms_setup(folder, data, list_channels: bool) -> None:
    """Each run's TDMS file in volts under the DAQ's own names Acc1..Acc4 (the sensors are moved and
    turned between runs, the DAQ channels keep their names), and its setup."""
    from nptdms import ChannelObject, TdmsWriter

    channels, runs = {}, []
    for run in data.runs:
        daq = {n: ("Hammer" if n == "force" else f"Acc{k}") for k, n in enumerate(run.channel_names)}
        with TdmsWriter(folder / f"{run.name}.tdms") as writer:
            writer.write_segment([
                ChannelObject("Untitled", daq[n], np.asarray(run.data[:, j], float) * (1 if n == "force" else 1 / G)
                              * 10.0 / 1000, properties={"wf_increment": 1 / run.sample_rate_hz, "unit_string": "V"})
                for j, n in enumerate(run.channel_names)])
        for n in run.channel_names:
            channels[n] = [f'source = "{daq[n]}"', f'unit = "{"N" if n == "force" else "g"}"', "sensitivity_mv = 10.0"]
        runs += [f"[runs.{run.name}]", f'file = "{run.name}.tdms"',
                 f"excitation_direction = {json.dumps(run.excitation_direction.tolist())}",
                 f"excitation_position_m = {json.dumps(run.excitation_position_m.tolist())}"]
        if list_channels:
            runs.append(f"channels = {json.dumps(list(run.channel_names))}")
    lines = ['format = "guidefit-setup"', "format_version = 1", 'guide = "MRB35"']
    for name, keys in channels.items():
        lines += [f"[channels.{name}]", *keys]
    (folder / "test.toml").write_text("\n".join(lines + runs) + "\n")


@pytest.fixture(scope="module")
def one_axis_daq(tmp_path_factory):
    folder = tmp_path_factory.mktemp("daq_one_axis")
    data = _sim(folder / "contract.h5", "default", layout="signals", gap_s=0.005, seed=3)
    return folder, data


def test_daq_setup_with_one_axis_per_run_identifies_as_the_contract_file(one_axis_daq, monkeypatch):
    folder, data = one_axis_daq
    _tdms_setup(folder, data, list_channels=True)
    monkeypatch.chdir(folder)
    a = json.loads(_cli("identify", "test.toml", "--json", "--no-jackknife").stdout)
    b = json.loads(_cli("identify", "contract.h5", "--json", "--no-jackknife").stdout)
    assert [s["name"] for s in a["sensors"]] == [s["name"] for s in b["sensors"]]
    assert {"vertical", "roll_low"} <= {m["label"] for m in a["modes"]}
    for key in ("K_V", "K_H", "c_V", "c_H"):
        assert a["parameters"][key]["value"] == pytest.approx(b["parameters"][key]["value"], rel=1e-6), key


def test_daq_setup_reading_one_source_twice_is_a_one_line_error(one_axis_daq, monkeypatch):
    """Without the runs' channel lists, acc_A_y and acc_A_x would both read Acc1 in every run."""
    folder, data = one_axis_daq
    _tdms_setup(folder, data, list_channels=False)
    monkeypatch.chdir(folder)
    result = _cli("identify", "test.toml", code=2)
    line = result.output.strip().splitlines()[-1]
    assert "runs.vertical: channels 'acc_A_y' and 'acc_A_x' both read 'Acc1'" in line
    assert "runs.vertical.channels" in line


def test_daq_setup_listing_two_channels_of_one_source_in_a_run_is_a_one_line_error(one_axis_daq, monkeypatch):
    """Issue 21, item 6: a run whose own channel list maps one DAQ channel to two guidefit channels
    (acc_A_y and acc_A_x both Acc1, the first try when the sensors are turned between runs)."""
    folder, data = one_axis_daq
    _tdms_setup(folder, data, list_channels=True)
    text = (folder / "test.toml").read_text()
    vertical = next(r for r in data.runs if "acc_A_y" in r.channel_names)
    listed = f"channels = {json.dumps(list(vertical.channel_names))}"
    assert listed in text
    (folder / "test.toml").write_text(
        text.replace(listed, f"channels = {json.dumps([*vertical.channel_names, 'acc_A_x'])}", 1))
    monkeypatch.chdir(folder)
    result = _cli("identify", "test.toml", code=2)
    line = result.output.strip().splitlines()[-1]
    assert f"runs.{vertical.name}: channels 'acc_A_y' and 'acc_A_x' both read 'Acc1'" in line
    assert "a sensor is one channel" in line
