"""One modal model for the whole test (issue 13): guidefit.modes.globalfit and guidefit.modal_stage.

Truth comes from two places: synthetic pole-residue FRFs written down here
(poles, residues, noise, window shift all known), and seeded
``guidefit.simulate`` recordings of the MRB35 carriage with coupling effects
(their truth file holds the modal table of the model with the effects).
Targets of the issue: every carriage mode within 0.05 % in f and 2 % in
zeta, and |error| <= 3 reported std.
"""

from __future__ import annotations

import json
import math
import warnings
from types import SimpleNamespace

import numpy as np
import pytest

from guidefit import modal_stage
from guidefit.identify import IdentifySettings, identify
from guidefit.modes import globalfit

CARRIAGE = ("yaw", "pitch", "roll_low", "vertical", "roll_high")


def _accelerance(f, poles_hz_zeta, constants, shift=0.0):
    """(F, R) accelerance of modes with modal constants (R,) each; ``shift`` (1/s): that of an exponential window
    e^{-shift t} on force and response, H(s + shift) (Laplace shift theorem)."""
    s = 2j * np.pi * np.asarray(f)[:, None] + shift
    H = np.zeros((len(f), len(constants[0])), complex)
    for (fn, z), c in zip(poles_hz_zeta, constants):
        wn = 2 * np.pi * fn
        p = wn * (-z + 1j * math.sqrt(1 - z * z))
        A = np.asarray(c) / (2j * p.imag)
        H += s * s * (A / (s - p) + np.conj(A) / (s - np.conj(p)))
    return H


def _frfset(name, f, H, tau=None):
    return SimpleNamespace(run=name, frequency_hz=f, H=H, channels=tuple(f"acc_{k}" for k in range(H.shape[1])),
                           exp_window_tau_s=tau, n_groups=0, group_sums={})


def test_polymax_separates_two_modes_1p5_percent_apart_without_a_model():
    """Two references excite the close pair differently: both stabilise and are selected, no model used."""
    f = np.arange(1000.0, 4000.0, 5.0)
    modes = [(2000.0, 0.02), (2030.0, 0.03), (3000.0, 0.10)]
    a = _accelerance(f, modes, [[0.5, 0.2, -0.3], [0.1, -0.4, 0.3], [0.3, 0.3, 0.3]])
    b = _accelerance(f, modes, [[-0.2, 0.4, 0.1], [0.5, 0.1, 0.2], [0.2, -0.3, 0.3]])
    rng = np.random.default_rng(1)
    a, b = (x + 1e-3 * np.abs(x).mean() * (rng.normal(size=x.shape) + 1j * rng.normal(size=x.shape)) for x in (a, b))
    H = np.hstack([a, b])
    diagram = globalfit.lscf_stabilisation(f, H, references=np.stack([a, b], axis=2))
    chosen = globalfit.select_poles(diagram).chosen
    assert len(chosen) == 3
    for c, (fn, z) in zip(chosen, modes):
        assert c.frequency_hz == pytest.approx(fn, rel=2e-3)
        assert c.damping_ratio == pytest.approx(z, rel=0.1)
    assert diagram.stable.sum() < diagram.orders.size  # the diagram also holds unstable (computational) poles


def test_noise_alone_gives_no_physical_pole():
    """Stability, not amplitude, selects: white noise beside one mode adds no selected pole."""
    f = np.arange(500.0, 3000.0, 5.0)
    H = _accelerance(f, [(1500.0, 0.02)], [[0.4, -0.2]])
    rng = np.random.default_rng(2)
    H = H + 0.02 * np.abs(H).mean() * (rng.normal(size=H.shape) + 1j * rng.normal(size=H.shape))
    chosen = globalfit.select_poles(globalfit.lscf_stabilisation(f, H)).chosen
    assert [round(c.frequency_hz) for c in chosen] == [1500]


def test_global_fit_undoes_each_runs_exponential_window_and_covers_truth():
    """Runs windowed differently (poles shifted by -1/tau in one run) share one set of true poles."""
    f = np.arange(800.0, 6000.0, 10.0)
    modes = [(1879.0, 0.02), (2496.0, 0.105), (3529.0, 0.029)]
    tau = 0.05
    rng = np.random.default_rng(3)
    runs = {}
    for name, shift, consts in (("vertical", 1 / tau, [[0.1, 0.1], [0.05, -0.05], [0.45, 0.45]]),
                                ("lateral", 0.0, [[0.3, -0.3], [0.5, 0.5], [0.01, 0.01]])):
        H = _accelerance(f, modes, consts, shift)
        H = H + 2e-3 * np.abs(H).mean() * (rng.normal(size=H.shape) + 1j * rng.normal(size=H.shape))
        runs[name] = _frfset(name, f, H, tau if shift else None)
    gf = globalfit.global_fit(runs, (900.0, 5000.0), jackknife=False)
    assert len(gf.modes) == 3
    for m, (fn, z) in zip(gf.modes, modes):
        assert abs(m.frequency_hz / fn - 1) < 5e-4 and abs(m.damping_ratio / z - 1) < 0.02
        assert abs(m.frequency_hz - fn) <= 3 * m.frequency_std_hz
        assert abs(m.damping_ratio - z) <= 3 * m.damping_std
    # residues: each run's modal constants come back (the vertical run's windowed FRF included)
    assert np.real(gf.run_mode(2, "vertical").modal_constants) == pytest.approx([0.45, 0.45], rel=0.02)


# --------------------------------------------------------------------------- simulated recordings


_CASES = {
    "corner": ["added_mass:mass_kg=0.3,at=A"],
    "row": ["row_damage:row=1,factor=0.5"],
    "close": ["base_mode:mass_kg=1,vertical_n_per_m=1.022e9"],  # vertical 1.5 % above pitch
    "base": ["base_mode:mass_kg=3,lateral_n_per_m=3e8,vertical_n_per_m=1e9"],
}


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """Lazily simulated recordings: case -> (path, truth); 4 hits of 0.05 s per run, seed 1."""
    from guidefit.io import write_recording
    from guidefit.model.effects import parse_effect
    from guidefit.simulate import SimulationConfig, simulate

    folder = tmp_path_factory.mktemp("global")
    cache = {}

    def get(case, **config):
        key = (case, tuple(sorted(config.items())))
        if key not in cache:
            cfg = SimulationConfig(**{"hits": 4, "record_s": 0.05, **config})
            data, truth = simulate("MRB35", effects=[parse_effect(e) for e in _CASES.get(case, [])], config=cfg,
                                   seed=1)
            path = folder / f"{case}_{len(cache)}.h5"
            write_recording(path, data)
            cache[key] = (path, truth, data)
        return cache[key]

    return get


def _identify(path, **settings):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return identify(path, settings=IdentifySettings(**settings))


@pytest.mark.parametrize("case", ["corner", "row", "close"])
def test_coupled_cases_meet_accuracy_and_three_std(recorded, case):
    """The issue's coupled cases: per-run fits were 0.3-2.1 % off in f_H with a 30-70x too small std."""
    path, truth, _ = recorded(case)
    result = _identify(path)
    got = {m.label: m for m in result.modes}
    for t in truth["modes"]:
        if t["label"] not in CARRIAGE:
            continue
        m = got[t["label"]]
        ef, ez = m.frequency_hz - t["frequency_hz"], m.damping_ratio - t["damping_ratio"]
        assert abs(ef) <= 5e-4 * t["frequency_hz"] and abs(ez) <= 0.02 * t["damping_ratio"], (t, m)
        assert abs(ef) <= 3 * m.frequency_std_hz and abs(ez) <= 3 * m.damping_std, (t, m)
    # K and c std propagate from f and zeta (Eq. 24-29)
    p = result.parameters
    assert p["K_V"]["std"] == pytest.approx(2 * p["K_V"]["value"] * p["f_V"]["std"] / p["f_V"]["value"], rel=1e-9)
    assert p["c_H"]["std"] > 0


def test_base_body_modes_are_extra_not_carriage_modes(recorded):
    """A heavy base adds two modes that move the carriage: the carriage-energy share tells them apart."""
    path, truth, _ = recorded("base")
    result = _identify(path, jackknife=False)
    t = {m["label"]: m["frequency_hz"] for m in truth["modes"]}
    got = {m.label: m.frequency_hz for m in result.modes}
    assert set(got) == set(CARRIAGE)
    for label in CARRIAGE:
        assert got[label] == pytest.approx(t[label], rel=5e-4)
    extra = sorted(m.frequency_hz for m in result.extra_modes)
    assert extra == pytest.approx(sorted([t["support_1"], t["support_2"]]), rel=5e-4)
    v = next(m for m in result.modes if m.label == "vertical")
    base_v = min(result.extra_modes, key=lambda m: abs(m.frequency_hz - t["support_2"]))
    assert v.carriage_energy > base_v.carriage_energy


def test_lateral_mode_seen_only_by_y_sensors_is_roll_low_not_pitch(recorded):
    """Was: labelled from y-only sensors, the lateral mode was called pitch and pitch became extra; then it was
    'ambiguous'. The model seen through the y sensors (x phi) and the off-centre vertical hit names it roll_low,
    and the result says what decided it."""
    path, truth, _ = recorded("clean_y", runs=_vertical_run(), axes="y")
    result = _identify(path, jackknife=False)
    labels = {m.label: m for m in result.modes}
    t = {m["label"]: m["frequency_hz"] for m in truth["modes"]}
    assert labels["pitch"].frequency_hz == pytest.approx(t["pitch"], rel=1e-4)
    assert labels["roll_low"].frequency_hz == pytest.approx(t["roll_low"], rel=1e-3)
    assert labels["roll_low"].label_basis in ("shape", "frequency", "shape+frequency")
    assert not [m for m in result.extra_modes if abs(m.frequency_hz / t["roll_low"] - 1) < 0.01]


def _vertical_run():
    from guidefit.simulate import DEFAULT_RUNS

    return (DEFAULT_RUNS[0],)


def test_runs_at_two_hit_forces_keep_their_own_estimates(recorded, tmp_path):
    """Runs differing only in hit force are not dropped: each keeps its f and zeta (modes[].estimates,
    run_modes), and the force bins within a run keep theirs (force_levels with damping)."""
    from dataclasses import replace

    from guidefit.io import RecordingData, write_recording

    _, truth, soft = recorded("clean", force_n=(60.0, 120.0), hits=6)
    _, _, hard = recorded("clean", force_n=(400.0, 800.0), hits=6)
    runs = (replace(soft.runs[0], name="vertical_soft"), replace(hard.runs[0], name="vertical_hard"),
            soft.runs[1])
    path = tmp_path / "two_forces.h5"
    write_recording(path, RecordingData(runs, guide="MRB35"))
    result = _identify(path, force_levels=True, force_bins=2)
    v = next(m for m in result.modes if m.label == "vertical")
    f_true = next(m["frequency_hz"] for m in truth["modes"] if m["label"] == "vertical")
    per_run = {e["run"]: e for e in v.estimates}
    assert {"vertical_soft", "vertical_hard"} <= set(per_run)
    for e in (per_run["vertical_soft"], per_run["vertical_hard"]):
        assert abs(e["frequency_hz"] - f_true) <= max(3 * e["frequency_std_hz"], 5e-4 * f_true)
    doc = json.loads(json.dumps(result.to_dict()))
    assert {(r["label"], r["run"]) for r in doc["run_modes"]} >= {("vertical", "vertical_soft"),
                                                                   ("vertical", "vertical_hard")}
    assert doc["modes"][0]["level"] is None and "estimates" in doc["modes"][0]
    levels = [lv for lv in doc["force_levels"] if lv["label"] == "vertical" and lv["frequency_hz"] is not None]
    assert {lv["level"] for lv in levels} == {0, 1}
    assert all(0 < lv["damping_ratio"] < 0.1 for lv in levels)


def test_modal_stage_starts_from_frf_sets(recorded):
    """identify_frfs takes FRF sets and channel geometry (what an FRF file gives) and finds the same modes."""
    from guidefit.identify import run_frfs
    from guidefit.io import read_recording
    from guidefit.model.guides import load_guide

    path, truth, _ = recorded("corner")
    settings = IdentifySettings(jackknife=False)
    collected = run_frfs(read_recording(path), settings).collected
    frf_by_run = {run.name: frf for run, frf, _ in collected}
    geometry = {run.name: modal_stage.geometry_of(run, frf) for run, frf, _ in collected}
    res = modal_stage.identify_frfs(frf_by_run, geometry, load_guide("MRB35"), settings)
    assert [m.label for m in res.modes] == [m["label"] for m in truth["modes"]]
    assert len(res.fit.diagram.orders) > 0 and res.fit.selection.chosen
    for m in res.modes:
        assert set(m.std_parts) == {"fit", "jackknife", "selection", "estimator"}


def test_exponential_window_is_modelled_exactly_on_a_simulated_recording(recorded):
    """Heavy base, no sensor noise, both runs under a 0.05 s exponential window: the windowed FRF is H(s + 1/tau)
    (accelerance factor and residual terms included). Moving only the poles by -1/tau left the vertical mode
    2.4e-5 (relative) low (3-4 reported std on the noisy recordings of bench_global), roll_low 9e-5, yaw's zeta
    6.5e-4 off; modelled exactly, every mode of the truth is within 2.2e-6 in f and 2e-5 in zeta (band edges)."""
    from guidefit.frf import WindowSettings
    from guidefit.identify import frf_of_recording

    path, truth, _ = recorded("base", noise_fraction=0.0, adc_bits=None, hits=2)
    frfs, _ = frf_of_recording(path, IdentifySettings(window=WindowSettings(exp_tau_s=0.05)))
    assert all(x.exp_window_tau_s == pytest.approx(0.05) for x in frfs)
    gf = globalfit.global_fit({f"r{i}": x for i, x in enumerate(frfs)}, (658.0, 7233.0), jackknife=False,
                              selection_spread=False)
    for t in truth["modes"]:
        m = min(gf.modes, key=lambda m: abs(m.frequency_hz - t["frequency_hz"]))
        assert abs(m.frequency_hz / t["frequency_hz"] - 1) < 1e-5, (t, m)
        assert abs(m.damping_ratio / t["damping_ratio"] - 1) < 1e-4, (t, m)
    # what --plot draws over the measured FRFs: the model through the run's window fits them (noise-free
    # data: to the fit's own misfit), the system's own FRF does not (the window's 1/tau of extra damping)
    for i, x in enumerate(frfs):
        at = np.searchsorted(x.frequency_hz, gf.frequency_hz)
        measured = np.asarray(x.H)[at]
        size = np.linalg.norm(measured)
        windowed = np.linalg.norm(gf.synthesize(f"r{i}", x.exp_window_tau_s) - measured) / size
        own = np.linalg.norm(gf.synthesize(f"r{i}") - measured) / size
        assert windowed < 1e-3 and own > 0.01, (windowed, own)  # measured: 8e-7, 5e-5 against 0.030, 0.035


def test_modal_stage_runs_with_one_blas_thread_and_restores_the_setting():
    """The small matrices of the global fit gain nothing from BLAS threads and lose much on a busy
    machine: inside ``one_blas_thread`` every BLAS library reports one thread, after it the setting
    it had before."""
    threadpoolctl = pytest.importorskip("threadpoolctl")
    before = [p["num_threads"] for p in threadpoolctl.threadpool_info() if p["user_api"] == "blas"]
    if not before:
        pytest.skip("no BLAS library loaded that threadpoolctl can see")
    with globalfit.one_blas_thread():
        inside = [p["num_threads"] for p in threadpoolctl.threadpool_info() if p["user_api"] == "blas"]
    after = [p["num_threads"] for p in threadpoolctl.threadpool_info() if p["user_api"] == "blas"]
    assert inside == [1] * len(before)
    assert after == before


def test_a_band_too_narrow_for_the_high_orders_ends_the_diagram_not_the_run(monkeypatch):
    """An order whose LSCF basis is numerically singular (a narrow band at a high order) ended identify
    with a bare LinAlgError; the diagram now stops at the last order the band supports, and a band too
    narrow for the first order is one IdentificationError."""
    from guidefit.errors import IdentificationError

    f = np.linspace(0.0, 10_000.0, 20_001)
    s = 2j * np.pi * f
    pole = 2 * np.pi * 5000.0 * (-0.02 + 1j)
    H = (1 / (s - pole) + 1 / (s - np.conj(pole)))[:, None] * np.array([1.0, 0.5])[None, :]
    real = globalfit._lscf_poles

    def singular_from(order):
        def poles(R, S, T, n, m, ts):
            if n >= order:
                raise np.linalg.LinAlgError(f"LSCF: the order-{n} basis Gram matrix is not positive definite")
            return real(R, S, T, n, m, ts)
        return poles

    monkeypatch.setattr(globalfit, "_lscf_poles", singular_from(20))
    diagram = globalfit.lscf_stabilisation(f, H, band_hz=(4000.0, 6000.0))
    assert diagram.orders.size and diagram.orders.max() < 20  # ended below the singular orders
    assert np.any(np.abs(diagram.frequency_hz - 5000.0) < 5.0)  # and still holds the mode
    monkeypatch.setattr(globalfit, "_lscf_poles", singular_from(0))
    with pytest.raises(IdentificationError, match="widen the band"):
        globalfit.lscf_stabilisation(f, H, band_hz=(4000.0, 6000.0))
