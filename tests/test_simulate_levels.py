"""The simulator chooses its hammer for the carriage when no forces are given (guidefit.simulate.levels).

Before: every guide got 200-500 N hits on a +/-1024 m/s^2 accelerometer range, so
every vertical hit of the 0.6 kg ball4_size25 carriage (peak about 1770 m/s^2)
and every hit of the 34 g ball2_size12 (about 43 500 m/s^2) clipped and
``identify`` on the default simulation rejected them all (exit 1).
"""

import json
from pathlib import Path

import pytest
from click.testing import CliRunner

from guidefit.cli import main
from guidefit.simulate import SimulationConfig, simulate
from guidefit.simulate.levels import PEAK_LIMIT

EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "guides"


def _simulate(tmp_path, guide, *args):
    out = tmp_path / "rec.h5"
    result = CliRunner().invoke(main, ["simulate", "--guide", str(guide), "--out", str(out), "--hits", "3",
                                       "--record-length", "0.03", "--seed", "5", *args])
    assert result.exit_code == 0, result.output
    return out, json.loads(out.with_suffix(".truth.json").read_text()), result.output


@pytest.mark.parametrize("name", ["ball4_size25", "ball2_size12"])
def test_default_simulation_of_a_ball_guide_identifies_without_clipping(tmp_path, name):
    guide = EXAMPLES / f"{name}.toml"
    out, truth, output = _simulate(tmp_path, guide)
    result = CliRunner().invoke(main, ["identify", str(out), "--json", "--guide", str(guide)])
    assert result.exit_code == 0, result.output
    found = json.loads(result.output.splitlines()[0])
    assert found["hits"] and all(h["accepted"] for h in found["hits"]), found["hits"]
    for key in ("f_V", "f_H"):
        assert found["parameters"][key]["value"] == pytest.approx(truth["parameters"][key]["value"], rel=5e-3), key
    # the choice is said on the command line and kept in the truth file
    choice = truth["force_choice"]
    assert output.splitlines()[0] == choice["message"]
    assert choice["force_n"][1] < 500 and choice["peak_m_s2"] <= PEAK_LIMIT * 1024.0
    assert truth["config"]["force_n"] == choice["force_n"]


def test_explicit_forces_are_used_as_given_and_clip(tmp_path):
    guide = EXAMPLES / "ball4_size25.toml"
    out, truth, output = _simulate(tmp_path, guide, "--force", "200,500", "--runs", "vertical")
    assert "force_choice" not in truth and "hammer chosen" not in output
    assert truth["config"]["force_n"] == [200.0, 500.0] and truth["config"]["force_range_n"] == 2048.0
    result = CliRunner().invoke(main, ["identify", str(out), "--json", "--guide", str(guide)])
    assert result.exit_code == 1 and "clipped" in result.output


def test_mrb35_keeps_the_default_forces_and_ranges():
    # MRB35 peaks near 330 m/s^2 at 500 N (32 % of the range): the rule leaves it alone
    _, truth = simulate("MRB35", config=SimulationConfig(hits=1, record_s=0.005), seed=1)
    assert "force_choice" not in truth
    assert truth["config"]["force_n"] == [200.0, 500.0] and truth["config"]["force_range_n"] == 2048.0
    assert truth["config"]["acc_range_m_s2"] == 1024.0


def test_an_ideal_chain_never_clips_so_it_keeps_the_default_forces():
    config = SimulationConfig(runs=SimulationConfig().runs[:1], hits=1, record_s=0.005).ideal()
    _, truth = simulate(str(EXAMPLES / "ball2_size12.toml"), config=config, seed=1)
    assert "force_choice" not in truth and truth["config"]["force_n"] == [200.0, 500.0]
