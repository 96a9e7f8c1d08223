"""Sparse sensor set-ups in the global modal stage (guidefit.modal_stage): motion the sensors cannot see
must not decide a label.

y-only accelerometers see no u or psi; points A and B alone (same z) see only ``v - z theta`` and
``u + z psi``. A least-squares motion through the hit-point rows gave unseen DOFs an arbitrary size (the
vertical mode came out as yaw, the gate then fired on a clean recording).
"""

from __future__ import annotations

import numpy as np
import pytest

from guidefit import modal_stage as ms
from guidefit.identify import IdentifySettings, identify
from guidefit.recording import Channel, write_recording
from guidefit.simulate import SimulationConfig, simulate

POINTS = {"A": (0.030, 0.0, 0.045), "B": (-0.030, 0.0, 0.045), "C": (-0.030, 0.0, -0.045),
          "D": (0.030, 0.0, -0.045)}
HITS = {"vertical": ((0.0, -1.0, 0.0), (0.004, 0.0, 0.008)), "lateral": ((-1.0, 0.0, 0.0), (0.05, -0.012, 0.006))}


@pytest.fixture(scope="module")
def nominal():
    from guidefit.model import vibration as vib
    from guidefit.model.guides import load_guide

    spec = vib.model_from_guide(load_guide("MRB35"))
    model = vib.solve_modes(spec)
    phi = dict(zip(model.labels, np.asarray(model.shapes)[:5].T))       # mass-normalised (u, v, theta, psi, phi)
    drive = {r: np.asarray(d) @ vib.rigid_body_map(p) for r, (d, p) in HITS.items()}
    return phi, drive, vib.carriage_mass_matrix(spec)


def _sensors(points, axes):
    from guidefit.identify import sensor_matrix

    chans = [Channel(f"acc_{p}_{a}", "m/s^2", np.array(POINTS[p]), np.eye(3)["xyz".index(a)], 1.0)
             for p in points for a in axes]
    return sensor_matrix(chans)


def _constants(q, S, drive, noise=0.0, seed=0):
    rng = np.random.default_rng(seed)
    out = {}
    for r, g in drive.items():
        m = (S @ q) * float(g @ q)
        out[r] = m + noise * np.abs(m).max() * rng.standard_normal(m.shape) + 1e-4 * rng.standard_normal(m.shape)
    return out


def test_unseen_motion_gets_no_energy_with_y_only_sensors(nominal):
    """The vertical mode seen by y sensors only: the lateral run's hit-point row reaches u and psi, which no
    sensor sees; the assembled motion keeps them at zero and is mass-normalised (q^T M q = 1)."""
    phi, drive, mass = nominal
    S = _sensors("ABCD", "y")
    constants = _constants(phi["vertical"], S, drive)
    q, _scale, observed = ms.assemble_motion(constants, {r: S for r in drive}, drive, mass=mass)
    assert list(observed) == [False, True, True, False, True]
    assert abs(q[0]) < 1e-6 and abs(q[3]) < 1e-6
    assert float(q @ mass @ q) == pytest.approx(1.0, rel=0.01)
    assert abs(q[1]) == pytest.approx(abs(phi["vertical"][1]), rel=0.01)


@pytest.mark.parametrize("label, group", [("vertical", "v"), ("pitch", "theta"), ("yaw", "psi"),
                                          ("roll_low", "u_phi"), ("roll_high", "u_phi")])
def test_points_a_b_alone_resolve_the_motion_from_the_hit_point_residues(nominal, label, group):
    """A and B see v - z theta and u + z psi only: the least-energy motion of the vertical mode splits its
    energy about 47/53 between v and theta. The pure motion of each group, fitted to the residues of both
    runs, needs q^T M q near 1 for the right group and far from it (or a large misfit) for the wrong one."""
    phi, drive, mass = nominal
    S = _sensors("AB", "xy")
    assert not ms.groups_separable(ms.null_space(S))
    constants = _constants(phi[label], S, drive, noise=0.01, seed=1)
    sensors = {r: S for r in drive}
    q0, scale, observed = ms.assemble_motion(constants, sensors, drive, mass=mass)
    q, observed, unresolved = ms._resolve_groups(q0, observed, scale, constants, sensors, drive, mass)
    from guidefit.modeshapes import energy_shares

    shares = energy_shares(q, mass)
    assert max(shares, key=shares.get) == group and unresolved == ()
    assert float(q @ mass @ q) == pytest.approx(1.0, rel=0.05)


def test_y_only_null_space_is_separable_and_needs_no_hypotheses():
    assert ms.groups_separable(ms.null_space(_sensors("ABCD", "y")))
    assert ms.groups_separable(ms.null_space(_sensors("ABCD", "xy")))


def _identify(tmp_path, **config):
    data, truth = simulate("MRB35", config=SimulationConfig(**{"hits": 3, "record_s": 0.02, **config}), seed=3)
    path = tmp_path / "rec.h5"
    write_recording(path, data)
    return identify(path, settings=IdentifySettings(jackknife=False)), {m["label"]: m for m in truth["modes"]}


def test_y_only_recording_labels_vertical_and_pitch_and_calls_the_roll_modes_ambiguous(tmp_path):
    """Was: 'neither the vertical nor the horizontal joint mode was found' (3529 Hz labelled yaw)."""
    result, truth = _identify(tmp_path, axes="y")
    got = {m.label: m.frequency_hz for m in result.modes}
    assert set(got) == {"vertical", "pitch"}
    for label in got:
        assert got[label] == pytest.approx(truth[label]["frequency_hz"], rel=5e-4)
    rolls = [m for m in result.extra_modes if m.label == "ambiguous"]
    assert sorted(m.frequency_hz for m in rolls) == pytest.approx(
        sorted(truth[lab]["frequency_hz"] for lab in ("roll_low", "roll_high")), rel=5e-4)
    assert all({c[0] for c in m.candidates} == {"roll_low", "roll_high"} for m in rolls)
    assert "roll_low" not in result.missing_modes and "roll_high" not in result.missing_modes
    assert any("'roll_low'" in w and "not told apart" in w for w in result.warnings)
    assert not any("not paired with any carriage mode" in w for w in result.warnings)
    assert result.gate is None and result.parameters["f_H"]["value"] is None


def test_points_a_b_only_label_all_five_modes_and_raise_no_gate(tmp_path):
    """Was: 1879 and 2276 Hz 'not paired with any carriage mode' and '4 of the 5 carriage modes ... are
    missing' on a clean recording."""
    result, truth = _identify(tmp_path, sensors="AB")
    got = {m.label: m.frequency_hz for m in result.modes}
    assert set(got) == {"yaw", "pitch", "roll_low", "vertical", "roll_high"}
    for label, f in got.items():
        assert f == pytest.approx(truth[label]["frequency_hz"], rel=5e-4)
    assert result.extra_modes == () and result.missing_modes == ()
    assert result.gate is None
    assert result.parameters["f_H"]["value"] == pytest.approx(truth["roll_low"]["frequency_hz"], rel=5e-4)


def test_points_a_b_only_with_a_scale_error_leave_v_and_theta_ambiguous_not_swapped(tmp_path):
    """The A/B choice between v and theta rests on the carriage energy q^T M q, i.e. on the recording's
    scale. With the force read 1000x high every share is ~1e-3 and the largest would call the vertical mode
    pitch; such modes are reported ambiguous instead, and no K_V is given."""
    from dataclasses import replace

    data, truth = simulate("MRB35", config=SimulationConfig(hits=3, record_s=0.02, sensors="AB"), seed=3)
    runs = []
    for run in data.runs:
        d = np.array(run.data)
        d[..., list(run.channel_names).index("force")] *= 1000.0
        runs.append(replace(run, data=d))
    path = tmp_path / "scaled.h5"
    write_recording(path, replace(data, runs=tuple(runs)))
    result = identify(path, settings=IdentifySettings(jackknife=False))
    labels = {m.label for m in result.modes}
    assert "vertical" not in labels and "pitch" not in labels
    f_v = next(m["frequency_hz"] for m in truth["modes"] if m["label"] == "vertical")
    (v,) = [m for m in result.extra_modes if abs(m.frequency_hz / f_v - 1) < 1e-3]
    assert v.label == "ambiguous" and {c[0] for c in v.candidates} == {"vertical", "pitch"}
    assert any("scale" in w and "label ambiguous" in w for w in result.warnings)
    assert result.parameters["K_V"]["value"] is None
