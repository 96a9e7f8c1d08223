"""UFF geometry from other programs (issue 21, items 4, 5 and 12).

* item 4: a file without coordinates of the reference (hammer) node has an
  unknown hit point, never the origin: the gate expects every mode the sensors
  see and rejects another structure's FRFs (before: the origin, where only
  the vertical mode is excitable, let them through with exit 0);
* item 5: Testlab's per-node displacement coordinate systems (datasets 18,
  2420) are applied: a file whose nodes' frames are turned (and its direction
  codes with them) gives the same K as the same FRFs in the global frame; a
  frame whose axis is not along a global axis, or an undefined system, is
  refused with one line;
* item 12: a file in a machine frame (z up) fails with a hint to
  ``--axis-map``, and with the map gives the same K.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from click.testing import CliRunner

from guidefit.cli import main
from guidefit.identify import frf_of_recording, identify
from guidefit.io import default_points, read_recording, write_frfs, write_recording
from guidefit.io.frf_files import read_frf_file

pyuff = pytest.importorskip("pyuff")

JOINT = ("K_V", "K_H", "c_V", "c_H")
# a proper rotation per node, rows = the node's local axes in the global frame (axes onto axes)
TURNS = {
    1: np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]),  # 90 deg about z
    2: np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]),  # 90 deg about x
    3: np.array([[-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]]),  # 180 deg about y
    4: np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]),  # axes cycled
    101: np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]),  # the hammers' nodes too
    102: np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]]),
}


def cli(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    """A simulated recording (two runs, known hit points) and its FRFs as guidefit's UFF."""
    from guidefit.simulate import SimulationConfig, simulate

    folder = tmp_path_factory.mktemp("uff_frames")
    data, _ = simulate("MRB35", config=replace(SimulationConfig(), hits=4, record_s=0.05), seed=3)
    rec = folder / "rec.h5"
    write_recording(rec, data)
    frfsets, _ = frf_of_recording(rec)
    write_frfs(folder / "frf.uff", frfsets, recording=rec)
    hits = {101 + i: np.asarray(run.excitation_position_m, float) for i, run in enumerate(read_recording(rec).runs)}
    return {"folder": folder, "rec": rec, "frf_uff": folder / "frf.uff", "hits": hits}


def _local_code(frame: np.ndarray, code: int) -> int:
    """The code along the node's local axis that is global direction ``code``."""
    g = np.zeros(3)
    g[abs(code) - 1] = np.sign(code)
    local = frame @ g
    k = int(np.argmax(np.abs(local)))
    assert abs(abs(local[k]) - 1.0) < 1e-12
    return int((k + 1) * np.sign(local[k]))


def with_geometry(src, dst, hits, *, turns=None, systems="2420", undefined=None, codes=None):
    """``src`` (guidefit's UFF) again with node coordinates (A-D and the hammers' nodes) and, per node
    in ``turns``, a displacement coordinate system of its own, its direction codes written in it.

    ``codes``: a function (node, global code) -> code to write instead (a machine frame).
    """
    sets = pyuff.UFF(str(src)).read_sets()
    turns = turns or {}
    points = default_points("MRB35")
    xyz = {k + 1: np.asarray(points[p], float) for k, p in enumerate("ABCD")}
    xyz.update(hits)
    nums = sorted(xyz)
    labels = {n: 10 + n for n in turns}
    disp = [undefined if undefined and n == 1 else labels.get(n, 0) for n in nums]
    geometry = [pyuff.prepare_2411(node_nums=np.array(nums), def_cs=np.zeros(len(nums), int),
                                   disp_cs=np.array(disp), color=np.ones(len(nums), int),
                                   x=np.array([xyz[n][0] for n in nums]), y=np.array([xyz[n][1] for n in nums]),
                                   z=np.array([xyz[n][2] for n in nums]))]
    if turns and systems == "2420":
        geometry.insert(0, pyuff.prepare_2420(
            Part_UID=1, Part_Name="test", CS_sys_labels=[labels[n] for n in turns], CS_types=[0] * len(turns),
            CS_colors=[8] * len(turns), CS_names=[f"node{n}" for n in turns],
            CS_matrices=[np.vstack([turns[n], xyz[n]]) for n in turns]))
    elif turns:  # dataset 18: origin, a point on +x, a point in the +xz plane
        geometry.insert(0, pyuff.prepare_18(
            cs_num=[labels[n] for n in turns], cs_type=[0] * len(turns), ref_cs_num=[0] * len(turns),
            color=[1] * len(turns), method=[1] * len(turns), cs_name=[f"node{n}" for n in turns],
            ref_o=[xyz[n] for n in turns], x_point=[xyz[n] + 0.1 * turns[n][0] for n in turns],
            xz_point=[xyz[n] + 0.1 * turns[n][0] + 0.1 * turns[n][2] for n in turns]))
    out = [sets[0], *geometry]
    for s in sets[1:]:
        s = dict(s)
        for key in ("rsp", "ref"):
            node, code = int(s[f"{key}_node"]), int(s[f"{key}_dir"])
            if codes is not None:
                code = codes(node, code)
            elif node in turns:
                code = _local_code(turns[node], code)
            s[f"{key}_dir"] = code
        out.append(s)
    pyuff.UFF(str(dst)).write_sets(out, mode="add")
    return dst


def _k_close(a, b, rel=0.01):
    for name in ("K_V", "K_H"):
        assert b.parameters[name]["value"] == pytest.approx(a.parameters[name]["value"], rel=rel), name


# ------------------------------------------------------------------ item 5: per-node coordinate systems


@pytest.fixture(scope="module")
def plain(case):
    """The FRFs with node coordinates, every node measuring along the global axes."""
    path = with_geometry(case["frf_uff"], case["folder"] / "plain.uff", case["hits"])
    return path, identify(path)


@pytest.mark.parametrize("systems", ["2420", "18"])
def test_turned_node_frames_give_the_same_joint(case, plain, tmp_path, systems):
    path = with_geometry(case["frf_uff"], tmp_path / "turned.uff", case["hits"], turns=TURNS, systems=systems)
    ref = plain[1]
    got = identify(path)
    assert got.gate is None and ref.gate is None
    _k_close(ref, got, rel=0.01)
    for name in JOINT:  # the same FRFs in the same frame: the same fit
        assert got.parameters[name]["value"] == pytest.approx(ref.parameters[name]["value"], rel=1e-6), name
    assert {m.label for m in got.modes} == {m.label for m in ref.modes}
    frf = read_frf_file(path)
    assert any("displacement coordinate systems" in note for note in frf.notes)
    vertical = next(r for r in frf.recording.runs if r.name == "vertical")
    assert tuple(vertical.excitation_direction) == pytest.approx((0.0, -1.0, 0.0))
    assert vertical.excitation_position_m == pytest.approx(case["hits"][101])


def test_turned_frames_read_as_global_axes_in_time_data(case, tmp_path):
    from guidefit.io.uff import read_uff_recording, write_uff_recording

    run = read_recording(case["rec"]).runs[0]
    short = replace(run.to_data(), data=np.asarray(run.read_hit(0))[:64], layout="signals", pretrigger_samples=None)
    src = tmp_path / "time.uff"
    write_uff_recording(src, short)
    turns = {n: t for n, t in TURNS.items() if n != 102}  # one run: no node 102
    turned = with_geometry(src, tmp_path / "turned_time.uff", {101: case["hits"][101]}, turns=turns)
    back = read_uff_recording(turned).runs[0]
    assert back.channel_names == short.channel_names
    assert np.allclose(np.array([c.direction for c in back.channels]), short.directions)
    assert back.hit_position_m == pytest.approx(case["hits"][101])
    assert np.allclose(back.read_block(), short.data)


def test_frames_guidefit_cannot_read_are_refused_in_one_line(case, tmp_path):
    askew = dict(TURNS)
    c, s = np.cos(np.radians(30)), np.sin(np.radians(30))
    askew[1] = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])  # 30 deg: not onto an axis
    path = with_geometry(case["frf_uff"], tmp_path / "askew.uff", case["hits"], turns={1: askew[1]},
                         codes=lambda node, code: code)
    result = cli("identify", path)
    assert result.exit_code == 2, result.output
    assert "not along X, Y or Z" in result.output and len(result.output.strip().splitlines()) == 1
    undefined = with_geometry(case["frf_uff"], tmp_path / "undefined.uff", case["hits"], undefined=7)
    result = cli("identify", undefined)
    assert result.exit_code == 2, result.output
    assert "coordinate system 7" in result.output and len(result.output.strip().splitlines()) == 1


def test_cylindrical_system_is_refused(case, tmp_path):
    path = with_geometry(case["frf_uff"], tmp_path / "cyl.uff", case["hits"], turns={1: TURNS[1]})
    sets = pyuff.UFF(str(path)).read_sets()
    sets[1]["CS_types"] = [1]
    bad = tmp_path / "cyl2.uff"
    pyuff.UFF(str(bad)).write_sets(sets, mode="add")
    result = cli("frf", bad)
    assert result.exit_code == 2 and "cylindrical" in result.output, result.output


# ------------------------------------------------------------------ item 4: unknown hit point


def foreign_frfs(path, *, hit_node_xyz=None):
    """FRFs of another structure (a carriage under a 3 kg mass off its centre: every mode moved and
    mixed), hit along -y at (0.02, 0, 0.035), read at A-D in x, y, z; reference node 20's coordinates
    only if ``hit_node_xyz``."""
    from guidefit.model import vibration as vib
    from guidefit.model.guides import load_guide

    spec = vib.with_point_masses(vib.model_from_guide(load_guide("MRB35")), [vib.PointMass(3.0, (0.05, -0.02, 0.08))])
    sol = vib.solve_modes(spec)
    f = np.arange(0.0, 10_000.0, 4.0)
    points = default_points("MRB35")
    dofs = [(k + 1, a + 1) for k in range(4) for a in range(3)]
    H = vib.accelerance(sol, spec, f, 0.03, (0.02, 0.0, 0.035), [0, -1, 0],
                        [points["ABCD"[n - 1]] for n, _ in dofs], [np.eye(3)[a - 1] for _, a in dofs])
    sets = [pyuff.prepare_164(units_code=1, units_description="SI", temp_mode=2, length=1.0, force=1.0,
                              temp=1.0, temp_offset=273.15)]
    if hit_node_xyz is not None:
        sets.append(pyuff.prepare_2411(node_nums=np.array([20]), def_cs=np.zeros(1, int), disp_cs=np.zeros(1, int),
                                       color=np.ones(1, int), x=np.array([hit_node_xyz[0]]),
                                       y=np.array([hit_node_xyz[1]]), z=np.array([hit_node_xyz[2]])))
    for j, (node, d) in enumerate(dofs):
        sets.append(pyuff.prepare_58(binary=0, func_type=4, data=H[:, j], x=f, abscissa_spacing=1,
                                     abscissa_spec_data_type=18, abscissa_axis_units_lab="Hz", rsp_node=node,
                                     rsp_dir=d, ref_node=20, ref_dir=-2, rsp_ent_name="x", ref_ent_name="h",
                                     id1="FRF", id2="test", id3="NONE", id4="NONE", id5="NONE",
                                     ordinate_spec_data_type=12, ordinate_axis_units_lab="m/s^2",
                                     orddenom_spec_data_type=13, orddenom_axis_units_lab="N"))
    pyuff.UFF(str(path)).write_sets(sets, mode="add")
    return path


def test_another_structure_without_a_hit_point_is_rejected_not_passed(tmp_path):
    bare = foreign_frfs(tmp_path / "bare.uff")
    got = identify(bare)
    # before: the hammer at the origin, only the vertical mode expected: K_V 9.4e8 N/m, exit 0
    assert got.gate is not None and "hit point unknown" in got.gate, got.gate
    assert got.parameters["K_V"]["value"] is None
    assert any("the hit point is unknown" in w for w in got.warnings)
    assert read_frf_file(bare).recording.runs[0].hit_position_m is None
    result = cli("identify", bare)
    assert result.exit_code == 1 and "identification rejected" in result.output
    # with the hammer's node where it was: rejected as well, and no warning about the hit point
    known = identify(foreign_frfs(tmp_path / "known.uff", hit_node_xyz=(0.02, 0.0, 0.035)))
    assert known.gate is not None
    assert not any("the hit point is unknown" in w for w in known.warnings)


def test_unknown_hit_point_expects_every_mode_the_sensors_see():
    from guidefit.consistency import ShapeSet, observable_modes
    from guidefit.io import Channel
    from guidefit.model import vibration as vib
    from guidefit.model.guides import load_guide
    from guidefit.modes.labels import driving_row, sensor_matrix

    model = vib.solve_modes(vib.model_from_guide(load_guide("MRB35")))
    points = default_points("MRB35")
    chans = [Channel(f"acc_{p}_{a}", "m/s^2", points[p], np.eye(3)["xyz".index(a)], 1.0) for p in "ABCD" for a in "xyz"]
    S = sensor_matrix(chans)
    empty = np.zeros((0, len(chans)))
    pos = np.array([c.position_m for c in chans])
    dirs = np.array([c.direction for c in chans])
    names = tuple(c.name for c in chans)
    at_origin = ShapeSet("v", names, S, pos, dirs, empty, driving_row((0, -1, 0), (0.0, 0.0, 0.0)))
    unknown = ShapeSet("v", names, S, pos, dirs, empty, driving_row((0, -1, 0), None))
    assert observable_modes(model, [at_origin]) == {"vertical"}
    assert observable_modes(model, [unknown]) == set(model.labels)


# ------------------------------------------------------------------ item 12: a machine frame (z up)

MACHINE = "x=X,y=Z,z=-Y"


def _machine_code(node: int, code: int) -> int:
    """guidefit's direction code as the machine frame (z up) writes it."""
    from guidefit.io.axes import parse_axis_map

    if abs(code) not in (1, 2, 3):
        return code
    vec = parse_axis_map(MACHINE)[:, abs(code) - 1] * np.sign(code)
    k = int(np.argmax(np.abs(vec)))
    return int((k + 1) * np.sign(vec[k]))


def machine_uff(src, dst):
    """``src`` with every direction code written in the machine frame, no node coordinates."""
    sets = pyuff.UFF(str(src)).read_sets()
    for s in sets[1:]:
        s["rsp_dir"] = _machine_code(s["rsp_node"], int(s["rsp_dir"]))
        s["ref_dir"] = _machine_code(s["ref_node"], int(s["ref_dir"]))
    pyuff.UFF(str(dst)).write_sets(sets, mode="add")
    return dst


def test_machine_frame_fails_with_a_hint_and_the_axis_map_gives_the_same_joint(case, tmp_path):
    import json

    path = machine_uff(case["frf_uff"], tmp_path / "machine.uff")
    result = cli("identify", path)
    # before: "neither the vertical nor the horizontal joint mode was found", no word about axes
    assert result.exit_code == 1, result.output
    assert f"try --axis-map {MACHINE}" in result.output
    mapped = cli("identify", path, "--axis-map", MACHINE, "--json")
    assert mapped.exit_code == 0, mapped.output
    got = json.loads(mapped.output.strip().splitlines()[-1])
    ref = identify(case["frf_uff"])
    for name in ("K_V", "K_H"):
        assert got["parameters"][name]["value"] == pytest.approx(ref.parameters[name]["value"], rel=0.01), name
    frf = cli("frf", path, "--axis-map", MACHINE, "--out", tmp_path / "back.uff")  # written in guidefit's frame
    assert frf.exit_code == 0, frf.output
    assert {s["rsp_dir"] for s in pyuff.UFF(str(tmp_path / "back.uff")).read_sets()[1:]} <= {1, -1, 2, -2}


def test_axis_map_syntax_is_export_s_and_bad_maps_are_one_line(case, tmp_path):
    from guidefit.export import ExportError
    from guidefit.export import parse_axis_map as export_parse
    from guidefit.io.axes import parse_axis_map

    assert np.array_equal(export_parse(MACHINE), parse_axis_map(MACHINE))
    with pytest.raises(ExportError, match="mirror image"):
        export_parse("x=X,y=Z,z=Y")
    for bad, needle in (("x=X,y=Z,z=Y", "mirror image"), ("x=X,y=X,z=Z", "distinct"), ("up=Z", "x=AXIS")):
        result = cli("identify", case["frf_uff"], "--axis-map", bad)
        assert result.exit_code == 2 and needle in result.output, result.output
        assert len(result.output.strip().splitlines()) == 1
    csv = tmp_path / "rec.csv"
    csv.write_text("# sample_rate_hz: 1000\n# excitation_direction: 0 -1 0\nforce,acc_A_y\n" + "0,0\n" * 8)
    result = cli("frf", csv, "--axis-map", MACHINE)
    assert result.exit_code == 2 and "a CSV, a test setup or a DAQ file" in result.output, result.output
