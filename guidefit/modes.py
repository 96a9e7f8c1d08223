r"""Modal parameters from accelerance FRFs: peak picking, half-power, modal curve fit.

This module turns an FRF set -- ``frequency_hz`` of shape ``(F,)`` and the
complex accelerance ``H`` of shape ``(F, R)`` in (m/s^2)/N for ``R`` response
channels and one excitation point -- into :class:`Mode` objects. It works on
arrays only (no file I/O) and has three levels of effort:

:func:`find_peaks`
    Candidate resonances from a mode indicator function that combines all
    channels (:func:`mode_indicator`), ranked by their prominence in dB above
    the local level.
:func:`half_power`
    The paper's single-degree-of-freedom estimate, Eq. (26) (vertical) and
    Eq. (28) (horizontal): ``xi = (f2 - f1) / (2 f)``, with the peak refined by
    parabolic interpolation and the half-power crossings interpolated between
    bins. :func:`sdof_from_half_power` gives the exact SDOF relations.
:func:`fit_modes` / :func:`fit_band` / :func:`auto_fit`
    A multi-channel modal curve fit in a frequency band: global poles shared
    by all channels, per-channel residues, lower and upper residual terms,
    solved by variable projection. Use it whenever the frequency must be
    known to about 0.1 % (see ``physics-notes.md``, identifiability), for
    heavily damped (10 %) modes, coarse resolution and close modes.

Model and residue convention
----------------------------
The fitted accelerance of channel ``r`` is

.. math::

    H_r(\omega) = (j\omega)^2 \sum_k \left[ \frac{A_{rk}}{j\omega - p_k}
                 + \frac{A_{rk}^*}{j\omega - p_k^*} \right]
                 + L_r + \frac{L1_r}{j\omega} + U_r (j\omega)^2

with the pole in the upper half plane,
``p_k = -zeta_k w_k + j w_k sqrt(1 - zeta_k^2)`` (rad/s), ``w_k = 2 pi f_k``.
The bracket is the displacement receptance (m/N), so ``A_rk`` is the residue
of a *receptance* pole, in m/(N s). The real residual terms stand for the
modes outside the band (see :func:`fit_modes`): ``L_r`` (1/kg) the mass line
of the modes below, ``L1_r`` their damping tail, ``U_r`` (m/N) the residual
compliance of the modes above. For a structure with real (normal) modes, mass-normalised shape
``phi_k`` (kg^-1/2) and the hammer at point ``e``,

.. math::

    A_{rk} = \frac{\phi_k(r)\,\phi_k(e)}{2 j \omega_{d,k}},
    \qquad \omega_{d,k} = \omega_k \sqrt{1 - \zeta_k^2},

so ``A_rk`` is negative imaginary on a driving point. The *modal constant*
``Mode.modal_constants = 2j w_d A_rk = phi_k(r) phi_k(e)`` (1/kg) is then real:
channels moving in phase with the driving point have a positive modal
constant, anti-phase channels a negative one, and the ratio between two
channels is the ratio of the mode shape at the two sensors (in each channel's
own measuring direction). For a single mass ``m`` on a spring the modal
constant is ``1/m``, so ``K = 4 pi^2 f^2 / modal_constant`` (Eq. (24)/(25)).

Which frequency is which
------------------------
For an SDOF accelerance the magnitude peaks *above* the undamped natural
frequency, ``f_peak = f_n / sqrt(1 - 2 zeta^2)`` (+0.08 % at zeta = 0.0288,
+1.12 % at zeta = 0.105). :func:`half_power` reports the |H| peak, as the
paper does; the paper's Eq. (26) ignores the difference and, divided by the
|H| peak, overestimates zeta by 0.3 % (zeta = 0.0288) and 4.7 %
(zeta = 0.105). :class:`Mode` always holds the undamped natural frequency
``|p| / 2 pi``; :func:`sdof_from_half_power` converts half-power frequencies
to it exactly.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from guidefit.errors import IdentificationError
from guidefit.prominence import prominent_peaks

__all__ = [
    "BandFit",
    "HalfPower",
    "HalfPowerWarning",
    "Mode",
    "ModeFitWarning",
    "Peaks",
    "SdofEstimate",
    "auto_fit",
    "find_peaks",
    "fit_band",
    "fit_modes",
    "half_power",
    "half_power_mode",
    "mode_indicator",
    "modes_to_frame",
    "natural_from_peak_frequency",
    "sdof_from_half_power",
    "synthesize",
]

_KINDS = ("accelerance", "mobility", "receptance")
_PEAK_INTERPOLATIONS = ("inverse_square", "log", "linear")
#: residual terms of the fitted accelerance; each enters with one real coefficient per channel
_RESIDUAL_TERMS = {
    "lower": lambda s: np.ones_like(s),  # L_r: mass line of the modes below the band
    "lower_damping": lambda s: 1.0 / s,  # L1_r / (jw): their damping tail
    "upper": lambda s: s * s,  # U_r (jw)^2: compliance of the modes above the band
    "upper_damping": lambda s: s**3,  # U1_r (jw)^3: their damping
}
_DEFAULT_RESIDUALS = ("lower", "lower_damping", "upper")


class HalfPowerWarning(UserWarning):
    """A half-power estimate is available but biased (too few bins in the band)."""


class ModeFitWarning(UserWarning):
    """A curve-fit result is suspicious (pole at a bound or outside the band)."""


@dataclass(frozen=True, eq=False)
class Mode:
    """One identified mode.

    Attributes
    ----------
    frequency_hz : float
        Undamped natural frequency ``|p| / 2 pi`` in Hz.
    damping_ratio : float
        Viscous damping ratio ``-Re(p) / |p|``.
    residues : numpy.ndarray
        ``(R,)`` complex receptance-pole residues ``A_rk`` in m/(N s), one per
        response channel; see the module docstring for the convention.
    method : str
        ``"curve_fit"`` or ``"half_power"``.
    frequency_std_hz, damping_std : float or None
        Standard deviations from the fit's Jacobian and residual variance
        (assumes independent noise in every bin; ``None`` for half-power).
    """

    frequency_hz: float
    damping_ratio: float
    residues: np.ndarray
    method: str
    frequency_std_hz: float | None = None
    damping_std: float | None = None

    @property
    def pole(self) -> complex:
        """Pole ``p`` in rad/s, upper half plane."""
        w = 2.0 * math.pi * self.frequency_hz
        z = self.damping_ratio
        return complex(-z * w, w * math.sqrt(max(1.0 - z * z, 0.0)))

    @property
    def damped_frequency_hz(self) -> float:
        """Damped natural frequency ``f_n sqrt(1 - zeta^2)`` in Hz."""
        return self.frequency_hz * math.sqrt(max(1.0 - self.damping_ratio**2, 0.0))

    @property
    def peak_frequency_hz(self) -> float:
        """Frequency of the SDOF accelerance magnitude peak, ``f_n / sqrt(1 - 2 zeta^2)``.

        ``nan`` for ``zeta >= 1/sqrt(2)`` (no peak).
        """
        if 2.0 * self.damping_ratio**2 >= 1.0:
            return math.nan
        return natural_from_peak_frequency(self.frequency_hz, self.damping_ratio, inverse=True)

    @property
    def modal_constants(self) -> np.ndarray:
        """``(R,)`` complex ``2j w_d A_r`` in 1/kg; ``phi(r) phi(e)``, real for normal modes."""
        return 2j * (2.0 * math.pi * self.damped_frequency_hz) * np.asarray(self.residues)


class Peaks(NamedTuple):
    """Result of :func:`find_peaks`, sorted by decreasing prominence."""

    frequency_hz: np.ndarray  #: peak frequencies, refined by parabolic interpolation (Hz)
    index: np.ndarray  #: indices of the peak bins into ``frequency_hz`` of the input
    prominence_db: np.ndarray  #: prominence of the mode indicator in dB


class HalfPower(NamedTuple):
    """Result of :func:`half_power` (all frequencies in Hz)."""

    f_peak_hz: float  #: interpolated frequency of the |H| maximum
    f1_hz: float  #: lower half-power frequency
    f2_hz: float  #: upper half-power frequency
    zeta: float  #: ``(f2 - f1) / (2 f_peak)``, Eq. (26)/(28)


class SdofEstimate(NamedTuple):
    """Result of :func:`sdof_from_half_power`."""

    f_n_hz: float  #: undamped natural frequency
    zeta: float  #: exact SDOF damping ratio
    f_peak_hz: float  #: where the |H| of this kind of FRF peaks for (f_n, zeta)


@dataclass(frozen=True, eq=False)
class BandFit:
    """Result of :func:`fit_band`.

    Attributes
    ----------
    modes : list of Mode
        Fitted modes, sorted by frequency.
    residuals : dict of str to numpy.ndarray
        ``(R,)`` real coefficient per fitted residual term: ``"lower"``
        ``L_r`` (1/kg), ``"lower_damping"`` ``L1_r`` (rad/(kg s)), ``"upper"``
        ``U_r`` (m/N), ``"upper_damping"`` ``U1_r`` (m s/(N rad)); see
        :func:`fit_modes`.
    band_hz : tuple of float
        The fitted band.
    nrmse : float
        ``||H - model|| / ||H||`` over the band (weighted as in the fit).
    n_bins : int
        Number of frequency bins in the band.
    """

    modes: list
    residuals: dict
    band_hz: tuple
    nrmse: float
    n_bins: int


# ---------------------------------------------------------------- validation


def _as_frequency(frequency_hz) -> np.ndarray:
    f = np.asarray(frequency_hz, dtype=float)
    if f.ndim != 1 or f.size < 3:
        raise ValueError(f"frequency_hz must be 1-D with at least 3 bins, got shape {f.shape}")
    if not np.all(np.isfinite(f)):
        raise ValueError("frequency_hz contains non-finite values")
    if np.any(np.diff(f) <= 0):
        raise ValueError("frequency_hz must be strictly increasing")
    return f


def _as_frf(f: np.ndarray, H) -> np.ndarray:
    """Return H as a complex (F, R) array."""
    H = np.asarray(H)
    if H.ndim == 1:
        H = H[:, None]
    if H.ndim != 2 or H.shape[0] != f.size:
        raise ValueError(f"H must have shape ({f.size},) or ({f.size}, R), got {H.shape}")
    if not np.all(np.isfinite(H)):
        raise ValueError("H contains non-finite values")
    return H.astype(complex)


def _band_mask(f: np.ndarray, f_lo, f_hi, name: str) -> np.ndarray:
    lo = -np.inf if f_lo is None else float(f_lo)
    hi = np.inf if f_hi is None else float(f_hi)
    if not lo < hi:
        raise ValueError(f"{name} must satisfy low < high, got ({f_lo}, {f_hi})")
    return (f >= lo) & (f <= hi)


# ------------------------------------------------------------- peak picking


def mode_indicator(frequency_hz, H) -> np.ndarray:
    """Mode indicator function that combines all response channels.

    ``MIF(f) = sum_r |H_r(f)|^2 / mean_f |H_r|^2``: each channel is normalised
    to unit mean power so that a mode seen mainly by a weak channel still
    shows. For a single excitation point this equals the squared first
    singular value (CMIF) of the normalised FRF row.

    Parameters
    ----------
    frequency_hz : array_like
        ``(F,)`` strictly increasing frequencies in Hz.
    H : array_like
        ``(F,)`` or ``(F, R)`` complex FRF (or magnitudes).

    Returns
    -------
    numpy.ndarray
        ``(F,)`` non-negative, dimensionless.

    Examples
    --------
    >>> import numpy as np
    >>> f = np.linspace(100.0, 300.0, 201)
    >>> H = np.stack([1 / (200.0**2 - f**2 + 2j * 0.02 * 200.0 * f)] * 2, axis=1)
    >>> mif = mode_indicator(f, H)
    >>> float(f[np.argmax(mif)])
    200.0
    """
    f = _as_frequency(frequency_hz)
    H = _as_frf(f, H)
    power = np.abs(H) ** 2
    mean = power.mean(axis=0)
    used = mean > 0
    if not np.any(used):
        return np.zeros(f.size)
    return (power[:, used] / mean[used]).sum(axis=1)


def _noise_power(H: np.ndarray) -> np.ndarray:
    """Robust per-channel noise power of complex (F, R) data from second differences.

    For white complex noise of power ``sigma^2`` the second difference has
    power ``6 sigma^2`` and ``|d|^2 / (6 sigma^2)`` is exponential, median
    ``ln 2``; a smooth FRF adds little where it is resolved by several bins.
    """
    if H.shape[0] < 3:
        return np.zeros(H.shape[1])
    d = H[:-2] - 2.0 * H[1:-1] + H[2:]
    return np.median(np.abs(d) ** 2, axis=0) / (6.0 * math.log(2.0))


def _parabolic_vertex(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Vertex (x, y) of the parabola through three points; middle point if degenerate."""
    (x0, x1, x2), (y0, y1, y2) = x, y
    d0, d2 = x0 - x1, x2 - x1
    # y = y1 + b t + a t^2 with t = x - x1
    den = d0 * d2 * (d0 - d2)
    if den == 0:
        return float(x1), float(y1)
    a = ((y0 - y1) * d2 - (y2 - y1) * d0) / den
    b = ((y2 - y1) * d0**2 - (y0 - y1) * d2**2) / den
    if a == 0:
        return float(x1), float(y1)
    t = -b / (2 * a)
    if not min(d0, d2) <= t <= max(d0, d2):
        return float(x1), float(y1)
    return float(x1 + t), float(y1 + b * t + a * t * t)


def find_peaks(
    frequency_hz,
    H,
    *,
    f_min: float | None = None,
    f_max: float | None = None,
    min_prominence_db: float = 3.0,
    min_snr_db: float | None = 15.0,
    floor_db: float = 40.0,
    min_distance_hz: float | None = None,
    max_peaks: int | None = None,
) -> Peaks:
    """Candidate resonances from the multi-channel mode indicator function.

    Peaks of ``10 log10(MIF)`` (:func:`mode_indicator` of the bins in
    ``[f_min, f_max]``) are found with :func:`scipy.signal.find_peaks`; the
    prominence is measured in dB, i.e. relative to the local level (the higher
    of the two lowest points between the peak and a higher neighbour). Every
    peak that passes is reported, also those no model predicted.

    Parameters
    ----------
    frequency_hz : array_like
        ``(F,)`` strictly increasing frequencies in Hz.
    H : array_like
        ``(F,)`` or ``(F, R)`` complex accelerance.
    f_min, f_max : float, optional
        Search range in Hz (default: all bins). Peaks at the range edges are
        not reported.
    min_prominence_db : float, default 3.0
        Minimum prominence in dB. A 15 %-damped accelerance peak on its own
        mass line stands about 10 dB out.
    min_snr_db : float or None, default 15.0
        Minimum ratio of the power by which the peak rises above its base
        (the prominence, in linear MIF units) to the noise power. The noise
        power of each channel is estimated robustly from second differences
        along frequency, ``median |H[k-1] - 2H[k] + H[k+1]|^2 / (6 ln 2)``
        over the range. This rejects the dB ripple of noise-dominated
        stretches (e.g. the low end of an accelerance), where noise alone
        makes peaks of several dB. ``None`` disables the test.
    floor_db : float, default 40.0
        Ignore peaks more than this many dB below the highest peak found.
    min_distance_hz : float, optional
        Minimum spacing of reported peaks (the more prominent one wins).
    max_peaks : int, optional
        Report at most this many (the most prominent).

    Returns
    -------
    Peaks
        ``(frequency_hz, index, prominence_db)`` sorted by decreasing
        prominence; ``frequency_hz`` is refined by a parabola through the
        three dB values around ``index``. Empty arrays if nothing qualifies.

    Examples
    --------
    >>> import numpy as np
    >>> f = np.arange(500.0, 5000.0, 5.0)
    >>> s = 2j * np.pi * f
    >>> def acc(fn, z, c):
    ...     w = 2 * np.pi * fn
    ...     return -c * (2 * np.pi * f) ** 2 / (w**2 + s**2 + 2 * z * w * s)
    >>> H = np.stack([acc(1075, 0.105, 0.4) + acc(3450, 0.03, 0.5),
    ...               acc(1075, 0.105, 0.3) - acc(3450, 0.03, 0.2)], axis=1)
    >>> peaks = find_peaks(f, H)
    >>> np.round(peaks.frequency_hz, -1)
    array([3450., 1090.])
    """
    f = _as_frequency(frequency_hz)
    H = _as_frf(f, H)
    if not min_prominence_db > 0:
        raise ValueError(f"min_prominence_db must be > 0, got {min_prominence_db}")
    if not floor_db > 0:
        raise ValueError(f"floor_db must be > 0, got {floor_db}")
    if max_peaks is not None and max_peaks < 1:
        raise ValueError(f"max_peaks must be >= 1, got {max_peaks}")
    sel = np.flatnonzero(_band_mask(f, f_min, f_max, "(f_min, f_max)"))
    empty = Peaks(np.zeros(0), np.zeros(0, dtype=int), np.zeros(0))
    if sel.size < 3:
        return empty
    mif = mode_indicator(f[sel], H[sel])
    tiny = np.finfo(float).tiny
    db = 10.0 * np.log10(np.maximum(mif, tiny))
    if min_distance_hz is not None:
        if not min_distance_hz > 0:
            raise ValueError(f"min_distance_hz must be > 0, got {min_distance_hz}")
        import scipy.signal

        distance = max(1.0, min_distance_hz / float(np.median(np.diff(f[sel]))))
        idx, props = scipy.signal.find_peaks(db, prominence=min_prominence_db, distance=distance)
        prom = props["prominences"]
    else:
        idx, prom = prominent_peaks(db, min_prominence_db)
    if idx.size == 0:
        return empty
    keep = db[idx] >= db[idx].max() - floor_db
    idx, prom = idx[keep], prom[keep]
    if min_snr_db is not None and idx.size:
        # noise power in MIF units: sum_r sigma_r^2 / mean|H_r|^2
        mean = np.mean(np.abs(H[sel]) ** 2, axis=0)
        used = mean > 0
        nu = float(np.sum(_noise_power(H[sel])[used] / mean[used]))
        excess = mif[idx] * (1.0 - 10.0 ** (-prom / 10.0))
        keep = excess >= nu * 10.0 ** (min_snr_db / 10.0)
        idx, prom = idx[keep], prom[keep]
    order = np.argsort(-prom, kind="stable")
    if max_peaks is not None:
        order = order[:max_peaks]
    idx, prom = idx[order], prom[order]
    fpk = np.array([_parabolic_vertex(f[sel][i - 1 : i + 2], db[i - 1 : i + 2])[0] for i in idx])
    return Peaks(fpk, sel[idx], prom)


# --------------------------------------------------------------- half power


def _magnitude(f: np.ndarray, H_channel_or_magnitude) -> np.ndarray:
    h = np.asarray(H_channel_or_magnitude)
    if h.ndim == 2 and h.shape[1] == 1:
        h = h[:, 0]
    if h.ndim != 1 or h.size != f.size:
        raise ValueError(f"H_channel_or_magnitude must have shape ({f.size},), got {np.shape(h)}")
    if not np.all(np.isfinite(h)):
        raise ValueError("H_channel_or_magnitude contains non-finite values")
    return np.abs(h).astype(float)


def half_power(
    frequency_hz,
    H_channel_or_magnitude,
    peak_index: int,
    *,
    peak_interpolation: str = "inverse_square",
    min_bins: float = 3.0,
    strict: bool = False,
) -> HalfPower:
    """Half-power (-3 dB) bandwidth damping of one peak, Eq. (26) and Eq. (28).

    The paper's single-DOF estimate ``xi = (f2 - f1) / (2 f)`` (Eq. (26) for
    the vertical, Eq. (28) for the horizontal mode), with ``f`` the frequency
    of the |H| maximum and ``f1 < f < f2`` where ``|H| = |H_peak| / sqrt(2)``.

    * The peak: starting at ``peak_index`` the search climbs to the local
      maximum bin, then a parabola through the three bins around it gives
      ``f_peak`` and ``|H_peak|``. The default parabola in ``1/|H|^2`` is
      exact for an SDOF resonance in ``(f_n/f)^2`` and nearly so in ``f``;
      ``"log"`` (parabola in ``ln|H|``, a Gaussian fit) and ``"linear"``
      (in ``|H|``) are offered for comparison.
    * The crossings: ``ln|H|`` is interpolated linearly between the two bins
      that straddle ``|H_peak| / sqrt(2)``. The half-power point of a
      resonance is an inflection point of ``ln|H|``, so this is accurate to
      third order (``|H|`` itself is convex there and would widen the band).

    For an SDOF accelerance with 2, 3, 5 bins between ``f1`` and ``f2`` the
    bandwidth error is at most 1.6 %, 0.4 %, 0.05 % (worst bin offset,
    noise-free). With noise, damping of 10 % or neighbouring modes use
    :func:`fit_modes`.

    This is the |H| peak, not the undamped natural frequency: for an
    accelerance ``f_peak = f_n / sqrt(1 - 2 zeta^2)``, and Eq. (26) divided by
    ``f_peak`` is 4.7 % high at zeta = 0.105. Use
    :func:`sdof_from_half_power` for the exact ``f_n`` and ``zeta``.

    Parameters
    ----------
    frequency_hz : array_like
        ``(F,)`` strictly increasing frequencies in Hz.
    H_channel_or_magnitude : array_like
        ``(F,)`` complex FRF of one channel, or its magnitude (any FRF kind;
        e.g. ``sqrt(mode_indicator(...))`` to use all channels).
    peak_index : int
        Index of (or near) the peak bin, e.g. from :func:`find_peaks`.
    peak_interpolation : {"inverse_square", "log", "linear"}
        Quantity the peak parabola is fitted to: ``1/|H|^2``, ``ln|H|``, ``|H|``.
    min_bins : float, default 3.0
        Fewer bins between ``f1`` and ``f2`` than this is flagged.
    strict : bool, default False
        Raise :class:`~guidefit.errors.IdentificationError` instead of
        warning :class:`HalfPowerWarning` when the band is under ``min_bins``.

    Returns
    -------
    HalfPower
        ``(f_peak_hz, f1_hz, f2_hz, zeta)``.

    Raises
    ------
    guidefit.errors.IdentificationError
        If the peak is at the array edge, or a crossing is not found before
        the array ends or the magnitude rises again by more than 1 dB (a
        neighbouring mode keeps the level above the half-power line).
    ValueError
        For malformed arguments.

    Warns
    -----
    HalfPowerWarning
        If the band spans fewer than ``min_bins`` bins (and not ``strict``).

    Examples
    --------
    >>> import numpy as np
    >>> f = np.arange(2000.0, 5000.0, 2.0)
    >>> fn, zeta = 3450.0, 0.0288
    >>> r = f / fn
    >>> H = -r**2 / (1 - r**2 + 2j * zeta * r)     # SDOF accelerance x m
    >>> hp = half_power(f, H, int(np.argmax(abs(H))))
    >>> round(hp.f_peak_hz, 1), round(hp.zeta, 5)    # Eq. (26): 0.3 % high
    (3452.9, 0.0289)
    >>> est = sdof_from_half_power(hp.f1_hz, hp.f2_hz)
    >>> round(est.f_n_hz, 1), round(est.zeta, 5)
    (3450.0, 0.0288)
    """
    f = _as_frequency(frequency_hz)
    mag = _magnitude(f, H_channel_or_magnitude)
    if peak_interpolation not in _PEAK_INTERPOLATIONS:
        raise ValueError(
            f"peak_interpolation must be one of {_PEAK_INTERPOLATIONS}, got {peak_interpolation!r}"
        )
    i = int(peak_index)
    if not 0 <= i < f.size:
        raise ValueError(f"peak_index must be in [0, {f.size - 1}], got {peak_index}")
    while True:  # climb to the local maximum
        if i > 0 and mag[i - 1] > mag[i]:
            i -= 1
        elif i < f.size - 1 and mag[i + 1] > mag[i]:
            i += 1
        else:
            break
    if i == 0 or i == f.size - 1:
        raise IdentificationError(
            f"half_power: peak_index={peak_index} climbs to the array edge at {f[i]:.1f} Hz"
        )
    if mag[i] <= 0:
        raise IdentificationError(f"half_power: zero magnitude at peak_index={peak_index}")
    x3, m3 = f[i - 1 : i + 2], mag[i - 1 : i + 2]
    if np.any(m3 <= 0):
        f_peak, h_peak = float(f[i]), float(mag[i])
    elif peak_interpolation == "inverse_square":
        f_peak, y = _parabolic_vertex(x3, m3**-2.0)
        h_peak = y**-0.5 if y > 0 else float(mag[i])
    elif peak_interpolation == "log":
        f_peak, y = _parabolic_vertex(x3, np.log(m3))
        h_peak = math.exp(y)
    else:
        f_peak, h_peak = _parabolic_vertex(x3, m3)
    h_peak = max(h_peak, float(mag[i]))
    with np.errstate(divide="ignore"):
        logmag = np.log(mag)
    thr = math.log(h_peak) - 0.5 * math.log(2.0)
    if logmag[i] <= thr:
        raise IdentificationError(
            f"half_power: the peak at {f_peak:.1f} Hz is narrower than one bin "
            f"(interpolated maximum {20 * math.log10(h_peak / mag[i]):.1f} dB above the bin)"
        )
    f1 = _crossing(f, logmag, i, thr, -1)
    f2 = _crossing(f, logmag, i, thr, +1)
    zeta = (f2 - f1) / (2.0 * f_peak)  # Eq. (26) / Eq. (28)
    n_bins = (f2 - f1) / float(np.median(np.diff(f[max(i - 3, 0) : i + 4])))
    if n_bins < min_bins:
        msg = (
            f"half_power: band of the peak at {f_peak:.1f} Hz spans {n_bins:.1f} bins "
            f"(min_bins={min_bins}); zeta={zeta:.4g} is biased, use fit_modes"
        )
        if strict:
            raise IdentificationError(msg)
        warnings.warn(msg, HalfPowerWarning, stacklevel=2)
    return HalfPower(float(f_peak), float(f1), float(f2), float(zeta))


def _crossing(f, logmag, i, thr, step, rise_db=1.0) -> float:
    """Frequency where ln|H| falls through ``thr`` walking from bin i in direction step."""
    rise = rise_db * math.log(10.0) / 20.0
    side = "upper" if step > 0 else "lower"
    j, low = i, logmag[i]
    while True:
        k = j + step
        if k < 0 or k >= f.size:
            raise IdentificationError(
                f"half_power: {side} half-power crossing of the peak at {f[i]:.1f} Hz "
                f"not found before the end of the band ({f[j]:.1f} Hz)"
            )
        if logmag[k] <= thr:
            if not np.isfinite(logmag[k]):
                return float(f[k])
            t = (logmag[j] - thr) / (logmag[j] - logmag[k])
            return float(f[j] + t * (f[k] - f[j]))
        low = min(low, logmag[k])
        if logmag[k] > low + rise:
            raise IdentificationError(
                f"half_power: {side} half-power crossing of the peak at {f[i]:.1f} Hz "
                f"not found; the level rises again at {f[k]:.1f} Hz (neighbouring mode)"
            )
        j = k


def sdof_from_half_power(f1_hz: float, f2_hz: float, kind: str = "accelerance") -> SdofEstimate:
    """Exact undamped frequency and damping of an SDOF FRF from its half-power points.

    With ``q = (f2^2 - f1^2) / (f2^2 + f1^2)``:

    * accelerance: ``zeta = sqrt((1 - 1/sqrt(1 + q^2)) / 2)``,
      ``f_n^2 = 2 (1 - 2 zeta^2) / (f1^-2 + f2^-2)``, peak at
      ``f_n / sqrt(1 - 2 zeta^2)``;
    * receptance: the same ``zeta``, ``f_n^2 = (f1^2 + f2^2) / (2 (1 - 2 zeta^2))``,
      peak at ``f_n sqrt(1 - 2 zeta^2)``;
    * mobility: ``f_n = sqrt(f1 f2)``, ``zeta = (f2 - f1) / (2 f_n)``, peak at ``f_n``.

    These follow from ``|H|^2 = |H_peak|^2 / 2`` for ``H = r^2 / (1 - r^2 + 2j zeta r)``
    (accelerance), whose half-power points satisfy
    ``(f_n/f)^2 = 1 - 2 zeta^2 +/- 2 zeta sqrt(1 - zeta^2)``. The paper's
    Eq. (26)/(28), ``(f2 - f1) / (2 f_peak)``, is their small-damping limit.

    Parameters
    ----------
    f1_hz, f2_hz : float
        Lower and upper half-power frequencies in Hz, ``0 < f1_hz < f2_hz``.
    kind : {"accelerance", "mobility", "receptance"}
        The kind of FRF whose magnitude gave ``f1_hz`` and ``f2_hz``.

    Returns
    -------
    SdofEstimate
        ``(f_n_hz, zeta, f_peak_hz)``.

    Examples
    --------
    >>> est = sdof_from_half_power(986.7, 1226.4)   # 1075 Hz, zeta 0.105 accelerance
    >>> round(est.f_n_hz), round(est.zeta, 3), round(est.f_peak_hz)
    (1075, 0.105, 1087)
    """
    f1, f2 = float(f1_hz), float(f2_hz)
    if not 0 < f1 < f2:
        raise ValueError(f"need 0 < f1_hz < f2_hz, got f1_hz={f1_hz}, f2_hz={f2_hz}")
    if kind not in _KINDS:
        raise ValueError(f"kind must be one of {_KINDS}, got {kind!r}")
    if kind == "mobility":
        fn = math.sqrt(f1 * f2)
        return SdofEstimate(fn, (f2 - f1) / (2 * fn), fn)
    q = (f2 * f2 - f1 * f1) / (f2 * f2 + f1 * f1)
    zeta = math.sqrt(max(0.0, (1.0 - 1.0 / math.sqrt(1.0 + q * q)) / 2.0))
    g = 1.0 - 2.0 * zeta * zeta
    if kind == "accelerance":
        fn = math.sqrt(2.0 * g / (f1**-2 + f2**-2))
    else:
        fn = math.sqrt((f1 * f1 + f2 * f2) / (2.0 * g))
    return SdofEstimate(fn, zeta, natural_from_peak_frequency(fn, zeta, kind, inverse=True))


def natural_from_peak_frequency(
    f_peak_hz: float, zeta: float, kind: str = "accelerance", *, inverse: bool = False
) -> float:
    """Undamped natural frequency from the |H| peak of an SDOF FRF (or back).

    ``f_n = f_peak sqrt(1 - 2 zeta^2)`` for accelerance,
    ``f_n = f_peak / sqrt(1 - 2 zeta^2)`` for receptance, ``f_n = f_peak`` for
    mobility. With ``inverse=True`` the first argument is ``f_n`` and the peak
    frequency is returned.

    Parameters
    ----------
    f_peak_hz : float
        Frequency of the magnitude peak in Hz (``f_n`` if ``inverse``).
    zeta : float
        Damping ratio, ``0 <= zeta < 1/sqrt(2)``.
    kind : {"accelerance", "mobility", "receptance"}
        The kind of FRF.
    inverse : bool, default False
        Convert ``f_n`` to the peak frequency instead.

    Returns
    -------
    float
        Frequency in Hz.

    Examples
    --------
    >>> round(natural_from_peak_frequency(1087.05, 0.105), 1)
    1075.0
    """
    if kind not in _KINDS:
        raise ValueError(f"kind must be one of {_KINDS}, got {kind!r}")
    if not 0 <= zeta < math.sqrt(0.5):
        raise ValueError(f"zeta must be in [0, 1/sqrt(2)), got {zeta}")
    if kind == "mobility":
        return float(f_peak_hz)
    g = math.sqrt(1.0 - 2.0 * zeta * zeta)
    up = (kind == "accelerance") != inverse
    return float(f_peak_hz) * g if up else float(f_peak_hz) / g


def half_power_mode(
    frequency_hz, H, peak_index: int, *, channel: int | None = None, **half_power_kwargs
) -> Mode:
    """A :class:`Mode` from the half-power method, with SDOF-estimated residues.

    :func:`half_power` runs on ``|H[:, channel]|`` or, if ``channel`` is None,
    on ``sqrt(mode_indicator)`` of all channels. ``f_n`` and ``zeta`` then come
    from :func:`sdof_from_half_power` (accelerance, exact for an SDOF), not
    from Eq. (26). Each channel's modal constant is the real least-squares
    fit of the SDOF accelerance shape to the bins between ``f1`` and ``f2``,
    so residue signs and ratios follow the convention of the module
    docstring. Neighbouring modes bias all of it; prefer :func:`fit_modes`.

    Parameters
    ----------
    frequency_hz : array_like
        ``(F,)`` frequencies in Hz.
    H : array_like
        ``(F,)`` or ``(F, R)`` complex accelerance.
    peak_index : int
        Index of (or near) the peak bin.
    channel : int, optional
        Channel for the half-power band (default: all channels combined).
    **half_power_kwargs
        Passed to :func:`half_power`.

    Returns
    -------
    Mode
        ``method="half_power"``, standard deviations ``None``.

    Examples
    --------
    >>> import numpy as np
    >>> f = np.arange(2000.0, 5000.0, 2.0)
    >>> r = f / 3450.0
    >>> sdof = -r**2 / (1 - r**2 + 2j * 0.0288 * r)
    >>> m = half_power_mode(f, np.stack([0.5 * sdof, -0.25 * sdof], axis=1), 725)
    >>> round(m.frequency_hz, 1), round(m.damping_ratio, 4)
    (3450.0, 0.0288)
    >>> np.round(m.modal_constants.real, 3)
    array([ 0.5 , -0.25])
    """
    f = _as_frequency(frequency_hz)
    H = _as_frf(f, H)
    if channel is None:
        mag = np.sqrt(mode_indicator(f, H))
    else:
        if not -H.shape[1] <= channel < H.shape[1]:
            raise ValueError(f"channel must be in [0, {H.shape[1] - 1}], got {channel}")
        mag = np.abs(H[:, channel])
    hp = half_power(f, mag, peak_index, **half_power_kwargs)
    est = sdof_from_half_power(hp.f1_hz, hp.f2_hz, "accelerance")
    sel = (f >= hp.f1_hz) & (f <= hp.f2_hz)
    if sel.sum() < 1:
        sel = np.abs(f - hp.f_peak_hz) == np.min(np.abs(f - hp.f_peak_hz))
    w, wn = 2 * np.pi * f[sel], 2 * np.pi * est.f_n_hz
    g = -(w**2) / (wn**2 - w**2 + 2j * est.zeta * wn * w)  # accelerance of modal constant 1
    c = (np.conj(g)[:, None] * H[sel]).sum(axis=0).real / np.sum(np.abs(g) ** 2)
    wd = wn * math.sqrt(1.0 - est.zeta**2)
    return Mode(est.f_n_hz, est.zeta, c / (2j * wd), "half_power", None, None)


# ------------------------------------------------------------ curve fitting


def _poles(wn: np.ndarray, zeta: np.ndarray) -> np.ndarray:
    return wn * (-zeta + 1j * np.sqrt(1.0 - zeta**2))


def _basis(s: np.ndarray, poles: np.ndarray, terms: tuple) -> np.ndarray:
    """(F, 2n + len(terms)) complex columns; real coefficients (Re A, Im A, ..., terms)."""
    s2 = (s * s)[:, None]
    poles = np.asarray(poles)
    a = s2 / (s[:, None] - poles[None, :])
    b = s2 / (s[:, None] - np.conj(poles)[None, :])
    out = np.empty((s.size, 2 * poles.size + len(terms)), dtype=complex)
    out[:, 0:2 * poles.size:2] = a + b  # the same element-wise operations as one column at a time
    out[:, 1:2 * poles.size:2] = 1j * (a - b)
    for j, t in enumerate(terms):
        out[:, 2 * poles.size + j] = _RESIDUAL_TERMS[t](s)
    return out


def _stack(z: np.ndarray) -> np.ndarray:
    return np.concatenate([z.real, z.imag], axis=0)


def _ls_solver(A: np.ndarray):
    """``V -> (A^T A)^-1 V`` by a Cholesky factor of the normal matrix, or ``None``.

    ``None`` when ``A^T A`` is not numerically positive definite (rank-deficient
    ``A``); callers then fall back to an SVD solve. LAPACK's ``potrf`` and
    ``potrs`` are called directly: they are what ``scipy.linalg.cho_factor``
    and ``cho_solve`` run (same arguments, same numbers), without their
    argument checks, which cost as much as the factorisation of these small
    matrices (the global fit factorises a few hundred of them).
    """
    potrf, potrs = _cholesky_lapack()
    factor, info = potrf(A.T @ A, lower=False, overwrite_a=False, clean=False)
    if info > 0:
        return None
    if info < 0:  # pragma: no cover - a malformed argument
        raise ValueError(f"illegal value in argument {-info} of LAPACK potrf")

    def solve(V):
        x, info = potrs(factor, V, lower=False, overwrite_b=False)
        if info != 0:  # pragma: no cover - a malformed argument
            raise ValueError(f"illegal value in argument {-info} of LAPACK potrs")
        return x

    return solve


_LAPACK: list = []


def _cholesky_lapack():
    """LAPACK ``dpotrf`` and ``dpotrs`` (scipy.linalg.lapack), looked up once."""
    if not _LAPACK:
        from scipy.linalg import lapack

        _LAPACK.extend([lapack.dpotrf, lapack.dpotrs])
    return _LAPACK[0], _LAPACK[1]


def _ls_fit(A: np.ndarray, Y: np.ndarray, solver=None):
    """Least-squares fit of Y by the columns of A (unit-norm columns).

    Normal equations with one step of iterative refinement: much cheaper
    than a QR for tall, narrow A, and as accurate while cond(A)^2 eps << 1.
    ``solver``: the :func:`_ls_solver` of ``A`` when the caller has it (the
    same design fitted to other data).

    Returns
    -------
    (E, B, solve)
        Residual ``Y - A B``, coefficients ``B`` and the normal-matrix solver of
        :func:`_ls_solver`; ``solve`` is ``None`` when A is rank deficient and the
        fit fell back to an SVD solve.
    """
    solve = solver or _ls_solver(A)
    if solve is not None:
        B = solve(A.T @ Y)
        B += solve(A.T @ (Y - A @ B))
        if np.all(np.isfinite(B)):
            return Y - A @ B, B, solve
    B = np.linalg.lstsq(A, Y, rcond=None)[0]
    return Y - A @ B, B, None


def _ls_residual(A: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """Residual of the least-squares fit of Y by the columns of A (see :func:`_ls_fit`)."""
    return _ls_fit(A, Y)[0]


def _projected_jacobian(A, dA, pairs, E, B, solve) -> np.ndarray:
    """Jacobian of the variable-projection residual ``E = (I - A A^+) Y``.

    Golub and Pereyra's exact derivative for a design matrix whose parameter
    ``j`` moves only the two columns ``pairs[j]``:
    ``dE/dx_j = -(I - A A^+) dA_j B - A (A^T A)^-1 dA_j^T E``.

    Parameters
    ----------
    A : (M, L) design matrix (weighted, unit-norm columns).
    dA : (P, M, 2) derivatives of the two moved columns, scaled like A's columns.
    pairs : (P, 2) int, the columns each parameter moves.
    E, B : the fit's residual (M, R) and coefficients (L, R).
    solve : the normal-matrix solver of :func:`_ls_solver`.

    Returns
    -------
    numpy.ndarray, shape (M, R, P)
    """
    n_params = dA.shape[0]
    L, R = B.shape
    M = A.shape[0]
    V = dA @ B[pairs]  # dA_j B, (P, M, R)
    Z = np.zeros((n_params, L, R))
    Z[np.arange(n_params)[:, None], pairs] = dA.transpose(0, 2, 1) @ E  # dA_j^T E
    rhs = (A.T @ V) - Z  # (P, L, R)
    coef = solve(rhs.transpose(1, 0, 2).reshape(L, -1))  # (L, P R)
    dE = (A @ coef).reshape(M, n_params, R) - V.transpose(1, 0, 2)
    dE = dE.transpose(0, 2, 1)
    return dE


def _pole_derivatives(s, wn, zeta):
    """d(raw basis column pair)/dx of every pole parameter x = (ln w_n..., ln zeta...).

    Returns complex (P, F, 2) with P = 2n: the derivatives of the columns
    ``a + b`` and ``j (a - b)`` of :func:`_basis` (``a = s^2/(s - p)``,
    ``b = s^2/(s - p*)``) with ``dp/d ln w_n = p`` and
    ``dp/d ln zeta = zeta w_n (-1 - j zeta / sqrt(1 - zeta^2))``.
    """
    poles = _poles(wn, zeta)
    dp = np.concatenate([poles, zeta * wn * (-1.0 - 1j * zeta / np.sqrt(1.0 - zeta**2))])
    p = np.concatenate([poles, poles])
    s2 = (s * s)[None, :]
    da = s2 / (s[None, :] - p[:, None]) ** 2 * dp[:, None]
    db = s2 / (s[None, :] - np.conj(p)[:, None]) ** 2 * np.conj(dp)[:, None]
    return np.stack([da + db, 1j * (da - db)], axis=2)


class _Problem:
    """Weighted, normalised band data of one fit (internal)."""

    def __init__(self, f, H, weights, terms):
        self.f = f
        self.s = 2j * np.pi * f
        self.terms = terms
        rms = np.sqrt(np.mean(np.abs(H) ** 2, axis=0))
        self.scale = np.where(rms > 0, 1.0 / np.where(rms > 0, rms, 1.0), 1.0)  # per channel
        W = np.ones((f.size, H.shape[1])) if weights is None else weights
        self.W2 = np.concatenate([W, W], axis=0)  # (2F, R) for stacked rows
        self.common = bool(np.all(W == W[:, :1]))
        self.Y = _stack(H * self.scale) * self.W2  # (2F, R)

    def _design(self, poles):
        Phi = _stack(_basis(self.s, poles, self.terms))  # (2F, L)
        norm = np.sqrt(np.sum(Phi**2, axis=0))
        norm[norm == 0] = 1.0
        return Phi / norm, norm

    def _groups(self):
        """Channel groups sharing one weighted design: all at once or one by one."""
        if self.common:
            return [slice(None)]
        return [slice(r, r + 1) for r in range(self.Y.shape[1])]

    def residual(self, poles) -> np.ndarray:
        Phi, _ = self._design(poles)
        E = np.empty_like(self.Y)
        for g in self._groups():
            w = self.W2[:, g][:, :1]
            E[:, g] = _ls_residual(Phi * w, self.Y[:, g])
        return E.ravel()

    def jacobian(self, wn, zeta) -> np.ndarray | None:
        """d residual / d (ln w_n, ln zeta), shape (2F R, 2n); ``None`` if rank deficient.

        The exact variable-projection derivative (:func:`_projected_jacobian`):
        one factorisation per channel group instead of the 2n extra residual
        evaluations of finite differences. Column scaling does not change the
        projection, so the unit-norm design is used with its columns'
        derivatives divided by the same norms.
        """
        Phi, norm = self._design(_poles(wn, zeta))
        n = wn.size
        dcols = _pole_derivatives(self.s, wn, zeta)  # (2n, F, 2) complex
        dPhi = np.concatenate([dcols.real, dcols.imag], axis=1)  # (2n, 2F, 2)
        k = np.concatenate([np.arange(n), np.arange(n)])
        pairs = np.stack([2 * k, 2 * k + 1], axis=1)
        dPhi = dPhi / norm[pairs][:, None, :]
        J = np.empty(self.Y.shape + (2 * n,))
        for g in self._groups():
            w = self.W2[:, g][:, :1]
            A = Phi * w
            E, B, solve = _ls_fit(A, self.Y[:, g])
            if solve is None:
                return None
            J[:, g, :] = _projected_jacobian(A, dPhi * w[None], pairs, E, B, solve)
        return J.reshape(-1, 2 * n)

    def coefficients(self, poles) -> np.ndarray:
        """(L, R) real coefficients of the normalised, weighted problem."""
        Phi, norm = self._design(poles)
        B = np.empty((Phi.shape[1], self.Y.shape[1]))
        for r in range(self.Y.shape[1]):
            B[:, r] = np.linalg.lstsq(Phi * self.W2[:, r : r + 1], self.Y[:, r], rcond=None)[0]
        return B / norm[:, None]


def _unpack(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    n = x.size // 2
    return np.exp(x[:n]), np.exp(x[n:])


def _covariance(prob: _Problem, wn, zeta, B) -> tuple[np.ndarray, np.ndarray]:
    """Std of (wn, zeta) per mode from the full Jacobian of the weighted residual."""
    n, R = wn.size, B.shape[1]
    s = prob.s
    poles = _poles(wn, zeta)
    Phi = _stack(_basis(s, poles, prob.terms))  # (2F, L)
    L = Phi.shape[1]
    rows = 2 * s.size
    J = np.zeros((rows * R, 2 * n + R * L))
    E = np.empty((rows, R))
    for r in range(R):
        w = prob.W2[:, r]
        sl = slice(r * rows, (r + 1) * rows)
        E[:, r] = prob.Y[:, r] - w * (Phi @ B[:, r])
        J[sl, 2 * n + r * L : 2 * n + (r + 1) * L] = w[:, None] * Phi
        for k in range(n):
            A = B[2 * k, r] + 1j * B[2 * k + 1, r]
            p = poles[k]
            dA = s * s * A / (s - p) ** 2
            dB = s * s * np.conj(A) / (s - np.conj(p)) ** 2
            dp_dwn = p / wn[k]
            dp_dz = wn[k] * (-1.0 - 1j * zeta[k] / math.sqrt(1.0 - zeta[k] ** 2))
            J[sl, k] = w * _stack(dA * dp_dwn + dB * np.conj(dp_dwn))
            J[sl, n + k] = w * _stack(dA * dp_dz + dB * np.conj(dp_dz))
    dof = J.shape[0] - J.shape[1]
    if dof <= 0:
        return np.full(n, np.nan), np.full(n, np.nan)
    sigma2 = float(np.sum(E**2)) / dof
    norm = np.sqrt(np.sum(J**2, axis=0))
    norm[norm == 0] = 1.0
    Js = J / norm
    cov = np.linalg.pinv(Js.T @ Js) / np.outer(norm, norm) * sigma2
    var = np.diag(cov)[: 2 * n]
    std = np.sqrt(np.maximum(var, 0.0))
    return std[:n], std[n:]


def _solve(prob: _Problem, wn0, z0, bounds_wn, max_nfev):
    """Variable-projection least squares from initial (wn, zeta); returns (wn, zeta, cost)."""
    import scipy.optimize

    zlo, zhi = 1e-5, 0.7
    x0 = np.concatenate([np.log(np.clip(wn0, *bounds_wn)), np.log(np.clip(z0, zlo, zhi))])
    n = wn0.size
    lo = np.concatenate([np.full(n, math.log(bounds_wn[0])), np.full(n, math.log(zlo))])
    hi = np.concatenate([np.full(n, math.log(bounds_wn[1])), np.full(n, math.log(zhi))])
    x0 = np.clip(x0, lo + 1e-12, hi - 1e-12)

    def fun(x):
        wn, z = _unpack(x)
        return prob.residual(_poles(wn, z))

    def jac(x):
        J = prob.jacobian(*_unpack(x))
        if J is not None:
            return J
        # Rank-deficient design: forward differences, as least_squares' "2-point".
        f0 = fun(x)
        steps = np.sqrt(np.finfo(float).eps) * np.maximum(1.0, np.abs(x))
        return np.stack([(fun(x + h * e) - f0) / h for h, e in zip(steps, np.eye(x.size))], axis=1)

    res = scipy.optimize.least_squares(
        fun,
        x0,
        jac=jac,
        bounds=(lo, hi),
        method="trf",
        x_scale=1.0,
        max_nfev=max_nfev,
        xtol=1e-12,
        ftol=1e-12,
        gtol=1e-12,
    )
    wn, z = _unpack(res.x)
    return wn, z, float(np.sum(res.fun**2))


def _peak_guesses(f, H, n, min_prominence_db=1.0, min_snr_db=15.0):
    """Up to n (f_n, zeta) guesses from peaks of the band's mode indicator."""
    pk = find_peaks(
        f,
        H,
        min_prominence_db=min_prominence_db,
        min_snr_db=min_snr_db,
        floor_db=60.0,
        max_peaks=n,
    )
    mag = np.sqrt(mode_indicator(f, H))
    return [_sdof_guess(f, mag, int(i), float(fp))[:2] for fp, i in zip(pk.frequency_hz, pk.index)]


def _sdof_guess(f, mag, i, fp) -> tuple[float, float, bool]:
    """(f_n, zeta, ok) from half-power on a magnitude; (fp, 0.03, False) if that fails."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", HalfPowerWarning)
            hp = half_power(f, mag, i)
        est = sdof_from_half_power(hp.f1_hz, hp.f2_hz)
        return est.f_n_hz, min(max(est.zeta, 1e-4), 0.5), True
    except IdentificationError:
        return fp, 0.03, False


def _suspicious(mode: Mode, lo: float, hi: float) -> bool:
    """Fitted mode outside the band or at a damping bound of :func:`_solve`."""
    z = mode.damping_ratio
    return not lo <= mode.frequency_hz <= hi or z > 0.69 or z < 2e-5


def _initial(prob: _Problem, H, n_modes, bounds_wn, max_nfev):
    """Initial poles: peaks of the band, then greedy additions at residual peaks."""
    f = prob.f
    guesses = _peak_guesses(f, H, n_modes)
    if not guesses:
        i = int(np.argmax(mode_indicator(f, H)))
        i = min(max(i, 1), f.size - 2)
        guesses = [_sdof_guess(f, np.sqrt(mode_indicator(f, H)), i, float(f[i]))[:2]]
    wn = 2 * np.pi * np.array([g[0] for g in guesses])
    z = np.array([g[1] for g in guesses])
    while wn.size < n_modes:
        wn, z, _ = _solve(prob, wn, z, bounds_wn, max_nfev)
        B = prob.coefficients(_poles(wn, z))
        model = _basis(prob.s, _poles(wn, z), prob.terms) @ B
        E = H * prob.scale - model
        cand = _peak_guesses(f, E, 3, min_prominence_db=0.5, min_snr_db=None)
        i = int(np.argmax(mode_indicator(f, E)))
        cand.append((float(f[i]), 0.03))
        best = None
        for fc, zc in cand:
            wn_t, z_t, cost = _solve(
                prob, np.append(wn, 2 * np.pi * fc), np.append(z, zc), bounds_wn, max_nfev
            )
            if best is None or cost < best[2]:
                best = (wn_t, z_t, cost)
        wn, z = best[0], best[1]
    return wn, z


def _initial_from(initial, n_modes):
    init = list(initial)
    if len(init) != n_modes:
        raise ValueError(f"initial must hold n_modes={n_modes} entries, got {len(init)}")
    fn, z = [], []
    for k, m in enumerate(init):
        if isinstance(m, Mode):
            fk, zk = m.frequency_hz, m.damping_ratio
        else:
            try:
                fk, zk = (float(v) for v in m)
            except (TypeError, ValueError):
                raise ValueError(
                    f"initial[{k}] must be a Mode or (frequency_hz, zeta), got {m!r}"
                ) from None
        if not (fk > 0 and 0 < zk < 1):
            raise ValueError(f"initial[{k}] needs frequency_hz > 0 and 0 < zeta < 1, got {m!r}")
        fn.append(fk)
        z.append(zk)
    return 2 * np.pi * np.array(fn), np.array(z)


def fit_band(
    frequency_hz,
    H,
    band_hz: tuple[float, float],
    n_modes: int,
    initial: Sequence | None = None,
    *,
    residuals: Sequence[str] = _DEFAULT_RESIDUALS,
    weights=None,
    max_nfev: int = 200,
    uncertainty: bool = True,
) -> BandFit:
    """Multi-channel modal curve fit in a band; :func:`fit_modes` plus residual terms.

    See :func:`fit_modes` for the method and the parameters.

    Returns
    -------
    BandFit
        Modes, residual-term coefficients per channel, the band, the
        normalised RMS misfit and the bin count.

    Examples
    --------
    >>> import numpy as np
    >>> f = np.arange(2000.0, 3000.0, 10.0)
    >>> s = 2j * np.pi * f
    >>> p = 2 * np.pi * 2400 * (-0.02 + 1j * np.sqrt(1 - 0.02**2))
    >>> A = np.array([1e-6j, -2e-6j])
    >>> H = s[:, None]**2 * (A / (s[:, None] - p) + A.conj() / (s[:, None] - p.conjugate())) + 0.1
    >>> fit = fit_band(f, H, (2000, 3000), 1)
    >>> round(fit.modes[0].frequency_hz, 3), np.round(fit.residuals["lower"], 6)
    (2400.0, array([0.1, 0.1]))
    """
    f = _as_frequency(frequency_hz)
    Hf = _as_frf(f, H)
    try:
        lo, hi = (float(b) for b in band_hz)
    except (TypeError, ValueError):
        raise ValueError(f"band_hz must be (f_lo, f_hi) in Hz, got {band_hz!r}") from None
    sel = _band_mask(f, lo, hi, "band_hz")
    if not isinstance(n_modes, (int, np.integer)) or n_modes < 1:
        raise ValueError(f"n_modes must be an integer >= 1, got {n_modes!r}")
    terms = (residuals,) if isinstance(residuals, str) else tuple(residuals)
    for term in terms:
        if term not in _RESIDUAL_TERMS:
            raise ValueError(f"residuals entries must be in {tuple(_RESIDUAL_TERMS)}, got {term!r}")
    if len(set(terms)) != len(terms):
        raise ValueError(f"residuals has repeated entries: {terms}")
    n_bins = int(sel.sum())
    n_lin = 2 * n_modes + len(terms)
    need = n_lin + n_modes + 2
    if n_bins < need:
        raise ValueError(
            f"band_hz={band_hz} holds {n_bins} bins; {n_modes} modes need at least {need}"
        )
    W = None
    if weights is not None:
        W = np.asarray(weights, dtype=float)
        if W.shape == (f.size,):
            W = np.repeat(W[:, None], Hf.shape[1], axis=1)
        if W.shape != Hf.shape or not np.all(np.isfinite(W)) or np.any(W < 0):
            raise ValueError(
                f"weights must be finite, >= 0 and of shape ({f.size},) or {Hf.shape}, "
                f"got shape {np.shape(weights)}"
            )
        W = W[sel]
    fb, Hb = f[sel], Hf[sel]
    prob = _Problem(fb, Hb, W, terms)
    if not np.any(prob.Y):
        raise IdentificationError(f"fit_band: H is zero in band_hz={band_hz}")
    bounds_wn = (2 * np.pi * 0.5 * fb[0], 2 * np.pi * 2.0 * fb[-1])
    if initial is None:
        wn0, z0 = _initial(prob, Hb, n_modes, bounds_wn, max_nfev)
    else:
        wn0, z0 = _initial_from(initial, n_modes)
    wn, z, cost = _solve(prob, wn0, z0, bounds_wn, max_nfev)
    order = np.argsort(wn)
    wn, z = wn[order], z[order]
    poles = _poles(wn, z)
    B = prob.coefficients(poles)  # for unit-RMS channels
    if uncertainty:
        std_wn, std_z = _covariance(prob, wn, z, B)
    else:
        std_wn = std_z = np.full(n_modes, np.nan)
    B = B / prob.scale[None, :]
    modes = []
    for k in range(n_modes):
        A = B[2 * k] + 1j * B[2 * k + 1]
        fk = float(wn[k] / (2 * np.pi))
        mode = Mode(
            fk, float(z[k]), A, "curve_fit", float(std_wn[k] / (2 * np.pi)), float(std_z[k])
        )
        if _suspicious(mode, fb[0], fb[-1]):
            warnings.warn(
                f"fit_band: mode {k} at {fk:.1f} Hz, zeta={z[k]:.3g} is outside "
                f"band_hz={band_hz} or at a damping bound; n_modes={n_modes} may be too many",
                ModeFitWarning,
                stacklevel=2,
            )
        modes.append(mode)
    coef = {t: B[2 * n_modes + j].copy() for j, t in enumerate(terms)}
    nrmse = math.sqrt(cost / float(np.sum(prob.Y**2)))
    return BandFit(modes, coef, (lo, hi), nrmse, n_bins)


def fit_modes(
    frequency_hz,
    H,
    band_hz: tuple[float, float],
    n_modes: int,
    initial: Sequence | None = None,
    *,
    residuals: Sequence[str] = _DEFAULT_RESIDUALS,
    weights=None,
    max_nfev: int = 200,
    uncertainty: bool = True,
) -> list[Mode]:
    """Fit ``n_modes`` modes with global poles to all channels in a band.

    The model is the pole-residue accelerance of the module docstring,
    ``H_r = (jw)^2 sum_k [A_rk/(jw - p_k) + A_rk*/(jw - p_k*)] + L_r + U_r (jw)^2``,
    with poles shared by all channels and complex residues per channel
    (conjugate pairs enforced). It is solved by variable projection: for
    given poles the residues and residual terms are a linear least-squares
    problem (real and imaginary parts stacked); the poles, parametrised by
    ``ln w_n`` and ``ln zeta``, minimise the projected misfit with
    :func:`scipy.optimize.least_squares`, given the exact Jacobian of the
    projected residual (Golub and Pereyra's formula, one Cholesky factor per
    evaluation; finite differences took 2n extra residual evaluations). Each channel is scaled to unit RMS in
    the band, so all channels count alike. The initial poles come from the
    band's peaks (:func:`find_peaks`, SDOF half-power damping); while fewer
    peaks than ``n_modes`` are seen (merged close modes), a mode is added at
    the strongest peak of the misfit and all are refitted.

    Parameters
    ----------
    frequency_hz : array_like
        ``(F,)`` strictly increasing frequencies in Hz.
    H : array_like
        ``(F,)`` or ``(F, R)`` complex accelerance in (m/s^2)/N.
    band_hz : (float, float)
        Fitted band in Hz. Include about two half-power bandwidths on each
        side of the outer modes; modes just outside the band are only
        approximated by the residual terms, so include a near neighbour
        in the band (and in ``n_modes``) rather than cut through its flank.
    n_modes : int
        Number of modes in the band.
    initial : sequence of Mode or (frequency_hz, zeta), optional
        Start values (``n_modes`` entries) instead of peak picking, e.g. the
        modes of the all-hits fit when refitting jackknife subsets.
    residuals : sequence of str, default ("lower", "lower_damping", "upper")
        Residual terms for the modes outside the band, each with one real
        coefficient per channel: ``"lower"`` ``L_r`` (the mass line of the
        modes below), ``"lower_damping"`` ``L1_r / (jw)`` (their damping
        tail), ``"upper"`` ``U_r (jw)^2`` (the residual compliance of the
        modes above), ``"upper_damping"`` ``U1_r (jw)^3``. They are the
        leading terms of a mode's accelerance far above (``1, 1/s``) and far
        below (``s^2, s^3``) its pole. In accelerance the modes below a band
        contribute O(1) and their damping tail decays only as ``1/w``, while
        modes above are suppressed by ``(w/w_k)^2``; hence the default. On
        the guideway test system of ``tests/test_modes.py`` the default cut
        the close pair's damping bias from 3.3 % (real ``L_r``, ``U_r`` only)
        to 0.2 %; adding ``"upper_damping"`` made the 10 %-damped mode's
        frequency 0.07 % biased at 3 % noise.
    weights : array_like, optional
        ``(F,)`` or ``(F, R)`` non-negative weights on the residual of each
        bin (e.g. derived from coherence), applied after the RMS scaling.
    max_nfev : int, default 200
        Function-evaluation limit of each nonlinear solve.
    uncertainty : bool, default True
        Compute ``frequency_std_hz`` and ``damping_std`` (NaN when False, e.g.
        for jackknife replicates, whose scatter is the uncertainty).

    Returns
    -------
    list of Mode
        Sorted by frequency; ``method="curve_fit"``. ``frequency_std_hz`` and
        ``damping_std`` are ``sqrt(diag(s^2 (J^T J)^-1))`` from the full
        Jacobian at the optimum, ``s^2`` the residual variance; they assume
        independent bins and ignore model error (band truncation).

    Raises
    ------
    ValueError
        For malformed arguments or a band with too few bins.
    guidefit.errors.IdentificationError
        If ``H`` is zero in the band.

    Warns
    -----
    ModeFitWarning
        If a fitted mode ends outside the band or at a damping bound.

    Examples
    --------
    >>> import numpy as np
    >>> f = np.arange(500.0, 1800.0, 10.0)
    >>> s = 2j * np.pi * f
    >>> wn, zeta = 2 * np.pi * 1075.0, 0.105
    >>> H = s**2 * 0.45 / (wn**2 + s**2 + 2 * zeta * wn * s)   # 1/m = 0.45 1/kg
    >>> [m] = fit_modes(f, H, (500.0, 1800.0), 1)
    >>> round(m.frequency_hz, 2), round(m.damping_ratio, 4), np.round(m.modal_constants.real, 4)
    (1075.0, 0.105, array([0.45]))
    """
    return fit_band(
        frequency_hz,
        H,
        band_hz,
        n_modes,
        initial,
        residuals=residuals,
        weights=weights,
        max_nfev=max_nfev,
        uncertainty=uncertainty,
    ).modes


def auto_fit(
    frequency_hz,
    H,
    f_min: float,
    f_max: float,
    *,
    min_prominence_db: float = 3.0,
    band_factor: float = 2.5,
    grow: bool = True,
    refine: bool = True,
    **fit_kwargs,
) -> list[Mode]:
    """Find and fit all modes between ``f_min`` and ``f_max`` without a model.

    1. :func:`find_peaks` lists the peaks; each gets a half-power bandwidth
       ``B`` from :func:`half_power` on ``sqrt(MIF)`` (5 % of the frequency
       if that fails) and the interval ``f_peak +/- band_factor * B``.
    2. Peaks whose intervals overlap form a group; each group is fitted by
       :func:`fit_band` with one mode per peak in the union of its intervals
       (clipped to ``[f_min, f_max]``). Modes that end outside the band or at
       a damping bound are dropped and the rest refitted.
    3. With ``grow`` (default), a group gets up to two more modes while its
       misfit exceeds 5 % and three times the noise level and an added mode
       (started at a peak of the misfit, in a band widened to hold it) is well
       determined and halves the squared misfit: a heavily damped mode next to
       a light one often has no peak of its own.
    4. With ``refine`` (default), all modes are refitted together over the
       union of the group bands, starting from the group results, so the
       flanks of neighbouring groups are modelled by modes instead of
       residual terms. The joint result replaces the group results unless it
       fits worse.

    Parameters
    ----------
    frequency_hz : array_like
        ``(F,)`` strictly increasing frequencies in Hz.
    H : array_like
        ``(F,)`` or ``(F, R)`` complex accelerance.
    f_min, f_max : float
        Search range in Hz.
    min_prominence_db : float, default 3.0
        Passed to :func:`find_peaks`.
    band_factor : float, default 2.5
        Half-width of a peak's fit interval in half-power bandwidths.
    grow : bool, default True
        Add modes that have no peak of their own (step 3).
    refine : bool, default True
        Refit all modes jointly at the end.
    **fit_kwargs
        ``residuals``, ``weights``, ``max_nfev`` for :func:`fit_band`.

    Returns
    -------
    list of Mode
        Sorted by frequency.

    Raises
    ------
    guidefit.errors.IdentificationError
        If no peak is found in ``[f_min, f_max]``.

    Examples
    --------
    >>> import numpy as np
    >>> f = np.arange(500.0, 5000.0, 5.0)
    >>> s = 2j * np.pi * f
    >>> def acc(fn, z, c):
    ...     w = 2 * np.pi * fn
    ...     return c * s**2 / (w**2 + s**2 + 2 * z * w * s)
    >>> H = np.stack([acc(1075, 0.105, 0.4) + acc(3450, 0.03, 0.5),
    ...               acc(1075, 0.105, 0.3) - acc(3450, 0.03, 0.2)], axis=1)
    >>> modes = auto_fit(f, H, 600.0, 4500.0)
    >>> [(round(m.frequency_hz, 1), round(m.damping_ratio, 4)) for m in modes]
    [(1075.0, 0.105), (3450.0, 0.03)]
    """
    f = _as_frequency(frequency_hz)
    Hf = _as_frf(f, H)
    if not band_factor > 0:
        raise ValueError(f"band_factor must be > 0, got {band_factor}")
    pk = find_peaks(f, Hf, f_min=f_min, f_max=f_max, min_prominence_db=min_prominence_db)
    if pk.index.size == 0:
        raise IdentificationError(
            f"auto_fit: no peak with prominence >= {min_prominence_db} dB "
            f"between f_min={f_min} Hz and f_max={f_max} Hz"
        )
    order = np.argsort(pk.frequency_hz)
    mag = np.sqrt(mode_indicator(f, Hf))
    items = []  # (f_n, zeta, interval low, interval high)
    for j in order:
        fp, i = float(pk.frequency_hz[j]), int(pk.index[j])
        fn, z, ok = _sdof_guess(f, mag, i, fp)
        bw = 2.0 * z * fn if ok else 0.1 * fp
        items.append((fn, z, fp - band_factor * bw, fp + band_factor * bw))
    groups = [[items[0]]]
    for it in items[1:]:
        if it[2] <= max(g[3] for g in groups[-1]):
            groups[-1].append(it)
        else:
            groups.append([it])
    lo_all, hi_all = max(f_min, f[0]), min(f_max, f[-1])
    modes, groups_fitted = [], []
    for j, g in enumerate(groups):
        # the group's territory ends a half-power bandwidth short of the modes fitted
        # so far below it and of the next group's peaks above it
        below = [m.frequency_hz * (1 + 2 * m.damping_ratio) for m in modes]
        t_lo = max([lo_all, *below])
        t_hi = (
            hi_all
            if j == len(groups) - 1
            else min(hi_all, min(it[0] * (1 - 2 * it[1]) for it in groups[j + 1]))
        )
        band = _widen(
            f,
            max(min(it[2] for it in g), lo_all),
            min(max(it[3] for it in g), hi_all),
            len(g),
            lo_all,
            hi_all,
        )
        fit = _fit_dropping(f, Hf, band, [(it[0], it[1]) for it in g], fit_kwargs)
        if fit is not None:
            fit = _grow(f, Hf, fit, (t_lo, t_hi), fit_kwargs) if grow else fit
            modes.extend(fit.modes)
            groups_fitted.append((fit.band_hz, fit.modes))
    if not modes:
        raise IdentificationError(
            f"auto_fit: no mode could be fitted between f_min={f_min} Hz and f_max={f_max} Hz"
        )
    if refine and len(groups_fitted) > 1 and len(modes) <= _MAX_JOINT_MODES:
        band = (groups_fitted[0][0][0], groups_fitted[-1][0][1])
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("error", ModeFitWarning)
                joint = fit_band(f, Hf, band, len(modes), modes, **fit_kwargs).modes
        except ModeFitWarning:
            joint = None
        # keep the joint fit only if no mode moved by more than half its bandwidth
        if joint is not None and all(
            abs(a.frequency_hz - b.frequency_hz) <= b.damping_ratio * b.frequency_hz
            for a, b in zip(joint, sorted(modes, key=lambda m: m.frequency_hz))
        ):
            modes = joint
    return sorted(modes, key=lambda m: m.frequency_hz)


_MAX_JOINT_MODES = 12


def _widen(f, lo, hi, n_modes, lo_all, hi_all, min_bins=None):
    """Widen (lo, hi) symmetrically, within (lo_all, hi_all), to hold enough bins for a fit."""
    need = min_bins if min_bins is not None else 3 * n_modes + 12
    while np.count_nonzero((f >= lo) & (f <= hi)) < need:
        if lo <= lo_all and hi >= hi_all:
            break
        step = float(np.median(np.diff(f)))
        lo, hi = max(lo - step, lo_all), min(hi + step, hi_all)
    return lo, hi


def _quiet_fit(f, H, band, init, fit_kwargs) -> BandFit | None:
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ModeFitWarning)
            return fit_band(f, H, band, len(init), init, **fit_kwargs)
    except ValueError:  # too few bins for this many modes
        return None


def _fit_dropping(f, H, band, init, fit_kwargs) -> BandFit | None:
    """Fit a group; drop modes that end outside the band or at a bound, refit; None if none."""
    while init:
        fit = _quiet_fit(f, H, band, init, fit_kwargs)
        if fit is None:
            init = init[:-1]
            continue
        good = [m for m in fit.modes if not _suspicious(m, band[0], band[1])]
        if len(good) == len(fit.modes):
            return fit
        init = good
    return None


def _noise_nrmse(f, H, band) -> float:
    """Misfit that noise alone would leave, in the units of BandFit.nrmse."""
    sel = (f >= band[0]) & (f <= band[1])
    power = np.mean(np.abs(H[sel]) ** 2, axis=0)
    used = power > 0
    return math.sqrt(float(np.mean(_noise_power(H[sel])[used] / power[used])) / 2.0)


def _misfit(f, H, band, fit: BandFit) -> float:
    """Relative misfit (as BandFit.nrmse, unweighted) of a fit's model over ``band``."""
    sel = (f >= band[0]) & (f <= band[1])
    power = np.mean(np.abs(H[sel]) ** 2, axis=0)
    power[power == 0] = 1.0
    E = H[sel] - synthesize(f[sel], fit.modes, fit.residuals)
    return math.sqrt(float(np.mean(np.mean(np.abs(E) ** 2, axis=0) / power)))


def _grow(f, H, fit: BandFit, territory, fit_kwargs, max_extra=2) -> BandFit:
    """Add modes a group misses (e.g. a heavily damped mode without a peak of its own).

    While the group's misfit exceeds both 5 % and three times the noise
    level (smaller misfits are mostly band truncation), a mode is tried at each of the strongest peaks of the misfit, in a band
    widened (within ``territory``, which ends short of the neighbouring
    groups' peaks) to 2.5 of its half-power bandwidths either side. The best
    trial is kept if all its modes lie inside its band with a free damping
    ratio, the new mode is well determined (standard deviations below 10 %
    of its bandwidth and 30 % of its damping ratio) and it halves the squared
    misfit over the group's band.
    """
    band = fit.band_hz
    noise = _noise_nrmse(f, H, band)
    for _ in range(max_extra):
        current = _misfit(f, H, band, fit)
        if current <= max(0.05, 3.0 * noise):
            break
        sel = (f >= fit.band_hz[0]) & (f <= fit.band_hz[1])
        E = H[sel] - synthesize(f[sel], fit.modes, fit.residuals)
        cand = _peak_guesses(f[sel], E, 3, min_prominence_db=0.5, min_snr_db=None)
        i = int(np.argmax(mode_indicator(f[sel], E)))
        cand.append((float(f[sel][i]), 0.05))
        best, best_misfit = None, current
        for fc, zc in cand:
            half = 5.0 * min(max(zc, 0.005), 0.3) * fc
            lo = max(min(fit.band_hz[0], fc - half), territory[0])
            hi = min(max(fit.band_hz[1], fc + half), territory[1])
            if not lo < fc < hi:
                continue
            trial = _quiet_fit(
                f, H, (lo, hi), [*fit.modes, (fc, min(max(zc, 0.005), 0.3))], fit_kwargs
            )
            if trial is None or any(_suspicious(m, lo, hi) for m in trial.modes):
                continue
            new = min(trial.modes, key=lambda m: abs(m.frequency_hz - fc))
            bandwidth = 2.0 * new.damping_ratio * new.frequency_hz
            if not (
                new.frequency_std_hz < 0.1 * bandwidth and new.damping_std < 0.3 * new.damping_ratio
            ):
                continue
            m = _misfit(f, H, band, trial)
            if m < best_misfit:
                best, best_misfit = trial, m
        if best is None or best_misfit**2 > 0.5 * current**2:
            break
        fit = best
    return fit


def synthesize(frequency_hz, modes: Sequence[Mode], residuals: dict | None = None,
               window_tau_s: float | None = None) -> np.ndarray:
    """Accelerance of modes (and residual terms) on a frequency grid.

    Evaluates the model of the module docstring and :func:`fit_modes`; the
    inverse of :func:`fit_band` and the way to build synthetic test FRFs.

    Parameters
    ----------
    frequency_hz : array_like
        ``(F,)`` frequencies in Hz.
    modes : sequence of Mode
        Modes with ``R`` residues each.
    residuals : dict of str to array_like, optional
        Residual-term coefficients as in :attr:`BandFit.residuals`, ``(R,)``
        real each.
    window_tau_s : float, optional
        The FRF as measured through an exponential window ``exp(-t/tau)`` on
        force and response: the whole model at ``s + 1/tau`` (what the
        global fit fits, :mod:`guidefit.globalvp`). None: the system's own FRF.

    Returns
    -------
    numpy.ndarray
        ``(F, R)`` complex accelerance in (m/s^2)/N.

    Examples
    --------
    >>> m = Mode(1000.0, 0.01, np.array([-1e-5j]), "curve_fit")   # modal constant > 0
    >>> H = synthesize([1000.0], [m])
    >>> np.round(H, 3)        # about -w^2 A / (jw - p) = +j w_n c / (2 zeta w_d) at w_n
    array([[0.+6.283j]])
    """
    f = np.atleast_1d(np.asarray(frequency_hz, dtype=float))
    if f.ndim != 1:
        raise ValueError(f"frequency_hz must be 1-D, got shape {f.shape}")
    residuals = dict(residuals or {})
    if not modes and not residuals:
        raise ValueError("synthesize needs at least one mode or residual term")
    for name in residuals:
        if name not in _RESIDUAL_TERMS:
            raise ValueError(f"residuals keys must be in {tuple(_RESIDUAL_TERMS)}, got {name!r}")
    if modes:
        R = np.asarray(modes[0].residues).size
    else:
        R = np.asarray(next(iter(residuals.values()))).size
    s = 2j * np.pi * f[:, None] + (1.0 / float(window_tau_s) if window_tau_s else 0.0)
    H = np.zeros((f.size, R), dtype=complex)
    for k, m in enumerate(modes):
        A = np.asarray(m.residues, dtype=complex).reshape(-1)
        if A.size != R:
            raise ValueError(f"modes[{k}].residues has {A.size} channels, expected {R}")
        p = m.pole
        H += s * s * (A / (s - p) + np.conj(A) / (s - np.conj(p)))
    for name, c in residuals.items():
        c = np.asarray(c, dtype=float).reshape(-1)
        if c.size != R:
            raise ValueError(f"residuals[{name!r}] has {c.size} channels, expected {R}")
        H += _RESIDUAL_TERMS[name](s) * c[None, :]
    return H


def modes_to_frame(modes: Sequence[Mode], channels: Sequence[str] | None = None):
    """Modes as a pandas DataFrame, one row per mode.

    Parameters
    ----------
    modes : sequence of Mode
        Modes with the same number of residues.
    channels : sequence of str, optional
        Channel names for the residue columns (default ``ch0``, ``ch1``, ...).

    Returns
    -------
    pandas.DataFrame
        Columns ``frequency_hz``, ``frequency_std_hz``, ``damping_ratio``,
        ``damping_std``, ``method``, then per channel ``residue_<name>``
        (complex, m/(N s)) and ``modal_constant_<name>`` (real part of
        ``2j w_d A``, 1/kg).

    Examples
    --------
    >>> m = Mode(1000.0, 0.01, np.array([-1e-5j, 2e-5j]), "curve_fit", 0.5, 1e-4)
    >>> df = modes_to_frame([m], channels=["acc_A_y", "acc_B_y"])
    >>> list(df.columns[:5])
    ['frequency_hz', 'frequency_std_hz', 'damping_ratio', 'damping_std', 'method']
    >>> round(float(df["modal_constant_acc_B_y"].iloc[0]), 4)
    -0.2513
    """
    import pandas as pd

    modes = list(modes)
    R = {np.asarray(m.residues).size for m in modes}
    if len(R) > 1:
        raise ValueError(f"modes have different numbers of residues: {sorted(R)}")
    n_ch = R.pop() if R else (len(channels) if channels is not None else 0)
    names = list(channels) if channels is not None else [f"ch{r}" for r in range(n_ch)]
    if len(names) != n_ch:
        raise ValueError(f"channels has {len(names)} names, the modes have {n_ch} residues")
    rows = []
    for m in modes:
        row = {
            "frequency_hz": m.frequency_hz,
            "frequency_std_hz": m.frequency_std_hz,
            "damping_ratio": m.damping_ratio,
            "damping_std": m.damping_std,
            "method": m.method,
        }
        res = np.asarray(m.residues, dtype=complex).reshape(-1)
        mc = m.modal_constants.reshape(-1)
        for r, name in enumerate(names):
            row[f"residue_{name}"] = res[r]
        for r, name in enumerate(names):
            row[f"modal_constant_{name}"] = float(mc[r].real)
        rows.append(row)
    columns = ["frequency_hz", "frequency_std_hz", "damping_ratio", "damping_std", "method"]
    columns += [f"residue_{n}" for n in names] + [f"modal_constant_{n}" for n in names]
    return pd.DataFrame(rows, columns=columns)
