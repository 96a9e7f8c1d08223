"""Windows of a hammer-test record: a force window on the force channel, an exponential window on
every channel, the defaults chosen from the data, and the damping the exponential window adds.

Part of the FRF stage (:mod:`guidefit.frf`, whose module docstring explains the windows and
their effect on the FRF); the windows and the correction are also importable from :mod:`guidefit.frf`.
The windows of an FrfSet are rebuilt by :func:`window_settings_of` and its window's damping removed by
:func:`undo_window_damping`, each the one place that does it.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

#: Threshold, as a fraction of the peak force, that delimits the force pulse.
PULSE_THRESHOLD = 0.05
#: The force window stays open this many pulse durations after the pulse ends.
FORCE_WINDOW_PULSES_AFTER = 4.0
#: Default taper of the force window as a fraction of its width.
FORCE_TAPER_FRACTION = 0.2
#: Tail of the record (fraction of its length) whose level sets the exponential window.
TAIL_FRACTION = 0.05

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
    n_samples, sample_rate_hz
        As in :func:`force_window`.
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


def window_settings_of(frf) -> WindowSettings:
    """The windows an :class:`~guidefit.frf.FrfSet` was computed with, as settings that apply them again.

    For FRFs of some of its hits (a force bin) with the same windows: its
    force window (width and taper; ``math.inf``: it had none) and its
    exponential window (``math.inf``: none). The one way guidefit rebuilds
    the windows from an FrfSet.

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> window_settings_of(SimpleNamespace(force_window_s=0.002, force_taper_s=0.0004, exp_window_tau_s=None))
    ...     # doctest: +ELLIPSIS
    WindowSettings(force_window_s=0.002, force_taper_s=0.0004, exp_tau_s=inf, ...)
    """
    width = frf.force_window_s
    return WindowSettings(force_window_s=width if width else math.inf,
                          force_taper_s=getattr(frf, "force_taper_s", None) if width else None,
                          exp_tau_s=frf.exp_window_tau_s or math.inf)


def undo_window_damping(frequency_hz, damping_ratio, frf):
    """``(f_n_hz, zeta)`` of a pole fitted to the FRFs of ``frf`` without its exponential window's damping.

    :func:`exponential_window_damping_correction` with the FrfSet's
    ``exp_window_tau_s``; the inputs unchanged when it had no exponential
    window. The one place guidefit applies the correction (identify's fits,
    half-power and force levels, the nonlinear level estimator).

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> undo_window_damping(1000.0, 0.02, SimpleNamespace(exp_window_tau_s=None))
    (1000.0, 0.02)
    >>> f, z = undo_window_damping(1000.0, 0.02, SimpleNamespace(exp_window_tau_s=0.1))
    >>> round(float(z), 5)  # 1/tau = 10 1/s of the 125.7 1/s decay was the window's
    0.01841
    """
    tau = getattr(frf, "exp_window_tau_s", None)
    if not tau:
        return frequency_hz, damping_ratio
    return exponential_window_damping_correction(damping_ratio, frequency_hz, tau, _stacklevel=3)


def exponential_window_damping_correction(zeta_measured, f_n_hz, tau_s, *, _stacklevel: int = 2):
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
            stacklevel=_stacklevel,  # the warning names the line that asked for the correction
        )
    return (w_true / (2.0 * np.pi))[()], zeta_true[()]


FORCE_OFFSET_FRACTION = 0.002  # a force median beyond 0.2 % of the peak there is a sensor bias, removed


def _force_offset(quiet_force: np.ndarray, pulse_force: np.ndarray) -> float:
    """The force offset: the median of ``quiet_force`` (samples where the hammer pushes nothing)
    if beyond 0.2 % of the peak of ``pulse_force``, else 0.

    Smaller offsets are noise-level (and AC-coupled amplifiers drift that much after a hit), left as
    they are; a larger one is a bias whose windowed rectangle would add to the force spectrum.
    """
    from guidefit.hit_checks import _median  # np.median's value for finite samples, 3x faster on a record

    quiet_force = np.ascontiguousarray(quiet_force, dtype=float)
    finite = np.isfinite(quiet_force).all()
    base = float(_median(quiet_force) if finite else np.median(quiet_force))
    return base if abs(base) > FORCE_OFFSET_FRACTION * max(float(pulse_force.max()), -float(pulse_force.min())) else 0.0
