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
    assert data["stiffness"]["K_V"]["value"] == pytest.approx(4 * 21 * 2.5754e7 * 0.5, rel=1e-6)


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
    assert "vertical" in result.output and "3529.0 Hz" in result.output
    assert out.stat().st_size > 10_000


def test_predict_sweep_json_lines():
    result = run("predict", "--sweep", "--json")
    assert result.exit_code == 0, result.output
    rows = [json.loads(line) for line in result.output.strip().splitlines()]
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
