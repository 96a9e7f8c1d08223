"""Every sensor layout x rig effect: labels, joint parameters, their std and explain's verdict.

Small seeded cases of guidefit's own simulator (the full matrix with more
seeds is ``benchmarks/layout_matrix.py``, its table in benchmarks/README.md).
Layouts: the guide's default (A-D along each run's hammer axis: y in the
vertical run, x in the lateral run), both axes, side-face lateral sensors,
triaxial sensors at A and C, two sensors per run (A, C) and one (A). Effects:
none, 0.1 kg at corner A, a soft lateral support (1.2e8 N/m), contact
stiffness 0.8. Tolerances are the independent validation's
(``../shared/validation``): f 0.1 %, K 0.2 %, zeta and c 5 %, |error| <= 3 std.
"""

from __future__ import annotations

import math
import warnings

import pytest

from guidefit.explain import explain
from guidefit.identify import IdentifySettings, identify
from guidefit.io import write_recording
from guidefit.model.effects import parse_effect
from guidefit.simulate import SimulationConfig, simulate

LAYOUTS = ("default", "both", "side", "triax:A,C", "pair", "single")
EFFECTS = {
    "nominal": ([], "adequate"),
    "mass_at_A": (["added_mass:mass_kg=0.1,at=A"], "added_mass"),
    "soft_lateral": (["support_compliance:lateral_n_per_m=1.2e8"], "support_compliance"),
    "contact_0.8": (["contact_stiffness:factor=0.8"], "contact_stiffness"),
}
#: explain's candidates in these tests: the three effects and two that none of the recordings has
CANDIDATES = ["added_mass", "support_compliance", "contact_stiffness", "com_offset", "row_damage"]
TOL = {"f_V": 1e-3, "f_H": 1e-3, "K_V": 2e-3, "K_H": 2e-3, "zeta_V": 0.05, "zeta_H": 0.05, "c_V": 0.05, "c_H": 0.05}
MASS_KG = 2.2


@pytest.fixture(scope="module")
def cases(tmp_path_factory):
    folder = tmp_path_factory.mktemp("layouts")
    cache = {}

    def get(effect, layout):
        if (effect, layout) not in cache:
            cfg = SimulationConfig(hits=4, record_s=0.05, sensor_layout=layout)
            data, truth = simulate("MRB35", effects=[parse_effect(e) for e in EFFECTS[effect][0]], config=cfg,
                                   seed=11)
            path = folder / f"{effect}_{layout.replace(':', '').replace(',', '')}.h5"
            write_recording(path, data)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                result = identify(path, settings=IdentifySettings())
            cache[effect, layout] = (result, truth)
        return cache[effect, layout]

    return get


def _truth_parameters(truth) -> dict:
    t = {m["label"]: m for m in truth["modes"]}
    out = {}
    for key, label in (("V", "vertical"), ("H", "roll_low")):
        f, zeta = t[label]["frequency_hz"], t[label]["damping_ratio"]
        out[f"f_{key}"], out[f"zeta_{key}"] = f, zeta
        out[f"K_{key}"] = 4 * math.pi**2 * MASS_KG * f**2  # Eq. (24)-(25)
        out[f"c_{key}"] = 4 * math.pi * MASS_KG * f * zeta  # Eq. (27), (29)
    return out


@pytest.mark.parametrize("effect", list(EFFECTS))
@pytest.mark.parametrize("layout", LAYOUTS)
def test_labels_parameters_and_std_on_every_layout(cases, effect, layout):
    result, truth = cases(effect, layout)
    t = {m["label"]: m["frequency_hz"] for m in truth["modes"]}
    assert result.gate is None and result.sensor_faults == ()
    for m in result.modes:  # every label given is the truth's mode of that label
        assert m.frequency_hz == pytest.approx(t[m.label], rel=2e-3), m.label
        assert m.label_basis in ("shape", "frequency", "shape+frequency") and m.label_note
    assert {"vertical", "roll_low"} <= {m.label for m in result.modes}
    expected = _truth_parameters(truth)
    for key, tol in TOL.items():
        p = result.parameters[key]
        err = p["value"] - expected[key]
        assert abs(err) <= tol * expected[key], f"{key}: {100 * err / expected[key]:+.3f} %"
        assert p["std"] > 0 and abs(err) <= 3 * p["std"], f"{key}: error {abs(err) / p['std']:.1f} std"


@pytest.mark.parametrize("effect", list(EFFECTS))
@pytest.mark.parametrize("layout", LAYOUTS)
def test_explain_names_the_effect_on_every_layout(cases, effect, layout):
    result, _ = cases(effect, layout)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ex = explain(result, candidates=CANDIDATES)
    expected = EFFECTS[effect][1]
    if expected == "adequate":
        assert ex.verdict == "adequate"
    else:
        assert ex.verdict == "explained" and ex.effects[0]["name"] == expected
