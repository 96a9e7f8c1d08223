"""predict: each stiffness named for what it is, a sweep range, one JSON document, 80 columns, units.

Issue 14: predict showed K_H = 1.08e9 N/m, its own --load implied 6.8e8 and identify reports an
apparent 5.4e8: three quantities under one name. Tables were cut at 80 columns ("2.151e-..."),
``--sweep --json`` gave 21 JSON lines, the sweep plot's y axis had no unit.
"""

from __future__ import annotations

import io
import json
import math

import numpy as np
import pytest
from click.testing import CliRunner
from rich.console import Console

from guidefit import report
from guidefit.cli import main
from guidefit.model.guides import load_guide
from guidefit.predict import parse_sweep, predict, predict_sweep

MRB35 = load_guide("MRB35")


def _cli(*args, **env):
    result = CliRunner(env={"COLUMNS": "80", **env}).invoke(main, [str(a) for a in args])
    return result.exit_code, result.stdout, result.stderr


def _json(*args):
    code, out, err = _cli("predict", "--json", *args)
    assert code == 0, err
    return json.loads(out)  # one document: json.loads of the whole output


def test_the_three_stiffnesses_have_distinct_names_and_values():
    free = _json()
    st = free["stiffness"]
    assert set(st) >= {"static_zero_load", "static_at_load", "apparent_single_dof"}
    for key in ("static_zero_load", "static_at_load", "apparent_single_dof"):
        assert st[key]["meaning"]  # each says what it is
    # static, Eq. (2), nominal K_n: K_V = K_H = 4 Z_L K_n sin^2(45 deg) by hand
    by_hand = 4 * 21 * 2.5754e7 * 0.5
    for key in ("static_zero_load", "static_at_load"):
        assert st[key]["K_V"]["value"] == pytest.approx(by_hand, rel=1e-6)
        assert st[key]["K_H"]["value"] == pytest.approx(by_hand, rel=1e-6)
    # apparent, Eq. (24)-(25), from predict's own frequencies: what identify reports
    f = {m["label"]: m["frequency_hz"] for m in free["modes"]}
    mass = MRB35.mass_kg
    assert st["apparent_single_dof"]["K_V"]["value"] == pytest.approx(4 * math.pi**2 * mass * f["vertical"]**2,
                                                                       rel=1e-9)
    assert st["apparent_single_dof"]["K_H"]["value"] == pytest.approx(4 * math.pi**2 * mass * f["roll_low"]**2,
                                                                       rel=1e-9)
    # the numbers: 1.08e9 static against an apparent 5.4e8 lateral value
    assert st["apparent_single_dof"]["K_H"]["value"] == pytest.approx(5.41e8, rel=5e-3)
    assert st["apparent_single_dof"]["K_H"]["value"] < 0.55 * st["static_zero_load"]["K_H"]["value"]


def test_under_load_the_static_tangent_at_the_load_differs_from_the_zero_load_one():
    loaded = _json("--load", "2000,1000,0")["stiffness"]
    assert loaded["static_zero_load"]["K_H"]["value"] == pytest.approx(1.0817e9, rel=1e-3)
    assert loaded["static_at_load"]["K_H"]["value"] < 0.9 * loaded["static_zero_load"]["K_H"]["value"]
    lib = predict(MRB35, load=(2000.0, 1000.0, 0.0))
    assert loaded["static_at_load"]["K_H"]["value"] == pytest.approx(float(lib.static.K_H), rel=1e-9)


def test_the_table_names_each_stiffness_and_fits_80_columns():
    code, out, err = _cli("predict", "--load", "2000,1000,0")
    assert code == 0, err
    assert "static tangent, zero load" in out and "static tangent, this load" in out and "apparent" in out
    assert "…" not in out and "..." not in out
    assert max(len(line) for line in out.splitlines()) <= 80


def test_parse_sweep():
    assert parse_sweep("FV:0:5000:21") == ("FV", 0.0, 5000.0, 21)
    assert parse_sweep("m:-10:10:3") == ("M", -10.0, 10.0, 3)
    for bad in ("FV:0:5000", "FX:0:1:2", "FV:a:1:2", "FV:0:1:1", "FV:0:inf:5", "FV:0:1:100000"):
        with pytest.raises(ValueError):
            parse_sweep(bad)


def test_sweep_range_gives_one_json_document():
    doc = _json("--sweep", "FV:0:900:7", "--load", "0,100,0")
    assert doc["sweep"]["quantity"] == "F_V_n" and doc["sweep"]["n"] == 7 and doc["sweep"]["unit"] == "N"
    rows = doc["rows"]
    assert len(rows) == 7
    np.testing.assert_allclose([r["F_V_n"] for r in rows], np.linspace(0, 900, 7), rtol=0, atol=1e-9)
    np.testing.assert_allclose([r["F_H_n"] for r in rows], 100.0, rtol=0, atol=1e-9)  # the rest from --load
    for r in rows:
        assert r["K_V_apparent_n_per_m"] == pytest.approx(4 * math.pi**2 * MRB35.mass_kg * r["f_vertical_hz"]**2,
                                                          rel=1e-9)
    # the vertical static stiffness softens as the lower rows unload
    assert rows[-1]["K_V_static_n_per_m"] < rows[0]["K_V_static_n_per_m"]


def test_bare_sweep_json_is_one_document_too():
    doc = _json("--sweep")
    assert len(doc["rows"]) == 21 and doc["sweep"]["n"] == 21


@pytest.mark.parametrize("bad", ["FV:0:1", "FV:0:1:1", "Z:0:1:5"])
def test_bad_sweep_is_one_line_exit_2(bad):
    code, _, err = _cli("predict", "--sweep", bad)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "--sweep" in err, err


def test_sweep_table_fits_80_columns_without_truncation():
    frame = predict_sweep(MRB35, sweep=("FV", 0.0, 900.0, 5))
    buffer = io.StringIO()
    report.render_sweep(frame, guide_name="MRB35", console=Console(file=buffer, width=80))
    text = buffer.getvalue()
    assert "…" not in text
    assert max(len(line) for line in text.splitlines()) <= 80
    assert "K_V stat" in text and "K_V app" in text and "F_V (N)" in text
    code, out, _ = _cli("predict", "--sweep", "M:0:20:3")
    assert code == 0 and "…" not in out and "M_gamma (N m)" in out


def test_sweep_plot_axes_say_their_units(tmp_path, monkeypatch):
    figures = []
    real = report._figure

    def keep(*args, **kwargs):
        fig, axes = real(*args, **kwargs)
        figures.append(axes)
        return fig, axes
    monkeypatch.setattr(report, "_figure", keep)
    frame = predict_sweep(MRB35, sweep=("FH", 0.0, 300.0, 3))
    report.plot_sweep(frame, tmp_path / "s.png")
    labels = [(ax.get_xlabel(), ax.get_ylabel()) for ax in figures[0].ravel()]
    assert labels == [("F_H (N)", "natural frequency (Hz)"), ("F_H (N)", "stiffness (N/m)")]
    assert (tmp_path / "s.png").stat().st_size > 10_000


# --------------------------------------------------------------------------- a sweep past lift-off


def test_sweep_past_lift_off_gives_the_loads_up_to_it_and_says_where_it_ends(tmp_path):
    # before: FV 0..3000 N on MRB35 failed whole (exit 2) at 1500 N, where rows 3 and 4 have lifted off
    from guidefit.model import static

    lift = static.lift_off_load(MRB35)  # 1071 N: F = 2 Z sin(b) Q(2 Delta), tests/test_static.py
    plot = tmp_path / "sweep.png"
    code, out, err = _cli("predict", "--sweep", "FV:0:3000:7", "--plot", plot)
    assert code == 0, err
    lines = [line for line in out.splitlines() if "sweep ends there" in line]
    assert len(lines) == 1 and "rows 3, 4 lift off above F_V = 1071 N" in lines[0], out
    assert "(3 of 7 loads computed)" in lines[0] and plot.stat().st_size > 0
    code, out, err = _cli("predict", "--json", "--sweep", "FV:0:3000:7")
    assert code == 0, err
    doc = json.loads(out)
    assert [r["F_V_n"] for r in doc["rows"]] == pytest.approx([0.0, 500.0, 1000.0])
    limit = doc["limit"]
    assert limit["value"] == pytest.approx(lift, rel=1e-6) and limit["unit"] == "N"
    assert limit["quantity"] == "F_V_n" and limit["rows_lifted"] == [3, 4]
    assert (limit["points_computed"], limit["points_requested"]) == (3, 7)
    assert err.strip().splitlines() == [f"warning: {limit['message']}"]
    # the points computed are those of the sweep that stops short of lift-off
    short = predict_sweep(MRB35, sweep=("FV", 0.0, 1000.0, 3))
    assert [r["f_vertical_hz"] for r in doc["rows"]] == pytest.approx(list(short["f_vertical_hz"]), rel=1e-12)
    assert short.attrs["limit"] is None and _json("--sweep", "FV:0:900:4")["limit"] is None


def test_bare_sweep_to_a_load_past_lift_off_ends_there_too():
    doc = _json("--sweep", "--load", "3000,0,0")
    assert len(doc["rows"]) == 8 and doc["limit"]["value"] == pytest.approx(1071, rel=1e-3)
    assert doc["sweep"]["to"] == pytest.approx(3000.0) and doc["sweep"]["n"] == 21


def test_sweep_whose_first_load_cannot_be_held_is_one_line_exit_2():
    code, _, err = _cli("predict", "--sweep", "FV:-60000:0:7")
    assert code == 2 and len(err.strip().splitlines()) == 1 and "do not restrain" in err, err
