"""Export to FEM spring-damper cards: fields, units and the split over elements."""

import json

import pytest
from click.testing import CliRunner

from guidefit.cli import main
from guidefit.errors import RecordingError
from guidefit.export import joint_elements, read_results, to_abaqus, to_ansys, to_nastran

RESULT = {"file": "carriage1.h5", "parameters": {
    "K_V": {"value": 1.03e9, "unit": "N/m"}, "c_V": {"value": 2750.0, "unit": "N*s/m"},
    "K_H": {"value": 1.00e8, "unit": "N/m"}, "c_H": {"value": 3109.0, "unit": "N*s/m"}}}


@pytest.fixture
def results_file(tmp_path):
    path = tmp_path / "results.jsonl"
    second = json.loads(json.dumps(RESULT))
    second["file"] = "carriage2.h5"
    path.write_text(json.dumps(RESULT) + "\n" + json.dumps(second) + "\n")
    return path


def test_elements_sum_to_identified_joint():
    els = joint_elements([RESULT])
    vertical = [e for e in els if e.dof == 2]
    horizontal = [e for e in els if e.dof == 1]
    assert len(vertical) == 4 and len(horizontal) == 8
    assert sum(e.stiffness_n_per_m for e in vertical) == pytest.approx(1.03e9)
    assert sum(e.damping_ns_per_m for e in horizontal) == pytest.approx(3109.0)


def test_nastran_cards_fixed_fields():
    text = to_nastran(joint_elements([RESULT]))
    lines = [line for line in text.splitlines() if not line.startswith("$")]
    pbush = lines[0]
    assert pbush[:8] == "PBUSH   " and pbush[16:24] == "K       "
    # vertical element: K on field DOF 2 (columns 32-40): 1.03e9 / 4 = 2.575e8
    assert float(pbush[32:40].replace("+", "E+")) == pytest.approx(2.575e8, rel=1e-3)
    b_line = lines[1]
    assert b_line[8:16] == "B       " and float(b_line[24:32].replace("+", "E+")) == pytest.approx(687.5, rel=1e-3)
    cbush = lines[2]
    assert cbush[:8] == "CBUSH   " and int(cbush[24:32]) == 10001 and int(cbush[32:40]) == 20001
    assert all(len(line) <= 80 for line in lines)


def test_ansys_and_abaqus_values():
    els = joint_elements([RESULT])
    ansys = to_ansys(els)
    assert "ET,1,COMBIN14" in ansys and "KEYOPT,2,2,2" in ansys
    assert f"R,30001,{1.03e9 / 4:.6e},{2750.0 / 4:.6e}" in ansys
    abaqus = to_abaqus(els)
    assert "*SPRING, ELSET=GF_K30001\n2, 2\n2.575000e+08" in abaqus
    assert "*DASHPOT, ELSET=GF_C30005\n1, 1\n3.886250e+02" in abaqus


def test_cli_export_two_carriages(results_file, tmp_path):
    out = tmp_path / "joints.bdf"
    result = CliRunner().invoke(main, ["export", str(results_file), "--format", "nastran", "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert out.read_text().count("CBUSH") == 24
    js = CliRunner().invoke(main, ["export", str(results_file)])
    assert len(json.loads(js.output)) == 24


def test_missing_parameter_is_bad_input(tmp_path):
    bad = json.loads(json.dumps(RESULT))
    bad["parameters"]["K_H"]["value"] = None
    path = tmp_path / "r.json"
    path.write_text(json.dumps(bad))
    with pytest.raises(RecordingError, match="K_H' was not identified"):
        joint_elements(read_results(path), where=str(path))
    result = CliRunner().invoke(main, ["export", str(path)])
    assert result.exit_code == 2 and "K_H" in result.output


def test_not_json(tmp_path):
    path = tmp_path / "r.json"
    path.write_text("{nope\n")
    with pytest.raises(RecordingError, match="line 1: not JSON"):
        read_results(path)
