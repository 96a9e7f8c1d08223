"""guidefit plan: the model's modes as a planned test will see them (the labeller's own computation)."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
from click.testing import CliRunner

from guidefit.cli import main
from guidefit.model.guides import load_guide
from guidefit.modes.labels import layout_view
from guidefit.plan import layout_runs, make_plan, plan

GUIDE = load_guide("MRB35")


def test_default_layout_decides_the_single_motion_modes_by_shape_and_roll_high_by_frequency():
    """x sensors on the top face (y = 0) do not read phi: roll_low and roll_high look alike there (auto-MAC
    near 1); the vertical, pitch and yaw modes each have a motion of their own."""
    p = make_plan(GUIDE, layout_runs(GUIDE, "default"))
    for label in ("vertical", "pitch", "yaw"):
        assert p.basis[label] == "shape"
    assert p.basis["roll_high"] in ("frequency", "shape+frequency")
    i, j = p.view.labels.index("roll_low"), p.view.labels.index("roll_high")
    assert p.view.auto_mac[i, j] > 0.9


def test_auto_mac_is_symmetric_with_a_unit_diagonal():
    from guidefit.model import vibration as vib

    model = vib.solve_modes(vib.model_from_guide(GUIDE))
    v = layout_view(model, {r.name: r.view() for r in layout_runs(GUIDE, "pair")})
    mac = v.auto_mac
    assert np.allclose(mac, mac.T, atol=1e-12)
    assert np.allclose(np.diag(mac)[list(v.visible)], 1.0, atol=1e-12)
    assert np.all((mac >= -1e-12) & (mac <= 1 + 1e-12))


def test_y_sensors_only_cannot_see_yaw():
    from guidefit.plan import PlanRun

    runs = [PlanRun(r.name, tuple(s for s in layout_runs(GUIDE, "both")[k].sensors if s.name.endswith("_y")),
                    r.excitation_direction, r.excitation_position_m)
            for k, r in enumerate(layout_runs(GUIDE, "both"))]
    p = make_plan(GUIDE, runs)
    assert p.basis["yaw"] == "not seen"
    assert not p.view.visible[p.view.labels.index("yaw")]


def test_both_axes_decide_every_label_by_shape_and_the_search_finds_it():
    p = make_plan(GUIDE, layout_runs(GUIDE, "default"), search=True)
    assert p.best["budget_sensors_per_run"] == 4
    by_layout = {x["layout"]: x for x in p.best["layouts"]}
    assert by_layout["both"]["decided_by_shape"] == 5 and by_layout["both"]["sensors_per_run"] == 8
    assert p.best["sensors_per_run"] <= 4  # the recommendation fits the planned DAQ


def test_plan_agrees_with_identify_on_a_simulated_recording(tmp_path):
    """The plan of a recording's geometry says what identify then reports for its labels."""
    from guidefit.identify import IdentifySettings, identify
    from guidefit.io import write_recording
    from guidefit.simulate import SimulationConfig, simulate

    data, _ = simulate("MRB35", config=SimulationConfig(hits=3, record_s=0.03, sensor_layout="default"), seed=2)
    path = tmp_path / "rec.h5"
    write_recording(path, data)
    p = plan(path, search=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = identify(path, settings=IdentifySettings(jackknife=False))
    by_shape = [m for m in result.modes if p.basis[m.label] == "shape"]
    assert {m.label for m in by_shape} >= {"vertical", "pitch", "yaw"}
    for m in by_shape:  # what the layout decides by shape, the data do too
        assert m.label_basis in ("shape", "shape+frequency")


def test_a_recording_without_excitation_position_is_planned_at_its_force_channel(tmp_path):
    """The contract's force channel position is the hit point; was: 'hit at unknown', no participation."""
    import h5py

    from guidefit.io import write_recording
    from guidefit.simulate import SimulationConfig, simulate

    data, _ = simulate("MRB35", config=SimulationConfig(hits=1, record_s=0.01, sensor_layout="default"), seed=2)
    path = tmp_path / "rec.h5"
    write_recording(path, data)
    with_attr = plan(path, search=False).to_dict()
    with h5py.File(path, "r+") as f:
        for run in f["runs"].values():
            del run.attrs["excitation_position_m"]
    without = plan(path, search=False).to_dict()
    assert [r["excitation_position_m"] for r in without["runs"]] == [r["excitation_position_m"]
                                                                     for r in with_attr["runs"]]
    assert without["modes"] == with_attr["modes"]


def _setup(folder):
    text = """format = "guidefit-setup"
format_version = 1
guide = "MRB35"
[channels.force]
source = "F"
unit = "N"
[channels.acc_A_y]
source = "A"
unit = "m/s^2"
[channels.acc_C_y]
source = "C"
unit = "m/s^2"
[channels.acc_A_x]
source = "A"
unit = "m/s^2"
[channels.acc_C_x]
source = "C"
unit = "m/s^2"
[runs.vertical]
file = "vertical.tdms"
excitation_direction = [0.0, -1.0, 0.0]
excitation_position_m = [0.004, 0.0, 0.008]
channels = ["force", "acc_A_y", "acc_C_y"]
[runs.lateral]
file = "lateral.tdms"
excitation_direction = [-1.0, 0.0, 0.0]
excitation_position_m = [0.05, -0.012, 0.006]
channels = ["force", "acc_A_x", "acc_C_x"]
"""
    path = folder / "test.toml"
    path.write_text(text)
    return path


def test_a_setup_is_planned_before_its_daq_files_exist(tmp_path):
    path = _setup(tmp_path)
    out = CliRunner().invoke(main, ["plan", str(path), "--json", "--no-search"])
    assert out.exit_code == 0, out.output
    d = json.loads(out.stdout)
    runs = {r["name"]: [s["name"] for s in r["sensors"]] for r in d["runs"]}
    assert runs == {"vertical": ["acc_A_y", "acc_C_y"], "lateral": ["acc_A_x", "acc_C_x"]}
    assert {m["label"] for m in d["modes"]} == {"yaw", "pitch", "roll_low", "vertical", "roll_high"}
    assert all(m["label_basis"] in ("shape", "frequency", "shape+frequency", "ambiguous", "not seen")
               for m in d["modes"])


def test_cli_table_json_and_plot(tmp_path):
    runner = CliRunner()
    out = runner.invoke(main, ["plan", "--sensors", "side", "--hit", "lateral:0.05,-0.02,0.01"])
    assert out.exit_code == 0, out.output
    assert "label by" in out.stdout and "auto-MAC" in out.stdout
    png = tmp_path / "mac.png"
    out = runner.invoke(main, ["plan", "--sensors", "pair", "--json", "--plot", str(png), "--no-search"])
    assert out.exit_code == 0, out.output
    d = json.loads(out.stdout)
    assert d["best"] is None and len(d["auto_mac"]["matrix"]) == 5
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize("args, words", [
    (["--sensors", "nonsense"], "nonsense"),
    (["--hit", "vertical"], "RUN:x,y,z"),
    (["--hit", "sideways:0,0,0"], "sideways"),
    (["--hit", "vertical:0,0,0", "--hit", "vertical:0,0,0.01"], "twice"),
    (["--plot", "mac.csv"], ".png, .pdf, .svg"),
])
def test_bad_input_is_one_line_exit_2(args, words):
    out = CliRunner().invoke(main, ["plan", *args, "--no-search"])
    assert out.exit_code == 2, out.output
    lines = [line for line in out.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and words in lines[0] and "Traceback" not in out.output
