r"""Frequency response functions of impact-hammer hits: windows, H1/H2/Hv, coherence.

Every accepted hit is one record of ``n_samples`` samples of all channels, the
force channel plus R response (acceleration) channels. Each record is windowed,
transformed with one real FFT and reduced to three spectral sums per frequency
bin: the force auto-spectrum :math:`S_{ff} = \sum |F|^2`, the response
auto-spectra :math:`S_{xx} = \sum |X|^2` and the cross-spectra
:math:`S_{fx} = \sum \overline{F} X` (:math:`S_{xf} = \overline{S_{fx}}`). The sums
are unscaled (no 1/N, no density factor); every estimator below is a ratio and
does not depend on a common scale. From them, per response channel:

- ``H1`` :math:`= S_{fx}/S_{ff}`: unbiased by noise on the response, biased low
  (in magnitude) by noise on the force. The usual choice for hammer tests.
- ``H2`` :math:`= S_{xx}/S_{xf}`: unbiased by force noise, biased high by
  response noise.
- ``Hv``: total least squares. Per bin, the eigenvector
  :math:`v` of the 2 x 2 Hermitian matrix
  :math:`\begin{bmatrix} S_{ff} & S_{fx} \\ S_{xf} & S_{xx} \end{bmatrix}` with the
  smallest eigenvalue :math:`\lambda` gives :math:`H_v = -v_1/v_2`; in closed form
  :math:`H_v = S_{fx}/(S_{ff} - \lambda)`,
  :math:`\lambda = \tfrac12 (S_{ff}+S_{xx}) - \sqrt{\tfrac14 (S_{ff}-S_{xx})^2 + |S_{fx}|^2}`
  (Shin and Hammond [1]_). It assumes equal noise power on force and
  response *in their own units*, so unlike H1 and H2 it is not invariant to a
  rescaling of one channel when noise is present.
- ordinary coherence :math:`\gamma^2 = |S_{fx}|^2/(S_{ff} S_{xx}) \in [0, 1]`
  (:math:`= H_1/H_2`).

Because :math:`0 \le \lambda \le \min(S_{ff}, S_{xx})`, all three estimators share
the phase of :math:`S_{fx}` and :math:`|H_1| \le |H_v| \le |H_2|`, with equality
when :math:`\gamma^2 = 1` (noise-free data, or a single hit).

Responses are accelerations in m/s^2 and the force in N, so every FRF here is an
accelerance in (m/s^2)/N.

Windows
-------
Two windows, both functions of the time :math:`t = n/f_s` from the first sample
of the record (:func:`choose_windows` picks them, :class:`WindowSettings`
overrides them):

- a **force window** on the force channel only: 1 from the start of the record
  (the pretrigger, where the pulse starts, is kept) to ``force_window_s`` after
  the trigger, then a raised-cosine taper of ``force_taper_s`` down to 0, zero
  after. It removes the force channel's noise after the pulse. Default: open
  until the pulse has ended plus four pulse durations; taper 0.2 x that width.
- an **exponential window** :math:`e^{-t/\tau}` on *every* channel, force
  included. Since :math:`(h * f)(t)\, e^{-t/\tau} = (h e^{-t/\tau}) * (f e^{-t/\tau})`,
  the windowed FRF is exactly :math:`H(s + 1/\tau)`: the FRF of the same system
  with every pole moved left by :math:`\sigma_w = 1/\tau` (extra damping). Modal
  damping fitted to it must be corrected with
  :func:`exponential_window_damping_correction`. Default: the weakest window
  that brings the response at the end of the record down to
  ``exp_end_fraction`` (1 %) of its peak; if the response has already decayed
  below that inside the record, no exponential window.

pyFRF (ladisk/pyFRF) applies its exponential window to the response only; that
FRF is the windowed system's FRF times :math:`F(s)/F(s+\sigma_w)`, about
:math:`e^{t_p/\tau}` for a pulse at :math:`t_p` (0.4 % on its example data).

Averaging and uncertainty
-------------------------
Hit ``i`` (counting accepted hits from 0) is added to group ``i % G``, or,
in :func:`compute_frf` for a run of at least ``PAIR_HITS_PER_GROUP * G`` (32)
stored hits, to group ``(i // 2) % G`` (two consecutive hits per group turn:
every group still gets hits, and the group sums are read and written once
per two hits, the largest memory traffic of the engine); the
per-group sums (``FrfSet.group_sums``) allow a delete-a-group jackknife
(:func:`jackknife_frf`, :meth:`FrfSet.leave_one_group_out`) of any quantity
derived from the FRFs. Memory is O(G F R) whatever the number of hits: hits are
consumed from an iterator a few at a time and never all held.
:attr:`FrfSet.H_std` gives the quick Bendat and Piersol random error of
:math:`|H|` from the coherence [2]_.

Precision
---------
The FFT computes in the precision the samples were stored in
(``precision="auto"``, the default): in single precision (``float32`` in,
``complex64`` out) when the file stores ``float32`` (or ``float16``, or
integers of at most 16 bits), else in double precision. Only the FFT is
single: its spectra are converted to ``complex128`` before the products, the
spectral sums are ``float64``, and so are H, the coherence and everything
after them. A float32 sample already carries a relative rounding error of up
to :math:`2^{-24} \approx 6 \times 10^{-8}`; a float32 FFT of length
:math:`n` adds an error of the same kind, about :math:`\sqrt{\log_2 n}` times
larger (4x at n = 100 000): both lie some 130 dB below the record's RMS, far
below the noise floor of any hammer-test chain (a 24-bit DAQ reaches about
-110 dB). Measured on simulated float32 recordings
(``tests/test_frf_precision.py``, docs/frf.md, 8 seeds): single and double
precision give identified frequencies and stiffnesses within 4e-9 relative,
damping ratios and dampings within 2e-8, and FRFs that differ by a median
3e-5 (at most 2e-3) of their own random error. ``precision="double"`` forces
float64 FFTs (about 1.3x the FFT time); float64 files are always transformed
in double precision. ``FrfSet.fft_precision`` says which was used.

References
----------
.. [1] K. Shin and J. K. Hammond, *Fundamentals of Signal Processing for Sound
   and Vibration Engineers*, Wiley, 2008, Ch. 9 (the H1, H2 and Hv estimators).
.. [2] J. S. Bendat and A. G. Piersol, *Random Data: Analysis and Measurement
   Procedures*, 4th ed., Wiley, 2010, Ch. 9 (random error of gain-factor
   estimates).
.. [3] M. A. Busing, E. Meijer and R. van der Leeden, "Delete-m jackknife for
   unequal m", *Statistics and Computing* 9 (1999) 3-8.

Examples
--------
A force pulse through a known filter, eight hits, no windows:

>>> import numpy as np
>>> from guidefit.frf import WindowSettings, frf_from_records
>>> rng = np.random.default_rng(0)
>>> force = np.zeros((8, 256)); force[:, 4] = rng.uniform(50, 80, 8); force[:, 5] = 30.0
>>> response = 2.0 * np.roll(force, 3, axis=1)       # H = 2 exp(-3 j w dt)
>>> records = np.stack([force, response], axis=-1)  # (hits, samples, channels)
>>> frf = frf_from_records(records, 1000.0, channel_names=("force", "acc_A_y"),
...                        window=WindowSettings(none=True))
>>> frf.channels, frf.H.shape, frf.n_averages
(('acc_A_y',), (129, 1), 8)
>>> bool(np.allclose(np.abs(frf.H), 2.0)), bool(np.allclose(frf.coherence, 1.0))
(True, True)
"""

from __future__ import annotations

import math
import threading
import warnings
from collections import Counter
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from guidefit.errors import IdentificationError, RecordingError

__all__ = [
    "ESTIMATORS",
    "PRECISIONS",
    "FrfSet",
    "JackknifeResult",
    "WindowChoice",
    "WindowSettings",
    "choose_windows",
    "coherence_from_sums",
    "compute_frf",
    "estimate_frf",
    "exponential_window",
    "exponential_window_damping_correction",
    "fft_dtype",
    "force_window",
    "frf_from_records",
    "jackknife_frf",
    "read_frf_h5",
    "spectral_sums",
    "write_frf_csv",
    "write_frf_h5",
]

#: Default number of jackknife groups (fewer when there are fewer hits).
DEFAULT_GROUPS = 8
#: Threshold, as a fraction of the peak force, that delimits the force pulse.
PULSE_THRESHOLD = 0.05
#: The force window stays open this many pulse durations after the pulse ends.
FORCE_WINDOW_PULSES_AFTER = 4.0
#: Default taper of the force window as a fraction of its width.
FORCE_TAPER_FRACTION = 0.2
#: Tail of the record (fraction of its length) whose level sets the exponential window.
TAIL_FRACTION = 0.05
#: Default windows are chosen from the first (up to) this many records, at most
#: ``_WINDOW_BYTES`` of them (as float64), at least one.
_WINDOW_HITS = 4
_WINDOW_BYTES = 64 * 2**20
#: Hits per FFT call are limited so that one block of input stays below this size.
_BLOCK_BYTES = 16 * 2**20
_MAX_BLOCK_HITS = 2
#: Frequency bins per chunk of the spectral products (keeps temporaries in cache).
_CHUNK_BINS = 16384
#: FFT precisions: ``"auto"`` (that of the stored samples), ``"single"``, ``"double"``.
PRECISIONS = ("auto", "single", "double")


def fft_dtype(precision: str = "auto", sample_dtype=np.float64) -> type:
    """The real dtype the FFTs compute in: ``numpy.float32`` or ``numpy.float64``.

    ``"auto"``: single precision when the stored samples carry no more than
    float32's 24-bit significand (float16 and float32, integers of at most
    16 bits), else double. See "Precision" in the module docstring.

    Examples
    --------
    >>> import numpy as np
    >>> [fft_dtype("auto", d).__name__ for d in (np.float32, np.int16, np.int32, np.float64)]
    ['float32', 'float32', 'float64', 'float64']
    >>> fft_dtype("double", np.float32).__name__
    'float64'
    """
    if precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {', '.join(PRECISIONS)}; got {precision!r}")
    if precision == "auto":
        dt = np.dtype(sample_dtype)
        narrow = (dt.kind == "f" and dt.itemsize <= 4) or (dt.kind in "iub" and dt.itemsize <= 2)
        return np.float32 if narrow else np.float64
    return np.float32 if precision == "single" else np.float64


def _precision_name(dtype) -> str:
    return "single" if np.dtype(dtype) == np.float32 else "double"


# --------------------------------------------------------------------------- estimators


def _h1(sff, sxx, sfx):
    return sfx / sff[..., None]


def _h2(sff, sxx, sfx):
    return sxx / np.conj(sfx)


def _hv(sff, sxx, sfx):
    # H = Sfx / (Sff - lam_min); Sff - lam_min = d + r with d = (Sff - Sxx)/2,
    # r = sqrt(d^2 + |Sfx|^2). For d < 0 use the cancellation-free d + r = |Sfx|^2/(r - d).
    d = 0.5 * (sff[..., None] - sxx)
    b2 = sfx.real**2 + sfx.imag**2
    r = np.sqrt(d * d + b2)
    denom = np.where(d >= 0, d + r, b2 / np.where(d >= 0, 1.0, r - d))
    return sfx / denom


#: The FRF estimators by name; each maps (Sff (..., F), Sxx (..., F, R), Sfx) -> H.
ESTIMATORS: dict[str, Callable] = {"H1": _h1, "H2": _h2, "Hv": _hv}


def _check_estimator(estimator: str) -> str:
    if estimator not in ESTIMATORS:
        raise ValueError(
            f"estimator {estimator!r} unknown; use one of {', '.join(ESTIMATORS)}"
        )
    return estimator


def estimate_frf(sff, sxx, sfx, estimator: str = "H1") -> np.ndarray:
    """FRF estimate per response channel from spectral sums.

    Parameters
    ----------
    sff : array_like, shape (F,)
        Force auto-spectrum (real, any common scale).
    sxx : array_like, shape (F, R)
        Response auto-spectra (real).
    sfx : array_like, shape (F, R)
        Cross-spectra :math:`\\sum \\overline{F} X` (complex).
    estimator : {"H1", "H2", "Hv"}
        See the module docstring.

    Returns
    -------
    numpy.ndarray, shape (F, R), complex
        NaN where the estimator is undefined (a zero denominator).

    Examples
    --------
    One bin, force spectrum 2, response 6j plus uncorrelated response noise
    (power 4); the true H is 3j:

    >>> import numpy as np
    >>> sff = np.array([4.0]); sxx = np.array([[36.0 + 4.0]]); sfx = np.array([[2 * 6j]])
    >>> [round(float(estimate_frf(sff, sxx, sfx, e)[0, 0].imag), 4) for e in ESTIMATORS]
    [3.0, 3.3333, 3.3028]
    """
    fn = ESTIMATORS[_check_estimator(estimator)]
    with np.errstate(divide="ignore", invalid="ignore"):
        return fn(np.asarray(sff, dtype=float), np.asarray(sxx, dtype=float),
                  np.asarray(sfx, dtype=complex))


def coherence_from_sums(sff, sxx, sfx) -> np.ndarray:
    """Ordinary coherence :math:`|S_{fx}|^2 / (S_{ff} S_{xx})`, clipped to [0, 1].

    Parameters
    ----------
    sff, sxx, sfx : array_like
        As in :func:`estimate_frf`.

    Returns
    -------
    numpy.ndarray, shape (F, R), float
        NaN where :math:`S_{ff} S_{xx} = 0`.

    Examples
    --------
    >>> import numpy as np
    >>> float(coherence_from_sums(np.array([4.0]), np.array([[40.0]]), np.array([[12j]]))[0, 0])
    0.9
    """
    sff = np.asarray(sff, dtype=float)
    sxx = np.asarray(sxx, dtype=float)
    sfx = np.asarray(sfx, dtype=complex)
    with np.errstate(divide="ignore", invalid="ignore"):
        g2 = (sfx.real**2 + sfx.imag**2) / (sff[..., None] * sxx)
    return np.clip(g2, 0.0, 1.0)


# --------------------------------------------------------------------------- windows


@dataclass(frozen=True)
class WindowSettings:
    """How to window each hit record; ``None`` fields are chosen from the data.

    Parameters
    ----------
    force_window_s : float or None
        Width in s of the force window's flat part, counted from the trigger
        (the pretrigger before it is always kept). ``None``: until the pulse end
        plus four pulse durations. ``math.inf``: no force window.
    force_taper_s : float or None
        Raised-cosine taper after the flat part, in s. ``None``: 0.2 x the width.
        ``0``: a hard cut (pyFRF's ``'force:...'`` window).
    exp_tau_s : float or None
        Time constant of the exponential window :math:`e^{-t/\\tau}`, applied to
        force and responses. ``None``: chosen by ``exp_end_fraction``.
        ``math.inf``: no exponential window.
    exp_end_fraction : float
        With ``exp_tau_s=None``, the strongest window is the one that falls to this
        value at the last sample; a weaker one is used when the response has
        decayed inside the record (its end level times the window then equals
        this fraction of its peak), none when it is already below it.
    none : bool
        No windows at all (every sample weighted 1); overrides the rest.

    Examples
    --------
    >>> WindowSettings(force_window_s=0.002, exp_tau_s=0.05)  # doctest: +ELLIPSIS
    WindowSettings(force_window_s=0.002, force_taper_s=None, exp_tau_s=0.05, ...)
    >>> WindowSettings(exp_end_fraction=2.0)
    Traceback (most recent call last):
    ...
    ValueError: WindowSettings.exp_end_fraction must be in (0, 1], got 2.0
    """

    force_window_s: float | None = None
    force_taper_s: float | None = None
    exp_tau_s: float | None = None
    exp_end_fraction: float = 0.01
    none: bool = False

    def __post_init__(self):
        for name in ("force_window_s", "exp_tau_s"):
            value = getattr(self, name)
            if value is not None and not value > 0:
                raise ValueError(f"WindowSettings.{name} must be > 0 or None, got {value!r}")
        taper = self.force_taper_s
        if taper is not None and not (taper >= 0 and math.isfinite(taper)):
            raise ValueError(
                f"WindowSettings.force_taper_s must be finite and >= 0 or None, got {taper!r}"
            )
        if not 0 < self.exp_end_fraction <= 1:
            raise ValueError(
                f"WindowSettings.exp_end_fraction must be in (0, 1], got {self.exp_end_fraction!r}"
            )


@dataclass(frozen=True)
class WindowChoice:
    """The windows actually applied (settings resolved against the data).

    Attributes
    ----------
    trigger_sample : int
        Sample of the record where the force window's width is counted from.
    force_window_s : float or None
        Flat width after the trigger; ``None``: no force window.
    force_taper_s : float
        Raised-cosine taper after the flat part.
    exp_tau_s : float or None
        Exponential-window time constant; ``None``: no exponential window.
    pulse_duration_s : float or None
        Estimated force pulse duration (diagnostic; ``None`` if not estimated).
    tail_level : float or None
        Largest |x - mean| over the last 5 % of the record / peak |x| of the
        record, worst response channel, median over the hits looked at
        (diagnostic; sets the default exponential window).
    """

    trigger_sample: int
    force_window_s: float | None
    force_taper_s: float
    exp_tau_s: float | None
    pulse_duration_s: float | None = None
    tail_level: float | None = None

    def arrays(self, n_samples: int, sample_rate_hz: float) -> tuple[np.ndarray, np.ndarray]:
        """Window arrays ``(w_force, w_response)``, each shape ``(n_samples,)``.

        ``w_force`` is the force window times the exponential window.

        Examples
        --------
        >>> w_f, w_x = WindowChoice(2, 0.003, 0.0, None).arrays(8, 1000.0)
        >>> w_f.tolist(), w_x.tolist()
        ([1.0, 1.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0], [1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0])
        """
        w_exp = exponential_window(n_samples, sample_rate_hz, self.exp_tau_s)
        w_force = force_window(
            n_samples, sample_rate_hz, self.force_window_s, self.trigger_sample, self.force_taper_s
        )
        return w_force * w_exp, w_exp


def force_window(
    n_samples: int,
    sample_rate_hz: float,
    width_s: float | None,
    trigger_sample: int = 0,
    taper_s: float = 0.0,
) -> np.ndarray:
    """Force window: 1 up to ``width_s`` after the trigger, cosine taper, then 0.

    Parameters
    ----------
    n_samples : int
        Record length.
    sample_rate_hz : float
        Sample rate in Hz.
    width_s : float or None
        Flat part after ``trigger_sample`` in s (rounded to whole samples);
        ``None`` or ``inf``: no window (all ones).
    trigger_sample : int
        Samples before the trigger; they are all kept (weight 1).
    taper_s : float
        Length of the raised-cosine taper from 1 to 0 after the flat part, in s;
        ``0`` for a hard cut.

    Returns
    -------
    numpy.ndarray, shape (n_samples,)

    Examples
    --------
    >>> force_window(10, 1000.0, 0.003, trigger_sample=2, taper_s=0.003).round(3).tolist()
    [1.0, 1.0, 1.0, 1.0, 1.0, 0.854, 0.5, 0.146, 0.0, 0.0]
    """
    if width_s is None or math.isinf(width_s):
        return np.ones(n_samples)
    w = np.zeros(n_samples)
    flat = min(n_samples, max(0, int(trigger_sample)) + round(float(width_s) * sample_rate_hz))
    w[:flat] = 1.0
    m = round(float(taper_s) * sample_rate_hz)
    if m > 0 and flat < n_samples:
        taper = 0.5 * (1.0 + np.cos(np.pi * np.arange(1, m + 1) / (m + 1)))
        k = min(m, n_samples - flat)
        w[flat:flat + k] = taper[:k]
    return w


def exponential_window(n_samples: int, sample_rate_hz: float, tau_s: float | None) -> np.ndarray:
    """Exponential window :math:`e^{-t/\\tau}`, :math:`t = n / f_s` from the record start.

    Parameters
    ----------
    n_samples : int
        Record length.
    sample_rate_hz : float
        Sample rate in Hz.
    tau_s : float or None
        Time constant in s; ``None`` or ``inf``: all ones.

    Returns
    -------
    numpy.ndarray, shape (n_samples,)

    Examples
    --------
    pyFRF's ``'exponential:0.01'`` (1 % at the last sample) over 1 s at 100 Hz:

    >>> import math
    >>> w = exponential_window(100, 100.0, 0.99 / math.log(100))
    >>> round(float(w[0]), 6), round(float(w[-1]), 6)
    (1.0, 0.01)
    """
    if tau_s is None or math.isinf(tau_s):
        return np.ones(n_samples)
    return np.exp(-np.arange(n_samples) / (sample_rate_hz * tau_s))


def _pulse_extent(force: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Start (inclusive) and end (exclusive) sample of the main pulse, per row."""
    n = force.shape[1]
    starts, ends = [], []
    for f in force:
        f = f - _force_offset(f, f)  # an offset (sensor bias) is not part of the pulse
        hi, lo = int(np.argmax(f)), int(np.argmin(f))
        p, sign = (hi, 1.0) if f[hi] >= -f[lo] else (lo, -1.0)
        below = sign * f <= PULSE_THRESHOLD * sign * f[p]
        left = np.flatnonzero(below[:p])
        right = np.flatnonzero(below[p + 1:])
        starts.append(left[-1] + 1 if left.size else 0)
        ends.append(p + 1 + right[0] if right.size else n)
    return np.array(starts), np.array(ends)


def choose_windows(
    force,
    responses,
    sample_rate_hz: float,
    settings: WindowSettings = WindowSettings(),
    pretrigger_samples: int | None = None,
) -> WindowChoice:
    """Resolve :class:`WindowSettings` against (a few) hit records.

    Parameters
    ----------
    force : array_like, shape (n_hits, n_samples) or (n_samples,)
        Force records in N.
    responses : array_like, shape (n_hits, n_samples, R) or (n_samples, R)
        Response records.
    sample_rate_hz : float
        Sample rate in Hz.
    settings : WindowSettings
        Explicit values win; ``None`` fields are estimated (rules in
        :class:`WindowSettings`): the pulse runs between the samples where the
        force crosses 5 % of its peak; the response end level is the largest
        |x - mean| over the last 5 % of the record relative to the record's peak
        |x| (worst channel); medians over the hits given.
    pretrigger_samples : int or None
        Trigger position; ``None``: the detected pulse start.

    Returns
    -------
    WindowChoice

    Examples
    --------
    A 10-sample pulse at sample 50 and a response that never decays:

    >>> import numpy as np
    >>> f = np.zeros(1000); f[50:60] = np.sin(np.pi * (np.arange(10) + 0.5) / 10)
    >>> x = np.sin(0.3 * np.arange(1000))[:, None]
    >>> c = choose_windows(f, x, 1000.0)
    >>> c.trigger_sample, round(c.pulse_duration_s, 3), round(c.force_window_s, 3)
    (50, 0.01, 0.05)
    >>> round(float(np.exp(-0.999 / c.exp_tau_s)), 4)   # window at the last sample
    0.01
    """
    force = np.asarray(force, dtype=float)
    responses = np.asarray(responses, dtype=float)
    if force.ndim == 1:
        force = force[None]
        responses = responses[None]
    if responses.ndim == 2:
        responses = responses[..., None]
    return _choose(force, np.swapaxes(responses, 1, 2), sample_rate_hz, settings,
                   pretrigger_samples)


def _choose(force, responses, sample_rate_hz, settings, pretrigger_samples) -> WindowChoice:
    """:func:`choose_windows` on force (hits, n) and responses (hits, R, n) rows."""
    n = force.shape[-1]
    fs = float(sample_rate_hz)
    if settings.none:
        return WindowChoice(int(pretrigger_samples or 0), None, 0.0, None)

    pulse_s = None
    if settings.force_window_s is None or pretrigger_samples is None:
        starts, ends = _pulse_extent(force)
        start = int(np.median(starts))
        end = int(np.median(ends))
        dur = max(1, int(np.median(ends - starts)))
        pulse_s = dur / fs
    trig = int(pretrigger_samples) if pretrigger_samples is not None else start
    if settings.force_window_s is None:
        flat_end = end + FORCE_WINDOW_PULSES_AFTER * dur
        width = max(flat_end - trig, dur) / fs
    else:
        width = settings.force_window_s
    if math.isinf(width):
        width, taper = None, 0.0
    else:
        taper = (settings.force_taper_s if settings.force_taper_s is not None
                 else FORCE_TAPER_FRACTION * width)

    tail = None
    if settings.exp_tau_s is not None:
        tau = None if math.isinf(settings.exp_tau_s) else float(settings.exp_tau_s)
    else:
        m = max(1, round(TAIL_FRACTION * n))
        # max/min reductions along contiguous rows, no temporaries of the record's size
        peak = np.maximum(responses.max(axis=-1), -responses.min(axis=-1))     # (hits, R)
        tail_x = responses[..., -m:]
        tail_x = tail_x - tail_x.mean(axis=-1, keepdims=True)
        dev = np.maximum(tail_x.max(axis=-1), -tail_x.min(axis=-1))
        with np.errstate(divide="ignore", invalid="ignore"):
            level = np.nan_to_num(dev / peak, nan=0.0)
        tail = float(np.median(np.max(level, axis=1)))
        frac = settings.exp_end_fraction
        end_value = 1.0 if tail <= frac else max(frac, frac / tail)
        if end_value >= 1.0 or n < 2:
            tau = None
        else:
            tau = ((n - 1) / fs) / math.log(1.0 / end_value)
    return WindowChoice(trig, width, float(taper), tau, pulse_s, tail)


def exponential_window_damping_correction(zeta_measured, f_n_hz, tau_s):
    """Undo the extra damping of an exponential window (exact pole shift).

    The window :math:`e^{-t/\\tau}` moves every pole by :math:`-\\sigma_w`,
    :math:`\\sigma_w = 1/\\tau`: :math:`p_{meas} = p_{true} - \\sigma_w`, the damped
    frequency :math:`\\omega_d` unchanged. From a measured undamped natural
    frequency :math:`\\omega_n = 2\\pi f_n` (= \\|pole\\|) and damping ratio
    :math:`\\zeta`: :math:`\\sigma_{true} = \\zeta\\omega_n - 1/\\tau`,
    :math:`\\omega_d = \\omega_n\\sqrt{1-\\zeta^2}`,
    :math:`\\omega_{n,true} = \\sqrt{\\sigma_{true}^2 + \\omega_d^2}`,
    :math:`\\zeta_{true} = \\sigma_{true}/\\omega_{n,true}`.

    Parameters
    ----------
    zeta_measured : float or array_like
        Damping ratio fitted to the windowed FRF.
    f_n_hz : float or array_like
        Undamped natural frequency fitted to the windowed FRF, in Hz.
    tau_s : float or None
        The window's time constant in s (``FrfSet.exp_window_tau_s``); ``None``
        or ``inf``: no window, the inputs are returned.

    Returns
    -------
    f_n_true_hz, zeta_true : float or numpy.ndarray
        A negative ``zeta_true`` (the window's damping exceeds the measured one:
        a bad fit) is returned as is, with a warning.

    Examples
    --------
    A 1 kHz mode with 1 % damping seen through a window with tau = 10 ms:

    >>> import math
    >>> sigma = 0.01 * 2 * math.pi * 1000 + 1 / 0.01        # measured decay rate
    >>> w_d = 2 * math.pi * 1000 * math.sqrt(1 - 0.01**2)
    >>> w_n = math.hypot(sigma, w_d)
    >>> f, z = exponential_window_damping_correction(sigma / w_n, w_n / (2 * math.pi), 0.01)
    >>> round(float(f), 9), round(float(z), 12)
    (1000.0, 0.01)
    """
    zeta = np.asarray(zeta_measured, dtype=float)
    f_n = np.asarray(f_n_hz, dtype=float)
    if tau_s is None or math.isinf(tau_s):
        return f_n[()], zeta[()]
    w_n = 2.0 * np.pi * f_n
    sigma = zeta * w_n - 1.0 / float(tau_s)
    w_d = w_n * np.sqrt(np.clip(1.0 - zeta * zeta, 0.0, None))
    w_true = np.hypot(sigma, w_d)
    zeta_true = sigma / w_true
    if np.any(zeta_true < 0):
        warnings.warn(
            f"exponential-window correction gives negative damping (tau_s={tau_s}): "
            "the measured damping is below the window's 1/tau",
            stacklevel=2,
        )
    return (w_true / (2.0 * np.pi))[()], zeta_true[()]


# --------------------------------------------------------------------------- accumulation


def _group_runs(i0: int, n: int, n_groups: int, pair: int = 1):
    """Split hits i0..i0+n-1 into runs (j0, j1, g0): hit i goes to group
    ``(i // pair) % n_groups``; with ``pair=1`` a run is consecutive hits in
    consecutive, distinct groups, with ``pair=2`` one or two hits of one group."""
    j = 0
    while j < n:
        if pair == 1:
            g0 = (i0 + j) % n_groups
            m = min(n - j, n_groups - g0)
        else:
            g0 = ((i0 + j) // pair) % n_groups
            m = min(n - j, pair - (i0 + j) % pair)
        yield j, j + m, g0
        j += m


#: Runs of at least this many stored hits per jackknife group put two consecutive hits
#: in each group (``pair=2``): every group still gets hits, and the group sums, the
#: largest memory traffic of the engine, are read and written once per two hits.
PAIR_HITS_PER_GROUP = 4


def _response_index(force_index: int, n_channels: int):
    """Index of the response channels: a slice when they are contiguous."""
    if force_index == 0:
        return slice(1, n_channels)
    if force_index == n_channels - 1:
        return slice(0, n_channels - 1)
    return np.array([k for k in range(n_channels) if k != force_index])


class _Accumulator:
    """Per-group spectral sums; blocks of windowed records in, sums out.

    Internal layout is (G, R, F) (frequency contiguous, matching the FFT output);
    :meth:`group_sums` exposes (G, F, R) views.
    """

    def __init__(self, n_samples, n_channels, force_index, n_groups, workers, pair=1, n_bins=None):
        self.n = n_samples
        self.c = n_channels
        self.fi = force_index
        self.n_groups = n_groups
        self.pair = pair
        self.workers = workers
        self.F = n_samples // 2 + 1 if n_bins is None else min(n_samples // 2 + 1, n_bins)
        self.resp = _response_index(force_index, n_channels)
        r = n_channels - 1
        self.sff = np.zeros((n_groups, self.F))
        self.sxx = np.zeros((n_groups, r, self.F))
        self.sfx = np.zeros((n_groups, r, self.F), dtype=complex)
        self.counts = np.zeros(n_groups, dtype=np.int64)
        self.n_hits = 0
        self._bufs = None

    def add(self, Z: np.ndarray, i0: int) -> None:
        """Add the spectra ``Z`` (n, C, >= F) of hits i0..i0+n-1 (their first F bins)."""
        n = Z.shape[0]
        ch = min(_CHUNK_BINS, self.F)
        if self._bufs is None or self._bufs[0].shape[0] < n:
            r = self.c - 1
            self._bufs = (np.empty((n, self.c, ch)), np.empty((n, self.c, ch)),
                          np.empty((n, ch), dtype=complex), np.empty((n, r, ch), dtype=complex),
                          np.empty((n, self.c, ch), dtype=complex))
        sq, tmp, fcb, pcb, up = self._bufs
        single = Z.dtype != np.complex128  # complex64 spectra: products and sums in float64
        runs = list(_group_runs(i0, n, self.n_groups, self.pair))
        fi, resp = self.fi, self.resp
        for a in range(0, self.F, ch):
            b = min(a + ch, self.F)
            m = b - a
            z = Z[:, :, a:b]
            if single:
                z = np.copyto(up[:n, :, :m], z) or up[:n, :, :m]
            s, t = sq[:n, :, :m], tmp[:n, :, :m]
            np.multiply(z.real, z.real, out=s)
            np.multiply(z.imag, z.imag, out=t)
            s += t
            fc = fcb[:n, :m]
            np.conjugate(z[:, fi], out=fc)
            p = pcb[:n, :, :m]
            np.multiply(z[:, resp], fc[:, None, :], out=p)
            if self.pair == 1:
                for j0, j1, g0 in runs:
                    g1 = g0 + j1 - j0
                    self.sff[g0:g1, a:b] += s[j0:j1, fi]
                    self.sxx[g0:g1, :, a:b] += s[j0:j1, resp]
                    self.sfx[g0:g1, :, a:b] += p[j0:j1]
                continue
            for j0, j1, g0 in runs:  # one group per run: its hits summed here, then added once
                for j in range(j0 + 1, j1):
                    s[j0] += s[j]
                    p[j0] += p[j]
                self.sff[g0, a:b] += s[j0, fi]
                self.sxx[g0, :, a:b] += s[j0, resp]
                self.sfx[g0, :, a:b] += p[j0]
        for j0, j1, g0 in runs:
            if self.pair == 1:
                self.counts[g0:g0 + j1 - j0] += 1
            else:
                self.counts[g0] += j1 - j0

    def group_sums(self) -> dict:
        g = min(self.n_groups, -(-self.n_hits // self.pair))  # the groups that got a hit
        return {
            "Sff": _readonly(self.sff[:g]),
            "Sxx": _readonly(self.sxx[:g].transpose(0, 2, 1)),
            "Sfx": _readonly(self.sfx[:g].transpose(0, 2, 1)),
            "n_hits": _readonly(self.counts[:g].copy()),
        }


FORCE_OFFSET_FRACTION = 0.002  # a force median beyond 0.2 % of the peak there is a sensor bias, removed


def _force_offset(quiet_force: np.ndarray, pulse_force: np.ndarray) -> float:
    """The force offset: the median of ``quiet_force`` (samples where the hammer pushes nothing)
    if beyond 0.2 % of the peak of ``pulse_force``, else 0.

    Smaller offsets are noise-level (and AC-coupled amplifiers drift that much after a hit), left as
    they are; a larger one is a bias whose windowed rectangle would add to the force spectrum.
    """
    from guidefit.hits import _median  # np.median's value for finite samples, 3x faster on a record

    quiet_force = np.ascontiguousarray(quiet_force, dtype=float)
    finite = np.isfinite(quiet_force).all()
    base = float(_median(quiet_force) if finite else np.median(quiet_force))
    return base if abs(base) > FORCE_OFFSET_FRACTION * max(float(pulse_force.max()), -float(pulse_force.min())) else 0.0


class _Buffers:
    """The memory of one :func:`_run_blocks` call: sums, block buffers, first records.

    ``touch``: write every page now (the first touch of fresh memory costs a
    page fault per 4 kB, about 60 MB here), so that a thread with nothing
    else to do can pay for it while another one reads the first pass over
    the force.
    """

    def __init__(self, n, c, dtype, force_index, n_groups, workers, pair=1, touch=False, n_bins=None):
        self.key = (n, c, np.dtype(dtype), force_index, n_groups, workers, pair, n_bins)
        self.n_first = max(1, min(_WINDOW_HITS, _WINDOW_BYTES // (8 * n * c)))
        self.block = _block_size(n, c)
        self.n_bufs = workers + 1 if workers > 1 else 1  # one being filled, one per helper, one queued
        if dtype == np.float64:  # the first records straight into the block buffers
            self.space = np.empty((max(self.n_bufs * self.block, self.n_first), c, n))
            self.first = self.space[:self.n_first]
        else:  # the windows are chosen from float64 copies, then rounded into the buffers
            self.first = np.empty((self.n_first, c, n))
            self.space = np.empty((self.n_bufs * self.block, c, n), dtype=dtype)
        self.acc = _Accumulator(n, c, force_index, n_groups, workers, pair, n_bins)
        if touch:
            for a in (self.space, self.first, self.acc.sff, self.acc.sxx, self.acc.sfx):
                a.fill(0)


def _early_buffers(expect, precision, force_index, n_groups, workers, pair=1, n_bins=None):
    """:class:`_Buffers` for records of shape ``expect`` (n_samples, n_channels), made and
    touched by a thread of their own while the caller goes on; ``None`` when there is
    nothing to expect or no second thread. ``.result()`` waits for them."""
    if expect is None or workers < 2:
        return None
    from concurrent.futures import ThreadPoolExecutor

    n, c = (int(v) for v in expect)
    pool = ThreadPoolExecutor(max_workers=1)
    future = pool.submit(_Buffers, n, c, fft_dtype(precision), force_index, n_groups, workers, pair,
                         True, None if n_bins is None else n_bins(n))
    pool.shutdown(wait=False)  # the thread ends with the job
    return future


def _run_blocks(items: Iterator[tuple[str, np.ndarray]], force_index: int, windows,
                n_groups: int, workers: int, force_offset: bool = False,
                precision: str = "auto", expect=None, pair: int = 1, n_bins=None) -> _Accumulator | None:
    """Window, FFT and accumulate all records, a few hits per FFT call.

    ``windows(first)`` gets the first (up to ``_WINDOW_HITS``) raw records as
    (hits, C, n_samples) rows and returns ``(w_force, w_response)``. Every
    record is multiplied by them while being copied, transposed, into a block
    buffer (FFTs along contiguous rows are faster than along axis 0 of
    (n_samples, C) records; a record that is the transpose of contiguous rows,
    as hits from :func:`guidefit.hits.iter_hits` give, is multiplied row by row).

    ``workers`` threads in all: the calling thread pulls the records from
    ``items`` (for hits: reads and checks them) and windows them into a block
    buffer; ``workers - 1`` helper threads transform the blocks and add their
    spectra to the sums (``scipy.fft`` and numpy's ufuncs release the GIL, so
    this overlaps the reading and checking). When the helpers fall behind (a
    block waits for one), the calling thread transforms its next block
    itself, so that neither side idles while the other has work. With ``workers=1`` everything
    runs on the calling thread. The sums are added block after block in hit
    order, so the result does not depend on the number of threads or their
    timing. Returns ``None`` when there is no record. ``force_offset``:
    remove each record's force offset (its median where the force window is
    0, see :func:`_force_offset`). ``precision``: of the block buffers and
    FFTs (:func:`fft_dtype`; ``"auto"`` from the first record's dtype); the
    windows are chosen and multiplied in float64 either way, and the product
    rounded once into the block buffer. ``expect``: the (n_samples,
    n_channels) the records will have, if known: their memory is then made
    by another thread while the first record is pulled (for stored hits,
    while the first pass reads the force of the hits). ``pair``: hits per
    group turn (see :data:`PAIR_HITS_PER_GROUP`). ``n_bins``: None (every bin),
    or a function of the record length giving how many of the first bins to sum
    (the FFT is whole either way; the bins above are not summed).
    """
    from concurrent.futures import ThreadPoolExecutor

    import scipy.fft

    early = _early_buffers(expect, precision, force_index, n_groups, workers, pair, n_bins)
    source = iter(items)
    first = None  # the first records, (hits, C, n); in the block buffers when they fit
    k = 0
    for _, record in source:
        if first is None:
            n, c = record.shape
            dtype = fft_dtype(precision, record.dtype)
            kept = None if n_bins is None else n_bins(n)
            key = (n, c, np.dtype(dtype), force_index, n_groups, workers, pair, kept)
            mem = early.result() if early is not None else None
            if mem is None or mem.key != key:
                mem = _Buffers(n, c, dtype, force_index, n_groups, workers, pair, n_bins=kept)
            early = None
            n_first, block, n_bufs = mem.n_first, mem.block, mem.n_bufs
            space, first, acc = mem.space, mem.first, mem.acc
            del mem
            helpers = workers - 1  # threads besides the calling one
        np.copyto(first[k], record.T)
        k += 1
        if k == n_first:
            break
    if first is None:
        return None
    del record
    first = first[:k]
    fi = force_index
    w_force, w_resp = windows(first)
    w_pair = (np.array(w_force, dtype=float), np.array(w_resp, dtype=float))  # (n,) each
    window_rows = [w_pair[0] if ch == fi else w_pair[1] for ch in range(c)]  # views, per channel
    window_t = np.stack(window_rows)  # (C, n), for the first records only
    # a hammer pushes nothing after the force window: the force there is the sensor's offset
    quiet = np.flatnonzero(window_t[fi] == 0.0)[-512:] if force_offset else np.empty(0)
    quiet = quiet if quiet.size >= 16 else None  # the last <= 512 quiet samples: plenty, cheap
    if quiet is not None:
        for j in range(k):
            first[j, fi] -= _force_offset(first[j, fi, quiet], first[j, fi])
    first *= window_t
    if space.shape[0] > n_bufs * block:  # the first records did not fit in the buffers
        space = np.empty((n_bufs * block, c, n))
    elif first.base is space:  # already in place in the buffers
        first = None
    bufs = [space[i * block:(i + 1) * block] for i in range(n_bufs)]
    ready = k  # windowed first records not yet handed to a block
    free = [threading.Event() for _ in range(n_bufs)]  # set: the buffer may be refilled
    for event in free:
        event.set()
    acc.precision = _precision_name(dtype)

    def fill(turn: int) -> int:
        """Windowed records into ``bufs[turn]`` (block, C, n); how many."""
        nonlocal ready, first
        buf = bufs[turn]
        k = 0
        if ready:  # the first records: in place already, or copied from ``first``
            k = min(block, ready)
            if first is not None:
                done = first.shape[0] - ready
                np.copyto(buf[:k], first[done:done + k])
            ready -= k
            if not ready:
                first = None
        if k < block:
            for _, record in source:
                rows = record.T
                for ch in range(c):  # row by row: the two window rows stay in cache
                    np.multiply(rows[ch], window_rows[ch], out=buf[k, ch])
                if quiet is not None:  # force offset (sensor bias): out of the windowed force
                    buf[k, fi] -= _force_offset(record[quiet, fi], buf[k, fi]) * window_rows[fi]
                del record, rows  # the hit's buffer may be reused (guidefit.hits._rows_buffer)
                k += 1
                if k == block:
                    break
        return k

    # spectra of transformed blocks wait here, by block number, to be added in order
    transformed: dict[int, tuple[np.ndarray, int]] = {}
    state = {"next": 0}  # the block to add next
    adding = threading.Lock()  # held while adding: one thread at a time, in order

    def add_ready(wait: bool) -> None:
        """Add the transformed blocks that are next in order (``wait``: for the lock)."""
        if not adding.acquire(blocking=wait):
            return  # another thread is adding; it takes the ready blocks too
        try:
            while state["next"] in transformed:
                acc.add(*transformed.pop(state["next"]))
                state["next"] += 1
        finally:
            adding.release()

    def transform(turn: int, k: int, i0: int, number: int) -> None:
        try:
            Z = scipy.fft.rfft(bufs[turn][:k], axis=-1, workers=1)
        finally:
            free[turn].set()
        transformed[number] = (Z, i0)
        add_ready(wait=False)

    with ThreadPoolExecutor(max_workers=helpers) if helpers else _NullExecutor() as pool:
        futures = []
        number = 0
        turn = 0
        while True:
            if not free[turn].is_set():
                add_ready(wait=False)  # rather than wait idle: add what a helper transformed
                free[turn].wait()
            if len(transformed) > n_bufs:  # bound the spectra waiting to be added
                add_ready(wait=True)
            k = fill(turn)
            if k == 0:
                break
            free[turn].clear()
            for future in [f for f in futures if f.done()]:
                future.result()  # re-raises a helper's error
                futures.remove(future)
            if any(not (f.running() or f.done()) for f in futures):
                transform(turn, k, acc.n_hits, number)  # the helpers are behind: this block here
            else:
                futures.append(pool.submit(transform, turn, k, acc.n_hits, number))
            number += 1
            acc.n_hits += k
            turn = (turn + 1) % n_bufs
            if k < block:
                break
        for future in futures:
            future.result()
        add_ready(wait=True)
    if state["next"] != number:  # cannot happen unless a block was lost
        raise RuntimeError(f"frf: {number - state['next']} transformed block(s) not added")
    return acc


class _NullExecutor:
    """Synchronous stand-in for a ThreadPoolExecutor (``workers=1``)."""

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def submit(self, fn, *args):
        class _Done:
            def __init__(self, value):
                self.value = value

            def result(self):
                return self.value

            def done(self):
                return True

        return _Done(fn(*args))


def _validated(items: Iterable[tuple[str, np.ndarray]], run: str,
               n_channels: int | None) -> Iterator[tuple[str, np.ndarray]]:
    """Yield (label, 2-D array) checking that every record has the first one's shape."""
    shape = None
    first_label = None
    for label, data in items:
        data = np.asarray(data)
        if data.ndim != 2:
            raise RecordingError(
                f"run '{run}': hit {label} data has shape {data.shape}, "
                "expected (n_samples, n_channels)"
            )
        if shape is None:
            shape, first_label = data.shape, label
            if n_channels is not None and data.shape[1] != n_channels:
                raise RecordingError(
                    f"run '{run}': hit {label} has {data.shape[1]} channels, "
                    f"the run declares {n_channels}"
                )
            if shape[0] < 2 or shape[1] < 2:
                raise RecordingError(
                    f"run '{run}': hit {label} has shape {shape}; need >= 2 samples "
                    "and a force plus >= 1 response channel"
                )
        elif data.shape != shape:
            raise RecordingError(
                f"run '{run}': hit {label} has {data.shape[0]} samples x {data.shape[1]} "
                f"channels, expected {shape[0]} x {shape[1]} as hit {first_label}"
            )
        yield label, data


def _labelled(records) -> Iterator[tuple[str, np.ndarray]]:
    if isinstance(records, np.ndarray) and records.ndim == 3:
        records = iter(records)
    for i, data in enumerate(records):
        yield str(i), data


def _block_size(n_samples: int, n_channels: int) -> int:
    return max(1, min(_MAX_BLOCK_HITS, _BLOCK_BYTES // (8 * n_samples * n_channels)))


def spectral_sums(
    records,
    force_index: int,
    w_force,
    w_response,
    n_groups: int = DEFAULT_GROUPS,
    workers: int = 2,
    precision: str = "auto",
) -> dict:
    """Per-group spectral sums of windowed records (the core under every FRF here).

    Parameters
    ----------
    records : array_like (n_hits, n_samples, n_channels) or iterable of (n_samples, n_channels)
        Hit records; an iterable is consumed a few records at a time.
    force_index : int
        Column of the force channel; every other column is a response.
    w_force, w_response : array_like, shape (n_samples,)
        Windows multiplied onto the force and onto every response channel.
    n_groups : int
        Hit ``i`` goes to group ``i % n_groups``; groups that got no hit (fewer
        hits than groups) are dropped.
    workers : int
        Threads in all: with more than one, ``workers - 1`` helper threads
        transform the blocks and accumulate their spectra while the calling
        thread windows the next records (and, for hits, reads and checks
        them). The result is the same for any number.
    precision : {"auto", "single", "double"}
        Of the FFTs (:func:`fft_dtype`); ``"auto"``: single for float32
        records, else double. The sums are float64 either way.

    Returns
    -------
    dict
        ``Sff`` (G, F) float, ``Sxx`` (G, F, R) float, ``Sfx`` (G, F, R) complex,
        ``n_hits`` (G,) int: unscaled sums of :math:`|F|^2`, :math:`|X|^2`,
        :math:`\\overline{F} X` of the DFTs (``scipy.fft.rfft``) of the windowed
        records; F = n_samples // 2 + 1.

    Raises
    ------
    RecordingError
        A record whose shape differs from the first one's.

    Examples
    --------
    >>> import numpy as np
    >>> rec = np.zeros((3, 8, 2)); rec[:, 0, 0] = 1.0; rec[:, 1, 1] = 2.0
    >>> s = spectral_sums(rec, 0, np.ones(8), np.ones(8), n_groups=2)
    >>> s["Sff"].shape, s["Sfx"].shape, s["n_hits"].tolist()
    ((2, 5), (2, 5, 1), [2, 1])
    >>> bool(np.isclose(s["Sfx"][0, 2, 0], -4j))   # 2 hits * conj(1) * 2 exp(-2j pi 2/8)
    True
    """
    n_groups = _check_groups(n_groups)
    fft_dtype(precision)  # checked before any record is read
    items = _validated(_labelled(records), "records", None)
    acc = _run_blocks(_checked_force(items, force_index, "records"), force_index,
                      lambda block: (w_force, w_response), n_groups, max(1, int(workers)),
                      precision=precision)
    if acc is None:
        raise IdentificationError("records: no record to average")
    return acc.group_sums()


def _check_groups(n_groups) -> int:
    if int(n_groups) != n_groups or n_groups < 1:
        raise ValueError(f"n_groups must be an integer >= 1, got {n_groups!r}")
    return int(n_groups)


def _checked_force(items, force_index: int, run: str):
    """Pass records through, checking ``force_index`` against the first one."""
    for k, item in enumerate(items):
        if k == 0:
            c = item[1].shape[1]
            if not 0 <= force_index < c:
                raise RecordingError(
                    f"run '{run}': force_index {force_index} out of range for {c} channels"
                )
        yield item


# --------------------------------------------------------------------------- FrfSet


def _readonly(a: np.ndarray) -> np.ndarray:
    a.flags.writeable = False
    return a


@dataclass(frozen=True, eq=False)
class FrfSet:
    """Averaged FRFs of every response channel of one run.

    Attributes
    ----------
    run : str
        Run name.
    frequency_hz : numpy.ndarray, shape (F,)
        Bin frequencies, ``scipy.fft.rfftfreq(n_samples, 1/fs)``.
    channels : tuple of str
        Response channel names, in the order of the columns of ``H``.
    H : numpy.ndarray, shape (F, R), complex
        Accelerance in (m/s^2)/N from ``estimator``; with an exponential window
        it is the FRF of the system with extra damping 1/tau (module docstring).
    coherence : numpy.ndarray, shape (F, R)
        Ordinary coherence in [0, 1].
    estimator : str
        ``"H1"``, ``"H2"`` or ``"Hv"``.
    n_averages : int
        Hits averaged.
    group_sums : dict
        ``Sff`` (G, F), ``Sxx`` (G, F, R), ``Sfx`` (G, F, R), ``n_hits`` (G,):
        see :func:`spectral_sums`.
    exp_window_tau_s : float or None
        Exponential-window time constant (``None``: no exponential window).
    force_window_s : float or None
        Flat force-window width after the trigger (``None``: no force window).
    force_taper_s : float or None
        Force-window taper length.
    trigger_s : float or None
        Time of the trigger from the record start.
    sample_rate_hz : float or None
        Sample rate of the records.
    fft_precision : str
        ``"single"`` (float32 FFTs, float64 sums) or ``"double"``; see
        "Precision" in the module docstring.
    """

    run: str
    frequency_hz: np.ndarray
    channels: tuple[str, ...]
    H: np.ndarray
    coherence: np.ndarray
    estimator: str
    n_averages: int
    group_sums: dict = field(repr=False)
    exp_window_tau_s: float | None
    force_window_s: float | None
    force_taper_s: float | None = None
    trigger_s: float | None = None
    sample_rate_hz: float | None = None
    fft_precision: str = "double"

    @property
    def n_groups(self) -> int:
        """Number of jackknife groups G (0 when the group sums were not kept)."""
        if not self.group_sums:
            return 0
        return int(np.asarray(self.group_sums["Sff"]).shape[0])

    def _need_groups(self, what: str, minimum: int) -> None:
        if self.n_groups < minimum:
            raise ValueError(
                f"run '{self.run}': {what} needs group sums of >= {minimum} groups, "
                f"this FrfSet has {self.n_groups}"
            )

    @property
    def H_std(self) -> np.ndarray:
        """Approximate standard deviation of :math:`|H|` per bin, (F, R).

        Bendat and Piersol's normalised random error of a gain factor,
        :math:`\\varepsilon = \\sqrt{1-\\gamma^2} / (|\\gamma| \\sqrt{2 n_{avg}})`,
        times :math:`|H|`. Zero when :math:`\\gamma^2 = 1` (always so for one hit,
        where it means nothing); use :func:`jackknife_frf` for derived quantities.
        """
        g2 = self.coherence
        with np.errstate(divide="ignore", invalid="ignore"):
            eps = np.sqrt(1.0 - g2) / (np.sqrt(g2) * math.sqrt(2.0 * self.n_averages))
        return eps * np.abs(self.H)

    def with_estimator(self, estimator: str) -> FrfSet:
        """The same averages with another estimator (``"H1"``, ``"H2"``, ``"Hv"``).

        Examples
        --------
        >>> import numpy as np
        >>> f = np.zeros((4, 16)); f[:, 1] = [1.0, 2.0, 3.0, 4.0]
        >>> rec = np.stack([f, 3 * f + 0.1 * np.random.default_rng(1).normal(size=f.shape)], -1)
        >>> h1 = frf_from_records(rec, 100.0, window=WindowSettings(none=True))
        >>> h2 = h1.with_estimator("H2")
        >>> bool(np.all(np.abs(h1.H) <= np.abs(h2.H) + 1e-12))
        True
        """
        self._need_groups("with_estimator", 1)
        return _frfset_from_sums(self, self.group_sums, estimator)

    def leave_one_group_out(self) -> Iterator[FrfSet]:
        """FrfSets of the hits without group g, for g = 0 .. G-1.

        The delete-a-group jackknife replicates; see :func:`jackknife_frf`.

        Examples
        --------
        >>> import numpy as np
        >>> rng = np.random.default_rng(2)
        >>> rec = rng.normal(size=(5, 32, 2))
        >>> frf = frf_from_records(rec, 100.0, window=WindowSettings(none=True), n_groups=3)
        >>> [r.n_averages for r in frf.leave_one_group_out()]
        [3, 3, 4]
        """
        self._need_groups("leave_one_group_out", 2)
        gs = self.group_sums
        tot = {k: np.sum(gs[k], axis=0) for k in ("Sff", "Sxx", "Sfx", "n_hits")}
        for g in range(self.n_groups):
            sub = {k: tot[k] - gs[k][g] for k in tot}
            sums = {k: np.delete(np.asarray(gs[k]), g, axis=0) for k in gs}
            yield _frfset_from_sums(self, sums, self.estimator, totals=sub)

    def to_frame(self):
        """pandas DataFrame: ``frequency_hz``, then ``<channel>_re``, ``_im``, ``_coherence``.

        Examples
        --------
        >>> import numpy as np
        >>> rec = np.random.default_rng(3).normal(size=(2, 8, 2))
        >>> frf = frf_from_records(rec, 8.0, channel_names=("force", "acc_A_y"))
        >>> list(frf.to_frame().columns)
        ['frequency_hz', 'acc_A_y_re', 'acc_A_y_im', 'acc_A_y_coherence']
        """
        import pandas as pd

        return pd.DataFrame(_columns(self))


def _columns(frf: FrfSet) -> dict:
    cols = {"frequency_hz": np.asarray(frf.frequency_hz)}
    for k, name in enumerate(frf.channels):
        cols[f"{name}_re"] = frf.H[:, k].real
        cols[f"{name}_im"] = frf.H[:, k].imag
        cols[f"{name}_coherence"] = frf.coherence[:, k]
    return cols


def _frfset_from_sums(template: FrfSet, sums: dict, estimator: str,
                      totals: dict | None = None) -> FrfSet:
    _check_estimator(estimator)
    if totals is None:
        totals = {k: np.sum(sums[k], axis=0) for k in ("Sff", "Sxx", "Sfx", "n_hits")}
    H = estimate_frf(totals["Sff"], totals["Sxx"], totals["Sfx"], estimator)
    coh = coherence_from_sums(totals["Sff"], totals["Sxx"], totals["Sfx"])
    return replace(template, H=_readonly(H), coherence=_readonly(coh), estimator=estimator,
                   n_averages=int(totals["n_hits"]), group_sums=sums)


# --------------------------------------------------------------------------- entrances


def frf_from_records(
    records,
    sample_rate_hz: float,
    force_index: int = 0,
    channel_names: Sequence[str] | None = None,
    estimator: str = "H1",
    window: WindowSettings = WindowSettings(),
    pretrigger_samples: int | None = None,
    run: str = "run",
    n_groups: int = DEFAULT_GROUPS,
    workers: int = 2,
    precision: str = "auto",
) -> FrfSet:
    """Averaged FRFs from plain arrays of hit records.

    Parameters
    ----------
    records : array_like (n_hits, n_samples, n_channels) or iterable of (n_samples, n_channels)
        Accepted hits, float SI (force in N, responses in m/s^2). An iterable is
        consumed a few records at a time; only the first 4 (fewer if they
        exceed 64 MB as float64) are looked at to choose default windows.
    sample_rate_hz : float
        Sample rate in Hz.
    force_index : int
        Column of the force channel.
    channel_names : sequence of str, optional
        Names of all ``n_channels`` columns; default ``ch0``, ``ch1``, ...
    estimator : {"H1", "H2", "Hv"}
        FRF estimator stored in ``H`` (others via :meth:`FrfSet.with_estimator`).
    window : WindowSettings
        Windows; see :class:`WindowSettings` and :func:`choose_windows`.
    pretrigger_samples : int, optional
        Samples before the trigger in each record; ``None``: detected.
    run : str
        Name used in the result and in error messages.
    n_groups : int
        Jackknife groups (fewer if there are fewer hits).
    workers : int
        Threads in all (see :func:`spectral_sums`); the result does not depend on it.
    precision : {"auto", "single", "double"}
        Of the FFTs (:func:`fft_dtype`); ``"auto"``: single for float32
        records, else double. The spectral sums are float64 either way.

    Returns
    -------
    FrfSet

    Raises
    ------
    IdentificationError
        No record.
    RecordingError
        Records of different shapes, or names that do not match the channels.

    Examples
    --------
    >>> import numpy as np
    >>> frf_from_records(np.zeros((0, 16, 2)), 100.0, run="x")
    Traceback (most recent call last):
    ...
    guidefit.errors.IdentificationError: run 'x': no accepted hit to average
    """
    return _frf(_labelled(records), sample_rate_hz, force_index, channel_names, estimator,
                window, pretrigger_samples, run, n_groups, workers, None, Counter(), precision)


def compute_frf(
    run,
    hits: Iterable,
    estimator: str = "H1",
    window: WindowSettings = WindowSettings(),
    n_groups: int = DEFAULT_GROUPS,
    workers: int = 2,
    precision: str = "auto",
    max_frequency_hz: float | None = None,
) -> FrfSet:
    """Averaged FRFs of every response channel of one run from its hits.

    Parameters
    ----------
    run : guidefit.recording.Run or similar
        Uses ``name``, ``sample_rate_hz``, ``channels`` (each with ``.name``),
        ``force_index`` and ``pretrigger_samples``.
    hits : iterable of guidefit.hits.Hit or similar
        Objects with ``accepted`` (bool), ``data`` ((n_samples, n_channels)
        float64 SI, ``None`` when rejected) and, optionally, ``index`` and
        ``reason``. Consumed lazily; rejected hits are skipped.
    estimator, window, n_groups, workers
        As in :func:`frf_from_records`.
    precision : {"auto", "single", "double"}
        Of the FFTs (:func:`fft_dtype`); ``"auto"``: that of the run's stored
        samples (``run.sample_dtype``; float64 if the run does not say),
        whatever the dtype of the hits' ``data``.
    max_frequency_hz : float, optional
        Keep only the bins up to this frequency (``frequency_hz`` then ends
        there; the FFT and the bins kept are the same as without it). The
        spectral sums, the largest cost after the FFT, are then made for
        those bins only: identify asks for a band a few times wider than it
        fits (:func:`guidefit.identify.frf_top_hz`). None: every bin up to
        the Nyquist frequency.

    Returns
    -------
    FrfSet

    Raises
    ------
    IdentificationError
        No accepted hit.
    RecordingError
        Hits of different lengths, or a channel count that differs from the run's.

    Examples
    --------
    >>> from types import SimpleNamespace as NS
    >>> import numpy as np
    >>> run = NS(name="vertical", sample_rate_hz=1000.0, force_index=0,
    ...          pretrigger_samples=2, channels=(NS(name="force"), NS(name="acc_A_y")))
    >>> data = np.zeros((64, 2)); data[2:5, 0] = [1.0, 2.0, 1.0]; data[3:9, 1] = 1.0
    >>> hits = [NS(index=0, accepted=True, data=data, reason=None),
    ...         NS(index=1, accepted=False, data=None, reason="double_hit")]
    >>> frf = compute_frf(run, hits)
    >>> frf.run, frf.channels, frf.n_averages, frf.H.shape
    ('vertical', ('acc_A_y',), 1, (33, 1))
    >>> compute_frf(run, hits[1:])
    Traceback (most recent call last):
    ...
    guidefit.errors.IdentificationError: run 'vertical': no accepted hit to average (1 rejected: double_hit x1)
    """
    names = [str(c.name) for c in run.channels]
    rejected: Counter = Counter()

    def accepted() -> Iterator[tuple[str, np.ndarray]]:
        for k, hit in enumerate(hits):
            label = str(getattr(hit, "index", k))
            rows = getattr(hit, "_rows", None)  # stored hits from iter_hits: data.T, contiguous
            if hit.accepted and rows is not None:
                yield label, rows.T
            elif hit.accepted and hit.data is not None:
                yield label, hit.data
            else:
                rejected[getattr(hit, "reason", None) or "rejected"] += 1

    dtype = fft_dtype(precision, getattr(run, "sample_dtype", np.float64))
    # stored hits have the run's n_samples (a continuous run's records have another length)
    expect = (int(run.n_samples), len(names)) if getattr(run, "layout", None) == "hits" else None
    stored = int(getattr(run, "n_hits_stored", 0) or 0)
    pair = 2 if stored >= PAIR_HITS_PER_GROUP * _check_groups(n_groups) else 1
    return _frf(accepted(), run.sample_rate_hz, run.force_index, names, estimator, window,
                run.pretrigger_samples, str(run.name), n_groups, workers, len(names), rejected,
                _precision_name(dtype), expect, pair, max_frequency_hz)


def kept_bins(n_samples: int, sample_rate_hz: float, max_frequency_hz: float | None) -> int:
    """How many of the ``n_samples // 2 + 1`` rFFT bins lie at or below ``max_frequency_hz``
    (all of them for None or a frequency at or above the Nyquist frequency; at least 2)."""
    every = n_samples // 2 + 1
    if max_frequency_hz is None:
        return every
    top = float(max_frequency_hz)
    if not top > 0:  # NaN too
        raise ValueError(f"max_frequency_hz={max_frequency_hz!r}: expected a positive frequency")
    if top >= sample_rate_hz / 2:
        return every
    return max(2, min(every, math.floor(top * n_samples / sample_rate_hz + 1e-9) + 1))


def top_of(frf) -> float | None:
    """The ``max_frequency_hz`` that gives the bins of ``frf`` again (for FRFs of some of
    its hits with its windows); None when ``frf`` ends at the Nyquist frequency."""
    f = np.asarray(frf.frequency_hz, dtype=float)
    fs = getattr(frf, "sample_rate_hz", None)
    if not fs or f.size < 2 or f[-1] >= 0.5 * fs - 0.5 * (f[1] - f[0]):
        return None
    return float(f[-1] + 0.5 * (f[1] - f[0]))


def _frf(items, sample_rate_hz, force_index, channel_names, estimator, window,
         pretrigger_samples, run, n_groups, workers, n_channels, rejected, precision,
         expect=None, pair=1, max_frequency_hz=None) -> FrfSet:
    _check_estimator(estimator)
    fft_dtype(precision)  # checked before any record is read
    n_groups = _check_groups(n_groups)
    fs = float(sample_rate_hz)
    if not (fs > 0 and math.isfinite(fs)):
        raise ValueError(f"run '{run}': sample_rate_hz must be a positive number, got {fs!r}")
    if window is None:
        window = WindowSettings()
    if not isinstance(window, WindowSettings):
        raise TypeError(f"window must be a WindowSettings or None, got {type(window).__name__}")
    if channel_names is not None and n_channels is None:
        n_channels = len(channel_names)
    fi = int(force_index)
    chosen: list[WindowChoice] = []

    def windows(block: np.ndarray):
        rows = block[:, _response_index(fi, block.shape[1])]
        choice = _choose(block[:, fi], rows, fs, window, pretrigger_samples)
        chosen.append(choice)
        return choice.arrays(block.shape[-1], fs)

    items = _checked_force(_validated(items, run, n_channels), fi, run)
    n_bins = None if max_frequency_hz is None else (lambda n: kept_bins(n, fs, max_frequency_hz))
    if n_bins is not None:
        n_bins(2)  # the frequency is checked before any record is read
    acc = _run_blocks(items, fi, windows, n_groups, max(1, int(workers)), force_offset=True,
                      precision=precision, expect=expect, pair=pair, n_bins=n_bins)
    if acc is None:
        reasons = ", ".join(f"{r} x{k}" for r, k in sorted(rejected.items()))
        detail = f" ({sum(rejected.values())} rejected: {reasons})" if rejected else ""
        raise IdentificationError(f"run '{run}': no accepted hit to average{detail}")
    n, c = acc.n, acc.c
    names = tuple(channel_names) if channel_names is not None else tuple(f"ch{k}" for k in range(c))
    choice = chosen[0]
    import scipy.fft

    template = FrfSet(
        run=run,
        frequency_hz=_readonly(scipy.fft.rfftfreq(n, 1.0 / fs)[:acc.F]),
        channels=tuple(names[k] for k in range(c) if k != fi),
        H=np.empty((0, 0), complex),
        coherence=np.empty((0, 0)),
        estimator=estimator,
        n_averages=0,
        group_sums={},
        exp_window_tau_s=choice.exp_tau_s,
        force_window_s=choice.force_window_s,
        force_taper_s=choice.force_taper_s if choice.force_window_s is not None else None,
        trigger_s=choice.trigger_sample / fs,
        sample_rate_hz=fs,
        fft_precision=acc.precision,
    )
    return _frfset_from_sums(template, acc.group_sums(), estimator)


# --------------------------------------------------------------------------- jackknife


@dataclass(frozen=True, eq=False)
class JackknifeResult:
    """Delete-a-group jackknife of a quantity derived from an FrfSet.

    Attributes
    ----------
    value : numpy.ndarray or float
        ``fn`` of the full FrfSet.
    std : numpy.ndarray or float
        Jackknife standard deviation (NaN with fewer than two groups).
    estimate : numpy.ndarray or float
        Bias-corrected jackknife estimate.
    pseudovalues : numpy.ndarray, shape (G, ...)
        :math:`h_g \\theta - (h_g - 1)\\theta_{(g)}`, :math:`h_g = n/m_g`.
    replicates : numpy.ndarray, shape (G, ...)
        ``fn`` of each leave-one-group-out FrfSet, :math:`\\theta_{(g)}`.
    group_sizes : numpy.ndarray, shape (G,)
        Hits per group :math:`m_g`.
    """

    value: np.ndarray
    std: np.ndarray
    estimate: np.ndarray
    pseudovalues: np.ndarray
    replicates: np.ndarray
    group_sizes: np.ndarray


def jackknife_frf(frfset: FrfSet, fn: Callable[[FrfSet], object]) -> JackknifeResult:
    """Delete-a-group jackknife of ``fn(frfset)`` (any scalar or array).

    Busing et al.'s delete-m_g jackknife, which reduces to the textbook
    delete-a-group jackknife when all groups hold the same number of hits:
    with :math:`h_g = n/m_g`, pseudovalues
    :math:`p_g = h_g\\theta - (h_g - 1)\\theta_{(g)}`, estimate
    :math:`\\sum_g (\\theta - \\theta_{(g)}) + \\sum_g m_g \\theta_{(g)}/n`, variance
    :math:`\\frac1G \\sum_g (p_g - \\hat\\theta_J)^2/(h_g - 1)`.

    Parameters
    ----------
    frfset : FrfSet
        With ``group_sums`` of G >= 2 groups for a finite std.
    fn : callable
        FrfSet -> float or array (e.g. a fitted modal frequency).

    Returns
    -------
    JackknifeResult

    Examples
    --------
    Std of the mean |H1| over bins 1-4 of a noisy 8-hit FrfSet:

    >>> import numpy as np
    >>> rng = np.random.default_rng(4)
    >>> f = rng.normal(size=(8, 16)); x = 2 * f + 0.2 * rng.normal(size=(8, 16))
    >>> frf = frf_from_records(np.stack([f, x], -1), 16.0, window=WindowSettings(none=True))
    >>> jk = jackknife_frf(frf, lambda s: np.abs(s.H[1:5, 0]).mean())
    >>> jk.pseudovalues.shape, bool(0 < jk.std < 0.2), bool(abs(jk.value - 2) < 0.2)
    ((8,), True, True)
    """
    frfset._need_groups("jackknife_frf", 1)
    theta = np.asarray(fn(frfset), dtype=float)
    m = np.asarray(frfset.group_sums["n_hits"], dtype=float)
    G = m.size
    if G < 2:
        nan = np.full(theta.shape, np.nan)[()]
        return JackknifeResult(theta[()], nan, theta[()], theta[None], theta[None], m)
    reps = np.stack([np.asarray(fn(s), dtype=float) for s in frfset.leave_one_group_out()])
    n = m.sum()
    h = (n / m).reshape((G,) + (1,) * theta.ndim)
    pseudo = h * theta - (h - 1.0) * reps
    mg = m.reshape(h.shape)
    estimate = np.sum(theta - reps, axis=0) + np.sum(mg * reps, axis=0) / n
    var = np.sum((pseudo - estimate) ** 2 / (h - 1.0), axis=0) / G
    return JackknifeResult(theta[()], np.sqrt(var)[()], estimate[()], pseudo, reps, m)


# --------------------------------------------------------------------------- export


def _as_list(frfsets) -> list[FrfSet]:
    items = [frfsets] if isinstance(frfsets, FrfSet) else list(frfsets)
    if not items:
        raise ValueError("frfsets is empty; need at least one FrfSet")
    return items


def write_frf_csv(path, frfsets) -> None:
    """Write FRFs as CSV: ``frequency_hz``, then ``<channel>_re``, ``_im``, ``_coherence``.

    One row per frequency bin and run. With several runs a first column ``run``
    is added and the rows of each run follow one another; a channel missing
    from a run leaves its cells empty. Numbers are written in Python's shortest
    round-trip form (``repr``: lossless; ``nan`` where undefined).

    Parameters
    ----------
    path : str or path-like
        Output file.
    frfsets : FrfSet or sequence of FrfSet

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> rec = np.random.default_rng(5).normal(size=(2, 8, 2))
    >>> frf = frf_from_records(rec, 8.0, channel_names=("force", "acc_A_y"))
    >>> path = os.path.join(tempfile.mkdtemp(), "frf.csv")
    >>> write_frf_csv(path, frf)
    >>> open(path).readline().strip()
    'frequency_hz,acc_A_y_re,acc_A_y_im,acc_A_y_coherence'
    """
    items = _as_list(frfsets)
    channels: list[str] = []
    for frf in items:
        channels += [c for c in frf.channels if c not in channels]
    header = ["frequency_hz"] + [f"{c}_{part}" for c in channels
                                 for part in ("re", "im", "coherence")]
    multi = len(items) > 1
    if multi:
        header = ["run"] + header

    def fmt(a) -> list[str]:
        return [repr(v) for v in np.asarray(a, dtype=float).tolist()]

    with open(path, "w", encoding="utf-8", newline="") as fh:
        fh.write(",".join(header) + "\n")
        for frf in items:
            F = len(frf.frequency_hz)
            cols = [fmt(frf.frequency_hz)]
            for c in channels:
                if c in frf.channels:
                    k = frf.channels.index(c)
                    cols += [fmt(frf.H[:, k].real), fmt(frf.H[:, k].imag),
                             fmt(frf.coherence[:, k])]
                else:
                    cols += [[""] * F] * 3
            if multi:
                cols = [[_csv_field(frf.run)] * F] + cols
            fh.writelines(",".join(row) + "\n" for row in zip(*cols))


def _csv_field(text: str) -> str:
    if any(ch in text for ch in ',"\n'):
        return '"' + text.replace('"', '""') + '"'
    return text


def _nan_if_none(value):
    return np.nan if value is None else float(value)


def write_frf_h5(path, frfsets, include_group_sums: bool = True) -> None:
    """Write FRFs to HDF5, one group ``/frf/<run>`` per FrfSet.

    Layout::

        /frf                         attrs format="guidefit-frf", format_version=1
        /frf/<run>/frequency_hz      (F,) float64, Hz
        /frf/<run>/H                 (F, R) complex128, (m/s^2)/N
        /frf/<run>/coherence         (F, R) float64
        /frf/<run>/group_sums/Sff    (G, F)      (optional)
        /frf/<run>/group_sums/Sxx    (G, F, R)
        /frf/<run>/group_sums/Sfx    (G, F, R) complex128
        /frf/<run>/group_sums/n_hits (G,)

    Attributes of ``/frf/<run>``: ``estimator``, ``channels`` (str array, the
    columns of H), ``n_averages``, ``exp_window_tau_s``, ``force_window_s``,
    ``force_taper_s``, ``trigger_s``, ``sample_rate_hz`` (NaN where not
    applicable, e.g. no exponential window), ``fft_precision`` (absent in
    files written before it existed: read as ``"double"``).

    Parameters
    ----------
    path : str or path-like
        Output file (overwritten).
    frfsets : FrfSet or sequence of FrfSet
        Run names must be distinct and contain no ``/``.
    include_group_sums : bool
        Also store the jackknife group sums (O(G F R) numbers).

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> rec = np.random.default_rng(6).normal(size=(3, 16, 3))
    >>> frf = frf_from_records(rec, 16.0, run="vertical")
    >>> path = os.path.join(tempfile.mkdtemp(), "frf.h5")
    >>> write_frf_h5(path, [frf])
    >>> back, = read_frf_h5(path)
    >>> back.run, back.channels, bool(np.array_equal(back.H, frf.H))
    ('vertical', ('ch1', 'ch2'), True)
    """
    import h5py

    items = _as_list(frfsets)
    names = [frf.run for frf in items]
    for name in names:
        if "/" in name or not name or names.count(name) > 1:
            raise ValueError(f"run name {name!r} not usable as an HDF5 group (empty, '/' or repeated)")
    with h5py.File(path, "w") as f:
        root = f.create_group("frf")
        root.attrs["format"] = "guidefit-frf"
        root.attrs["format_version"] = 1
        for frf in items:
            g = root.create_group(frf.run)
            g.create_dataset("frequency_hz", data=np.asarray(frf.frequency_hz, dtype=float))
            g.create_dataset("H", data=np.asarray(frf.H, dtype=complex))
            g.create_dataset("coherence", data=np.asarray(frf.coherence, dtype=float))
            g.attrs["estimator"] = frf.estimator
            g.attrs["channels"] = np.array(frf.channels, dtype=h5py.string_dtype())
            g.attrs["n_averages"] = int(frf.n_averages)
            g.attrs["fft_precision"] = frf.fft_precision
            for key in ("exp_window_tau_s", "force_window_s", "force_taper_s", "trigger_s",
                        "sample_rate_hz"):
                g.attrs[key] = _nan_if_none(getattr(frf, key))
            if include_group_sums and frf.group_sums:
                s = g.create_group("group_sums")
                for key in ("Sff", "Sxx", "Sfx", "n_hits"):
                    s.create_dataset(key, data=np.asarray(frf.group_sums[key]))


def read_frf_h5(path) -> tuple[FrfSet, ...]:
    """Read FrfSets written by :func:`write_frf_h5` (layout there).

    Examples
    --------
    See :func:`write_frf_h5`.
    """
    import h5py

    def opt(v):
        v = float(v)
        return None if math.isnan(v) else v

    out = []
    with h5py.File(path, "r") as f:
        for name, g in f["frf"].items():
            a = g.attrs
            sums = {k: g["group_sums"][k][()] for k in g["group_sums"]} if "group_sums" in g else {}
            channels = tuple(c.decode() if isinstance(c, bytes) else str(c) for c in a["channels"])
            out.append(FrfSet(
                run=name,
                frequency_hz=g["frequency_hz"][()],
                channels=channels,
                H=g["H"][()],
                coherence=g["coherence"][()],
                estimator=str(a["estimator"]),
                n_averages=int(a["n_averages"]),
                group_sums=sums,
                exp_window_tau_s=opt(a["exp_window_tau_s"]),
                force_window_s=opt(a["force_window_s"]),
                force_taper_s=opt(a["force_taper_s"]),
                trigger_s=opt(a["trigger_s"]),
                sample_rate_hz=opt(a["sample_rate_hz"]),
                fft_precision=str(a.get("fft_precision", "double")),
            ))
    return tuple(out)
