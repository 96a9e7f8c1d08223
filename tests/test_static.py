"""Static contact model (Eq. 1-4): contact law, equilibrium, tangent stiffness, lift-off.

Expected values are derived by hand from the MRB35 inputs (Table 1 of the paper,
completed in shared/physics-notes.md): Z = 21 rollers per row, b = 45 deg,
L = 5.1 mm, Delta = 0.72 um, nominal K_n = 2.5754e7 N/m.
"""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from guidefit.errors import ModelError
from guidefit.model import static
from guidefit.model import vibration as vib
from guidefit.model.guides import load_guide

MRB35 = load_guide("MRB35")
Z = 21
S2 = math.sin(math.radians(45.0)) ** 2
DELTA = 0.72e-6
K_N_NOMINAL = 2.5754e7


def palmgren_load_by_hand(approach_m, length_m):
    """Q (N) of two Palmgren contacts in series: delta_c [mm] = 3.84e-5 Q^0.9 / L^0.8."""
    delta_c_mm = 0.5 * approach_m * 1e3
    return (delta_c_mm * (length_m * 1e3) ** 0.8 / 3.84e-5) ** (1 / 0.9)


# --------------------------------------------------------------------------- contact law


def test_law_force_is_palmgren_by_hand():
    a = np.array([0.3e-6, DELTA, 5e-6])
    assert static.roller_force(a, MRB35, "law") == pytest.approx(palmgren_load_by_hand(a, 0.0051), rel=1e-12)
    # and back: two contacts of 3.84e-5 Q^0.9 / L^0.8 mm each give the approach
    q = static.roller_force(a, MRB35, "law")
    assert 2 * 3.84e-5 * q**0.9 / 5.1**0.8 * 1e-3 == pytest.approx(a, rel=1e-12)


def test_compression_only():
    assert static.roller_force([-1e-6, 0.0], MRB35).tolist() == [0.0, 0.0]
    assert static.roller_stiffness([-1e-6, 0.0], MRB35).tolist() == [0.0, 0.0]


@pytest.mark.parametrize("calibration", ["law", "nominal"])
def test_stiffness_is_derivative_of_force_eq4(calibration):
    a = np.array([0.2e-6, DELTA, 3e-6])
    h = 1e-12
    numeric = (static.roller_force(a + h, MRB35, calibration) - static.roller_force(a - h, MRB35, calibration)) / (2 * h)
    assert static.roller_stiffness(a, MRB35, calibration) == pytest.approx(numeric, rel=1e-7)


def test_law_stiffness_at_preload_is_7_9e7_and_nominal_factor_is_a_third():
    # physics notes: "Palmgren's line-contact law ... gives K_n = 7.9e7 N/m"; factor "about 0.33"
    k_law = float(static.roller_stiffness(DELTA, MRB35, "law"))
    assert k_law == pytest.approx(10 / 9 * palmgren_load_by_hand(DELTA, 0.0051) / DELTA, rel=1e-12)
    assert k_law == pytest.approx(7.9e7, rel=0.01)
    assert float(static.roller_stiffness(DELTA, MRB35, "nominal")) == pytest.approx(K_N_NOMINAL, rel=1e-12)
    factor = static.contact_constant(MRB35, "nominal") / static.contact_constant(MRB35, "law")
    assert factor == pytest.approx(K_N_NOMINAL / k_law, rel=1e-12)
    assert factor == pytest.approx(0.33, abs=0.01)


def test_calibration_inputs_are_checked():
    with pytest.raises(ModelError, match="calibration 'hertz': allowed law, nominal"):
        static.roller_force(1e-6, MRB35, "hertz")
    with pytest.raises(ModelError, match="contact.preload_m"):
        static.tangent_stiffness(MRB35.with_changes(preload_m=0.0))
    with pytest.raises(ModelError, match="contact.roller_length_m"):
        static.tangent_stiffness(MRB35.with_changes(roller_length_m=None), calibration="law")


# --------------------------------------------------------------------------- zero load


def test_nominal_zero_load_stiffness_is_4_z_kn_sin2b():
    st0 = static.tangent_stiffness(MRB35)
    k_v = 4 * Z * K_N_NOMINAL * S2  # 1.082e9 N/m, the value behind f_V = 3529 Hz
    assert st0.K_V == pytest.approx(k_v, rel=1e-12)
    assert st0.K_V == pytest.approx(1.082e9, rel=1e-3)
    # 45 degree rows: K_H = 4 Z K_n cos^2 b = K_V (partial derivatives, others held)
    assert st0.K_H == pytest.approx(st0.K_V, rel=1e-12)
    # roll about the load point, Eq. (14): 2 Z K_n [(h1 c - e s)^2 + (h3 c + e s)^2]
    c = s = math.sqrt(0.5)
    e, h1, h3 = 0.032, 0.0235, 0.0342
    assert st0.K_gamma == pytest.approx(2 * Z * K_N_NOMINAL * ((h1 * c - e * s) ** 2 + (h3 * c + e * s) ** 2),
                                        rel=1e-12)
    assert (st0.delta_V, st0.delta_H, st0.gamma) == (0.0, 0.0, 0.0)
    assert st0.rows_lifted == () and st0.rows_partial == ()
    assert st0.K_n_nominal_n_per_m == pytest.approx(K_N_NOMINAL, rel=1e-12)
    assert st0.K_n_law_n_per_m == pytest.approx(7.9e7, rel=0.01)


def test_law_zero_load_stiffness_is_3_3e9():
    st0 = static.tangent_stiffness(MRB35, calibration="law")
    k_n = float(static.roller_stiffness(DELTA, MRB35, "law"))
    assert st0.K_V == pytest.approx(4 * Z * k_n * S2, rel=1e-12)
    assert st0.K_V == pytest.approx(3.3e9, rel=0.01)
    assert st0.calibration_factor == 1.0


def test_zero_load_matches_tangent_matrix_of_vibration_model():
    st0 = static.tangent_stiffness(MRB35)
    k_vib = vib.carriage_stiffness_matrix(vib.rollers_from_guide(MRB35))
    assert st0.tangent_matrix == pytest.approx(k_vib, rel=1e-12, abs=1e-9 * np.abs(k_vib).max())


def test_zero_load_roller_stiffness_reproduces_f_v_3529_hz():
    st0 = static.tangent_stiffness(MRB35)
    spec = vib.with_roller_stiffness(vib.model_from_guide(MRB35), st0.roller_stiffness_n_per_m)
    assert vib.solve_modes(spec).frequency_hz("vertical") == pytest.approx(3529.0, abs=0.5)


# --------------------------------------------------------------------------- Eq. (2) against numbers


def _equilibrium_q(load, calibration="nominal"):
    return static.solve_equilibrium(MRB35, load, calibration).displacement_q


@pytest.mark.parametrize("calibration", ["nominal", "law"])
def test_zero_load_k_v_is_slope_of_load_deflection_curve(calibration):
    h = 1.0  # N
    dv = -(_equilibrium_q((h, 0, 0), calibration)[1] - _equilibrium_q((-h, 0, 0), calibration)[1]) / (2 * h)
    st0 = static.tangent_stiffness(MRB35, calibration=calibration)
    assert st0.K_V == pytest.approx(1.0 / dv, rel=1e-4)
    assert st0.K_V_free == pytest.approx(1.0 / dv, rel=1e-4)


@pytest.mark.parametrize("load", [(0.0, 0.0, 0.0), (600.0, 150.0, 8.0), (-300.0, -200.0, 3.0)])
def test_partial_stiffnesses_are_central_differences_with_others_held(load):
    st_ = static.tangent_stiffness(MRB35, load)
    q0 = st_.displacement_q
    for j, k_expected in ((1, st_.K_V), (0, st_.K_H), (4, st_.K_gamma)):
        h = 1e-9 if j < 2 else 1e-8
        dq = np.zeros(5)
        dq[j] = h
        df = (static.load_at_displacement(MRB35, q0 + dq) - static.load_at_displacement(MRB35, q0 - dq)) / (2 * h)
        assert df[j] == pytest.approx(k_expected, rel=1e-6)
        assert df == pytest.approx(st_.tangent_matrix[:, j], rel=1e-5, abs=1e-6 * abs(k_expected))


def test_free_lateral_stiffness_is_slope_with_roll_free():
    h = 1.0
    du = (_equilibrium_q((0, h, 0))[0] - _equilibrium_q((0, -h, 0))[0]) / (2 * h)
    st0 = static.tangent_stiffness(MRB35)
    assert st0.K_H_free == pytest.approx(1.0 / du, rel=1e-4)
    assert st0.K_H_free < st0.K_H  # the u-phi coupling of Eq. (10), (14)


# --------------------------------------------------------------------------- equilibrium


LOAD_GRID = [(fv, fh, m) for fv in (-2500.0, -400.0, 0.0, 700.0, 5000.0)
             for fh in (-3000.0, 0.0, 900.0) for m in (-60.0, 0.0, 25.0)]


@pytest.mark.parametrize("calibration", ["nominal", "law"])
def test_newton_converges_from_zero_on_a_grid(calibration):
    for load in LOAD_GRID + [(0, 0, 0, 40.0, -30.0), (200.0, 100.0, 0.0, -80.0, 0.0)]:
        eq = static.solve_equilibrium(MRB35, load, calibration)
        f = static.load_vector(load)
        # residual recomputed independently from the forward map
        r = static.load_at_displacement(MRB35, eq.displacement_q, calibration) - f
        gross = np.abs(eq.gradients).T @ eq.roller_load_n + np.abs(f)
        assert np.max(np.abs(r) / gross) < 1e-9, load
        assert eq.iterations < 30


def test_downward_load_compresses_upper_rows():
    """F_V > 0 presses the carriage onto the rail: rows 1, 2 (n_y = +sin b) carry it."""
    eq = static.solve_equilibrium(MRB35, (500.0, 0.0, 0.0))
    q_row = {r: eq.roller_load_n[eq.row == r] for r in range(1, 5)}
    q_pre = float(static.roller_force(DELTA, MRB35))
    assert np.all(q_row[1] > q_pre) and np.all(q_row[2] > q_pre)
    assert np.all(q_row[3] < q_pre) and np.all(q_row[4] < q_pre)
    assert eq.displacement_q[1] < 0  # the carriage moves down, delta_V > 0
    assert static.tangent_stiffness(MRB35, (500.0, 0.0, 0.0)).delta_V > 0
    # vertical balance: 2 Z sin b (Q_upper - Q_lower) = F_V
    vertical = math.sqrt(0.5) * (q_row[1].sum() + q_row[2].sum() - q_row[3].sum() - q_row[4].sum())
    assert vertical == pytest.approx(500.0, rel=1e-9)
    # pulling the carriage off the rail loads the lower rows
    up = static.solve_equilibrium(MRB35, (-500.0, 0.0, 0.0))
    assert np.all(up.roller_load_n[up.row == 3] > q_pre) and np.all(up.roller_load_n[up.row == 1] < q_pre)


def test_three_component_load_equals_generalised_force():
    a = static.solve_equilibrium(MRB35, (800.0, -150.0, 12.0))
    b = static.solve_equilibrium(MRB35, (-150.0, -800.0, 0.0, 0.0, 12.0))
    assert a.displacement_q == pytest.approx(b.displacement_q, rel=1e-12, abs=1e-20)


def test_lateral_load_reversal_mirrors_solution():
    pos = static.solve_equilibrium(MRB35, (400.0, 700.0, 0.0))
    neg = static.solve_equilibrium(MRB35, (400.0, -700.0, 0.0))
    mirror = np.array([-1.0, 1.0, 1.0, -1.0, -1.0])  # x -> -x: u, psi, phi change sign
    assert neg.displacement_q == pytest.approx(mirror * pos.displacement_q, rel=1e-9, abs=1e-18)
    swap = {1: 2, 2: 1, 3: 4, 4: 3}
    for r in range(1, 5):
        assert neg.roller_load_n[neg.row == r] == pytest.approx(pos.roller_load_n[pos.row == swap[r]], rel=1e-9)
    sp, sn = static.tangent_stiffness(MRB35, (400.0, 700.0, 0.0)), static.tangent_stiffness(MRB35, (400.0, -700.0, 0.0))
    assert (sn.K_V, sn.K_H, sn.K_gamma) == pytest.approx((sp.K_V, sp.K_H, sp.K_gamma), rel=1e-9)


# --------------------------------------------------------------------------- lift-off and limits


@pytest.mark.parametrize("calibration, expected", [("nominal", 1070.6), ("law", 3281.9)])
def test_rows_lift_off_at_2_z_sinb_q_of_twice_preload(calibration, expected):
    """Rows 3, 4 unload when delta_V = Delta / sin b; rows 1, 2 then carry Q(2 Delta).

    The physics notes' "rows lose contact at about F_V = 3.3 kN" is the law
    calibration; with the nominal calibration (K_n = 2.5754e7 N/m) it is 1.07 kN,
    in line with the notes' "softens sharply above roughly 1 kN".
    """
    by_hand = 2 * Z * math.sqrt(0.5) * float(static.roller_force(2 * DELTA, MRB35, calibration))
    assert by_hand == pytest.approx(expected, abs=0.1)
    lift = static.lift_off_load(MRB35, (1.0, 0.0, 0.0), calibration)
    assert lift == pytest.approx(by_hand, rel=1e-8)
    assert static.solve_equilibrium(MRB35, (0.99 * lift, 0, 0), calibration).rows_lifted == ()
    assert static.solve_equilibrium(MRB35, (1.01 * lift, 0, 0), calibration).rows_lifted == (3, 4)
    q = static.solve_equilibrium(MRB35, (lift, 0, 0), calibration).displacement_q
    assert -q[1] == pytest.approx(DELTA / math.sqrt(0.5), rel=1e-7)


def test_vertical_stiffness_falls_until_lift_off_then_rises():
    """Concave law (K ~ delta^(1/9)): unloading rows lose more than loaded rows gain."""
    lift = static.lift_off_load(MRB35, (1.0, 0.0, 0.0), "law")
    frame = static.load_deflection(MRB35, "V", max_load=2 * lift, n=41, calibration="law")
    k = frame["K_V_n_per_m"].to_numpy()
    before = frame["F_V_n"].to_numpy() < lift
    assert np.all(np.diff(k[before]) < 0)
    assert np.all(np.diff(k[~before]) > 0)
    # at lift-off: 2 Z K(2 Delta) sin^2 b = 2^(1/9) / 2 of the zero-load value
    assert k[before][-1] > 2 ** (1 / 9) / 2 * k[0]


def test_full_lift_off_leaves_a_mechanism_and_is_refused():
    eq = static.solve_equilibrium(MRB35, (1500.0, 0.0, 0.0))
    assert eq.rows_lifted == (3, 4)
    with pytest.raises(ModelError) as err:
        static.tangent_stiffness(MRB35, (1500.0, 0.0, 0.0))
    message = str(err.value)
    assert "\n" not in message and "F_V=1500 N" in message and "rows lifted off: 3, 4" in message


@pytest.mark.parametrize("load", [(1e9, 0.0, 0.0), (0.0, 2e5, 0.0), (0.0, 0.0, 1e5), (150e3, 0.0, 0.0)])
def test_excessive_load_is_one_line_model_error(load):
    with pytest.raises(ModelError) as err:
        static.solve_equilibrium(MRB35, load)
    message = str(err.value)
    assert "\n" not in message and message.startswith("load (") and "capacity" in message


def test_load_no_roller_resists_is_refused():
    single = MRB35.with_changes(rollers_per_row=1, roller_span_m=0.0)
    with pytest.raises(ModelError, match="no roller can resist"):
        static.solve_equilibrium(single, (0.0, 0.0, 0.0, 5.0, 0.0))


@pytest.mark.parametrize("bad", [(1.0, 2.0), (1.0, math.nan, 0.0), "abc", (1, 2, 3, 4)])
def test_bad_load_shape_is_refused(bad):
    with pytest.raises(ModelError, match="load"):
        static.solve_equilibrium(MRB35, bad)


# --------------------------------------------------------------------------- properties

LIFT = {d: static.lift_off_load(MRB35, u, "nominal")
        for d, u in (("V", (1, 0, 0)), ("H", (0, 1, 0)), ("gamma", (0, 0, 1)))}


@settings(max_examples=60, deadline=None)
@given(st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1), st.sampled_from(["nominal", "law"]))
def test_tangent_symmetric_positive_definite_before_lift_off(a, b, c, calibration):
    # |a| + |b| + |c| <= 0.9 of each direction's lift-off load: no roller loses contact
    total = max(abs(a) + abs(b) + abs(c), 1.0) / 0.9
    load = (a / total * LIFT["V"], b / total * LIFT["H"], c / total * LIFT["gamma"])
    st_ = static.tangent_stiffness(MRB35, load, calibration)
    k = st_.tangent_matrix
    assert k == pytest.approx(k.T, rel=1e-12, abs=1e-12 * np.abs(k).max())
    d = 1 / np.sqrt(np.diag(k))
    assert np.linalg.eigvalsh(k * d[:, None] * d[None, :])[0] > 1e-6
    assert 0 < st_.K_H_free <= st_.K_H * (1 + 1e-12) and 0 < st_.K_gamma_free <= st_.K_gamma * (1 + 1e-12)


@settings(max_examples=40, deadline=None)
@given(st.floats(-4000, 4000), st.floats(-3000, 3000), st.floats(-80, 80))
def test_equilibrium_balances_the_load(fv, fh, m):
    eq = static.solve_equilibrium(MRB35, (fv, fh, m), "law")
    f = static.load_vector((fv, fh, m))
    balance = f + eq.gradients.T @ eq.roller_load_n
    assert np.max(np.abs(balance) / (np.abs(eq.gradients).T @ eq.roller_load_n + np.abs(f))) < 1e-9
    assert np.all(eq.roller_load_n >= 0)
    assert np.all((eq.approach_m > 0) == (eq.roller_load_n > 0))


# --------------------------------------------------------------------------- curves and sweeps


def test_load_deflection_frame_and_plot(tmp_path):
    frames = {d: static.load_deflection(MRB35, d, n=9) for d in ("V", "H", "gamma")}
    v = frames["V"]
    assert list(v.columns) == ["F_V_n", "delta_V_m", "K_V_n_per_m", "K_V_free_n_per_m", "n_rows_lifted",
                               "n_rollers_unloaded"]
    assert v.attrs["lift_off_load"] == pytest.approx(LIFT["V"])
    assert v["F_V_n"].iloc[-1] == pytest.approx(2 * LIFT["V"])  # default range: twice the lift-off load
    assert v["n_rows_lifted"].iloc[0] == 0 and v["n_rows_lifted"].iloc[-1] == 2
    assert np.all(np.diff(v["delta_V_m"]) > 0)
    assert list(frames["gamma"].columns[:3]) == ["M_gamma_nm", "gamma_rad", "K_gamma_nm_per_rad"]
    out = tmp_path / "fig3.png"
    static.plot_load_deflection(frames, out)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_load_deflection_rejects_bad_direction():
    with pytest.raises(ModelError, match="direction 'X': allowed V, H, gamma"):
        static.load_deflection(MRB35, "X")


def test_sweep_columns_and_zero_load_frequencies():
    frame = static.sweep(MRB35, n=5)
    for col in ("load_n", "K_V_n_per_m", "K_H_n_per_m", "K_gamma_nm_per_rad", "f_vertical_hz", "f_roll_low_hz",
                "f_roll_high_hz", "f_pitch_hz", "f_yaw_hz", "rows_lifted", "n_rows_lifted"):
        assert col in frame.columns
    assert frame.columns[0] == "load_n"
    assert frame["load_n"].iloc[-1] == pytest.approx(0.9 * LIFT["V"])
    assert frame["f_vertical_hz"].iloc[0] == pytest.approx(3529.0, abs=0.5)
    assert np.all(np.diff(frame["f_vertical_hz"]) < 0)  # the preloaded joint softens under load
    assert set(frame["rows_lifted"]) == {""}


def test_sweep_along_a_direction_and_a_moment():
    lateral = static.sweep(MRB35, direction_load=(0.0, -400.0, 0.0), n=3)
    assert lateral["load_n"].tolist() == pytest.approx([0.0, -200.0, -400.0])
    moment = static.sweep(MRB35, [(0.0, 0.0, 0.0), (0.0, 0.0, 10.0)])
    assert moment.columns[0] == "load_nm"
