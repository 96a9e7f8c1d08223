"""Property tests of every output path against the files a command reads (issue 21: "property tests ...
for every output path"): an output is refused exactly when it names a file the inputs read, however it
is spelled (a symbolic or hard link, ``sub/..``, a link to a folder), and two outputs onto one file are
refused; an output that is a new file or another file is written.

The inputs are a test setup (TOML) whose run reads a DAQ file, beside a recording; the outputs are
drawn from every way of naming these files and others. The oracle is the file system's own idea of
"the same file" (inode, or the resolved name where the file does not exist yet), computed here
independently of :func:`guidefit.outputs.refuse_inputs`.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from guidefit.outputs import OutputError, refuse_inputs

pytestmark = pytest.mark.skipif(not hasattr(os, "symlink"), reason="needs symbolic links")

SETUP = """format = "guidefit-setup"
format_version = 1
[channels.force]
source = "F"
[channels.acc_A_y]
source = "A"
[runs.vertical]
file = "daq/vertical.csv"
excitation_direction = [0.0, -1.0, 0.0]
"""


def _tree(root: Path) -> dict[str, Path]:
    """The files of one command line: a setup and the DAQ file it reads, a recording, an unrelated
    file, and links of every kind to them."""
    (root / "daq").mkdir()
    (root / "sub").mkdir()
    daq = root / "daq" / "vertical.csv"
    daq.write_text("F,A\n0,0\n")
    setup = root / "test.toml"
    setup.write_text(SETUP)
    rec = root / "rec.h5"
    rec.write_bytes(b"not read as HDF5 here")
    other = root / "other.csv"
    other.write_text("x\n")
    (root / "link_daq.csv").symlink_to(daq)
    (root / "link_setup.toml").symlink_to(setup)
    (root / "daqdir").symlink_to(root / "daq", target_is_directory=True)
    os.link(daq, root / "hard_daq.csv")
    os.link(other, root / "hard_other.csv")
    return {"daq": daq, "setup": setup, "rec": rec, "other": other}


def _names(root: Path) -> list[str]:
    """Ways to name an output: the files above, spelled directly, through links and ``..``, and new ones."""
    return ["daq/vertical.csv", "sub/../daq/vertical.csv", "link_daq.csv", "hard_daq.csv", "daqdir/vertical.csv",
            "test.toml", "link_setup.toml", "rec.h5", "./rec.h5", "sub/../rec.h5",
            "other.csv", "hard_other.csv", "new.csv", "sub/new.csv", "daq/new.csv", "daqdir/new2.csv"]


def _same(a: Path, b: Path) -> bool:
    if a.exists() and b.exists():
        return a.stat().st_ino == b.stat().st_ino and a.stat().st_dev == b.stat().st_dev
    return os.path.realpath(a) == os.path.realpath(b)


@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(picks=st.lists(st.integers(0, 15), min_size=1, max_size=3), with_setup=st.booleans())
def test_an_output_is_refused_exactly_when_it_is_a_file_the_inputs_read(tmp_path_factory, picks, with_setup):
    root = tmp_path_factory.mktemp("outs")
    files = _tree(root)
    names = _names(root)
    outputs = [root / names[i] for i in picks]
    inputs = [files["setup"] if with_setup else files["other"], files["rec"]]
    read = [files["rec"]] + ([files["setup"], files["daq"]] if with_setup else [files["other"]])
    clash_in = any(_same(out, src) for out in outputs for src in read)
    clash_out = any(_same(a, b) for k, a in enumerate(outputs) for b in outputs[:k])
    if clash_in or clash_out:
        with pytest.raises(OutputError) as info:
            refuse_inputs(outputs, inputs)
        assert "\n" not in str(info.value)
    else:
        refuse_inputs(outputs, inputs)  # nothing read is named: written


def test_cli_refuses_a_summary_onto_the_setups_daq_file_through_a_folder_link(tmp_path):
    """The command line end of the property: identify a setup, --summary onto its DAQ file named through a
    linked folder: exit 2, one line, the DAQ file untouched."""
    from click.testing import CliRunner

    from guidefit.cli import main

    files = _tree(tmp_path)
    before = files["daq"].read_bytes()
    result = CliRunner().invoke(main, ["identify", str(files["setup"]), "--summary",
                                       str(tmp_path / "daqdir" / "vertical.csv")])
    assert result.exit_code == 2, result.output
    assert "is an input of this command" in result.output.strip().splitlines()[-1]
    assert files["daq"].read_bytes() == before
