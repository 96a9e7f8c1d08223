"""Conformance audit against shared/recording-format.md with an independent writer.

The recordings come from ``_contract_gen`` (numpy + h5py only, no guidefit
code): the pinned nominal MRB35 rigid body on its roller springs, half-sine
hits, exact modal superposition. So the right answers are known without
guidefit's simulator: f_V = 3529.0 Hz, f_H (roll_low) = 2496.5 Hz, every
modal damping ratio 0.02, and the FRFs themselves.
"""

import json
import subprocess
import sys

import _contract_gen as gen
import h5py
import numpy as np
import pytest

from guidefit.identify import IdentifySettings, frf_of_recording, identify

FREQS, _ = gen.modes()
F_V, F_H = FREQS[3], FREQS[2]
FAST = IdentifySettings(jackknife=False)


def cli(*args):
    proc = subprocess.run([sys.executable, "-m", "guidefit", *map(str, args)], capture_output=True, text=True,
                          timeout=300, check=False)
    return proc.returncode, proc.stdout, proc.stderr


def test_generator_reproduces_the_pinned_nominal_frequencies():
    # physics-notes: yaw 1879.1, pitch 2275.9, roll_low 2496.4, vertical 3529.0, roll_high 5563.6 Hz
    assert FREQS == pytest.approx([1879.1, 2275.9, 2496.4, 3529.0, 5563.6], abs=0.1)


def test_predict_agrees_with_the_independent_nominal_model():
    import guidefit

    frame = guidefit.predict(guidefit.load_guide("MRB35")).modes.to_frame()
    assert list(frame["label"]) == ["yaw", "pitch", "roll_low", "vertical", "roll_high"]
    np.testing.assert_allclose(frame["frequency_hz"], FREQS, rtol=1e-9)


def _two_runs(n_hits=2, n=4000, fs=200_000.0, **kw):
    out = {}
    for i, run in enumerate(("vertical", "lateral")):
        chans, data = gen.run_hits(run, n_hits=n_hits, n=n, fs=fs, seed=i)
        out[run] = dict(chans=chans, data=data, fs=fs, direction=gen.RUNS[run][1],
                        position=gen.RUNS[run][0], **kw)
    return out


def _reorder(spec, order_of):
    for r in spec.values():
        order = order_of(len(r["chans"]))
        r["chans"] = [r["chans"][i] for i in order]
        r["data"] = r["data"][..., order]
    return spec


def _flip(spec, names=("acc_A_y", "acc_C_x")):
    # sensors mounted the other way round: direction and reading both change sign
    for r in spec.values():
        for i, (name, pos, d) in enumerate(r["chans"]):
            if name in names:
                r["chans"][i] = (name, pos, tuple(-np.asarray(d)))
                r["data"][..., i] *= -1
    return spec


def _signals(spec):
    for r in spec.values():
        gap = np.zeros((2000, r["data"].shape[-1]))
        r["data"] = np.concatenate([np.concatenate([gap, h]) for h in r["data"]] + [gap])
        r["layout"] = "signals"
    return spec


VARIANTS = {
    "hits_float64": lambda: (_two_runs(pretrigger=200), {}),
    "hits_float32_g": lambda: (_two_runs(dtype=np.float32, units=["N"] + ["g"] * 8), {}),
    "signals_lzf_chunked": lambda: (_signals(_two_runs(chunks=(777, 9), compression="lzf")), {}),
    "fixed_length_strings_no_optional": lambda: (_two_runs(str_kind="fixed"), {"guide": None}),
    "force_last_shuffled": lambda: (_reorder(_two_runs(), lambda n: list(np.random.default_rng(3).permutation(n))),
                                    {}),
    "flipped_sensors": lambda: (_flip(_two_runs()), {}),
    "odd_length_gzip": lambda: (_two_runs(n=3999, chunks=(1, 500, 9), compression="gzip"), {}),
    "fs_51200": lambda: (_two_runs(n=1024, fs=51_200.0), {}),
    "free_run_names": lambda: ({"run 01": _two_runs()["vertical"], "ünï.2": _two_runs()["lateral"]}, {}),
}


@pytest.mark.parametrize("name", sorted(VARIANTS))
def test_conforming_variant_gives_the_true_modes(tmp_path, name):
    spec, root = VARIANTS[name]()
    path = gen.write_file(tmp_path / f"{name}.h5", spec, **root)
    result = identify(path, settings=FAST)
    p = result.parameters
    # noise 0.2 % of peak, exact modal data: the fit lands within 0.02 % (0.7 Hz) and 1 % in damping
    assert p["f_V"]["value"] == pytest.approx(F_V, rel=2e-4)
    assert p["f_H"]["value"] == pytest.approx(F_H, rel=2e-4)
    assert p["zeta_V"]["value"] == pytest.approx(0.02, rel=0.01)
    assert p["K_V"]["value"] == pytest.approx(4 * np.pi ** 2 * gen.M * F_V ** 2, rel=4e-4)
    assert not [h for h in result.hit_rows() if not h["accepted"]]


def test_g_file_gives_the_same_frf_as_the_si_file_and_both_the_true_one(tmp_path):
    si = gen.write_file(tmp_path / "si.h5", _two_runs())
    in_g = _two_runs(units=["N"] + ["g", "m/s^2"] * 4)
    g_path = gen.write_file(tmp_path / "g.h5", in_g)
    with h5py.File(g_path) as f:  # really stored in g: 9.80665 times smaller numbers
        with h5py.File(si) as f_si:
            ratio = f_si["runs/vertical/hits"][0, :, 1] / f["runs/vertical/hits"][0, :, 1]
            assert np.nanmedian(ratio) == pytest.approx(gen.G, rel=1e-12)
    a, _ = frf_of_recording(si, FAST)
    b, _ = frf_of_recording(g_path, FAST)
    for fa, fb in zip(a, b):
        np.testing.assert_allclose(fb.H, fa.H, rtol=1e-9, atol=1e-12 * np.abs(fa.H).max())
    vertical = next(s for s in a if s.run == "vertical")
    k = vertical.channels.index("acc_A_y")
    f = np.asarray(vertical.frequency_hz)
    band = (f > 1500) & (f < 6000)
    truth = gen.accel_frf(f[band], [gen.sensor_row(gen.POINTS["A"], gen.AXES["y"])],
                          gen.sensor_row(*gen.RUNS["vertical"]), np.full(5, 0.02))[:, 0]
    measured = np.asarray(vertical.H)[band, k]
    # windowing and 0.2 % noise: within 3 % of the analytic FRF (m/s^2/N) across the modes
    assert np.median(np.abs(measured / truth - 1)) < 0.03


# ----------------------------------------------------------------- defects found by the audit


def _all_hits_rejected_in_vertical(tmp_path):
    spec = _two_runs(n_hits=3)
    # every vertical hit's force corrupt (a NaN): rejected 'non_finite'. (Pulses that are all negative
    # no longer do: that is the contract's other sign convention, read with the hammer's sign turned.)
    spec["vertical"]["data"][..., 5, 0] = np.nan
    return gen.write_file(tmp_path / "neg.h5", spec)


def test_hits_of_a_run_without_frf_are_listed_as_rejected(tmp_path):
    """Was: a run whose hits were all rejected vanished from the hit table and the JSON ``hits``.

    The table said "hits: 2 accepted, 0 rejected" for a file with 3 rejected hits.
    """
    path = _all_hits_rejected_in_vertical(tmp_path)
    result = identify(path, settings=FAST)
    rows = result.hit_rows()
    vertical = [h for h in rows if h["run"] == "vertical"]
    assert len(vertical) == 3 and not any(h["accepted"] for h in vertical)
    assert all(h["reason"].startswith("non_finite") for h in vertical)
    assert result.to_dict()["hits"] == rows
    assert result.parameters["f_V"]["value"] is None  # nothing made up from the rejected run
    assert result.parameters["f_H"]["value"] == pytest.approx(F_H, rel=2e-4)
    code, out, err = cli("identify", path)
    assert code == 1, err  # f_V is missing because the run that gives it failed: incomplete (below)
    assert "hits: 3 accepted, 3 rejected" in out


def test_a_joint_mode_lost_with_its_failed_run_is_incomplete_not_exit_0(tmp_path):
    """Was: every hit of the vertical run rejected (here: pushing against excitation_direction; a
    clipped force, a dead channel alike) left f_V, K_V, c_V null with exit 0 and no error, as if
    the layout could not see the vertical mode; the run that excites and sees it gave no FRF."""
    path = _all_hits_rejected_in_vertical(tmp_path)
    result = identify(path, settings=FAST)
    assert result.parameters["K_V"]["value"] is None
    assert result.parameters["K_H"]["value"] is not None
    assert len(result.unidentified) == 1
    assert "run 'vertical'" in result.unidentified[0] and "gave no FRF" in result.unidentified[0]
    code, _, err = cli("identify", path)
    assert code == 1
    assert "identification incomplete" in err and "f_V, K_V, c_V not identified" in err


def test_warning_of_a_failed_run_names_the_run_once(tmp_path):
    """Was: "run 'vertical': run 'vertical': no accepted hit to average"."""
    result = identify(_all_hits_rejected_in_vertical(tmp_path), settings=FAST)
    failed = [w for w in result.warnings if "no accepted hit" in w]
    assert failed and all(w.count("run 'vertical'") == 1 for w in failed)


def test_a_dead_channel_is_named_not_silent(tmp_path):
    """Was: a response channel holding 0.0 in every sample (dead sensor, unplugged cable) gave exit 0
    and no warning at all, while the same channel held at 5 m/s^2 rejected every hit as clipped."""
    spec = _two_runs(n_hits=3)
    chans = spec["vertical"]["chans"]
    k = next(i for i, c in enumerate(chans) if c[0] != "force")
    spec["vertical"]["data"][..., k] = 0.0
    result = identify(gen.write_file(tmp_path / "dead.h5", spec), settings=FAST)
    dead = [w for w in result.warnings if "reads nothing" in w]
    assert len(dead) == 1 and f"channel '{chans[k][0]}'" in dead[0] and "run 'vertical'" in dead[0]
    assert result.parameters["f_V"]["value"] == pytest.approx(F_V, rel=1e-3)  # the others still give it


def test_two_hit_points_of_one_run_are_named(tmp_path):
    """Was: excitation_position_m 59 mm from the force channel's position (both the hit point) gave
    only "modal constants 0.13 times the other runs' ... calibration off"; now a warning names both."""
    spec = _two_runs(n_hits=2)
    spec["vertical"]["position"] = (0.03, 0.0, -0.045)  # the force channel stays at the true hit point
    result = identify(gen.write_file(tmp_path / "two_points.h5", spec), settings=FAST)
    both = [w for w in result.warnings if "are the hit point" in w or "both are the hit point" in w]
    assert len(both) == 1 and "run 'vertical'" in both[0] and "mm apart" in both[0]
    assert not any("both are the hit point" in w for w in identify(
        gen.write_file(tmp_path / "good.h5", _two_runs(n_hits=2)), settings=FAST).warnings)


PARAMETER_UNITS = {"f_V": "Hz", "zeta_V": "1", "K_V": "N/m", "c_V": "N*s/m",
                   "f_H": "Hz", "zeta_H": "1", "K_H": "N/m", "c_H": "N*s/m"}


def test_identify_json_has_the_contract_fields_for_every_file_even_a_failed_one(tmp_path):
    """Was: a file without a result printed ``"parameters": {}`` and no ``guide``."""
    good = gen.write_file(tmp_path / "good.h5", _two_runs())
    spec = _two_runs()
    for r in spec.values():
        r["data"][..., 5, 0] = np.nan  # every hit's force corrupt: every hit rejected
    rejected = gen.write_file(tmp_path / "all_rejected.h5", spec)
    folder = tmp_path / "folder.h5"
    folder.mkdir()
    files = [good, rejected, folder, tmp_path / "missing.h5"]
    code, out, err = cli("identify", *files, "--json")
    lines = out.strip().splitlines()
    assert len(lines) == len(files)  # one JSON line per input file, a directory included
    objs = [json.loads(line) for line in lines]
    assert [o["file"] for o in objs] == [str(f) for f in files]
    for o in objs:
        assert set(o["parameters"]) == set(PARAMETER_UNITS)
        for name, unit in PARAMETER_UNITS.items():
            assert o["parameters"][name]["unit"] == unit and "std" in o["parameters"][name]
        assert isinstance(o["modes"], list) and isinstance(o["warnings"], list)
    assert objs[0]["guide"] == "MRB35" and objs[0]["parameters"]["f_V"]["value"] == pytest.approx(F_V, rel=2e-4)
    assert objs[1]["guide"] == "MRB35" and objs[1]["exit_code"] == 1
    assert all(p["value"] is None for o in objs[1:] for p in o["parameters"].values())
    assert objs[2]["exit_code"] == 2 and "is a directory" in objs[2]["error"]
    assert objs[3]["exit_code"] == 2 and objs[3]["guide"] is None
    assert code == 2
    # one line per failed file, nothing else (was: a blank line left by the progress bar)
    assert err.count("\n") == 3 and all(line.startswith("guidefit: error: ") for line in err.splitlines())


@pytest.mark.parametrize("args", [
    ("identify",),
    ("identify", "--no-such-option", "x.h5"),
    ("no-such-command",),
    ("frf", "DIR"),
    ("identify", "x.h5", "--jobs", "0"),
    ("frf", "x.h5", "--window", "force=abc"),
])
def test_usage_errors_are_one_line(tmp_path, args):
    """Was: click's three-line usage block ("Usage: ...", "Try ...", "Error: ...")."""
    args = [str(tmp_path) if a == "DIR" else a for a in args]
    code, _, err = cli(*args)
    lines = err.strip().splitlines()
    assert code == 2
    assert len(lines) == 1 and lines[0].startswith("guidefit: error: "), err


def test_unknown_guide_named_by_a_file_says_which_file(tmp_path):
    """Was: "guide 'MRB99': not a built-in guide ..." without the file that named it."""
    path = gen.write_file(tmp_path / "rec.h5", _two_runs(n_hits=1), guide="MRB99")
    for command in ("identify", "explain"):
        code, _, err = cli(command, path)
        assert code == 2
        assert err.count("\n") == 1 and str(path) in err and "MRB99" in err and "--guide" in err
    code, _, err = cli("identify", path, "--guide", "MRB35", "--no-jackknife")
    assert code == 0, err


def test_run_without_accelerometer_is_refused_naming_the_file(tmp_path):
    """Was: "run 'only_force': hit 0 has shape (n, 1); ..." without the file name."""
    path = tmp_path / "force_only.csv"
    t = np.arange(400) / 200_000.0
    force = gen.half_sine(400, 200_000.0, 1e-4, 300.0, 1e-3)
    lines = ["# sample_rate_hz: 200000", "# excitation_direction: 0 -1 0", "time,force"]
    lines += [f"{a:.9g},{b:.9g}" for a, b in zip(t, force)]
    path.write_text("\n".join(lines) + "\n")
    for command in ("identify", "frf"):
        code, _, err = cli(command, path)
        assert code == 2
        assert err.count("\n") == 1 and str(path) in err and "no acceleration channel" in err


def test_optional_text_attribute_without_a_value_counts_as_absent(tmp_path):
    """Was: exit 2 for ``guide``/``description`` stored with a null dataspace (h5py.Empty).

    Some HDF5 writers store an empty string that way; for an optional attribute that is
    "not given", not a malformed file. A required attribute stored so is still refused.
    """
    path = gen.write_file(tmp_path / "rec.h5", _two_runs(n_hits=1))
    with h5py.File(path, "a") as f:
        f.attrs["guide"] = h5py.Empty("S10")
        f.attrs["description"] = h5py.Empty("S1")
    result = identify(path, settings=FAST)
    assert result.guide.name == "MRB35"
    assert result.parameters["f_V"]["value"] == pytest.approx(F_V, rel=2e-4)
    with h5py.File(path, "a") as f:
        f.attrs["format"] = h5py.Empty("S4")
    code, _, err = cli("identify", path)
    assert code == 2 and err.count("\n") == 1 and "'format'" in err


def test_records_too_short_for_any_mode_fail_cleanly(tmp_path):
    """Was: "internal error: ValueError: frequency_hz must be 1-D with at least 3 bins" for 2-sample hits."""
    spec = _two_runs(n=2000)
    for r in spec.values():
        r["data"] = r["data"][:, 195:197]  # 2 samples around the pulse start, no pretrigger attribute
    path = gen.write_file(tmp_path / "two_samples.h5", spec)
    code, out, err = cli("identify", path, "--json", "--no-jackknife")
    assert code == 1, err
    assert err.count("\n") == 1 and "internal error" not in err and "too coarse" in err
    obj = json.loads(out)
    assert obj["exit_code"] == 1 and all(p["value"] is None for p in obj["parameters"].values())


def test_output_error_without_a_file_name_has_no_empty_prefix(tmp_path):
    """Was: "guidefit: error: : Cannot save file into a non-existent directory: ..."."""
    path = gen.write_file(tmp_path / "rec.h5", _two_runs(n_hits=1))
    code, _, err = cli("identify", path, "--no-jackknife", "--summary", tmp_path / "no" / "such" / "dir" / "s.csv")
    assert code == 2
    assert err.count("\n") == 1 and err.startswith("guidefit: error: ") and not err.startswith("guidefit: error: :")


def _explain_json(path):
    code, out, err = cli("explain", path, "--json")
    assert code == 0, err
    lines = out.strip().splitlines()
    assert len(lines) == 1  # one JSON object
    d = json.loads(lines[0])
    assert d["file"] == str(path) and d["verdict"] in ("adequate", "explained", "unexplained")
    for key in ("error_before", "error_after"):
        assert isinstance(d[key]["rms_frequency_error_pct"], float)
    for m in d["modes"]:
        assert isinstance(m["label"], str) and isinstance(m["measured_hz"], float)
        assert {"model_before_hz", "model_after_hz"} <= set(m)
    for e in d["effects"]:
        assert isinstance(e["name"], str)
        assert all({"value", "std"} <= set(p) for p in e["parameters"].values())
    return d


def test_explain_on_independent_data_nominal_and_added_mass(tmp_path):
    """The nominal carriage is 'adequate' with no effect; 0.1 kg at the centre (in g units) is found."""
    nominal = _explain_json(gen.write_file(tmp_path / "nominal.h5", _two_runs(n_hits=2)))
    assert nominal["verdict"] == "adequate" and nominal["effects"] == []
    assert nominal["error_before"]["rms_frequency_error_pct"] < 0.05
    spec = {}
    for i, run in enumerate(("vertical", "lateral")):
        chans, data = gen.run_hits(run, n_hits=2, n=4000, seed=i, mass=gen.M + 0.1)
        spec[run] = dict(chans=chans, data=data, fs=200_000.0, direction=gen.RUNS[run][1],
                         position=gen.RUNS[run][0], units=["N"] + ["g"] * 8)
    heavy = _explain_json(gen.write_file(tmp_path / "heavy.h5", spec))
    # a centre mass shifts only the translational modes: vertical 3529 -> 3451 Hz (-2.2 %)
    assert heavy["verdict"] == "explained"
    assert [e["name"] for e in heavy["effects"]] == ["added_mass"]
    assert heavy["effects"][0]["parameters"]["mass_kg"]["value"] == pytest.approx(0.1, abs=0.005)
    assert heavy["error_after"]["rms_frequency_error_pct"] < 0.05 < heavy["error_before"]["rms_frequency_error_pct"]


def _tip(tmp_path, width_s):
    rng = np.random.default_rng(7)
    spec = {}
    for run in ("vertical", "lateral"):
        pos, d = gen.RUNS[run]
        chans = [(n, pos if n == "force" else p, d if n == "force" else dd) for n, p, dd in gen.default_channels()]
        data = np.stack([gen.hit_record(4000, 200_000.0, chans, pos, d, width_s=width_s, noise=0.002, rng=rng)
                         for _ in range(3)])
        spec[run] = dict(chans=chans, data=data, fs=200_000.0, direction=d, position=pos)
    return identify(gen.write_file(tmp_path / f"tip_{width_s}.h5", spec), settings=FAST)


def test_soft_hammer_tip_notch_at_a_joint_mode_is_warned(tmp_path):
    """Was: f_V 15 Hz (0.4 %, 2.3 std) off with no warning when a 1 ms pulse puts a notch at 3.5 kHz.

    A half-sine of width T has spectral zeros at (k + 1/2)/T: 2.5 and 3.5 kHz for T = 1 ms, right at
    f_H = 2496 Hz and f_V = 3529 Hz. A 0.1 ms pulse is flat (within 3 dB) up to 6 kHz.
    """
    soft = _tip(tmp_path, 1e-3)
    notched = [w for w in soft.warnings if "force there" in w]
    assert any(w.startswith("mode vertical") for w in notched)
    assert any(w.startswith("mode roll_low") for w in notched)
    hard = _tip(tmp_path, 1e-4)
    assert not [w for w in hard.warnings if "force there" in w]
    assert hard.parameters["f_V"]["value"] == pytest.approx(F_V, rel=2e-4)


@pytest.mark.parametrize("layout", ["hits", "signals"])
@pytest.mark.parametrize("value", [1e305, -1.7e308, 1e120])
def test_a_corrupt_huge_sample_rejects_its_hit(tmp_path, layout, value):
    """Was: "internal error: ValueError: H_channel_or_magnitude contains non-finite values".

    A flipped exponent bit turns a sample into ~1e305: finite, but its square overflows the
    spectral sums. Such a sample (beyond 1e100) now counts as non_finite; in a continuous record
    it no longer sets the trigger level either, so the other hits are found and used.
    """
    spec = _two_runs(n_hits=3, n=4000)
    for r in spec.values():
        if layout == "signals":
            gap = np.zeros((2000, 9))
            r["data"] = np.concatenate([np.concatenate([gap, h]) for h in r["data"]] + [gap])
            r["data"][2000 + 6000 + 900, 0] = value  # in the force of the second hit
        else:
            r["data"][1, 900, 3] = value
        r["layout"] = layout
    path = gen.write_file(tmp_path / "corrupt.h5", spec)
    result = identify(path, settings=FAST)
    rows = result.hit_rows()
    rejected = [h for h in rows if not h["accepted"]]
    assert len(rows) == 6 and [h["hit"] for h in rejected] == [1, 1]
    assert all(h["reason"].startswith("non_finite") for h in rejected)
    assert result.parameters["f_V"]["value"] == pytest.approx(F_V, rel=2e-4)
    assert result.parameters["f_H"]["value"] == pytest.approx(F_H, rel=2e-4)


def _csv(tmp_path, name, meta_lines, header=True):
    chans, data = gen.run_hits("vertical", n_hits=2, n=3000, seed=0, axes="y")
    gap = np.zeros((1500, data.shape[-1]))
    signal = np.concatenate([np.concatenate([gap, h]) for h in data] + [gap])
    path = tmp_path / name
    gen.write_csv(path, chans, signal, 200_000.0, (0, -1, 0), meta={}, time_col=False, positions=False)
    lines = path.read_text().splitlines()
    path.write_text("\n".join(meta_lines + lines) + "\n")
    return path


def test_csv_key_given_twice_with_another_value_is_refused(tmp_path):
    """Was: the later '# sample_rate_hz' line silently won: f_V = 1764.5 Hz from a 200 kHz file."""
    ok = _csv(tmp_path, "once.csv", [])
    assert identify(ok, settings=FAST).parameters["f_V"]["value"] == pytest.approx(F_V, rel=2e-4)
    same = _csv(tmp_path, "same_twice.csv", ["# sample_rate_hz: 200000.0"])
    assert identify(same, settings=FAST).parameters["f_V"]["value"] == pytest.approx(F_V, rel=2e-4)
    twice = _csv(tmp_path, "twice.csv", ["# Sample_Rate_Hz: 100000"])
    code, out, err = cli("identify", twice, "--json", "--no-jackknife")
    assert code == 2 and err.count("\n") == 1
    assert "'sample_rate_hz': given again" in err and "100000" in err
    assert json.loads(out)["parameters"]["f_V"]["value"] is None


def test_csv_time_column_not_first_says_so(tmp_path):
    path = tmp_path / "time_last.csv"
    path.write_text("# sample_rate_hz: 200000\n# excitation_direction: 0 -1 0\nforce,acc_A_y,time\n0,0,0\n1,1,0.000005\n")
    code, _, err = cli("identify", path)
    assert code == 2 and err.count("\n") == 1 and "'time' column must be its first column" in err


def test_paper_case_compliant_lateral_support_independent_data(tmp_path):
    """physics-notes: a lateral rail support of 1.2e8 N/m pulls the u-phi mode from 2496 to ~1075 Hz.

    The independent writer condenses a massless rail on that spring into the roller springs:
    roll_low = 1080.9 Hz, the other joint mode untouched. Identify must report it as f_H with
    K_H = 4 pi^2 M f_H^2 (the paper's 1.00e8 N/m) and explain must name the support.
    """
    freqs, _ = gen.modes(k_support=1.2e8)
    zetas = [0.105, 0.02, 0.02, 0.0288, 0.02]  # ascending: roll_low is now the lowest mode
    spec = {}
    for i, run in enumerate(("vertical", "lateral")):
        chans, data = gen.run_hits(run, n_hits=2, n=6000, seed=i, k_support=1.2e8, zetas=zetas)
        spec[run] = dict(chans=chans, data=data, fs=200_000.0, direction=gen.RUNS[run][1],
                         position=gen.RUNS[run][0])
    path = gen.write_file(tmp_path / "support.h5", spec)
    p = identify(path, settings=FAST).parameters
    assert freqs[0] == pytest.approx(1080.9, abs=0.1)
    assert p["f_H"]["value"] == pytest.approx(freqs[0], rel=5e-4)
    assert p["zeta_H"]["value"] == pytest.approx(0.105, rel=0.02)
    assert p["K_H"]["value"] == pytest.approx(4 * np.pi ** 2 * gen.M * freqs[0] ** 2, rel=1e-3)
    assert p["f_V"]["value"] == pytest.approx(F_V, rel=2e-4)
    d = _explain_json(path)
    assert d["verdict"] == "explained"
    assert [(e["name"], e["variant"]) for e in d["effects"]] == [("support_compliance", "lateral")]
    assert d["effects"][0]["parameters"]["lateral_n_per_m"]["value"] == pytest.approx(1.2e8, rel=0.01)


def test_heavy_vertical_base_splits_the_vertical_mode_independent_data(tmp_path):
    """physics-notes: a heavy base splits the vertical mode into an in-phase and an anti-phase pair
    with identical shapes at A-D. 3 kg on 3e9 N/m: 2852.0 and 6227.6 Hz. f_V is the in-phase
    (lower) one; explain must find base_mode with the body's mass and spring."""
    modal = gen.modes_with_vertical_base(3.0, 3e9)
    assert modal[0][3] == pytest.approx(2852.0, abs=0.1) and modal[0][5] == pytest.approx(6227.6, abs=0.1)
    spec = {}
    for i, run in enumerate(("vertical", "lateral")):
        chans, data = gen.run_hits(run, n_hits=2, n=6000, seed=i, modal=modal)
        spec[run] = dict(chans=chans, data=data, fs=200_000.0, direction=gen.RUNS[run][1],
                         position=gen.RUNS[run][0])
    path = gen.write_file(tmp_path / "base.h5", spec)
    result = identify(path, settings=FAST)
    assert result.parameters["f_V"]["value"] == pytest.approx(modal[0][3], rel=2e-4)
    assert result.parameters["f_H"]["value"] == pytest.approx(F_H, rel=2e-4)
    assert [m.frequency_hz for m in result.extra_modes] == [pytest.approx(modal[0][5], rel=2e-4)]
    # was: "(shape not matching any carriage mode)" for a mode whose shape is the vertical one (its
    # label went to the nearer mode of the pair)
    extra = [w for w in result.warnings if "does not predict" in w]
    assert len(extra) == 1 and "not paired with any carriage mode" in extra[0]
    d = _explain_json(path)
    assert d["verdict"] == "explained"
    assert [(e["name"], e["variant"]) for e in d["effects"]] == [("base_mode", "vertical")]
    params = d["effects"][0]["parameters"]
    assert params["mass_kg"]["value"] == pytest.approx(3.0, rel=0.02)
    assert params["vertical_n_per_m"]["value"] == pytest.approx(3e9, rel=0.02)


@pytest.mark.parametrize("toml, message", [
    ('[parameters]\nK_v = { min = 1e9 }\n', "unknown parameter 'parameters.K_v'"),
    ('[parameters]\nK_V = { min = nan }\n', "must be a finite number"),
    ('[parameters]\nf_H = { max = inf }\n', "must be a finite number"),
    ('[quality]\nmin_coherence = 1.5\n', "from 0 to 1"),
    ('[quality]\nmax_rejected_hits = 2.5\n', "an integer >= 0"),
    ('[quality]\nmax_relative_std = -0.1\n', ">= 0"),
])
def test_invalid_check_spec_is_bad_input(tmp_path, toml, message):
    """Was: a typo'd name failed every file ("K_v not identified", exit 1); NaN limits passed anything."""
    from guidefit.report.check import CheckSpecError, parse_spec

    spec = tmp_path / "spec.toml"
    spec.write_text(toml)
    import tomllib

    with pytest.raises(CheckSpecError, match=message.replace("(", r"\(").replace(")", r"\)")):
        parse_spec(tomllib.loads(toml), str(spec))


def test_check_spec_nan_limit_refused_on_the_command_line(tmp_path):
    path = gen.write_file(tmp_path / "rec.h5", _two_runs(n_hits=1))
    spec = tmp_path / "spec.toml"
    spec.write_text("[parameters]\nK_V = { min = nan }\n")
    code, _, err = cli("identify", path, "--check", spec, "--no-jackknife")
    assert code == 2 and err.count("\n") == 1 and "finite number" in err


@pytest.mark.parametrize("offset_n", [-30.0, -3.0, 30.0, 100.0])
def test_force_sensor_offset_does_not_bias_the_frf(tmp_path, offset_n):
    """Was: a constant force offset (sensor bias) stayed in the windowed force: -30 N on 300 N hits
    put H 11 % off the true accelerance and f_V 2.8 Hz (90 std) low; +30 N stretched the detected
    pulse over the whole record (no force window), 1 % off. The offset is now removed."""
    clean = gen.write_file(tmp_path / "clean.h5", _two_runs(n_hits=2, n=6000, pretrigger=200))
    spec = _two_runs(n_hits=2, n=6000, pretrigger=200)
    for r in spec.values():
        r["data"][..., 0] += offset_n
    biased = gen.write_file(tmp_path / "offset.h5", spec)
    a, _ = frf_of_recording(clean, FAST)
    b, _ = frf_of_recording(biased, FAST)
    for fa, fb in zip(a, b):
        f = np.asarray(fa.frequency_hz)
        band = (f > 1500) & (f < 6000)
        assert np.median(np.abs(fb.H[band] / fa.H[band] - 1)) < 0.002
    result = identify(biased, settings=FAST)
    assert result.parameters["f_V"]["value"] == pytest.approx(F_V, rel=5e-5)


def test_html_report_lists_the_hits_of_a_run_without_frf(tmp_path):
    """Was: the HTML report counted hits from the runs with FRFs only (same gap as the table).

    And: the report of this incomplete identification (identify and explain exit 1) exited 0 with
    no word of f_V, K_V, c_V missing; now the report is written, says so, and exits 1."""
    path = _all_hits_rejected_in_vertical(tmp_path)
    out = tmp_path / "report.html"
    code, _, err = cli("report", path, "-o", str(out))
    assert code == 1, err
    assert "identification incomplete" in err and "f_V, K_V, c_V not identified" in err
    text = out.read_text()
    assert "3 accepted, 3 rejected" in text and "Identification incomplete" in text


def test_explain_on_an_incomplete_identification_says_so_and_exits_1(tmp_path):
    """Was: identify exit 1 ('identification incomplete': the vertical run gave no FRF) while explain on the
    same file gave its verdict on the modes it had ('adequate') with exit 0 and no word of the missing mode."""
    path = _all_hits_rejected_in_vertical(tmp_path)
    code, out, err = cli("explain", path, "--candidates", "added_mass")
    assert code == 1, err
    assert "identification incomplete" in err and "f_V, K_V, c_V not identified" in err
    assert out.strip()  # the explanation of the modes found is still shown


def test_explain_modes_of_an_incomplete_result_exits_1(tmp_path):
    """Was: explain --modes of that file's identify --json ('unidentified' set) exit 0, no word."""
    path = _all_hits_rejected_in_vertical(tmp_path)
    _, out, _ = cli("identify", path, "--json")
    modes = tmp_path / "r.json"
    modes.write_text(out)
    code, out, err = cli("explain", "--modes", str(modes), "--candidates", "added_mass", "--json")
    assert code == 1, err
    assert "identification incomplete" in err and "f_V, K_V, c_V not identified" in err
    assert json.loads(out)["verdict"]
