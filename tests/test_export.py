"""Export of joints to FEM decks: explained vs apparent values, full matrices, units, axes, ids, safety.

Decks are read back with pyNastran (Nastran) and with small parsers of the
ANSYS and Abaqus cards written here; every number is compared with the
joint it came from.
"""

import json
import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from guidefit.cli import main
from guidefit.export import (
    apparent_joint,
    build_elements,
    explained_joint,
    parse_axis_map,
    read_results,
    to_nastran,
)
from guidefit.export.core import _nastran_float, _nastran_real
from guidefit.model import vibration as vib
from guidefit.model.guides import load_guide

ROOT = Path(__file__).resolve().parents[1]
PAPER_LIKE = ROOT / "sample_data" / "mrb35_paper_like.h5"
RESULT = {"file": "carriage1.h5", "guide": "MRB35", "parameters": {
    "K_V": {"value": 1.03e9, "unit": "N/m"}, "c_V": {"value": 2750.0, "unit": "N*s/m"},
    "K_H": {"value": 1.00e8, "unit": "N/m"}, "c_H": {"value": 3109.0, "unit": "N*s/m"}},
    "modes": [{"label": "vertical", "frequency_hz": 3450.0, "damping_ratio": 0.0288},
              {"label": "roll_low", "frequency_hz": 1075.0, "damping_ratio": 0.105}]}
ADEQUATE = {"file": "carriage1.h5", "verdict": "adequate", "guide": "MRB35", "effects": []}


def _nominal_k6():
    k5 = vib.carriage_stiffness_matrix(vib.model_from_guide(load_guide("MRB35")).rollers)
    k6 = np.zeros((6, 6))
    idx = np.array([0, 1, 3, 4, 5])
    k6[np.ix_(idx, idx)] = k5
    return k6


def _run(*args):
    result = CliRunner().invoke(main, ["export", *map(str, args)])
    return result.exit_code, result.output


def _write(tmp_path, name, docs):
    path = tmp_path / name
    path.write_text("".join(json.dumps(d) + "\n" for d in docs))
    return path


@pytest.fixture
def results_file(tmp_path):
    second = json.loads(json.dumps(RESULT))
    second["file"] = "carriage2.h5"
    return _write(tmp_path, "results.jsonl", [RESULT, second])


def _pynastran():
    """pyNastran's BDF class, or a skip (not installed, or an install that cannot import with this numpy)."""
    try:
        from pyNastran.bdf.bdf import BDF
    except Exception as exc:  # noqa: BLE001 - pyNastran 1.4 fails with AttributeError on numpy >= 2.4
        pytest.skip(f"pyNastran not usable: {type(exc).__name__}: {exc}")
    return BDF


def _bdf(text, tmp_path):
    BDF = _pynastran()

    path = tmp_path / "deck.bdf"
    path.write_text(text)
    model = BDF(debug=None)
    model.read_bdf(str(path), punch=True, xref=False)
    return model


def _dmig_matrix(dmig, dofs):
    """The full symmetric matrix of a pyNastran DMIG over the given (grid, component) order."""
    index = {tuple(int(v) for v in d): k for k, d in enumerate(dofs)}
    out = np.zeros((len(dofs), len(dofs)))
    for gj, gi, value in zip(dmig.GCj, dmig.GCi, dmig.Real):
        a, b = index[tuple(int(v) for v in gi)], index[tuple(int(v) for v in gj)]
        out[a, b] = out[b, a] = value
    return out


def _rel(a, b):
    """Largest error relative to each entry's matrix scale sqrt(|A_ii A_jj|) (diagonal: to itself)."""
    d = np.sqrt(np.abs(np.diag(b)))
    scale = np.maximum(np.outer(d, d), 1e-300)
    return float(np.max(np.abs(a - b) / scale))


# --------------------------------------------------------------------------- joints


def test_apparent_springs_sum_to_the_identified_joint():
    joint = apparent_joint(RESULT)
    els = build_elements([joint], "springs")
    vertical = [e for e in els if e.dof == 2]
    horizontal = [e for e in els if e.dof == 1]
    assert len(vertical) == 4 and len(horizontal) == 8
    assert sum(e.stiffness[1, 1] for e in vertical) == pytest.approx(1.03e9, rel=1e-12)
    assert sum(e.damping[0, 0] for e in horizontal) == pytest.approx(3109.0, rel=1e-12)


def test_explained_joint_is_the_roller_matrix_not_the_apparent_value():
    """explain says 'adequate': the joint is the nominal rollers' matrix, K_xx 1.08e9, not K_H = 1.0e8."""
    joint = explained_joint(RESULT, ADEQUATE)
    assert _rel(joint.stiffness, _nominal_k6()) < 1e-12
    guide = load_guide("MRB35")
    kn, z, b = guide.roller_stiffness_n_per_m, guide.rollers_per_row, guide.contact_angle_rad
    assert joint.stiffness[0, 0] == pytest.approx(4 * z * kn * math.cos(b) ** 2, rel=1e-9)
    assert joint.apparent["K_H"] == 1.0e8 and joint.stiffness[0, 0] > 10 * joint.apparent["K_H"]
    assert np.allclose(joint.stiffness, joint.stiffness.T) and np.all(joint.stiffness[2] == 0)
    # damping: for the uncoupled vertical mode the modal damping matrix is Eq. (27) at the rig-free f_V
    f_v = joint.explained["f_V"]
    assert joint.damping[1, 1] == pytest.approx(4 * math.pi * guide.mass_kg * f_v * 0.0288, rel=1e-9)
    assert any("pitch" in n for n in joint.notes)  # unmeasured modes' damping is said


def test_explained_joint_keeps_contact_effects_and_drops_the_rig():
    explanation = {"verdict": "explained", "guide": "MRB35", "effects": [
        {"name": "contact_stiffness", "parameters": {"factor": {"value": 0.81, "std": 0.01}}},
        {"name": "support_compliance", "variant": "lateral",
         "parameters": {"lateral_n_per_m": {"value": 1.2e8, "std": 1e6}}},
        {"name": "added_mass", "parameters": {"mass_kg": {"value": 0.1}, "at": {"value": "ABCD"}}}]}
    joint = explained_joint(RESULT, explanation)
    assert _rel(joint.stiffness, 0.81 * _nominal_k6()) < 1e-12
    assert [r.split(" ")[0] for r in joint.removed] == ["support_compliance", "added_mass"]
    assert joint.kept[0].startswith("contact_stiffness")


def test_damping_comes_from_the_mode_not_from_a_force_level_entry():
    level = {"label": "vertical", "frequency_hz": 3440.0, "damping_ratio": 0.09, "level": "F3"}
    result = dict(RESULT, modes=[level, *RESULT["modes"]])
    assert explained_joint(result, ADEQUATE).damping[1, 1] == pytest.approx(
        explained_joint(RESULT, ADEQUATE).damping[1, 1], rel=1e-12)


def test_damping_of_a_mode_labelled_by_an_alias_is_its_own():
    """'Vertical' (an alias explain reads as vertical) was 'not measured': the mean ratio replaced it."""
    result = json.loads(json.dumps(RESULT))
    result["modes"][0]["label"] = "Vertical"
    assert explained_joint(result, ADEQUATE).damping[1, 1] == pytest.approx(
        explained_joint(RESULT, ADEQUATE).damping[1, 1], rel=1e-12)


def test_paper_like_recording_exports_the_contact_stiffness(tmp_path):
    """The paper's case end to end: identify + explain (soft lateral support, sensor mass) -> joint without them."""
    from guidefit.explain import explain
    from guidefit.identify import identify

    ident = identify(PAPER_LIKE)
    results = _write(tmp_path, "r.jsonl", [ident.to_dict()])
    expl = _write(tmp_path, "e.json", [explain(ident).to_dict()])
    code, out = _run(results, "--explain", expl, "--format", "json")
    assert code == 0, out
    doc = json.loads(out)
    joint = doc["joints"][0]
    assert joint["apparent_eq24_29_si"]["K_H_n_per_m"] == pytest.approx(1.0e8, rel=0.02)
    assert {r.split(" ")[0] for r in joint["explained_joint_si"]["rig_effects_removed"]} == {
        "support_compliance", "added_mass"}
    assert _rel(np.array(joint["stiffness_si_model_axes"]), _nominal_k6()) < 1e-3  # truth: nominal contacts
    assert np.array(doc["elements"][0]["stiffness"])[0, 0] == pytest.approx(1.0817e9, rel=1e-3)


def test_unexplained_is_refused_with_one_line(tmp_path):
    results = _write(tmp_path, "r.jsonl", [RESULT])
    expl = _write(tmp_path, "e.json", [{"file": "carriage1.h5", "verdict": "unexplained", "effects": []}])
    code, out = _run(results, "--explain", expl)
    assert code == 1 and "--joint apparent" in out and len(out.strip().splitlines()) == 1
    code, out = _run(results, "--joint", "apparent")
    assert code == 0


def test_a_given_explanation_is_used_or_refused_never_dropped(tmp_path):
    """identify ran on /data/carriage1.h5, explain on carriage1.h5: the same test; an explanation of
    another test is an error. Before: neither matched, the given 'unexplained' was dropped, exit 0."""
    results = _write(tmp_path, "r.jsonl", [dict(RESULT, file="/data/carriage1.h5")])
    expl = _write(tmp_path, "e.json", [{"file": "carriage1.h5", "verdict": "unexplained", "effects": []}])
    code, out = _run(results, "--explain", expl)
    assert code == 1 and "unexplained" in out
    other = _write(tmp_path, "o.json", [dict(ADEQUATE, file="carriage2.h5")])
    code, out = _run(results, "--explain", other)
    assert code == 2 and "matches no result" in out and len(out.strip().splitlines()) == 1
    modes = _write(tmp_path, "m.json", [dict(ADEQUATE, file=str(results))])  # explain --modes r.jsonl
    code, out = _run(results, "--explain", modes)
    assert code == 0, out


def test_a_carriage_identify_failed_on_is_not_dropped_in_silence(tmp_path):
    """identify a.h5 broken.h5 --json: the second line holds 'error'. Was: skipped, one joint, exit 0;
    now the deck of the others is written, a line names the one left out, exit 1."""
    failed = {"file": "broken.h5", "guide": None, "modes": [], "error": "broken.h5: truncated HDF5 file",
              "exit_code": 2}
    result = CliRunner().invoke(main, ["export", str(_write(tmp_path, "r.jsonl", [RESULT, failed])),
                                       "--joint", "apparent", "-o", str(tmp_path / "j.json")])
    assert result.exit_code == 1 and "entry 2 (broken.h5)" in result.stderr and "truncated" in result.stderr
    assert len(json.loads((tmp_path / "j.json").read_text())["joints"]) == 1  # the identified carriage
    # node ids given per results line keep their carriages (was: '2 ids for 1 carriage', exit 2)
    result = CliRunner().invoke(main, ["export", str(tmp_path / "r.jsonl"), "--joint", "apparent",
                                       "--carriage-node", "11,12", "--rail-node", "21,22", "--format", "json"])
    assert result.exit_code == 1
    element = json.loads(result.stdout)["elements"][0]
    assert (element["carriage_node"], element["rail_node"]) == (11, 21)


def test_export_guide_is_the_guide_the_joint_is_explained_on(tmp_path):
    """export --guide X: the modes were explained on the result's guide (MRB35: contact_stiffness 0.8)
    and X's joint built with that factor (a ball guide's rollers x 0.8, 'explained', exit 0); now they
    are explained on X, as explain --modes --guide X does (nothing fits: exit 1), and an explanation
    of another guide is refused."""
    ball = ROOT / "examples" / "guides" / "ball4_size25.toml"
    sol = vib.solve_modes(vib.model_from_guide(load_guide("MRB35")))
    soft = json.loads(json.dumps(RESULT))
    soft["modes"] = [{"label": lab, "frequency_hz": f * math.sqrt(0.8), "frequency_std_hz": 0.1,
                      "damping_ratio": 0.03} for lab, f in zip(sol.labels, sol.frequencies_hz)]
    results = _write(tmp_path, "r.jsonl", [soft])
    code, out = _run(results, "--format", "json")
    assert code == 0 and "contact_stiffness (factor = 0.8" in out  # on its own guide
    code, out = _run(results, "--guide", ball)
    assert code == 1 and "unexplained" in out
    code, out = _run(results, "--guide", ball, "--explain", _write(tmp_path, "e.json", [ADEQUATE]))
    assert code == 2 and "fitted on guide 'MRB35'" in out


def test_a_parameter_in_another_unit_is_converted_or_refused(tmp_path):
    """K_H 'N/mm' was exported as if N/m (5.4e5 for 5.4e8, exit 0); now converted; an unknown unit: exit 2."""
    result = json.loads(json.dumps(RESULT))
    result["parameters"]["K_H"] = {"value": 1.0e5, "unit": "N/mm"}
    code, out = _run(_write(tmp_path, "r.jsonl", [result]), "--joint", "apparent")
    assert code == 0 and json.loads(out)["joints"][0]["apparent_eq24_29_si"]["K_H_n_per_m"] == pytest.approx(1e8)
    result["parameters"]["K_H"]["unit"] = "lbf/in"
    code, out = _run(_write(tmp_path, "r.jsonl", [result]), "--joint", "apparent")
    assert code == 2 and "lbf/in" in out and len(out.strip().splitlines()) == 1


def test_explain_reads_f_h_in_its_unit():
    """f_H completes a missing roll_low mode: 2.4965 kHz was read as 2.4965 Hz."""
    from guidefit.explain import modes_from_result

    modes, *_ = modes_from_result({"modes": [{"label": "vertical", "frequency_hz": 3529.0}],
                                   "parameters": {"f_H": {"value": 2.4965, "unit": "kHz", "std": 0.001}}})
    roll_low = next(m for m in modes if m.label == "roll_low")
    assert roll_low.frequency_hz == pytest.approx(2496.5) and roll_low.frequency_std_hz == pytest.approx(1.0)


# --------------------------------------------------------------------------- decks read back


@pytest.mark.parametrize("units", ["si", "mm-N-s", "mm-t-s"])
def test_nastran_dmig_round_trip_and_units(tmp_path, units):
    _pynastran()
    results = _write(tmp_path, "r.jsonl", [RESULT])
    expl = _write(tmp_path, "e.json", [ADEQUATE])
    code, out = _run(results, "--explain", expl, "--format", "nastran", "--units", units,
                     "--carriage-node", "501", "--rail-node", "502")
    assert code == 0, out
    model = _bdf(out, tmp_path)
    dofs = [(501, c) for c in range(1, 7)] + [(502, c) for c in range(1, 7)]
    k12 = _dmig_matrix(model.dmig["GFJK"], dofs)
    joint = explained_joint(RESULT, ADEQUATE)
    s = 1.0 if units == "si" else 1e3
    factor = np.array([1, 1, 1, s, s, s])[:, None] / np.array([s, s, s, 1, 1, 1])[None, :]
    k = joint.stiffness * factor
    assert _rel(k12[:6, :6], k) < 1e-12 and _rel(k12[6:, 6:], k) < 1e-12 and _rel(-k12[:6, 6:], k) < 1e-12
    if units != "si":  # N/mm, N mm/rad, N/rad: hand-checked factors
        assert k12[0, 0] == pytest.approx(joint.stiffness[0, 0] / 1e3, rel=1e-12)
        assert k12[5, 5] == pytest.approx(joint.stiffness[5, 5] * 1e3, rel=1e-12)
        assert k12[0, 5] == pytest.approx(joint.stiffness[0, 5], rel=1e-12)
    b12 = _dmig_matrix(model.dmig["GFJB"], dofs)
    assert _rel(b12[:6, :6], joint.damping * factor) < 1e-12


def test_nastran_cbush_full_precision_and_axis_map(tmp_path):
    _pynastran()
    joint = apparent_joint({"parameters": {"K_V": {"value": 2.7041234567891e8}, "K_H": {"value": 1.2345678901234e8},
                                           "c_V": {"value": 2750.123456789}, "c_H": {"value": 3109.98765432}}})
    rot = parse_axis_map("x=X,y=Z,z=-Y")
    els = build_elements([joint], "bush", axis_map=rot)
    text = to_nastran([joint], els, element="bush")
    assert "2.704+8" not in text
    prop = _bdf(text, tmp_path).properties[30001]
    # model vertical y -> machine Z (K3), lateral x -> machine X (K1)
    assert prop.Ki[2] == pytest.approx(2.7041234567891e8, rel=1e-12)
    assert prop.Ki[0] == pytest.approx(1.2345678901234e8, rel=1e-12)
    assert prop.Bi[2] == pytest.approx(2750.123456789, rel=1e-12)


def test_axis_map_rotates_the_full_matrix_and_rejects_mirrors():
    joint = explained_joint(RESULT, ADEQUATE)
    rot = parse_axis_map("x=Y,y=Z,z=X")
    k = build_elements([joint], "matrix", axis_map=rot)[0].stiffness
    t = np.zeros((6, 6))
    t[:3, :3] = t[3:, 3:] = rot
    assert _rel(k, t @ joint.stiffness @ t.T) < 1e-14
    assert k[2, 2] == pytest.approx(joint.stiffness[1, 1], rel=1e-14)  # vertical is machine Z
    assert k[1, 5] == pytest.approx(joint.stiffness[0, 4], rel=1e-14)  # u-phi coupling moved with its axes
    code, out = _run("nonexistent.json", "--axis-map", "x=X,y=Y,z=-Z")
    assert code == 2 and "mirror" in out


def test_nastran_real_fields_keep_13_digits():
    rng = np.random.default_rng(1)
    for x in np.concatenate([10 ** rng.uniform(-3, 13, 300), -(10 ** rng.uniform(-2, 13, 300))]):
        text = _nastran_real(x)
        assert len(text) == 16
        assert abs(_nastran_float(text) - x) <= 1e-12 * abs(x), text
    def worst(lo, hi):
        return max(abs(_nastran_float(_nastran_real(-x)) + x) / x for x in 10 ** rng.uniform(lo, hi, 300))

    assert worst(-9, -3) <= 5e-12 and worst(-99, -9) <= 5e-11  # negative and tiny: 12, then 11 digits (documented)


def test_ansys_matrix27_and_abaqus_connector_round_trip(tmp_path):
    results = _write(tmp_path, "r.jsonl", [RESULT])
    expl = _write(tmp_path, "e.json", [ADEQUATE])
    joint = explained_joint(RESULT, ADEQUATE)
    code, ansys = _run(results, "--explain", expl, "--format", "ansys")
    assert code == 0, ansys
    consts, current = {}, None
    for line in ansys.splitlines():
        if line.startswith("R,"):
            parts = line.split(",")
            current = int(parts[1])
            consts[current] = [float(v) for v in parts[2:]]
        elif line.startswith("RMORE,"):
            consts[current] += [float(v) for v in line.split(",")[1:]]
    assert sorted(consts) == [30001, 30002] and all(len(v) == 78 for v in consts.values())
    upper = iter(consts[30001])
    k12 = np.zeros((12, 12))
    for r in range(12):
        for c in range(r, 12):
            k12[r, c] = k12[c, r] = next(upper)
    assert _rel(k12[:6, :6], joint.stiffness) < 1e-15 and _rel(-k12[6:, :6], joint.stiffness) < 1e-15
    code, abaqus = _run(results, "--explain", expl, "--format", "abaqus")
    lines = abaqus.splitlines()
    start = lines.index("*CONNECTOR ELASTICITY") + 1
    values = [float(v) for line in lines[start:start + 3] for v in line.split(",")]
    k = np.zeros((6, 6))
    it = iter(values)
    for c in range(6):
        for r in range(c + 1):
            k[r, c] = k[c, r] = next(it)
    assert _rel(k, joint.stiffness) < 1e-15


# --------------------------------------------------------------------------- hostile input


def test_file_name_cannot_inject_cards(tmp_path):
    _pynastran()
    evil = dict(RESULT, file="x.h5\nGRID,1,,0.,0.,0.\nCBUSH   99      99      1       2\nENDDATA\r\u2028$")
    results = _write(tmp_path, "r.jsonl", [evil])
    for fmt, starts in (("nastran", ("GRID", "CBUSH  ", "ENDDATA")), ("ansys", ("GRID", "N,", "FINISH")),
                        ("abaqus", ("GRID", "*NODE", "ENDDATA"))):
        code, out = _run(results, "--joint", "apparent", "--format", fmt)
        assert code == 0, out
        assert not any(line.startswith(starts) for line in out.splitlines()), fmt
        assert "x.h5?GRID,1,,0.,0.,0.?CBUSH" in out
    code, out = _run(results, "--joint", "apparent", "--format", "nastran", "--element", "bush")
    model = _bdf(out, tmp_path)
    assert not model.nodes and len(model.elements) == 1


@pytest.mark.parametrize("bad", ["Infinity", "-Infinity", "NaN", "1e999", "true"])
def test_non_finite_values_are_one_line_errors(tmp_path, bad):
    path = tmp_path / "r.json"
    path.write_text(json.dumps(RESULT).replace("1030000000.0", bad))
    for fmt in ("nastran", "ansys", "abaqus", "json"):
        code, out = _run(path, "--joint", "apparent", "--format", fmt)
        assert code == 2 and len(out.strip().splitlines()) == 1
        assert ("not a finite number" if bad != "true" else "expected a number") in out
        assert "INF" not in out.upper().replace("INFINITY", "").replace("INF ", "")


def test_id_overflow_and_repeats_are_refused(results_file):
    code, out = _run(results_file, "--joint", "apparent", "--element", "springs", "--vertical", "60",
                     "--horizontal", "60")
    assert code == 2 and "would repeat" in out
    code, out = _run(results_file, "--joint", "apparent", "--format", "nastran", "--first-element", "99999950")
    assert code == 2 and "outside 1..99999999" in out
    code, out = _run(results_file, "--joint", "apparent", "--format", "nastran", "--carriage-node", "5,100000000")
    assert code == 2 and "100000000" in out
    code, out = _run(results_file, "--joint", "apparent", "--carriage-node", "5")
    assert code == 2 and "one per carriage" in out
    code, out = _run(results_file, "--joint", "apparent", "--element", "springs", "--format", "json")
    assert code == 0
    ids = [e["element_id"] for e in json.loads(out)["elements"]]
    assert len(ids) == len(set(ids)) == 24


def test_missing_parameter_and_bad_json_are_bad_input(tmp_path):
    """A parameter null (not identified: a valid result of an incomplete identification) is exit 1, as
    identify's exit for it (was 2, 'bad input'); a parameter missing from the object is bad input."""
    bad = json.loads(json.dumps(RESULT))
    bad["parameters"]["K_H"]["value"] = None
    path = _write(tmp_path, "r.json", [bad])
    code, out = _run(path, "--joint", "apparent")
    assert code == 1 and "K_H' was not identified" in out
    bad["parameters"]["K_H"] = None
    code, out = _run(_write(tmp_path, "r.json", [bad]), "--joint", "apparent")
    assert code == 1 and "K_H' was not identified" in out
    del bad["parameters"]["K_H"]
    code, out = _run(_write(tmp_path, "r.json", [bad]), "--joint", "apparent")
    assert code == 2 and "K_H' missing" in out
    nope = tmp_path / "n.json"
    nope.write_text("{nope\n")
    code, out = _run(nope)
    assert code == 2 and "line 1: not JSON" in out
    assert read_results(_write(tmp_path, "l.json", [[RESULT]]))[0]["file"] == "carriage1.h5"


# --------------------------------------------------------------------------- Nastran against CalculiX


def _ccx_cards(text):
    """(keyword line, data lines) of each card of a CalculiX deck, comments dropped (blank data lines kept)."""
    cards = []
    for line in text.splitlines():
        if line.startswith("**"):
            continue
        if line.startswith("*"):
            cards.append((line.upper(), []))
        elif cards:
            cards[-1][1].append(line)
    return cards


def _ccx_global(text, rot_offset=50):
    """K and C of a guidefit CalculiX include as {((node, comp), (node, comp)): value}, Nastran DOF numbering.

    Springs (SPRING1 on an auxiliary DOF, SPRING2 between node DOFs) and dashpots (DASHPOTA from an auxiliary
    node to a fixed ground node, along x) are assembled as k v v^T; an auxiliary DOF is replaced by its
    *EQUATION's combination of node DOFs; DOF d of a rotation node n + rot_offset is component 3 + d of n
    (the default node ids: carriage 10001, rail 20001, plus fewer than ``rot_offset`` springs).
    """
    cards = _ccx_cards(text)
    coords, elements, equations, terms = {}, {}, {}, []
    for key, data in cards:
        if key.startswith("*NODE"):
            for row in data:
                n, *xyz = row.split(",")
                coords[int(n)] = np.array([float(v) for v in xyz])
        elif key.startswith("*ELEMENT"):
            kind = key.split("TYPE=")[1].split(",")[0]
            for row in data:
                _, *nodes = (int(v) for v in row.split(","))
                elements[key.split("ELSET=")[1]] = (kind, nodes)
        elif key.startswith("*EQUATION"):
            cells = [c for row in data[1:] for c in row.split(",") if c.strip()]
            t = [(int(cells[a]), int(cells[a + 1]), float(cells[a + 2])) for a in range(0, len(cells), 3)]
            equations[t[0][:2]] = {(n, d): -c / t[0][2] for n, d, c in t[1:]}
    for key, data in cards:
        if key.startswith("*SPRING") or key.startswith("*DASHPOT"):
            kind, nodes = elements[key.split("ELSET=")[1]]
            dofs, value = data[0], float(data[1])
            if kind == "SPRING1":
                v = {(nodes[0], int(dofs)): 1.0}
            elif kind == "SPRING2":
                d1, d2 = (int(x) for x in dofs.split(","))
                v = {(nodes[0], d1): 1.0, (nodes[1], d2): -1.0}
            else:  # DASHPOTA from an auxiliary node to the ground node, along x
                assert kind == "DASHPOTA" and not dofs.strip()
                assert np.allclose(coords[nodes[1]] - coords[nodes[0]], [1, 0, 0])
                v = {(nodes[0], 1): 1.0}
            terms.append(("K" if key.startswith("*SPRING") else "C", value, v))
    out = {"K": {}, "C": {}}
    for which, value, v in terms:
        full = {}
        for dof, c in v.items():
            for (n, d), a in equations.get(dof, {dof: 1.0}).items():
                key = (n - rot_offset, 3 + d) if n % 10000 >= rot_offset else (n, d)  # default ids: 10001, 20001
                full[key] = full.get(key, 0.0) + c * a
        for a, ca in full.items():
            for b, cb in full.items():
                out[which][a, b] = out[which].get((a, b), 0.0) + value * ca * cb
    return out


def _nastran_global(model):
    """K and C of a guidefit Nastran deck read by pyNastran: DMIG K2GG/B2GG or PBUSH/CBUSH, same layout."""
    out = {"K": {}, "C": {}}
    for which, name in (("K", "GFJK"), ("C", "GFJB")):
        if name in model.dmig:
            d = model.dmig[name]
            for gj, gi, value in zip(d.GCj, d.GCi, d.Real):
                a, b = tuple(int(x) for x in gi), tuple(int(x) for x in gj)
                out[which][a, b] = out[which][b, a] = float(value)
    for elem in model.elements.values():
        prop = model.properties[elem.pid]
        ga, gb = elem.nodes
        for which, values in (("K", prop.Ki), ("C", prop.Bi)):
            for comp, value in enumerate(values, start=1):
                if value:
                    for (n, m), s in (((ga, ga), 1), ((gb, gb), 1), ((ga, gb), -1), ((gb, ga), -1)):
                        key = ((n, comp), (m, comp))
                        out[which][key] = out[which].get(key, 0.0) + s * float(value)
    return out


def _same_matrices(a, b):
    """Largest difference of two {(dof, dof): value} matrices relative to sqrt(|A_ii A_jj|) of the entry."""
    worst = 0.0
    for which in ("K", "C"):
        x, y = a[which], b[which]
        diag = {k[0]: abs(v) for k, v in y.items() if k[0] == k[1]}
        for key in set(x) | set(y):
            scale = math.sqrt(diag.get(key[0], 0.0) * diag.get(key[1], 0.0)) or max(abs(v) for v in y.values())
            worst = max(worst, abs(x.get(key, 0.0) - y.get(key, 0.0)) / scale)
    return worst


@pytest.mark.parametrize("element", ["matrix", "bush", "springs"])
@pytest.mark.parametrize("joint,units,axis_map", [("explained", "si", None), ("apparent", "si", None),
                                                   ("explained", "mm-N-s", "x=X,y=Z,z=-Y")])
def test_calculix_include_encodes_the_joints_matrices(tmp_path, element, joint, units, axis_map):
    """The CalculiX include, springs and equations assembled back, is the exported element's K and C (1e-9)."""
    results = _write(tmp_path, "r.jsonl", [RESULT])
    expl = _write(tmp_path, "e.json", [ADEQUATE])
    args = ["--joint", joint, "--explain", expl, "--element", element, "--units", units] + \
        (["--axis-map", axis_map] if axis_map else [])
    code, text = _run(results, *args, "--format", "calculix")
    assert code == 0, text
    got = _ccx_global(text)
    j = (explained_joint(RESULT, ADEQUATE) if joint == "explained" else apparent_joint(RESULT))
    want = {"K": {}, "C": {}}
    for e in build_elements([j], element, units=units, axis_map=parse_axis_map(axis_map), ids_per_element=13
                            if element != "springs" else 2):
        for which, m in (("K", e.stiffness), ("C", e.damping)):
            m = np.diag(np.diag(m)) if element == "bush" else m  # a bush is the diagonal (couplings noted)
            for a in range(6):
                for b in range(6):
                    if m[a, b]:
                        for (n1, n2), s in (((e.carriage_node, e.carriage_node), 1), ((e.rail_node, e.rail_node), 1),
                                            ((e.carriage_node, e.rail_node), -1), ((e.rail_node, e.carriage_node), -1)):
                            key = ((n1, a + 1), (n2, b + 1))
                            want[which][key] = want[which].get(key, 0.0) + s * float(m[a, b])
    assert _same_matrices(got, want) < 1e-9


@pytest.mark.parametrize("element", ["matrix", "bush", "springs"])
@pytest.mark.parametrize("joint,units,axis_map", [("explained", "si", None), ("apparent", "si", None),
                                                   ("explained", "mm-N-s", "x=X,y=Z,z=-Y")])
def test_nastran_deck_read_by_pynastran_equals_the_calculix_include(tmp_path, element, joint, units, axis_map):
    """pyNastran's K and C of the Nastran deck (DMIG or PBUSH/CBUSH) equal the CalculiX include's, 1e-9."""
    _pynastran()
    results = _write(tmp_path, "r.jsonl", [RESULT])
    expl = _write(tmp_path, "e.json", [ADEQUATE])
    args = ["--joint", joint, "--explain", expl, "--element", element, "--units", units] + \
        (["--axis-map", axis_map] if axis_map else [])
    code, nastran = _run(results, *args, "--format", "nastran")
    assert code == 0, nastran
    code, calculix = _run(results, *args, "--format", "calculix")
    assert code == 0, calculix
    from_nastran, from_ccx = _nastran_global(_bdf(nastran, tmp_path)), _ccx_global(calculix)
    assert from_nastran["K"] and from_nastran["C"]
    assert _same_matrices(from_nastran, from_ccx) < 1e-9
    assert _same_matrices(from_ccx, from_nastran) < 1e-9
