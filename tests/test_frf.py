"""Tests of guidefit.frf against truth that can be written down.

- a 2-DOF mass-spring-damper hit by a half-sine pulse, its acceleration computed
  in closed form from the state-space eigen-solution (no ODE solver): H1 must
  match the analytic accelerance up to the aliasing of the sampled pulse, whose
  bound is computed from the pulse's analytic spectrum;
- the exponential window's exact pole shift, on a decaying sinusoid;
- estimator invariants (hypothesis): coherence in [0, 1], |H1| <= |Hv| <= |H2|,
  force scaling, H1 = H2 = Hv on noise-free data;
- grouping, jackknife, bounded memory, entrance validation, export round trips.
"""

from __future__ import annotations

import math
import weakref
from types import SimpleNamespace as NS

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from guidefit.errors import IdentificationError, RecordingError
from guidefit.frf import (
    ESTIMATORS,
    FrfSet,
    WindowChoice,
    WindowSettings,
    choose_windows,
    coherence_from_sums,
    compute_frf,
    estimate_frf,
    exponential_window,
    exponential_window_damping_correction,
    force_window,
    frf_from_records,
    jackknife_frf,
    read_frf_h5,
    spectral_sums,
    write_frf_csv,
    write_frf_h5,
)

NONE = WindowSettings(none=True)


# --------------------------------------------------------------------------- 2-DOF truth


def two_dof(m=(1.0, 0.4), k=(3.0e7, 1.5e7), c=(120.0, 40.0)):
    """Ground-k1-m1-k2-m2 chain; modes near 660 and 1290 Hz, zeta 0.8 % and 1.2 %."""
    M = np.diag(m)
    K = np.array([[k[0] + k[1], -k[1]], [-k[1], k[1]]])
    C = np.array([[c[0] + c[1], -c[1]], [-c[1], c[1]]])
    return M, K, C


def accelerance(M, K, C, s):
    """Accelerance s^2 (M s^2 + C s + K)^-1 e_0 of both DOFs (force on DOF 0), (len(s), 2)."""
    e0 = np.array([1.0, 0.0])
    return np.array([si**2 * np.linalg.solve(M * si**2 + C * si + K, e0) for si in s])


def half_sine_response(M, K, C, t, t0, T, F0=1.0):
    """Force F0 sin(pi (t-t0)/T) on [t0, t0+T] and the exact accelerations of both DOFs.

    With A = V diag(lam) V^-1 the state matrix, the displacement is
    x = sum_r c_r y_r, y_r = int_0^t exp(lam_r (t-s)) f(s) ds (closed form for a
    half-sine), c_r = V[:2, r] (V^-1 B)_r. Since sum c_r = 0 and
    sum c_r lam_r = M^-1 e_0, the acceleration is sum c_r lam_r^2 y_r + M^-1 e_0 f.
    """
    n = M.shape[0]
    Mi = np.linalg.inv(M)
    A = np.block([[np.zeros((n, n)), np.eye(n)], [-Mi @ K, -Mi @ C]])
    b0 = Mi @ np.array([1.0, 0.0])
    B = np.concatenate([np.zeros(n), b0])
    lam, V = np.linalg.eig(A)
    cr = V[:n, :] * (np.linalg.solve(V, B))[None, :]
    W = np.pi / T
    tau = t - t0
    u = np.clip(tau, 0.0, T)
    f = np.where((tau >= 0) & (tau <= T), F0 * np.sin(W * u), 0.0)
    acc = np.zeros((t.size, n), dtype=complex)
    tp = np.where(tau > 0, tau, 0.0)
    for r, lr in enumerate(lam):
        y = F0 * np.exp(lr * tp) / 2j * ((np.exp((1j * W - lr) * u) - 1) / (1j * W - lr)
                                         - (np.exp((-1j * W - lr) * u) - 1) / (-1j * W - lr))
        acc += np.outer(np.where(tau > 0, y, 0.0) * lr**2, cr[:, r])
    return f, acc.real + np.outer(f, b0)


def half_sine_spectrum(freq, T):
    """|Fourier transform| of a unit half-sine of duration T."""
    x = 2.0 * freq * T
    with np.errstate(divide="ignore", invalid="ignore"):
        mag = np.abs(2 * T / np.pi * np.cos(np.pi * freq * T) / (1 - x**2))
    return np.where(np.isclose(np.abs(x), 1.0), T / 2, mag)


def aliasing_bound(freq, fs, T, H, inv_mass):
    """Bound of |H1 - H| from the aliased pulse spectrum.

    The DFTs of the sampled signals are sums over images m fs; with
    alpha = sum_{m != 0} |F(f + m fs)| / |F(f)|, |H1 - H| <= alpha (|H| + max |H| above
    Nyquist), and above a few kHz the accelerance is the mass line <= inv_mass.
    """
    m = np.arange(1, 400)
    images = (half_sine_spectrum(freq[:, None] + m * fs, T)
              + half_sine_spectrum(m * fs - freq[:, None], T)).sum(axis=1)
    alpha = images / half_sine_spectrum(freq, T)
    return alpha[:, None] * (np.abs(H) + inv_mass)


FS = 102400.0
T_PULSE = 2e-4
PRE = 50


@pytest.fixture(scope="module")
def unit_hit():
    """Force and accelerations of one unit half-sine hit, 0.32 s at 102.4 kHz."""
    M, K, C = two_dof()
    t = np.arange(32768) / FS
    f, acc = half_sine_response(M, K, C, t, PRE / FS, T_PULSE)
    return (M, K, C), np.column_stack([f, acc])


def test_h1_matches_analytic_accelerance_noise_free(unit_hit):
    (M, K, C), rec = unit_hit
    frf = frf_from_records(100.0 * rec[None], FS, channel_names=("force", "acc_1", "acc_2"),
                           window=NONE)
    sel = (frf.frequency_hz > 0) & (frf.frequency_hz <= 4000)
    f = frf.frequency_hz[sel]
    H = accelerance(M, K, C, 2j * np.pi * f)
    err = np.abs(frf.H[sel] - H)
    bound = aliasing_bound(f, FS, T_PULSE, H, 1 / M.diagonal().min())
    assert np.all(err <= bound + 1e-9 * np.abs(H).max())
    # the bound is tight: the error is aliasing, not something else
    assert np.max(err / bound) > 0.3
    assert np.max(err) < 2e-3 * np.abs(H).max()
    for e in ESTIMATORS:   # noise-free: all estimators agree, coherence 1 (one hit)
        assert np.allclose(frf.with_estimator(e).H, frf.H, rtol=1e-9, atol=0)
    assert np.allclose(frf.coherence, 1.0)


def test_h1_matches_analytic_accelerance_with_noise_and_default_windows(unit_hit):
    (M, K, C), rec = unit_hit
    rng = np.random.default_rng(11)
    amps = rng.uniform(60.0, 100.0, 12)
    peak = np.abs(100 * rec[:, 1:]).max()

    def hits():
        for a in amps:
            x = a * rec
            x[:, 0] += 0.05 * rng.standard_normal(len(x))              # force noise, N
            x[:, 1:] += 2e-3 * peak * rng.standard_normal((len(x), 2))  # response noise
            yield x

    frf = frf_from_records(hits(), FS, pretrigger_samples=PRE)
    assert frf.n_averages == 12 and frf.n_groups == 8
    assert frf.force_window_s is not None and frf.force_window_s < 2e-3
    sigma_w = 0.0 if frf.exp_window_tau_s is None else 1.0 / frf.exp_window_tau_s
    sel = (frf.frequency_hz > 0) & (frf.frequency_hz <= 4000)
    f = frf.frequency_hz[sel]
    H = accelerance(M, K, C, 2j * np.pi * f + sigma_w)   # windowed system: poles shifted
    good = frf.coherence[sel] > 0.9
    assert np.all(good.mean(axis=0) > 0.6)
    err = np.abs(frf.H[sel] - H)
    tol = aliasing_bound(f, FS, T_PULSE, H, 1 / M.diagonal().min()) + 5 * frf.H_std[sel]
    assert np.all(err[good] <= tol[good] + 1e-3 * np.abs(H[good]))


def test_exponential_window_gives_pole_shifted_frf_of_truncated_record(unit_hit):
    (M, K, C), rec = unit_hit
    short = 100.0 * rec[None, :4096]          # 40 ms: the response has not decayed
    tau = 5e-3
    frf = frf_from_records(short, FS, window=WindowSettings(force_window_s=math.inf,
                                                            exp_tau_s=tau))
    assert frf.exp_window_tau_s == tau and frf.force_window_s is None
    sel = (frf.frequency_hz > 0) & (frf.frequency_hz <= 4000)
    f = frf.frequency_hz[sel]
    H = accelerance(M, K, C, 2j * np.pi * f + 1 / tau)
    err = np.abs(frf.H[sel] - H)
    # leakage left after the window: the windowed response at the record end
    leak = np.exp(-short.shape[1] / FS / tau) * np.abs(H).max()
    assert np.all(err <= aliasing_bound(f, FS, T_PULSE, H, 1 / M.diagonal().min()) + 2 * leak)
    unwindowed = frf_from_records(short, FS, window=NONE)
    H0 = accelerance(M, K, C, 2j * np.pi * f)
    assert np.max(np.abs(unwindowed.H[sel] - H0)) > 10 * np.max(err)   # truncation leakage


# --------------------------------------------------------------------------- pole shift


def prony_pole(x, dt):
    """Pole of a noise-free damped sinusoid from a 2nd-order linear prediction."""
    A = np.column_stack([x[1:-1], x[:-2]])
    a1, a2 = np.linalg.lstsq(A, x[2:], rcond=None)[0]
    z = np.roots([1.0, -a1, -a2])
    p = np.log(z[np.argmax(z.imag)]) / dt
    return abs(p) / (2 * np.pi), -p.real / abs(p)


@pytest.mark.parametrize("f_n, zeta, tau", [(1000.0, 0.01, 0.01), (3450.0, 0.0288, 2e-3),
                                            (120.0, 0.2, 0.05)])
def test_damping_correction_recovers_windowed_decaying_sinusoid(f_n, zeta, tau):
    fs = 50_000.0
    t = np.arange(4000) / fs
    w_n = 2 * np.pi * f_n
    w_d = w_n * math.sqrt(1 - zeta**2)
    x = np.exp(-zeta * w_n * t) * np.sin(w_d * t + 0.3)
    xw = x * exponential_window(t.size, fs, tau)
    f_meas, zeta_meas = prony_pole(xw, 1 / fs)
    assert zeta_meas > zeta * 1.05                   # the window added damping
    f_true, zeta_true = exponential_window_damping_correction(zeta_meas, f_meas, tau)
    assert f_true == pytest.approx(f_n, rel=1e-9)
    assert zeta_true == pytest.approx(zeta, rel=1e-8)
    # sigma_w = 1/tau exactly
    assert zeta_meas * 2 * np.pi * f_meas - zeta * w_n == pytest.approx(1 / tau, rel=1e-8)


def test_damping_correction_vectorised_and_no_window():
    f, z = exponential_window_damping_correction([0.02, 0.05], [1000.0, 2000.0], None)
    assert np.array_equal(f, [1000.0, 2000.0]) and np.array_equal(z, [0.02, 0.05])
    f, z = exponential_window_damping_correction(np.array([0.02, 0.05]), 1000.0, 0.1)
    assert f.shape == z.shape == (2,)
    assert np.all(z < [0.02, 0.05]) and np.all(f < 1000.0)
    with pytest.warns(UserWarning, match="negative damping"):
        exponential_window_damping_correction(0.001, 100.0, 0.001)


# --------------------------------------------------------------------------- invariants


def random_records(seed, n_hits, n_samples, n_resp, noise):
    """Random force, responses = random FIR filters of it (circular) plus noise."""
    rng = np.random.default_rng(seed)
    force = rng.standard_normal((n_hits, n_samples))
    h = rng.standard_normal((n_resp, 6)) * np.exp(-np.arange(6) / 2.0)
    F = np.fft.rfft(force, axis=1)
    Hf = np.fft.rfft(h, n_samples, axis=1)                         # (R, F)
    resp = np.fft.irfft(F[:, None, :] * Hf[None], n_samples, axis=2)
    resp += noise * rng.standard_normal(resp.shape)
    rec = np.concatenate([force[:, :, None], np.transpose(resp, (0, 2, 1))], axis=2)
    return rec, Hf.T


record_cases = st.tuples(st.integers(0, 2**32 - 1), st.integers(1, 6), st.integers(8, 48),
                         st.integers(1, 3))


@settings(max_examples=60, deadline=None)
@given(record_cases, st.floats(0.01, 2.0))
def test_coherence_in_unit_interval_and_estimator_ordering(case, noise):
    seed, n_hits, n, r = case
    rec, _ = random_records(seed, n_hits, n, r, noise)
    rec[:, :, 0] += noise * np.random.default_rng(seed + 1).standard_normal(rec.shape[:2])
    frfs = {e: frf_from_records(rec, 100.0, window=NONE, estimator=e) for e in ESTIMATORS}
    g2 = frfs["H1"].coherence
    assert np.all((g2 >= 0) & (g2 <= 1))
    a1, av, a2 = (np.abs(frfs[e].H) for e in ("H1", "Hv", "H2"))
    tol = 1e-9 * a2
    assert np.all(a1 <= av + tol) and np.all(av <= a2 + tol)
    # all three share the phase of Sfx; gamma^2 = H1 / H2
    assert np.allclose(frfs["Hv"].H * np.abs(frfs["H1"].H), frfs["H1"].H * av, rtol=1e-7,
                       atol=1e-12 * a2.max())
    assert np.allclose(g2, a1 / a2, rtol=1e-9, atol=1e-12)


@settings(max_examples=40, deadline=None)
@given(record_cases, st.floats(1e-3, 1e3))
def test_scaling_the_force_scales_h1_h2_inversely(case, scale):
    seed, n_hits, n, r = case
    rec, _ = random_records(seed, n_hits, n, r, 0.3)
    scaled = rec.copy()
    scaled[:, :, 0] *= scale
    for e in ("H1", "H2"):
        a = frf_from_records(rec, 100.0, window=NONE, estimator=e)
        b = frf_from_records(scaled, 100.0, window=NONE, estimator=e)
        assert np.allclose(b.H * scale, a.H, rtol=1e-9, atol=1e-12 * np.abs(a.H).max())
        assert np.allclose(b.coherence, a.coherence, rtol=1e-9, atol=1e-12)


@settings(max_examples=40, deadline=None)
@given(record_cases)
def test_noise_free_estimators_agree_and_equal_the_true_frf(case):
    seed, n_hits, n, r = case
    rec, Htrue = random_records(seed, n_hits, n, r, 0.0)
    frf = frf_from_records(rec, 100.0, window=NONE)
    ok = np.abs(np.fft.rfft(rec[:, :, 0], axis=1)).min(axis=0) > 1e-6   # force not ~0
    for e in ESTIMATORS:
        H = frf.with_estimator(e).H
        assert np.allclose(H[ok], Htrue[ok], rtol=1e-7, atol=1e-9)
    assert np.allclose(frf.coherence[ok], 1.0, atol=1e-9)


def test_hv_is_not_invariant_to_force_scaling_with_noise():
    # Hv assumes equal noise on force and response in their own units (documented)
    rec, _ = random_records(3, 6, 64, 1, 0.5)
    rec[:, :, 0] += 0.5 * np.random.default_rng(4).standard_normal(rec.shape[:2])
    a = frf_from_records(rec, 1.0, window=NONE, estimator="Hv")
    scaled = rec.copy()
    scaled[:, :, 0] *= 10.0
    b = frf_from_records(scaled, 1.0, window=NONE, estimator="Hv")
    assert not np.allclose(10.0 * b.H, a.H, rtol=1e-3)


def test_hv_closed_form_is_the_smallest_eigenvector():
    rng = np.random.default_rng(5)
    sff = rng.uniform(0.1, 10, 20)
    sxx = rng.uniform(0.1, 10, (20, 1))
    sfx = (rng.normal(size=(20, 1)) + 1j * rng.normal(size=(20, 1)))
    sfx *= np.sqrt(sff[:, None] * sxx) * 0.9 / np.abs(sfx)          # a valid |Sfx|
    H = estimate_frf(sff, sxx, sfx, "Hv")[:, 0]
    for k in range(20):
        S = np.array([[sff[k], sfx[k, 0]], [np.conj(sfx[k, 0]), sxx[k, 0]]])
        _w, v = np.linalg.eigh(S)
        assert H[k] == pytest.approx(-v[0, 0] / v[1, 0], rel=1e-10)


def test_estimate_frf_rejects_unknown_estimator():
    with pytest.raises(ValueError, match="estimator 'H3' unknown; use one of H1, H2, Hv"):
        estimate_frf(np.ones(2), np.ones((2, 1)), np.ones((2, 1)), "H3")
    with pytest.raises(ValueError, match="estimator 'h1'"):
        frf_from_records(np.ones((1, 8, 2)), 1.0, estimator="h1")


def test_coherence_of_one_hit_is_one_and_zero_sums_give_nan():
    g2 = coherence_from_sums(np.array([0.0, 2.0]), np.array([[1.0], [3.0]]),
                             np.array([[0.0], [np.sqrt(6.0)]]))
    assert np.isnan(g2[0, 0]) and g2[1, 0] == pytest.approx(1.0)


# --------------------------------------------------------------------------- windows


def test_force_window_keeps_pretrigger_and_tapers():
    w = force_window(100, 1000.0, 0.01, trigger_sample=20, taper_s=0.005)
    assert np.all(w[:30] == 1.0) and np.all(w[35:] == 0.0)
    assert np.all(np.diff(w[29:36]) < 0)
    assert np.array_equal(force_window(10, 1000.0, None), np.ones(10))
    assert np.array_equal(force_window(10, 1000.0, math.inf), np.ones(10))
    hard = force_window(25600, 25600.0, 0.01)          # pyFRF 'force:0.01' on 1 s
    assert hard.sum() == 256 and np.all(hard[:256] == 1.0)


def test_exponential_window_matches_pyfrf_definition():
    n, fs = 25600, 25600.0
    w = exponential_window(n, fs, (n - 1) / fs / math.log(100))
    pyfrf = np.exp(np.log(0.01) * np.arange(n) / (n - 1))
    assert np.allclose(w, pyfrf, rtol=1e-13, atol=0)
    assert np.array_equal(exponential_window(5, 1.0, None), np.ones(5))


def decaying_hit(n=4000, fs=10000.0, sigma=50.0, pre=100):
    t = (np.arange(n) - pre) / fs
    f = np.where((t >= 0) & (t < 5e-4), np.sin(np.pi * t / 5e-4), 0.0)
    x = np.where(t >= 0, np.exp(-sigma * t) * np.sin(2 * np.pi * 400 * t), 0.0)
    return f, x[:, None]


def test_default_windows_from_pulse_and_decay():
    fs = 10000.0
    f, x = decaying_hit(sigma=50.0)       # end level exp(-19.5): decayed
    c = choose_windows(f, x, fs)
    assert c.trigger_sample == 101          # first sample above 5 % of the peak
    assert c.pulse_duration_s == pytest.approx(5e-4, abs=2e-4)
    assert c.force_window_s == pytest.approx(5 * 5e-4, rel=0.4)
    assert c.force_taper_s == pytest.approx(0.2 * c.force_window_s)
    assert c.exp_tau_s is None                      # no exponential window needed

    f, x = decaying_hit(sigma=0.0)        # never decays: strongest window, 1 % at the end
    c = choose_windows(f, x, fs)
    assert math.exp(-(len(f) - 1) / fs / c.exp_tau_s) == pytest.approx(0.01)

    f, x = decaying_hit(sigma=np.log(10) / 0.39)   # ~10 % left in the tail
    c = choose_windows(f, x, fs)
    end = math.exp(-(len(f) - 1) / fs / c.exp_tau_s)
    assert 0.06 < end < 0.15                        # weaker: 1 % / tail level
    assert end == pytest.approx(0.01 / c.tail_level)


def test_explicit_window_settings_override_and_none():
    f, x = decaying_hit(sigma=0.0)
    c = choose_windows(f, x, 10000.0, WindowSettings(force_window_s=0.002, force_taper_s=0.0,
                                                     exp_tau_s=0.1), pretrigger_samples=90)
    assert (c.trigger_sample, c.force_window_s, c.force_taper_s, c.exp_tau_s) == \
        (90, 0.002, 0.0, 0.1)
    c = choose_windows(f, x, 10000.0, WindowSettings(exp_tau_s=math.inf))
    assert c.exp_tau_s is None
    c = choose_windows(f, x, 10000.0, NONE)
    w_f, w_x = c.arrays(len(f), 10000.0)
    assert np.all(w_f == 1.0) and np.all(w_x == 1.0)


@pytest.mark.parametrize("kwargs, field", [
    ({"force_window_s": 0.0}, "force_window_s"),
    ({"exp_tau_s": -1.0}, "exp_tau_s"),
    ({"force_taper_s": math.inf}, "force_taper_s"),
    ({"exp_end_fraction": 0.0}, "exp_end_fraction"),
])
def test_window_settings_validation_names_the_field(kwargs, field):
    with pytest.raises(ValueError, match=f"WindowSettings.{field}"):
        WindowSettings(**kwargs)


def test_windows_apply_to_force_and_response_as_documented():
    f, x = decaying_hit(sigma=0.0)
    rec = np.column_stack([f, x])[None]
    frf = frf_from_records(rec, 10000.0, window=WindowSettings(force_window_s=0.003,
                                                               exp_tau_s=0.05))
    choice = WindowChoice(101, 0.003, 0.2 * 0.003, 0.05)
    w_f, w_x = choice.arrays(len(f), 10000.0)
    s = spectral_sums(rec, 0, w_f, w_x)
    assert np.allclose(frf.H, s["Sfx"][0] / s["Sff"][0][:, None], rtol=1e-12)
    assert frf.exp_window_tau_s == 0.05 and frf.force_window_s == 0.003
    assert frf.trigger_s == pytest.approx(0.0101)


# --------------------------------------------------------------------------- groups, jackknife


def test_group_sums_layout_and_streaming_equals_array():
    rec, _ = random_records(7, 11, 40, 3, 0.2)
    frf = frf_from_records(rec, 100.0, window=NONE)
    gs = frf.group_sums
    G, F, R = 8, 21, 3
    assert gs["Sff"].shape == (G, F) and gs["Sxx"].shape == (G, F, R)
    assert gs["Sfx"].shape == (G, F, R) and gs["Sfx"].dtype == complex
    assert gs["n_hits"].tolist() == [2, 2, 2, 1, 1, 1, 1, 1]
    X = np.fft.rfft(rec, axis=1)
    assert np.allclose(gs["Sfx"][3], np.conj(X[3, :, :1]) * X[3, :, 1:], rtol=1e-12)
    assert np.allclose(gs["Sxx"][0], np.abs(X[0, :, 1:])**2 + np.abs(X[8, :, 1:])**2)
    for workers in (1, 2):
        streamed = frf_from_records((r for r in rec), 100.0, window=NONE, workers=workers)
        assert np.allclose(streamed.H, frf.H, rtol=1e-12)
        for k in gs:
            assert np.allclose(streamed.group_sums[k], gs[k], rtol=1e-12)


def test_threads_and_hit_rows_give_the_same_bits(tmp_path):
    """compute_frf over iter_hits (FFT threads, hits handed over as channel
    rows) equals frf_from_records over the plainly read records, bit for bit,
    for any number of workers: the sums are added in hit order."""
    from guidefit.hits import iter_hits
    from guidefit.io import RunData, read_hit, read_recording, write_recording

    rng = np.random.default_rng(21)
    fs, n, hits = 20_000.0, 3000, 11
    t = np.arange(n) / fs
    records = np.zeros((hits, n, 3), dtype=np.float32)
    for i in range(hits):
        force = np.where((t >= 0.005) & (t < 0.0055), np.sin(np.pi * (t - 0.005) / 5e-4), 0.0)
        records[i, :, 0] = (60 + 5 * i) * force + rng.normal(0, 0.05, n)
        ring = np.where(t >= 0.005, np.exp(-300 * (t - 0.005)) * np.sin(2 * np.pi * 900 * (t - 0.005)), 0)
        records[i, :, 1] = (2 + 0.1 * i) * ring + rng.normal(0, 0.01, n)
        records[i, :, 2] = (1 + 0.1 * i) * ring + rng.normal(0, 0.01, n)
    run = RunData("vertical", fs, [0, -1, 0], ["force", "acc_A_y", "acc_B_y"], ["N", "g", "m/s^2"],
                  [[0, 0, 0], [0.03, 0, 0.045], [-0.03, 0, 0.045]],
                  [[0, -1, 0], [0, 1, 0], [0, 1, 0]], data=records, layout="hits",
                  pretrigger_samples=100)
    write_recording(tmp_path / "hits.h5", run)
    stored = read_recording(tmp_path / "hits.h5").runs[0]
    plain = np.stack([read_hit(stored, i) for i in range(hits)])
    # float32 samples: FFTs in single precision by default ("auto"), double on request
    for precision, want_precision in (("auto", "single"), ("double", "double")):
        want = frf_from_records(plain, fs, pretrigger_samples=100, channel_names=stored.channel_names,
                                run="vertical", workers=1, precision=want_precision)
        assert want.exp_window_tau_s is not None and want.force_window_s is not None
        assert want.fft_precision == want_precision
        for workers in (1, 2, 3):
            got = compute_frf(stored, iter_hits(stored), workers=workers, precision=precision)
            assert got.n_averages == hits and got.fft_precision == want_precision
            np.testing.assert_array_equal(got.H, want.H)
            np.testing.assert_array_equal(got.coherence, want.coherence)
            for key in want.group_sums:
                np.testing.assert_array_equal(got.group_sums[key], want.group_sums[key])
        assert (got.exp_window_tau_s, got.force_window_s) == (want.exp_window_tau_s,
                                                              want.force_window_s)


def test_max_frequency_keeps_the_first_bins_unchanged(tmp_path):
    """FRFs that end at ``max_frequency_hz`` are the first bins of the whole ones:
    the same FFT, the same windows, the same sums bin by bin (to rounding)."""
    from guidefit.frf import kept_bins
    from guidefit.hits import iter_hits
    from guidefit.io import RunData, read_recording, write_recording

    rng = np.random.default_rng(5)
    fs, n, hits = 20_000.0, 4000, 9
    t = np.arange(n) / fs
    records = np.zeros((hits, n, 2), dtype=np.float32)
    for i in range(hits):
        records[i, :, 0] = (50 + 3 * i) * np.where((t >= 0.005) & (t < 0.0055),
                                                   np.sin(np.pi * (t - 0.005) / 5e-4), 0.0)
        records[i, :, 1] = np.where(t >= 0.005, np.exp(-200 * (t - 0.005)) * np.sin(2 * np.pi * 700 * (t - 0.005)), 0)
        records[i] += rng.normal(0, 0.01, (n, 2))
    run = RunData("vertical", fs, [0, -1, 0], ["force", "acc_A_y"], ["N", "m/s^2"],
                  [[0, 0, 0], [0.03, 0, 0.045]], [[0, -1, 0], [0, 1, 0]], data=records, layout="hits",
                  pretrigger_samples=100)
    write_recording(tmp_path / "hits.h5", run)
    stored = read_recording(tmp_path / "hits.h5").runs[0]
    whole = compute_frf(stored, iter_hits(stored))
    for workers in (1, 2):
        cut = compute_frf(stored, iter_hits(stored), workers=workers, max_frequency_hz=2_500.0)
        k = cut.frequency_hz.size
        assert k == kept_bins(n, fs, 2_500.0) == 501 and cut.frequency_hz[-1] == pytest.approx(2_500.0)
        np.testing.assert_allclose(cut.frequency_hz, whole.frequency_hz[:k], rtol=1e-15)
        np.testing.assert_allclose(cut.H, whole.H[:k], rtol=1e-12, atol=0)
        np.testing.assert_allclose(cut.coherence, whole.coherence[:k], rtol=1e-12, atol=1e-15)
        for key in ("Sff", "Sxx", "Sfx"):
            np.testing.assert_allclose(cut.group_sums[key], whole.group_sums[key][:, :k], rtol=1e-12, atol=0)
    assert kept_bins(n, fs, None) == kept_bins(n, fs, fs) == n // 2 + 1
    assert kept_bins(n, fs, 1e-9) == 2  # at least the DC bin and one more
    with pytest.raises(ValueError, match="max_frequency_hz"):
        compute_frf(stored, iter_hits(stored), max_frequency_hz=float("nan"))


@pytest.mark.parametrize("workers", [1, 2, 3])
def test_an_error_while_adding_a_block_is_raised(monkeypatch, workers):
    import guidefit.frf as frf_module

    add = frf_module._Accumulator.add
    calls = []

    def failing(self, Z, i0):
        calls.append(i0)
        if len(calls) == 3:
            raise MemoryError("no room for the sums")
        return add(self, Z, i0)

    monkeypatch.setattr(frf_module._Accumulator, "add", failing)
    rec = np.random.default_rng(0).normal(size=(20, 64, 3))
    with pytest.raises(MemoryError, match="no room"):
        frf_from_records(iter(rec), 100.0, window=NONE, workers=workers)


def test_force_in_any_column():
    rec, _ = random_records(8, 5, 32, 3, 0.2)
    moved = rec[:, :, [1, 2, 0, 3]]
    a = frf_from_records(rec, 1.0, channel_names=["f", "a", "b", "c"], window=NONE)
    b = frf_from_records(moved, 1.0, force_index=2, channel_names=["a", "b", "f", "c"],
                         window=NONE)
    assert a.channels == b.channels == ("a", "b", "c")
    assert np.allclose(a.H, b.H, rtol=1e-12) and np.allclose(a.coherence, b.coherence)


def test_fewer_hits_than_groups():
    rec, _ = random_records(9, 3, 32, 1, 0.2)
    frf = frf_from_records(rec, 1.0, window=NONE)
    assert frf.n_groups == 3 and frf.group_sums["n_hits"].tolist() == [1, 1, 1]
    one = frf_from_records(rec[:1], 1.0, window=NONE)
    assert one.n_groups == 1 and np.allclose(one.coherence, 1.0)
    jk = jackknife_frf(one, lambda s: np.abs(s.H[3, 0]))
    assert np.isnan(jk.std)
    with pytest.raises(ValueError, match="leave_one_group_out needs group sums of >= 2 groups"):
        list(one.leave_one_group_out())


def test_frfset_without_group_sums_says_so(tmp_path):
    pytest.importorskip("h5py")
    rec, _ = random_records(9, 3, 32, 1, 0.2)
    frf = frf_from_records(rec, 1.0, window=None, run="v")        # None: default windows
    write_frf_h5(tmp_path / "f.h5", frf, include_group_sums=False)
    (back,) = read_frf_h5(tmp_path / "f.h5")
    assert back.n_groups == 0 and np.array_equal(back.H, frf.H)
    with pytest.raises(ValueError, match="run 'v': jackknife_frf needs group sums"):
        jackknife_frf(back, lambda s: 0.0)
    with pytest.raises(ValueError, match="with_estimator needs group sums"):
        back.with_estimator("H2")


def test_leave_one_group_out_equals_recomputing_without_the_group():
    rec, _ = random_records(10, 13, 32, 2, 0.3)
    frf = frf_from_records(rec, 1.0, window=NONE, estimator="Hv", n_groups=4)
    loo = list(frf.leave_one_group_out())
    assert len(loo) == 4
    for g, sub in enumerate(loo):
        keep = [i for i in range(13) if i % 4 != g]
        ref = frf_from_records(rec[keep], 1.0, window=NONE, estimator="Hv")
        assert sub.n_averages == len(keep) and sub.estimator == "Hv"
        assert np.allclose(sub.H, ref.H, rtol=1e-10) and np.allclose(sub.coherence,
                                                                     ref.coherence)


def test_jackknife_equal_groups_is_textbook_and_std_matches_monte_carlo():
    # |H1| at a few bins: jackknife std and Bendat-Piersol H_std vs the spread
    # over independent repetitions of the whole experiment
    rng = np.random.default_rng(12)
    n, hits, reps = 64, 16, 150
    h = np.exp(-np.arange(8) / 2.0)
    bins = [3, 9, 17]
    values, jk_std, bp_std = [], [], []
    for _ in range(reps):
        force = rng.standard_normal((hits, n))
        resp = np.fft.irfft(np.fft.rfft(force, axis=1) * np.fft.rfft(h, n), n, axis=1)
        resp += 0.4 * rng.standard_normal(resp.shape)
        frf = frf_from_records(np.stack([force, resp], -1), 1.0, window=NONE)
        jk = jackknife_frf(frf, lambda s: np.abs(s.H[bins, 0]))
        values.append(jk.value)
        jk_std.append(jk.std)
        bp_std.append(frf.H_std[bins, 0])
    spread = np.std(values, axis=0, ddof=1)
    assert np.all(np.abs(np.mean(jk_std, axis=0) / spread - 1) < 0.35)
    assert np.all(np.abs(np.mean(bp_std, axis=0) / spread - 1) < 0.35)
    # equal groups: pseudovalues G theta - (G-1) theta_g, std = sd(pseudo)/sqrt(G)
    G = 8
    assert np.allclose(jk.pseudovalues, G * jk.value - (G - 1) * jk.replicates)
    assert np.allclose(jk.std, np.std(jk.pseudovalues, axis=0, ddof=1) / np.sqrt(G))
    assert np.allclose(jk.estimate, jk.pseudovalues.mean(axis=0))


def test_memory_is_bounded_never_all_hits():
    alive = []
    peak = [0]

    def hits():
        for _ in range(40):
            a = np.random.default_rng(1).standard_normal((256, 3))
            alive.append(weakref.ref(a))      # numpy arrays are freed by refcount
            peak[0] = max(peak[0], sum(r() is not None for r in alive))
            yield a
            del a

    frf = frf_from_records(hits(), 1000.0, window=NONE)
    assert frf.n_averages == 40
    assert peak[0] <= 3


# --------------------------------------------------------------------------- entrance


def make_run(name="vertical", n_channels=3, pretrigger=10):
    names = ["force"] + [f"acc_{p}_y" for p in "ABCD"[: n_channels - 1]]
    return NS(name=name, sample_rate_hz=1000.0, force_index=0, pretrigger_samples=pretrigger,
              channels=tuple(NS(name=n) for n in names))


def make_hit(index, data=None, accepted=True, reason=None):
    return NS(index=index, accepted=accepted, data=data, reason=reason)


def test_compute_frf_skips_rejected_hits_and_names_channels():
    rec, _ = random_records(13, 4, 64, 2, 0.1)
    hits = [make_hit(0, rec[0]), make_hit(1, None, False, "double_hit"),
            make_hit(2, rec[1]), make_hit(3, rec[2] * 0, False, "clipping"), make_hit(4, rec[3])]
    frf = compute_frf(make_run(), hits, window=NONE)
    ref = frf_from_records(rec[[0, 1, 3]], 1000.0, window=NONE)
    assert frf.channels == ("acc_A_y", "acc_B_y") and frf.run == "vertical"
    assert frf.n_averages == 3 and np.allclose(frf.H, ref.H, rtol=1e-12)


def test_no_accepted_hit_is_an_identification_error():
    hits = [make_hit(0, None, False, "double_hit"), make_hit(1, None, False, "double_hit"),
            make_hit(2, None, False, "clipping")]
    with pytest.raises(IdentificationError) as err:
        compute_frf(make_run("x"), hits)
    msg = str(err.value)
    assert msg.startswith("run 'x': no accepted hit")
    assert "clipping x1" in msg and "double_hit x2" in msg and "\n" not in msg
    with pytest.raises(IdentificationError, match="run 'x': no accepted hit"):
        compute_frf(make_run("x"), [])
    assert err.value.exit_code == 1


def test_mismatched_record_lengths_are_a_one_line_recording_error():
    hits = [make_hit(0, np.zeros((100, 3))), make_hit(7, np.zeros((90, 3)))]
    with pytest.raises(RecordingError) as err:
        compute_frf(make_run("lateral"), hits)
    assert str(err.value) == ("run 'lateral': hit 7 has 90 samples x 3 channels, "
                              "expected 100 x 3 as hit 0")
    with pytest.raises(RecordingError, match="hit 0 has 4 channels, the run declares 3"):
        compute_frf(make_run(), [make_hit(0, np.zeros((100, 4)))])
    with pytest.raises(RecordingError, match=r"hit 1 data has shape \(100,\)"):
        frf_from_records([np.zeros((100, 2)), np.zeros(100)], 1.0)
    with pytest.raises(RecordingError, match="force_index 5 out of range for 2 channels"):
        frf_from_records(np.zeros((1, 10, 2)), 1.0, force_index=5)
    with pytest.raises(ValueError, match="sample_rate_hz must be a positive number"):
        frf_from_records(np.zeros((1, 10, 2)), 0.0)
    with pytest.raises(ValueError, match="n_groups must be an integer >= 1"):
        frf_from_records(np.zeros((1, 10, 2)), 1.0, n_groups=0)


# --------------------------------------------------------------------------- FrfSet, export


@pytest.fixture
def two_runs():
    rec, _ = random_records(14, 5, 32, 2, 0.2)
    a = frf_from_records(rec, 100.0, channel_names=("force", "acc_A_y", "acc_B_y"),
                         run="vertical", window=WindowSettings(exp_tau_s=0.1))
    b = frf_from_records(rec[:, :, :2], 100.0, channel_names=("force", "acc_A_y"),
                         run="lateral", estimator="H2")
    return a, b


def test_frfset_is_frozen_and_arrays_read_only(two_runs):
    a, _ = two_runs
    with pytest.raises(AttributeError):
        a.estimator = "H2"
    with pytest.raises(ValueError):
        a.H[0, 0] = 1.0
    assert isinstance(a, FrfSet) and a.frequency_hz[1] == pytest.approx(100.0 / 32)


def test_to_frame_columns(two_runs):
    pd = pytest.importorskip("pandas")
    a, _ = two_runs
    df = a.to_frame()
    assert list(df.columns) == ["frequency_hz", "acc_A_y_re", "acc_A_y_im", "acc_A_y_coherence",
                                "acc_B_y_re", "acc_B_y_im", "acc_B_y_coherence"]
    assert isinstance(df, pd.DataFrame) and len(df) == 17
    assert np.array_equal(df["acc_B_y_im"].to_numpy(), a.H[:, 1].imag)


def test_csv_single_and_several_runs(tmp_path, two_runs):
    a, b = two_runs
    one = tmp_path / "one.csv"
    write_frf_csv(one, a)
    lines = one.read_text().splitlines()
    assert lines[0] == ("frequency_hz,acc_A_y_re,acc_A_y_im,acc_A_y_coherence,"
                        "acc_B_y_re,acc_B_y_im,acc_B_y_coherence")
    data = np.loadtxt(one, delimiter=",", skiprows=1)
    assert np.array_equal(data[:, 0], a.frequency_hz)
    assert np.array_equal(data[:, 1] + 1j * data[:, 2], a.H[:, 0])     # lossless
    assert np.array_equal(data[:, 6], a.coherence[:, 1])
    both = tmp_path / "both.csv"
    write_frf_csv(both, [a, b])
    lines = both.read_text().splitlines()
    assert lines[0].startswith("run,frequency_hz,acc_A_y_re")
    assert len(lines) == 1 + 17 + 17
    assert lines[1].startswith("vertical,0.0,") and lines[18].startswith("lateral,0.0,")
    assert lines[18].endswith(",,,")                  # lateral has no acc_B_y


def test_h5_round_trip(tmp_path, two_runs):
    h5py = pytest.importorskip("h5py")
    a, b = two_runs
    path = tmp_path / "frf.h5"
    write_frf_h5(path, [a, b])
    with h5py.File(path, "r") as f:
        g = f["frf/vertical"]
        assert set(g) == {"frequency_hz", "H", "coherence", "group_sums"}
        assert g.attrs["estimator"] == "H1" and g.attrs["n_averages"] == 5
        assert list(g.attrs["channels"]) == ["acc_A_y", "acc_B_y"]
        assert g.attrs["exp_window_tau_s"] == 0.1
        assert g["H"].dtype == complex and g["H"].shape == (17, 2)
    back = {s.run: s for s in read_frf_h5(path)}
    for orig in (a, b):
        r = back[orig.run]
        assert r.channels == orig.channels and r.estimator == orig.estimator
        assert np.array_equal(r.H, orig.H) and np.array_equal(r.coherence, orig.coherence)
        assert r.exp_window_tau_s == orig.exp_window_tau_s
        assert r.force_window_s == orig.force_window_s and r.n_averages == orig.n_averages
        assert np.array_equal(r.group_sums["Sfx"], orig.group_sums["Sfx"])
    assert back["vertical"].with_estimator("H2").H == pytest.approx(a.with_estimator("H2").H)
    with pytest.raises(ValueError, match="not usable as an HDF5 group"):
        write_frf_h5(tmp_path / "bad.h5", [a, a])


def test_memory_made_early_for_another_shape_is_not_used():
    """compute_frf makes the sums and buffers of a stored-hits run early, for
    (n_samples, n_channels) of the run; hits of another length must not use
    them, and the result must equal that of a run that announces nothing."""
    from types import SimpleNamespace as NS

    rng = np.random.default_rng(5)
    data = rng.normal(size=(6, 64, 2))
    data[:, 2:5, 0] += [[1.0, 3.0, 1.0]]
    hits = [NS(index=i, accepted=True, data=d, reason=None) for i, d in enumerate(data)]
    channels = (NS(name="force"), NS(name="acc_A_y"))
    base = dict(name="vertical", sample_rate_hz=1000.0, force_index=0, pretrigger_samples=2,
                channels=channels)
    announced = NS(**base, layout="hits", n_samples=128)  # says 128, the hits have 64
    plain = NS(**base)
    for workers in (1, 2):
        got = compute_frf(announced, hits, workers=workers)
        want = compute_frf(plain, hits, workers=workers)
        assert got.H.shape == (33, 1)
        np.testing.assert_array_equal(got.H, want.H)
        np.testing.assert_array_equal(got.group_sums["Sff"], want.group_sums["Sff"])


def test_large_runs_put_two_consecutive_hits_in_each_group(tmp_path):
    """A run of >= 4 G stored hits: hit i goes to group (i // 2) % G; each
    group's sums are those of its hits, the FRF is that of all hits, and the
    result is the same for any number of threads."""
    from guidefit.frf import PAIR_HITS_PER_GROUP, WindowSettings
    from guidefit.hits import iter_hits
    from guidefit.io import RunData, read_hit, read_recording, write_recording

    rng = np.random.default_rng(8)
    fs, n, G = 20_000.0, 512, 8
    hits = PAIR_HITS_PER_GROUP * G + 3  # 35: 17 pairs and one hit alone
    t = np.arange(n) / fs
    records = np.zeros((hits, n, 2), dtype=np.float32)
    for i in range(hits):
        force = np.where((t >= 0.002) & (t < 0.0025), np.sin(np.pi * (t - 0.002) / 5e-4), 0.0)
        records[i, :, 0] = (50 + i) * force + rng.normal(0, 0.05, n)
        ring = np.where(t >= 0.002, np.exp(-400 * (t - 0.002)) * np.sin(2 * np.pi * 900 * (t - 0.002)), 0)
        records[i, :, 1] = (1 + 0.02 * i) * ring + rng.normal(0, 0.01, n)
    run = RunData("vertical", fs, [0, -1, 0], ["force", "acc_A_y"], ["N", "m/s^2"],
                  [[0, 0, 0], [0.03, 0, 0.045]], [[0, -1, 0], [0, 1, 0]], data=records,
                  layout="hits", pretrigger_samples=40)
    write_recording(tmp_path / "many.h5", run)
    stored = read_recording(tmp_path / "many.h5").runs[0]
    paired = compute_frf(stored, iter_hits(stored), workers=1)
    assert paired.group_sums["n_hits"].tolist() == [6, 5, 4, 4, 4, 4, 4, 4]
    for workers in (2, 3):
        again = compute_frf(stored, iter_hits(stored), workers=workers)
        np.testing.assert_array_equal(again.H, paired.H)
        for key in paired.group_sums:
            np.testing.assert_array_equal(again.group_sums[key], paired.group_sums[key])
    # each hit in a group of its own, with the same windows: the pairs' sums are theirs
    plain = np.stack([read_hit(stored, i) for i in range(hits)])
    window = WindowSettings(force_window_s=paired.force_window_s, force_taper_s=paired.force_taper_s,
                            exp_tau_s=paired.exp_window_tau_s)
    single = frf_from_records(plain, fs, window=window, pretrigger_samples=40, n_groups=hits,
                              precision="single")
    for key in ("Sff", "Sxx", "Sfx"):
        per_hit = np.asarray(single.group_sums[key])
        want = np.stack([per_hit[[i for i in range(hits) if (i // 2) % G == g]].sum(axis=0)
                         for g in range(G)])
        np.testing.assert_allclose(paired.group_sums[key], want, rtol=1e-12,
                                   atol=1e-12 * np.abs(want).max())
    np.testing.assert_allclose(paired.H, single.H, rtol=1e-10)
    np.testing.assert_allclose(paired.coherence, single.coherence, rtol=1e-10, atol=1e-12)
