"""Runs recorded with another record length or sample rate join the global fit on one frequency grid.

The vertical run of a one-axis-per-run MRB35 recording (default layout) and its
lateral run are simulated with their own record length or sample rate (both
allowed by the recording contract: ``sample_rate_hz`` is a run attribute, each
run holds its own hits). Before, the run on the other grid was left out of the
global fit ("its FRFs are on another frequency grid; left out of the global
fit") and its modes came from the other run only, or were lost.
"""

import json
import warnings
from dataclasses import replace
from types import SimpleNamespace as NS

import numpy as np
import pytest
from click.testing import CliRunner

from guidefit.cli import main
from guidefit.frf import WindowSettings, common_grid, compute_frf, first_bins
from guidefit.simulate import DEFAULT_RUNS, SimulationConfig, simulate

VERTICAL = dict(record_s=0.05, sample_rate_hz=200_000.0)


def _mixed(folder, lateral: dict, seed: int = 1):
    """A two-run recording: vertical run with :data:`VERTICAL`, lateral run with ``lateral``; and its truth."""
    from guidefit.io import write_recording

    base = SimulationConfig(hits=4, sensor_layout="default")
    vertical, truth = simulate("MRB35", config=replace(base, runs=DEFAULT_RUNS[:1], **VERTICAL), seed=seed)
    side, _ = simulate("MRB35", config=replace(base, runs=DEFAULT_RUNS[1:], **lateral), seed=seed)
    assert [r.name for r in (*vertical.runs, *side.runs)] == ["vertical", "lateral"]
    path = folder / "mixed.h5"
    write_recording(path, replace(vertical, runs=(*vertical.runs, *side.runs)))
    return path, truth["parameters"]


@pytest.mark.parametrize("lateral", [
    dict(record_s=0.1, sample_rate_hz=200_000.0),  # longer records: the vertical run is zero-padded
    dict(record_s=0.025, sample_rate_hz=200_000.0),  # shorter records: the lateral run is zero-padded
    dict(record_s=0.1, sample_rate_hz=100_000.0),  # another rate and length: 10 Hz bins, padded to them
    dict(record_s=0.05, sample_rate_hz=25_600.0),  # another rate: the FRFs end at its Nyquist frequency
], ids=["longer", "shorter", "rate_and_length", "low_rate"])
def test_runs_on_other_grids_join_the_global_fit(tmp_path, lateral):
    path, truth = _mixed(tmp_path, lateral)
    result = CliRunner().invoke(main, ["identify", str(path), "--json"])
    assert result.exit_code == 0, result.output
    out = json.loads(result.output.splitlines()[0])
    assert not [w for w in out["warnings"] if "left out" in w or "another frequency grid" in w], out["warnings"]
    p = out["parameters"]
    for name, tol in (("f_V", 1e-3), ("f_H", 1e-3), ("K_V", 2e-3), ("K_H", 2e-3)):
        value, std, true = p[name]["value"], p[name]["std"], truth[name]["value"]
        assert value == pytest.approx(true, rel=tol), name
        assert abs(value - true) <= 3 * std, (name, value, true, std)


def test_explain_and_report_work_on_a_file_with_two_record_lengths(tmp_path):
    path, _ = _mixed(tmp_path, dict(record_s=0.1, sample_rate_hz=200_000.0))
    explained = CliRunner().invoke(main, ["explain", str(path), "--json", "--candidates", "added_mass"])
    assert explained.exit_code == 0, explained.output
    assert "another frequency grid" not in explained.output
    html = tmp_path / "report.html"
    reported = CliRunner().invoke(main, ["report", str(path), "-o", str(html), "--candidates", "added_mass"])
    assert reported.exit_code == 0, reported.output
    assert html.stat().st_size > 0 and "another frequency grid" not in html.read_text()


def _decaying_hits(n_samples: int, fs: float, n_hits: int = 3):
    """Hits of a 1-DOF system (500 Hz, 1 %: at the record's end still 5 % of its peak, so the automatic
    exponential window is on)."""
    rng = np.random.default_rng(7)
    t = np.arange(n_samples) / fs
    hits = []
    for k in range(n_hits):
        force = np.zeros(n_samples)
        force[10:13] = rng.uniform(50, 80) * np.array([0.3, 1.0, 0.6])
        w = 2 * np.pi * 500.0
        impulse = np.exp(-0.01 * w * t) * np.sin(w * t)
        response = np.convolve(force, impulse)[:n_samples] + 1e-3 * rng.normal(size=n_samples)
        hits.append(NS(index=k, accepted=True, data=np.stack([force, response], axis=1), reason=None))
    return hits


def test_zero_padding_samples_the_same_spectrum_on_a_finer_grid():
    fs, n = 8000.0, 800
    run = NS(name="r", sample_rate_hz=fs, force_index=0, pretrigger_samples=8,
             channels=(NS(name="force"), NS(name="acc_A_y")))
    hits = _decaying_hits(n, fs)
    own = compute_frf(run, hits, window=WindowSettings(), workers=1)
    padded = compute_frf(run, hits, window=WindowSettings(), workers=1, n_fft=2 * n)
    assert own.n_fft is None and padded.n_fft == 2 * n and padded.record_samples == n
    assert padded.resolution_hz == pytest.approx(own.resolution_hz)  # finer bins, not a finer resolution
    assert padded.frequency_hz[1] == pytest.approx(own.frequency_hz[1] / 2)
    # every second bin of the padded FFT is a bin of the record's own FFT: the same spectrum, the same FRF
    np.testing.assert_allclose(padded.H[::2], own.H, rtol=1e-9, atol=1e-12 * np.abs(own.H).max())
    # the windows are those of the record (chosen from it), not of the padded length; so is the shift of the
    # poles by the exponential window, 1 / tau, that the modal fit takes out
    assert own.exp_window_tau_s is not None
    assert padded.exp_window_tau_s == own.exp_window_tau_s
    assert padded.force_window_s == own.force_window_s


def test_zero_padding_never_shortens_a_record():
    fs, n = 8000.0, 800
    run = NS(name="r", sample_rate_hz=fs, force_index=0, pretrigger_samples=8,
             channels=(NS(name="force"), NS(name="acc_A_y")))
    with pytest.raises(ValueError, match="shorter than the records"):
        compute_frf(run, _decaying_hits(n, fs), workers=1, n_fft=n - 2)


def test_common_grid_pads_to_the_longest_duration_and_ends_at_the_lowest_nyquist():
    def frf(fs, seconds, top=None):
        n = int(round(fs * seconds))
        f = np.fft.rfftfreq(n, 1 / fs)
        return NS(sample_rate_hz=fs, frequency_hz=f if top is None else f[f <= top])

    # 0.1 s at 200 kHz and 0.05 s at 51.2 kHz, asked to 21.7 kHz: 10 Hz bins, the second run ends at 25.6 kHz
    assert common_grid([frf(200e3, 0.1, 21.7e3), frf(51.2e3, 0.05, 21.7e3)], 21.7e3) == [(20000, 2171), (5120, 2171)]
    # asked above the lower rate's Nyquist frequency: both end there
    assert common_grid([frf(200e3, 0.1), frf(25.6e3, 0.1)]) == [(20000, 1281), (2560, 1281)]
    # a duration that is no whole number of samples at both rates: the next one that is (1/1600 s steps)
    assert common_grid([frf(200e3, 0.1004), frf(51.2e3, 0.1)]) == [(20125, 2577), (5152, 2577)]
    assert common_grid([frf(200e3, 0.1), frf(200e3, 0.1)]) is None  # one grid already: nothing to do
    assert common_grid([frf(200e3, 0.1), frf(199_999.5, 0.05)]) is None  # no common grid by padding


def test_first_bins_cuts_every_array_of_an_frfset():
    fs, n = 8000.0, 800
    run = NS(name="r", sample_rate_hz=fs, force_index=0, pretrigger_samples=8,
             channels=(NS(name="force"), NS(name="acc_A_y")))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        frf = compute_frf(run, _decaying_hits(n, fs), workers=1)
    cut = first_bins(frf, 100)
    assert cut.frequency_hz.size == cut.H.shape[0] == cut.coherence.shape[0] == 100
    assert cut.group_sums["Sff"].shape[1] == cut.group_sums["Sfx"].shape[1] == 100
    np.testing.assert_array_equal(cut.H, frf.H[:100])


def test_frf_h5_keeps_the_record_length_of_zero_padded_frfs(tmp_path):
    from guidefit.frf import read_frf_h5, write_frf_h5

    fs, n = 8000.0, 800
    run = NS(name="r", sample_rate_hz=fs, force_index=0, pretrigger_samples=8,
             channels=(NS(name="force"), NS(name="acc_A_y")))
    padded = compute_frf(run, _decaying_hits(n, fs), workers=1, n_fft=4 * n)
    write_frf_h5(tmp_path / "frf.h5", [padded])
    back, = read_frf_h5(tmp_path / "frf.h5")
    assert (back.record_samples, back.n_fft) == (n, 4 * n)
    assert back.resolution_hz == pytest.approx(fs / n)


def test_frfs_read_from_a_file_on_two_grids_still_leave_a_run_out_and_say_why(tmp_path):
    """No hits to transform again: the run on the other grid is left out, with the reason."""
    from guidefit.frf import write_frf_h5
    from guidefit.hits import HitSettings, iter_hits
    from guidefit.io import read_recording

    path, _ = _mixed(tmp_path, dict(record_s=0.1, sample_rate_hz=200_000.0))
    frfs = [compute_frf(r, iter_hits(r, HitSettings()), max_frequency_hz=21_700.0)
            for r in read_recording(path).runs]
    write_frf_h5(tmp_path / "frf.h5", frfs)
    result = CliRunner().invoke(main, ["identify", str(tmp_path / "frf.h5"), "--json"])
    out = json.loads(next(line for line in result.output.splitlines() if line.startswith("{")))
    grid = [w for w in out["warnings"] if "another frequency grid" in w]
    assert len(grid) == 1 and "FRFs read from a file" in grid[0] and "left out of the global fit" in grid[0]
