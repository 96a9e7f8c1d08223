"""The CI example script in docs/ runs a production-line check end to end."""

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.skipif(shutil.which("bash") is None, reason="needs bash")
def test_ci_example_script(tmp_path):
    guidefit_bin = Path(sys.executable).parent / "guidefit"
    if not guidefit_bin.exists():
        pytest.skip("guidefit console script not installed beside this Python")
    spec = tmp_path / "line_spec.toml"
    spec.write_text("[parameters]\nK_V = { min = 0.9e9, max = 1.2e9 }\nK_H = { min = 2e8 }\n")
    samples = [str(ROOT / "sample_data" / "mrb35_sample.h5"), str(ROOT / "sample_data" / "mrb35_paper_like.h5")]
    env = {"PATH": f"{guidefit_bin.parent}:/usr/bin:/bin"}
    proc = subprocess.run(["bash", str(ROOT / "docs" / "ci-example.sh"), str(spec), *samples],
                          cwd=tmp_path, check=False, capture_output=True, text=True, env=env, timeout=600)
    # the paper-like carriage has K_H = 1.0e8 N/m < 2e8: out of tolerance -> exit 1
    assert proc.returncode == 1, proc.stderr
    assert "K_H" in proc.stderr
    deck = (tmp_path / "joints.bdf").read_text()  # both carriages' explained joints, full matrices
    assert "$ carriage 2: " in deck and "$ carriage 3: " not in deck and deck.count("DMIG*   GFJK            0") == 1
    assert "rig effects removed: support_compliance" in deck  # the paper-like carriage's soft support
    assert 'failures="1"' in (tmp_path / "junit.xml").read_text()
    assert len((tmp_path / "results.jsonl").read_text().strip().splitlines()) == 2
