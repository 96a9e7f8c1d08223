"""Command line: exit codes, one-line errors, JSON, documentation of every command."""

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

from guidefit.cli import main

ROOT = Path(__file__).resolve().parents[1]


def run(*args):
    return CliRunner().invoke(main, list(args))


def test_guides_lists_mrb35():
    result = run("guides")
    assert result.exit_code == 0
    assert "MRB35" in result.output


def test_predict_json_gives_papers_frequency():
    result = run("predict", "--guide", "MRB35", "--json")
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
    freqs = {m["label"]: m["frequency_hz"] for m in data["modes"]}
    assert freqs["vertical"] == pytest.approx(3529.0, abs=1.0)
    # nominal calibration: K_V = 4 Z K_n sin^2(45 deg)
    assert data["stiffness"]["static_zero_load"]["K_V"]["value"] == pytest.approx(4 * 21 * 2.5754e7 * 0.5, rel=1e-6)


def test_predict_under_load_changes_frequencies():
    free = json.loads(run("predict", "--json").output)
    loaded = json.loads(run("predict", "--json", "--load", "800,0,0").output)
    f0 = {m["label"]: m["frequency_hz"] for m in free["modes"]}
    f1 = {m["label"]: m["frequency_hz"] for m in loaded["modes"]}
    assert f1["vertical"] != pytest.approx(f0["vertical"], rel=1e-4)


def test_predict_table_and_plot(tmp_path):
    out = tmp_path / "p.png"
    result = run("predict", "--plot", str(out))
    assert result.exit_code == 0, result.output
    assert "vertical" in result.output and "3529.0" in result.output
    assert out.stat().st_size > 10_000


def test_predict_sweep_json_is_one_document():
    result = run("predict", "--sweep", "--json")
    assert result.exit_code == 0, result.output
    rows = json.loads(result.output)["rows"]
    assert len(rows) > 5


@pytest.mark.parametrize(
    "args, fragment",
    [
        (["predict", "--guide", "NOPE"], "not a built-in guide"),
        (["predict", "--load", "1,2"], "expected FV,FH,M"),
        (["predict", "--load", "1e9,0,0"], "load"),
    ],
)
def test_bad_input_exits_2_with_one_line(args, fragment):
    result = run(*args)
    assert result.exit_code == 2, result.output
    assert fragment in result.output
    assert "Traceback" not in result.output


def test_bad_guide_file_via_subprocess(tmp_path):
    guide = tmp_path / "g.toml"
    guide.write_text("name = 'x'\n[carriage]\nmass_kg = -1\n")
    proc = subprocess.run([sys.executable, "-m", "guidefit", "predict", "--guide", str(guide)],
                          check=False, capture_output=True, text=True)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("guidefit: error:")


def test_every_command_is_documented():
    """Each CLI command appears in the README or docs/ (sqlite-utils' habit)."""
    text = (ROOT / "README.md").read_text() + "".join(p.read_text() for p in (ROOT / "docs").glob("*.md"))
    for name in main.commands:
        assert re.search(rf"guidefit {name}\b", text), f"command '{name}' is not documented"


# ------------------------------------------------------------------ --fft-precision


@pytest.fixture(scope="module")
def float32_recordings(tmp_path_factory):
    """Two small simulated recordings stored as float32 (as ``guidefit simulate`` writes them)."""
    from dataclasses import replace

    from guidefit.simulate import SimulationConfig, write_simulation

    folder = tmp_path_factory.mktemp("fft_precision")
    config = replace(SimulationConfig(), hits=4, record_s=0.05)
    return [write_simulation(folder / f"rec{seed}.h5", "MRB35", config=config, seed=seed).recordings[0]
            for seed in (1, 2)]


@pytest.mark.parametrize("args, expected", [
    ((), "single"),  # auto: the file stores float32
    (("--fft-precision", "auto"), "single"),
    (("--fft-precision", "single"), "single"),
    (("--fft-precision", "double"), "double"),
])
def test_frf_fft_precision_is_written_to_the_h5(tmp_path, float32_recordings, args, expected):
    from guidefit.frf import read_frf_h5

    out = tmp_path / "frf.h5"
    result = run("frf", str(float32_recordings[0]), "--out", str(out), *args)
    assert result.exit_code == 0, result.output
    assert [frf.fft_precision for frf in read_frf_h5(out)] == [expected, expected]


def test_identify_fft_precision_reaches_every_worker(float32_recordings):
    """--jobs 2 (a process per file) gives the results of --jobs 1, and double differs from single."""

    def values(*args):
        result = run("identify", *map(str, float32_recordings), "--json", "--no-jackknife", *args)
        assert result.exit_code == 0, result.output
        objs = [json.loads(line) for line in result.output.strip().splitlines()]
        return [{k: p["value"] for k, p in o["parameters"].items()} for o in objs]

    def same(a, b):  # same code on the same machine: floats within 1e-9 relative, never bit equality
        assert len(a) == len(b) and all(x.keys() == y.keys() for x, y in zip(a, b))
        for x, y in zip(a, b):
            for k in x:
                assert (x[k] is None) == (y[k] is None), k
                if x[k] is not None:
                    assert x[k] == pytest.approx(y[k], rel=1e-9, abs=1e-300), k

    double = values("--fft-precision", "double")
    same(values("--fft-precision", "double", "--jobs", "2"), double)
    single = values()  # auto on float32 files
    same(values("--fft-precision", "single", "--jobs", "2"), single)
    # float32 FFTs move the damping ratios by ~1e-8 relative (tests/test_frf_precision.py): not the same bits
    assert [v["zeta_V"] for v in single] != [v["zeta_V"] for v in double]
    for s, d in zip(single, double):
        assert s["zeta_V"] == pytest.approx(d["zeta_V"], rel=1e-7)


@pytest.mark.parametrize("command", ["identify", "frf"])
def test_bad_fft_precision_exits_2_with_one_line(command):
    result = run(command, "x.h5", "--fft-precision", "quad")
    assert result.exit_code == 2, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("guidefit: error:"), result.output
    assert "--fft-precision" in lines[0] and "'quad'" in lines[0] and "auto" in lines[0]


def test_fft_precision_choices_are_the_librarys():
    from guidefit.frf import PRECISIONS

    for name in ("identify", "frf"):
        (option,) = [p for p in main.commands[name].params if p.name == "fft_precision"]
        assert tuple(option.type.choices) == PRECISIONS and option.default == "auto"


def test_estimator_choices_are_the_frf_estimators():
    """--estimator of identify and frf offers exactly guidefit.frf.ESTIMATORS (written once)."""
    from guidefit.frf import ESTIMATORS

    for command in ("identify", "frf"):
        out = CliRunner().invoke(main, [command, "--help"])
        assert out.exit_code == 0 and f"[{'|'.join(ESTIMATORS)}]" in out.output, command
        bad = CliRunner().invoke(main, [command, "x.h5", "--estimator", "H3"])
        assert bad.exit_code == 2 and all(name in bad.output for name in ESTIMATORS), command
