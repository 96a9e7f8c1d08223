"""Guide catalogue and TOML loader: values, units and one-line errors."""

import pytest

from guidefit.errors import GuideError
from guidefit.model.guides import builtin_guides, load_guide

GOOD = """
name = "MY35"
[carriage]
mass_kg = 2.2
inertia_kg_m2 = [3.9e-3, 5.7e-3, 2.4e-3]
[rows]
e_m = "32 mm"
h1_m = 0.0235
h0_m = 0.0107
contact_angle_deg = 45
rollers_per_row = 21
roller_span_m = "90 mm"
[contact]
roller_stiffness_n_per_m = "25.754 N/um"
[points]
A = [0.03, 0, 0.045]
"""


def test_builtin_mrb35_has_pinned_values():
    g = load_guide("mrb35")
    assert "MRB35" in builtin_guides()
    assert g.roller_span_m == pytest.approx(0.090)
    assert g.roller_stiffness_n_per_m == pytest.approx(2.5754e7)
    assert g.measuring_points_m["C"] == (-0.030, 0.0, -0.045)


def test_user_toml_with_units(tmp_path):
    path = tmp_path / "g.toml"
    path.write_text(GOOD)
    g = load_guide(path)
    assert g.e_m == pytest.approx(0.032)
    assert g.roller_stiffness_n_per_m == pytest.approx(2.5754e7)
    assert g.source == str(path)


@pytest.mark.parametrize(
    "old, new, match",
    [
        ("mass_kg = 2.2", "", "carriage.mass_kg' missing"),
        ("mass_kg = 2.2", "mass_kg = -2.2", "carriage.mass_kg': must be positive"),
        ("mass_kg = 2.2", "mass = 2.2", "unknown field 'carriage.mass'; did you mean 'mass_kg'"),
        ('e_m = "32 mm"', 'e_m = "32"', "unit '' not allowed"),
        ('e_m = "32 mm"', 'e_m = "32 kg"', "unit 'kg' not allowed"),
        ("rollers_per_row = 21", "rollers_per_row = 2.5", "positive integer"),
        ("contact_angle_deg = 45", "contact_angle_deg = 95", "in \\(0, 90\\)"),
        ('name = "MY35"', 'name = "MY35"\ncolour = "red"', "unknown field 'colour'"),
        ("[contact]", "[contact]\nwear = 1", "unknown field 'contact.wear'"),
        # lengths in mm given as m: e_m = 32 gave a 64 m carriage and MHz modes with exit 0
        ('e_m = "32 mm"', "e_m = 32", "rows.e_m': 32 is 32 m; .*millimetres given"),
        ('e_m = "32 mm"', 'e_m = "32 m"', "rows.e_m': '32 m' is 32 m"),
        ("A = [0.03, 0, 0.045]", "A = [30, 0, 45]", "points.A'.*millimetres given"),
    ],
)
def test_bad_guide_files_give_one_line_errors(tmp_path, old, new, match):
    path = tmp_path / "bad.toml"
    path.write_text(GOOD.replace(old, new))
    with pytest.raises(GuideError, match=match) as info:
        load_guide(path)
    assert "\n" not in str(info.value)
    assert str(path) in str(info.value)


def test_unknown_guide_name():
    with pytest.raises(GuideError, match="not a built-in guide"):
        load_guide("NOPE99")


def test_not_toml(tmp_path):
    path = tmp_path / "x.toml"
    path.write_text("[[[")
    with pytest.raises(GuideError, match="not valid TOML"):
        load_guide(path)
