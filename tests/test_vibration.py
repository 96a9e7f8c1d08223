"""Vibration model (Eq. 5-23): assembled eigen-solution against closed forms and physics."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from guidefit.errors import ModelError
from guidefit.model import vibration as vib
from guidefit.model.effects import apply_effects, parse_effect
from guidefit.model.guides import load_guide

MRB35 = load_guide("MRB35")

# physics-notes.md, "Nominal MRB35 reference model (pinned)"
PINNED_HZ = {"yaw": 1879.1, "pitch": 2275.9, "roll_low": 2496.4, "vertical": 3529.0, "roll_high": 5563.6}


def test_mrb35_vertical_is_papers_3529_hz():
    sol = vib.solve_modes(vib.model_from_guide(MRB35))
    assert sol.frequency_hz("vertical") == pytest.approx(3529.0, abs=1.0)


def test_mrb35_matches_pinned_reference_frequencies():
    sol = vib.solve_modes(vib.model_from_guide(MRB35))
    for label, f in PINNED_HZ.items():
        # pinned values are printed to 0.1 Hz
        assert sol.frequency_hz(label) == pytest.approx(f, abs=0.1), label


guides = st.builds(
    lambda e, h1, h0, beta, z, span, kn, m, jx, jy, jz, conv, arr: MRB35.with_changes(
        e_m=e, h1_m=h1, h0_m=h0, contact_angle_deg=beta, rollers_per_row=z, roller_span_m=span,
        roller_stiffness_n_per_m=kn, mass_kg=m, inertia_kg_m2=(jx, jy, jz), e_convention=conv,
        arrangement=arr,
    ),
    st.floats(0.005, 0.08), st.floats(0.0, 0.05), st.floats(0.003, 0.04), st.floats(15, 75),
    st.integers(2, 40), st.floats(0.02, 0.3), st.floats(1e6, 1e9), st.floats(0.3, 20),
    st.floats(1e-4, 5e-2), st.floats(1e-4, 5e-2), st.floats(1e-4, 5e-2),
    st.sampled_from(["half", "full"]), st.sampled_from(["O", "X"]),
)


@settings(max_examples=60, deadline=None)
@given(guides)
def test_closed_forms_eq15_to_23_equal_eigen_solution(guide):
    sol = vib.solve_modes(vib.model_from_guide(guide))
    closed = vib.closed_form_frequencies_hz(guide)
    # the X arrangement can make the low roll mode nearly a mechanism (eigenvalue ~ 0):
    # compare on the scale of the highest frequency
    scale = max(closed.values())
    assert sorted(sol.frequencies_hz) == pytest.approx(sorted(closed.values()), rel=1e-9, abs=1e-8 * scale)
    # labels: the decoupled modes are exactly where their closed forms say
    for label in ("vertical", "pitch", "yaw"):
        assert any(abs(f - closed[label]) <= 1e-8 * scale for f in sol.frequencies_hz)


@settings(max_examples=30, deadline=None)
@given(guides)
def test_stiffness_symmetric_positive_definite(guide):
    k = vib.carriage_stiffness_matrix(vib.rollers_from_guide(guide))
    assert np.allclose(k, k.T, rtol=0, atol=1e-9 * np.abs(k).max())
    assert np.linalg.eigvalsh(k).min() > 0


@settings(max_examples=30, deadline=None)
@given(guides, st.floats(0.01, 100.0))
def test_frequencies_scale_with_sqrt_kn_over_m(guide, factor):
    base = vib.solve_modes(vib.model_from_guide(guide)).frequencies_hz
    scaled_k = vib.solve_modes(vib.scale_roller_stiffness(vib.model_from_guide(guide), factor)).frequencies_hz
    assert scaled_k == pytest.approx(base * math.sqrt(factor), rel=1e-9)
    heavier = guide.with_changes(mass_kg=guide.mass_kg * factor,
                                 inertia_kg_m2=tuple(j * factor for j in guide.inertia_kg_m2))
    assert vib.solve_modes(vib.model_from_guide(heavier)).frequencies_hz == pytest.approx(
        base / math.sqrt(factor), rel=1e-9)


@pytest.mark.parametrize("where", [(0, 0, 0), (0.03, 0, 0.045), (-0.03, 0.01, -0.045)])
def test_added_mass_lowers_every_frequency(where):
    base = vib.solve_modes(vib.model_from_guide(MRB35)).frequencies_hz
    heavier = vib.solve_modes(vib.with_point_masses(vib.model_from_guide(MRB35), [(0.05, where)]))
    assert np.all(heavier.frequencies_hz <= base + 1e-9)
    assert heavier.frequencies_hz[heavier.labels.index("vertical")] < 3529.0 - 10


def test_mass_at_origin_equals_mass_increase():
    spec = vib.with_point_masses(vib.model_from_guide(MRB35), [(0.1, (0, 0, 0))])
    f = vib.solve_modes(spec).frequency_hz("vertical")
    assert f == pytest.approx(3529.0335 * math.sqrt(2.2 / 2.3), rel=1e-6)


def test_com_offset_couples_u_and_phi_by_minus_m_yc():
    spec = vib.model_from_guide(MRB35.with_changes(center_of_mass_m=(0.0, -0.01, 0.0)))
    m = vib.carriage_mass_matrix(spec)
    assert m[0, 4] == pytest.approx(-2.2 * -0.01)  # -M y_c with y_c = -0.01
    assert m[4, 4] == pytest.approx(MRB35.inertia_kg_m2[2] + 2.2 * 0.01**2)


def test_massless_rigid_support_equals_no_support():
    spec = vib.model_from_guide(MRB35)
    stiff = vib.with_support(spec, vib.SupportBody(stiffness_to_ground=(1e16,) * 5))
    assert vib.solve_modes(stiff).frequencies_hz == pytest.approx(vib.solve_modes(spec).frequencies_hz, rel=1e-5)


def test_series_support_spring_vertical_is_series_combination():
    # vertical: 4 rows in parallel (K_V = 1.0817e9) in series with k_s
    k_s = 2e9
    spec = vib.with_support(vib.model_from_guide(MRB35),
                            vib.SupportBody(stiffness_to_ground=(math.inf, k_s, math.inf, math.inf, math.inf)))
    k_v = 4 * 21 * MRB35.roller_stiffness_n_per_m * 0.5
    expect = math.sqrt(k_v * k_s / (k_v + k_s) / 2.2) / (2 * math.pi)
    assert vib.solve_modes(spec).frequency_hz("vertical") == pytest.approx(expect, rel=1e-9)


def test_papers_lateral_support_explains_1075_hz():
    # physics notes: a lateral rail spring of about 1.2e8 N/m pulls roll_low to ~1075 Hz, f_V unchanged
    spec = apply_effects(vib.model_from_guide(MRB35), MRB35,
                         [parse_effect("support_compliance:lateral_n_per_m=1.2e8")])
    sol = vib.solve_modes(spec)
    assert 1000 < sol.frequency_hz("roll_low") < 1150
    assert sol.frequency_hz("vertical") == pytest.approx(3529.03, abs=0.1)


def test_base_mode_adds_modes_and_splits_vertical():
    spec = apply_effects(vib.model_from_guide(MRB35), MRB35,
                         [parse_effect("base_mode:mass_kg=3,vertical_n_per_m=2e9,lateral_n_per_m=5e8")])
    sol = vib.solve_modes(spec)
    assert len(sol.frequencies_hz) == 7
    assert sum(lab.startswith("support") for lab in sol.labels) == 2


def test_vertical_mode_moves_points_in_phase():
    sol = vib.solve_modes(vib.model_from_guide(MRB35))
    k = sol.labels.index("vertical")
    vertical = [sol.point_motion[p][k, 1] for p in "ABCD"]
    assert all(np.sign(vertical) == np.sign(vertical[0]))
    pitch = sol.labels.index("pitch")
    # pitch: front points (A, B at +z) move against the rear points (C, D)
    assert np.sign(sol.point_motion["A"][pitch, 1]) == -np.sign(sol.point_motion["D"][pitch, 1])


def test_accelerance_high_frequency_limit_is_inverse_mass():
    sol = vib.solve_modes(vib.model_from_guide(MRB35))
    spec = vib.model_from_guide(MRB35)
    h = vib.accelerance(sol, spec, [1e6], 0.02, (0, 0, 0), (0, 1, 0), [(0, 0, 0)], [(0, 1, 0)])
    assert abs(h[0, 0]) == pytest.approx(1 / 2.2, rel=1e-3)


def test_unrestrained_model_is_reported():
    spec = vib.scale_roller_stiffness(vib.model_from_guide(MRB35), 0.0)
    with pytest.raises(ModelError, match="singular"):
        vib.solve_modes(spec)


def test_per_roller_stiffness_shape_checked():
    with pytest.raises(ModelError, match="roller stiffness"):
        vib.rollers_from_guide(MRB35, np.ones(5))


def test_best_assignment_has_the_hungarian_methods_total():
    """The exhaustive label assignment reaches the optimum of scipy's Hungarian method."""
    from scipy.optimize import linear_sum_assignment

    from guidefit.model.vibration import _best_assignment

    rng = np.random.default_rng(3)
    for n, k in [(5, 5), (6, 5), (8, 5), (3, 3), (7, 4)]:
        for _ in range(20):
            score = rng.random((n, k))
            rows, cols = _best_assignment(score)
            r2, c2 = linear_sum_assignment(-score)
            assert len(set(rows)) == k and sorted(cols) == list(range(k))
            assert np.all(np.diff(rows) > 0)
            assert score[rows, cols].sum() == pytest.approx(score[r2, c2].sum(), rel=1e-12)
