"""Issue 21: no lost file, no malformed output, no internal error on numbers out of range.

Items 7 and 8: every output is compared with every file the command's inputs read (a
setup's DAQ files, an HDF5 file's external links, raw storage and virtual sources), not
only with the paths on the command line. Item 10b: the JUnit XML stays well-formed
whatever a file name holds. Item 11c: a JSON number beyond the float range (or NaN,
Infinity) is one line naming the key, exit 2.
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET

import pytest
from click.testing import CliRunner

from guidefit.cli import main

RESULT = {"file": "carriage1.h5", "guide": "MRB35", "parameters": {
    "K_V": {"value": 1.03e9, "unit": "N/m"}, "c_V": {"value": 2750.0, "unit": "N*s/m"},
    "K_H": {"value": 1.00e8, "unit": "N/m"}, "c_H": {"value": 3109.0, "unit": "N*s/m"}},
    "modes": [{"label": "vertical", "frequency_hz": 3450.0, "damping_ratio": 0.0288},
              {"label": "roll_low", "frequency_hz": 1075.0, "damping_ratio": 0.105}]}


def _cli(*args):
    result = CliRunner().invoke(main, [str(a) for a in args])
    return result.exit_code, result.stdout, result.stderr


# ------------------------------------------------------------- item 11c: JSON numbers


@pytest.mark.parametrize("number", ["1e999", "-1e999", "1" + "0" * 400, "1" + "0" * 5000, "NaN", "Infinity"])
@pytest.mark.parametrize("joint", ["apparent", "explained"])
def test_export_of_a_number_beyond_float_is_one_line_naming_the_key(tmp_path, number, joint):
    path = tmp_path / "r.jsonl"
    path.write_text(json.dumps(RESULT).replace("1030000000.0", number) + "\n" + json.dumps(RESULT) + "\n")
    code, out, err = _cli("export", path, "--joint", joint)
    assert code == 2, err
    assert len(err.strip().splitlines()) == 1 and "internal error" not in err, err
    assert "line 1: parameters.K_V.value:" in err and "not a finite number" in err, err
    assert len(err) < 300, err  # a 5000-digit number is not echoed whole
    assert out == ""


def test_a_number_beyond_float_elsewhere_is_refused_too(tmp_path):
    """Not only the parameters export reads first: a mode's damping ratio, in a JSON array file."""
    bad = json.loads(json.dumps(RESULT))
    text = json.dumps([bad]).replace("0.105", "1" + "0" * 400)
    path = tmp_path / "r.json"
    path.write_text(text)
    code, _, err = _cli("export", path)
    assert code == 2 and "[0].modes[1].damping_ratio:" in err, err
    modes = tmp_path / "modes.json"
    modes.write_text('{"modes": [{"label": "vertical", "frequency_hz": 1e999}]}')
    code, _, err = _cli("explain", "--modes", modes)
    assert code == 2 and "modes[0].frequency_hz: 1e999 is not a finite number" in err, err


# ------------------------------------------------------------- item 10b: JUnit XML


@pytest.fixture(scope="module")
def rec(tmp_path_factory):
    from guidefit.simulate import SimulationConfig, write_simulation

    folder = tmp_path_factory.mktemp("safety")
    return write_simulation(folder / "rec.h5", "MRB35", config=SimulationConfig(hits=3, record_s=0.05),
                            seed=3).recordings[0]


def test_junit_xml_is_well_formed_whatever_a_file_name_holds(rec, tmp_path):
    import os

    names = ["rec\x01.h5", "rec\x1b[31m.h5", os.fsdecode(b"rec\xff.h5")]  # the last: not UTF-8 (a surrogate)
    paths = []
    for name in names:
        path = tmp_path / name
        path.write_bytes(rec.read_bytes())
        paths.append(path)
    broken = tmp_path / "broken\x07.h5"
    broken.write_bytes(b"not an HDF5 file\x00")
    junit = tmp_path / "junit.xml"
    code, _, err = _cli("identify", *paths, broken, "--no-jackknife", "--json", "--junit", junit)
    assert code == 2, err  # the broken file
    root = ET.parse(junit).getroot()  # well-formed
    cases = root.findall(".//testcase")
    assert [c.get("name").rsplit("/", 1)[-1] for c in cases] == [
        "rec\\x01.h5", "rec\\x1b[31m.h5", "rec\\udcff.h5", "broken\\x07.h5"]
    assert [c.find("error") is not None for c in cases] == [False, False, False, True]
    assert "broken\\x07.h5" in cases[-1].find("error").get("message")
