r"""Frequency response functions of impact-hammer hits: windows, H1/H2/Hv, coherence.

The windows are in :mod:`guidefit.frf.windows`, the streaming FFT engine that
makes the spectral sums in :mod:`guidefit.frf.spectra`, the :class:`FrfSet` data
type and its estimator formulas in :mod:`guidefit.frfset`; their names are
importable from here as well (this module is the FRF stage's entrance). FRF
files (``frf.csv``, ``frf.h5``) are written and read in
:mod:`guidefit.io.frf_files`; :func:`write_frf_csv`, :func:`write_frf_h5` and
:func:`read_frf_h5` are importable from here too, their documented old home.
This module does no file I/O.

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

Common grid
-----------
The runs of one test are fitted together (:func:`guidefit.modes.global_fit`),
which needs their FRFs on one frequency grid. A run recorded with a shorter
record or at another sample rate has another bin spacing ``fs / n``; its
FRFs are then computed with ``n_fft`` (:func:`compute_frf`): each record,
*after* its windows, zero-padded to ``n_fft`` samples before the FFT, so that
its bins are ``fs / n_fft`` apart, those of the longest record
(:func:`common_grid` chooses ``n_fft`` per run). This changes no spectrum: a
windowed record is a finite sequence, its spectrum (the DTFT) is defined at
every frequency, and the padded FFT samples that same spectrum on a finer
grid. It adds no information either (neighbouring bins of a padded record are
correlated; the std of the fit is carried by the hit-group jackknife, which
sees that). It is honest because the windows end the record on a decayed
response: the exponential window is chosen so that the response at the
record's end is at most ``exp_end_fraction`` of its peak, and the force
window ends the force long before. The exponential window's shift of the
poles (:math:`1/\tau`) depends on its time constant, not on the record or
FFT length, so its damping correction is unchanged.

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
from collections import Counter
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from guidefit.errors import IdentificationError
from guidefit.frf.spectra import (  # noqa: F401  (re-exported: the FRF engine's names, importable from here)
    DEFAULT_GROUPS,
    PAIR_HITS_PER_GROUP,
    PRECISIONS,
    _Accumulator,
    _check_groups,
    _checked_force,
    _labelled,
    _precision_name,
    _readonly,
    _response_index,
    _run_blocks,
    _validated,
    fft_dtype,
    spectral_sums,
)
from guidefit.frf.windows import (  # noqa: F401  (re-exported: the windows, importable from here)
    FORCE_OFFSET_FRACTION,
    FORCE_TAPER_FRACTION,
    FORCE_WINDOW_PULSES_AFTER,
    PULSE_THRESHOLD,
    TAIL_FRACTION,
    WindowChoice,
    WindowSettings,
    _choose,
    choose_windows,
    exponential_window,
    exponential_window_damping_correction,
    force_window,
)
from guidefit.frfset import (  # (re-exported: the FrfSet type and its estimators, importable from here)
    ESTIMATORS,
    FrfSet,
    _check_estimator,
    _frfset_from_sums,
    coherence_from_sums,
    estimate_frf,
)
from guidefit.io.frf_files import (  # (re-exported: the documented FRF file functions' old home)
    read_frf_h5,
    write_frf_csv,
    write_frf_h5,
)

__all__ = [
    "ESTIMATORS",
    "PRECISIONS",
    "FrfSet",
    "JackknifeResult",
    "WindowChoice",
    "WindowSettings",
    "choose_windows",
    "coherence_from_sums",
    "common_grid",
    "compute_frf",
    "estimate_frf",
    "exponential_window",
    "exponential_window_damping_correction",
    "fft_dtype",
    "fft_length",
    "first_bins",
    "force_window",
    "frf_from_records",
    "jackknife_frf",
    "read_frf_h5",
    "spectral_sums",
    "write_frf_csv",
    "write_frf_h5",
]

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
    n_fft: int | None = None,
) -> FrfSet:
    """Averaged FRFs of every response channel of one run from its hits.

    Parameters
    ----------
    run : guidefit.io.Run or similar
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
    n_fft : int, optional
        FFT length: every windowed record zero-padded to ``n_fft`` samples,
        bins ``fs / n_fft`` apart (see "Common grid" above; the FrfSet's
        ``record_samples`` and ``n_fft`` say so). None: the records' own length.

    Returns
    -------
    FrfSet

    Raises
    ------
    IdentificationError
        No accepted hit.
    RecordingError
        Hits of different lengths, or a channel count that differs from the run's.
    ValueError
        ``n_fft`` shorter than the records.

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
                # counted by kind ("clipped"), not by the whole reason (which names channels and samples)
                rejected[(getattr(hit, "reason", None) or "rejected").split(":", 1)[0].strip()] += 1

    dtype = fft_dtype(precision, getattr(run, "sample_dtype", np.float64))
    # stored hits have the run's n_samples (a continuous run's records have another length)
    expect = (int(run.n_samples), len(names)) if getattr(run, "layout", None) == "hits" else None
    stored = int(getattr(run, "n_hits_stored", 0) or 0)
    pair = 2 if stored >= PAIR_HITS_PER_GROUP * _check_groups(n_groups) else 1
    return _frf(accepted(), run.sample_rate_hz, run.force_index, names, estimator, window,
                run.pretrigger_samples, str(run.name), n_groups, workers, len(names), rejected,
                _precision_name(dtype), expect, pair, max_frequency_hz, n_fft)


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


def fft_length(frf) -> int:
    """The FFT length behind ``frf``'s bins, ``fs / df`` (its records' length, or the padded one: a duck-typed
    :attr:`guidefit.frfset.FrfSet.n_fft` that is never None)."""
    f = np.asarray(frf.frequency_hz, dtype=float)
    return int(round(float(frf.sample_rate_hz) / float(f[1] - f[0])))


def common_grid(frfs: Sequence, max_frequency_hz: float | None = None) -> list | None:
    """Per FrfSet, the ``(n_fft, bins)`` that put all of them on one frequency grid.

    The grid is ``k / T`` for ``k = 0 .. bins - 1``: ``T`` the longest
    record's duration (rounded up, when the sample rates differ, to the
    first duration that is a whole number of samples at every rate), the
    last bin at or below ``max_frequency_hz`` and every run's Nyquist
    frequency. A run's records, windowed, are zero-padded to
    ``n_fft = fs T`` samples ("Common grid" in the module docstring); the
    bins of a run whose records already span ``T`` are its own, its FRFs at
    most cut to ``bins``.

    Parameters
    ----------
    frfs : sequence of FrfSet
        One per run, with ``sample_rate_hz`` and at least two bins each.
    max_frequency_hz : float, optional
        The top the FRFs were asked for (:func:`compute_frf`).

    Returns
    -------
    list of (int, int) or None
        ``(n_fft, bins)`` per FrfSet, in order; None when they share one grid
        already (nothing to do) or have no common grid by zero padding
        (a sample rate that is not a whole number of Hz, or a run without
        its sample rate or with fewer than two bins).

    Examples
    --------
    >>> from types import SimpleNamespace as NS
    >>> import numpy as np
    >>> short = NS(sample_rate_hz=1000.0, frequency_hz=np.arange(6) * 10.0)     # 0.1 s records
    >>> long = NS(sample_rate_hz=1000.0, frequency_hz=np.arange(11) * 5.0)      # 0.2 s records
    >>> common_grid([short, long], 50.0)
    [(200, 11), (200, 11)]
    >>> common_grid([long, long], 50.0) is None
    True
    """
    keys = set()
    for frf in frfs:
        fs, f = getattr(frf, "sample_rate_hz", None), np.asarray(frf.frequency_hz, dtype=float)
        if not fs or f.size < 2:
            return None
        keys.add((f.size, round(float(f[1] - f[0]), 9)))
    if len(keys) <= 1:
        return None
    rates = [float(frf.sample_rate_hz) for frf in frfs]
    if any(abs(r - round(r)) > 1e-9 * r for r in rates):
        return None
    step = 1.0 / math.gcd(*(int(round(r)) for r in rates))  # durations that are whole samples at every rate
    longest = max(fft_length(frf) / r for frf, r in zip(frfs, rates))
    span = math.ceil(longest / step - 1e-9) * step
    n_fft = [int(round(r * span)) for r in rates]
    top = min(r / 2 for r in rates)
    if max_frequency_hz is not None:
        top = min(top, float(max_frequency_hz))
    bins = min(kept_bins(n, r, top) for n, r in zip(n_fft, rates))
    return [(n, bins) for n in n_fft]


def first_bins(frf: FrfSet, bins: int) -> FrfSet:
    """``frf`` cut to its first ``bins`` frequency bins (its FRFs, coherence and spectral sums)."""
    from dataclasses import replace

    if bins >= len(frf.frequency_hz):
        return frf
    sums = {k: (v if k == "n_hits" else _readonly(np.array(np.asarray(v)[:, :bins])))
            for k, v in frf.group_sums.items()}
    return replace(frf, frequency_hz=_readonly(np.array(frf.frequency_hz[:bins])),
                   H=_readonly(np.array(frf.H[:bins])), coherence=_readonly(np.array(frf.coherence[:bins])),
                   group_sums=sums)


def _frf(items, sample_rate_hz, force_index, channel_names, estimator, window,
         pretrigger_samples, run, n_groups, workers, n_channels, rejected, precision,
         expect=None, pair=1, max_frequency_hz=None, n_fft=None) -> FrfSet:
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
                      precision=precision, expect=expect, pair=pair, n_bins=n_bins, n_fft=n_fft)
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
        frequency_hz=_readonly(scipy.fft.rfftfreq(acc.n_fft, 1.0 / fs)[:acc.F]),
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
        record_samples=n if acc.n_fft != n else None,
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
