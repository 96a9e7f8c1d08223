"""The catalogue of malformed inputs, end to end through the command line.

Every case gets exit 2 (bad input) or 1 (valid input, but no result can be
trusted) and exactly one line on stderr that names the file, the place and
what was expected; never a traceback.
"""

import subprocess
import sys

import h5py
import numpy as np
import pytest

from guidefit.io import write_recording
from guidefit.simulate import DEFAULT_RUNS, SimulationConfig, simulate

FS = 200_000.0


def guidefit(*args, cwd=None):
    proc = subprocess.run([sys.executable, "-m", "guidefit", *map(str, args)], check=False, capture_output=True, text=True,
                          cwd=cwd, timeout=300)
    return proc.returncode, proc.stdout, proc.stderr


def write_h5(path, mutate=None, layout="hits"):
    """A valid small recording, then ``mutate(file)`` breaks it."""
    t = np.arange(2000) / FS
    force = np.where(t < 1e-4, 300 * np.sin(np.pi * t / 1e-4), 0.0)
    acc = 50 * np.exp(-600 * t) * np.sin(2 * np.pi * 3500 * t)
    data = np.stack([force, acc, acc], axis=1)
    with h5py.File(path, "w") as f:
        f.attrs["format"] = "guidefit-recording"
        f.attrs["format_version"] = 1
        f.attrs["guide"] = "MRB35"
        run = f.create_group("runs/vertical")
        run.attrs["sample_rate_hz"] = FS
        run.attrs["excitation_direction"] = [0.0, -1.0, 0.0]
        arr = np.stack([data, data * 0.9]) if layout == "hits" else np.concatenate([np.zeros((200, 3)), data])
        ds = run.create_dataset(layout, data=arr)
        ds.attrs["channel_names"] = ["force", "acc_A_y", "acc_B_y"]
        ds.attrs["units"] = ["N", "m/s^2", "m/s^2"]
        ds.attrs["positions_m"] = [[0, 0, 0], [0.03, 0, 0.045], [-0.03, 0, 0.045]]
        ds.attrs["directions"] = [[0, -1, 0], [0, 1, 0], [0, 1, 0]]
        if mutate:
            mutate(f)
    return path


def _set(path_in_file, name, value):
    def mutate(f):
        obj = f[path_in_file] if path_in_file else f
        obj.attrs[name] = value
    return mutate


def _del(path_in_file, name=None):
    def mutate(f):
        if name is None:
            del f[path_in_file]
        else:
            del (f[path_in_file] if path_in_file else f).attrs[name]
    return mutate


def _replace_data(data):
    def mutate(f):
        ds = f["runs/vertical/hits"]
        attrs = dict(ds.attrs)
        del f["runs/vertical/hits"]
        new = f["runs/vertical"].create_dataset("hits", data=data)
        for k, v in attrs.items():
            new.attrs[k] = v
    return mutate


H5_CASES = {
    "missing format": (_del("", "format"), "format"),
    "wrong version": (_set("", "format_version", 7), "version"),
    "no runs": (_del("runs"), "runs"),
    "no dataset": (_del("runs/vertical/hits"), "signals"),
    "missing channel_names": (_del("runs/vertical/hits", "channel_names"), "channel_names"),
    "missing units": (_del("runs/vertical/hits", "units"), "units"),
    "missing positions": (_del("runs/vertical/hits", "positions_m"), "positions_m"),
    "missing directions": (_del("runs/vertical/hits", "directions"), "directions"),
    "no force channel": (_set("runs/vertical/hits", "channel_names", ["acc_C_y", "acc_A_y", "acc_B_y"]), "force"),
    "two force channels": (_set("runs/vertical/hits", "channel_names", ["force", "force", "acc_B_y"]), "force"),
    "bad unit": (_set("runs/vertical/hits", "units", ["N", "m/s2", "m/s^2"]), "unit"),
    "force in g": (_set("runs/vertical/hits", "units", ["g", "m/s^2", "m/s^2"]), "force"),
    "zero sample rate": (_set("runs/vertical", "sample_rate_hz", 0.0), "sample_rate_hz"),
    "negative sample rate": (_set("runs/vertical", "sample_rate_hz", -5.0), "sample_rate_hz"),
    "non-unit direction": (_set("runs/vertical/hits", "directions", [[0, -1, 0], [0, 2, 0], [0, 1, 0]]), "direction"),
    "non-unit excitation": (_set("runs/vertical", "excitation_direction", [0, -3, 0]), "excitation_direction"),
    "channel count mismatch": (_set("runs/vertical/hits", "channel_names", ["force", "acc_A_y"]), "channel"),
    "wrong shape": (_replace_data(np.zeros((2000, 3))), "hits"),
    "complex dtype": (_replace_data(np.zeros((2, 2000, 3), complex)), "dtype"),
    # was: exit 0 (a setup) or exit 1 with the plausibility gate's "neither joint mode found" (every position 1000x)
    "positions in millimetres": (_set("runs/vertical/hits", "positions_m", [[0, 0, 0], [30, 0, 45], [-30, 0, 45]]),
                                 "millimetres given?"),
    "hit point in millimetres": (_set("runs/vertical", "excitation_position_m", [4.0, 0.0, 8.0]), "millimetres"),
    # was: exit 0 with K_V null (the labels believed the excitation: x on y sensors sees no vertical mode)
    "force across the hit": (_set("runs/vertical", "excitation_direction", [-1.0, 0.0, 0.0]), "line of action"),
    "missing sample rate": (_del("runs/vertical", "sample_rate_hz"), "sample_rate_hz"),
}


@pytest.mark.parametrize("case", sorted(H5_CASES))
def test_malformed_hdf5_exit_2_one_line(tmp_path, case):
    mutate, fragment = H5_CASES[case]
    path = write_h5(tmp_path / "bad.h5", mutate)
    code, _out, err = guidefit("identify", path)
    assert code == 2, (case, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    assert "bad.h5" in lines[0], lines[0]
    assert fragment.lower() in lines[0].lower(), lines[0]


@pytest.mark.parametrize("content", [b"", b"\x89HDF\r\n\x1a\n\x00\x00\x00", b"hello, this is not a recording"])
def test_empty_truncated_and_non_hdf5(tmp_path, content):
    path = tmp_path / "bad.h5"
    path.write_bytes(content)
    code, _, err = guidefit("identify", path)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "bad.h5" in err


def test_truncated_real_file(tmp_path):
    good = write_h5(tmp_path / "good.h5")
    data = good.read_bytes()
    cut = tmp_path / "cut.h5"
    cut.write_bytes(data[: len(data) // 2])
    code, _, err = guidefit("identify", cut)
    assert code == 2 and "cut.h5" in err and len(err.strip().splitlines()) == 1


def test_missing_file(tmp_path):
    code, _, err = guidefit("identify", tmp_path / "nope.h5")
    assert code == 2 and "nope.h5" in err


CSV_HEADER = "# sample_rate_hz: 200000\n# excitation_direction: 0 -1 0\n# guide: MRB35\n"


@pytest.mark.parametrize(
    "body, fragment",
    [
        ("force;acc_A_y\n1,0;2,0\n3,0;4,0\n", "';'"),
        ("force,acc_A_y\n1.0,2.0\n3.0,\n", "missing"),
        ("force,acc_A_y\n1.0,2.0\n3.0,abc\n", "abc"),
        ("1.0,2.0\n3.0,4.0\n", "header"),
        ("force,acc_A_y,acc_A_y\n1,2,3\n", "acc_A_y"),
        ("# directions: 1 0 0; 0 1 0\nforce,acc_A_y\n1,2\n3,4\n", "line of action"),  # force along x, hit along -y
        ("# positions_m: 0 0 0; 30 0 45\nforce,acc_A_y\n1,2\n3,4\n", "millimetres"),
    ],
)
def test_malformed_csv(tmp_path, body, fragment):
    path = tmp_path / "bad.csv"
    path.write_text(CSV_HEADER + body)
    code, _, err = guidefit("identify", path)
    assert code == 2, err
    assert len(err.strip().splitlines()) == 1 and "bad.csv" in err
    assert fragment.lower() in err.lower(), err


def test_csv_without_rate(tmp_path):
    path = tmp_path / "bad.csv"
    path.write_text("# excitation_direction: 0 -1 0\nforce,acc_A_y\n1,2\n3,4\n")
    code, _, err = guidefit("identify", path)
    assert code == 2 and "sample" in err.lower() and "bad.csv" in err


def test_nan_samples_reject_the_hit_and_no_result_is_exit_1(tmp_path):
    def mutate(f):
        ds = f["runs/vertical/hits"]
        arr = ds[...]
        arr[:, 500, 1] = np.nan
        ds[...] = arr
    path = write_h5(tmp_path / "nan.h5", mutate)
    code, _, err = guidefit("identify", path)
    assert code == 1, err
    assert "nan.h5" in err and "Traceback" not in err


def test_no_hit_reaches_trigger(tmp_path):
    def mutate(f):
        ds = f["runs/vertical/signals"]
        ds[...] = np.zeros(ds.shape)
    path = write_h5(tmp_path / "quiet.h5", mutate, layout="signals")
    code, _, err = guidefit("identify", path)
    assert code == 1, err
    assert "quiet.h5" in err and len(err.strip().splitlines()) == 1


def test_all_hits_rejected_lists_reasons_in_json(tmp_path):
    rec, _ = simulate("MRB35", config=SimulationConfig(runs=(DEFAULT_RUNS[0],), hits=2, record_s=0.01,
                                                       force_n=(5000.0, 6000.0)), seed=1)
    path = tmp_path / "clipped.h5"
    write_recording(path, rec)
    code, _out, err = guidefit("identify", path, "--json")
    assert code == 1
    assert "clipped.h5" in err


@pytest.mark.parametrize(
    "text, fragment",
    [
        ("name='x'\n", "section [carriage] missing"),
        ("[carriage]\nmass_kg = -2\n", "mass_kg"),
        ("[carriage]\nmass_kg = 2\ncolour = 1\n", "colour"),
    ],
)
def test_bad_guide_toml(tmp_path, text, fragment):
    guide = tmp_path / "g.toml"
    guide.write_text(text)
    code, _, err = guidefit("predict", "--guide", guide)
    assert code == 2 and fragment in err and len(err.strip().splitlines()) == 1


def test_usage_errors_exit_2():
    code, _, _err = guidefit("identify")
    assert code == 2
    code, _, _err = guidefit("predict", "--calibration", "magic")
    assert code == 2


def test_channel_name_with_a_trailing_line_break_is_refused_in_one_line(tmp_path):
    """Issue 21, item 10: the pattern's ``$`` matched before a final newline, so 'acc_A_y\\n' was a valid name
    that then broke the CSV header."""
    import shutil
    from pathlib import Path

    from click.testing import CliRunner

    from guidefit.cli import main

    path = tmp_path / "newline.h5"
    shutil.copy(Path(__file__).resolve().parents[1] / "sample_data" / "mrb35_sample.h5", path)
    with h5py.File(path, "r+") as f:
        run = next(iter(f["runs"].values()))
        ds = run["hits"] if "hits" in run else run["signals"]
        names = [n.decode() if isinstance(n, bytes) else str(n) for n in ds.attrs["channel_names"]]
        names[1] = names[1] + "\n"
        ds.attrs["channel_names"] = names
    out = CliRunner().invoke(main, ["identify", str(path)])
    assert out.exit_code == 2, out.output
    lines = [line for line in out.output.splitlines() if line.strip()]
    assert len(lines) == 1 and "not recognised" in lines[0] and "\\n" in lines[0]


@pytest.mark.parametrize("command", [["identify", "FILE"], ["explain", "FILE"], ["predict"], ["plan"]])
def test_a_plot_no_figure_can_be_is_refused_before_any_work(tmp_path, command):
    """Issue 21, item 11: ``--plot out.csv`` was found after the whole run (an internal error, exit 1)."""
    from pathlib import Path

    from click.testing import CliRunner

    from guidefit.cli import main

    sample = str(Path(__file__).resolve().parents[1] / "sample_data" / "mrb35_sample.h5")
    args = [sample if a == "FILE" else a for a in command] + ["--plot", str(tmp_path / "out.csv")]
    out = CliRunner().invoke(main, args)
    assert out.exit_code == 2, out.output
    lines = [line for line in out.output.splitlines() if line.strip()]
    assert len(lines) == 1 and "--plot" in lines[0] and ".png" in lines[0]
    assert not (tmp_path / "out.csv").exists()
