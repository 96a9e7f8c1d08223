"""Sensor consistency and the plausibility gate (guidefit.consistency, hooked into identify).

Faults are made the way they happen: a seeded simulated recording (known
truth) whose channel samples are negated, scaled or taken from another axis
afterwards, or written with a wrong unit. The real data are the five pyFRF
impact hits (shared/real-data/README.md: MIT licence, the OpenModal project),
read in place from ../shared and skipped when absent.
"""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from guidefit import consistency as cons
from guidefit.cli import main
from guidefit.identify import IdentifySettings, identify
from guidefit.io import RecordingData, RunData, write_recording
from guidefit.modes.labels import driving_row
from guidefit.simulate import SimulationConfig, simulate

REAL = Path(__file__).parents[1].parent / "shared" / "real-data" / "pyfrf-impact"
FAST = IdentifySettings(jackknife=False)
POINTS = {"A": (0.030, 0.0, 0.045), "B": (-0.030, 0.0, 0.045), "C": (-0.030, 0.0, -0.045),
          "D": (0.030, 0.0, -0.045)}
G = 9.80665


# --------------------------------------------------------------------------- helpers


@pytest.fixture(scope="module")
def simulated():
    """Nominal MRB35, both runs, sensors A-D in x, y and z (z only to make axis faults), 3 short hits."""
    return simulate("MRB35", config=SimulationConfig(hits=3, record_s=0.02, axes="xyz"), seed=1)


def _edit(data: RecordingData, channel=None, factor=1.0, take_from=None, force_factor=1.0, units=None):
    """The recording with one channel's samples scaled or taken from another channel; z channels dropped."""
    runs = []
    for run in data.runs:
        names = list(run.channel_names)
        d = np.array(run.data, dtype=np.float64)
        if channel in names:
            j = names.index(channel)
            if take_from:
                d[..., j] = d[..., names.index(take_from)]
            d[..., j] *= factor
        d[..., names.index("force")] *= force_factor
        keep = [i for i, n in enumerate(names) if not n.endswith("_z")]
        kept_units = tuple(run.units[i] for i in keep)
        if units:
            kept_units = tuple(units if u != "N" else u for u in kept_units)
        runs.append(replace(run, data=d[..., keep], channel_names=tuple(names[i] for i in keep), units=kept_units,
                            positions_m=np.asarray(run.positions_m)[keep],
                            directions=np.asarray(run.directions)[keep]))
    return replace(data, runs=tuple(runs))


def _identify(tmp_path, data, name="rec"):
    path = tmp_path / f"{name}.h5"
    write_recording(path, data)
    return identify(path, settings=FAST), path


def _accurate(result, truth):
    """identify's usual accuracy on these short clean records: f within 0.02 %, zeta within 1 %."""
    p, t = result.parameters, truth["parameters"]
    for key in ("f_V", "f_H"):
        assert p[key]["value"] == pytest.approx(t[key]["value"], rel=2e-4), key
    for key in ("zeta_V", "zeta_H"):
        assert p[key]["value"] == pytest.approx(t[key]["value"], rel=0.01), key
    assert [m.label for m in result.modes] == ["yaw", "pitch", "roll_low", "vertical", "roll_high"]


def _rigid_sets(shapes_by_run, seed=0):
    """ShapeSets of rigid motions at A-D (x, y) for unit tests of the fault search."""
    from guidefit.io import Channel
    from guidefit.modes.labels import sensor_matrix

    chans = [Channel(f"acc_{p}_{a}", "m/s^2", np.array(POINTS[p]), np.eye(3)[{"x": 0, "y": 1}[a]], 1.0)
             for p in "ABCD" for a in "xy"]
    S = sensor_matrix(chans)
    rng = np.random.default_rng(seed)
    out = []
    for run, (direction, q) in shapes_by_run.items():
        out.append(cons.ShapeSet(run, tuple(c.name for c in chans), S, np.array([c.position_m for c in chans]),
                                 np.array([c.direction for c in chans]), q @ S.T * (1 + 0 * rng.random()),
                                 driving_row(direction, (0.01, 0.0, 0.02))))
    return out


# --------------------------------------------------------------------------- the fault search alone


def test_sign_flip_found_from_rigid_shapes_alone():
    q = np.random.default_rng(3).standard_normal((4, 5))
    sets = _rigid_sets({"vertical": ((0, -1, 0), q)})
    sets[0].shapes[:, 3] *= -1                       # acc_B_y
    (fault,) = cons.find_sensor_faults(sets)
    assert (fault.channel, fault.kind) == ("acc_B_y", "scale")
    assert fault.factor == pytest.approx(-1.0, rel=1e-9)
    assert fault.relres_before > 0.1 and fault.relres_after < 1e-9
    assert "sign reversed (mounted upside down?)" in fault.message


def test_noise_alone_raises_no_fault():
    rng = np.random.default_rng(4)
    sets = _rigid_sets({"vertical": ((0, -1, 0), rng.standard_normal((5, 5)))})
    noisy = [replace(s, shapes=s.shapes + 0.02 * np.abs(s.shapes).max() * rng.standard_normal(s.shapes.shape))
             for s in sets]
    assert cons.find_sensor_faults(noisy) == ()


def test_twin_x_sensors_told_apart_by_the_driving_point():
    """A_x and B_x sit at the same z: rigid motion alone cannot say which one is reversed. The
    driving-point residue (b . q > 0 for every mode) can: reversing the good one makes it negative."""
    from guidefit.model import vibration as vib
    from guidefit.model.guides import load_guide

    model = vib.solve_modes(vib.model_from_guide(load_guide("MRB35")))
    phi = np.asarray(model.shapes)[:5].T                                  # (5 modes, 5 DOFs), mass-normalised
    b = driving_row((-1.0, 0.0, 0.0), (0.035, -0.01, 0.015))
    sets = _rigid_sets({"lateral": ((-1.0, 0.0, 0.0), phi * (phi @ b)[:, None])})
    sets = [replace(s, driving=b) for s in sets]
    sets[0].shapes[:, 0] *= -1                                             # acc_A_x reversed
    mass = vib.carriage_mass_matrix(vib.model_from_guide(load_guide("MRB35")))
    (fault,) = cons.find_sensor_faults(sets, mass)
    assert fault.channel == "acc_A_x" and fault.alternatives == ()
    assert fault.factor == pytest.approx(-1.0, rel=1e-6)


# --------------------------------------------------------------------------- through identify


FAULTS = [
    # (channel, factor, take_from, kind, expected factor or axis, words in the message)
    ("acc_B_y", -1.0, None, "scale", -1.0, "sign reversed (mounted upside down?)"),
    ("acc_C_y", G, None, "scale", G, "reads 9.81x what rigid motion predicts (g and m/s^2 mixed up: factor 9.81?)"),
    ("acc_A_x", 1000.0, None, "scale", 1000.0, "reads 1000x what rigid motion predicts"),
    ("acc_D_x", 1 / G, None, "scale", 1 / G, "reads 1/9.81 (0.102x)"),
    ("acc_D_y", 10.0, None, "scale", 10.0, "factor 10?"),
    ("acc_A_y", 1.0, "acc_A_z", "axis", "z", "reads the +z axis, not its declared one"),
    ("acc_B_x", 1.0, "acc_B_y", "axis", "y", "reads the +y axis, not its declared one"),
]


@pytest.mark.parametrize("channel, factor, take_from, kind, expected, words", FAULTS,
                         ids=[f"{f[0]}-{f[3]}-{f[4]}" for f in FAULTS])
def test_faulty_channel_named_with_its_size_and_modes_unspoilt(tmp_path, simulated, channel, factor, take_from,
                                                               kind, expected, words):
    data, truth = simulated
    result, _ = _identify(tmp_path, _edit(data, channel, factor, take_from))
    (fault,) = result.sensor_faults
    assert (fault.channel, fault.kind) == (channel, kind)
    assert fault.alternatives == ()
    if kind == "scale":
        # 0.01 % sensor noise: the factor is recovered to well within 1 %
        assert fault.factor == pytest.approx(expected, rel=0.01)
    else:
        assert fault.axis == expected and fault.factor == pytest.approx(1.0, rel=0.02)
    assert fault.relres_before > 0.1 and fault.relres_after < 0.01
    assert words in fault.message and fault.message.startswith(channel)
    assert [w for w in result.warnings if w.startswith(channel)] == [fault.message]
    assert result.gate is None
    _accurate(result, truth)


def test_fault_found_and_clean_silent_at_thirty_times_the_noise(tmp_path):
    """Sensor noise 0.3 % of the range (about 1 % of the peak response): the sign flip is still found, the
    factor within 1 %, and the same recording without the fault stays silent."""
    data, _ = simulate("MRB35", config=SimulationConfig(hits=3, record_s=0.02, noise_fraction=3e-3), seed=1)
    clean, _ = _identify(tmp_path, data, "clean")
    assert clean.sensor_faults == () and clean.gate is None
    flipped, _ = _identify(tmp_path, _edit(data, "acc_C_y", -1.0), "flipped")
    (fault,) = flipped.sensor_faults
    assert fault.channel == "acc_C_y" and fault.factor == pytest.approx(-1.0, rel=0.01)
    assert flipped.parameters["f_V"]["value"] == pytest.approx(clean.parameters["f_V"]["value"], rel=1e-6)


def test_two_faulty_channels_at_once(tmp_path, simulated):
    """No single correction explains two faults; the pair search (both left out of the prediction) does."""
    data, truth = simulated
    result, _ = _identify(tmp_path, _edit(_edit(data, "acc_B_y", -1.0), "acc_D_x", G))
    got = {f.channel: f.factor for f in result.sensor_faults}
    assert set(got) == {"acc_B_y", "acc_D_x"}
    assert got["acc_B_y"] == pytest.approx(-1.0, rel=0.01) and got["acc_D_x"] == pytest.approx(G, rel=0.01)
    assert result.gate is None
    _accurate(result, truth)


@pytest.fixture(scope="module")
def side_faces():
    """Nominal MRB35, the side-face layout (lateral run: E, F on the +x face, G, H on the -x face)."""
    return simulate("MRB35", config=SimulationConfig(hits=2, record_s=0.02, sensor_layout="side"), seed=3)


@pytest.mark.parametrize("flipped", [("acc_G_x", "acc_H_x"), ("acc_E_x", "acc_H_x")])
def test_two_flipped_side_sensors_are_the_ones_physics_allows(tmp_path, side_faces, flipped):
    """Was: G and H declared along -x (their samples along +x) gave f_H = 1879 Hz (the yaw mode
    labelled roll_low), K_H -43 %, exit 0: flipping E and H back fits rigid motion as well as G and H
    (it trades u for psi), and the pair search took the first. Equivalent pairs are now told apart
    as single channels are, by the driving-point sign and the modal mass."""
    data, truth = side_faces
    runs = []
    for run in data.runs:
        dirs = np.array(run.directions, float)
        for name in flipped:
            if name in run.channel_names:
                dirs[run.channel_names.index(name)] *= -1
        runs.append(replace(run, directions=dirs))
    result, _ = _identify(tmp_path, replace(data, runs=tuple(runs)))
    assert {f.channel for f in result.sensor_faults} == set(flipped)
    assert result.parameters["f_H"]["value"] == pytest.approx(truth["parameters"]["f_H"]["value"], rel=1e-3)
    assert result.parameters["K_H"]["value"] == pytest.approx(truth["parameters"]["K_H"]["value"], rel=2e-3)


@pytest.mark.parametrize("flipped, how", [(("acc_E_x", "acc_G_x"), "samples"), (("acc_E_x", "acc_G_x"), "declared"),
                                          (("acc_F_x", "acc_H_x"), "samples")])
def test_side_sensors_reversed_at_one_height_are_found_by_the_other_run(tmp_path, side_faces, flipped, how):
    """Was: E and G (one height, opposite faces) reversed, in their samples or their declared direction,
    still read a rigid motion (u and psi trade places), so the sensor check was silent: yaw labelled
    roll_low, f_H = 1879 Hz, K_H -43 %, c_H -86 %, exit 0, beside a warning 'run lateral: -4.79 times the
    other runs'. The lateral run's negative scale (F, H: 4.79x, and its 2497 Hz mode read as yaw where
    the vertical run reads roll) now tries the sign sets its rigid fit cannot see: the pair is named and
    corrected, K_H as on the clean file."""
    data, truth = side_faces
    runs = []
    for run in data.runs:
        dirs, d = np.array(run.directions, float), np.array(run.data, float)
        for name in flipped:
            if name in run.channel_names:
                j = run.channel_names.index(name)
                if how == "declared":
                    dirs[j] *= -1
                else:
                    d[..., j] *= -1
        runs.append(replace(run, directions=dirs, data=d))
    result, _ = _identify(tmp_path, replace(data, runs=tuple(runs)))
    assert {f.channel for f in result.sensor_faults} == set(flipped)
    assert "sign reversed together" in result.sensor_faults[0].message
    assert result.gate is None
    for key in ("f_H", "K_H", "c_H"):
        assert result.parameters[key]["value"] == pytest.approx(truth["parameters"][key]["value"], rel=5e-3), key


def test_sign_sets_a_run_cannot_see_and_an_undecided_one():
    """The side-face x sensors at two heights: reversing both at one height keeps every rigid reading
    rigid; A-D y sensors (a twist constraint) have no such set. A run read at a negative scale whose
    candidate sets do not make it agree with the other run is named, not corrected."""
    from guidefit.model import vibration as vib
    from guidefit.model.guides import load_guide
    from guidefit.sensor_signs import SignCheck, sign_faults, undetectable_flips

    z = [0.04, -0.04, 0.04, -0.04]
    side = np.array([[1.0, 0.0, 0.0, zi, 0.015] for zi in z])
    assert undetectable_flips(side) == [(0, 2), (1, 3)]
    ys = np.array([[0.0, 1.0, -zz, 0.0, xx] for xx, zz in ((0.03, 0.045), (-0.03, 0.045), (-0.03, -0.045),
                                                              (0.03, -0.045))])
    assert undetectable_flips(ys) == []
    model = vib.solve_modes(vib.model_from_guide(load_guide("MRB35")))
    phi = np.asarray(model.shapes)[:5]
    g_v, g_l = driving_row((0, -1.0, 0), (0.004, 0, 0.008)), driving_row((-1.0, 0, 0), (0.05, -0.012, 0.006))
    f = tuple(model.frequencies_hz)

    def shape_set(run, S, g, sign):
        shapes = (phi.T @ S.T) * (g @ phi)[:, None] * sign
        return cons.ShapeSet(run, tuple(f"acc_{i}" for i in range(len(S))), S, np.zeros((len(S), 3)),
                             np.zeros((len(S), 3)), shapes, g, tuple(model.labels), f)

    good = [shape_set("vertical", ys, g_v, 1.0), shape_set("lateral", side, g_l, 1.0)]
    assert sign_faults(good, model).faults == () and sign_faults(good, model).unresolved is None
    eg = [good[0], shape_set("lateral", side, g_l, np.array([-1.0, 1.0, -1.0, 1.0]))]
    assert {channel for channel, _ in sign_faults(eg, model).faults} == {"acc_0", "acc_2"}
    for factor in (-1.0, -10.0):  # the hammer reversed (and a unit error): the labeller reads the run at its sign
        assert sign_faults([good[0], shape_set("lateral", side, g_l, factor)], model) == SignCheck()
    undecided = sign_faults([good[0], shape_set("lateral", side, g_l, np.array([-10.0, 10.0, -10.0, 10.0]))], model)
    assert undecided.faults == ()
    assert "acc_0+acc_2 or acc_1+acc_3" in undecided.unresolved and "run 'lateral'" in undecided.unresolved


def test_corrected_channel_gives_the_clean_file_numbers_jackknife_included(tmp_path, simulated):
    """The refit runs on the FRFs with the x1000 channel divided out, group sums too: f, zeta and their
    jackknife std are those of the clean recording (to rounding), not merely close to the truth."""
    data, _ = simulated
    write_recording(tmp_path / "clean.h5", _edit(data))
    write_recording(tmp_path / "k.h5", _edit(data, "acc_A_x", 1000.0))
    clean, faulty = identify(tmp_path / "clean.h5"), identify(tmp_path / "k.h5")
    assert [f.channel for f in faulty.sensor_faults] == ["acc_A_x"]
    for key in ("f_V", "f_H", "zeta_V", "zeta_H"):
        assert faulty.parameters[key]["value"] == pytest.approx(clean.parameters[key]["value"], rel=1e-9)
        assert faulty.parameters[key]["std"] == pytest.approx(clean.parameters[key]["std"], rel=1e-6)


def test_sensor_fault_in_json_and_on_the_command_line(tmp_path, simulated):
    data, _ = simulated
    path = tmp_path / "flipped.h5"
    write_recording(path, _edit(data, "acc_B_y", -1.0))
    out = CliRunner().invoke(main, ["identify", str(path), "--json", "--no-jackknife"])
    assert out.exit_code == 0
    d = json.loads(out.stdout.splitlines()[-1])
    assert d["gate"] is None and d["parameters"]["K_V"]["value"] > 0
    assert [(f["channel"], f["kind"], round(f["factor"], 2)) for f in d["sensor_faults"]] == [("acc_B_y", "scale", -1)]
    assert any(w.startswith("acc_B_y: sign reversed") for w in d["warnings"])


# --------------------------------------------------------------------------- silent where all is well


@pytest.mark.parametrize("effects", [
    [],
    ["added_mass:mass_kg=0.3,at=A"],          # a heavy corner mass couples the modes
    ["row_damage:row=1,factor=0.2"],          # a partly lost row breaks the symmetry
    ["base_mode:mass_kg=3.0,vertical_n_per_m=3e9"],   # a heavy base with its own (extra) mode
], ids=["nominal", "corner_mass", "damaged_row", "heavy_base"])
def test_clean_and_coupled_recordings_raise_nothing(tmp_path, effects):
    data, truth = simulate("MRB35", effects, config=SimulationConfig(hits=3, record_s=0.02), seed=2)
    result, _ = _identify(tmp_path, data)
    assert result.sensor_faults == ()
    assert result.gate is None
    assert not [w for w in result.warnings if "modal mass" in w or "rigid" in w]
    assert result.parameters["K_V"]["value"] == pytest.approx(truth["parameters"]["K_V"]["value"], rel=2e-3)


@pytest.mark.parametrize("config", [dict(sensors="AB"), dict(axes="y"), dict(sample_rate_hz=12800.0, record_s=0.06)],
                         ids=["sensors_A_B_only", "y_axes_only", "fs_12800"])
def test_sparse_or_slow_set_ups_raise_nothing(tmp_path, config):
    """A and B alone cannot tell u from psi (the least-squares motion, and so the modal mass, of a lateral
    mode would be biased: was a '21 kg, factor 9.81' warning); y sensors alone see no u or psi; at 12.8 kHz
    roll_high lies above the search band and is not expected."""
    cfg = SimulationConfig(**{"hits": 3, "record_s": 0.02, **config})
    data, truth = simulate("MRB35", config=cfg, seed=3)
    result, _ = _identify(tmp_path, data)
    assert result.sensor_faults == () and result.gate is None
    assert not [w for w in result.warnings if "modal mass" in w]
    assert result.parameters["f_V"]["value"] == pytest.approx(truth["parameters"]["f_V"]["value"], rel=5e-4)


@pytest.mark.parametrize("kw", [dict(), dict(layout="signals", units_acc="g"), dict(k_support=1.2e8)],
                         ids=["standard", "signals_in_g", "paper_soft_rig"])
def test_independent_contract_recordings_raise_nothing(tmp_path, kw):
    """The conformance audit's own writer (tests/_contract_gen.py, no guidefit code), incl. the paper-like soft
    rig (lateral support 1.2e8 N/m: f_H 1081 Hz, zeta_H 10.5 %) and accelerations stored in g."""
    import _contract_gen as gen

    if "k_support" in kw:
        spec = {}
        for i, run in enumerate(("vertical", "lateral")):
            chans, data = gen.run_hits(run, n_hits=2, n=6000, seed=i, k_support=kw["k_support"],
                                       zetas=[0.105, 0.02, 0.02, 0.0288, 0.02])
            spec[run] = dict(chans=chans, data=data, fs=200_000.0, direction=gen.RUNS[run][1],
                             position=gen.RUNS[run][0])
        path = gen.write_file(tmp_path / "soft.h5", spec)
    else:
        path = gen.standard_file(tmp_path / "std.h5", n_hits=2, n=4000, **kw)
    result = identify(path, settings=FAST)
    assert result.sensor_faults == () and result.gate is None
    assert not [w for w in result.warnings if "modal mass" in w]
    assert result.parameters["K_V"]["value"] > 0 and result.parameters["K_H"]["value"] > 0


def test_bundled_sample_stays_clean():
    sample = Path(__file__).parents[1] / "sample_data" / "mrb35_sample.h5"
    result = identify(sample, settings=FAST)
    assert result.gate is None and result.sensor_faults == () and result.warnings == ()


# --------------------------------------------------------------------------- modal mass: scale errors


def test_force_read_1000x_high_is_named(tmp_path, simulated):
    """mV/N entered as mV/kN: the force reads 1000x high, the residues are 1000x small, and the carriage
    seems 1000x heavier. K and c follow from frequencies and M, so they stay; the warning names 1000."""
    data, truth = simulated
    result, _ = _identify(tmp_path, _edit(data, force_factor=1000.0))
    mass = [w for w in result.warnings if "modal mass" in w]
    assert len(mass) == 2                                          # vertical and roll_low
    assert all("factor 1000: force reads 1000x high" in w for w in mass)
    kg = [float(w.split("driving-point residue ")[1].split(" kg")[0]) for w in mass]
    assert kg == [pytest.approx(2200.0, rel=0.05)] * 2
    assert result.sensor_faults == () and result.gate is None
    assert result.parameters["K_V"]["value"] == pytest.approx(truth["parameters"]["K_V"]["value"], rel=5e-4)


def test_accelerations_in_m_s2_declared_as_g_are_named(tmp_path, simulated):
    data, _ = simulated
    result, _ = _identify(tmp_path, _edit(data, units="g"))        # every acceleration read 9.81x high
    mass = [w for w in result.warnings if "modal mass" in w]
    assert mass and all("factor 9.81: accelerations read 9.81x high (data in m/s^2 declared as g, or a sensitivity "
                        'in mV/(m/s^2) entered with unit = "g"?)' in w for w in mass)
    kg = float(mass[0].split("driving-point residue ")[1].split(" kg")[0])
    assert kg == pytest.approx(2.2 / G, rel=0.05)


def test_every_accelerometer_reversed_gives_a_negative_driving_point(tmp_path, simulated):
    """All responses negated keep the shapes rigid (no channel fault), but the carriage then moves against the
    hammer at the driving point, which no structure does."""
    data, _ = simulated
    runs = []
    for run in _edit(data).runs:
        d = np.array(run.data)
        d[..., [i for i, n in enumerate(run.channel_names) if n != "force"]] *= -1
        runs.append(replace(run, data=d))
    result, _ = _identify(tmp_path, replace(data, runs=tuple(runs)))
    assert result.sensor_faults == () and result.gate is None
    negative = [w for w in result.warnings if "driving-point residue is negative" in w]
    assert [w.split()[1] for w in negative] == ["roll_low", "vertical"]


def test_modal_mass_hint_words():
    assert "another structure" in cons.scale_factor_hint(40.0)
    assert cons.scale_factor_hint(1 / 1000).startswith("factor 1000: force reads 1000x low")
    assert cons.scale_factor_hint(G).startswith("factor 9.81: accelerations read 9.81x low")


# --------------------------------------------------------------------------- the plausibility gate


@pytest.fixture(scope="module")
def real_recording(tmp_path_factory):
    """The five pyFRF hits written as a recording that claims guide MRB35 (one vertical accelerometer).

    The first 0.5 s of each 1 s hit (decayed to a few % by then): the same modes, and the modal curve
    fit of the whole second takes about 25 s of CPU (auto_fit over 25600 bins and 12 modes), too long
    for a test. The whole records gave K_V = 1.17e9 +/- 3.7e4 N/m with exit 0 before the gate.
    """
    if not (REAL / "measurements_1.npy").exists():
        pytest.skip(f"real data not found at {REAL}")
    arrays = [np.load(REAL / f"measurements_{k}.npy") for k in range(1, 6)]
    fs = 1.0 / float(np.median(np.diff(arrays[0][0])))
    data = np.stack([np.column_stack([a[1], a[2]]) for a in arrays])[:, : int(0.5 * fs)]
    run = RunData("vertical", fs, [0, -1, 0], ["force", "acc_A_y"], ["N", "m/s^2"],
                  np.array([[0.01, 0.0, 0.02], POINTS["A"]]), [[0, -1, 0], [0, 1, 0]], data=data)
    path = tmp_path_factory.mktemp("real") / "pyfrf_as_mrb35.h5"
    write_recording(path, RecordingData((run,), guide="MRB35"))
    return path


def test_gate_on_real_data_of_another_structure(real_recording):
    """Was: K_V = 1.17e9 +/- 3.7e4 N/m, exit 0, 17 warnings. One accelerometer tells no shape: the labels
    rest on frequency, and the vertical label's 5969 Hz is 1.69 times the model's."""
    result = identify(real_recording, settings=FAST)
    assert result.gate is not None and "frequency alone" in result.gate and "1.69 times" in result.gate
    assert all(p["value"] is None and p["std"] is None for p in result.parameters.values())
    assert result.modes or result.extra_modes                      # the modes it found are still reported


def test_gate_on_the_command_line_exit_1_one_line_no_k(real_recording):
    runner = CliRunner()
    out = runner.invoke(main, ["identify", str(real_recording), "--json", "--no-jackknife"])
    assert out.exit_code == 1
    lines = [line for line in out.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("guidefit: identification rejected: ")
    d = json.loads(out.stdout.splitlines()[-1])
    assert d["gate"] and (d["modes"] or d["extra_modes"])
    for key in ("K_V", "K_H", "c_V", "c_H"):
        assert d["parameters"][key]["value"] is None
    table = runner.invoke(main, ["identify", str(real_recording), "--no-jackknife"])
    assert table.exit_code == 1 and "no joint parameters" in table.stdout and "K_V" not in table.stdout


def _non_carriage(freqs_hz, seed=0, n=4000, fs=200_000.0, hits=3):
    """A recording of a structure whose modes are not rigid motions of anything: every sensor has its own
    random modal amplitude (a plate, say), modal superposition of half-sine hits, sensors at A-D in x, y."""
    rng = np.random.default_rng(seed)
    names = ["force"] + [f"acc_{p}_{a}" for p in "ABCD" for a in "xy"]
    pos = np.array([[0.0, 0.0, 0.0]] + [POINTS[p] for p in "ABCD" for _ in "xy"])
    dirs = np.array([[0.0, -1.0, 0.0]] + [np.eye(3)[k] for _ in "ABCD" for k in (0, 1)])
    npad = 4 * n
    f = np.fft.rfftfreq(npad, 1 / fs)
    w, wk = 2 * np.pi * f[:, None], 2 * np.pi * np.asarray(freqs_hz)[None, :]
    runs = []
    for run, direction in (("vertical", (0.0, -1.0, 0.0)), ("lateral", (-1.0, 0.0, 0.0))):
        phi_out = rng.standard_normal((len(freqs_hz), 8)) * 0.5     # (modes, sensors), 1/sqrt(kg)
        phi_in = rng.uniform(0.3, 0.7, len(freqs_hz))
        H = (-(w**2) / (wk**2 - w**2 + 2j * 0.02 * wk * w)) @ (phi_in[:, None] * phi_out)
        t = np.arange(npad) / fs
        records = []
        for peak in rng.uniform(200, 400, hits):
            force = np.where((t >= 1e-3) & (t <= 1.1e-3), peak * np.sin(np.pi * (t - 1e-3) / 1e-4), 0.0)
            acc = np.fft.irfft(np.fft.rfft(force)[:, None] * H, npad, axis=0)[:n]
            rec = np.column_stack([force[:n], acc])
            records.append(rec + 1e-4 * np.abs(rec).max(axis=0) * rng.standard_normal(rec.shape))
        d = dirs.copy()
        d[0] = direction
        runs.append(RunData(run, fs, direction, names, ["N"] + ["m/s^2"] * 8, pos, d, data=np.stack(records),
                            pretrigger_samples=200))
    return RecordingData(tuple(runs), guide="MRB35")


def test_gate_on_a_synthetic_non_carriage_structure(tmp_path):
    """Five modes right at the model's frequencies, so frequencies alone would pass; the shapes at A-D are not
    the motion of a rigid carriage."""
    result, path = _identify(tmp_path, _non_carriage([1880.0, 2280.0, 2500.0, 3530.0, 5560.0]))
    assert result.gate is not None
    assert all(p["value"] is None for p in result.parameters.values())
    out = CliRunner().invoke(main, ["identify", str(path), "--no-jackknife"])
    assert out.exit_code == 1
    assert len([line for line in out.stderr.splitlines() if line.strip()]) == 1


def test_plausibility_is_silent_for_rigid_sets_and_names_non_rigid_ones():
    from guidefit.model import vibration as vib
    from guidefit.model.guides import load_guide

    model = vib.solve_modes(vib.model_from_guide(load_guide("MRB35")))
    phi = np.asarray(model.shapes)[:5].T
    b = driving_row((0.0, -1.0, 0.0), (0.01, 0.0, 0.02))
    sets = _rigid_sets({"vertical": ((0.0, -1.0, 0.0), phi * (phi @ b)[:, None])})
    sets = [replace(s, driving=b, labels=tuple(model.labels), frequencies_hz=tuple(model.frequencies_hz))
            for s in sets]

    class Mode:
        def __init__(self, label, f):
            self.label, self.frequency_hz, self.energy = label, f, {"v": 1.0}

    modes = [Mode(lab, f) for lab, f in zip(model.labels, model.frequencies_hz)]
    assert cons.plausibility(modes, [], sets, model) is None
    rng = np.random.default_rng(1)
    bent = [replace(s, shapes=s.shapes + 0.5 * np.abs(s.shapes).max() * rng.standard_normal(s.shapes.shape))
            for s in sets]
    why = cons.plausibility(modes, [], bent, model)
    assert why is not None and "not rigid-body motions" in why
    assert math.isfinite(cons.rigid_misfit(bent)[0][4])


def test_gate_in_the_html_report_exit_1(real_recording, tmp_path):
    # the report renders the same identification: the rejection line, no joint parameters, exit 1
    out_path = tmp_path / "report.html"
    out = CliRunner().invoke(main, ["report", str(real_recording), "-o", str(out_path), "--no-jackknife"])
    assert out.exit_code == 1, out.output
    lines = [line for line in out.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("guidefit: identification rejected: ")
    html = out_path.read_text()
    assert "Identification rejected" in html


@pytest.mark.parametrize("layout", ["single", "pair"])
def test_hit_point_given_only_by_the_force_channel_position(tmp_path, layout):
    """The contract's hit point is ``excitation_position_m``, else the force channel's position
    (``positions_m`` of ``force``, required). Was: the labeller read ``excitation_position_m`` only,
    so a file without it (as an independent writer may make) had its hit point taken as unknown:
    on one accelerometer per run every mode but roll_high was 'ambiguous', f_V, f_H, K_V, K_H null,
    'identification rejected' (exit 1) on a valid test that gave every number within 0.02 % with it."""
    data, truth = simulate("MRB35", config=SimulationConfig(hits=2, record_s=0.02, sensor_layout=layout), seed=3)
    runs = tuple(replace(run, excitation_position_m=None) for run in data.runs)
    assert all(r.positions_m[r.channel_names.index("force")] is not None for r in runs)
    result, _ = _identify(tmp_path, replace(data, runs=runs))
    assert result.gate is None and not result.unidentified
    _accurate(result, truth)
