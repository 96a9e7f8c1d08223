"""Ball guides: the point-contact law (Eq. 3), the guide TOML for balls, predict and a round trip.

Checks of the law against closed forms that are exact special cases of Hertz
point contact (K. L. Johnson, *Contact Mechanics*, 1985, ch. 4: a sphere on a
flat or in a spherical seat is a circular contact with a = (3 Q R / (4 E*))^(1/3)
and delta = a^2 / R, 1/R the relative curvature), and against the constants of
Harris & Kotzalas, *Rolling Bearing Analysis* (5th ed., vol. 1, ch. 6) for
steel: a = 0.0236 a* (Q / sum_rho)^(1/3), delta = 2.79e-4 delta* Q^(2/3)
sum_rho^(1/3) (mm, N); and a published worked example of a ball in a bearing
race (load, ellipse, approach, pressure; the source is cited at its test).
The published stiffness of a commercial ball guide with public geometry was
not available to this project; see docs/static.md.
"""

import json
import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from guidefit.cli import main
from guidefit.errors import GuideError
from guidefit.model import contact, static
from guidefit.model import vibration as vib
from guidefit.model.guides import load_guide

EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "guides"
FOUR_ROW = EXAMPLES / "ball4_size25.toml"
TWO_ROW = EXAMPLES / "ball2_size12.toml"
STEEL_E_PRIME = contact.effective_modulus(2.1e11, 0.3, 2.1e11, 0.3)


# --------------------------------------------------------------------------- the law


def test_sphere_on_flat_is_the_circular_hertz_contact():
    # conformity -> infinity is a flat groove: equal curvature both ways, k = 1, exact closed form
    r, q = 0.005, 100.0
    c = contact.point_contact(2.0 / r, 0.0, STEEL_E_PRIME)
    a, b = c.semi_axes_m(q)
    e_star = STEEL_E_PRIME / 2.0
    a_ref = (3.0 * q * r / (4.0 * e_star)) ** (1.0 / 3.0)
    assert c.k == pytest.approx(1.0, abs=1e-12)
    assert float(a) == pytest.approx(a_ref, rel=1e-12)
    assert float(b) == pytest.approx(a_ref, rel=1e-12)
    assert float(c.approach_m(q)) == pytest.approx(a_ref**2 / r, rel=1e-12)
    assert float(c.max_pressure_pa(q)) == pytest.approx(1.5 * q / (math.pi * a_ref**2), rel=1e-12)


def test_ball_in_a_spherical_seat_uses_the_relative_curvature():
    # ball radius r1 in a spherical cup of radius r2: 1/R = 1/r1 - 1/r2 in both directions
    r1, r2, q = 0.004, 0.005, 50.0
    rel = 1.0 / r1 - 1.0 / r2
    c = contact.point_contact(2.0 * rel, 0.0, STEEL_E_PRIME)
    a_ref = (3.0 * q / (4.0 * (STEEL_E_PRIME / 2.0) * rel)) ** (1.0 / 3.0)
    assert float(c.semi_axes_m(q)[0]) == pytest.approx(a_ref, rel=1e-12)
    assert float(c.approach_m(q)) == pytest.approx(a_ref**2 * rel, rel=1e-12)


@pytest.mark.parametrize("f_rho", [0.05, 0.5, 0.9, 0.926, 0.98])
def test_ellipticity_solves_the_elliptic_integral_equation(f_rho):
    from scipy.special import ellipe, ellipk

    k = contact.ellipticity(f_rho)
    m = 1.0 - 1.0 / k**2
    e, kk = ellipe(m), ellipk(m)
    assert ((k**2 + 1) * e - 2 * kk) / ((k**2 - 1) * e) == pytest.approx(f_rho, abs=1e-10)


def test_harris_steel_constants():
    # Harris & Kotzalas ch. 6, steel (E = 207.5 GPa, nu = 0.3): a = 0.0236 a* (Q/sum_rho)^(1/3) mm,
    # delta = 2.79e-4 delta* Q^(2/3) sum_rho^(1/3) mm; the 3-digit constants bound the agreement (0.2 %)
    e_prime = contact.effective_modulus(2.075e11, 0.3, 2.075e11, 0.3)
    c = contact.groove_contact(0.0127, 0.52, e_prime, race_curvature_per_m=2.0 / 0.0523)
    a_star = (2.0 * c.k**2 * c.E / math.pi) ** (1 / 3)
    delta_star = 2.0 * c.K / math.pi * (math.pi / (2.0 * c.k**2 * c.E)) ** (1 / 3)
    q, sum_rho_mm = 4000.0, c.sum_rho * 1e-3
    a_mm = float(c.semi_axes_m(q)[0]) * 1e3
    delta_mm = float(c.approach_m(q)) * 1e3
    assert a_mm == pytest.approx(0.0236 * a_star * (q / sum_rho_mm) ** (1 / 3), rel=2e-3)
    assert delta_mm == pytest.approx(2.79e-4 * delta_star * q ** (2 / 3) * sum_rho_mm ** (1 / 3), rel=2e-3)


def test_published_worked_example_ball_in_a_circular_race():
    # AMESWeb, "Example - Contact stresses in a steel ball bearing"
    # (https://www.amesweb.info/HertzianContact/ContactStressesSteelBallBearing.aspx): a ball of
    # radius 4.90 mm on the inner race of a bearing (groove radius 5 mm, race radius 25 mm), steel
    # E = 210 GPa, nu = 0.29, load P = 1500 N on the topmost ball. Printed: p_max = 2193.6 MPa,
    # approach d = 0.012 mm, contact ellipse a = 2.101 mm, b = 0.156 mm. The exact elliptic-integral
    # solution is 0.4 % below the printed a and within 0.1 % of b and p_max; the approach is printed
    # to two digits. 0.5 % bounds a calculator's tabulated Hertz coefficients (Hamrock & Brewe's
    # closed forms are 2.2 % off in a here, Ry/Rx = 60).
    e_prime = contact.effective_modulus(2.1e11, 0.29, 2.1e11, 0.29)
    c = contact.groove_contact(2 * 4.90e-3, 5.0 / 9.80, e_prime, race_curvature_per_m=1.0 / 25e-3)
    a_m, b_m = (float(x) for x in c.semi_axes_m(1500.0))
    assert a_m == pytest.approx(2.101e-3, rel=5e-3)
    assert b_m == pytest.approx(0.156e-3, rel=5e-3)
    assert float(c.max_pressure_pa(1500.0)) == pytest.approx(2193.6e6, rel=5e-3)
    assert abs(float(c.approach_m(1500.0)) - 0.012e-3) <= 0.0005e-3  # the printed 0.012 mm


@pytest.mark.parametrize("conformity", [0.51, 0.52, 0.54, 0.6])
def test_hamrock_brewe_approximation_error(conformity):
    # Hamrock & Brewe (1983) state about 3 % on k and 1 % on the integrals for 1 <= Ry/Rx <= 100;
    # guidefit uses the exact solution
    d = 0.00476
    c = contact.groove_contact(d, conformity, STEEL_E_PRIME)
    rx, ry = d / 2.0, 1.0 / (2.0 / d - 1.0 / (conformity * d))
    k_hb, kk_hb, e_hb = contact.hamrock_brewe(ry / rx)
    assert k_hb == pytest.approx(c.k, rel=0.035)  # 3.2 % at f = 0.51 (Ry/Rx = 51)
    assert kk_hb == pytest.approx(c.K, rel=0.002)
    assert e_hb == pytest.approx(c.E, rel=0.002)


def test_hamrock_brewe_leaves_its_range_near_conformity_one_half():
    # conformity 0.505: Ry/Rx = 101, just outside the fit; k is 6 % off there
    d = 0.00476
    c = contact.groove_contact(d, 0.505, STEEL_E_PRIME)
    k_hb = contact.hamrock_brewe(1.0 / (2.0 / d - 1.0 / (0.505 * d)) / (d / 2.0))[0]
    assert 0.05 < k_hb / c.k - 1.0 < 0.08


def test_two_contacts_in_series_and_eq3():
    g = load_guide(FOUR_ROW)
    rail, carriage = contact.guide_contacts(g)
    k_h = contact.ball_law_constant(g)
    q = 150.0
    alpha = float(rail.approach_m(q) + carriage.approach_m(q))
    assert k_h * alpha**1.5 == pytest.approx(q, rel=1e-12)  # Eq. (3): Q = k_h alpha^(3/2)
    # equal grooves: each contact takes half the approach, k_h = k_contact / 2^(3/2)
    assert k_h == pytest.approx(rail.deflection_constant ** -1.5 / 2**1.5, rel=1e-12)
    # K_n = (3/2) k_h alpha^(1/2) is the slope of Q(alpha)
    h = 1e-12
    slope = (static.roller_force(alpha + h, g, "law") - static.roller_force(alpha - h, g, "law")) / (2 * h)
    assert float(static.roller_stiffness(alpha, g, "law")) == pytest.approx(1.5 * k_h * alpha**0.5, rel=1e-12)
    assert float(slope) == pytest.approx(1.5 * k_h * alpha**0.5, rel=1e-5)


def test_law_lift_off_and_monotone():
    g = load_guide(FOUR_ROW)
    a = np.linspace(-1e-6, 5e-6, 61)
    q = static.roller_force(a, g, "law")
    k = static.roller_stiffness(a, g, "law")
    assert np.all(q[a <= 0] == 0) and np.all(k[a <= 0] == 0)  # no tension
    assert np.all(np.diff(q[a > 0]) > 0) and np.all(np.diff(k[a > 0]) > 0)  # stiffening, K ~ alpha^(1/2)


def test_tighter_groove_is_stiffer():
    ks = [contact.ball_constant([contact.groove_contact(0.005, f, STEEL_E_PRIME)] * 2) for f in (0.51, 0.52, 0.55)]
    assert ks[0] > ks[1] > ks[2]


def test_preload_force_gives_the_interference():
    g = load_guide(FOUR_ROW)  # preload class ZA: 0.06 x 35 kN
    k_h = contact.ball_law_constant(g)
    q0 = k_h * g.preload_m**1.5
    assert 2 * g.rollers_per_row * q0 * math.sin(g.contact_angle_rad) == pytest.approx(0.06 * 35e3, rel=1e-10)
    # nominal = law for a ball guide whose K_n comes from Eq. (3)
    assert static.contact_constant(g, "nominal") == pytest.approx(static.law_constant(g), rel=1e-12)


def test_ball_pair_lifts_off_at_2_83_times_the_preload():
    # opposed preloaded point contacts unload at 2^(3/2) times the preload (F_pre = 2 Z Q0 sin b)
    g = load_guide(FOUR_ROW)
    f_pre = 0.06 * 35e3
    assert static.lift_off_load(g) == pytest.approx(2**1.5 * f_pre, rel=1e-6)


# --------------------------------------------------------------------------- the guide TOML

BALL = """
name = "B"
[carriage]
mass_kg = 0.5
inertia_kg_m2 = [4e-4, 4e-4, 2e-4]
[rows]
e_m = 0.011
h1_m = 0.012
h0_m = 0.008
contact_angle_deg = 45
elements_per_row = 10
element_span_m = 0.045
[contact]
contact_type = "ball"
ball_diameter_m = "5 mm"
conformity_rail = 0.52
conformity_carriage = 0.52
preload_m = "2 um"
"""


def _load(tmp_path, text):
    path = tmp_path / "g.toml"
    path.write_text(text)
    return load_guide(path)


def test_ball_toml_loads_and_mrb35_is_unchanged(tmp_path):
    g = _load(tmp_path, BALL)
    assert g.is_ball and g.rollers_per_row == 10 and g.element_diameter_m == pytest.approx(0.005)
    assert g.roller_stiffness_n_per_m == pytest.approx(1.5 * contact.ball_law_constant(g) * (2e-6) ** 0.5)
    m = load_guide("MRB35")
    assert not m.is_ball and m.contact_law == "palmgren" and m.row_count == 4


@pytest.mark.parametrize("old, new, message", [
    ('conformity_rail = 0.52', 'conformity_rail = 0.49', "field 'contact.conformity_rail' must be in (0.5, 1)"),
    ('conformity_rail = 0.52\n', '', "field 'contact.conformity_rail' missing"),
    ('preload_m = "2 um"', 'preload_m = "2 um"\npreload_n = 100', "'contact.preload_m' and 'contact.preload_n'"),
    ('preload_m = "2 um"', 'preload_class = "ZA"', "needs 'contact.dynamic_load_rating_n'"),
    ('preload_m = "2 um"', 'preload_class = "ZZ"', "field 'contact.preload_class'"),
    ('preload_m = "2 um"', '', "a ball guide without preload has no stiffness"),
    ('contact_type = "ball"', 'contact_type = "balls"', "field 'contact.contact_type'"),
    ('h0_m = 0.008', 'h0_m = 0.008\nrow_count = 3', "field 'rows.row_count' must be 2 or 4"),
    ('h0_m = 0.008', 'h0_m = 0.008\nrow_count = 2', "field 'rows.h0_m' must be 0 or absent"),
    ('h0_m = 0.008', 'h0_m = 0.008\ngroove = "gothic_arch"', "field 'rows.groove'"),
    ('ball_diameter_m = "5 mm"', 'ball_diameter_m = "5 kg"', "unit 'kg' not allowed"),
    ('ball_diameter_m = "5 mm"', 'ball_diameter_m = "5 mm"\nroller_length_m = 0.005', "roller_length_m"),
    ('contact_type = "ball"', 'contact_type = "ball"\ncontact_law = "palmgren"', "field 'contact.contact_law'"),
    ('preload_m = "2 um"', 'preload_m = "2 um"\nelement_poisson = 0.7', "field 'contact.element_poisson'"),
])
def test_ball_toml_errors_are_one_line_naming_the_key(tmp_path, old, new, message):
    assert old in BALL
    with pytest.raises(GuideError) as info:
        _load(tmp_path, BALL.replace(old, new))
    assert message in str(info.value)
    assert "\n" not in str(info.value)


def test_roller_guide_refuses_ball_fields(tmp_path):
    text = load_guide("MRB35") and (Path(__file__).resolve().parents[1] / "guidefit/model/data/MRB35.toml").read_text()
    with pytest.raises(GuideError, match="'contact.conformity_rail' is for ball guides"):
        _load(tmp_path, text.replace('contact_law = "palmgren"', 'contact_law = "palmgren"\nconformity_rail = 0.52'))


def test_cli_exit_2_on_a_bad_ball_guide(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text(BALL.replace("conformity_rail = 0.52", "conformity_rail = 0.4"))
    result = CliRunner().invoke(main, ["predict", "--guide", str(path)])
    assert result.exit_code == 2
    assert "conformity_rail" in result.output and "Traceback" not in result.output


# --------------------------------------------------------------------------- model and commands


def test_two_row_guide_is_four_contact_lines_at_two_places():
    g = load_guide(TWO_ROW)
    geo = vib.row_geometry(g)
    assert geo[0][:2] == geo[2][:2] and geo[1][:2] == geo[3][:2]  # rows 1/3 and 2/4 are one ball row
    sol = vib.solve_modes(vib.model_from_guide(g))
    assert np.all(sol.frequencies_hz > 0)
    assert sol.frequency_hz("vertical") == pytest.approx(vib.f_vertical_hz(g), rel=1e-9)


@pytest.mark.parametrize("path, k_v, f_v", [(FOUR_ROW, 6.748e8, 5337.3), (TWO_ROW, 9.015e7, 8195.3)])
def test_predict_on_the_examples(path, k_v, f_v):
    result = CliRunner().invoke(main, ["predict", "--guide", str(path), "--json"])
    assert result.exit_code == 0, result.output
    g = load_guide(path)
    st = static.tangent_stiffness(g)
    assert st.K_V == pytest.approx(k_v, rel=1e-3)
    assert vib.solve_modes(vib.model_from_guide(g)).frequency_hz("vertical") == pytest.approx(f_v, rel=1e-3)
    # the static model's K_V under load rises for balls above lift-off, falls before (concave pairs)
    frame = static.sweep(g, n=3)
    assert frame["K_V_n_per_m"].iloc[0] == pytest.approx(st.K_V, rel=1e-9)


def test_simulate_identify_round_trip_on_a_ball_guide(tmp_path):
    out = tmp_path / "ball.h5"
    result = CliRunner().invoke(main, ["simulate", "--guide", str(FOUR_ROW), "--out", str(out), "--hits", "3",
                                       "--record-length", "0.03", "--force", "40,100", "--seed", "3"])
    assert result.exit_code == 0, result.output
    truth = json.loads(out.with_suffix(".truth.json").read_text())["parameters"]
    result = CliRunner().invoke(main, ["identify", str(out), "--json"])  # the file names the guide, not its TOML
    assert result.exit_code == 2 and "--guide FILE.toml" in result.output.strip().splitlines()[-1], result.output
    result = CliRunner().invoke(main, ["identify", str(out), "--json", "--guide", str(FOUR_ROW)])
    assert result.exit_code == 0, result.output
    found = json.loads(result.output.splitlines()[0])
    assert found["guide"] == "BALL4-25"
    for name, tol in (("f_V", 1e-3), ("K_V", 2e-3), ("f_H", 2e-3), ("K_H", 4e-3), ("zeta_V", 0.03)):
        assert found["parameters"][name]["value"] == pytest.approx(truth[name]["value"], rel=tol), name
