"""HTML report: self-contained, complete, and rendered by a real browser when one is installed."""

import base64
import re
import shutil
import subprocess
from pathlib import Path

import pytest
from click.testing import CliRunner

from guidefit.cli import main

SAMPLE = Path(__file__).resolve().parents[1] / "sample_data" / "mrb35_sample.h5"


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    out = tmp_path_factory.mktemp("report") / "report.html"
    result = CliRunner().invoke(main, ["report", str(SAMPLE), "-o", str(out)])
    assert result.exit_code == 0, result.output
    return out


def test_report_is_self_contained_and_complete(report):
    text = report.read_text()
    # no external resources: every src is an embedded data URI
    assert not re.search(r"""(src|href)=['"](?!data:)""", text)
    images = re.findall(r"data:image/png;base64,([A-Za-z0-9+/=]+)", text)
    assert images and base64.b64decode(images[0])[:8] == b"\x89PNG\r\n\x1a\n"
    for needle in ("K_V", "c_H", "vertical", "roll_low", "accepted", "verdict"):
        assert needle in text, needle


def _browser():
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    return None


@pytest.mark.skipif(_browser() is None, reason="no headless Chromium installed")
def test_report_renders_in_headless_chromium(report, tmp_path):
    shot = tmp_path / "shot.png"
    proc = subprocess.run(
        [_browser(), "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         f"--user-data-dir={tmp_path / 'profile'}", "--window-size=1200,2400", f"--screenshot={shot}",
         report.as_uri()],
        check=False, capture_output=True, text=True, timeout=120)
    assert shot.exists(), proc.stderr
    dom = subprocess.run(
        [_browser(), "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
         f"--user-data-dir={tmp_path / 'profile2'}", "--dump-dom", report.as_uri()],
        check=False, capture_output=True, text=True, timeout=120).stdout
    assert "Joint parameters" in dom and "<img" in dom
    assert shot.stat().st_size > 20_000  # a rendered page with a plot, not a blank one
