"""Input you can trust: HDF5 links, virtual datasets, external storage, integer samples.

Each case comes from a hostile-input probe that got a wrong number with exit 0.
"""

from __future__ import annotations

import os
import subprocess
import sys

import h5py
import numpy as np
import pytest

from guidefit.errors import RecordingError
from guidefit.io import RecordingData, RunData, open_reader, read_block, read_recording, write_recording

FS = 10_000.0
NAMES = ["force", "acc_A_y", "acc_A_x"]
POS = [[0, 0, 0], [0.03, 0, 0.045], [0.03, 0, 0.045]]


def _run(name, direction, offset, layout="signals"):
    data = np.arange(60.0).reshape(20, 3) + offset
    if layout == "hits":
        data = np.stack([data, data + 0.5])
    dirs = [direction, [0, 1, 0], [1, 0, 0]]
    return RunData(name, FS, direction, NAMES, ["N", "m/s^2", "m/s^2"], POS, dirs, data=data)


def _data_file(path, layout="signals"):
    runs = [_run("vertical", [0, -1, 0], 0.0, layout), _run("lateral", [1, 0, 0], 1000.0, layout)]
    write_recording(path, RecordingData(runs, guide="MRB35"))
    return path


def _master(path, links):
    """A recording whose runs are external links: {name in master: (file, path there)}."""
    with h5py.File(path, "w") as f:
        f.attrs["format"] = "guidefit-recording"
        f.attrs["format_version"] = 1
        runs = f.create_group("runs")
        for name, (file, target) in links.items():
            runs[name] = h5py.ExternalLink(file, target)
    return path


# ------------------------------------------------------------------ external links


@pytest.mark.parametrize("layout", ["signals", "hits"])
def test_runs_linked_under_swapped_names_read_the_linked_samples(tmp_path, layout):
    """The run's name is its name in the master file; its metadata and samples are
    those of the linked group (before: the samples of the master's path in the linked
    file, i.e. the other run's: K_V -50 % / K_H +100 % with exit 0)."""
    data = _data_file(tmp_path / "data.h5", layout)
    master = _master(tmp_path / "master.h5", {"vertical": ("data.h5", "/runs/lateral"),
                                              "lateral": ("data.h5", "/runs/vertical")})
    own = {r.name: r for r in read_recording(data).runs}
    for run in read_recording(master).runs:
        linked = own["lateral" if run.name == "vertical" else "vertical"]
        np.testing.assert_array_equal(run.excitation_direction, linked.excitation_direction)
        np.testing.assert_array_equal(run.to_data().data, linked.to_data().data)
        with open_reader(run) as reader:
            if layout == "hits":
                np.testing.assert_array_equal(reader.read_hits(0, 2), linked.to_data(si=True).data)
            else:
                np.testing.assert_array_equal(reader.read_block(3, 9), read_block(linked, 3, 9))


def test_runs_linked_under_new_names_are_found(tmp_path, monkeypatch):
    """Before: 'component not found' (the linked dataset's own path looked up in the master)."""
    _data_file(tmp_path / "data.h5")
    sub = tmp_path / "sub"
    sub.mkdir()
    master = _master(sub / "master.h5", {"run_a": ("../data.h5", "/runs/vertical")})
    monkeypatch.chdir(tmp_path.parent)  # links resolve against the master's folder, not the working directory
    (run,) = read_recording(master).runs
    assert run.name == "run_a"
    np.testing.assert_array_equal(run.read_block(0, 2)[:, 0], [0.0, 3.0])


def test_external_link_to_a_missing_file_or_a_fifo_is_one_error(tmp_path):
    master = _master(tmp_path / "m.h5", {"vertical": ("gone.h5", "/runs/vertical")})
    with pytest.raises(RecordingError, match=r"run 'vertical'.*external link.*does not exist"):
        read_recording(master)
    os.mkfifo(tmp_path / "pipe.h5")
    master = _master(tmp_path / "m2.h5", {"vertical": ("pipe.h5", "/runs/vertical")})
    with pytest.raises(RecordingError, match="not a regular file"):
        read_recording(master)


# ---------------------------------------------------------------- virtual datasets


def _vds_file(tmp_path, covered_rows=20):
    data = _data_file(tmp_path / "data.h5")
    with h5py.File(data, "r") as f:
        attrs = dict(f["runs/vertical/signals"].attrs)
    layout = h5py.VirtualLayout(shape=(20, 3), dtype="f8")
    layout[:covered_rows] = h5py.VirtualSource("data.h5", "/runs/vertical/signals",
                                               shape=(20, 3))[:covered_rows]
    path = tmp_path / "vds.h5"
    with h5py.File(path, "w") as f:
        f.attrs["format"] = "guidefit-recording"
        f.attrs["format_version"] = 1
        g = f.create_group("runs/vertical")
        g.attrs["sample_rate_hz"] = FS
        g.attrs["excitation_direction"] = [0.0, -1.0, 0.0]
        ds = f["runs/vertical"].create_virtual_dataset("signals", layout, fillvalue=0.0)
        for k, v in attrs.items():
            ds.attrs[k] = v
    return path, data


def test_virtual_dataset_is_read_and_a_missing_source_is_an_error(tmp_path):
    path, data = _vds_file(tmp_path)
    np.testing.assert_array_equal(read_recording(path).runs[0].read_block(19, 20)[0], [57, 58, 59])
    os.replace(data, tmp_path / "moved.h5")  # h5py would read the whole run as zeros
    with pytest.raises(RecordingError, match=r"virtual dataset source 'data.h5:/runs/vertical/signals'.*does not exist"):
        read_recording(path)


def test_virtual_dataset_with_unmapped_part_is_an_error(tmp_path):
    path, _ = _vds_file(tmp_path, covered_rows=15)
    with pytest.raises(RecordingError, match="maps 45 of its 60 values"):
        read_recording(path)


# ------------------------------------------------------------ external raw storage


def _external_file(tmp_path, target, offset=0, write_bytes=True):
    data = np.arange(60.0).reshape(20, 3)
    if write_bytes:
        with open(target, "wb") as fh:
            fh.write(b"\0" * offset + data.tobytes())
    path = tmp_path / "ext.h5"
    with h5py.File(path, "w") as f:
        f.attrs["format"] = "guidefit-recording"
        f.attrs["format_version"] = 1
        g = f.create_group("runs/vertical")
        g.attrs["sample_rate_hz"] = FS
        g.attrs["excitation_direction"] = [0.0, -1.0, 0.0]
        ds = g.create_dataset("signals", shape=(20, 3), dtype="<f8",
                              external=[(os.fsencode(os.path.relpath(target, tmp_path)
                                                     if target.parent == tmp_path else target),
                                         offset, h5py.h5f.UNLIMITED)])
        ds.attrs["channel_names"] = NAMES
        ds.attrs["units"] = ["N", "m/s^2", "m/s^2"]
        ds.attrs["positions_m"] = POS
        ds.attrs["directions"] = [[0, -1, 0], [0, 1, 0], [1, 0, 0]]
    return path, data


def test_external_raw_storage_beside_the_file_is_read_from_there(tmp_path, monkeypatch):
    path, data = _external_file(tmp_path, tmp_path / "raw.bin", offset=16)
    other = tmp_path / "elsewhere"
    other.mkdir()
    (other / "raw.bin").write_bytes(np.ones(60).tobytes())  # a decoy in the working directory
    monkeypatch.chdir(other)
    np.testing.assert_array_equal(read_recording(path).runs[0].read_block(), data)


def test_external_raw_storage_outside_the_folder_or_special_is_refused(tmp_path):
    outside = tmp_path.parent / f"{tmp_path.name}_outside.bin"
    try:
        path, _ = _external_file(tmp_path, outside)
        with pytest.raises(RecordingError, match="outside the recording's folder"):
            read_recording(path)
    finally:
        outside.unlink()
    path, _ = _external_file(tmp_path, tmp_path / "raw.bin")
    (tmp_path / "raw.bin").unlink()
    os.symlink("/dev/zero", tmp_path / "raw.bin")  # a device, through a link in the folder
    with pytest.raises(RecordingError, match="outside the recording's folder|not a regular file"):
        read_recording(path)
    (tmp_path / "raw.bin").unlink()
    os.mkfifo(tmp_path / "raw.bin")
    with pytest.raises(RecordingError, match="not a regular file"):
        read_recording(path)


def test_short_external_raw_storage_is_refused(tmp_path):
    """HDF5 reads what an external file lacks as zeros."""
    path, data = _external_file(tmp_path, tmp_path / "raw.bin")
    with open(tmp_path / "raw.bin", "r+b") as fh:
        fh.truncate(data.nbytes // 2)
    with pytest.raises(RecordingError, match=f"holds {data.nbytes // 2} bytes.*needs {data.nbytes}"):
        read_recording(path)


def test_cli_gives_one_line_for_a_hostile_link(tmp_path):
    os.mkfifo(tmp_path / "pipe.h5")
    master = _master(tmp_path / "m.h5", {"vertical": ("pipe.h5", "/runs/vertical")})
    done = subprocess.run([sys.executable, "-m", "guidefit", "identify", str(master)],
                          capture_output=True, text=True, check=False, timeout=120)
    assert done.returncode == 2
    assert len(done.stderr.strip().splitlines()) == 1 and "not a regular file" in done.stderr


def test_soft_link_to_an_external_link_to_a_fifo_is_refused(tmp_path):
    os.mkfifo(tmp_path / "pipe.h5")
    path = tmp_path / "soft.h5"
    with h5py.File(path, "w") as f:
        f.attrs["format"] = "guidefit-recording"
        f.attrs["format_version"] = 1
        f["elsewhere"] = h5py.ExternalLink("pipe.h5", "/runs/vertical")
        f.create_group("runs")["vertical"] = h5py.SoftLink("/elsewhere")
    with pytest.raises(RecordingError, match="not a regular file"):
        read_recording(path)


def test_soft_linked_run_reads_its_target(tmp_path):
    path = _data_file(tmp_path / "data.h5")
    with h5py.File(path, "r+") as f:
        f["runs"]["alias"] = h5py.SoftLink("/runs/lateral")
    runs = {r.name: r for r in read_recording(path).runs}
    np.testing.assert_array_equal(runs["alias"].read_block(), runs["lateral"].read_block())


def test_reading_while_the_caller_holds_the_dataset_open(tmp_path):
    path = _data_file(tmp_path / "data.h5", "hits")
    with h5py.File(path, "r") as f:
        held = f["runs/vertical/hits"]
        run = read_recording(path).run("vertical")
        with open_reader(run) as reader:
            np.testing.assert_array_equal(reader.read_hits(0, 2), held[...])
