"""Outputs: written whole, never over an input, symbolic links replaced; limits and warnings.

Issue 14 ("never lose data"): ``report rec.h5 -o rec.h5``, ``frf rec.h5 --out rec.h5`` and
``identify rec.h5 --csv rec.h5`` overwrote the input with exit 0; a kill or a full disk left a
truncated file that looked complete; ``simulate`` under a file-size limit segfaulted; a guide
with 10^4 rollers per row was killed for memory; nested TOML/JSON was "internal error:
RecursionError"; Python's warning text reached stderr.
"""

from __future__ import annotations

import hashlib
import json
import os
import resource
import subprocess
import sys
import time
import warnings
from pathlib import Path

import pytest
from click.testing import CliRunner

from guidefit.cli import main
from guidefit.outputs import OutputError, refuse_inputs, replacing, write_text
from guidefit.simulate import SimulationConfig, write_simulation

GUIDE_TOML = (Path(__file__).parents[1] / "guidefit" / "model" / "data" / "MRB35.toml").read_text()


def _cli(*args):
    result = CliRunner().invoke(main, [str(a) for a in args])
    return result.exit_code, result.stdout, result.stderr


def _digest(path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def _leftovers(folder: Path, keep) -> list[str]:
    """Files in ``folder`` other than ``keep`` (temporary files a writer left behind)."""
    return sorted(p.name for p in folder.iterdir() if p.name not in set(keep))


@pytest.fixture(scope="module")
def rec(tmp_path_factory):
    folder = tmp_path_factory.mktemp("outputs")
    out = write_simulation(folder / "rec.h5", "MRB35", config=SimulationConfig(hits=3, record_s=0.05), seed=3)
    return out.recordings[0]


@pytest.fixture
def case(rec, tmp_path):
    """A copy of the recording (and a guide TOML) in a fresh folder."""
    target = tmp_path / "rec.h5"
    target.write_bytes(rec.read_bytes())
    (tmp_path / "guide.toml").write_text(GUIDE_TOML)
    return target


# ------------------------------------------------------------- never onto an input

_ONTO_INPUT = [
    ("report", "{rec}", "-o", "{rec}"),
    ("frf", "{rec}", "--out", "{rec}"),
    ("identify", "{rec}", "--csv", "{rec}"),
    ("identify", "{rec}", "--summary", "{rec}"),
    ("identify", "{rec}", "--junit", "{rec}"),
    ("identify", "{rec}", "--plot", "{rec}"),
    ("identify", "{rec}", "--csv", "{dir}/guide.toml", "--guide", "{dir}/guide.toml"),
    ("explain", "{rec}", "--plot", "{rec}"),
    ("explain", "--modes", "{dir}/modes.json", "--plot", "{dir}/modes.json"),
    ("export", "{dir}/modes.json", "-o", "{dir}/modes.json"),
    ("predict", "--guide", "{dir}/guide.toml", "--plot", "{dir}/guide.toml"),
]


@pytest.mark.parametrize("args", _ONTO_INPUT, ids=lambda a: " ".join(a).replace("{", "").replace("}", ""))
def test_a_command_refuses_to_write_onto_its_input(case, args):
    folder = case.parent
    (folder / "modes.json").write_text(json.dumps({"modes": [{"label": "vertical", "frequency_hz": 3500.0}]}))
    before = {p.name: _digest(p) for p in folder.iterdir()}
    code, _, err = _cli(*(a.format(rec=case, dir=folder) for a in args))
    assert code == 2, err
    assert len(err.strip().splitlines()) == 1 and "is an input of this command" in err, err
    assert {p.name: _digest(p) for p in folder.iterdir()} == before  # nothing written, nothing left


def test_hard_and_symbolic_links_to_an_input_count_as_the_input(case):
    folder = case.parent
    os.link(case, folder / "hard.h5")
    (folder / "soft.csv").symlink_to(case)
    before = _digest(case)
    for target in ("hard.h5", "soft.csv"):
        code, _, err = _cli("frf", case, "--out", folder / target)
        assert code == 2 and "is an input" in err, err
    code, _, err = _cli("report", folder / "hard.h5", "-o", case)
    assert code == 2 and "is an input" in err, err
    assert _digest(case) == before


def test_simulate_refuses_when_a_sidecar_would_overwrite_its_guide(tmp_path):
    (tmp_path / "sim.truth.json").write_text(GUIDE_TOML)  # a guide TOML under the truth file's name
    (tmp_path / "run_lateral.csv").write_text(GUIDE_TOML)  # ... under a CSV-per-run name
    for guide, out in (("sim.truth.json", "sim.h5"), ("run_lateral.csv", "run.csv")):
        code, _, err = _cli("simulate", "--guide", tmp_path / guide, "--out", tmp_path / out, "--hits", 1)
        assert code == 2 and "is an input" in err, err
        assert (tmp_path / guide).read_text() == GUIDE_TOML
    assert _leftovers(tmp_path, ["sim.truth.json", "run_lateral.csv"]) == []


def test_two_outputs_onto_one_file_are_refused(case, tmp_path):
    other = tmp_path / "other" / "rec.h5"  # the same stem in another folder: the same --plot name
    other.parent.mkdir()
    other.write_bytes(case.read_bytes())
    code, _, err = _cli("identify", case, other, "--plot", tmp_path / "p.png")
    assert code == 2 and "given for two outputs" in err, err
    code, _, err = _cli("identify", case, "--csv", tmp_path / "a.xml", "--junit", tmp_path / "a.xml")
    assert code == 2 and "given for two outputs" in err, err
    assert not list(tmp_path.glob("*.png")) and not (tmp_path / "a.xml").exists()


def test_refuse_inputs_library_call(tmp_path):
    a = tmp_path / "a.h5"
    a.write_bytes(b"x")
    refuse_inputs([tmp_path / "b.h5", None], [a, None])
    with pytest.raises(OutputError, match="is an input"):
        refuse_inputs([tmp_path / "." / "a.h5"], [a])


# ------------------------------------------------------------- written whole


def test_a_symlinked_output_is_replaced_not_followed(case):
    folder = case.parent
    victim = folder / "victim.txt"
    victim.write_text("keep me\n")
    (folder / "frf.csv").symlink_to(victim)
    code, _, err = _cli("frf", case, "--out", folder / "frf.csv")
    assert code == 0, err
    assert victim.read_text() == "keep me\n"
    assert not (folder / "frf.csv").is_symlink()
    assert (folder / "frf.csv").read_text().startswith("run,frequency_hz,")


def test_replacing_leaves_the_destination_untouched_when_the_writer_fails(tmp_path):
    out = tmp_path / "table.csv"
    out.write_text("old, complete\n")
    with pytest.raises(OutputError, match="table.csv: cannot write .No space"), replacing(out) as tmp:
        tmp.write_text("half a ta")
        raise OSError(28, "No space left on device")
    assert out.read_text() == "old, complete\n"
    assert _leftovers(tmp_path, ["table.csv"]) == []
    with pytest.raises(KeyboardInterrupt), replacing(tmp_path / "new.csv") as tmp:
        tmp.write_text("partial")
        raise KeyboardInterrupt
    assert _leftovers(tmp_path, ["table.csv"]) == []


def test_replacing_gives_the_permissions_open_would(tmp_path):
    umask = os.umask(0o022)
    try:
        write_text(tmp_path / "a.txt", "x")
    finally:
        os.umask(umask)
    assert (tmp_path / "a.txt").stat().st_mode & 0o777 == 0o644
    os.chmod(tmp_path / "a.txt", 0o640)  # a file the user restricted keeps its permissions
    write_text(tmp_path / "a.txt", "y")
    assert (tmp_path / "a.txt").stat().st_mode & 0o777 == 0o640


def _half_then_fail(real, path_at=0):
    """``real`` writes its file, which is then cut in half (complete-looking), then the disk is full."""
    def writer(*args, **kwargs):
        real(*args, **kwargs)
        path = args[path_at]
        with open(path, "r+b") as handle:
            handle.truncate(max(1, os.path.getsize(path) // 2))
        raise OSError(28, "No space left on device")
    return writer


@pytest.mark.parametrize("command", ["frf", "identify-csv", "identify-junit", "export"])
def test_a_writer_failing_midway_leaves_no_truncated_output(case, monkeypatch, command):
    import guidefit.outputs
    import guidefit.report
    import guidefit.report.check

    folder = case.parent
    out = folder / {"frf": "frf.csv", "identify-csv": "rows.csv", "identify-junit": "j.xml",
                    "export": "deck.json"}[command]
    out.write_text("previous complete output\n")
    if command == "frf":
        import guidefit.io.frf_files  # the format writer under the registry's whole-file writer

        monkeypatch.setattr(guidefit.io.frf_files, "write_frf_csv",
                            _half_then_fail(guidefit.io.frf_files.write_frf_csv))
        args = ("frf", case, "--out", out)
    elif command == "identify-csv":
        monkeypatch.setattr(guidefit.report, "write_summary_csv",
                            _half_then_fail(guidefit.report.write_summary_csv, path_at=1))
        args = ("identify", case, "--no-jackknife", "--csv", out)
    elif command == "identify-junit":
        monkeypatch.setattr(guidefit.report.check, "junit_xml", _half_then_fail(guidefit.report.check.junit_xml, path_at=1))
        args = ("identify", case, "--no-jackknife", "--junit", out)
    else:
        code, stdout, _ = _cli("identify", case, "--no-jackknife", "--json")
        (folder / "id.json").write_text(stdout)

        def failing(path, data):
            with replacing(path) as tmp:
                tmp.write_bytes(data[: len(data) // 2])
                raise OSError(28, "No space left on device")
        monkeypatch.setattr(guidefit.outputs, "write_bytes", failing)
        args = ("export", folder / "id.json", "--joint", "apparent", "-o", out)
    code, _, err = _cli(*args)
    assert code == 2, err
    assert len(err.strip().splitlines()) == 1 and "No space left" in err, err
    assert out.read_text() == "previous complete output\n"
    assert not [n for n in _leftovers(folder, []) if ".tmp" in n]


def _fsize_limit(limit_bytes):
    def apply():
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit_bytes, limit_bytes))
    return apply


@pytest.mark.parametrize("args", [
    ["simulate", "--out", "sim.h5", "--hits", "8"],
    ["simulate", "--out", "sim.csv", "--hits", "8"],
    ["simulate", "--out", "sim.h5", "--hits", "8", "--layout", "signals"],  # HDF5 streamed block by block
    ["frf", "{rec}", "--out", "frf.h5"],
    ["frf", "{rec}", "--out", "frf.csv"],
    ["predict", "--plot", "p.png"],
], ids=lambda a: "-".join(x for x in a if not x.startswith("{")))
def test_a_file_size_limit_is_one_line_exit_2(rec, tmp_path, args):
    """Was: simulate segfaulted (exit 139) with four h5py tracebacks; frf .h5 was an internal error.
    SIGXFSZ stays at Python's default (ignored), so the write fails with EFBIG."""
    proc = subprocess.run([sys.executable, "-m", "guidefit", *(a.format(rec=rec) for a in args)], cwd=tmp_path,
                          check=False, capture_output=True, text=True, timeout=60, preexec_fn=_fsize_limit(20_000))
    assert proc.returncode == 2, proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    assert "Traceback" not in proc.stderr and "cannot write (File too large)" in proc.stderr, proc.stderr
    assert _leftovers(tmp_path, []) == []  # no truncated output, no temporary file


# ------------------------------------------------------------- limits


def test_a_guide_with_ten_thousand_rollers_per_row_is_one_line_exit_2(tmp_path):
    guide = tmp_path / "big.toml"
    guide.write_text(GUIDE_TOML.replace("rollers_per_row = 21", "rollers_per_row = 10000"))
    for args in (("predict", "--guide", guide), ("simulate", "--guide", guide, "--out", tmp_path / "s.h5")):
        code, _, err = _cli(*args)
        assert code == 2, err
        assert len(err.strip().splitlines()) == 1 and "rollers_per_row" in err and "at most" in err, err
    assert not (tmp_path / "s.h5").exists()


def test_a_huge_guide_file_is_refused_before_it_is_parsed(tmp_path):
    guide = tmp_path / "huge.toml"
    guide.write_text(GUIDE_TOML + "\n# " + "x" * 2_000_000 + "\n")
    code, _, err = _cli("predict", "--guide", guide)
    assert code == 2 and "larger than" in err, err


@pytest.mark.parametrize("what", ["huge", "fifo", "folder"])
@pytest.mark.parametrize("command", ["explain", "export"])
def test_a_json_input_that_is_huge_or_not_a_file_is_one_line_exit_2(tmp_path, monkeypatch, command, what):
    """A result file is refused before it is read when it is larger than the cap (a sparse
    file: no disk used), a FIFO (reading would block) or a folder."""
    import os

    import guidefit.jsonio as jsonio

    path = tmp_path / "result.json"
    if what == "huge":
        monkeypatch.setattr(jsonio, "MAX_JSON_BYTES", 1_000_000)
        with open(path, "wb") as fh:
            fh.truncate(1_000_001)
    elif what == "fifo":
        os.mkfifo(path)
    else:
        path.mkdir()
    args = ("explain", "--modes", path) if command == "explain" else ("export", path)
    code, _, err = _cli(*args)
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "internal error" not in err, err
    assert {"huge": "larger than", "fifo": "not a regular file", "folder": "directory"}[what] in err, err


@pytest.mark.parametrize("kind", ["guide-toml", "check-toml", "modes-json", "export-json", "modes-jsonl"])
def test_deeply_nested_documents_are_one_line_exit_2(case, kind):
    folder = case.parent
    n = 100_000
    if kind.endswith("toml"):
        path = folder / "deep.toml"
        path.write_text("a = " + "[" * n + "]" * n + "\n")
    else:
        path = folder / "deep.json"
        deep = "[" * n + "]" * n
        path.write_text('{"modes": []}\n' + deep + "\n" if kind == "modes-jsonl" else deep)
    args = {"guide-toml": ("predict", "--guide", path),
            "check-toml": ("identify", case, "--no-jackknife", "--check", path),
            "modes-json": ("explain", "--modes", path),
            "modes-jsonl": ("explain", "--modes", path),
            "export-json": ("export", path)}[kind]
    code, _, err = _cli(*args)
    assert code == 2, err
    assert len(err.strip().splitlines()) == 1 and "internal error" not in err and "nested" in err, err


# ------------------------------------------------------------- warnings


def test_python_warnings_reach_the_user_as_one_guidefit_line(monkeypatch):
    import numpy as np

    import guidefit.report

    real = guidefit.report.print_guides

    def noisy(guides):
        with np.errstate(divide="warn", invalid="warn"):
            np.log(np.array([0.0]))  # numpy RuntimeWarning
        warnings.warn("Covariance of the parameters could not be estimated", stacklevel=1)
        real(guides)
    monkeypatch.setattr(guidefit.report, "print_guides", noisy)
    code, out, err = _cli("guides")
    assert code == 0 and "MRB35" in out
    lines = err.strip().splitlines()
    assert lines and all(line.startswith("guidefit: warning: ") for line in lines), err
    assert "divide by zero" in err and "Covariance" in err
    assert ".py" not in err and "Warning:" not in err.replace("Warning)", "")  # no file, no Python form


def test_a_real_run_prints_no_python_warning_text(case):
    """identify and predict --sweep with plots (numpy, scipy, pandas, h5py, matplotlib inside), as a user
    runs them, with every Python warning shown (-W default): guidefit's own lines only."""
    folder = case.parent
    for args in (["identify", str(case), "--no-jackknife", "--plot", str(folder / "p.png")],
                 ["predict", "--sweep", "FV:0:900:4", "--plot", str(folder / "s.png")]):
        proc = subprocess.run([sys.executable, "-W", "default", "-m", "guidefit", *args], capture_output=True,
                              text=True, timeout=120, cwd=folder, check=False)
        assert proc.returncode in (0, 1), proc.stderr
        for line in proc.stderr.splitlines():
            assert line.startswith("guidefit: "), proc.stderr
        assert ".py:" not in proc.stderr and "Traceback" not in proc.stderr


def test_a_kill_at_any_moment_leaves_the_old_or_the_new_complete_file(rec, tmp_path):
    """Was: frf's CSV truncated in 7 of 16 kills. SIGKILL cannot be caught: what protects the
    destination is that it only ever receives a complete file by rename."""
    command = [sys.executable, "-m", "guidefit", "frf", str(rec), "--out", "frf.csv"]
    started = time.monotonic()
    subprocess.run(command, cwd=tmp_path, check=True, capture_output=True, timeout=60)
    took = time.monotonic() - started
    new = (tmp_path / "frf.csv").read_bytes()
    old = b"run,frequency_hz\nprevious,complete\n"
    outcomes = set()
    for fraction in (0.5, 0.7, 0.8, 0.9, 0.95, 1.0):
        (tmp_path / "frf.csv").write_bytes(old)
        proc = subprocess.Popen(command, cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        time.sleep(fraction * took)
        proc.kill()
        proc.wait(timeout=30)
        got = (tmp_path / "frf.csv").read_bytes()
        assert got in (old, new), f"killed at {fraction:.2f} x {took:.2f} s: {len(got)} bytes, neither file"
        outcomes.add(got == new)
        for left in _leftovers(tmp_path, ["frf.csv"]):  # what a kill may leave: a hidden temporary file
            assert left.startswith(".frf.csv.") and ".tmp" in left, left
            (tmp_path / left).unlink()
    assert outcomes  # each kill landed before or after the rename


def test_library_log_warnings_are_one_guidefit_line(monkeypatch, capsys):
    import logging

    from guidefit.outputs import one_line_logging

    monkeypatch.setattr(logging, "lastResort", logging.lastResort)  # put back after the test
    one_line_logging()
    logging.lastResort.stream = sys.stderr  # capsys's stream
    logger = logging.getLogger("matplotlib.font_manager.test")
    monkeypatch.setattr(logger, "propagate", False)  # as without pytest's handlers: the last resort writes
    logger.warning("Matplotlib is building the font cache;\nwait")
    assert capsys.readouterr().err == "guidefit: warning: Matplotlib is building the font cache; wait " \
                                      "(matplotlib.font_manager.test)\n"


def test_a_json_result_with_a_byte_order_mark_is_read(tmp_path):
    """A results file saved by a Windows editor starts with a UTF-8 BOM; it was 'not JSON', exit 2."""
    from guidefit.jsonio import read_json_documents

    path = tmp_path / "r.json"
    path.write_bytes(b"\xef\xbb\xbf" + b'{"a": 1}\n{"a": 2}\n')
    assert read_json_documents(path) == [{"a": 1}, {"a": 2}]
