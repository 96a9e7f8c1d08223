"""The effect library as one registry (issue 16): every effect declared once, documented and tested.

* the table of docs/explain.md is the registry's (:func:`guidefit.model.effects.doc_table`);
* every registered effect is named by a test other than this one;
* explain has no rule of its own: an effect registered from a test is fitted;
* the support body is one structure under two names; aliases work;
* the roller-row segment is the per-roller model (checked against a
  stiffness array built by hand) and ``guidefit simulate --effect row_segment:...``
  writes it.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from click.testing import CliRunner

from guidefit.cli import main
from guidefit.errors import ModelError
from guidefit.model import effects as fx
from guidefit.model import vibration as vib
from guidefit.model.effects import EFFECTS, apply_effects, combinable, doc_table, make_effect, parse_effect
from guidefit.model.guides import load_guide

ROOT = Path(__file__).resolve().parents[1]
GUIDE = load_guide("MRB35")


def test_docs_table_is_the_registry():
    text = (ROOT / "docs" / "explain.md").read_text(encoding="utf-8")
    assert doc_table() in text, "docs/explain.md: the effect table differs from guidefit.model.effects.doc_table()"
    table = text[text.index("| effect | variants tried |"):]
    table = table[:table.index("\n\n")]
    assert re.findall(r"^\| `(\w+)` \|", table, flags=re.M) == list(EFFECTS)


@pytest.mark.parametrize("name", list(EFFECTS))
def test_every_effect_is_named_by_a_test(name):
    others = [p for p in (ROOT / "tests").glob("test_*.py") if p.name != Path(__file__).name]
    assert any(name in p.read_text(encoding="utf-8") for p in others), f"no test names effect {name}"


@pytest.mark.parametrize("name", list(EFFECTS))
def test_every_effect_declares_a_complete_entry(name):
    d = EFFECTS[name]
    assert d.name == name and d.meaning and d.doc.variants and d.doc.fitted and d.doc.meaning
    variants = d.variants(fx.FitContext(guide=GUIDE))
    assert variants and all(v.effect == name for v in variants)
    for v in variants:
        assert {fr.name for fr in v.free} | set(v.fixed) <= set(d.parameters)  # fits only its own parameters
        for fr in v.free:
            lo, hi = fr.bounds
            assert lo < hi
    # the documented defaults make a valid effect once the required parameters are given
    required = {k: (p.lower if p.unit else "A") for k, p in d.parameters.items() if p.default is None and k != "depth_m"}
    if name == "row_segment":
        required.update(first=1, last=10, factor=0.5)
    if name in ("row_damage", "row_segment"):
        required.update(row=2, factor=0.5)
    if name == "base_mode":
        required.update(mass_kg=3.0)
    spec = apply_effects(vib.model_from_guide(GUIDE), GUIDE, [make_effect(name, required)])
    assert vib.solve_modes(spec).frequencies_hz.size >= 5


def test_combination_rules_come_from_the_registry():
    assert not combinable("support_compliance", "base_mode")  # one structure
    assert not combinable("row_damage", "row_segment")  # a row and a part of it
    assert not combinable("added_mass", "added_mass")
    assert combinable("contact_stiffness", "row_segment") and combinable("added_mass", "support_compliance")
    with pytest.raises(ModelError, match="same structure"):
        apply_effects(vib.model_from_guide(GUIDE), GUIDE, [
            parse_effect("support_compliance:lateral_n_per_m=1e8"), parse_effect("base_mode:mass_kg=2,vertical_n_per_m=1e9")])


def test_support_body_is_one_structure_under_two_names():
    """support_compliance with a mass is the body that base_mode names; the names say whether the mass is fitted."""
    a = parse_effect("support_compliance:vertical_n_per_m=3e9,mass_kg=3")
    b = parse_effect("base_mode:vertical_n_per_m=3e9,mass_kg=3")
    fa = vib.solve_modes(apply_effects(vib.model_from_guide(GUIDE), GUIDE, [a])).frequencies_hz
    fb = vib.solve_modes(apply_effects(vib.model_from_guide(GUIDE), GUIDE, [b])).frequencies_hz
    assert fa.size == fb.size == 6 and np.allclose(fa, fb, rtol=1e-12)
    assert EFFECTS["support_compliance"].structure == EFFECTS["base_mode"].structure
    # the massless limit: a light body tends to the massless support's frequencies (carriage modes)
    light = parse_effect("base_mode:lateral_n_per_m=1.2e8,mass_kg=1e-3")
    massless = parse_effect("support_compliance:lateral_n_per_m=1.2e8")
    fl = vib.solve_modes(apply_effects(vib.model_from_guide(GUIDE), GUIDE, [light])).frequencies_hz
    fm = vib.solve_modes(apply_effects(vib.model_from_guide(GUIDE), GUIDE, [massless])).frequencies_hz
    assert np.allclose(np.sort(fl)[:5], np.sort(fm), rtol=2e-4)


def test_aliases_resolve_to_the_registry_names():
    assert parse_effect("support_body:mass_kg=3,vertical_n_per_m=3e9").name == "base_mode"
    assert parse_effect("support_massless:lateral_n_per_m=1.2e8").name == "support_compliance"
    with pytest.raises(ModelError, match="unknown effect 'wobble'; have added_mass"):
        parse_effect("wobble:x=1")
    with pytest.raises(ModelError, match="whole number"):
        parse_effect("row_damage:row=2.5,factor=0.5")


def test_row_segment_is_the_per_roller_model():
    """Half of row 2 (rollers 1-10 of 21) at 30 %: the effect equals a stiffness array built by hand."""
    k = np.full((4, GUIDE.rollers_per_row), GUIDE.roller_stiffness_n_per_m * GUIDE.effective_roller_fraction)
    k[1, :10] *= 0.3  # row 2, rollers 1-10 along +z
    by_hand = vib.solve_modes(vib.model_from_guide(GUIDE, k)).frequencies_hz
    effect = parse_effect("row_segment:row=2,first=1,last=10,factor=0.3")
    sol = vib.solve_modes(apply_effects(vib.model_from_guide(GUIDE), GUIDE, [effect]))
    assert np.allclose(sol.frequencies_hz, by_hand, rtol=0, atol=1e-6)  # within 1 uHz
    nominal = vib.solve_modes(vib.model_from_guide(GUIDE)).frequencies_hz
    assert np.max(np.abs(sol.frequencies_hz / nominal - 1)) > 0.03  # a change far above any noise
    # the whole row is row_damage
    whole = apply_effects(vib.model_from_guide(GUIDE), GUIDE, [parse_effect("row_segment:row=3,first=1,last=21,factor=0.4")])
    row = apply_effects(vib.model_from_guide(GUIDE), GUIDE, [parse_effect("row_damage:row=3,factor=0.4")])
    assert np.allclose(vib.solve_modes(whole).frequencies_hz, vib.solve_modes(row).frequencies_hz, rtol=1e-12)


def test_segment_weights_move_smoothly_with_fractional_ends():
    rollers = vib.rollers_from_guide(GUIDE)
    w = vib.segment_weights(rollers, 4, 3.25, 7.5)
    assert w.sum() == pytest.approx(7.5 - 3.25 + 1)
    assert set(np.unique(rollers.row[w > 0])) == {4}
    idx = vib.roller_index_in_row(rollers)
    assert w[(rollers.row == 4) & (idx == 3)][0] == pytest.approx(0.75)
    assert w[(rollers.row == 4) & (idx == 8)][0] == pytest.approx(0.5)
    with pytest.raises(ModelError, match="first <= last"):
        apply_effects(vib.model_from_guide(GUIDE), GUIDE, [parse_effect("row_segment:row=1,first=15,last=3,factor=0.5")])


def test_simulate_cli_writes_a_row_segment(tmp_path):
    out = tmp_path / "seg.h5"
    result = CliRunner().invoke(main, ["simulate", "--out", str(out), "--effect",
                                       "row_segment:row=2,first=1,last=10,factor=0.3", "--hits", "1",
                                       "--record-length", "0.02", "--ideal"])
    assert result.exit_code == 0, result.output
    truth = json.loads((tmp_path / "seg.truth.json").read_text(encoding="utf-8"))
    assert truth["effects"] == [{"name": "row_segment", "parameters": {"row": 2.0, "first": 1.0, "last": 10.0,
                                                                        "factor": 0.3}}]
    sol = vib.solve_modes(apply_effects(vib.model_from_guide(GUIDE), GUIDE,
                                        [parse_effect("row_segment:row=2,first=1,last=10,factor=0.3")]))
    got = {m["label"]: m["frequency_hz"] for m in truth["modes"]}
    for label, f in zip(sol.labels, sol.frequencies_hz):
        assert got[label] == pytest.approx(f, rel=1e-9)
    bad = CliRunner().invoke(main, ["simulate", "--out", str(tmp_path / "bad.h5"), "--effect",
                                    "row_segment:row=2,first=12,last=3,factor=0.3"])
    assert bad.exit_code == 2 and "first <= last" in bad.output and "Traceback" not in bad.output


def test_explain_fits_an_effect_registered_elsewhere(monkeypatch):
    """Adding an effect is one EffectDef: explain needs no rule of its own to fit it."""
    from guidefit.explain import explain_modes, synthetic_modes

    def apply(spec, guide, p):
        return vib.scale_roller_stiffness(spec, p["gain"])

    toy = fx.EffectDef(
        name="toy_gain", meaning="every roller times gain (a test double of contact_stiffness)",
        parameters={"gain": fx.Parameter("1", None, "gain", 0.1, 10.0)}, apply=apply,
        variants=lambda ctx: [fx.Variant("toy_gain", "", {}, (fx.log_free("gain", "1", 0.1, 10.0, (0.5, 1.0, 2.0)),))],
        doc=fx.DocRow("-", "`gain`", "test double"), order=99)
    monkeypatch.setitem(EFFECTS, "toy_gain", toy)
    modes, sensors, _ = synthetic_modes(GUIDE, [make_effect("contact_stiffness", {"factor": 0.8})], seed=2)
    result = explain_modes(modes, GUIDE, sensors, candidates=["toy_gain", "added_mass"])
    assert result.verdict == "explained" and result.effects[0]["name"] == "toy_gain"
    assert result.effects[0]["parameters"]["gain"]["value"] == pytest.approx(0.8, rel=0.01)


def test_amplitude_dependence_accepts_only_a_predicted_trend():
    from guidefit.model.effects.amplitude_dependence import accept

    levels = fx.LevelData(frequency_hz=np.array([3529.0, 3528.0, 3526.0]), sigma_hz=np.full(3, 0.4),
                          force_n=np.array([100.0, 300.0, 600.0]), weight=np.ones(3), hit_forces_n=((100.0,),) * 3,
                          label=("vertical",) * 3, run=("vertical",) * 3, hit=(None,) * 3, band=(None,) * 3,
                          groups=(np.arange(3),))
    assert accept(levels, np.array([3529.0, 3528.1, 3525.9])) is None
    reason = accept(levels, np.array([3529.0, 3529.0, 3528.9]))
    assert reason and "no trend" in reason


def test_forward_request_docstring_names_every_field():
    """The plug-in contract of a forward model (the nonlinear helper implements one) is documented field by field."""
    doc = fx.ForwardRequest.__doc__
    for name in fx.ForwardRequest.__dataclass_fields__:
        assert f"``{name}``" in doc, name


def test_an_effect_gathers_its_own_data_from_the_identification(monkeypatch):
    """``prepare``: explain_identification asks every candidate effect for the data it needs."""
    from dataclasses import replace as dc_replace

    from guidefit.errors import IdentificationError
    from guidefit.explain import explain_identification, synthetic_modes

    modes, _, _ = synthetic_modes(GUIDE, [make_effect("contact_stiffness", {"factor": 0.9})], seed=4)

    class FakeIdentification:  # the parts of guidefit.identify.Identification that explain reads
        file = "fake.h5"
        guide = GUIDE
        parameters, extra_modes, runs = {}, (), ()

        def __init__(self):
            self.modes = [SimpleNamespace(label=m.label, run=None, frequency_hz=m.frequency_hz, damping_ratio=None,
                                          frequency_std_hz=m.frequency_std_hz, shape=None) for m in modes]

    seen = []

    def drop_roll_high(identification, got_modes, levels, notes):
        seen.append(identification.file)
        notes.append("toy: roll_high left to another test")
        return [m for m in got_modes if m.label != "roll_high"], levels

    def fails(identification, got_modes, levels, notes):
        raise IdentificationError("no runs that differ only in hit force")

    monkeypatch.setitem(EFFECTS, "contact_stiffness", dc_replace(EFFECTS["contact_stiffness"], prepare=drop_roll_high))
    monkeypatch.setitem(EFFECTS, "added_mass", dc_replace(EFFECTS["added_mass"], prepare=fails))
    result = explain_identification(FakeIdentification(), candidates=["contact_stiffness", "added_mass"])
    assert seen == ["fake.h5"]
    assert "roll_high" not in {m["label"] for m in result.modes} and len(result.modes) == 4
    assert "toy: roll_high left to another test" in result.notes
    assert any(n.startswith("added_mass: its data could not be gathered") for n in result.notes)
    assert result.verdict == "explained" and result.effects[0]["name"] == "contact_stiffness"
