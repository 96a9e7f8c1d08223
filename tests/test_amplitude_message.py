"""identify on a carriage whose modes move with the hit force (simulate's amplitude_dependence, a low
preload, hits from 300 to 900 N): one linear model does not fit, and the reason given is the amplitude
dependence with the hits' forces and the frequency shift, never a reversed hammer (the driving-point
residues, read from the sensors' rigid fit, are positive)."""

from __future__ import annotations

import warnings
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from guidefit.identify import IdentifySettings, identify
from guidefit.io import write_recording


@pytest.fixture(scope="module")
def soft_preload(tmp_path_factory):
    from guidefit.model.effects import parse_effect
    from guidefit.simulate import SimulationConfig, simulate

    config = replace(SimulationConfig(), force_n=(300.0, 900.0))
    data, _ = simulate("MRB35", [parse_effect("amplitude_dependence:preload_factor=0.5")], config=config, seed=0)
    path = tmp_path_factory.mktemp("amplitude") / "soft_preload.h5"
    write_recording(path, data)
    return path, data


def test_amplitude_dependent_carriage_is_not_called_a_reversed_hammer(soft_preload):
    path, _ = soft_preload
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = identify(path, settings=IdentifySettings(jackknife=False))
    said = [*result.warnings, result.gate or ""]
    assert not any("is reversed" in line for line in said), said  # the hammer and sensors are signed right
    assert result.gate is not None and "amplitude dependence" in result.gate, result.gate
    assert "guidefit explain" in result.gate and "force levels" in result.gate
    line = next(w for w in result.warnings if "amplitude dependence" in w)
    # the hits' peak forces and the frequency shift are named
    low, high = (float(x) for x in line.split("range from ")[1].split(" N")[0].split(" to "))
    assert 250 < low < 450 and 750 < high < 950, line
    assert "moves from" in line and " %)" in line


def test_driving_point_signs_tell_a_reversed_hammer(soft_preload):
    """The driving-point residues g . S^+ c of the modes are positive for the test as recorded and
    negative with its hammer reversed (every modal constant of the run flips)."""
    from guidefit.modal_stage import driving_point_signs
    from guidefit.modes.labels import RunView

    _, data = soft_preload
    run = data.runs[0]
    names = [n for n in run.channel_names if n != "force"]
    chans = [SimpleNamespace(position_m=run.positions_m[k], direction=run.directions[k])
             for k in map(run.channel_names.index, names)]
    view = RunView(chans, run.excitation_direction, run.excitation_position_m)
    q = np.array([0.0, 1.0, 0.3, 0.0, 0.0])  # a vertical-pitch motion, mass-normalised or not
    constants = view.sensors @ q * float(view.drive @ q)
    assert driving_point_signs([{"constants": {run.name: constants}}], {run.name: view}) == {run.name: 1}
    assert driving_point_signs([{"constants": {run.name: -constants}}], {run.name: view}) == {run.name: -1}
