"""guidefit update: joint factors of a CalculiX machine deck fitted to measured modes.

The solver tests run ``ccx`` on the machine example (examples/machine: B31
beams, four MRB35 joints, about 0.1 s a run) and skip without it, saying so.
The truth of the example's "measured" modes is K_V x 0.8 on joint2 and
joint3 (examples/machine/truth.json), frequencies with 0.1 % noise.
"""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from guidefit.cli import main
from guidefit.export import export
from guidefit.machine.ccx_deck import DeckError, load_deck, parse_joint_file, render_joint_file
from guidefit.machine.update import UpdateError, parse_params

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "machine"
CCX = shutil.which("ccx")
needs_ccx = pytest.mark.skipif(CCX is None, reason="CalculiX ccx not installed (apt-get install calculix-ccx)")
RESULT = {"file": "c1.h5", "guide": "MRB35", "parameters": {
    "K_V": {"value": 1.03e9}, "c_V": {"value": 2750.0}, "K_H": {"value": 1.00e8}, "c_H": {"value": 3109.0}},
    "modes": [{"label": "vertical", "frequency_hz": 3450.0, "damping_ratio": 0.0288}]}
ADEQUATE = {"file": "c1.h5", "verdict": "adequate", "guide": "MRB35", "effects": []}


@pytest.fixture
def example(tmp_path):
    for name in ("machine.inp", "joints.inp", "measured.csv"):
        shutil.copy(EXAMPLE / name, tmp_path / name)
    return tmp_path


def _joint(tmp_path, **options) -> Path:
    results, explain = tmp_path / "r.jsonl", tmp_path / "e.json"
    results.write_text(json.dumps(RESULT) + "\n")
    explain.write_text(json.dumps(ADEQUATE))
    out = tmp_path / "j.inp"
    out.write_text(export(results, "calculix", explanations=[explain], **options))
    return out


def _one_line_exit_2(result, *words):
    assert result.exit_code == 2, result.output
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and "Traceback" not in result.output, result.output
    for w in words:
        assert w in lines[0], lines[0]
    return lines[0]


# --------------------------------------------------------------------------- without the solver


def test_param_syntax():
    ps = parse_params(["each:K_V=0.5..2", "joint1,joint2:K_H", "all:K_yaw"], 4)
    assert [p.name for p in ps] == ["joint1:K_V", "joint2:K_V", "joint3:K_V", "joint4:K_V", "joint1+joint2:K_H",
                                    "all:K_yaw"]
    assert (ps[0].lower, ps[0].upper, ps[0].directions) == (0.5, 2.0, (1,))
    assert ps[4].joints == (0, 1) and (ps[4].lower, ps[4].upper) == (0.1, 10.0)
    for bad, said in (("joint5:K_V", "not a joint"), ("each:K_Q", "unknown"), ("each:c_V", "damping"),
                      ("each:K_V=2..3", "bounds"), ("each:K_V=0.5", "bounds"), ("K_V", "SEL:NAME"),
                      ("each:K_V,all:K_V", "both scale")):
        with pytest.raises(UpdateError, match=said):
            parse_params(bad.split(",") if bad.startswith("each:K_V,") else [bad], 4)
    with pytest.raises(UpdateError, match="both scale joint1"):
        parse_params(["each:K_V", "joint1:K"], 4)


@pytest.mark.parametrize("element,units,axis_map", [("matrix", "si", None), ("matrix", "mm-N-s", "x=X,y=Z,z=-Y"),
                                                    ("bush", "mm-t-s", "x=-Y,y=X,z=Z"), ("springs", "si", None)])
def test_scaling_is_d_k_d_in_the_model_frame(tmp_path, element, units, axis_map):
    """A factor f on K_V (model y) gives K' = D K D with D = diag(sqrt f) on the machine axis y maps to."""
    path = _joint(tmp_path, element=element, units=units, axis_map=axis_map)
    jf = parse_joint_file(path, path.read_text().splitlines())
    assert (jf.element, jf.units) == (element, units)
    factors = np.array([[1.0, 0.8, 1.0, 1.0, 1.3, 1.0]])  # K_V x 0.8, K_yaw x 1.3
    again = parse_joint_file(path, render_joint_file(jf, factors).splitlines())
    f_machine = np.ones(6)
    f_machine[jf.machine_of_model] = factors[0]
    d = np.diag(np.sqrt(f_machine))
    k0, k1 = jf.stiffness(0), again.stiffness(0)
    assert np.abs(k1 - d @ k0 @ d).max() <= 1e-12 * np.abs(k0).max()
    if element != "springs":  # springs carry no yaw of their own: their positions give it
        assert again.model_diagonal(0)[[1, 4]] == pytest.approx(jf.model_diagonal(0)[[1, 4]] * [0.8, 1.3], rel=1e-12)
    assert render_joint_file(jf, np.ones((1, 6))).splitlines()[:5] == path.read_text().splitlines()[:5]


def test_deck_without_guidefit_joint_is_refused(example, tmp_path):
    (example / "plain.inp").write_text((example / "machine.inp").read_text().replace(
        "*INCLUDE,INPUT=joints.inp", "** no joints"))
    out = CliRunner().invoke(main, ["update", str(example / "plain.inp"), str(example / "measured.csv"),
                                    "--param", "each:K_V"])
    _one_line_exit_2(out, "includes no joint written by guidefit")
    assert not list(example.glob("*.updated.inp"))


def test_missing_include_and_reference_assembly_refused(example, tmp_path):
    (example / "a.inp").write_text("*INCLUDE,INPUT=nowhere.inp\n")
    with pytest.raises(DeckError, match="not found"):
        load_deck(example / "a.inp")
    results = tmp_path / "r.jsonl"
    results.write_text(json.dumps(RESULT) + "\n")
    (example / "ref.inp").write_text(export(results, "calculix", joint="apparent", assembly="reference"))
    (example / "b.inp").write_text("*INCLUDE,INPUT=ref.inp\n")
    with pytest.raises(DeckError, match="reference assembly"):
        load_deck(example / "b.inp")


def test_units_that_disagree(example, tmp_path):
    out = CliRunner().invoke(main, ["update", str(example / "machine.inp"), str(example / "measured.csv"),
                                    "--param", "each:K_V", "--units", "mm-t-s"])
    _one_line_exit_2(out, "units that disagree")
    other = _joint(tmp_path, units="mm-N-s", carriage_nodes=[90001], rail_nodes=[90002], first_element=95001)
    shutil.copy(other, example / "other.inp")
    text = (example / "machine.inp").read_text().replace("*INCLUDE,INPUT=joints.inp",
                                                          "*INCLUDE,INPUT=joints.inp\n*INCLUDE,INPUT=other.inp")
    (example / "mixed.inp").write_text(text)
    out = CliRunner().invoke(main, ["update", str(example / "mixed.inp"), str(example / "measured.csv"),
                                    "--param", "each:K_V"])
    _one_line_exit_2(out, "different units", "si", "mm-N-s")


def test_missing_and_failing_solver(example, tmp_path):
    args = ["update", str(example / "machine.inp"), str(example / "measured.csv"), "--param", "all:K_V"]
    out = CliRunner().invoke(main, [*args, "--ccx", str(tmp_path / "no-such-ccx")])
    _one_line_exit_2(out, "not found", "calculix-ccx")
    fake = tmp_path / "fakeccx"
    fake.write_text("#!/bin/sh\necho ' *ERROR reading *BOUNDARY: node 123 is not defined'\nexit 0\n")
    fake.chmod(0o755)
    out = CliRunner().invoke(main, [*args, "--ccx", str(fake)])
    _one_line_exit_2(out, "ccx failed", "node 123")
    assert not list(example.glob("*.updated.inp"))


# --------------------------------------------------------------------------- with the solver


@needs_ccx
def test_example_update_recovers_the_truth(example):
    """each:K_V on the example: joint2, joint3 x 0.8, joint1, joint4 x 1, within 2 std and 3 %; errors shrink."""
    truth = json.loads((EXAMPLE / "truth.json").read_text())["factors"]
    out = CliRunner().invoke(main, ["update", str(example / "machine.inp"), str(example / "measured.csv"),
                                    "--param", "each:K_V=0.5..2", "--jobs", "2", "--json"])
    assert out.exit_code == 0, out.output
    doc = json.loads(out.stdout)
    for p in doc["parameters"]:
        want = truth.get(p["name"], 1.0)
        assert p["identifiable"] and p["fitted"]
        assert abs(p["factor"] - want) <= 2 * p["factor_std"], p
        assert p["factor"] == pytest.approx(want, rel=0.03)
        assert p["factor_std"] < 0.03
    assert doc["before"]["max_abs_error_pct"] > 3.0 and doc["after"]["max_abs_error_pct"] < 0.3
    assert doc["before"]["paired_by"] == "mac" and doc["after"]["min_mac"] > 0.99
    assert doc["sigma_pct"] == pytest.approx(0.1, rel=0.5)  # the residual's std: the noise put in
    assert doc["runs"] < 80 and doc["ccx_seconds"] > 0
    written = example / "joints.updated.inp"
    assert doc["written"] == [str(written)]
    again = load_deck_with(example, written)
    for j, p in enumerate(doc["parameters"]):
        k, c = again.joints[j]
        assert again.joint_files[k].model_diagonal(c)[1] == pytest.approx(p["updated"][0], rel=1e-12)
    assert "updated by guidefit" in written.read_text()


def load_deck_with(folder, joint_file):
    text = (folder / "machine.inp").read_text().replace("INPUT=joints.inp", f"INPUT={joint_file.name}")
    (folder / "updated_machine.inp").write_text(text)
    return load_deck(folder / "updated_machine.inp")


@needs_ccx
def test_unidentifiable_parameter_is_named_and_held(example):
    """The example's modes do not see the carriages' yaw stiffness apart: update says so and keeps it."""
    out = CliRunner().invoke(main, ["update", str(example / "machine.inp"), str(example / "measured.csv"),
                                    "--param", "all:K_V", "--param", "each:K_yaw", "--jobs", "2"])
    assert out.exit_code == 0, out.output
    assert "not identifiable: " in out.stderr and "K_yaw" in out.stderr
    assert "all:K_V" in out.stdout and "wrote" in out.stdout


@needs_ccx
def test_measured_without_shapes_pairs_by_order_with_a_warning(example):
    freqs = [line.split(",")[1] for line in (example / "measured.csv").read_text().splitlines()[2:]]
    (example / "freqs.csv").write_text("frequency_hz\n" + "\n".join(freqs) + "\n")
    out = CliRunner().invoke(main, ["update", str(example / "machine.inp"), str(example / "freqs.csv"),
                                    "--param", "all:K_V", "--json"])
    assert out.exit_code == 0, out.output
    assert "paired by order" in out.stderr and "no shapes on the test side" in out.stderr
    assert json.loads(out.stdout)["after"]["paired_by"] == "order"


@needs_ccx
def test_frequencies_far_off_are_units_that_disagree(example):
    lines = (example / "measured.csv").read_text().splitlines()
    rows = [line.split(",") for line in lines[2:]]
    scaled = [",".join([r[0], repr(float(r[1]) * 1000**0.5), *r[2:]]) for r in rows]
    (example / "mm.csv").write_text("\n".join(lines[:2] + scaled) + "\n")
    out = CliRunner().invoke(main, ["update", str(example / "machine.inp"), str(example / "mm.csv"),
                                    "--param", "all:K_V"])
    _one_line_exit_2(out, "units that disagree")
    assert not list(example.glob("*.updated.inp"))


@needs_ccx
def test_correlate_prints_table_3_of_the_example(example):
    import subprocess

    subprocess.run([CCX, "-i", "machine"], cwd=example, capture_output=True, check=True, timeout=60)
    out = CliRunner().invoke(main, ["correlate", str(example / "machine.dat"), str(example / "measured.csv")])
    assert out.exit_code == 0, out.output
    assert "paired by mac" in out.output and len(out.output.splitlines()) == 14


def test_example_joints_are_what_export_writes(tmp_path):
    """examples/machine/joints.inp is guidefit export's output for the example's results (no drift)."""
    results = EXAMPLE / "results.jsonl"
    explains = []
    for j in range(4):
        e = tmp_path / f"e{j}.json"
        e.write_text(json.dumps({"file": f"carriage{j + 1}.h5", "verdict": "adequate", "guide": "MRB35",
                                 "effects": []}))
        explains.append(e)
    text = export(results, "calculix", explanations=explains)
    strip = [line for line in text.splitlines() if not line.startswith("** guidefit ")]
    want = [line for line in (EXAMPLE / "joints.inp").read_text().splitlines() if not line.startswith("** guidefit ")]
    assert strip == want
