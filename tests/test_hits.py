"""Tests of guidefit.hits: hit detection and per-hit quality checks.

Every signal is synthetic and built here: half-sine force pulses at 200 kHz,
decaying sinusoid responses, a 16-bit ADC (force range +/-2048 N, acceleration
range +/-1024 m/s^2). The expected outcome of each case follows from how the
signal was built (which hit got a second pulse, which one was clipped).
"""

from pathlib import Path

import numpy as np
import pytest

import guidefit.hit_checks as hit_checks
import guidefit.hits as hits_module
from guidefit.hits import (
    REJECTION_CODES,
    HitSettings,
    HitSettingsError,
    check_hit,
    iter_hits,
    summarise_hits,
)
from guidefit.io import (
    RunData,
    RunReader,
    read_block,
    read_hit,
    read_recording,
    write_recording,
)

FS = 200_000.0
FORCE_RANGE = 2048.0
ACC_RANGE = 1024.0
NAMES = ["force", "acc_A_y", "acc_B_y"]
REAL_DATA = Path(__file__).resolve().parents[2] / "shared" / "real-data" / "pyfrf-impact"


def half_sine(n, start, peak, width_s=1e-4):
    """Half-sine force pulse of ``width_s`` starting at sample ``start``."""
    t = (np.arange(n) - start) / FS
    return np.where(
        (t >= 0) & (t <= width_s), peak * np.sin(np.pi * np.clip(t, 0, width_s) / width_s), 0.0
    )


def ringing(n, start, amplitude, f_hz=3450.0, zeta=0.03):
    """Decaying sinusoid starting at sample ``start``."""
    t = (np.arange(n) - start) / FS
    w = 2 * np.pi * f_hz
    return np.where(
        t >= 0, amplitude * np.exp(-zeta * w * t) * np.sin(w * np.sqrt(1 - zeta**2) * t), 0.0
    )


def adc(x, full_scale, bits=16):
    """Quantise to a ``bits`` ADC of +/-``full_scale``, clipping at the rails."""
    lsb = full_scale / 2 ** (bits - 1)
    return np.clip(np.round(x / lsb), -(2 ** (bits - 1)), 2 ** (bits - 1) - 1) * lsb


def record(
    n=10_000,
    start=200,
    peak=300.0,
    width_s=1e-4,
    acc=(40.0, 25.0),
    f_hz=3450.0,
    zeta=0.03,
    seed=0,
    noise_lsb=0.5,
    quantise=True,
):
    """One hit record (n, 3): force, acc_A_y, acc_B_y."""
    rng = np.random.default_rng(seed)
    force = half_sine(n, start, peak, width_s)
    cols = [force] + [ringing(n, start, a, f_hz, zeta) for a in acc]
    out = []
    for col, full_scale in zip(cols, (FORCE_RANGE, ACC_RANGE, ACC_RANGE)):
        lsb = full_scale / 2**15
        col = col + noise_lsb * lsb * rng.standard_normal(n)
        out.append(adc(col, full_scale) if quantise else col)
    return np.column_stack(out)


def hits_run(tmp_path, records, pretrigger=200, name="rec.h5", direction=(0.0, -1.0, 0.0)):
    data = np.stack(records)
    run = RunData(
        "vertical",
        FS,
        direction,
        NAMES,
        ["N", "m/s^2", "m/s^2"],
        [[0, 0, 0], [0.03, 0, 0.045], [-0.03, 0, 0.045]],
        [[0, -1, 0], [0, 1, 0], [0, 1, 0]],
        data=data,
        pretrigger_samples=pretrigger,
    )
    write_recording(tmp_path / name, run)
    return read_recording(tmp_path / name).runs[0]


def signals_run(tmp_path, signal, name="sig.h5"):
    run = RunData(
        "vertical",
        FS,
        [0.0, -1.0, 0.0],
        NAMES,
        ["N", "m/s^2", "m/s^2"],
        [[0, 0, 0], [0.03, 0, 0.045], [-0.03, 0, 0.045]],
        [[0, -1, 0], [0, 1, 0], [0, 1, 0]],
        data=signal,
    )
    write_recording(tmp_path / name, run)
    return read_recording(tmp_path / name).runs[0]


def longest_flat_top(x):
    """Longest run of samples equal to max(x) (to check a fixture means what it says)."""
    at = np.flatnonzero(x == x.max())
    runs = np.split(at, np.flatnonzero(np.diff(at) > 1) + 1)
    return max(len(r) for r in runs)


def only(run, settings=None):
    (hit,) = list(iter_hits(run, settings))
    return hit


# ----------------------------------------------------------------- stored hits


def test_clean_quantised_hits_are_accepted(tmp_path):
    run = hits_run(tmp_path, [record(peak=p, seed=k) for k, p in enumerate((250.0, 300.0, 350.0))])
    got = list(iter_hits(run))
    assert [h.index for h in got] == [0, 1, 2]
    assert all(h.accepted and h.reason is None and h.codes == () for h in got), [
        h.reason for h in got
    ]
    for hit, peak in zip(got, (250.0, 300.0, 350.0)):
        assert hit.peak_force_n == pytest.approx(peak, abs=0.2)
        assert hit.data.shape == (10_000, 3) and hit.data.dtype == np.float64
        assert not hit.data.flags.writeable
        assert hit.pretrigger_samples == 200 and hit.start_sample == 0
        assert hit.metrics["pulse_width_s"] == pytest.approx(1e-4, abs=1e-5)
        assert hit.metrics["second_impact_ratio"] == 0.0
        assert hit.metrics["end_ratio"] < 0.01


@pytest.mark.parametrize(
    ("ratio", "gap_s", "double"),
    [
        (0.15, 0.5e-3, True),  # 15 % of the peak, 0.5 ms after the first pulse ends
        (0.12, 0.1e-3, True),  # soon after
        (0.40, 20e-3, True),  # late in the record
        (0.08, 0.5e-3, False),  # below the 10 % limit
    ],
)
def test_double_hit_after_the_pulse(tmp_path, ratio, gap_s, double):
    first = record(peak=300.0)
    second_start = 200 + 20 + round(gap_s * FS)  # the first pulse lasts 20 samples
    first[:, 0] += adc(half_sine(10_000, second_start, ratio * 300.0), FORCE_RANGE)
    hit = only(hits_run(tmp_path, [first]))
    assert hit.accepted is not double
    if double:
        assert hit.codes == ("double_hit",) and hit.data is None
        assert hit.reason.startswith(f"double_hit: second impact of {ratio:.0%} of the peak")
        assert "after it" in hit.reason
        assert hit.metrics["second_impact_ratio"] == pytest.approx(ratio, abs=0.01)
    else:
        assert hit.metrics["second_impact_ratio"] == 0.0


def test_double_hit_with_the_larger_impact_second(tmp_path):
    rec = record(peak=60.0)
    rec[:, 0] += adc(half_sine(10_000, 400, 300.0), FORCE_RANGE)
    hit = only(hits_run(tmp_path, [rec]))
    assert hit.codes == ("double_hit",)
    assert "20% of the peak" in hit.reason and "before it" in hit.reason


def test_double_hit_merged_into_one_pulse(tmp_path):
    rec = record(peak=300.0)
    # starts 2 samples before the first ends: the force never falls below 5 %
    rec[:, 0] += adc(half_sine(10_000, 218, 150.0), FORCE_RANGE)
    hit = only(hits_run(tmp_path, [rec]))
    assert hit.codes == ("double_hit",)
    assert "two peaks within one pulse" in hit.reason


def test_smooth_quantised_peaks_with_repeated_top_codes_are_not_clipping(tmp_path):
    # A soft-tip pulse (1 ms) and slow, small responses: their 16-bit tops repeat
    # the same code several times, which is not an overload.
    rec = record(peak=40.0, width_s=1e-3, acc=(5.0, 2.0), f_hz=1075.0, zeta=0.02, noise_lsb=0.0)
    for column in range(3):
        assert longest_flat_top(rec[:, column]) >= 3, column  # the fixture has flat tops
    hit = only(hits_run(tmp_path, [rec]))
    assert hit.accepted, hit.reason


def test_smooth_peaks_with_noise_across_many_seeds_are_not_clipping(tmp_path):
    records = [
        record(peak=p, width_s=w, acc=(a, a / 3), f_hz=f, zeta=0.03, noise_lsb=nl, seed=seed)
        for seed, (p, w, a, f, nl) in enumerate(
            [
                (40, 1e-3, 5, 1075, 1.0),
                (80, 5e-4, 2, 1075, 2.0),
                (20, 2e-3, 1, 900, 0.5),
                (1500, 1e-4, 800, 3450, 1.0),
            ]
        )
    ]
    got = list(iter_hits(hits_run(tmp_path, records), HitSettings(min_peak_fraction=0.0)))
    assert [h.reason for h in got] == [None] * 4


def test_clipping_criterion_on_many_simulated_oscillations():
    """No unclipped quantised oscillation is flagged; clipped ones (5 %+ over) are.

    Decaying cosines of 3-20 000 samples per period and 3-30 000 LSB, with
    0-5 LSB of noise, through a 12- or 16-bit ADC (the study behind the limit,
    at a tenth of its size).
    """
    rng = np.random.default_rng(11)
    false_alarms = missed = clipped_total = 0
    t0 = np.arange(2000.0)
    for _ in range(1500):
        w = 2 * np.pi / 10 ** rng.uniform(0.5, 4.3)
        noise = rng.choice([0.0, rng.uniform(0, 5)]) * rng.standard_normal(t0.size)
        t = t0 - rng.uniform(0, 2000)
        envelope = np.cos(w * t) * np.exp(-np.abs(t) / rng.uniform(50, 5000))
        smooth = 10 ** rng.uniform(0.5, 4.5) * envelope + noise
        if np.abs(smooth).max() < 32767:
            false_alarms += hit_checks._flat_top(np.round(smooth) * 0.0625, 3) is not None
        rail = rng.choice([32767, 2047])
        x = rail * (1 + 10 ** rng.uniform(np.log10(0.05), 0.7)) * envelope + noise
        q = np.clip(np.round(x), -rail - 1, rail)
        if np.abs(x).max() >= 1.05 * rail and max(longest_flat_top(q), longest_flat_top(-q)) >= 3:
            clipped_total += 1
            missed += hit_checks._flat_top(q * 0.0625, 3) is None
    assert false_alarms == 0
    assert clipped_total > 500 and missed <= 0.01 * clipped_total, (missed, clipped_total)


def test_clipped_force_pulse(tmp_path):
    rec = record(peak=3000.0)  # beyond the 2048 N range
    assert longest_flat_top(rec[:, 0]) >= 3
    hit = only(hits_run(tmp_path, [rec]))
    assert hit.codes == ("clipped",)
    assert hit.reason.startswith("clipped: force (")
    assert "at 2047.94 N" in hit.reason


def test_clipped_response_names_the_channel(tmp_path):
    rec = record(acc=(40.0, 1300.0))  # acc_B_y beyond +/-1024 m/s^2
    hit = only(hits_run(tmp_path, [rec]))
    assert hit.codes == ("clipped",)
    assert "acc_B_y" in hit.reason and "acc_A_y" not in hit.reason and "m/s^2" in hit.reason


def test_clipped_unquantised_data(tmp_path):
    rec = record(quantise=False, noise_lsb=0.0)
    rec[:, 1] = np.clip(rec[:, 1], -30.0, 30.0)
    hit = only(hits_run(tmp_path, [rec]))
    assert hit.codes == ("clipped",) and "acc_A_y" in hit.reason


def test_non_finite_samples(tmp_path):
    rec = record()
    rec[500, 2] = np.nan
    rec[501, 2] = np.inf
    hit = only(hits_run(tmp_path, [rec]))
    assert hit.codes == ("non_finite",) and not hit.accepted and hit.data is None
    assert hit.reason == "non_finite: 2 NaN/Inf sample(s) in acc_B_y"
    assert hit.peak_force_n == pytest.approx(300.0, abs=0.2)


def test_too_weak_relative_and_absolute(tmp_path):
    run = hits_run(
        tmp_path, [record(peak=300.0), record(peak=10.0, acc=(1.3, 0.8)), record(peak=320.0)]
    )
    got = list(iter_hits(run))
    assert [h.accepted for h in got] == [True, False, True]
    assert got[1].codes == ("too_weak",)
    assert "5% of the run's median peak 300 N" in got[1].reason
    strict = list(iter_hits(run, HitSettings(min_peak_force_n=310.0)))
    assert [h.accepted for h in strict] == [False, False, True]
    assert "below 310 N (the minimum)" in strict[0].reason


def test_response_that_has_not_decayed(tmp_path):
    slow = record(zeta=0.0005)  # time constant 92 ms in a 50 ms record
    hit = only(hits_run(tmp_path, [slow]))
    assert hit.codes == ("not_decayed",)
    assert "acc_A_y ends at" in hit.reason and "acc_B_y ends at" in hit.reason
    assert hit.metrics["end_ratio"] > 0.5


def test_noise_at_the_end_is_not_slow_decay(tmp_path):
    rec = record(acc=(40.0, 0.2), noise_lsb=0.0)
    rng = np.random.default_rng(5)
    rec[:, 2] = adc(ringing(10_000, 200, 0.2) + 0.02 * rng.standard_normal(10_000), ACC_RANGE)
    hit = only(hits_run(tmp_path, [rec]))
    assert hit.metrics["end_ratio"] > 0.1  # the noise alone is 10 %+ of the peak ...
    assert hit.accepted, hit.reason  # ... but it is noise, seen before the trigger too


def test_dropout_of_every_channel(tmp_path):
    rec = record()
    rec[240:640, :] = 0.0  # the DAQ lost 2 ms of samples just after the impact
    hit = only(hits_run(tmp_path, [rec]))
    assert hit.codes == ("dropout",)
    assert hit.reason.startswith(
        "dropout: every channel frozen for 400 samples (2 ms) from sample 240"
    )


def test_noise_free_unquantised_record_is_accepted(tmp_path):
    # flat zeros before the trigger and an exactly-zero force after the pulse are normal
    rec = record(quantise=False, noise_lsb=0.0)
    assert np.all(rec[:200] == 0.0)
    hit = only(hits_run(tmp_path, [rec]))
    assert hit.accepted, hit.reason


def test_negative_hit(tmp_path):
    hit = only(hits_run(tmp_path, [-record()]))
    assert hit.codes == ("negative",)
    assert hit.peak_force_n == pytest.approx(-300.0, abs=0.2)
    assert "against excitation_direction" in hit.reason


def test_several_reasons_are_all_reported(tmp_path):
    rec = record(peak=3000.0, zeta=0.0005)
    rec[:, 0] += adc(half_sine(10_000, 2000, 600.0), FORCE_RANGE)
    hit = only(hits_run(tmp_path, [rec]))
    assert hit.codes == ("double_hit", "clipped", "not_decayed")
    assert hit.reason.count("; ") == 2


def test_every_rejection_code_is_documented():
    assert set(REJECTION_CODES) == {
        "non_finite",
        "negative",
        "too_weak",
        "double_hit",
        "clipped",
        "dropout",
        "flat_end",
        "not_decayed",
        "incomplete",
        "overlap",
    }


def test_stored_hits_without_pretrigger_attribute(tmp_path):
    hit = only(hits_run(tmp_path, [record(start=37)], pretrigger=None))
    assert hit.accepted and hit.pretrigger_samples == 38  # first sample >= 5 % of the peak


def test_record_length_for_stored_hits(tmp_path):
    run = hits_run(tmp_path, [record(), record(seed=1)])
    short = list(iter_hits(run, HitSettings(record_length_s=0.01)))
    assert [h.data.shape for h in short] == [(2000, 3), (2000, 3)]
    with pytest.raises(HitSettingsError, match="the stored hits have 10000"):
        iter_hits(run, HitSettings(record_length_s=0.1))


def test_check_hit_directly_leaves_the_input_alone(tmp_path):
    run = hits_run(tmp_path, [record()])
    data = record(seed=3)
    hit = check_hit(run, data, pretrigger_samples=200, index=7)
    assert hit.accepted and hit.index == 7
    data[0, 0] = 1.0  # still writable, and the hit holds its own copy
    assert hit.data[0, 0] != 1.0
    with pytest.raises(ValueError, match=r"expected \(n_samples, 3\)"):
        check_hit(run, data[:, :2])


# -------------------------------------------------------------------- signals

STARTS = (2_000, 17_000, 35_000, 50_000)


def signal_with(starts=STARTS, n=60_000, peaks=None, seed=0):
    rng = np.random.default_rng(seed)
    peaks = peaks or [300.0 + 20 * k for k in range(len(starts))]
    force = sum(half_sine(n, s, p) for s, p in zip(starts, peaks))
    acc = [sum(ringing(n, s, a * p / 300.0) for s, p in zip(starts, peaks)) for a in (40.0, 25.0)]
    cols = [force, *acc]
    return np.column_stack(
        [
            adc(c + 0.5 * fs_ / 2**15 * rng.standard_normal(n), fs_)
            for c, fs_ in zip(cols, (FORCE_RANGE, ACC_RANGE, ACC_RANGE))
        ]
    )


def test_signals_triggers_and_common_record_length(tmp_path):
    run = signals_run(tmp_path, signal_with())
    got = list(iter_hits(run))
    assert [h.accepted for h in got] == [True] * 4, [h.reason for h in got]
    triggers = [s + 1 for s in STARTS]  # first sample above 5 % of the largest peak
    assert [h.start_sample for h in got] == [t - 200 for t in triggers]
    # shortest spacing 15 000 samples, shortened so the last hit fits: 60 000 - 49 801
    assert {h.data.shape for h in got} == {(10_199, 3)}
    assert all(h.pretrigger_samples == 200 for h in got)
    np.testing.assert_array_equal(
        got[2].data, run.read_block(got[2].start_sample, got[2].start_sample + 10_199)
    )
    assert [round(h.peak_force_n) for h in got] == [300, 320, 340, 360]


def test_signals_chunking_does_not_change_the_hits(tmp_path, monkeypatch):
    run = signals_run(tmp_path, signal_with())
    rows_read = []
    real_read_block = RunReader.read_block  # iter_hits reads through one open_reader

    def spy(self, start, stop, channels=None):
        rows_read.append(stop - start)
        return real_read_block(self, start, stop, channels)

    monkeypatch.setattr(RunReader, "read_block", spy)
    small = list(iter_hits(run, chunk_samples=777))  # triggers straddle chunk boundaries
    assert max(rows_read) <= 10_199  # never the whole 60 000-sample signal
    large = list(iter_hits(run, chunk_samples=1_000_000))
    assert [h.start_sample for h in small] == [h.start_sample for h in large]
    assert [h.peak_force_n for h in small] == [h.peak_force_n for h in large]
    for a, b in zip(small, large):
        np.testing.assert_array_equal(a.data, b.data)


def test_signals_double_hit_and_overlap(tmp_path):
    starts = (2_000, 17_000, 18_600, 35_000, 50_000)  # an impact 8 ms after the second hit
    run = signals_run(tmp_path, signal_with(starts, peaks=[300, 320, 120, 340, 360]))
    got = list(iter_hits(run))
    assert [h.index for h in got] == [0, 1, 2, 3, 4]
    assert [h.codes for h in got] == [(), ("double_hit",), ("overlap",), (), ()]
    assert "hit 1 came only 8 ms earlier" in got[2].reason
    assert got[2].data is None and got[2].peak_force_n == pytest.approx(120, abs=1)
    assert {h.data.shape for h in got if h.accepted} == {(10_199, 3)}  # spacings >= 15 000


def test_signals_first_hit_early_and_last_hit_late(tmp_path):
    starts = (60, 17_000, 35_000, 52_000)
    run = signals_run(tmp_path, signal_with(starts))
    got = list(iter_hits(run))
    assert got[0].accepted and got[0].pretrigger_samples == 61 and got[0].start_sample == 0
    # a fixed pretrigger does not fit before the first hit; a fixed length not after the last
    fixed = list(iter_hits(run, HitSettings(pretrigger_s=1e-3, record_length_s=0.05)))
    assert [h.codes for h in fixed] == [("incomplete",), (), (), ("incomplete",)]
    assert "start 139 samples before the signal" in fixed[0].reason
    assert "end 1801 samples after the signal" in fixed[3].reason


def test_signals_absolute_trigger_level_and_no_hits(tmp_path):
    run = signals_run(tmp_path, signal_with())
    got = list(iter_hits(run, HitSettings(trigger_level_n=330.0)))
    # 340 sin(pi k / 20) >= 330 from k = 9; 360 sin(pi k / 20) >= 330 from k = 8
    assert [h.start_sample + 200 for h in got] == [35_000 + 9, 50_000 + 8]
    assert [h.accepted for h in got] == [True, True]
    quiet = signals_run(tmp_path, np.zeros((5_000, 3)), name="quiet.h5")
    assert list(iter_hits(quiet)) == []


def test_signals_weak_hit_by_absolute_minimum(tmp_path):
    run = signals_run(tmp_path, signal_with(peaks=[300, 60, 320, 340]))
    got = list(iter_hits(run, HitSettings(min_peak_force_n=100.0)))
    assert [h.codes for h in got] == [(), ("too_weak",), (), ()]


# -------------------------------------------------------------- settings, table


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"trigger_fraction": 0.0}, "trigger_fraction is 0.0; expected a number in (0, 1)"),
        ({"trigger_level_n": -1.0}, "trigger_level_n is -1.0; expected a positive number"),
        ({"holdoff_s": float("nan")}, "holdoff_s is nan"),
        ({"pretrigger_s": -0.1}, "pretrigger_s is -0.1; expected a number >= 0"),
        ({"clip_min_run": 2}, "clip_min_run is 2; expected an integer >= 3"),
        (
            {"double_hit_ratio": 0.04},
            "pulse_end_fraction (0.05) must be below double_hit_ratio (0.04)",
        ),
        ({"max_end_ratio": True}, "max_end_ratio is True"),
        ({"dropout_min_s": 0.0}, "dropout_min_s is 0.0; expected a positive number"),
    ],
)
def test_settings_validation(kwargs, message):
    with pytest.raises(HitSettingsError) as info:
        HitSettings(**kwargs)
    assert message in str(info.value)
    assert isinstance(info.value, ValueError) and info.value.exit_code == 2


def test_pretrigger_longer_than_record_is_refused(tmp_path):
    run = signals_run(tmp_path, signal_with())
    with pytest.raises(HitSettingsError, match="pretrigger_s"):
        iter_hits(run, HitSettings(pretrigger_s=0.02, record_length_s=0.01))


def test_summarise_hits_table(tmp_path):
    run = hits_run(tmp_path, [record(), -record(seed=1)])
    table = summarise_hits(iter_hits(run))
    assert list(table.columns) == [
        "run",
        "index",
        "start_sample",
        "pretrigger_samples",
        "peak_force_n",
        "accepted",
        "codes",
        "reason",
        "pulse_width_s",
        "second_impact_ratio",
        "end_ratio",
    ]
    assert table["accepted"].tolist() == [True, False]
    assert table["codes"].tolist() == ["", "negative"]
    assert summarise_hits([]).empty


# ------------------------------------------------------------------ real data


@pytest.mark.skipif(not REAL_DATA.is_dir(), reason="shared/real-data not present")
def test_real_pyfrf_hits_are_all_accepted(tmp_path):
    """Five published hammer hits (pyFRF, MIT licence; see shared/real-data/README.md)."""
    arrays = [np.load(REAL_DATA / f"measurements_{k}.npy") for k in range(1, 6)]
    fs = 1.0 / np.median(np.diff(arrays[0][0]))
    data = np.stack([np.column_stack([a[1], a[2]]) for a in arrays])
    run = RunData(
        "pyfrf",
        fs,
        [0, 0, 1],
        ["force", "acc_A_z"],
        ["N", "m/s^2"],
        np.zeros((2, 3)),
        [[0, 0, 1], [0, 0, 1]],
        data=data,
    )
    write_recording(tmp_path / "pyfrf.h5", run)
    got = list(iter_hits(read_recording(tmp_path / "pyfrf.h5").runs[0]))
    assert [h.accepted for h in got] == [True] * 5, [h.reason for h in got]
    peaks = [h.peak_force_n for h in got]
    assert 65 < min(peaks) and max(peaks) < 90  # README: peaks 68-89 N
    assert all(18 <= h.pretrigger_samples <= 22 for h in got)  # force starts about 22 samples in


# ------------------------------------------- optimised iteration vs a plain reference


def _reference_flat_top(x, min_run):
    """hits._flat_top as first written: np.abs, np.unique."""
    n = x.size
    biggest = float(np.max(np.abs(x)))
    if biggest == 0:
        return None
    lsb = None
    for value in {float(np.max(x)), float(np.min(x))}:
        if abs(value) < 0.9 * biggest:
            continue
        at = np.flatnonzero(x == value)
        if at.size < min_run:
            continue
        breaks = np.flatnonzero(np.diff(at) > 1)
        for a, b in zip(np.r_[at[0], at[breaks + 1]], np.r_[at[breaks], at[-1]]):
            m = int(b - a + 1)
            if m < min_run:
                continue
            k = max(2, m // 4)
            drops = []
            if a >= 2:
                drops.append(abs(value - x[a - min(k, a)]))
            if b + 2 < n:
                drops.append(abs(value - x[b + min(k, n - 1 - b)]))
            if not drops:
                return m, value
            if lsb is None:
                steps = np.diff(np.unique(x))
                lsb = float(np.min(steps)) if steps.size else np.inf
            if min(drops) > (4 + 96 / (m - 2) ** 2) * lsb:
                return m, value
    return None


def _reference_assess(data, run, s, pre, median_peak, force_base=None):
    """hits._assess written plainly: every channel and question in its own full pass."""
    names, fs, fi, n = run.channel_names, run.sample_rate_hz, run.force_index, data.shape[0]
    metrics = dict.fromkeys(hit_checks._METRICS, np.nan)
    finite = np.isfinite(data)
    if not finite.all():
        bad = [names[c] for c in np.flatnonzero(~finite.all(axis=0))]
        force = data[:, fi][finite[:, fi]]
        peak = hit_checks._signed_extreme(force - np.median(force)) if force.size else np.nan
        count = int((~finite).sum())
        return ["non_finite"], [f"non_finite: {count} NaN/Inf sample(s) in {', '.join(bad)}"], peak, pre, metrics
    quiet = slice(0, pre - 2) if pre is not None and pre >= 16 else None

    def centred(c):
        x = data[:, c]
        return x - (np.median(x[quiet]) if quiet else np.median(x))

    fc = centred(fi)
    p = int(np.argmax(np.abs(fc)))
    peak = float(fc[p])
    if peak == 0:
        return ["too_weak"], ["too_weak: the force is flat"], peak, pre, metrics
    if peak < 0:
        return ["negative"], [
            f"negative: force peak {peak:.4g} N points against excitation_direction (force sign or direction wrong?)"
        ], peak, pre, metrics
    if pre is None:
        level = s.trigger_level_n if s.trigger_level_n is not None else s.trigger_fraction * peak
        pre = int(np.argmax(fc >= min(level, peak)))
    codes, reasons = [], []
    limit, why = 0.0, ""
    if s.min_peak_force_n is not None:
        limit, why = s.min_peak_force_n, "the minimum"
    if median_peak is not None and np.isfinite(median_peak) and s.min_peak_fraction * median_peak > limit:
        limit = s.min_peak_fraction * median_peak
        why = f"{s.min_peak_fraction:.0%} of the run's median peak {median_peak:.4g} N"
    if peak < limit:
        codes.append("too_weak")
        reasons.append(f"too_weak: peak {peak:.4g} N below {limit:.4g} N ({why})")
    double = hit_checks._double_hit(fc, p, peak, fs, s, metrics)
    if double:
        codes.append("double_hit")
        reasons.append(f"double_hit: {double}")
    clipped = []
    for c in range(data.shape[1]):
        flat = _reference_flat_top(data[:, c], s.clip_min_run)
        if flat is not None:
            clipped.append(f"{names[c]} ({flat[0]} samples at {flat[1]:.6g} {run.channels[c].unit_si})")
    if clipped:
        codes.append("clipped")
        reasons.append(f"clipped: {', '.join(clipped)}")
    min_len = max(8, round(s.dropout_min_s * fs))
    still = np.all(data[1:] == data[:-1], axis=1)
    if still.any() and run.response_indices:
        active_end = 0
        for c in run.response_indices:
            x = centred(c)
            top = np.max(np.abs(x))
            if top > 0:
                active_end = max(active_end, int(np.flatnonzero(np.abs(x) >= 0.1 * top)[-1]))
        edges = np.diff(np.r_[0, still.astype(np.int8), 0])
        for a, b in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)):
            m = int(b - a + 1)
            if m >= min_len and pre <= a < active_end:
                codes.append("dropout")
                reasons.append(
                    f"dropout: every channel frozen for {m} samples ({m / fs * 1e3:.3g} ms) from sample {a}, "
                    "while the response is still ringing"
                )
                break
    n_end = max(8, int(np.ceil(s.decay_end_fraction * n)))
    worst, slow = 0.0, []
    for c in run.response_indices:
        x = centred(c)
        top = float(np.max(np.abs(x)))
        if top == 0 or n_end >= n:
            continue
        rms_end = float(np.sqrt(np.mean(x[-n_end:] ** 2)))
        noise = float(np.sqrt(np.mean(x[quiet] ** 2))) if quiet else 0.0
        ratio = rms_end * np.sqrt(2) / top
        worst = max(worst, ratio)
        if ratio > s.max_end_ratio and rms_end > 3 * noise:
            slow.append(f"{names[c]} ends at {ratio:.0%} of its peak")
    metrics["end_ratio"] = worst
    if slow:
        codes.append("not_decayed")
        reasons.append(f"not_decayed: {', '.join(slow)} (limit {s.max_end_ratio:.0%}, a longer record helps)")
    return codes, reasons, peak, pre, metrics


def _reference_stored_hits(run, s, length):
    """Stored hits read one call (one file open) at a time, twice; plain checks."""
    fi, pre = run.force_index, run.pretrigger_samples
    peaks = []
    for i in range(run.n_hits_stored):
        force = read_hit(run, i, [fi])[:length, 0]
        finite = np.isfinite(force)
        quiet = finite[: pre - 2] if pre is not None and pre >= 16 else finite
        base = force[: quiet.size][quiet]
        if base.size:
            peaks.append(abs(hit_checks._signed_extreme(force[finite] - np.median(base))))
    median_peak = float(np.median(peaks)) if peaks else None
    out = []
    for i in range(run.n_hits_stored):
        data = read_hit(run, i)[:length].copy()
        codes, reasons, peak, trigger, metrics = _reference_assess(data, run, s, pre, median_peak)
        accepted = not codes
        out.append((i, 0, accepted, "; ".join(reasons) or None, tuple(codes), trigger, peak, metrics,
                    data if accepted else None))
    return out


class _PlainReader:
    """open_reader's interface, every read through read_block / read_hit (a file open each)."""

    def __init__(self, run):
        self.run = run

    def read_block(self, start=0, stop=None, channels=None):
        return read_block(self.run, start, stop, channels)


def _as_tuple(hit):
    return (hit.index, hit.start_sample, hit.accepted, hit.reason, hit.codes, hit.pretrigger_samples,
            hit.peak_force_n, dict(hit.metrics), hit.data)


def _assert_same_hits(got, want):
    assert len(got) == len(want)
    for g, w in zip(got, want):
        assert g[:6] == w[:6]
        np.testing.assert_array_equal(g[6], w[6])  # peak (NaN equal to NaN)
        assert g[7].keys() == w[7].keys()
        for key in g[7]:  # float32 samples are checked in float32: the metrics within its rounding
            np.testing.assert_allclose(g[7][key], w[7][key], rtol=1e-6, equal_nan=True)
        if w[8] is None:
            assert g[8] is None
        else:
            assert g[8].dtype == np.float64 and g[8].shape == w[8].shape and g[8].flags.c_contiguous
            assert not g[8].flags.writeable
            np.testing.assert_array_equal(g[8], w[8])


@pytest.mark.parametrize("layout", ["hits", "signals"])
def test_optimised_iteration_matches_a_plain_reference(tmp_path, monkeypatch, layout):
    from contextlib import contextmanager

    from guidefit.simulate import SimulationConfig, write_simulation

    path = tmp_path / f"faults_{layout}.h5"
    config = SimulationConfig(
        faults=("double_hit", "overload", "dropped_hit"), hits=6, record_s=0.02, layout=layout
    )
    write_simulation(path, "MRB35", config=config, seed=0)
    runs = read_recording(path).runs
    settings = [HitSettings(), HitSettings(min_peak_fraction=0.9)]
    if layout == "hits":
        settings.append(HitSettings(record_length_s=0.015))
    got = {}
    for run in runs:
        for k, s in enumerate(settings):
            got[run.name, k] = [_as_tuple(h) for h in iter_hits(run, s)]
    codes = {c for hits in got.values() for h in hits for c in h[4]}
    assert {"double_hit", "clipped", "dropout"} <= codes  # the faults were seen
    assert any(h[2] for hits in got.values() for h in hits)  # and clean hits accepted
    if layout == "hits":
        for run in runs:
            for k, s in enumerate(settings):
                length = run.n_samples if s.record_length_s is None else round(s.record_length_s * run.sample_rate_hz)
                want = _reference_stored_hits(run, s, length)
                _assert_same_hits(got[run.name, k], want)
        # the larger-run path: force read in blocks of two hits, every hit read again
        monkeypatch.setattr(hits_module, "_CACHE_BYTES", 0)
        monkeypatch.setattr(hits_module, "_READ_BYTES", 2 * 8 * runs[0].n_samples * runs[0].n_channels)
        for run in runs:
            for k, s in enumerate(settings):
                _assert_same_hits([_as_tuple(h) for h in iter_hits(run, s)], got[run.name, k])
            monkeypatch.undo()
            want = _reference_stored_hits(run, settings[0], run.n_samples)
            _assert_same_hits(got[run.name, 0], want)
            monkeypatch.setattr(hits_module, "_CACHE_BYTES", 0)
    else:
        # the same trigger search with a file open per read and the plain checks
        monkeypatch.setattr(hits_module, "open_reader", contextmanager(lambda run: (yield _PlainReader(run))))
        monkeypatch.setattr(hits_module, "_assess", _reference_assess)
        for run in runs:
            for k, s in enumerate(settings):
                want = [_as_tuple(h) for h in iter_hits(run, s)]
                assert [h[1] for h in want] == [h[1] for h in got[run.name, k]]  # record boundaries
                _assert_same_hits(got[run.name, k], want)


def test_fast_median_is_numpy_median():
    rng = np.random.default_rng(5)
    for trial in range(300):
        n = int(rng.integers(1, 60_000))
        kind = trial % 5
        if kind == 0:
            x = rng.standard_normal(n)
        elif kind == 1:
            x = np.round(rng.standard_normal(n) * 3) * 0.1  # many ties
        elif kind == 2:
            x = np.where(rng.random(n) < rng.random(), 0.0, rng.standard_normal(n))
        elif kind == 3:
            t = np.arange(n)
            x = np.sin(2 * np.pi * t / rng.integers(2, 5000)) * np.exp(-t / rng.integers(100, 100_000))
        else:
            x = np.sort(rng.standard_normal(n))[:: 1 if trial % 2 else -1].copy()
        got, want = hit_checks._median(x), np.median(x)
        assert got == want and type(got) is type(want), (trial, n)


def _stored_run(path, records, pretrigger_samples, units=("N", "m/s^2", "m/s^2")):
    """A vertical hits-layout run of force, acc_A_y and acc_B_y written to ``path`` and read back."""
    run = RunData("vertical", FS, [0, -1, 0], NAMES, list(units),
                  [[0, 0, 0], [0.03, 0, 0.045], [-0.03, 0, 0.045]],
                  [[0, -1, 0], [0, 1, 0], [0, 1, 0]], data=records, layout="hits",
                  pretrigger_samples=pretrigger_samples)
    write_recording(path, run)
    return read_recording(path).runs[0]


def test_stored_hits_in_g_read_once_as_stored_equal_read_hit(tmp_path, monkeypatch):
    """Stored hits are read as stored and converted to SI once (rows for the
    checks, data on demand): the same values, peaks and decisions as the plain
    reference reading ``read_hit``, for a channel stored in g, in both the
    small-run (read once) and the block-read paths."""
    rng = np.random.default_rng(11)
    n, hits = 4000, 6
    records = np.zeros((hits, n, 3), dtype=np.float32)
    for i in range(hits):
        records[i, :, 0] = half_sine(n, 200, 80.0 + 10 * i) + rng.normal(0, 0.01, n)
        records[i, :, 1] = (ringing(n, 200, 30.0) + rng.normal(0, 0.01, n)) / 9.80665
        records[i, :, 2] = ringing(n, 200, 20.0, f_hz=2100.0) + rng.normal(0, 0.01, n)
    records[4, 2500:2600, 0] += half_sine(100, 0, 40.0)  # a double hit
    stored = _stored_run(tmp_path / "g.h5", records, 200, units=("N", "g", "m/s^2"))
    assert stored.channels[1].scale_to_si == 9.80665
    want = _reference_stored_hits(stored, HitSettings(), n)
    assert [w[4] for w in want] == [(), (), (), (), ("double_hit",), ()]
    _assert_same_hits([_as_tuple(h) for h in iter_hits(stored)], want)
    monkeypatch.setattr(hits_module, "_CACHE_BYTES", 0)
    monkeypatch.setattr(hits_module, "_READ_BYTES", 4 * 8 * n * 3)  # blocks of 4 hits, 2 left
    got = list(iter_hits(stored))
    _assert_same_hits([_as_tuple(h) for h in got], want)
    for hit in got:  # data is made on demand, once, read-only
        if hit.accepted:
            assert hit.data is hit.data
            np.testing.assert_array_equal(hit.data, read_hit(stored, hit.index))


def test_iter_hits_reuses_row_buffers_only_when_released(tmp_path):
    """Hits kept by the caller keep their own samples."""
    records = np.zeros((5, 2000, 3))
    for i in range(5):
        records[i, :, 0] = half_sine(2000, 100, 50.0 + i)
        records[i, :, 1] = ringing(2000, 100, 10.0 + i)
        records[i, :, 2] = ringing(2000, 100, 5.0 + i, f_hz=1800.0)
    kept = list(iter_hits(_stored_run(tmp_path / "keep.h5", records, 100)))
    assert all(h.accepted for h in kept)
    for i, hit in enumerate(kept):
        np.testing.assert_array_equal(hit.data, records[i])


def test_first_pass_over_half_the_force_judges_as_the_full_median(tmp_path, monkeypatch):
    """The first pass reads the force of the last n // 2 + 2 stored hits only; each
    hit is judged against an upper bound of the run's median peak and, if too weak
    against it, against the exact median (the rest of the force read then). The
    decisions, reasons, peaks and metrics must be those of the full two-pass
    reference, for weak hits early, late and first, a non-finite force, and
    median-fraction limits that make none, some or most hits too weak."""
    from guidefit.io import RunReader

    rng = np.random.default_rng(17)
    n, hits = 3000, 12
    peaks = np.array([3.0, 60, 75, 2.5, 90, 55, 120, 70, 65, 4.0, 80, 58])  # weak: 0, 3, 9
    records = np.zeros((hits, n, 3), dtype=np.float32)
    for i in range(hits):
        records[i, :, 0] = half_sine(n, 150, peaks[i]) + rng.normal(0, 0.01, n)
        records[i, :, 1] = ringing(n, 150, 0.3 * peaks[i]) + rng.normal(0, 0.01, n)
        records[i, :, 2] = ringing(n, 150, 0.2 * peaks[i], f_hz=2100.0) + rng.normal(0, 0.01, n)
    records[7, 1000, 0] = np.nan  # in the first pass's half: a peak from the finite samples
    stored = _stored_run(tmp_path / "weak.h5", records, 150)
    monkeypatch.setattr(hits_module, "_CACHE_BYTES", 0)
    monkeypatch.setattr(hits_module, "_READ_BYTES", 3 * 8 * n * 3)  # blocks of 3 hits
    read = []
    original = RunReader.read_hits_raw

    def counting(self, first, last, *args, **kwargs):
        read.append(last - first)
        return original(self, first, last, *args, **kwargs)

    monkeypatch.setattr(RunReader, "read_hits_raw", counting)
    for fraction in (0.01, 0.05, 0.5, 0.9, 0.99):
        s = HitSettings(min_peak_fraction=fraction)
        want = _reference_stored_hits(stored, s, n)
        read.clear()
        _assert_same_hits([_as_tuple(h) for h in iter_hits(stored, s)], want)
        weak = [w[0] for w in want if "too_weak" in w[4]]
        if fraction == 0.01:  # nobody too weak: the force of 8 of the 12 hits read once more
            assert weak == [] and sum(read) == hits + hits // 2 + 2
        else:  # hit 0 is too weak: the force of hits 1-3 is read at once, then every hit
            assert 0 in weak and sum(read) == 2 * hits - 1
    # a weak hit after strong ones (hit 2, before the first pass's half): the exact median mid-way
    swapped = records.copy()
    swapped[[0, 2]] = records[[2, 0]]
    stored = _stored_run(tmp_path / "weak2.h5", swapped, 150)
    for fraction in (0.05, 0.5):
        s = HitSettings(min_peak_fraction=fraction)
        want = _reference_stored_hits(stored, s, n)
        assert "too_weak" not in want[0][4] and "too_weak" in want[2][4]
        _assert_same_hits([_as_tuple(h) for h in iter_hits(stored, s)], want)
    # the bound is an upper bound of np.median with unknown values absent or anything
    values = [1.0, 3.0, 5.0]
    for extra in ([], [0.0], [10.0], [0.0, 0.0], [10.0, 10.0], [2.0, 4.0]):
        bound = hits_module._median_upper_bound(values, 2)
        assert float(np.median(values + extra)) <= bound
    assert hits_module._median_upper_bound([], 0) is None
    assert hits_module._median_upper_bound([1.0], 1) == float("inf")


@pytest.mark.parametrize("n", [5, 8192, 8193, 30_001])
@pytest.mark.parametrize("dtype", [np.float32, np.int16, np.float64])
def test_rows_from_raw_is_the_plain_conversion_and_its_extremes(n, dtype):
    """Block-by-block conversion gives exactly ``float64(raw.T) * scale`` and the rows' max and min,
    NaN and Inf propagating as in ``rows.max(axis=1)`` (a NaN or an Inf at a block edge too)."""
    rng = np.random.default_rng(n)
    raw = (rng.normal(0, 1000, (n, 3))).astype(dtype)
    scale = np.array([1.0, 9.80665, 2.5e-3])
    for bad in (None, np.nan, np.inf):
        data = raw.copy()
        if bad is not None and np.issubdtype(dtype, np.floating):
            data[min(n - 1, 8191), 1] = bad
            data[n - 1, 2] = -bad
        for sc in (None, scale):
            rows = np.empty((3, n))
            tops, bottoms = hit_checks._rows_from_raw(rows, data, sc)
            want = data.T.astype(np.float64) * (1.0 if sc is None else sc[:, None])
            # one correctly rounded IEEE multiply per element, no reduction order: equal on any CPU
            np.testing.assert_array_equal(rows, want)
            np.testing.assert_array_equal(tops, want.max(axis=1))
            np.testing.assert_array_equal(bottoms, want.min(axis=1))


def test_a_signal_holding_one_hit_gives_it_the_rest_of_the_signal(tmp_path):
    """Was: a 0.03 s signals-layout run with one hit (no spacing between hits) asked for the 0.5 s
    cap: "incomplete: the record would end ... samples after the signal", no run gave an FRF, exit 1."""
    from dataclasses import replace

    from guidefit.identify import IdentifySettings, identify
    from guidefit.io import write_recording
    from guidefit.simulate import DEFAULT_RUNS, SimulationConfig, simulate

    config = replace(SimulationConfig(), runs=(DEFAULT_RUNS[0],), hits=1, record_s=0.03, layout="signals",
                     sensor_layout="default")
    data, truth = simulate("MRB35", config=config, seed=4)
    write_recording(tmp_path / "one.h5", data)
    result = identify(tmp_path / "one.h5", settings=IdentifySettings(jackknife=False))
    assert [h["accepted"] for h in result.hit_rows()] == [True]
    assert result.parameters["K_V"]["value"] == pytest.approx(truth["parameters"]["K_V"]["value"], rel=2e-3)


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_signals_force_corrupt_over_an_impact_is_a_rejected_hit(tmp_path, bad):
    """A NaN (or Inf) block in the force over one impact of a continuous record hid that hit's
    trigger: the hit vanished without a word (3 hits, all accepted, no warning). The corrupt block
    opens a record as a hit does: that hit is there, rejected as non_finite, the others as before."""
    signal = signal_with()
    signal[STARTS[1] - 10:STARTS[1] + 40, 0] = bad
    got = list(iter_hits(signals_run(tmp_path, signal)))
    assert len(got) == 4, [h.reason for h in got]
    assert [h.accepted for h in got] == [True, False, True, True], [h.reason for h in got]
    assert got[1].codes == ("non_finite",) and "in force" in got[1].reason
    assert [h.start_sample for h in (got[0], got[2], got[3])] == [s + 1 - 200 for s in STARTS if s != STARTS[1]]
