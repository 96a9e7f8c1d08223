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
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from guidefit.modes.fitcore import RESIDUAL_TERMS
from guidefit.modes.prominence import prominent_peaks

__all__ = [
    "BandFit",
    "HalfPower",
    "HalfPowerWarning",
    "Mode",
    "ModeFitWarning",
    "Peaks",
    "SdofEstimate",
    "find_peaks",
    "mode_indicator",
    "modes_to_frame",
    "natural_from_peak_frequency",
    "synthesize",
]

_KINDS = ("accelerance", "mobility", "receptance")
_PEAK_INTERPOLATIONS = ("inverse_square", "log", "linear")


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


def _db_peaks(f, db, min_prominence_db, min_distance_hz) -> tuple[np.ndarray, np.ndarray]:
    """``(index, prominence)`` of the peaks of ``db`` at least ``min_prominence_db`` prominent
    (and ``min_distance_hz`` apart, by :func:`scipy.signal.find_peaks`, when given)."""
    if min_distance_hz is not None:
        if not min_distance_hz > 0:
            raise ValueError(f"min_distance_hz must be > 0, got {min_distance_hz}")
        import scipy.signal

        distance = max(1.0, min_distance_hz / float(np.median(np.diff(f))))
        idx, props = scipy.signal.find_peaks(db, prominence=min_prominence_db, distance=distance)
        return idx, props["prominences"]
    return prominent_peaks(db, min_prominence_db)


def _above_noise(H, mif, idx, prom, min_snr_db) -> np.ndarray:
    """Which peaks rise above their base by ``min_snr_db`` over the noise power (:func:`_noise_power`)."""
    # noise power in MIF units: sum_r sigma_r^2 / mean|H_r|^2
    mean = np.mean(np.abs(H) ** 2, axis=0)
    used = mean > 0
    nu = float(np.sum(_noise_power(H)[used] / mean[used]))
    excess = mif[idx] * (1.0 - 10.0 ** (-prom / 10.0))
    return excess >= nu * 10.0 ** (min_snr_db / 10.0)


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
    idx, prom = _db_peaks(f[sel], db, min_prominence_db, min_distance_hz)
    if idx.size == 0:
        return empty
    keep = db[idx] >= db[idx].max() - floor_db
    idx, prom = idx[keep], prom[keep]
    if min_snr_db is not None and idx.size:
        keep = _above_noise(H[sel], mif, idx, prom, min_snr_db)
        idx, prom = idx[keep], prom[keep]
    order = np.argsort(-prom, kind="stable")
    if max_peaks is not None:
        order = order[:max_peaks]
    idx, prom = idx[order], prom[order]
    fpk = np.array([_parabolic_vertex(f[sel][i - 1 : i + 2], db[i - 1 : i + 2])[0] for i in idx])
    return Peaks(fpk, sel[idx], prom)


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
        global fit fits, :mod:`guidefit.modes.globalvp`). None: the system's own FRF.

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
        if name not in RESIDUAL_TERMS:
            raise ValueError(f"residuals keys must be in {tuple(RESIDUAL_TERMS)}, got {name!r}")
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
        H += RESIDUAL_TERMS[name](s) * c[None, :]
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
