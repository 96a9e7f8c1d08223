"""Force levels for explain: identify's narrow-band refits and how explain uses them.

Truth written down by hand: pole-residue FRFs synthesised from known modes
(:func:`guidefit.modes.synthesize`), a frequency law ``f0 - c F^2``, shapes
with a known perpendicular perturbation.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from guidefit.explain import ForceLevel, MeasuredMode, _level_shape_scatter, effective_force, explain_modes
from guidefit.identify_runs import _refit_in_band, _refit_one
from guidefit.modes import Mode, synthesize


def _mode(f_hz, zeta, constants):
    """A Mode from real modal constants (1/kg) per channel."""
    wd = 2 * math.pi * f_hz * math.sqrt(1 - zeta**2)
    return Mode(f_hz, zeta, np.asarray(constants, complex) / (2j * wd), "curve_fit")


def _frf(modes):
    f = np.arange(500.0, 7000.0, 20.0)
    return SimpleNamespace(frequency_hz=f, H=synthesize(f, modes))


#: a weak 2 %-damped mode 9 % below a strong 10 %-damped one (MRB35's pitch and roll_low in a vertical run)
PAIR = [_mode(2275.9, 0.02, [0.05, 0.02]), _mode(2496.5, 0.105, [1.0, -0.8])]
FAR = _mode(3529.0, 0.029, [0.3, 0.6])  # a strong mode far above (the vertical mode)


def test_narrow_refit_is_not_pulled_by_a_damped_neighbour():
    frf = _frf(PAIR)
    weak = PAIR[0]
    alone = _refit_one(frf, weak)  # its +/- 6 % band cuts through the neighbour's flank
    assert alone.frequency_hz / weak.frequency_hz - 1 > 0.03
    fit, band = _refit_in_band(frf, weak, [(m, "x") for m in PAIR])
    assert band[0] < weak.frequency_hz < band[1]
    assert fit.frequency_hz == pytest.approx(weak.frequency_hz, rel=1e-9)
    assert fit.damping_ratio == pytest.approx(weak.damping_ratio, rel=1e-6)
    # a distant mode is left to the residual terms, as in any narrow-band fit: a truncation error well
    # below the 0.1 % floor of a force level
    fit, _ = _refit_in_band(_frf(PAIR + [FAR]), weak, [(m, "x") for m in PAIR + [FAR]])
    assert fit.frequency_hz == pytest.approx(weak.frequency_hz, rel=3e-4)


def test_refit_that_moves_by_more_than_its_bandwidth_is_rejected():
    wrong = _mode(2150.0, 0.005, [0.05, 0.02])  # the real mode is at 2275.9 Hz, beyond zeta f = 11 Hz
    fit, band = _refit_in_band(_frf(PAIR), wrong, [(PAIR[1], "x")])
    assert band[0] < 2150.0 < band[1] and fit is None


def test_effective_force_gives_the_h1_weighted_frequency_of_a_quadratic_drop():
    f0, c = 3430.0, 4e-7  # Hz, Hz/N^2
    forces = np.array([120.0, 260.0, 410.0, 590.0])
    h1 = np.sum(forces**2 * (f0 - c * forces**2)) / np.sum(forces**2)  # H1 weights each hit by F^2
    assert f0 - c * effective_force(forces) ** 2 == pytest.approx(h1, rel=1e-12)
    assert effective_force(forces) > np.mean(forces)


def _levels(run, label, freqs, forces):
    return [ForceLevel(float(np.mean(fs)), label, f, 0.5, run=run, hit_forces_n=tuple(fs))
            for f, fs in zip(freqs, forces)]


def test_mode_is_compared_through_its_own_levels():
    forces = [(100.0, 150.0), (300.0, 350.0), (500.0, 600.0)]
    freqs = [3529.4, 3529.2, 3528.8]
    modes = [MeasuredMode(3527.0, 0.5, label="vertical", run="vertical")]
    result = explain_modes(modes, "MRB35", force_levels=_levels("vertical", "vertical", freqs, forces),
                           candidates=["contact_stiffness"])
    w = np.array([np.sum(np.square(fs)) for fs in forces])
    row = result.modes[0]
    assert row["measured_hz"] == pytest.approx(np.sum(w * freqs) / np.sum(w), rel=1e-12)
    assert row["identified_hz"] == 3527.0
    assert any("narrow-band refits" in n for n in result.notes)


def test_mode_that_no_force_bin_reproduces_is_left_out():
    modes = [MeasuredMode(3529.0, 0.5, label="vertical", run="vertical"),
             MeasuredMode(2202.0, 3.7, label="pitch", run="lateral")]
    levels = [ForceLevel(200.0, "pitch", None, None, run="lateral"), ForceLevel(500.0, "pitch", None, None, run="lateral")]
    result = explain_modes(modes, "MRB35", force_levels=levels, candidates=["contact_stiffness"])
    status = {m["label"]: m["status"] for m in result.modes}
    assert status == {"vertical": "paired", "pitch": "left out"}
    assert result.verdict == "adequate"


def test_shape_scatter_over_force_bins():
    unit = np.array([1.0, -1.0, 1.0, -1.0]) / 2.0
    perp = np.array([1.0, 1.0, -1.0, -1.0]) / 2.0  # unit, orthogonal to unit
    mode = MeasuredMode(2202.0, 1.0, label="pitch", run="lateral", shape=dict(zip("abcd", unit)))
    same = [ForceLevel(300.0, "pitch", 2202.0, 1.0, run="lateral", shape=dict(zip("abcd", unit)))] * 2
    assert _level_shape_scatter(mode, list("abcd"), unit, same) == 0.0
    eps = 0.1
    tilted = [ForceLevel(300.0, "pitch", 2202.0, 1.0, run="lateral", shape=dict(zip("abcd", unit + s * eps * perp)))
              for s in (1, -1)]
    expected = eps / math.sqrt(1 + eps**2) * math.sqrt(4 / 3)  # |perp part| of the unit vector, per channel
    assert _level_shape_scatter(mode, list("abcd"), unit, tilted) == pytest.approx(expected, rel=1e-9)
    other_run = [ForceLevel(300.0, "pitch", 2202.0, 1.0, run="vertical", shape=dict(zip("abcd", perp)))] * 2
    assert _level_shape_scatter(mode, list("abcd"), unit, other_run) == 0.0


def test_runs_that_differ_only_in_hit_force_are_one_trend():
    """Three vertical runs at 100 N, 1 kN and 5 kN, same hit point and direction: one experiment, one trend.

    Each run's mode is predicted at its own run's force; the levels of the
    three runs form one (experiment, label) group whose trend is compared,
    and ``amplitude_dependence`` is tried on it. Without a hit point and
    direction the runs cannot be told to be one test: three single levels,
    no trend.
    """
    from dataclasses import replace

    from guidefit.explain.candidates import level_trend
    from guidefit.explain.data import prepare
    from guidefit.explain.settings import DEFAULT_HITS
    from guidefit.model.guides import load_guide

    guide = load_guide("MRB35")
    point, direction = DEFAULT_HITS["vertical"]
    forces, freqs = (100.0, 1000.0, 5000.0), (3529.0, 3462.0, 2905.0)
    runs = [f"vertical {F:.0f} N" for F in forces]
    modes = [MeasuredMode(f, 0.5, label="vertical", run=r) for f, r in zip(freqs, runs)]
    levels = [ForceLevel(F, "vertical", f, 0.5, hit_position_m=point, hit_direction=direction, run=r)
              for F, f, r in zip(forces, freqs, runs)]
    data = prepare(modes, guide, [], levels, [])
    assert [sorted(g.tolist()) for g in data.lv_groups] == [[0, 1, 2]]
    assert data.mode_levels == [[0], [1], [2]]
    np.testing.assert_allclose(data.mode_force, forces, rtol=1e-12)
    chi2, dof, p = level_trend(data)
    assert chi2 > 100.0
    assert dof == 2 and p < 1e-6
    notes: list = []
    plain = prepare(modes, guide, [], [replace(lv, hit_position_m=None, hit_direction=None) for lv in levels], notes)
    assert plain.lv_f.size == 0 and any("3 force level(s) not used" in n for n in notes)
    result = explain_modes(modes, guide, force_levels=levels, candidates=["amplitude_dependence"])
    assert not any(n.startswith("amplitude_dependence not tried") for n in result.notes)
    assert any(c["name"] == "amplitude_dependence" for c in result.candidates)


def test_a_model_that_cannot_be_evaluated_has_as_many_residuals_as_one_that_can():
    """least_squares needs one length: a failed model (a segment with first > last) with shapes and level groups."""
    from guidefit.explain import synthetic_modes
    from guidefit.explain.data import prepare
    from guidefit.explain.evaluation import Context, evaluate
    from guidefit.model.effects import Effect, make_effect
    from guidefit.model.guides import load_guide
    from guidefit.model.vibration import model_from_guide

    guide = load_guide("MRB35")
    modes, sensors, levels = synthetic_modes(guide, [make_effect("contact_stiffness", {"factor": 0.9})],
                                             forces=(100.0, 600.0, 1500.0))
    data = prepare(modes, guide, sensors, levels, [])
    assert data.lv_groups and data.shapes
    ctx = Context(guide, model_from_guide(guide))
    good = evaluate(ctx, data, [make_effect("contact_stiffness", {"factor": 0.9})])
    bad = evaluate(ctx, data, [Effect("row_segment", {"row": 1, "first": 15.0, "last": 3.0, "factor": 0.5})])
    assert good.ok and not bad.ok
    assert bad.r.shape == good.r.shape
