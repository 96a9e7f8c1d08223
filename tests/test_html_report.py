"""HTML report: one pipeline with identify/explain, complete provenance, escaped text, real browser rendering."""

import base64
import hashlib
import json
import math
import re
import shutil
import subprocess
from pathlib import Path

import pytest
from click.testing import CliRunner

from guidefit import __version__
from guidefit.cli import main
from guidefit.report import fmt
from guidefit.report.html import loads_embedded

SAMPLE = Path(__file__).resolve().parents[1] / "sample_data" / "mrb35_sample.h5"
CHROMIUM = Path("/usr/bin/chromium")


def _cli(*args):
    result = CliRunner().invoke(main, [str(a) for a in args])
    assert result.exit_code == 0, result.output
    return result.output


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    out = tmp_path_factory.mktemp("report") / "report.html"
    _cli("report", SAMPLE, "-o", out)
    return out.read_text(encoding="utf-8")


def _close(a, b, path="", rel=1e-9):
    """Same JSON structure, equal strings, floats within ``rel`` (same code, same machine: ~exact)."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and set(a) == set(b), f"{path}: keys {set(a) ^ set(b)}"
        for k in a:
            _close(a[k], b[k], f"{path}.{k}", rel)
    elif isinstance(a, list):
        assert isinstance(b, list) and len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b)):
            _close(x, y, f"{path}[{i}]", rel)
    elif isinstance(a, float) and isinstance(b, int | float) and not isinstance(b, bool):
        assert math.isclose(a, b, rel_tol=rel, abs_tol=1e-300), f"{path}: {a} != {b}"
    else:
        assert a == b, f"{path}: {a!r} != {b!r}"


def test_report_numbers_are_those_of_explain_and_identify_json(report):
    """The defect: report printed RMS 5.6e-4 % where explain says 6.3e-3 %, and ranked differently."""
    embedded = loads_embedded(report)
    explain_json = json.loads(_cli("explain", SAMPLE, "--json"))
    explain_json.pop("settings")["model_evaluations"]
    embedded["explain"].pop("settings")
    _close(embedded["explain"], explain_json)
    identify_json = json.loads(_cli("identify", SAMPLE, "--json"))
    identify_json.pop("force_levels", None)
    _close(embedded["identify"], identify_json)
    # what the reader sees is that number, and the candidates in explain's order
    rms = explain_json["error_before"]["rms_frequency_error_pct"]
    assert f"<b id='rms-before'>{fmt(rms)}</b>" in report
    table = report[report.index("<table class=\"candidates\">"):]
    shown = re.findall(r"<tr><td>([^<]*)</td>", table[:table.index("</table>")])
    assert shown == [c.get("variant") or c["name"] for c in explain_json["candidates"]]


def test_report_forwards_the_identify_options(tmp_path):
    out = tmp_path / "r.html"
    _cli("report", SAMPLE, "-o", out, "--estimator", "H2", "--no-jackknife")
    embedded = loads_embedded(out.read_text())
    identify_json = json.loads(_cli("identify", SAMPLE, "--json", "--estimator", "H2", "--no-jackknife"))
    identify_json.pop("force_levels", None)
    _close(embedded["identify"]["parameters"], identify_json["parameters"])
    assert "identify estimator</td><td>&#x27;H2&#x27;" in out.read_text()


def test_report_metadata_and_sections(report):
    for needle in (f"<td>SHA-256</td><td>{hashlib.sha256(SAMPLE.read_bytes()).hexdigest()}</td>",
                   f"<td>guidefit</td><td>{__version__}</td>", "identify estimator", "explain candidates",
                   "<h2>Runs and sensors</h2>", "<td>acc_A_y</td>", "<h2>Joint parameters",
                   "<h2>FRFs and fitted modes</h2>", "<h2>Mode shapes at the measuring points</h2>",
                   "<h3>Modes before and after</h3>", "<h2>Hits</h2>", "<h2>Joint for the machine model", "verdict", "K_V", "c_H", "roll_low"):
        assert needle in report, needle
    assert re.search(r"<td>date</td><td>\d{4}-\d\d-\d\d \d\d:\d\d:\d\d UTC</td>", report)
    # self-contained: every src is an embedded PNG, no external resource
    assert not re.search(r"""(src|href)=['"](?!data:)""", report)
    images = re.findall(r"data:image/png;base64,([A-Za-z0-9+/=]+)", report)
    assert len(images) >= 3 and all(base64.b64decode(i)[:8] == b"\x89PNG\r\n\x1a\n" for i in images)


def test_hostile_names_and_descriptions_are_escaped(tmp_path):
    import h5py

    evil = tmp_path / "<script>alert(1)<\\script>.h5"
    shutil.copyfile(SAMPLE, evil)
    with h5py.File(evil, "a") as f:
        f.attrs["description"] = "<img src=x onerror=alert(2)></script><script>alert(3)</script>"
    out = tmp_path / "r.html"
    _cli("report", evil, "-o", out, "--no-jackknife")
    text = out.read_text()
    assert "<img src=x" not in text and "<script>alert" not in text
    assert "&lt;img src=x onerror=alert(2)&gt;" in text
    assert text.count("</script>") == 1  # only the embedded JSON's own end
    assert loads_embedded(text)["identify"]["file"] == str(evil)


def test_report_refuses_to_overwrite_its_input(tmp_path):
    rec = tmp_path / "rec.h5"
    shutil.copyfile(SAMPLE, rec)
    result = CliRunner().invoke(main, ["report", str(rec), "-o", str(rec)])
    assert result.exit_code == 2 and "is an input of this command" in result.output
    assert rec.read_bytes() == SAMPLE.read_bytes()


def _chromium(tmp_path, *args):
    return subprocess.run(
        [str(CHROMIUM), "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
         "--disable-component-update", "--disable-sync", "--no-first-run",
         f"--user-data-dir={tmp_path / 'profile'}", *args],
        check=False, capture_output=True, text=True, timeout=180)


@pytest.mark.skipif(not CHROMIUM.exists(), reason="no /usr/bin/chromium (apt-get install chromium)")
def test_report_renders_in_headless_chromium(report, tmp_path):
    import matplotlib.image as mpimg
    import numpy as np

    page = tmp_path / "report.html"
    page.write_text(report, encoding="utf-8")
    shot = tmp_path / "shot.png"
    proc = _chromium(tmp_path, "--window-size=1200,3000", f"--screenshot={shot}", page.as_uri())
    assert shot.exists(), proc.stderr
    pixels = mpimg.imread(shot)[..., :3]
    ink = np.mean(np.any(pixels < 0.9, axis=-1))  # share of pixels that are not (near) white
    assert pixels.std() > 0.05 and ink > 0.05, (pixels.std(), ink)
    dom = _chromium(tmp_path, "--dump-dom", page.as_uri()).stdout
    for heading in ("Provenance", "Runs and sensors", "Joint parameters", "FRFs and fitted modes",
                    "Mode shapes at the measuring points", "Explanation of the model-measurement residual", "Hits"):
        assert heading in dom, heading
    assert dom.count("<img") >= 3


def test_explain_plot_draws_the_identification_it_explained(tmp_path, monkeypatch):
    """explain --plot used to re-run the FRFs (fixed 300-8000 Hz band, 2 % model damping); now it reuses them."""
    import guidefit.identify

    def no_recomputation(*args, **kwargs):
        raise AssertionError("FRFs recomputed for the plot")

    monkeypatch.setattr(guidefit.identify, "frf_of_recording", no_recomputation)
    png = tmp_path / "explain.png"
    result = CliRunner().invoke(main, ["explain", str(SAMPLE), "--no-jackknife", "--plot", str(png)])
    assert result.exit_code == 0, result.output
    assert "overlay left out" not in result.output and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_failed_explanation_is_said_and_exits_1(tmp_path, monkeypatch):
    """explain raising (a model error) left 'explain gave no result' inside the HTML and exit 0."""
    import guidefit.explain
    from guidefit.errors import ModelError

    def failing(*args, **kwargs):
        raise ModelError("the model has no solution here")

    monkeypatch.setattr(guidefit.explain, "explain", failing)
    out = tmp_path / "r.html"
    result = CliRunner().invoke(main, ["report", str(SAMPLE), "-o", str(out), "--no-jackknife"])
    assert result.exit_code == 1
    assert "explain gave no result" in result.stderr and "no solution here" in result.stderr
    assert "no solution here" in out.read_text(encoding="utf-8")  # the report is still written
