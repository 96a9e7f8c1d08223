"""The nonlinear-contact forward model (guidefit.nonlinear) on seeded simulated force levels."""

import math

import numpy as np
import pytest

from guidefit.errors import ModelError
from guidefit.nonlinear import (
    ForwardModel,
    apparent_mode,
    fit_levels,
    measure_levels,
    pulse_duration,
    simulate_force_levels,
)


@pytest.fixture(scope="module")
def identification(tmp_path_factory):
    """Three runs of the vertical hit at 100, 1000 and 5000 N (MRB35, nominal preload), identified.

    Short seeded records, two hits per level, the simulator at twice the
    sample rate; identify searches 2.6-4.3 kHz only (the vertical mode) to
    keep the test fast.
    """
    from guidefit.identify import IdentifySettings, identify
    from guidefit.io import write_recording

    path = tmp_path_factory.mktemp("nonlinear") / "levels.h5"
    data, _ = simulate_force_levels("MRB35", ["amplitude_dependence:preload_factor=1"], (100.0, 1000.0, 5000.0),
                                    hits=2, record_s=0.02, seed=3, oversample=2)
    write_recording(path, data)
    return identify(path, settings=IdentifySettings(force_levels=True, f_min_hz=2600.0, f_max_hz=4300.0))


@pytest.fixture(scope="module")
def levels(identification):
    notes = []
    out = measure_levels(identification, notes=notes)
    assert not notes
    return out


def test_levels_follow_contact_loss(levels):
    # one level per run, forces increasing; rows lift off at 5 kN: the apparent frequency falls well below
    # the small-amplitude 3529 Hz, by far more than at 1 kN
    for lv, force in zip(levels, (100.0, 1000.0, 5000.0), strict=True):
        assert abs(lv.peak_force_n / force - 1) < 0.06
    f = [lv.frequency_hz for lv in levels]
    # the apparent frequency is the peak's centroid: above f_n by the accelerance peak's offset and the
    # exponential window's extra damping, a few tenths of a percent
    assert 0 < f[0] / 3529.0 - 1 < 5e-3
    assert 0 < f[0] - f[1] < f[1] - f[2]
    assert f[2] < 0.95 * f[0]
    assert all(math.isclose(lv.setup.pulse_s, 1e-4, rel_tol=0.02) for lv in levels)


def test_levels_need_the_time_data(identification):
    # identified from FRFs (no Recording with hits): no force levels, one line saying why
    from dataclasses import replace

    from guidefit.errors import RecordingError

    with pytest.raises(RecordingError, match="no time data: force levels need the hits"):
        measure_levels(replace(identification, recording=None))


def test_forward_model_reproduces_the_simulation(levels):
    # at the true preload the forward model (fewer hits, lower rate, no noise) predicts every level
    # within its uncertainty
    fm = ForwardModel("MRB35", levels, n_hits=2)
    pred = fm.predict(1.0)
    for lv, p in zip(levels, pred):
        assert abs(p.frequency_hz - lv.frequency_hz) < 2 * lv.sigma_hz()
    # a lower preload predicts a lower frequency at 5 kN (more contact loss)
    assert fm.predict(0.7)[2].frequency_hz < pred[2].frequency_hz - 10.0


def test_fit_recovers_the_preload(levels):
    fit = fit_levels(levels, "MRB35", fit_kn=False, n_hits=2)
    assert abs(fit.preload_factor - 1.0) < 0.05
    assert 0 < fit.preload_std < 0.05
    assert abs(fit.preload_factor - 1.0) < 4 * fit.preload_std + 0.01
    assert fit.within_uncertainty


def test_fit_needs_two_levels(levels):
    with pytest.raises(ModelError, match="at least 2"):
        fit_levels(levels[:1], "MRB35")


def test_apparent_mode_and_pulse():
    f = np.linspace(2000.0, 3000.0, 401)
    s = 2j * np.pi * f
    w, z = 2 * np.pi * 2500.0, 0.05
    p = complex(-z * w, w * math.sqrt(1 - z * z))
    H = s**2 * (1 / (s - p) + 1 / (s - np.conj(p)))
    fit = apparent_mode(f, np.column_stack([H, 0.5 * H]), (2200.0, 2800.0))
    assert fit.frequency_hz == pytest.approx(2500.0, rel=1e-6)
    assert fit.damping_ratio == pytest.approx(0.05, rel=1e-4)
    t = np.arange(200) / 200e3
    force = np.where(t < 2e-4, 80.0 * np.sin(np.pi * t / 2e-4), 0.0)
    assert pulse_duration(force, 200e3) == pytest.approx(2e-4, rel=0.01)


def test_explain_names_amplitude_dependence(identification, levels, monkeypatch):
    # the done-when case, small: explain (amplitude_dependence against the global stiffness scale and the
    # vertical support that were its rivals) names the preload within 5 %, and the fitted preload
    # reproduces every level within its uncertainty; the levels' hits come from the recording identify
    # read (Identification.recording), the file is not read again
    from guidefit.explain import explain_identification

    def no_second_read(*args, **kwargs):
        raise AssertionError("explain read the recording again")

    monkeypatch.setattr("guidefit.io.registry.read_recording", no_second_read)
    monkeypatch.setattr("guidefit.io.read_recording", no_second_read)

    result = explain_identification(identification, candidates=["amplitude_dependence", "contact_stiffness",
                                                                 "support_compliance"])
    assert result.verdict == "explained"
    (effect,) = result.to_dict()["effects"]
    assert effect["name"] == "amplitude_dependence"
    p = effect["parameters"]["preload_factor"]
    assert abs(p["value"] - 1.0) < 0.05
    assert abs(p["value"] - 1.0) < 3 * p["std"] + 0.01
    assert result.to_dict()["error_after"]["within_uncertainty"]
    assert any("enter through the levels" in n for n in result.notes)
    pred = ForwardModel("MRB35", levels, n_hits=2).predict(p["value"])
    for lv, x in zip(levels, pred):
        assert abs(x.frequency_hz - lv.frequency_hz) < 2 * lv.sigma_hz()


def test_harder_levels_are_fitted_apart_and_said(identification):
    # the 1 kN and 5 kN runs move f_V (-0.3 %, -18 %): a shared-pole fit would average the levels, so
    # identify fits the 100 N run alone, says why for each harder run, and keeps their hits and FRFs for
    # explain's force-level model (identify._levels_agree)
    runs = {r.name: r for r in identification.runs}
    assert set(runs) == {"vertical_100N", "vertical_1000N", "vertical_5000N"}
    said = [w for w in identification.warnings if "left out of the shared-pole fit" in w]
    assert len(said) == 2 and all(("1000N" in w) != ("5000N" in w) for w in said)
    assert runs["vertical_5000N"].modes == [] and runs["vertical_5000N"].hits
    v = next(m for m in identification.modes if m.label == "vertical")
    # the softest level: within the window/noise bias of the small-amplitude 3529.0 Hz, not pulled down
    assert abs(v.frequency_hz / 3529.0 - 1) < 1e-3
