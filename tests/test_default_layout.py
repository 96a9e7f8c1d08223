"""The paper's own test, one axis per run (y at A-D hit vertically, x at A-D hit laterally), beyond the matrix.

Force levels (explain names amplitude_dependence), an accelerometer mounted
upside down and one with its sensitivity 20 % off (each named and corrected,
f_V and f_H unspoilt), and a structure that is not a carriage (refused by
the gate). Small seeded simulations of guidefit's own simulator.
"""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np
import pytest

from guidefit.identify import IdentifySettings, identify
from guidefit.io import RecordingData, RunData, write_recording
from guidefit.simulate import SimulationConfig, simulate

FAST = IdentifySettings(jackknife=False)


@pytest.fixture(scope="module")
def one_axis(tmp_path_factory):
    """Clean one-axis-per-run recording and its identification."""
    folder = tmp_path_factory.mktemp("default_layout")
    data, truth = simulate("MRB35", config=SimulationConfig(hits=4, record_s=0.05, sensor_layout="default"), seed=5)
    path = folder / "clean.h5"
    write_recording(path, data)
    return data, truth, identify(path, settings=FAST), folder


def _scaled(data: RecordingData, channel: str, factor: float) -> RecordingData:
    runs = []
    for run in data.runs:
        d = np.array(run.data, dtype=np.float64)
        if channel in run.channel_names:
            d[..., list(run.channel_names).index(channel)] *= factor
        runs.append(replace(run, data=d))
    return replace(data, runs=tuple(runs))


def test_clean_one_axis_recording_names_all_five_modes(one_axis):
    _, truth, result, _ = one_axis
    t = {m["label"]: m["frequency_hz"] for m in truth["modes"]}
    assert {m.label for m in result.modes} == set(t)
    for m in result.modes:
        assert m.frequency_hz == pytest.approx(t[m.label], rel=5e-4)
    assert result.sensor_faults == () and result.gate is None


@pytest.mark.parametrize("channel, factor, words", [
    ("acc_C_y", -1.0, "sign reversed"),   # mounted upside down, vertical run
    ("acc_C_y", 1.2, "1.2x"),             # sensitivity entered 20 % off, vertical run
    ("acc_B_x", 1.2, "1.2x"),             # ... lateral run: A and B read the same (same z), both named
])
def test_faulty_accelerometer_is_named_and_corrected(one_axis, channel, factor, words):
    data, _, clean, folder = one_axis
    path = folder / f"fault_{channel}.h5"
    write_recording(path, _scaled(data, channel, factor))
    result = identify(path, settings=FAST)
    (fault,) = result.sensor_faults
    assert channel in (fault.channel, *fault.alternatives) and channel in fault.message
    if fault.channel == channel:
        assert fault.factor == pytest.approx(factor, rel=0.02)
    assert words in fault.message
    for key in ("f_V", "f_H"):  # corrected: the clean file's numbers
        assert result.parameters[key]["value"] == pytest.approx(clean.parameters[key]["value"], rel=1e-5)
    assert result.gate is None


@pytest.mark.parametrize("factor", [1000.0, 1 / 9.81, -1.0])
def test_one_run_off_by_a_unit_factor_keeps_its_labels_and_says_so(one_axis, factor):
    """Every accelerometer of the lateral run off by a unit factor (mV/g entered for mV/(m/s^2), a kilo
    prefix): the modes it does not see were called too weak to be the carriage's, K_V lost with exit 0.
    Each run is now labelled at its own scale, and the run and its factor are named."""
    data, _, clean, folder = one_axis
    lateral = next(r for r in data.runs if "acc_A_x" in r.channel_names)
    scaled = data
    for name in lateral.channel_names:
        if name != "force":
            scaled = _scaled(scaled, name, factor)
    path = folder / f"run_scale_{factor:g}.h5"
    write_recording(path, scaled)
    result = identify(path, settings=FAST)
    assert {m.label for m in result.modes} == {m.label for m in clean.modes}
    for key in ("K_V", "K_H", "c_V", "c_H"):  # amplitude-free: the clean file's numbers
        assert result.parameters[key]["value"] == pytest.approx(clean.parameters[key]["value"], rel=1e-4), key
    said = [w for w in result.warnings if w.startswith(f"run '{lateral.name}': ")]
    assert len(said) == 1, result.warnings
    if factor > 0:
        assert f"its modal constants are {factor:.3g} times" in said[0], said
    else:  # the run's hammer or every accelerometer reversed
        assert "antiphase" in said[0] and "reversed" in said[0], said
    assert not any(w.startswith("the modal constants are") for w in result.warnings)  # no recording-wide claim
    assert result.gate is None


def test_force_levels_on_one_axis_are_explained_by_amplitude_dependence(tmp_path):
    from guidefit.explain import explain
    from guidefit.nonlinear import simulate_force_levels

    data, _ = simulate_force_levels("MRB35", ["amplitude_dependence:preload_factor=1"], (100.0, 1000.0, 5000.0),
                                    hits=3, record_s=0.03, seed=3, oversample=2, sensor_layout="default")
    assert all(ch.endswith("_y") for run in data.runs for ch in run.channel_names if ch != "force")
    path = tmp_path / "levels.h5"
    write_recording(path, data)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = identify(path, settings=IdentifySettings(force_levels=True))
        assert any("a force level, left out of the shared-pole fit" in w for w in result.warnings)
        ex = explain(result, candidates=["amplitude_dependence", "contact_stiffness", "added_mass"])
    assert ex.verdict == "explained" and ex.effects[0]["name"] == "amplitude_dependence"


def _plate(freqs_hz, seed=0, n=4000, fs=200_000.0, hits=3):
    """A structure whose modes are no rigid motion of anything (each sensor its own random modal amplitude),
    recorded the paper's way: y at A-D in the vertical run, x at A-D in the lateral run."""
    from guidefit.model.guides import load_guide
    from guidefit.simulate.layouts import DEFAULT_RUNS, resolve_layout

    rng = np.random.default_rng(seed)
    sensors = resolve_layout(load_guide("MRB35"), "default", DEFAULT_RUNS)
    f = np.fft.rfftfreq(4 * n, 1 / fs)
    w, wk = 2 * np.pi * f[:, None], 2 * np.pi * np.asarray(freqs_hz)[None, :]
    runs = []
    for run in DEFAULT_RUNS:
        chans = sensors[run.name]
        phi_out = rng.standard_normal((len(freqs_hz), len(chans))) * 0.5
        phi_in = rng.uniform(0.3, 0.7, len(freqs_hz))
        H = (-(w**2) / (wk**2 - w**2 + 2j * 0.02 * wk * w)) @ (phi_in[:, None] * phi_out)
        t = np.arange(4 * n) / fs
        records = []
        for peak in rng.uniform(200, 400, hits):
            force = np.where((t >= 1e-3) & (t <= 1.1e-3), peak * np.sin(np.pi * (t - 1e-3) / 1e-4), 0.0)
            acc = np.fft.irfft(np.fft.rfft(force)[:, None] * H, 4 * n, axis=0)[:n]
            rec = np.column_stack([force[:n], acc])
            records.append(rec + 1e-4 * np.abs(rec).max(axis=0) * rng.standard_normal(rec.shape))
        runs.append(RunData(run.name, fs, run.direction, ["force"] + [c.name for c in chans],
                            ["N"] + ["m/s^2"] * len(chans), np.array([run.position_m] + [c.position_m for c in chans]),
                            np.array([run.direction] + [c.direction for c in chans]), data=np.stack(records),
                            pretrigger_samples=200))
    return RecordingData(tuple(runs), guide="MRB35")


def test_a_structure_that_is_not_a_carriage_is_refused(tmp_path):
    """Five modes at the model's own frequencies: frequencies alone would pass, the readings do not."""
    path = tmp_path / "plate.h5"
    write_recording(path, _plate([1880.0, 2280.0, 2500.0, 3530.0, 5560.0]))
    result = identify(path, settings=FAST)
    assert result.gate is not None
    assert all(p["value"] is None for p in result.parameters.values())


def test_a_joint_mode_the_set_up_sees_but_cannot_name_is_an_incomplete_identification(tmp_path):
    """A heavy base on the one-axis layout: the roll pair cannot be told apart (honestly ``ambiguous``),
    so f_H, K_H, c_H are missing although the layout excites and sees the mode. That was exit 0 with
    null numbers; it is now exit 1 with one line saying which parameters and why, the rest still given."""
    import json

    from click.testing import CliRunner

    from guidefit.cli import main

    data, _ = simulate("MRB35", effects=["base_mode:mass_kg=3,lateral_n_per_m=3e8,vertical_n_per_m=1e9"],
                       config=SimulationConfig(hits=4, record_s=0.05, sensor_layout="default"), seed=1)
    path = tmp_path / "heavy_base.h5"
    write_recording(path, data)
    result = CliRunner().invoke(main, ["identify", str(path), "--json", "--no-jackknife"])
    out = json.loads(result.stdout.strip().splitlines()[-1])
    assert out["parameters"]["K_H"]["value"] is None and out["parameters"]["K_V"]["value"] is not None
    assert result.exit_code == 1, result.output
    (line,) = out["unidentified"]
    assert line.startswith("f_H, K_H, c_H not identified: the roll_low mode") and "not told apart" in line
    assert "guidefit: identification incomplete:" in result.stderr


def test_a_complete_identification_is_not_incomplete(one_axis):
    _, _, clean, _ = one_axis
    assert clean.unidentified == () and clean.to_dict()["unidentified"] == []
