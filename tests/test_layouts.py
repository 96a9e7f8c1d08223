"""Sensor layouts and hit points (guidefit.simulate.layouts, ``guidefit simulate --sensors/--hit``).

Expected channels are written down from the recording contract and the MRB35
points of ``guidefit/model/data/MRB35.toml``: A (+0.030, 0, +0.045),
B (-0.030, 0, +0.045), C (-0.030, 0, -0.045), D (+0.030, 0, -0.045); the side
points E-H at (+/-0.050, -0.015, +/-0.040) (docs/simulate.md, "Sensor layouts").
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from guidefit.cli import main
from guidefit.errors import ModelError
from guidefit.model.guides import load_guide
from guidefit.simulate import DEFAULT_RUNS, HammerRun, SimulationConfig, simulate, truth_path
from guidefit.simulate.layouts import (
    SensorSpec,
    apply_hits,
    parse_hit,
    read_layout_file,
    resolve_layout,
    run_axis,
    side_points_m,
)

MRB35 = load_guide("MRB35")
A, B, C, D = (0.030, 0.0, 0.045), (-0.030, 0.0, 0.045), (-0.030, 0.0, -0.045), (0.030, 0.0, -0.045)
X, Y, Z = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)
E, F, G, H = (0.05, -0.015, 0.04), (0.05, -0.015, -0.04), (-0.05, -0.015, 0.04), (-0.05, -0.015, -0.04)
AXIAL = HammerRun("axial", (0.0, -0.01, 0.06), (0.0, 0.0, -1.0))


def specs(*rows):
    return tuple(SensorSpec(name, pos, d) for name, pos, d in rows)


def table(layout, runs=DEFAULT_RUNS, guide=MRB35):
    """Run -> [(name, position, direction)] rounded to 1e-12 (float noise of the side points)."""
    out = resolve_layout(guide, layout, runs)
    return {run: [(s.name, tuple(round(v, 12) for v in s.position_m), tuple(s.direction)) for s in sensors]
            for run, sensors in out.items()}


# --------------------------------------------------------------------------- named layouts


def test_default_is_a_to_d_along_each_runs_hammer_axis():
    expected = {
        "vertical": [("acc_A_y", A, Y), ("acc_B_y", B, Y), ("acc_C_y", C, Y), ("acc_D_y", D, Y)],
        "lateral": [("acc_A_x", A, X), ("acc_B_x", B, X), ("acc_C_x", C, X), ("acc_D_x", D, X)],
    }
    assert table("default") == expected
    assert table("ad") == expected
    assert table("default", (AXIAL,)) == {"axial": [("acc_A_z", A, Z), ("acc_B_z", B, Z), ("acc_C_z", C, Z),
                                                   ("acc_D_z", D, Z)]}


def test_run_axis_is_the_largest_component_ties_to_the_first():
    assert run_axis((0.0, -1.0, 0.0)) == "y"
    assert run_axis((-1.0, 0.0, 0.0)) == "x"
    assert run_axis((0.3, -0.2, 0.9)) == "z"
    assert run_axis((1.0, -1.0, 0.0)) == "x"


def test_pair_and_single_have_two_and_one_sensor_per_run():
    assert table("pair") == {"vertical": [("acc_A_y", A, Y), ("acc_C_y", C, Y)],
                             "lateral": [("acc_A_x", A, X), ("acc_C_x", C, X)]}
    assert table("single") == {"vertical": [("acc_A_y", A, Y)], "lateral": [("acc_A_x", A, X)]}


def test_both_is_x_and_y_at_a_to_d_in_every_run_as_the_library_default():
    row = [(f"acc_{p}_{a}", pos, d) for p, pos in zip("ABCD", (A, B, C, D)) for a, d in (("x", X), ("y", Y))]
    assert table("both") == {"vertical": row, "lateral": row}
    data, _ = simulate(MRB35, config=SimulationConfig(hits=1, record_s=0.002))  # sensor_layout None
    assert [n for n in data.runs[0].channel_names[1:]] == [r[0] for r in row]


def test_triax_at_named_points_and_all_four_by_default():
    row = [("acc_A_x", A, X), ("acc_A_y", A, Y), ("acc_A_z", A, Z),
           ("acc_C_x", C, X), ("acc_C_y", C, Y), ("acc_C_z", C, Z)]
    assert table("triax:A,C") == {"vertical": row, "lateral": row}
    assert table("triax: C , A")["vertical"][0][0] == "acc_C_x"
    assert len(table("triax")["lateral"]) == 12


def test_side_puts_lateral_sensors_on_the_side_faces():
    assert table("side") == {
        "vertical": [("acc_A_y", A, Y), ("acc_B_y", B, Y), ("acc_C_y", C, Y), ("acc_D_y", D, Y)],
        "lateral": [("acc_E_x", E, X), ("acc_F_x", F, X), ("acc_G_x", G, X), ("acc_H_x", H, X)],
    }


def test_side_points_a_guide_defines_are_used(tmp_path):
    points = dict(MRB35.measuring_points_m, E=(0.06, -0.02, 0.03), F=(0.06, -0.02, -0.03),
                  G=(-0.06, -0.02, 0.03), H=(-0.06, -0.02, -0.03))
    guide = MRB35.with_changes(measuring_points_m=points)
    assert side_points_m(guide)["G"] == (-0.06, -0.02, 0.03)
    assert table("side", guide=guide)["lateral"][0] == ("acc_E_x", (0.06, -0.02, 0.03), X)


@pytest.mark.parametrize(("layout", "fragment"), [
    ("bogus", "layout 'bogus' unknown"),
    ("triax:A,Q", "point 'Q' not defined by guide MRB35"),
    ("triax:", "expected triax:POINT"),
    ("triax:A,A", "named twice"),
])
def test_bad_layout_names_are_one_line_model_errors(layout, fragment):
    with pytest.raises(ModelError, match=fragment) as info:
        resolve_layout(MRB35, layout, DEFAULT_RUNS)
    assert "\n" not in str(info.value)


def test_a_guide_without_point_c_cannot_have_the_default_layout():
    guide = MRB35.with_changes(measuring_points_m={"A": A, "B": B})
    with pytest.raises(ModelError, match="layout 'default': point 'C' not defined"):
        resolve_layout(guide, "default", DEFAULT_RUNS)
    assert table("single", guide=guide)["vertical"] == [("acc_A_y", A, Y)]


# --------------------------------------------------------------------------- TOML layouts


RIG = """
[[sensor]]
name = "acc_A_y"
runs = ["vertical"]

[[sensor]]
name = "acc_E_x"
position_m = [0.05, -0.015, 0.04]
direction = [2, 0, 0]
runs = ["lateral"]

[[sensor]]
name = "acc_K_y"
position_m = [0.0, 0.0, 0.0]
direction = [0, 1, 1]
"""


def test_toml_layout_gives_each_run_its_sensors(tmp_path):
    path = tmp_path / "rig.toml"
    path.write_text(RIG)
    out = read_layout_file(path, MRB35, DEFAULT_RUNS)
    s = 1 / np.sqrt(2.0)
    assert out == {
        "vertical": specs(("acc_A_y", A, Y), ("acc_K_y", (0.0, 0.0, 0.0), (0.0, s, s))),
        "lateral": specs(("acc_E_x", E, X), ("acc_K_y", (0.0, 0.0, 0.0), (0.0, s, s))),
    }
    assert resolve_layout(MRB35, str(path), DEFAULT_RUNS) == out


@pytest.mark.parametrize(("text", "fragment"), [
    ("[[sensor]]\nname = 'acc_A_y'\ncolour = 'red'\n", "sensor[0]: unknown key 'colour'"),
    ("[[sensors]]\nname = 'acc_A_y'\n", "unknown key 'sensors'"),
    ("sensor = 3\n", "key 'sensor' must be one or more [[sensor]] tables"),
    ("[[sensor]]\nposition_m = [0, 0, 0]\n", "sensor[0]: key 'name' missing"),
    ("[[sensor]]\nname = 'A_y'\n", "sensor[0]: key 'name' = 'A_y'; expected 'acc_<point>_<axis>'"),
    ("[[sensor]]\nname = 'acc_A_w'\n", "key 'name' = 'acc_A_w'"),
    ("[[sensor]]\nname = 'acc_A_y'\nposition_m = [0, 0]\n", "sensor[0] (acc_A_y): key 'position_m'"),
    ("[[sensor]]\nname = 'acc_A_y'\nposition_m = [0, 'x', 0]\n", "key 'position_m'"),
    ("[[sensor]]\nname = 'acc_A_y'\ndirection = [0, 0, 0]\n", "key 'direction' = [0, 0, 0]; expected a non-zero"),
    ("[[sensor]]\nname = 'acc_A_y'\ndirection = [0, nan, 0]\n", "key 'direction'"),
    ("[[sensor]]\nname = 'acc_Q_y'\n", "key 'position_m' missing and guide MRB35 defines no point 'Q'"),
    ("[[sensor]]\nname = 'acc_A_y'\nruns = ['top']\n", "key 'runs': run 'top' not simulated"),
    ("[[sensor]]\nname = 'acc_A_y'\nruns = 'vertical'\n", "key 'runs' must be a non-empty list"),
    ("[[sensor]]\nname = 'acc_A_y'\nruns = ['vertical']\n", "run 'lateral' has no sensor"),
    ("[[sensor]]\nname = 'acc_A_y'\n[[sensor]]\nname = 'acc_A_y'\n", "sensor[1] (acc_A_y): channel 'acc_A_y' twice"),
    ("[[sensor]\n", "not valid TOML"),
])
def test_toml_layout_errors_name_the_key(tmp_path, text, fragment):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ModelError) as info:
        resolve_layout(MRB35, str(path), DEFAULT_RUNS)
    assert fragment in str(info.value) and "\n" not in str(info.value)


def test_missing_toml_file_is_a_model_error(tmp_path):
    with pytest.raises(ModelError, match="no such file"):
        resolve_layout(MRB35, str(tmp_path / "none.toml"), DEFAULT_RUNS)


# --------------------------------------------------------------------------- hits


def test_parse_hit_and_apply_hits_move_only_the_named_run():
    assert parse_hit("vertical:0,0.001,-2e-3") == ("vertical", (0.0, 0.001, -0.002))
    runs = apply_hits(DEFAULT_RUNS, ["lateral:0.05,-0.02,0", ("vertical", (0.01, 0, 0))])
    assert runs[0] == HammerRun("vertical", (0.01, 0.0, 0.0), (0.0, -1.0, 0.0))
    assert runs[1] == HammerRun("lateral", (0.05, -0.02, 0.0), (-1.0, 0.0, 0.0))
    assert apply_hits(DEFAULT_RUNS, []) == DEFAULT_RUNS


@pytest.mark.parametrize("text", ["vertical", "vertical:1,2", "vertical:1,2,3,4", ":1,2,3", "vertical:a,b,c",
                                  "vertical:nan,0,0", "vertical:inf,0,0"])
def test_bad_hit_text_is_one_line(text):
    with pytest.raises(ModelError, match="hit: expected RUN:x,y,z"):
        parse_hit(text)


def test_apply_hits_refuses_unknown_and_repeated_runs():
    with pytest.raises(ModelError, match="run 'top' not simulated; have vertical, lateral"):
        apply_hits(DEFAULT_RUNS, ["top:0,0,0"])
    with pytest.raises(ModelError, match="run 'vertical' given twice"):
        apply_hits(DEFAULT_RUNS, ["vertical:0,0,0", "vertical:0,0,0.01"])


# --------------------------------------------------------------------------- simulate and CLI


def test_simulation_config_layout_and_loose_sensor_in_one_run():
    cfg = SimulationConfig(hits=1, record_s=0.002, sensor_layout="pair", faults=("loose_sensor:channel=acc_C_y",))
    data, truth = simulate(MRB35, config=cfg)
    assert [r.channel_names for r in data.runs] == [("force", "acc_A_y", "acc_C_y"), ("force", "acc_A_x", "acc_C_x")]
    assert truth["config"]["sensor_layout"] == "pair"
    assert [s["name"] for s in truth["runs"]["lateral"]["sensors"]] == ["acc_A_x", "acc_C_x"]
    assert truth["runs"]["vertical"]["hits"][0]["faults"][0]["name"] == "loose_sensor"
    assert truth["runs"]["lateral"]["hits"][0]["faults"] == []
    bad = SimulationConfig(hits=1, record_s=0.002, sensor_layout="pair", faults=("loose_sensor:channel=acc_B_y",))
    with pytest.raises(ModelError, match="channel 'acc_B_y' not recorded in any run"):
        simulate(MRB35, config=bad)
    with pytest.raises(ModelError, match="layout 'nope' unknown"):
        simulate(MRB35, config=SimulationConfig(hits=1, record_s=0.002, sensor_layout="nope"))


def _simulate_cli(tmp_path, *args):
    out = tmp_path / "t.h5"
    result = CliRunner().invoke(main, ["simulate", "--out", str(out), "--hits", "1", "--record-length", "0.002",
                                       "--ideal", *args])
    assert result.exit_code == 0, result.output
    from guidefit.io import read_recording

    return read_recording(out), json.loads(truth_path(out).read_text())


@pytest.mark.parametrize("layout", ["default", "ad", "both", "pair", "single", "side", "triax:A,C", "rig.toml"])
def test_cli_simulate_writes_each_layout(tmp_path, layout):
    if layout.endswith(".toml"):
        (tmp_path / layout).write_text(RIG)
        layout = str(tmp_path / layout)
    expected = table(layout)
    rec, truth = _simulate_cli(tmp_path, "--sensors", layout)
    assert [r.name for r in rec.runs] == list(expected)
    for run in rec.runs:
        acc = [ch for ch in run.channels if ch.name != "force"]
        assert [ch.name for ch in acc] == [e[0] for e in expected[run.name]]
        np.testing.assert_allclose([ch.position_m for ch in acc], [e[1] for e in expected[run.name]], atol=1e-12)
        np.testing.assert_allclose([ch.direction for ch in acc], [e[2] for e in expected[run.name]], atol=1e-12)
    assert truth["config"]["sensor_layout"] == layout


def test_cli_default_layout_is_one_axis_per_run_and_hit_moves_the_hammer(tmp_path):
    rec, truth = _simulate_cli(tmp_path, "--hit", "lateral:0.05,-0.02,0.01", "--runs", "lateral")
    (run,) = rec.runs
    assert run.channel_names == ("force", "acc_A_x", "acc_B_x", "acc_C_x", "acc_D_x")
    np.testing.assert_allclose(run.excitation_position_m, (0.05, -0.02, 0.01))
    force = next(ch for ch in run.channels if ch.name == "force")
    np.testing.assert_allclose(force.position_m, (0.05, -0.02, 0.01))
    assert truth["runs"]["lateral"]["excitation_position_m"] == [0.05, -0.02, 0.01]


@pytest.mark.parametrize(("args", "fragment"), [
    (["--sensors", "bogus"], "layout 'bogus' unknown"),
    (["--sensors", "triax:A,Z9"], "point 'Z9' not defined"),
    (["--sensors", "missing.toml"], "no such file"),
    (["--hit", "vertical:1,2"], "expected RUN:x,y,z"),
    (["--hit", "top:0,0,0"], "run 'top' not simulated"),
    (["--runs", "vertical", "--hit", "lateral:0,0,0"], "run 'lateral' not simulated"),
    (["--sensors", "single", "--fault", "loose_sensor"], "channel 'acc_C_y' not recorded"),
])
def test_cli_bad_layout_or_hit_exits_2_with_one_line(tmp_path, args, fragment):
    result = CliRunner().invoke(main, ["simulate", "--out", str(tmp_path / "x.h5"), "--hits", "1", *args])
    assert result.exit_code == 2, result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("guidefit: error:") and fragment in lines[0], result.stderr
    assert "Traceback" not in result.output
    assert not (tmp_path / "x.h5").exists()


def test_cli_bad_toml_layout_exits_2_naming_the_key(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[[sensor]]\nname = 'acc_A_y'\ndirection = [0, 0, 0]\n")
    result = CliRunner().invoke(main, ["simulate", "--out", str(tmp_path / "x.h5"), "--sensors", str(bad)])
    assert result.exit_code == 2
    assert result.stderr.count("\n") == 1 and "key 'direction'" in result.stderr and "Traceback" not in result.output


def test_a_layout_file_given_as_a_path_is_recorded_as_text(tmp_path):
    from guidefit.simulate import write_simulation

    path = tmp_path / "rig.toml"
    path.write_text(RIG)
    out = write_simulation(tmp_path / "x.h5", MRB35, config=SimulationConfig(hits=1, record_s=0.002,
                                                                             sensor_layout=path).ideal())
    assert out.truth["config"]["sensor_layout"] == str(path)
    assert [s["name"] for s in out.truth["runs"]["lateral"]["sensors"]] == ["acc_E_x", "acc_K_y"]
