r"""The FrfSet data type: averaged FRFs of one run with the spectral sums they come from.

A data module: :mod:`guidefit.frf` makes FrfSets from hit records, the FRF
file readers of :mod:`guidefit.io` make them from files; both import them
from here, so reading a file needs no signal processing. Besides the
dataclass it holds only the estimator formulas that define ``H`` and the
coherence from the sums (``H1``, ``H2``, ``Hv``; their theory is in
:mod:`guidefit.frf`'s docstring), because :meth:`FrfSet.with_estimator` and
:meth:`FrfSet.leave_one_group_out` recompute them. Every name here is
importable from :mod:`guidefit.frf` as well.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace

import numpy as np

__all__ = ["ESTIMATORS", "FrfSet", "coherence_from_sums", "estimate_frf"]


def _readonly(a: np.ndarray) -> np.ndarray:
    a.flags.writeable = False
    return a


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


# --------------------------------------------------------------------------- FrfSet


@dataclass(frozen=True, eq=False)
class FrfSet:
    """Averaged FRFs of every response channel of one run.

    Attributes
    ----------
    run : str
        Run name.
    frequency_hz : numpy.ndarray, shape (F,)
        Bin frequencies, ``scipy.fft.rfftfreq(n_samples, 1/fs)`` (``n_fft`` for zero-padded records).
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
        see :func:`guidefit.frf.spectral_sums`.
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
    record_samples : int or None
        The records' own length when they were zero-padded, after their
        windows, to put the run on a common frequency grid with other runs
        ("Common grid" in :mod:`guidefit.frf`; :attr:`n_fft` is then the
        padded length); None: not padded.
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
    record_samples: int | None = None

    @property
    def n_fft(self) -> int | None:
        """The FFT length of zero-padded records (``fs / df``); None when the records were not padded."""
        if self.record_samples is None:
            return None
        return int(round(float(self.sample_rate_hz) / float(self.frequency_hz[1] - self.frequency_hz[0])))

    @property
    def resolution_hz(self) -> float:
        """The spectral resolution, one over the record's duration: the bin spacing, or for zero-padded
        records (finer bins, no finer resolution) ``fs / record_samples``."""
        if self.record_samples is not None:
            return float(self.sample_rate_hz) / self.record_samples
        return float(self.frequency_hz[1] - self.frequency_hz[0])

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
        where it means nothing); use :func:`guidefit.frf.jackknife_frf` for derived quantities.
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
        >>> from guidefit.frf import WindowSettings, frf_from_records
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

        The delete-a-group jackknife replicates; see :func:`guidefit.frf.jackknife_frf`.

        Examples
        --------
        >>> import numpy as np
        >>> from guidefit.frf import WindowSettings, frf_from_records
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
        >>> from guidefit.frf import frf_from_records
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


