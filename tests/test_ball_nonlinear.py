"""Ball guides in the nonlinear-contact models: the force-level fit and explain's amplitude_dependence
follow the guide's own contact law (Eq. 3 for balls, ``Q ~ delta^(3/2)``, ``K_n ~ delta^(1/2)``), the
law of the static model (:func:`guidefit.model.static.roller_stiffness`), not the roller's 1/9."""

import math
from pathlib import Path

import numpy as np
import pytest

from guidefit import nonlinear
from guidefit.model import static
from guidefit.model.effects import amplitude_dependence as ad
from guidefit.model.guides import load_guide

FOUR_ROW = Path(__file__).resolve().parents[1] / "examples" / "guides" / "ball4_size25.toml"


@pytest.fixture(scope="module")
def ball():
    return load_guide(FOUR_ROW)


def _static_slope(guide, factor: float = 1.01) -> float:
    """d ln K_n / d ln delta of the static model at the guide's preload (central difference)."""
    d = guide.preload_m
    k_hi, k_lo = (float(static.roller_stiffness(d * f, guide)) for f in (factor, 1.0 / factor))
    return math.log(k_hi / k_lo) / (2.0 * math.log(factor))


def test_fit_coordinates_use_the_guides_law(ball):
    # the slope of the fit's coordinate k p^s is the static model's: 1/2 for balls (Eq. 3), 1/9 for rollers
    assert nonlinear.stiffness_slope(ball) == pytest.approx(_static_slope(ball), abs=1e-6)
    assert nonlinear.stiffness_slope(ball) == pytest.approx(0.5, abs=1e-12)
    assert nonlinear.stiffness_slope(load_guide("MRB35")) == pytest.approx(1.0 / 9.0, abs=1e-12)
    fm = nonlinear.ForwardModel(ball, [])
    # (ln p, ln k p^s) -> (p, k) round trip with the ball's slope; with the roller's 1/9 k would come back
    # off by p^(1/2 - 1/9) = 1.31 at p = 2
    p, k = nonlinear._params(np.log([2.0, 0.8 * 2.0**fm.stiffness_slope]), True, 1.0, fm.stiffness_slope)
    assert (p, k) == pytest.approx((2.0, 0.8), rel=1e-12)


def test_forward_model_small_amplitude_follows_the_static_slope(ball):
    # the forward model's linearised frequencies at preload factor p: every mode's f^2 scales as
    # K_n(p Delta) / K_n(Delta) of the static model, p^(1/2) for balls (f ~ p^(1/4))
    fm = nonlinear.ForwardModel(ball, [])
    f1 = fm.small_amplitude_hz(1.0)
    for p in (0.5, 2.0):
        ratio = float(static.roller_stiffness(p * ball.preload_m, ball) / static.roller_stiffness(ball.preload_m, ball))
        assert ratio == pytest.approx(math.sqrt(p), rel=1e-9)
        fp = fm.small_amplitude_hz(p)
        for label in f1:
            assert (fp[label] / f1[label]) ** 2 == pytest.approx(ratio, rel=1e-6), label


def test_nonlinear_model_tangent_is_the_static_law(ball):
    # the simulator's nonlinear contacts (the forward model's hits): at a preload factor p the element
    # tangent stiffness is the static model's K_n(p Delta), and its slope the ball law's 1/2
    from guidefit.model.effects import Effect
    from guidefit.simulate import build_model

    k = {}
    for p in (0.5, 1.0, 2.0):
        model = build_model(ball, [Effect("amplitude_dependence", {"preload_factor": p})], {})
        assert model.contacts.exponent == pytest.approx(1.5, abs=1e-12)
        k[p] = model.spec.rollers.stiffness_n_per_m
    assert np.allclose(k[1.0], static.roller_stiffness(ball.preload_m, ball), rtol=1e-6)
    assert np.allclose(np.log(k[2.0] / k[0.5]) / math.log(4.0), 0.5, atol=1e-6)


@pytest.mark.parametrize("name", ["ball", "MRB35"])
def test_describing_function_below_lift_off_is_the_static_curvature(ball, name):
    # explain's describing function D(r) = k_eq / K_n at a relative amplitude r < 1 is, to O(r^4),
    # 1 + (delta^2 K_n'' / K_n) r^2 / 8 with K_n'' from the static model: 1 - r^2/32 for balls, 1 - r^2/81 rollers
    guide = ball if name == "ball" else load_guide("MRB35")
    d, h = guide.preload_m, 1e-3
    k = [float(static.roller_stiffness(d * (1 + s * h), guide)) for s in (-1, 0, 1)]
    curvature = (k[0] - 2 * k[1] + k[2]) / h**2 / k[1]  # delta^2 K'' / K
    e = static.exponent(guide)
    assert curvature == pytest.approx((e - 1) * (e - 2), rel=1e-4)
    log_r, table = ad.describing_function_table(guide)
    r = np.exp(log_r)
    sel = (r > 0.05) & (r < 0.2)
    expected = 1 + curvature * r[sel] ** 2 / 8
    # the r^4 term: |D - expected| < r^4 / 100 for either law (its coefficient is below 0.002)
    assert np.all(np.abs(table[sel] - expected) < r[sel] ** 4 / 100 + 1e-9)



@pytest.fixture(scope="module")
def ball_levels(ball, tmp_path_factory):
    """Three runs of the vertical hit at 300, 1500 and 4000 N on the 0.6 kg four-row carriage (preload
    6.6 um, nominal), identified; accelerometer range 4 m/s^2 per N so that nothing clips."""
    from guidefit.identify import IdentifySettings, identify
    from guidefit.io import write_recording

    path = tmp_path_factory.mktemp("ball_levels") / "levels.h5"
    data, _ = nonlinear.simulate_force_levels(ball, ["amplitude_dependence:preload_factor=1"], (300.0, 1500.0, 4000.0),
                                              hits=2, record_s=0.02, seed=3, oversample=2, acc_range_per_n=4.0)
    write_recording(path, data)
    return identify(path, guide=ball, settings=IdentifySettings(force_levels=True))


def test_force_level_fit_recovers_a_ball_guides_preload(ball, ball_levels):
    # the forward model with the ball law predicts the levels (the 4 kN level 35 Hz low from contact loss)
    # and the fit of preload and K_n factor recovers both (seeded: p 0.99 +/- 0.06, k 1.004 +/- 0.031)
    notes = []
    levels = nonlinear.measure_levels(ball_levels, notes=notes)
    assert not notes and len(levels) == 3
    f = [lv.frequency_hz for lv in levels]
    assert f[0] - f[2] > 20.0  # contact loss at 4 kN
    fm = nonlinear.ForwardModel(ball, levels, n_hits=1)
    for lv, p in zip(levels, fm.predict(1.0)):
        assert abs(p.frequency_hz - lv.frequency_hz) < 2 * lv.sigma_hz()
    fit = nonlinear.fit_levels(levels, ball, fit_kn=True, n_hits=1, forward=fm)
    assert abs(fit.preload_factor - 1.0) < 3 * fit.preload_std and fit.preload_std < 0.1
    assert abs(fit.kn_factor - 1.0) < 3 * fit.kn_std and fit.kn_std < 0.05
    assert fit.within_uncertainty


def test_explain_names_amplitude_dependence_on_a_ball_guide(ball_levels):
    # explain's amplitude_dependence against its rivals (global stiffness scale, vertical support) on the
    # ball guide's levels: explained, preload within 1 % (seeded: 1.0015 +/- 0.0021)
    from guidefit.explain import explain_identification

    result = explain_identification(ball_levels, candidates=["amplitude_dependence", "contact_stiffness",
                                                              "support_compliance"])
    assert result.verdict == "explained"
    (effect,) = result.to_dict()["effects"]
    assert effect["name"] == "amplitude_dependence"
    p = effect["parameters"]["preload_factor"]
    assert abs(p["value"] - 1.0) < 0.01
    assert abs(p["value"] - 1.0) < 3 * p["std"] + 0.005
    assert result.to_dict()["error_after"]["within_uncertainty"]
