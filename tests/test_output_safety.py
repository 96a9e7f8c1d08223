"""Issue 21: no lost file, no malformed output, no internal error on numbers out of range.

Items 7 and 8: every output is compared with every file the command's inputs read (a
setup's DAQ files, an HDF5 file's external links, raw storage and virtual sources), not
only with the paths on the command line. Item 10b: the JUnit XML stays well-formed
whatever a file name holds. Item 11c: a JSON number beyond the float range (or NaN,
Infinity) is one line naming the key, exit 2.
"""

from __future__ import annotations

import json
import os
import xml.etree.ElementTree as ET
from pathlib import Path

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


# ------------------------------------------------------------- items 7 and 8: never onto a file an input reads


def _digests(folder):
    import hashlib

    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.iterdir()) if p.is_file()}


@pytest.fixture(scope="module")
def setup_folder(tmp_path_factory):
    """A simulated vertical run as a DAQ text export in volts (vertical.csv) and its setup (test.toml)."""
    from dataclasses import replace

    import numpy as np

    from guidefit.simulate import DEFAULT_RUNS, SimulationConfig, simulate

    config = replace(SimulationConfig(), runs=(DEFAULT_RUNS[0],), hits=3, record_s=0.03, layout="signals",
                     gap_s=0.005, sensors="AB", axes="y")
    data, _ = simulate("MRB35", config=config, seed=5)
    folder = tmp_path_factory.mktemp("setup_out")
    run = data.runs[0]
    sens = {"force": 2.25, "acc_A_y": 10.2, "acc_B_y": 10.0}
    cols = [np.asarray(run.data[:, run.channel_names.index(n)], float) * mv / 1000 for n, mv in sens.items()]
    t = np.arange(run.data.shape[0]) / run.sample_rate_hz
    rows = "\n".join(",".join(f"{v:.10g}" for v in row) for row in np.column_stack([t, *cols]))
    (folder / "vertical.csv").write_text("time [s],Kraft [V],A_Y [V],B_Y [V]\n" + rows + "\n")
    lines = ['format = "guidefit-setup"', "format_version = 1", 'guide = "MRB35"']
    for (name, mv), source in zip(sens.items(), ("Kraft", "A_Y", "B_Y")):
        unit = "N" if name == "force" else "m/s^2"
        lines += [f"[channels.{name}]", f'source = "{source}"', f'unit = "{unit}"', f"sensitivity_mv = {mv}"]
    lines += ["[runs.vertical]", 'file = "vertical.csv"',
              f"excitation_direction = {json.dumps(run.excitation_direction.tolist())}",
              f"excitation_position_m = {json.dumps(run.excitation_position_m.tolist())}"]
    (folder / "test.toml").write_text("\n".join(lines) + "\n")
    return folder


@pytest.fixture
def setup_case(setup_folder, tmp_path, monkeypatch):
    for name in ("test.toml", "vertical.csv"):
        (tmp_path / name).write_bytes((setup_folder / name).read_bytes())
    monkeypatch.chdir(tmp_path)
    return tmp_path


_ONTO_DAQ = [
    ("identify", "test.toml", "--summary", "{out}"),
    ("identify", "test.toml", "--csv", "{out}"),
    ("identify", "test.toml", "--junit", "{out}"),
    ("frf", "test.toml", "--out", "{out}"),
    ("report", "test.toml", "-o", "{out}"),
    ("convert", "test.toml", "-o", "{out}"),
]


@pytest.mark.parametrize("args", _ONTO_DAQ, ids=lambda a: " ".join(a[:1] + a[2:3]))
@pytest.mark.parametrize("out", ["vertical.csv", "sub/../vertical.csv", "alias.csv", "hard.csv"])
def test_no_output_onto_a_daq_file_the_setup_reads(setup_case, args, out):
    """Before: identify --summary, --csv, --junit, frf --out and report -o wrote over vertical.csv."""
    (setup_case / "sub").mkdir()
    (setup_case / "alias.csv").symlink_to(setup_case / "vertical.csv")
    os.link(setup_case / "vertical.csv", setup_case / "hard.csv")
    before = _digests(setup_case)
    code, _, err = _cli(*(a.format(out=out) for a in args))
    assert code == 2, err
    assert len(err.strip().splitlines()) == 1, err
    assert f"{out}: is an input of this command (vertical.csv, read through test.toml)" in err, err
    assert _digests(setup_case) == before and sorted(p.name for p in setup_case.iterdir()) == [
        "alias.csv", "hard.csv", "sub", "test.toml", "vertical.csv"]


def _copy_runs(rec, path, dataset):
    """A contract file like ``rec`` whose run datasets are made by ``dataset(group, name, array, attrs)``."""
    import h5py

    with h5py.File(rec, "r") as src, h5py.File(path, "w") as out:
        out.attrs.update(dict(src.attrs))
        for name, group in src["runs"].items():
            g = out.create_group(f"runs/{name}")
            g.attrs.update(dict(group.attrs))
            for key, ds in group.items():
                dataset(g, f"{name}_{key}", key, ds[()], dict(ds.attrs))
    return path


def _linked(rec, folder, how):
    """(recording, the file it reads its samples from) for an external link, raw storage or a virtual dataset."""
    import h5py

    if how == "external link":
        data = folder / "data.h5"
        data.write_bytes(rec.read_bytes())
        master = folder / "master.h5"
        with h5py.File(master, "w") as f:
            f.attrs.update({"format": "guidefit-recording", "format_version": 1, "guide": "MRB35"})
            for name in ("vertical", "lateral"):
                f[f"runs/{name}"] = h5py.ExternalLink("data.h5", f"/runs/{name}")
        return master, data
    if how == "raw storage":
        def raw(g, stem, key, array, attrs):
            (folder / f"{stem}.bin").write_bytes(array.tobytes())
            ds = g.create_dataset(key, shape=array.shape, dtype=array.dtype,
                                  external=[(os.fsencode(f"{stem}.bin"), 0, h5py.h5f.UNLIMITED)])
            ds.attrs.update(attrs)

        return _copy_runs(rec, folder / "ext.h5", raw), folder / "vertical_hits.bin"
    source = folder / "source.h5"
    source.write_bytes(rec.read_bytes())

    def virtual(g, stem, key, array, attrs):
        layout = h5py.VirtualLayout(shape=array.shape, dtype=array.dtype)
        layout[...] = h5py.VirtualSource("source.h5", f"{g.name}/{key}", shape=array.shape)
        g.create_virtual_dataset(key, layout).attrs.update(attrs)

    return _copy_runs(rec, folder / "vds.h5", virtual), source


@pytest.mark.parametrize("how", ["external link", "raw storage", "virtual dataset"])
@pytest.mark.parametrize("args", [("frf", "--out"), ("identify", "--csv"), ("report", "-o")],
                         ids=lambda a: " ".join(a))
def test_no_output_onto_a_file_an_hdf5_recording_links_to(rec, tmp_path, how, args):
    """Before: frf master.h5 --out data.h5 (and identify --csv, report -o) wrote over the linked file."""
    recording, target = _linked(rec, tmp_path, how)
    from guidefit.io import read_recording

    assert len(read_recording(recording).runs) == 2  # the reader follows the reference
    before = _digests(tmp_path)
    code, _, err = _cli(args[0], recording, args[1], target)
    assert code == 2, err
    assert len(err.strip().splitlines()) == 1, err
    assert f"is an input of this command ({target}, read through {recording})" in err, err
    assert _digests(tmp_path) == before


def test_files_read_follows_links_of_linked_files_once(rec, tmp_path):
    """A link chain master -> mid -> data, a cycle back to the master, and a setup: each file once."""
    import h5py

    from guidefit.outputs import files_read

    data = tmp_path / "data.h5"
    data.write_bytes(rec.read_bytes())
    with h5py.File(tmp_path / "mid.h5", "w") as f:
        f["runs"] = h5py.ExternalLink("data.h5", "/runs")
        f["back"] = h5py.ExternalLink("master.h5", "/")
    with h5py.File(tmp_path / "master.h5", "w") as f:
        f["runs"] = h5py.ExternalLink("mid.h5", "/runs")
    os.mkfifo(tmp_path / "fifo.toml")  # never opened: a FIFO would block
    read = files_read([tmp_path / "master.h5", tmp_path / "fifo.toml", None])
    names = [(p.name, r and r.name) for p, r in read]
    assert names == [("master.h5", None), ("fifo.toml", None), ("mid.h5", "master.h5"), ("data.h5", "mid.h5")]


def test_a_virtual_source_mapped_whole_is_read_and_checked(rec, tmp_path):
    """``layout[...] = VirtualSource(...)`` (h5py's plain idiom) was 'damaged HDF5 file (Invalid pointer)';
    a source smaller than what it fills is still refused (HDF5 would fill the rest)."""
    import h5py
    import numpy as np

    from guidefit.errors import RecordingError
    from guidefit.io import read_recording

    recording, source = _linked(rec, tmp_path, "virtual dataset")
    runs = {run.name: run for run in read_recording(recording).runs}
    own = {run.name: run for run in read_recording(source).runs}
    np.testing.assert_array_equal(runs["vertical"].to_data().data, own["vertical"].to_data().data)
    with h5py.File(source, "a") as f:
        hits = f["runs/lateral/hits"]
        smaller = hits[:2]
        attrs = dict(hits.attrs)
        del f["runs/lateral/hits"]
        f["runs/lateral"].create_dataset("hits", data=smaller).attrs.update(attrs)
    with pytest.raises(RecordingError, match=r"source\.h5:/runs/lateral/hits' has shape \(2, "):
        read_recording(recording)


def test_a_master_file_reached_through_a_symbolic_link_names_both_folders(rec, tmp_path, monkeypatch):
    """HDF5 looks for a relative link target beside the file as named (and guidefit's reader beside
    the file as resolved): an output onto either is refused, named as the user would name it."""
    import h5py

    real, other = tmp_path / "real", tmp_path / "other"
    real.mkdir()
    other.mkdir()
    (real / "data.h5").write_bytes(rec.read_bytes())
    (other / "data.h5").write_bytes(rec.read_bytes())
    with h5py.File(real / "master.h5", "w") as f:
        f.attrs.update({"format": "guidefit-recording", "format_version": 1})
        f["runs/vertical"] = h5py.ExternalLink("data.h5", "/runs/vertical")
    (other / "master.h5").symlink_to(real / "master.h5")
    monkeypatch.chdir(tmp_path)
    for out in ("other/data.h5", "real/data.h5"):
        code, _, err = _cli("frf", "other/master.h5", "--out", out)
        assert code == 2 and f"{out}: is an input of this command (" in err, err
    code, _, err = _cli("frf", "real/master.h5", "--out", "real/data.h5")
    assert "(real/data.h5, read through real/master.h5)" in err, err


def test_files_read_finds_a_tdms_index_and_links_after_a_user_block(tmp_path):
    """A setup's TDMS file brings its .tdms_index; an HDF5 file with a 512-byte user block (MAT v7.3)
    is still HDF5 (signature at 512) and its external links are followed."""
    import h5py

    from guidefit.outputs import files_read

    (tmp_path / "test.toml").write_text('[runs.a]\nfile = "a.tdms"\n[runs.b]\nfile = "b.mat"\n[runs.c]\nfile = 3\n')
    (tmp_path / "a.tdms").write_bytes(b"TDSm")
    (tmp_path / "a.tdms_index").write_bytes(b"TDSh")
    with h5py.File(tmp_path / "b.mat", "w", userblock_size=512) as f:
        f["x"] = h5py.ExternalLink("samples.h5", "/x")
    with open(tmp_path / "b.mat", "r+b") as fh:
        fh.write(b"MATLAB 7.3 MAT-file")
    read = [str(p.relative_to(tmp_path)) for p, _ in files_read([tmp_path / "test.toml"])]
    assert read == ["test.toml", "a.tdms", "b.mat", "a.tdms_index", "samples.h5"]


GUIDE_TOML = (Path(__file__).parents[1] / "guidefit" / "model" / "data" / "MRB35.toml").read_text()


@pytest.mark.parametrize("where", ["hdf5 attribute", "setup", "results json"])
def test_no_output_onto_a_guide_toml_an_input_names(rec, setup_case, where):
    """A guide name that is a file is read as the guide (as --guide would be): it is an input too."""
    import h5py

    (setup_case / "my_guide.toml").write_text(GUIDE_TOML)
    if where == "hdf5 attribute":
        (setup_case / "rec.h5").write_bytes(rec.read_bytes())
        with h5py.File(setup_case / "rec.h5", "a") as f:
            f.attrs["guide"] = "my_guide.toml"
        args = ("identify", "rec.h5", "--no-jackknife", "--csv", "my_guide.toml")
    elif where == "setup":
        text = (setup_case / "test.toml").read_text().replace('guide = "MRB35"', 'guide = "my_guide.toml"')
        (setup_case / "test.toml").write_text(text)
        args = ("identify", "test.toml", "--no-jackknife", "--junit", "my_guide.toml")
    else:
        (setup_case / "r.jsonl").write_text(json.dumps({**RESULT, "guide": "my_guide.toml"}) + "\n")
        args = ("export", "r.jsonl", "-o", "my_guide.toml")
    code, _, err = _cli(*args)
    assert code == 2, err
    assert "my_guide.toml: is an input of this command (my_guide.toml, read through " in err, err
    assert (setup_case / "my_guide.toml").read_text() == GUIDE_TOML
