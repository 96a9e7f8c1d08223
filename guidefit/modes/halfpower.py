"""The paper's half-power method: the -3 dB band of a resonance peak and the natural frequency and
damping it gives, Eq. (26)-(29) as :func:`guidefit.identify` applies them, with the peak corrections.

Part of the modal stage beside :mod:`guidefit.modes.base` (types, peak picking); every name here is
importable from :mod:`guidefit.modes` too.
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from guidefit.errors import IdentificationError
from guidefit.modes.base import (
    _KINDS,
    _PEAK_INTERPOLATIONS,
    HalfPower,
    HalfPowerWarning,
    Mode,
    SdofEstimate,
    _as_frequency,
    _as_frf,
    _parabolic_vertex,
    mode_indicator,
    natural_from_peak_frequency,
)

__all__ = ["half_power", "half_power_mode", "sdof_from_half_power"]


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
    # long because: its docstring (the method, its accuracy, the parameters, a doctest) is 80 of the lines
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
    i = _climb(f, mag, i, peak_index)
    f_peak, h_peak = _peak_vertex(f, mag, i, peak_interpolation)
    f1, f2 = _band_edges(f, mag, i, f_peak, h_peak)
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


def _climb(f, mag, i: int, peak_index) -> int:
    """The local maximum of ``mag`` reached by climbing from bin ``i``; an
    :class:`~guidefit.errors.IdentificationError` at the array edge or a zero magnitude."""
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
    return i


def _peak_vertex(f, mag, i: int, peak_interpolation: str) -> tuple[float, float]:
    """``(f_peak, |H_peak|)``: the vertex of the parabola through bins ``i - 1 .. i + 1`` of
    ``1/|H|^2``, ``ln|H|`` or ``|H|`` (``peak_interpolation``), not below the bin's own level."""
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
    return f_peak, max(h_peak, float(mag[i]))


def _band_edges(f, mag, i: int, f_peak: float, h_peak: float) -> tuple[float, float]:
    """``(f1, f2)``: where ``ln|H|`` falls through ``|H_peak| / sqrt(2)`` on either side of bin ``i``
    (:func:`_crossing`); an :class:`~guidefit.errors.IdentificationError` when the peak is narrower
    than one bin."""
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
    return f1, f2


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
