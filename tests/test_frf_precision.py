"""FFT precision: float32 FFTs of a float32 recording against float64 FFTs of the same file.

Why single precision loses nothing the data has. A float32 sample is rounded to
at most 2**-24 = 6e-8 of itself; a float32 FFT of n samples adds, per bin, an
error of about sqrt(log2 n) 2**-24 ||x||_2 (measured 1.3e-7 ||x||_2 rms per bin
at n = 10 000; rounding the windowed samples to float32 adds 5-10x less). The
simulated chain's sensor noise (1e-4 of the range: 0.2 N on the force, 0.1 m/s^2
on the accelerations) puts about 2 N per bin into the force-windowed force
spectrum, against 2e-4 N of float32 error: 1e-4 of the noise. The FRF
differences below are that, seen through H's random error (Bendat and Piersol's
``FrfSet.H_std`` from the coherence of 4 hits, itself a noisy estimate, hence
the tail of the ratio).

Measured with ``IdentifySettings(fft_precision=...)`` on ``guidefit simulate``
recordings (MRB35, 4 hits per run, 0.05 s records at 200 kHz, seeds 1-8;
guidefit 6eefdaf and 0e04ea4, the larger of the two), single against double
precision (16 hits of 0.1 s, seeds 11-12: the same or smaller):

- ``|H_single - H_double| / H_std`` over bins with coherence > 0.5
  (about 41 000 of the 80 000 bins x channels of a recording): median 3e-5,
  99th percentile 2.4e-4, maximum 6.9e-4 ... 1.6e-3;
- ``max |dH| / max |H|``: 3.8e-5 ... 1.1e-4, at bins where S_ff is 1e-7 of its
  peak (zeros of the half-sine spectrum, above the anti-alias band), so that
  float32's error relative to |F| is some 3000x larger than at the peak; in
  the band of the modes (< 20 kHz) the median of |dH|/|H| is 2e-7 ... 4e-7
  (seed 5);
- coherence: |gamma^2_single - gamma^2_double| <= 2.0e-4;
- identified parameters, relative: f_V, f_H, K_V, K_H <= 3.9e-9;
  zeta_V, zeta_H, c_V, c_H <= 1.9e-8; every difference <= 1.3e-4 of the
  parameter's own std.

The bounds asserted here are the worst of those seeds with a margin of 5x
to 10x; the test uses one seed (1).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from guidefit.frf import PRECISIONS, fft_dtype, frf_from_records
from guidefit.identify import IdentifySettings, frf_of_recording, identify
from guidefit.io import RecordingData, write_recording
from guidefit.simulate import SimulationConfig, simulate

CONFIG = replace(SimulationConfig(), hits=4, record_s=0.05)
PARAMETERS = ("f_V", "f_H", "zeta_V", "zeta_H", "K_V", "K_H", "c_V", "c_H")
#: measured <= 1.6e-3 (seeds 1-8): float32 changes H by well under 1 % of its own random error
MAX_DH_PER_STD = 1e-2
#: measured 2.7e-5 ... 3.2e-5 (seeds 1-8)
MEDIAN_DH_PER_STD = 3e-4
#: measured <= 1.1e-4 (seeds 1-8), at bins where the force spectrum is 70 dB below its peak
MAX_DH_PER_MAX_H = 1e-3
#: measured <= 1.9e-8 (zeta, c) and <= 3.9e-9 (f, K), seeds 1-8
PARAMETER_RTOL = 1e-7
#: measured <= 1.3e-4 of the parameter's std, seeds 1-8
PARAMETER_PER_STD = 1e-3


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """The same simulated recording stored as float32 (as simulated) and as float64."""
    folder = tmp_path_factory.mktemp("precision")
    recording, _truth = simulate("MRB35", config=CONFIG, seed=1)
    assert {run.data.dtype for run in recording.runs} == {np.dtype(np.float32)}
    wide = RecordingData(tuple(replace(run, data=np.asarray(run.data, dtype=np.float64)) for run in recording.runs),
                         recording.guide, recording.description)
    write_recording(folder / "f32.h5", recording)
    write_recording(folder / "f64.h5", wide)
    return folder / "f32.h5", folder / "f64.h5"


@pytest.fixture(scope="module")
def identified(files):
    """identify() of the float32 file with single and with double precision FFTs."""
    f32, _ = files
    return {p: identify(f32, settings=IdentifySettings(fft_precision=p, jackknife=False))
            for p in ("single", "double")}


# ------------------------------------------------------------------ fft_dtype


@pytest.mark.parametrize("dtype, expected", [
    (np.float32, np.float32),
    (np.float16, np.float32),
    (np.int16, np.float32),
    (np.uint16, np.float32),
    (np.int8, np.float32),
    (np.uint8, np.float32),
    (np.int32, np.float64),
    (np.uint32, np.float64),
    (np.int64, np.float64),
    (np.float64, np.float64),
])
def test_auto_follows_the_significand_of_the_stored_samples(dtype, expected):
    # float32 has a 24-bit significand: float16 and integers of <= 16 bits fit, int32 and float64 do not
    assert fft_dtype("auto", dtype) is expected
    assert fft_dtype("auto", np.dtype(dtype)) is expected


@pytest.mark.parametrize("dtype", [np.float16, np.float32, np.int16, np.int32, np.float64])
def test_single_and_double_are_forced_whatever_the_samples(dtype):
    assert fft_dtype("single", dtype) is np.float32
    assert fft_dtype("double", dtype) is np.float64


def test_default_is_auto_and_precisions_are_the_three_names():
    assert PRECISIONS == ("auto", "single", "double")
    assert fft_dtype() is np.float64  # auto, float64 samples
    assert IdentifySettings().fft_precision == "auto"


@pytest.mark.parametrize("name", ["quad", "Single", "float32", "", None])
def test_unknown_precision_is_a_value_error_naming_it(name):
    with pytest.raises(ValueError, match="precision must be one of auto, single, double") as info:
        fft_dtype(name, np.float32)
    assert repr(name) in str(info.value)


def test_frf_from_records_checks_the_precision():
    records = np.zeros((2, 64, 2))
    records[:, 3, 0] = 1.0
    records[:, 5, 1] = 1.0
    with pytest.raises(ValueError, match="'quad'"):
        frf_from_records(records, 1000.0, precision="quad")


# ------------------------------------------------------------------ auto on files


def test_auto_gives_single_on_float32_and_double_on_float64_files(files, identified):
    f32, f64 = files
    narrow, _ = frf_of_recording(f32)
    wide, _ = frf_of_recording(f64)
    assert [frf.fft_precision for frf in narrow] == ["single", "single"]
    assert [frf.fft_precision for frf in wide] == ["double", "double"]
    # the same samples, so auto is exactly the forced choice: bit for bit (identify's FRFs end at
    # 3x its band's top: the same sums, bin for bin, of the bins they keep)
    for frf, run in zip(narrow, identified["single"].runs):
        assert np.array_equal(frf.H[:run.frf.H.shape[0]], run.frf.H)
    for frf, run in zip(wide, identified["double"].runs):
        assert np.array_equal(frf.H[:run.frf.H.shape[0]], run.frf.H)


# ------------------------------------------------------------------ single against double


def test_single_precision_frf_differs_far_below_its_random_error(identified):
    ratios, worst_rel = [], 0.0
    for single, double in zip(identified["single"].runs, identified["double"].runs):
        s, d = single.frf, double.frf
        assert (s.fft_precision, d.fft_precision) == ("single", "double")
        assert s.H.dtype == d.H.dtype == np.complex128  # everything after the FFT is float64
        assert s.n_averages == d.n_averages == CONFIG.hits
        dH = np.abs(s.H - d.H)
        assert np.any(dH > 0)  # the two really computed differently
        ok = d.coherence > 0.5
        assert ok.sum() > 0.3 * ok.size  # about half the bins: the modes' band and more
        ratios.append(dH[ok] / d.H_std[ok])
        worst_rel = max(worst_rel, float(dH.max() / np.abs(d.H).max()))
        np.testing.assert_allclose(s.coherence, d.coherence, rtol=0, atol=1e-3)  # measured <= 2.0e-4
    ratio = np.concatenate(ratios)
    assert np.all(np.isfinite(ratio))
    assert np.median(ratio) < MEDIAN_DH_PER_STD
    assert ratio.max() < MAX_DH_PER_STD
    assert worst_rel < MAX_DH_PER_MAX_H


def test_single_precision_identifies_the_same_parameters(identified):
    single, double = identified["single"].parameters, identified["double"].parameters
    for name in PARAMETERS:
        s, d = single[name], double[name]
        assert s["value"] is not None and d["value"] is not None, name
        assert s["value"] == pytest.approx(d["value"], rel=PARAMETER_RTOL, abs=0), name
        assert abs(s["value"] - d["value"]) < PARAMETER_PER_STD * d["std"], name
