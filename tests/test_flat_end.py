"""flat_end: a hit whose responses end held exactly constant while they still rang.

A DAQ that stopped (its last value held) or a padded export (zeros) cut the
response; fitted as if it had died out, the damping comes out wrong with exit 0
(the bundled sample, zeroed after each record's sample 600: zeta_V +52 %).
A quantised response that decayed below one LSB is constant too, legitimately.
"""

from __future__ import annotations

import dataclasses
import json
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from guidefit.hits import REJECTION_CODES, iter_hits
from guidefit.io import read_recording, write_recording
from guidefit.simulate import SimulationConfig, simulate

SAMPLE = Path(__file__).resolve().parents[1] / "sample_data" / "mrb35_sample.h5"


def _cut_sample(tmp_path, cut, held=None):
    """The sample with every response from record sample ``cut`` on set to zero, or
    (``held``) to the value it had there."""
    path = tmp_path / "cut.h5"
    shutil.copy(SAMPLE, path)
    with h5py.File(path, "r+") as f:
        for name in f["runs"]:
            ds = f["runs"][name]["hits"]
            data = ds[...]
            data[:, cut:, :] = data[:, cut - 1 : cut, :] if held else 0.0
            ds[...] = data
    return path


def test_code_is_documented():
    assert "flat_end" in REJECTION_CODES


@pytest.mark.parametrize("cut, held", [(600, False), (800, True), (2500, False)])
def test_cut_records_of_the_sample_are_rejected_with_the_reason(tmp_path, cut, held):
    """Cut at sample 600 (2 ms after the trigger at 200), 800 (3 ms; the held last
    value of a DAQ that stopped) and 2500 (11.5 ms: still ringing above its noise)."""
    for run in read_recording(_cut_sample(tmp_path, cut, held)).runs:
        for hit in iter_hits(run):
            assert not hit.accepted and "flat_end" in hit.codes, hit.reason
            assert f"from sample {cut - 1 if held else cut})" in hit.reason and " held at " in hit.reason


def test_a_cut_in_the_noise_is_harmless_and_accepted(tmp_path):
    """Cut at sample 6000 of 10 000 the responses had decayed into their noise (RMS
    within 3 x the pre-trigger noise): nothing was lost (identify's results move by
    less than 0.01 %, benchmarks/README.md), so the hits stay."""
    for run in read_recording(_cut_sample(tmp_path, 6000)).runs:
        assert all(hit.accepted for hit in iter_hits(run))


def test_cli_reports_the_rejection_and_gives_no_number(tmp_path):
    path = _cut_sample(tmp_path, 600)
    done = subprocess.run([sys.executable, "-m", "guidefit", "identify", str(path), "--json"],
                          capture_output=True, text=True, check=False, timeout=300)
    assert done.returncode == 1, done.stderr
    result = json.loads(done.stdout)
    assert result["parameters"]["zeta_V"]["value"] is None
    assert "flat_end" in json.dumps(result)


def test_quiet_quantised_tails_are_accepted(tmp_path):
    """Noise-free ADC data (12 and 16 bits, low and high level, light and heavy
    damping, short and long records): most responses end constant once they decay
    below one LSB, and none of those is a flat_end."""
    constant_ends = 0
    for bits, force, damping, record_s in [(16, (200.0, 500.0), None, 0.1), (12, (2.0, 10.0), 0.08, 0.03),
                                           (16, (2.0, 10.0), 0.003, 0.03)]:
        config = SimulationConfig(hits=2, noise_fraction=0.0, adc_bits=bits, force_n=force, record_s=record_s,
                                  damping={} if damping is None else dict.fromkeys(
                                      ("vertical", "pitch", "yaw", "roll_low", "roll_high"), damping))
        recording, _ = simulate("MRB35", config=config, seed=3)
        for run in recording.runs:
            constant_ends += int(np.sum(np.ptp(run.data[:, -100:, 1:], axis=1) == 0))
        path = tmp_path / f"quiet{bits}.h5"
        write_recording(path, recording)
        for run in read_recording(path).runs:
            for hit in iter_hits(run):
                assert "flat_end" not in hit.codes, hit.reason
    assert constant_ends > 20  # the case is really there


def test_continuous_record_of_a_daq_that_stopped(tmp_path):
    """signals layout: the DAQ stops 4 ms after the last hit and holds its last sample."""
    config = SimulationConfig(hits=3, layout="signals", gap_s=0.02, record_s=0.05, runs=(SimulationConfig().runs[0],))
    recording, _ = simulate("MRB35", config=config, seed=4)
    path = tmp_path / "signals.h5"
    write_recording(path, recording)
    (run,) = read_recording(path).runs
    good = list(iter_hits(run))
    assert all(h.accepted for h in good) and len(good) == 3
    data = recording.runs[0].data.copy()
    stop = good[-1].start_sample + (good[-1].pretrigger_samples or 0) + int(0.004 * run.sample_rate_hz)
    data[stop:] = data[stop - 1]
    write_recording(path, dataclasses.replace(recording.runs[0], data=data))
    hits = list(iter_hits(read_recording(path).runs[0]))
    assert [h.accepted for h in hits] == [True, True, False]
    assert "flat_end" in hits[-1].codes
