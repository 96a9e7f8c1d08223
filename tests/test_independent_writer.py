"""identify on recordings written by a second, independent writer (tests/_indep_writer.py).

guidefit's own writer always makes the same choices where the contract
(shared/recording-format.md, version 1) leaves them to the writer; here each
choice is varied alone and identify must give the truth of the simulation (f
within 0.1 %, K within 0.5 %) or, for a file outside the contract, a one-line
error with exit 2. The JSON results are checked against every rule the
contract states for them.
"""

from __future__ import annotations

import json
import math

import _indep_writer as W
import pytest
from click.testing import CliRunner

from guidefit.cli import main
from guidefit.identify import IdentifySettings, identify
from guidefit.simulate import SimulationConfig, simulate

FAST = IdentifySettings(jackknife=False)
TOL = {"f_V": 1e-3, "f_H": 1e-3, "K_V": 5e-3, "K_H": 5e-3}
UNITS = {"f_V": "Hz", "f_H": "Hz", "zeta_V": "1", "zeta_H": "1", "K_V": "N/m", "K_H": "N/m", "c_V": "N*s/m",
         "c_H": "N*s/m"}


@pytest.fixture(scope="module", params=["default", "single", "side"])
def simulated(request):
    """(layout, recording, truth): MRB35, both runs, 2 short hits."""
    data, truth = simulate("MRB35", config=SimulationConfig(hits=2, record_s=0.02, sensor_layout=request.param),
                           seed=3)
    return request.param, data, truth


def _accels(data):
    return tuple(n for r in data.runs for n in r.channel_names if n != "force")


def _force_last(names):
    return [i for i, n in enumerate(names) if n != "force"] + [names.index("force")]


def _renamed_points(data):
    """A-D as P-S and E-H as E1-H1: point names are free."""
    new = dict(zip("ABCDEFGH", ("P", "Q", "R", "S", "E1", "F1", "G1", "H1")))
    return {n: f"acc_{new[n.split('_')[1]]}_{n.split('_')[2]}" for n in _accels(data)}


VARIANTS = {
    "as_given": lambda d: {},
    "no_excitation_position": lambda d: {"omit": ("excitation_position_m",)},
    "no_pretrigger": lambda d: {"omit": ("pretrigger_samples",)},
    "no_optional_at_all": lambda d: {"omit": ("excitation_position_m", "pretrigger_samples", "description",
                                              "guide")},
    "fixed_length_bytes": lambda d: {"text": "fixed_bytes"},
    "variable_length_bytes": lambda d: {"text": "vlen_bytes"},
    "python_lists_of_text": lambda d: {"text": "object_str"},
    "integer_rate": lambda d: {"rate": "int"},
    "rate_as_1_element_array": lambda d: {"rate": "array1"},
    "float32_rate_and_vectors": lambda d: {"rate": "float32", "vector": "float32"},
    "vectors_as_lists": lambda d: {"vector": "list"},
    "force_last": lambda d: {"channel_order": _force_last},
    "channels_reversed": lambda d: {"channel_order": lambda n: list(range(len(n)))[::-1]},
    "every_accelerometer_reversed": lambda d: {"flip": _accels(d)},
    "one_accelerometer_reversed": lambda d: {"flip": _accels(d)[:1]},
    "float32_samples": lambda d: {"dtype": "float32"},
    "chunked": lambda d: {"storage": "chunked"},
    "gzip": lambda d: {"storage": "gzip"},
    "signals_layout": lambda d: {"layout": "signals"},
    "runs_named_run1_run2": lambda d: {"run_names": {"vertical": "run1", "lateral": "run2"}},
    "runs_in_other_order": lambda d: {"run_order": ["lateral", "vertical"]},
    "unknown_attributes_and_datasets": lambda d: {"extra": True},
    "accelerations_in_g": lambda d: {"units_g": _accels(d)},
    "other_point_names": lambda d: {"rename": _renamed_points(d)},
}


def _within(params, truth, keys=TOL):
    for key in keys:
        value = (params.get(key) or {}).get("value")
        assert value is not None, key
        assert value == pytest.approx(truth["parameters"][key]["value"], rel=TOL[key]), key


@pytest.mark.parametrize("variant", sorted(VARIANTS))
def test_every_writer_choice_gives_the_truth(tmp_path, simulated, variant):
    _layout, data, truth = simulated
    path = tmp_path / f"{variant}.h5"
    W.write_h5(path, data, **VARIANTS[variant](data))
    _within(identify(path, settings=FAST).parameters, truth)


def _contract_errors(obj) -> list[str]:
    """Every rule shared/recording-format.md states for one ``identify --json`` object."""
    def number(x):
        return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)

    errors = [f"'{k}' missing" for k in ("file", "guide", "parameters", "modes", "warnings") if k not in obj]
    if not isinstance(obj.get("file"), str):
        errors.append("file is not text")
    if obj.get("guide") is not None and not isinstance(obj["guide"], str):
        errors.append("guide is neither text nor null")
    for key, unit in UNITS.items():
        p = obj.get("parameters", {}).get(key)
        if not isinstance(p, dict):
            errors.append(f"{key} missing")
            continue
        if p.get("unit") != unit:
            errors.append(f"{key}: unit {p.get('unit')!r}, contract {unit!r}")
        if p.get("value") is not None and not number(p["value"]):
            errors.append(f"{key}: value {p['value']!r}")
        if "std" not in p or (p["std"] is not None and not (number(p["std"]) and p["std"] >= 0)):
            errors.append(f"{key}: std {p.get('std')!r}")
    for m in obj.get("modes", []):
        if not (isinstance(m.get("label"), str) and number(m.get("frequency_hz"))
                and (m.get("damping_ratio") is None or number(m["damping_ratio"]))):
            errors.append(f"mode {m!r:.60}")
    if not isinstance(obj.get("warnings"), list) or not all(isinstance(w, str) for w in obj["warnings"]):
        errors.append("warnings is not a list of text")
    return errors


def test_identify_json_follows_the_contract_for_good_and_failed_files(tmp_path, simulated):
    """One JSON line per file, each with the contract's fields, units and null rules, also when it fails."""
    _layout, data, truth = simulated
    good, lateral_only, bad = tmp_path / "good.h5", tmp_path / "lateral.h5", tmp_path / "bad.h5"
    W.write_h5(good, data, text="fixed_bytes", layout="signals", run_names={"vertical": "a", "lateral": "b"})
    W.write_h5(lateral_only, data, run_order=["lateral"])
    W.write_h5(bad, data, dtype="float64")
    import h5py

    with h5py.File(bad, "a") as f:
        f["runs/vertical"].attrs["sample_rate_hz"] = -1.0
    result = CliRunner().invoke(main, ["identify", "--json", str(good), str(lateral_only), str(bad)])
    lines = result.stdout.strip().splitlines()
    assert len(lines) == 3
    objs = [json.loads(line) for line in lines]
    assert [o["file"] for o in objs] == [str(good), str(lateral_only), str(bad)]
    for o in objs:
        assert _contract_errors(o) == [], o["file"]
    _within(objs[0]["parameters"], truth)
    assert objs[2]["parameters"]["f_V"]["value"] is None
    assert result.exit_code == 2


# --------------------------------------------------------------------------- CSV


def _csv_text(tmp_path, data, **kw):
    path = tmp_path / "v.csv"
    W.write_csv(path, data.runs[0], **kw)
    return path.read_text()


CSV_VARIANTS = {
    "as_given": lambda t: t,
    "crlf": lambda t: t.replace("\n", "\r\n"),
    "byte_order_mark": lambda t: "\ufeff" + t,
    "free_comment_lines": lambda t: "# recorded on bench 3\n#no space after the hash\n" + t,
    "unknown_keys": lambda t: t.replace("# guide: MRB35\n", "# guide: MRB35\n# operator: X\n# tip: steel\n"),
    "hash_without_space": lambda t: t.replace("# ", "#"),
    "direction_with_commas": lambda t: t.replace("# excitation_direction: 0 -1 0", "# excitation_direction: 0,-1,0"),
    "rate_with_decimals": lambda t: t.replace("# sample_rate_hz: 200000", "# sample_rate_hz: 200000.0"),
    "rate_in_e_notation": lambda t: t.replace("# sample_rate_hz: 200000", "# sample_rate_hz: 2e5"),
    "quoted_header": lambda t: _quote(t, header_only=True),
    "every_field_quoted": lambda t: _quote(t, header_only=False),
}


def _quote(text, header_only):
    lines = text.splitlines(True)
    first = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    out = lines[:first]
    for k, line in enumerate(lines[first:]):
        cells = line.rstrip("\n").split(",")
        out.append(",".join(f'"{c}"' for c in cells) + "\n" if k == 0 or not header_only else line)
    return "".join(out)


@pytest.fixture(scope="module")
def default_layout():
    return simulate("MRB35", config=SimulationConfig(hits=2, record_s=0.02, sensor_layout="default"), seed=3)


@pytest.mark.parametrize("variant", sorted(CSV_VARIANTS))
def test_csv_writer_choices_give_the_truth(tmp_path, default_layout, variant):
    data, truth = default_layout
    path = tmp_path / "vertical.csv"
    path.write_text(CSV_VARIANTS[variant](_csv_text(tmp_path, data)), newline="")
    _within(identify(path, settings=FAST).parameters, truth, keys=("f_V", "K_V"))


@pytest.mark.parametrize("kw", [{"time": True, "meta": False}, {"time": True}, {"fmt": "%.6e"}, {"fmt": "%.8f"},
                                {"channel_order": _force_last}, {"guide": None}])
def test_csv_column_and_number_choices_give_the_truth(tmp_path, default_layout, kw):
    data, truth = default_layout
    path = tmp_path / "vertical.csv"
    W.write_csv(path, data.runs[0], **kw)
    _within(identify(path, settings=FAST).parameters, truth, keys=("f_V", "K_V"))


@pytest.mark.parametrize("kw, message", [({"delimiter": ";"}, "separated by ';'"),
                                         ({"delimiter": "\t"}, "separated by tabs"),
                                         ({"delimiter": ";", "decimal": ","}, "separated by ';'")])
def test_csv_outside_the_contract_is_one_line_exit_2(tmp_path, default_layout, kw, message):
    data, _ = default_layout
    path = tmp_path / "vertical.csv"
    W.write_csv(path, data.runs[0], **kw)
    result = CliRunner().invoke(main, ["identify", str(path)])
    assert result.exit_code == 2
    assert message in result.stderr and len(result.stderr.strip().splitlines()) == 1


def test_one_run_one_accelerometer_file_is_labelled(tmp_path):
    """Was: a file holding one run of the 'single' layout (one accelerometer at A) had its modes labelled by
    rounding: with one channel every model mode fits the shape (MAC 1) and the common scale took the first
    in floating-point order. Vertical run: yaw (predicted reading 6e-32), 'modal constants 1.49e+30 times
    those the model predicts', no mode labelled, rejected 'does not look like a carriage' (exit 1); lateral
    run stored as float32 (guidefit's own writer): 'modal constants 3.95 times', f_H lost, exit 1, while the
    same values as float64 gave f_H. Now the tie goes to the model mode nearest in frequency."""
    data, truth = simulate("MRB35", config=SimulationConfig(hits=2, record_s=0.02, sensor_layout="single"), seed=3)
    for run, dtype, keys in (("vertical", "float64", ("f_V", "K_V")), ("lateral", "float32", ("f_H", "K_H")),
                             ("lateral", "float64", ("f_H", "K_H"))):
        path = tmp_path / f"{run}_{dtype}.h5"
        W.write_h5(path, data, run_order=[run], dtype=dtype)
        result = identify(path, settings=FAST)
        assert not any("times those the model predicts" in w for w in result.warnings), (run, dtype)
        _within(result.parameters, truth, keys=keys)


def test_hammer_direction_and_force_both_negated_gives_the_truth(tmp_path, default_layout):
    """The contract: a positive force sample is a force along excitation_direction; a writer that
    declares the axis the other way round writes negative pulses (the same physics). Was: every hit
    rejected as 'negative', 'no run gave an FRF', exit 1; now read with the hammer's sign turned, said."""
    data, truth = default_layout
    path = tmp_path / "force_negated.h5"
    W.write_h5(path, data, force_sign=-1.0)
    result = identify(path, settings=FAST)
    _within(result.parameters, truth)
    assert sum("force pulses are negative" in w for w in result.warnings) == 2
