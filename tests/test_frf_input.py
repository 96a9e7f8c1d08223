"""FRFs as input: identify / explain / report from frf.h5 and UFF-58 FRFs (issue 15, "FRFs in").

One small seeded simulation (two runs, four hits of 50 ms, known truth) is
identified from its time data and from FRF files written from it:

* ``frf.h5`` keeps the FrfSets whole, jackknife group sums included, so the
  identification is the same numbers (same FRFs, same fit, same jackknife);
* guidefit's UFF-58 keeps 12 significant digits of each FRF value and the
  exact bins (its sample rate in ID line 5): the same K and c far within
  their std; its std is the fit's own (UFF carries no hits);
* a UFF-58 file written with pyuff directly, as another program would
  (its own reference node, no guidefit ID lines, no coherence), maps to the
  same channels and gives the same joint as the recording with the same FRF
  window (none);
* receptance and mobility are converted to accelerance (same joint);
* malformed FRF files give exit 2 and one line.
"""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from click.testing import CliRunner

from guidefit.cli import main
from guidefit.errors import RecordingError
from guidefit.identify import IdentifySettings, frf_of_recording, identify
from guidefit.io import write_frfs, write_recording
from guidefit.io.frf_files import FrfFile, holds_frfs, read_frf_file, read_input

pyuff = pytest.importorskip("pyuff")

JOINT = ("K_V", "K_H", "c_V", "c_H")


def cli(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    """A simulated recording, its identification, and FRF files written from it."""
    from guidefit.frf import WindowSettings
    from guidefit.simulate import SimulationConfig, simulate

    folder = tmp_path_factory.mktemp("frf_input")
    data, truth = simulate("MRB35", config=replace(SimulationConfig(), hits=4, record_s=0.05), seed=3)
    rec = folder / "rec.h5"
    write_recording(rec, data)
    frfsets, _ = frf_of_recording(rec)
    write_frfs(folder / "frf.h5", frfsets, recording=rec)
    write_frfs(folder / "frf.uff", frfsets, recording=rec)
    no_window = IdentifySettings(window=WindowSettings(none=True))
    plain, _ = frf_of_recording(rec, no_window)
    return {"folder": folder, "rec": rec, "truth": truth, "ident": identify(rec), "frfsets": frfsets,
            "plain_frfsets": plain, "plain_ident": identify(rec, settings=no_window),
            "frf_h5": folder / "frf.h5", "frf_uff": folder / "frf.uff"}


def _assert_same_joint(got, ref, within: float):
    """Each joint parameter of ``got`` within ``within`` times its own reported std of ``ref``'s."""
    for name in JOINT:
        a, b = ref.parameters[name], got.parameters[name]
        assert b["std"] is not None and b["std"] > 0, name
        assert abs(b["value"] - a["value"]) <= within * b["std"], (name, a, b)


# ------------------------------------------------------------------ round trips


def test_frf_h5_gives_the_recordings_identification(case):
    got = identify(case["frf_h5"])
    ref = case["ident"]
    # the same FrfSets (group sums included): the same fit and jackknife, to rounding
    for name in JOINT:
        a, b = ref.parameters[name], got.parameters[name]
        assert b["value"] == pytest.approx(a["value"], rel=1e-9), name
        assert b["std"] == pytest.approx(a["std"], rel=1e-6), name
    assert got.hits_checked is False and got.hit_rows() == []
    assert got.summary_row()["hits_checked"] is False and case["ident"].summary_row()["hits_checked"] is True
    assert any("no hit checks were possible" in w for w in got.warnings)
    assert not any("hit-to-hit scatter is not included" in w for w in got.warnings)
    # geometry and hammer directions came with the file
    by_run = {r.name: r for r in got.runs}
    assert by_run["vertical"].excitation_direction == pytest.approx((0.0, -1.0, 0.0))
    assert {ch.name: tuple(ch.position_m) for ch in by_run["vertical"].channels} == \
        {ch.name: tuple(ch.position_m) for ch in next(r for r in case["ident"].runs if r.name == "vertical").channels}


def test_frf_uff_gives_the_same_joint_within_its_std_and_says_what_is_missing(case):
    got = identify(case["frf_uff"])
    ref = case["ident"]
    _assert_same_joint(got, ref, within=0.01)  # 12-digit values and exact bins: the same fit
    for name in JOINT:  # the std is the fit's own: no larger than fit + jackknife from the recording
        assert got.parameters[name]["std"] <= ref.parameters[name]["std"] * (1 + 1e-9), name
    assert got.hits_checked is False
    assert any("hit-to-hit scatter is not included" in w for w in got.warnings)
    assert [r.name for r in got.runs] == ["vertical", "lateral"]
    assert got.guide.name == "MRB35"


def test_identify_json_says_no_hits_were_checked(case):
    result = cli("identify", case["frf_uff"], "--json")
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["hits_checked"] is False and data["hits"] == []
    assert data["parameters"]["K_V"]["value"] == pytest.approx(case["ident"].parameters["K_V"]["value"], rel=1e-6)
    table = cli("identify", case["frf_h5"])
    assert table.exit_code == 0 and "hits: not checked (FRF input" in table.output


def test_checks_that_need_hits_or_coherence_are_not_passed_vacuously(case, tmp_path):
    from guidefit.report.check import check_result, parse_spec

    spec = parse_spec({"quality": {"max_rejected_hits": 0, "min_coherence": 0.5}}, "spec")
    assert check_result(case["ident"].to_dict(), spec) == []
    frf_h5 = check_result(identify(case["frf_h5"]).to_dict(), spec)
    assert len(frf_h5) == 1 and "no hit checks were possible" in frf_h5[0]
    no_coherence = _other_tool_uff(tmp_path / "nocoh.uff", case["plain_frfsets"])
    violations = check_result(identify(no_coherence).to_dict(), spec)
    assert sum("no coherence at the" in v for v in violations) == 2  # vertical and roll_low


def test_time_data_json_says_hits_were_checked(case):
    assert case["ident"].to_dict()["hits_checked"] is True


def test_another_estimator_from_frf_h5_uses_its_sums_and_uff_says_it_cannot(case):
    h2 = IdentifySettings(estimator="H2")
    from_rec, from_h5 = identify(case["rec"], settings=h2), identify(case["frf_h5"], settings=h2)
    for name in JOINT:
        assert from_h5.parameters[name]["value"] == pytest.approx(from_rec.parameters[name]["value"], rel=1e-9)
    from_uff = identify(case["frf_uff"], settings=h2)
    assert any("holds H1 FRFs; estimator H2 needs the spectral sums" in w for w in from_uff.warnings)


def test_frf_command_converts_frf_h5_to_uff(case, tmp_path):
    out = tmp_path / "conv.uff"
    result = cli("frf", case["frf_h5"], "--out", out)
    assert result.exit_code == 0, result.output
    got = identify(out)
    assert got.runs[0].excitation_direction is not None
    _assert_same_joint(got, case["ident"], within=0.01)
    # the hammer directions came through frf.h5 into the UFF reference DOFs
    assert {r.name: tuple(r.excitation_direction) for r in got.runs}["lateral"] == pytest.approx((-1.0, 0.0, 0.0))


def test_explain_and_report_start_from_the_frf_file(case, tmp_path):
    from guidefit.report.html import _header, _hits, report_results

    # what explain and the report start from (identify_for_explain): no force levels without hits
    res = report_results(case["frf_uff"], candidates=["added_mass"])
    assert res.identification.hits_checked is False and res.identification.to_dict()["force_levels"] == []
    assert res.explanation.verdict in ("adequate", "explained", "unexplained")
    # the report's parts that read the input: the FRF file's runs and sensors, no hit table
    # (the whole HTML with its figures: tests/test_html_report.py; it takes ~8 s on a busy machine)
    header = "\n".join(_header(res))
    assert "acc_C_y" in header and "<td>frf</td>" in header
    hits = "\n".join(_hits(res))
    assert "No hit checks were possible" in hits and "peak force (N)" not in hits


def test_input_kind_is_decided_from_the_content(case, tmp_path):
    from guidefit.io import read_recording
    from guidefit.io.uff import write_uff_recording

    time_uff = tmp_path / "time.uff"
    write_uff_recording(time_uff, read_recording(case["rec"]))
    assert not holds_frfs(case["rec"]) and not holds_frfs(time_uff)
    assert holds_frfs(case["frf_h5"]) and holds_frfs(case["frf_uff"])
    assert isinstance(read_input(case["frf_uff"]), FrfFile)
    assert not isinstance(read_input(time_uff), FrfFile)


# ------------------------------------------------------------------ another program's UFF-58


def _other_tool_uff(path, frfsets, *, numerator=12, units="m/s^2", from_bin=0, coherence=False,
                    denominator=13, den_units="N", axes=None, node_base=1, geometry=None):
    """FRFs as another program writes them with pyuff: its own nodes (A-D = node_base + 0..3), reference node 20.

    ``geometry``: a point -> position mapping written as a dataset 2411 (node coordinates).
    """
    sets = [pyuff.prepare_164(units_code=1, units_description="SI", temp_mode=2, length=1.0, force=1.0,
                              temp=1.0, temp_offset=273.15)]
    if geometry is not None:
        xyz = np.array([geometry[p] for p in "ABCD"], float)
        sets.append(pyuff.prepare_2411(node_nums=np.arange(4) + node_base, def_cs=np.zeros(4, int), disp_cs=np.zeros(4, int),
                                       color=np.ones(4, int), x=xyz[:, 0], y=xyz[:, 1], z=xyz[:, 2]))
    power = {12: 0, 11: 1, 8: 2}.get(numerator, 0)
    for i, frf in enumerate(frfsets):
        ref_dir = -2 if frf.run == "vertical" else -1
        f = np.asarray(frf.frequency_hz)[from_bin:]
        if axes is not None:
            f = axes[i]
        for k, channel in enumerate(frf.channels):
            _, point, axis = channel.split("_")
            H = np.asarray(frf.H)[from_bin:, k] / (2j * np.pi * f) ** power
            common = dict(binary=0, rsp_node="ABCD".index(point) + node_base, rsp_dir="xyz".index(axis) + 1,
                          ref_node=20 + i, ref_dir=ref_dir, x=f, abscissa_spacing=1, abscissa_spec_data_type=18,
                          abscissa_axis_units_lab="Hz", rsp_ent_name="carriage", ref_ent_name="hammer",
                          id1=f"FRF {point}{axis}", id2="impact test", id3="NONE", id4="NONE", id5="NONE")
            sets.append(pyuff.prepare_58(func_type=4, data=H, ordinate_spec_data_type=numerator,
                                         ordinate_axis_units_lab=units, orddenom_spec_data_type=denominator,
                                         orddenom_axis_units_lab=den_units, **common))
            if coherence:
                sets.append(pyuff.prepare_58(func_type=6, data=np.asarray(frf.coherence)[from_bin:, k],
                                             ordinate_spec_data_type=1, ordinate_axis_units_lab="NONE",
                                             orddenom_spec_data_type=0, orddenom_axis_units_lab="NONE", **common))
    pyuff.UFF(str(path)).write_sets(sets, mode="add")
    return path


def test_uff_frfs_of_another_program_give_the_same_joint(case, tmp_path):
    path = _other_tool_uff(tmp_path / "other.uff", case["plain_frfsets"])
    got = identify(path)
    # no coherence in the file: the global fit weights each FRF by its RMS instead of its noise
    # (globalfit._noise_weights), so the estimate moves within its std, not to the last digit
    _assert_same_joint(got, case["plain_ident"], within=2.0)
    names = {r.name for r in got.runs}
    assert names == {"ref20-Y", "ref21-X"}
    run = next(r for r in got.runs if r.name == "ref20-Y")
    assert run.excitation_direction == pytest.approx((0.0, -1.0, 0.0))
    assert {ch.name for ch in run.channels} == set(case["plain_frfsets"][0].channels)
    text = " ".join(got.warnings)
    assert "exponential window" in text and "no coherence" in text and "twice the highest frequency" in text
    assert "estimator" not in text  # the file does not say which: nothing to compare --estimator with


def test_node_coordinates_of_the_file_place_other_nodes(case, tmp_path):
    from guidefit.io import default_points

    points = {p: np.asarray(v, float) for p, v in default_points("MRB35").items()}
    path = _other_tool_uff(tmp_path / "nodes.uff", case["plain_frfsets"], node_base=31, geometry=points)
    got = identify(path)
    _assert_same_joint(got, case["plain_ident"], within=2.0)  # no coherence: RMS weights (above)
    run = next(r for r in got.runs if r.name == "ref20-Y")
    by_name = {ch.name: ch for ch in run.channels}
    assert by_name["acc_N33_y"].position_m == pytest.approx(points["C"])  # node 33 is the file's point C
    assert not any("no position for" in w for w in got.warnings)
    # without the coordinates nodes 31-34 have no position: said, not hidden
    bare = _other_tool_uff(tmp_path / "bare.uff", case["plain_frfsets"][:1], node_base=31)
    assert any("no position for acc_N31_x" in note for note in read_frf_file(bare).notes)


@pytest.mark.parametrize("numerator, units", [(8, "m"), (11, "m/s")])
def test_receptance_and_mobility_are_converted(case, tmp_path, numerator, units):
    ref = _other_tool_uff(tmp_path / "acc.uff", case["plain_frfsets"], from_bin=1, coherence=True)
    path = _other_tool_uff(tmp_path / "conv.uff", case["plain_frfsets"], numerator=numerator, units=units,
                           from_bin=1, coherence=True)
    a, b = identify(ref), identify(path)
    for name in JOINT:  # the same accelerance after conversion (12-digit values)
        assert b.parameters[name]["value"] == pytest.approx(a.parameters[name]["value"], rel=1e-7), name
    assert any("converted to accelerance" in w for w in b.warnings)


# ------------------------------------------------------------------ bad input: exit 2, one line


def _one_line_exit_2(path, *needles):
    result = cli("identify", path)
    assert result.exit_code == 2, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("guidefit: error:"), result.output
    for needle in needles:
        assert needle in lines[0], lines[0]
    return lines[0]


def test_nan_in_frf_h5(case, tmp_path):
    import h5py

    path = tmp_path / "nan.h5"
    path.write_bytes(case["frf_h5"].read_bytes())
    with h5py.File(path, "r+") as f:
        H = f["frf/vertical/H"][()]
        H[100, 2] = np.nan
        f["frf/vertical/H"][...] = H
    _one_line_exit_2(path, "run 'vertical'", "non-finite", "acc_B_x")


@pytest.mark.parametrize("value", [-0.02, 0.0, np.inf])
def test_exponential_window_of_no_positive_time_constant_is_refused(case, tmp_path, value):
    """Was: tau <= 0 accepted, c_V 180 std off with exit 0 (the UFF reader refused the same value)."""
    import h5py

    path = tmp_path / "tau.h5"
    path.write_bytes(case["frf_h5"].read_bytes())
    with h5py.File(path, "r+") as f:
        f["frf/vertical"].attrs["exp_window_tau_s"] = value
    _one_line_exit_2(path, "run 'vertical'", "exp_window_tau_s", "seconds > 0")


def test_mismatched_coherence_in_frf_h5(case, tmp_path):
    import h5py

    path = tmp_path / "shape.h5"
    path.write_bytes(case["frf_h5"].read_bytes())
    with h5py.File(path, "r+") as f:
        del f["frf/lateral/coherence"]
        f["frf/lateral/coherence"] = np.ones((10, 8))
    _one_line_exit_2(path, "run 'lateral'", "coherence has shape")


def test_nan_in_uff(case, tmp_path):
    clean = _other_tool_uff(tmp_path / "clean.uff", case["plain_frfsets"][:1])
    lines = clean.read_text().splitlines(keepends=True)
    # a value line of the second dataset 58 (after its 11 header lines): one value replaced by NaN
    starts = [i for i, line in enumerate(lines) if line.strip() == "58"]
    k = starts[1] + 12
    lines[k] = "{:>20}".format("NaN") + lines[k][20:]
    path = tmp_path / "nan.uff"
    path.write_text("".join(lines))
    _one_line_exit_2(path, "non-finite")


def test_frf_without_force_reference(case, tmp_path):
    path = _other_tool_uff(tmp_path / "trans.uff", case["plain_frfsets"][:1], denominator=12,
                           den_units="m/s^2")
    _one_line_exit_2(path, "without a force reference", "set 2")


def test_mixed_frequency_axes_in_a_run(case, tmp_path):
    frf = case["plain_frfsets"][0]
    f = np.asarray(frf.frequency_hz)
    path = tmp_path / "mixed.uff"
    # two channels of one run on different axes: written as two "runs" of one frf set with one reference
    one = replace(frf, channels=frf.channels[:1], H=frf.H[:, :1], coherence=frf.coherence[:, :1])
    two = replace(frf, run="vertical", channels=frf.channels[1:2], H=frf.H[:, 1:2], coherence=frf.coherence[:, 1:2])
    _other_tool_uff(path, [one], axes=[f])
    sets = pyuff.UFF(str(path)).read_sets()
    extra = _other_tool_uff(tmp_path / "b.uff", [two], axes=[f * 1.001])
    sets_b = pyuff.UFF(str(extra)).read_sets()
    path.unlink()
    pyuff.UFF(str(path)).write_sets(list(sets) + [sets_b[1]], mode="add")
    _one_line_exit_2(path, "share one frequency axis")


@pytest.mark.parametrize("numerator, units, needle", [
    (9, "N", "reaction force (9) over force"),
    (12, "mm/s^2", "unit 'mm/s^2' unsupported"),
])
def test_unsupported_ordinates_are_refused(case, tmp_path, numerator, units, needle):
    path = _other_tool_uff(tmp_path / "bad.uff", case["plain_frfsets"][:1], numerator=numerator, units=units)
    _one_line_exit_2(path, needle)


def _edited_sets(path, edit):
    """Rewrite a UFF file with ``edit(sets)`` applied to its pyuff datasets."""
    sets = pyuff.UFF(str(path)).read_sets()
    edit(sets)
    path.unlink()
    pyuff.UFF(str(path)).write_sets(sets, mode="add")
    return path


@pytest.mark.parametrize("edit, needle", [
    (lambda sets: sets[1].update(data=np.abs(sets[1]["data"]), ord_data_type=4), "FRF with real values"),
    (lambda sets: sets[2].update(rsp_node=sets[1]["rsp_node"], rsp_dir=sets[1]["rsp_dir"]), "two FRFs of response"),
    (lambda sets: [s.update(ref_dir=5) for s in sets[1:]], "is a rotation"),
    (lambda sets: sets[0].update(length=0.001), "guidefit reads SI"),
])
def test_malformed_uff_frfs_are_refused(case, tmp_path, edit, needle):
    path = _edited_sets(_other_tool_uff(tmp_path / "x.uff", case["plain_frfsets"][:1]), edit)
    _one_line_exit_2(path, needle)


def test_frf_csv_is_refused_with_the_reason(case, tmp_path):
    path = tmp_path / "frf.csv"
    write_frfs(path, case["frfsets"])
    _one_line_exit_2(path, "frf.csv", "exponential-window", "--out frf.h5")


def test_reading_samples_of_an_frf_run_is_an_error(case):
    frf_file = read_frf_file(case["frf_h5"])
    with pytest.raises(RecordingError, match="holds FRFs, not time data"):
        frf_file.recording.runs[0].source.read((slice(0, 1),))


def test_frf_h5_links_and_group_sums_are_checked(case, tmp_path):
    import os

    import h5py

    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    path = tmp_path / "ext.h5"
    path.write_bytes(case["frf_h5"].read_bytes())
    with h5py.File(path, "r+") as f:
        del f["frf/vertical/H"]
        f["frf/vertical/H"] = h5py.ExternalLink(str(fifo), "/H")  # would block a reader that follows it
    _one_line_exit_2(path, "run 'vertical'", "not a regular file")
    path = tmp_path / "sums.h5"
    path.write_bytes(case["frf_h5"].read_bytes())
    with h5py.File(path, "r+") as f:
        sff = f["frf/lateral/group_sums/Sff"][()]
        del f["frf/lateral/group_sums/Sff"]
        f["frf/lateral/group_sums/Sff"] = sff[:, :10]  # a jackknife on other bins than H: refused
    _one_line_exit_2(path, "run 'lateral'", "group_sums/Sff")


def test_frf_h5_without_an_estimator_is_read_as_h1_with_a_note(case, tmp_path):
    """docs/frf.md: a missing estimator is taken as H1, with a note (was: refused, 'not one of H1, H2, Hv')."""
    import h5py

    path = tmp_path / "no_estimator.h5"
    path.write_bytes(case["frf_h5"].read_bytes())
    with h5py.File(path, "r+") as f:
        for run in f["frf"]:
            del f["frf"][run].attrs["estimator"]
    source = read_input(path)
    assert isinstance(source, FrfFile)
    assert any("no estimator in the file" in n and "taken as H1" in n for n in source.notes)
    got = identify(path)
    _assert_same_joint(got, case["ident"], within=1.0)
