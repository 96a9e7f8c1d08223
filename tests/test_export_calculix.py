"""CalculiX export: the include's terms give back the joint; ccx itself reproduces guidefit's frequencies and damping.

The solver tests run ``ccx`` (Debian package ``calculix-ccx``, installed by
``.ci/run``) on the reference assembly: one small deck per case, well under a
second each. Without ccx they skip, saying so.
"""

import json
import math
import re
import shutil
import subprocess

import numpy as np
import pytest
from click.testing import CliRunner

from guidefit.cli import main
from guidefit.export import build_elements, export, joints_from_results, parse_axis_map
from guidefit.export.calculix import IDS_PER_ELEMENT, _ccx, _terms
from guidefit.export.reference import mass_points, point_gradient, reference_models
from guidefit.io.fe_results import ccx_eigen_table, ccx_steady_state
from guidefit.model import vibration as vib
from guidefit.model.guides import load_guide

RESULT = {"file": "carriage1.h5", "guide": "MRB35", "parameters": {
    "K_V": {"value": 1.03e9}, "c_V": {"value": 2750.0}, "K_H": {"value": 1.00e8}, "c_H": {"value": 3109.0}},
    "modes": [{"label": "vertical", "frequency_hz": 3450.0, "damping_ratio": 0.0288},
              {"label": "roll_low", "frequency_hz": 1075.0, "damping_ratio": 0.105}]}
ADEQUATE = {"file": "carriage1.h5", "verdict": "adequate", "guide": "MRB35", "effects": []}
#: a centre of mass off the origin, so that mass couplings are in play
GUIDE = load_guide("MRB35").with_changes(center_of_mass_m=(0.004, 0.01, -0.003))
CCX = shutil.which("ccx")
needs_ccx = pytest.mark.skipif(CCX is None, reason="CalculiX ccx not installed (apt-get install calculix-ccx)")


@pytest.fixture
def files(tmp_path):
    results = tmp_path / "results.jsonl"
    results.write_text(json.dumps(RESULT) + "\n")
    explain = tmp_path / "explain.json"
    explain.write_text(json.dumps(ADEQUATE))
    return results, explain


def _deck(files, joint, element, units="si", axis_map=None, assembly="reference"):
    results, explain = files
    return export(results, "calculix", joint=joint, explanations=[explain], element=element, units=units,
                  axis_map=axis_map, assembly=assembly, guide=GUIDE)


def _model(joint, element, units="si", axis_map=None):
    joints = joints_from_results([RESULT], joint, [ADEQUATE], GUIDE)
    rot = parse_axis_map(axis_map)
    els = build_elements(joints, element, units=units, axis_map=rot, ids_per_element=IDS_PER_ELEMENT[element])
    return reference_models(joints, els, units=units, axis_map=rot, element=element, rot_offset=50, guide=GUIDE)[0]


def _run_ccx(tmp_path, text, name="deck"):
    (tmp_path / f"{name}.inp").write_text(text)
    run = subprocess.run([CCX, "-i", name], cwd=tmp_path, capture_output=True, text=True, timeout=120,
                         check=False)
    errors = [line for line in run.stdout.splitlines() if "ERROR" in line]
    assert not errors, errors[:3]
    return (tmp_path / f"{name}.dat").read_text()


def _equations(text):
    """{dependent node: {(node, dof): coefficient}} of the deck's *EQUATION cards."""
    lines = text.splitlines()
    out = {}
    for i, line in enumerate(lines):
        if line == "*EQUATION":
            n, cells, k = int(lines[i + 1]), [], i + 2
            while len(cells) < 3 * n:
                cells += [c for c in lines[k].split(",") if c.strip()]
                k += 1
            terms = [(int(cells[a]), int(cells[a + 1]), float(cells[a + 2])) for a in range(0, len(cells), 3)]
            out[terms[0][0]] = {(nd, d): c for nd, d, c in terms[1:]}
    return out


# --------------------------------------------------------------------------- without the solver


@pytest.mark.parametrize("units,axis_map", [("si", None), ("mm-N-s", "x=X,y=Z,z=-Y"), ("mm-t-s", "x=-Y,y=X,z=Z")])
def test_matrix_include_terms_sum_to_the_joint(files, units, axis_map):
    """Each SPRING1/DASHPOTA term times its equation's v v^T, summed, is the exported 6x6 (couplings included)."""
    text = _deck(files, "explained", "matrix", units, axis_map, assembly="include")
    eqs = _equations(text)
    joints = joints_from_results([RESULT], "explained", [ADEQUATE], GUIDE)
    el = build_elements(joints, "matrix", units=units, axis_map=parse_axis_map(axis_map), ids_per_element=13)[0]
    index = {(10001, d + 1): d for d in range(3)} | {(10051, d + 1): 3 + d for d in range(3)}
    for card, want in (("SPRING", el.stiffness), ("DASHPOT", el.damping)):
        total = np.zeros((6, 6))
        for m in re.finditer(rf"\*{card},ELSET=GF[KD](\d+)\n(?:1\n|\n)(\S+)", text):
            aux, value = int(m.group(1)), float(m.group(2))
            v = np.zeros(6)
            for (node, dof), c in eqs[aux].items():
                if (node, dof) in index:
                    v[index[node, dof]] = -c
                else:  # the rail side: the opposite coefficient
                    assert eqs[aux][(node - 10000, dof)] == pytest.approx(-c, rel=1e-13)
            total += value * np.outer(v, v)
        scale = np.sqrt(np.outer(np.abs(np.diag(want)), np.abs(np.diag(want))))
        # each entry to 1e-9 of its rows' scale; the zero z row to roundoff of the largest entry
        assert np.all(np.abs(total - want) <= 1e-9 * scale + 1e-12 * np.abs(want).max())


def test_numbers_fit_ccx_fields_and_read_back():
    for x in (2.866280773293728e-05, -1.2345678901234567e-300, 1081667999.9999998, 0.1 + 0.2, -7.0):
        text = _ccx(x)
        assert len(text) <= 20 and float(text) == pytest.approx(x, rel=1e-13)


def test_reference_body_has_the_guides_mass_matrix():
    """Seven point masses give the guide's mass, centre of mass and inertia exactly (Eq. 5-8 with offset)."""
    mass = np.zeros((6, 6))
    for m, p in mass_points(GUIDE):
        g = point_gradient(p)
        mass += m * g.T @ g
    m5 = vib.carriage_mass_matrix(vib.model_from_guide(GUIDE))
    idx = [0, 1, 3, 4, 5]
    assert np.allclose(mass[np.ix_(idx, idx)], m5, rtol=0, atol=1e-12)
    assert mass[2, 2] == pytest.approx(GUIDE.mass_kg, rel=1e-12)


def test_non_positive_matrix_is_refused():
    with pytest.raises(ValueError, match="not positive semi-definite"):
        _terms(np.diag([1.0, -1.0, 0, 0, 0, 0]))


def test_assembly_is_for_calculix_only(files):
    out = CliRunner().invoke(main, ["export", str(files[0]), "--format", "nastran", "--joint", "apparent",
                                    "--assembly", "reference"])
    assert out.exit_code == 2
    assert "for --format calculix only" in out.output and len(out.output.strip().splitlines()) == 1


def test_too_many_springs_for_the_rotation_offset_is_refused(files):
    out = CliRunner().invoke(main, ["export", str(files[0]), "--format", "calculix", "--joint", "apparent",
                                    "--element", "springs", "--vertical", "30", "--horizontal", "30"])
    assert out.exit_code == 2 and "id" in out.output and len(out.output.strip().splitlines()) == 1


def test_reference_springs_at_some_corners_only_are_refused(files):
    """--vertical 3 --horizontal 5: three of the four corners held springs, so the reference deck's
    vertical mode was 3644 Hz for the joint's 3529 Hz (exit 0); now one line, exit 2."""
    out = CliRunner().invoke(main, ["export", str(files[0]), "--format", "calculix", "--joint", "apparent",
                                    "--element", "springs", "--vertical", "3", "--horizontal", "5",
                                    "--assembly", "reference"])
    assert out.exit_code == 2 and "multiples of 4 and 8" in out.output
    assert len(out.output.strip().splitlines()) == 1


# --------------------------------------------------------------------------- ccx


@needs_ccx
@pytest.mark.parametrize("joint", ["explained", "apparent"])
@pytest.mark.parametrize("element", ["matrix", "bush", "springs"])
def test_ccx_frequencies_equal_guidefits(tmp_path, files, joint, element):
    """ccx's natural frequencies of the reference assembly = guidefit's for that joint and body, within 0.1 %."""
    dat = _run_ccx(tmp_path, _deck(files, joint, element))
    ccx = ccx_eigen_table(dat)
    model = _model(joint, element)
    want = model.frequencies_hz()
    if joint == "explained" and element == "matrix":  # guidefit's own vibration model, Eq. 5-23
        want = np.sort(vib.solve_modes(vib.model_from_guide(GUIDE)).frequencies_hz)
        assert np.allclose(model.frequencies_hz(), want, rtol=1e-9)
    if joint == "apparent" and element != "springs":  # Eq. 24-25 backwards: f = sqrt(K/M) / 2 pi
        want_eq = [math.sqrt(RESULT["parameters"][k]["value"] / GUIDE.mass_kg) / (2 * math.pi) for k in ("K_H", "K_V")]
        assert np.allclose(want, want_eq, rtol=1e-9)
    assert ccx.size == want.size
    assert np.max(np.abs(ccx / want - 1)) < 1e-3


@needs_ccx
@pytest.mark.parametrize("joint,element", [("explained", "matrix"), ("apparent", "springs")])
def test_ccx_frequencies_in_other_units_and_axes(tmp_path, files, joint, element):
    want = _model(joint, element).frequencies_hz()
    for units, axis_map in (("mm-N-s", "x=X,y=Z,z=-Y"), ("mm-t-s", "x=Z,y=-X,z=-Y")):
        dat = _run_ccx(tmp_path, _deck(files, joint, element, units, axis_map), f"deck_{units}")
        assert np.max(np.abs(ccx_eigen_table(dat) / want - 1)) < 1e-3


@needs_ccx
@pytest.mark.parametrize("element", ["matrix", "bush", "springs"])
def test_ccx_steady_state_carries_the_joints_damping(tmp_path, files, element):
    """The dashpots: ccx's harmonic response = (K - w^2 M + i w C)^-1 f with the joint's C, within 1 %,
    at the natural frequencies (where the response is the damping's)."""
    dat = _run_ccx(tmp_path, _deck(files, "explained", element))
    model = _model("explained", element)
    load = np.ones(int(model.free.sum()))
    steps = ccx_steady_state(dat)
    assert len(steps) >= model.free.sum()
    for f, u in steps:
        got = np.concatenate([u.get(model.ref_node, np.zeros(3)), u.get(model.rot_node, np.zeros(3))])[model.free]
        want = model.response(f, load)
        assert np.linalg.norm(got - want) < 0.01 * np.linalg.norm(want)


@needs_ccx
def test_ccx_recovers_the_identified_c(tmp_path, files):
    """Apparent joint: at f_V the vertical response to 1 N is 1 / (w c_V); ccx's gives c_V within 1 %."""
    dat = _run_ccx(tmp_path, _deck(files, "apparent", "bush"))
    model = _model("apparent", "bush")
    f_v = max(model.frequencies_hz())
    f, u = min(ccx_steady_state(dat), key=lambda s: abs(s[0] - f_v))
    assert f == pytest.approx(f_v, rel=1e-5)
    c = 1.0 / (2 * math.pi * f * abs(u[model.ref_node][1]))
    assert c == pytest.approx(RESULT["parameters"]["c_V"]["value"], rel=0.01)
