"""guidefit correlate: Table 3 (Eq. 34 error, MAC) from FE and test files, pairing, checks, bad input."""

import json
import shutil
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from guidefit.cli import main
from guidefit.io.fe_results import FEModes, read_f06, read_fe
from guidefit.machine.correlate import correlate, eq34_error_pct, mac
from guidefit.model import vibration as vib
from guidefit.model.guides import load_guide

GUIDE = load_guide("MRB35")
POINTS = {"A": (0.03, 0.0, 0.045), "B": (-0.03, 0.0, 0.045), "C": (-0.03, 0.0, -0.045), "D": (0.03, 0.0, -0.045),
          "E": (0.0, -0.02, 0.0)}


def _model_modes():
    sol = vib.solve_modes(vib.model_from_guide(GUIDE))
    shapes = {p: (vib.rigid_body_map(x) @ sol.shapes[:5]).T for p, x in POINTS.items()}
    return sol.frequencies_hz, shapes, sol.labels


def _csv(path, freqs, shapes, names=None, labels=None):
    names = names or {p: p for p in shapes}
    cols = ["frequency_hz"] + (["label"] if labels else []) + [f"{names[p]}:{a}" for p in shapes for a in "xyz"]
    rows = []
    for k, f in enumerate(freqs):
        row = [repr(float(f))] + ([labels[k]] if labels else [])
        row += [repr(float(shapes[p][k, i])) for p in shapes for i in range(3)]
        rows.append(",".join(row))
    path.write_text(",".join(cols) + "\n" + "\n".join(rows) + "\n")
    return path


def _invoke(*args):
    return CliRunner().invoke(main, ["correlate", *map(str, args)])


def test_eq34_and_mac():
    assert eq34_error_pct(1014.0, 1000.0) == pytest.approx(1.4)
    assert eq34_error_pct(853.0, 1000.0) == pytest.approx(-14.7)
    assert mac(np.array([1.0, 2.0, 0.0]), np.array([-2.0, -4.0, 0.0])) == pytest.approx(1.0)
    assert mac(np.array([1.0, 0.0]), np.array([0.0, 1.0])) == pytest.approx(0.0)


def test_mac_pairs_shuffled_modes_through_a_point_map(tmp_path):
    """Test modes in another order and under other point names: MAC pairs each with its FE mode."""
    freqs, shapes, labels = _model_modes()
    fe = _csv(tmp_path / "fe.csv", freqs, shapes)
    order = [3, 0, 4, 1, 2]
    rng = np.random.default_rng(1)
    test_shapes = {p: -2.0 * s[order] + 1e-4 * rng.standard_normal(s[order].shape) for p, s in shapes.items()}
    test_f = freqs[order] * 0.98
    names = {p: f"acc{p}" for p in shapes}
    test = _csv(tmp_path / "test.csv", test_f, test_shapes, names, [labels[k] for k in order])
    pmap = tmp_path / "map.txt"
    pmap.write_text("# test = fe\n" + "".join(f"acc{p} = {p}\n" for p in shapes))
    out = _invoke(fe, test, "--point-map", pmap, "--json", "--check", "max_error_pct=2.5,min_mac=0.99")
    assert out.exit_code == 0, out.output
    doc = json.loads(out.output)
    assert doc["paired_by"] == "mac"
    for row in doc["modes"]:
        assert row["fe_mode"] == order[row["test_mode"] - 1] + 1
        assert row["error_pct"] == pytest.approx(100 * (1 / 0.98 - 1), rel=1e-9)
        assert row["mac"] > 0.999


def test_without_shapes_pairs_by_order_with_a_warning(tmp_path):
    fe = tmp_path / "fe.csv"
    fe.write_text("frequency_hz\n1014\n2100\n")
    test = tmp_path / "test.csv"
    test.write_text("frequency_hz\n1000\n2000\n")
    out = _invoke(fe, test)
    assert out.exit_code == 0
    assert "paired by order" in out.output and "+1.40" in out.output and "+5.00" in out.output
    out = _invoke(fe, test, "--check", "max_error_pct=3")
    assert out.exit_code == 1 and "test mode 2" in out.output


def test_a_test_that_missed_a_mode_pairs_the_rest_with_their_own_fe_modes(tmp_path):
    """FE yaw, pitch, roll_low, vertical, roll_high; the test found no pitch (no shapes on the FE side).
    Was: lowest with lowest, roll_low (2497 Hz) with the FE pitch (2276 Hz), -8.84 %, exit 0."""
    fe = tmp_path / "fe.csv"
    fe.write_text("frequency_hz\n1879.1\n2275.9\n2496.5\n3529.0\n5563.6\n")
    test = tmp_path / "test.csv"
    test.write_text("frequency_hz\n1879.0\n2496.6\n3529.1\n5563.5\n")
    out = _invoke(fe, test, "--json", "--check", "max_error_pct=0.1")
    assert out.exit_code == 0, out.output
    rows = json.loads(out.stdout)["modes"]
    assert [r["fe_mode"] for r in rows] == [1, 3, 4, 5]
    assert max(abs(r["error_pct"]) for r in rows) < 0.01


def test_nastran_f06_eigenvalue_table(tmp_path):
    f06 = tmp_path / "run.f06"
    f06.write_text("""1    MSC.NASTRAN JOB                                                   PAGE    12
                                              R E A L   E I G E N V A L U E S
   MODE    EXTRACTION      EIGENVALUE            RADIANS             CYCLES            GENERALIZED         GENERALIZED
    NO.       ORDER                                                                       MASS              STIFFNESS
        1         1        3.947842E+07        6.283185E+03        1.000000E+03        1.000000E+00        3.947842E+07
        2         2        1.579137E+08        1.256637E+04        2.000000E+03        1.000000E+00        1.579137E+08
1    MSC.NASTRAN JOB                                                   PAGE    13
""")
    modes = read_f06(f06)
    assert np.allclose(modes.frequencies_hz, [1000.0, 2000.0])
    test = tmp_path / "t.csv"
    test.write_text("frequency_hz\n990\n2010\n")
    assert _invoke(f06, test).exit_code == 0


def test_guidefit_json_and_uff55_test_sides(tmp_path):
    pyuff = pytest.importorskip("pyuff")
    freqs, shapes, labels = _model_modes()
    fe = _csv(tmp_path / "fe.csv", freqs, shapes)
    doc = {"file": "machine.h5", "modes": [
        {"label": labels[k], "frequency_hz": float(freqs[k]) * 1.01,
         "shape": {f"acc_{p}_{a}": float(shapes[p][k, i]) for p in "ABCD" for i, a in enumerate("xy")}}
        for k in range(5)]}
    js = tmp_path / "results.json"
    js.write_text(json.dumps(doc))
    out = _invoke(fe, js, "--json")
    assert out.exit_code == 0, out.output
    rows = json.loads(out.output)["modes"]
    assert [r["fe_mode"] for r in rows] == [1, 2, 3, 4, 5] and min(r["mac"] for r in rows) > 0.999
    uff = tmp_path / "modes.uff"
    nodes = {p: k + 1 for k, p in enumerate(POINTS)}
    writer = pyuff.UFF(str(uff))
    for k in range(5):
        writer.write_sets(pyuff.prepare_55(
            model_type=1, analysis_type=2, data_ch=2, spec_data_type=8, data_type=2, n_data_per_node=3,
            r1=np.array([shapes[p][k, 0] for p in POINTS]), r2=np.array([shapes[p][k, 1] for p in POINTS]),
            r3=np.array([shapes[p][k, 2] for p in POINTS]), load_case=1, mode_n=k + 1, freq=float(freqs[k]) * 0.97,
            modal_m=1.0, modal_damp_vis=0.0, modal_damp_his=0.0, node_nums=np.array(list(nodes.values())),
            ), mode="add" if k else "overwrite")
    pmap = tmp_path / "map.txt"
    pmap.write_text("".join(f"{n} = {p}\n" for p, n in nodes.items()))
    out = _invoke(fe, uff, "--point-map", pmap, "--json")
    assert out.exit_code == 0, out.output
    rows = json.loads(out.output)["modes"]
    assert [r["fe_mode"] for r in rows] == [1, 2, 3, 4, 5]
    assert all(r["error_pct"] == pytest.approx(100 * (1 / 0.97 - 1), abs=0.01) for r in rows)  # UFF: 6 digits


def test_plot_is_written(tmp_path):
    freqs, shapes, _ = _model_modes()
    fe = _csv(tmp_path / "fe.csv", freqs, shapes)
    test = _csv(tmp_path / "test.csv", freqs * 1.03, shapes)
    plot = tmp_path / "mac.png"
    assert _invoke(fe, test, "--plot", plot).exit_code == 0
    assert plot.read_bytes()[:4] == b"\x89PNG"


@pytest.mark.parametrize("fe_text,test_text,args,message", [
    ("frequency_hz\n1000\n", "frequency_hz\n1000\n", ["--check", "max_err=5"], "--check"),
    ("freq\n1000\n", "frequency_hz\n1000\n", [], "frequency_hz"),
    ("frequency_hz\n1000\n", "frequency_hz\n1000\n2000\n", [], "compute more FE modes"),
    ("frequency_hz\n-5\n", "frequency_hz\n1000\n", [], "positive"),
])
def test_bad_input_is_one_line_exit_2(tmp_path, fe_text, test_text, args, message):
    fe, test = tmp_path / "fe.csv", tmp_path / "test.csv"
    fe.write_text(fe_text)
    test.write_text(test_text)
    out = _invoke(fe, test, *args)
    assert out.exit_code == 2 and message in out.output
    assert len(out.output.strip().splitlines()) == 1


def test_unknown_suffix_and_a_dat_without_eigenvalues(tmp_path):
    test = tmp_path / "test.csv"
    test.write_text("frequency_hz\n1000\n")
    bad = tmp_path / "model.bdf"
    bad.write_text("x")
    assert _invoke(bad, test).exit_code == 2
    dat = tmp_path / "static.dat"
    dat.write_text("\n displacements (vx,vy,vz) for set N and time  0.1E+01\n\n 1 0. 0. 0.\n")
    out = _invoke(dat, test)
    assert out.exit_code == 2 and "E I G E N V A L U E" in out.output


def test_hundred_modes_under_a_second():
    rng = np.random.default_rng(0)
    n = 100
    shapes = {f"P{k}": rng.standard_normal((n, 3)) for k in range(40)}
    fe = FEModes(np.sort(rng.uniform(10, 5000, n)), shapes)
    perm = rng.permutation(n)
    test = FEModes(fe.frequencies_hz[perm] * 1.01, {p: s[perm] for p, s in shapes.items()})
    start = time.perf_counter()
    result = correlate(fe, test)
    assert time.perf_counter() - start < 1.0
    assert all(r["fe_mode"] == perm[r["test_mode"] - 1] + 1 for r in result.rows)


@pytest.mark.skipif(shutil.which("ccx") is None, reason="CalculiX ccx not installed (apt-get install calculix-ccx)")
def test_ccx_dat_against_the_model_it_came_from(tmp_path):
    """The reference deck's .dat (frequencies and shapes at its mass nodes) against guidefit's model: MAC 1, 0 %."""
    results = tmp_path / "r.json"
    results.write_text(json.dumps({"file": "c.h5", "guide": "MRB35", "parameters": {
        "K_V": {"value": 1.03e9}, "c_V": {"value": 2750.0}, "K_H": {"value": 1.0e8}, "c_H": {"value": 3109.0}},
        "modes": [{"label": "vertical", "frequency_hz": 3450.0, "damping_ratio": 0.03}]}))
    explain = tmp_path / "e.json"
    explain.write_text(json.dumps({"file": "c.h5", "verdict": "adequate", "guide": "MRB35", "effects": []}))
    out = CliRunner().invoke(main, ["export", str(results), "--explain", str(explain), "--format", "calculix",
                                    "--assembly", "reference", "-o", str(tmp_path / "deck.inp")])
    assert out.exit_code == 0, out.output
    subprocess.run([shutil.which("ccx"), "-i", "deck"], cwd=tmp_path, capture_output=True, check=False, timeout=120)
    from guidefit.export.reference import mass_points

    sol = vib.solve_modes(vib.model_from_guide(GUIDE))
    pts = {str(10051 + k): p for k, (_, p) in enumerate(mass_points(GUIDE), start=1)}
    shapes = {n: (vib.rigid_body_map(p) @ sol.shapes[:5]).T for n, p in pts.items()}
    test = _csv(tmp_path / "test.csv", sol.frequencies_hz, shapes)
    out = _invoke(tmp_path / "deck.dat", test, "--json", "--check", "max_error_pct=0.01,min_mac=0.9999")
    assert out.exit_code == 0, out.output
    assert json.loads(out.output)["paired_by"] == "mac"


_FRD = """    1C
    2C                             2                                     1
 -1       101 0.00000E+00 5.00000E-02 0.00000E+00
 -1        25 1.00000E-01 5.00000E-02 0.00000E+00
 -3
    1PSTEP                         1           1           1
  100CL  101 124.0903727           2                     2    1MODAL      1
 -4  DISP        4    1
 -5  D1          1    2    1    0
 -5  D2          1    2    2    0
 -5  D3          1    2    3    0
 -5  ALL         1    2    0    0    1ALL
 -1       101 2.15125E-03-4.41551E-05-6.19797E-02
 -1        25 1.85608E-06-3.54146E-08 3.53801E-05
 -3
    1PSTEP                         2           1           1
  100CL  102 1032.531148           2                     2    2MODAL      1
 -4  DISP        4    1
 -5  D1          1    2    1    0
 -5  D2          1    2    2    0
 -5  D3          1    2    3    0
 -5  ALL         1    2    0    0    1ALL
 -1       101-1.05617E-04-1.22313E-04-6.18317E-02
 -1        25 3.70844E-06-7.03724E-08 4.75377E-06
 -3
    1PSTEP                         3           0           2
  100CL  106 11.12725674           2                     1    6           1
 -4  DISP        4    1
 -5  D1          1    2    1    0
 -5  D2          1    2    2    0
 -5  D3          1    2    3    0
 -5  ALL         1    2    0    0    1ALL
 -1       101 1.00000E+00 1.00000E+00 1.00000E+00
 -1        25 1.00000E+00 1.00000E+00 1.00000E+00
 -3
 9999
"""


def test_ccx_frd_fixed_columns_and_only_the_frequency_step(tmp_path):
    """Touching numbers are split by column; the later (steady-state, ictype 1) step's blocks are no modes."""
    frd = tmp_path / "job.frd"
    frd.write_text(_FRD)
    modes = read_fe(frd)
    assert np.allclose(modes.frequencies_hz, [124.0903727, 1032.531148], rtol=1e-12)
    assert sorted(modes.shapes) == ["101", "25"]
    assert np.allclose(modes.shapes["101"][0], [2.15125e-3, -4.41551e-5, -6.19797e-2], rtol=1e-12)
    assert np.allclose(modes.shapes["25"][1], [3.70844e-6, -7.03724e-8, 4.75377e-6], rtol=1e-12)


def test_ccx_frd_without_mode_shapes_is_one_line_exit_2(tmp_path):
    frd = tmp_path / "static.frd"
    frd.write_text(_FRD.split("    1PSTEP")[0] + " 9999\n")
    test = tmp_path / "test.csv"
    test.write_text("frequency_hz\n1000\n")
    out = _invoke(frd, test)
    assert out.exit_code == 2 and "*NODE FILE" in out.output
    assert len(out.output.strip().splitlines()) == 1


@pytest.mark.skipif(shutil.which("ccx") is None, reason="CalculiX ccx not installed (apt-get install calculix-ccx)")
def test_ccx_frd_equals_the_dat_of_the_same_run(tmp_path):
    """The machine example with *NODE FILE: the .frd's modes are the .dat's (frequencies, MAC 1 pairwise)."""
    example = Path(__file__).resolve().parent.parent / "examples" / "machine"
    shutil.copy(example / "joints.inp", tmp_path / "joints.inp")
    deck = (example / "machine.inp").read_text()
    assert "*NODE PRINT,NSET=MEASURED" in deck
    deck = deck.replace("*NODE PRINT,NSET=MEASURED", "*NODE FILE,OUTPUT=2D,NSET=MEASURED\nU\n*NODE PRINT,NSET=MEASURED")
    (tmp_path / "machine.inp").write_text(deck)
    subprocess.run([shutil.which("ccx"), "-i", "machine"], cwd=tmp_path, capture_output=True, check=False,
                   timeout=120)
    frd, dat = read_fe(tmp_path / "machine.frd"), read_fe(tmp_path / "machine.dat")
    assert len(frd) == len(dat) == 12
    assert np.allclose(frd.frequencies_hz, dat.frequencies_hz, rtol=1e-6)  # the .dat prints 7 digits
    assert sorted(frd.shapes) == sorted(dat.shapes) and len(frd.shapes) == 16
    result = correlate(frd, dat)  # the .dat as the "test" side: the same modes at the same nodes
    assert result.paired_by == "mac"
    assert [r["fe_mode"] for r in result.rows] == list(range(1, 13))
    assert max(abs(r["error_pct"]) for r in result.rows) < 1e-4
    assert min(r["mac"] for r in result.rows) > 0.99999


@pytest.fixture(scope="module")
def frf_uff(tmp_path_factory):
    """FRFs (UFF-58) of a simulated MRB35 recording, two references (vertical and lateral hits)."""
    where = tmp_path_factory.mktemp("frf")
    rec, uff = where / "r.h5", where / "r.uff"
    out = CliRunner().invoke(main, ["simulate", "--guide", "MRB35", "--out", str(rec), "--hits", "4"])
    assert out.exit_code == 0, out.output
    out = CliRunner().invoke(main, ["frf", str(rec), "--out", str(uff)])
    assert out.exit_code == 0, out.output
    return uff


def test_uff58_frfs_fitted_by_the_global_estimator_pair_by_mac(tmp_path, frf_uff):
    """The model's modes (shuffled, under other point names) against FRFs simulated from it: MAC pairs, ~0 %."""
    freqs, shapes, labels = _model_modes()
    order = [2, 4, 0, 3, 1]
    names = {p: f"n{k}" for k, p in enumerate(shapes)}
    fe = _csv(tmp_path / "fe.csv", freqs[order], {p: s[order] for p, s in shapes.items()}, names,
              [labels[k] for k in order])
    pmap = tmp_path / "map.txt"
    pmap.write_text("".join(f"{p} = {n}\n" for p, n in names.items()))
    out = _invoke(fe, frf_uff, "--point-map", pmap, "--json", "--check", "max_error_pct=0.05,min_mac=0.99")
    assert out.exit_code == 0, out.output
    doc = json.loads(out.stdout)
    assert doc["paired_by"] == "mac" and set(doc["common_points"]) == set("ABCD")
    assert len(doc["modes"]) == 5
    for row, k in zip(doc["modes"], range(5)):  # test modes in frequency order: model mode k is FE row order.index(k)
        assert row["fe_mode"] == order.index(k) + 1
        assert row["test_hz"] == pytest.approx(freqs[k], rel=1e-4)
        assert abs(row["error_pct"]) < 0.05 and row["mac"] > 0.99
    # one axis per reference (y in the vertical run, x in the lateral one): the rolls and the lateral motion look
    # alike at four x DOFs; the pairing says so and falls back on frequency among them
    assert any("alike" in w for w in doc["warnings"])


def test_uff58_frfs_against_frequencies_only_pair_by_order(tmp_path, frf_uff):
    """A CSV of the model frequencies alone: pairing by order, with the warning; a wrong model shows its error."""
    freqs, _, _ = _model_modes()
    fe = tmp_path / "fe.csv"
    fe.write_text("frequency_hz\n" + "".join(f"{1.05 * float(f)!r}\n" for f in freqs))
    out = _invoke(fe, frf_uff, "--json")
    assert out.exit_code == 0, out.output
    doc = json.loads(out.stdout)
    assert doc["paired_by"] == "order" and "no shapes on the FE side" in doc["warnings"][0]
    assert [r["fe_mode"] for r in doc["modes"]] == [1, 2, 3, 4, 5]
    assert all(r["error_pct"] == pytest.approx(5.0, abs=0.05) for r in doc["modes"])
    out = _invoke(fe, frf_uff, "--band", "8000,100")
    assert out.exit_code == 2 and "--band" in out.output and len(out.output.strip().splitlines()) == 1


def test_uff58_frfs_that_end_below_the_fe_modes_are_one_line_exit_2(tmp_path, frf_uff):
    fe = tmp_path / "fe.csv"
    fe.write_text("frequency_hz\n200000\n300000\n")
    out = _invoke(fe, frf_uff)
    assert out.exit_code == 2 and "--band" in out.output and len(out.output.strip().splitlines()) == 1


@pytest.fixture(scope="module")
def frf_both(tmp_path_factory):
    """FRFs of a recording with x and y at A-D in both runs (UFF-58 and guidefit's frf.h5): references linked."""
    where = tmp_path_factory.mktemp("frfboth")
    rec = where / "r.h5"
    out = CliRunner().invoke(main, ["simulate", "--guide", "MRB35", "--out", str(rec), "--hits", "4",
                                    "--sensors", "both"])
    assert out.exit_code == 0, out.output
    for name in ("r.uff", "frf.h5"):
        out = CliRunner().invoke(main, ["frf", str(rec), "--out", str(where / name)])
        assert out.exit_code == 0, out.output
    return where / "r.uff", where / "frf.h5"


@pytest.mark.parametrize("which", [0, 1])
def test_frfs_of_references_sharing_sensors_give_whole_shapes(tmp_path, frf_both, which):
    """Two references measured at the same 8 DOFs: one rank-one shape per mode, MAC 1 to its own model mode only."""
    freqs, shapes, _ = _model_modes()
    order = [4, 3, 2, 1, 0]
    fe = _csv(tmp_path / "fe.csv", freqs[order], {p: s[order] for p, s in shapes.items()})
    out = _invoke(fe, frf_both[which], "--json", "--check", "max_error_pct=0.01,min_mac=0.999")
    assert out.exit_code == 0, out.output
    doc = json.loads(out.stdout)
    assert doc["paired_by"] == "mac" and doc["warnings"] == []
    assert [r["fe_mode"] for r in doc["modes"]] == [order.index(k) + 1 for k in range(5)]
    mac_matrix = np.array(doc["mac_matrix"])  # FE x test: off the pairs below 0.02
    paired = np.zeros_like(mac_matrix, dtype=bool)
    paired[[r["fe_mode"] - 1 for r in doc["modes"]], [r["test_mode"] - 1 for r in doc["modes"]]] = True
    assert mac_matrix[~paired].max() < 0.02


def test_json_shapes_are_read_along_each_sensor_direction(tmp_path):
    """A side-face sensor acc_G_x declared along -x: its modal constant was put on +x (a per-DOF sign
    error that spoils the MAC); now read along -x. An oblique sensor is left out."""
    from guidefit.machine.correlate import read_test_json

    result = {"file": "r.h5", "modes": [{"label": "roll_low", "frequency_hz": 2496.5,
                                         "shape": {"acc_E_x": 0.3, "acc_G_x": -0.3, "acc_K_x": 0.2}}],
              "sensors": [{"name": "acc_E_x", "position_m": [0.05, -0.015, 0.04], "direction": [1, 0, 0]},
                          {"name": "acc_G_x", "position_m": [-0.05, -0.015, 0.04], "direction": [-1, 0, 0]},
                          {"name": "acc_K_x", "position_m": [0.05, 0, 0], "direction": [1, 1, 0]}]}
    path = tmp_path / "r.json"
    path.write_text(json.dumps(result))
    test = read_test_json(path)
    assert test.shapes["E"][0, 0] == pytest.approx(0.3) and test.shapes["G"][0, 0] == pytest.approx(0.3)
    assert "K" not in test.shapes
