r"""Nonlinear contacts: a forward model of hits at several force levels.

A preloaded Hertz contact (``Q = C delta^e`` for ``delta > 0``: Palmgren's
roller law, Eq. 4, ``e = 10/9``; Hertz point contact of a ball, Eq. 3,
``e = 3/2``; :func:`guidefit.model.static.exponent`) softens as a hit unloads it
and carries nothing once it lifts off. A carriage hit harder and harder
therefore rings at a lower and lower *apparent* frequency: with the MRB35
preload, a 1 kN hit lifts nearly every roller during its first cycles, and
the vertical peak of a 5 kN hit is skewed and split. What a modal fit of such a peak finds is
not a property of the carriage alone; it depends on the hit, on the windows,
on the FRF estimator and on the fit. So the measurement is compared with a
simulation of the same experiment, passed through the same chain:

1. **Measured levels** (:func:`measure_levels`). Runs that differ only in hit
   force (the same hit point, direction and sensors) are levels of one test;
   a run whose hit forces spread by :data:`FORCE_RATIO` is split into force
   terciles. Each level's hits are averaged with the run's windows and
   estimator (:func:`guidefit.frf.compute_frf`); the level's apparent
   frequency is the centroid of the fourth power of the mode-weighted FRF
   power between 0.6 and 1.15 times the mode's small-amplitude frequency
   (:func:`peak_centroid`, jackknife std over the hit groups), its damping
   that of one pole fitted around it (:func:`apparent_mode`,
   :func:`guidefit.modes.fit_modes`): :func:`level_estimate`. The centroid
   moves continuously with the model's parameters where a one-pole fit
   jumps between the lobes of a peak split by contact loss.
2. **Forward model** (:class:`ForwardModel`). For a preload factor ``p``
   (``Delta' = p Delta``, small-amplitude ``K_n`` scaled by ``p^(e-1)``,
   :func:`stiffness_slope`) and a roller-stiffness factor ``k`` (``K_n`` scaled),
   each level's hits are simulated in the time domain with the preloaded
   Hertz law (:func:`guidefit.simulate.hit_response`, the simulator's RK4
   integrator, exact linear decay once every roller's excursion is below
   1 % of the preload) at the measured peak forces (up to
   :data:`SIM_HITS` hits, the force quantiles of the level), the measured
   pulse duration, hit point and direction, at the sensors' positions and
   axes, for the measured record length and pretrigger, at a sample rate of
   at least :data:`SIM_RATE_MIN_HZ` (an integer fraction of the measured one,
   so the FRF has the same bins). The records go through the same windows
   (the measured run's force window and exponential window), the same FRF
   estimator and :func:`level_estimate`, the peak searched from the model's
   own small-amplitude frequency. Results are cached by parameters.
3. **Fit** (:func:`fit_levels`). ``ln p`` (and ``ln k``, fixed mainly by the
   lowest level, where the contacts are linear) are fitted to the levels'
   apparent frequencies by :func:`scipy.optimize.least_squares`; the standard
   deviations come from the Jacobian, ``cov = (J^T J)^-1 max(1, chi2/dof)``.
   Each level's uncertainty is its jackknife standard deviation with a
   floor of :data:`LEVEL_FLOOR` of the frequency (the model-form floor of
   explain) and the forward model's own numerical error
   (:data:`FORWARD_MODEL_ERROR`, measured against the full simulation chain by
   ``benchmarks/bench_nonlinear.py``). The first guess is the minimum of a
   spline through the costs on a coarse grid over ``p`` with one simulated
   hit per level.
4. **explain** (:func:`prepare_for_explain`, the ``prepare`` hook of
   ``amplitude_dependence``; its ``forward`` uses :func:`level_predictions`).

The describing function of ``amplitude_dependence`` (the RMS of the modal
amplitudes, a chirp fitted in a narrow band around the small-amplitude
frequency) follows the drop only below lift-off: -0.12 % for a measured
-0.28 % at 1 kN and -3.7 % for -14.4 % at 5 kN on the MRB35 (tables in
``docs/explain.md``, "Nonlinear contacts: the forward model").

Examples
--------
>>> from guidefit.nonlinear import apparent_mode
>>> import numpy as np
>>> f = np.linspace(3000.0, 4000.0, 201)
>>> s = 2j * np.pi * f
>>> p = -0.03 * 2 * np.pi * 3500 + 2j * np.pi * 3500 * np.sqrt(1 - 0.03**2)
>>> H = s**2 * (1 / (s - p) + 1 / (s - np.conj(p)))
>>> fit = apparent_mode(f, H[:, None], (3200.0, 3800.0))
>>> round(fit.frequency_hz, 1), round(fit.damping_ratio, 4)
(3500.0, 0.03)
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from guidefit.errors import IdentificationError, ModelError, RecordingError

#: Runs (or hit-force bins) form levels when their forces differ by at least this factor.
FORCE_RATIO = 1.5
#: Hits simulated per level by the forward model (the quantiles of the level's measured forces).
SIM_HITS = 3
#: Lowest sample rate of the forward model (Hz): RK4 step and harmonics of the lift-off.
SIM_RATE_MIN_HZ = 80e3
#: Relative floor of a level's frequency uncertainty (the model-form floor of explain, 0.05 %).
LEVEL_FLOOR = 5e-4
#: Relative numerical error of the forward model against the full simulation chain (bench_nonlinear.py).
FORWARD_MODEL_ERROR = 5e-4
#: Band half-width of the one-pole fit: max(BAND_ZETAS zeta, BAND_MIN) of the peak frequency.
BAND_ZETAS, BAND_MIN = 3.0, 0.03
#: Exponent of the power whose centroid is a level's peak (:func:`level_band`).
PEAK_POWER = 4.0
#: Bins over which the one-pole fit's weights rise from 0 to 1 at each end of its band.
EDGE_BINS = 2.0
#: The peak of a level is searched between these factors of the mode's small-amplitude frequency.
PEAK_SEARCH = (0.6, 1.15)


@dataclass(frozen=True)
class ModeFit:
    """One-pole fit of a level's mode: frequency (Hz), its std and the damping ratio."""

    frequency_hz: float
    frequency_std_hz: float | None
    damping_ratio: float


@dataclass(frozen=True)
class LevelSetup:
    """How one force level was measured: what the forward model reproduces.

    Positions in m (carriage frame), times in s; ``positions_m`` and
    ``directions`` are those of the response channels, in FRF order.
    """

    sample_rate_hz: float
    n_samples: int
    pretrigger_samples: int
    channel_names: tuple
    positions_m: np.ndarray
    directions: np.ndarray
    hit_position_m: tuple
    hit_direction: tuple
    pulse_s: float
    window: object  # guidefit.frf.WindowSettings of the level's FRF (guidefit.frf.windows.window_settings_of)
    estimator: str = "H1"


@dataclass(frozen=True)
class MeasuredLevel:
    """The apparent frequency of one mode on one force level (its hits averaged)."""

    run: str
    label: str
    hit_forces_n: tuple
    frequency_hz: float
    frequency_std_hz: float | None
    damping_ratio: float
    band_hz: tuple
    setup: LevelSetup = field(repr=False)
    reference_hz: float = math.nan  # the mode's small-amplitude frequency on the lowest level (peak search)
    reference_damping: float = 0.03  # its damping ratio there (band width)
    weights: tuple = ()  # per channel, of the peak search (the mode's shape squared)

    @property
    def peak_force_n(self) -> float:
        """Mean peak force of the level's hits (N)."""
        return float(np.mean(self.hit_forces_n))

    def sigma_hz(self) -> float:
        """Uncertainty of the level in the fit: fit std, :data:`LEVEL_FLOOR`, :data:`FORWARD_MODEL_ERROR`."""
        std = self.frequency_std_hz if self.frequency_std_hz and math.isfinite(self.frequency_std_hz) else 0.0
        return math.sqrt(std**2 + (LEVEL_FLOOR * self.frequency_hz) ** 2
                         + (FORWARD_MODEL_ERROR * self.frequency_hz) ** 2)


# --------------------------------------------------------------------------- the estimator


def apparent_mode(frequency_hz, H, band_hz, initial=None) -> ModeFit:
    """One pole fitted to every channel of an FRF in ``band_hz``: the level's apparent mode.

    :func:`guidefit.modes.fit_modes` with one mode (channels scaled alike,
    residual terms for the modes outside the band, the bins' weights rising
    linearly over :data:`EDGE_BINS` bins at the band's ends); the pole of
    the FRF as given (:func:`level_estimate` removes the FrfSet's exponential
    window's damping, :func:`guidefit.frf.windows.undo_window_damping`, as identify
    does). ``initial``: (frequency_hz, zeta) to start the fit from (default
    the band's peaks). The same function estimates the measured and the
    simulated levels.

    Raises :class:`~guidefit.errors.IdentificationError` when no pole is found.
    """
    import warnings

    from guidefit.modes import curvefit

    f = np.asarray(frequency_hz, float)
    H = np.asarray(H)
    if H.ndim == 1:
        H = H[:, None]
    lo, hi = (float(x) for x in band_hz)
    # bins fade in over EDGE_BINS at the band's ends: a band that moves with the parameters then changes
    # the fit continuously instead of by a whole bin (the forward model's least squares needs that)
    ramp = EDGE_BINS * float(np.median(np.diff(f)))
    weights = np.clip((f - lo) / ramp, 0.0, 1.0) * np.clip((hi - f) / ramp, 0.0, 1.0)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            mode = curvefit.fit_modes(f, H, (lo, hi), 1, weights=weights,
                                       initial=None if initial is None else [initial])[0]
    except (ValueError, np.linalg.LinAlgError) as exc:
        raise IdentificationError(f"no mode in {band_hz[0]:.0f}-{band_hz[1]:.0f} Hz ({exc})") from None
    return ModeFit(float(mode.frequency_hz), mode.frequency_std_hz, float(mode.damping_ratio))


def peak_centroid(frequency_hz, H, mode_hz: float, weights=None) -> float:
    """A level's apparent frequency (Hz): the centroid of ``P^4``, ``P = sum_r w_r |H_r|^2``.

    Taken between :data:`PEAK_SEARCH` times ``mode_hz`` (the mode's
    small-amplitude frequency; contact loss only lowers it; the upper end leaves the P^4 of the flank below 1e-6). For a single
    resonance it is its peak; when contact loss splits the peak into lobes
    it lies between them and moves continuously as they trade places, where
    a one-pole fit jumps from one lobe to the other (by 80 Hz between
    preload factors 0.59 and 0.60 at 5 kN) and no least-squares fit of the
    preload could use it. ``weights``: per channel (default equal).

    >>> f = np.linspace(2000.0, 4000.0, 401)
    >>> H = 1.0 / (1.0 - (f / 3000.0) ** 2 + 0.06j * f / 3000.0)
    >>> round(peak_centroid(f, H[:, None], 3500.0), 1)  # near this receptance's peak f_n sqrt(1 - 2 zeta^2)
    2996.5
    """
    f = np.asarray(frequency_hz, float)
    H = np.asarray(H)
    if H.ndim == 1:
        H = H[:, None]
    w = np.ones(H.shape[1]) if weights is None else np.asarray(weights, float)
    sel = (f >= PEAK_SEARCH[0] * mode_hz) & (f <= PEAK_SEARCH[1] * mode_hz)
    if not np.any(sel):
        raise IdentificationError(f"no FRF bins near {mode_hz:.0f} Hz")
    power = (np.abs(H[sel]) ** 2) @ w
    if not np.any(power > 0) or power.size < 4:
        raise IdentificationError(f"no response near {mode_hz:.0f} Hz")
    # on a grid 8 times finer (cubic spline through the bins): a narrow peak moving across the bins then
    # moves the centroid smoothly instead of in steps of the bin's share
    from scipy.interpolate import CubicSpline

    fine = np.linspace(f[sel][0], f[sel][-1], 8 * power.size)
    q = np.maximum(CubicSpline(f[sel], power / power.max())(fine), 0.0) ** PEAK_POWER
    return float(np.sum(fine * q) / np.sum(q))


def level_band(frequency_hz, H, mode_hz: float, damping_ratio: float, weights=None) -> tuple[float, float]:
    """Band of a level's one-pole fit: +/- max(3 zeta, 3 %) around :func:`peak_centroid`.

    >>> f = np.linspace(2000.0, 4000.0, 401)
    >>> H = 1.0 / (1.0 - (f / 3000.0) ** 2 + 0.06j * f / 3000.0)
    >>> [round(x) for x in level_band(f, H[:, None], 3500.0, 0.02)]  # peak near 3000 Hz, +/- 6 %
    [2817, 3176]
    """
    peak = peak_centroid(frequency_hz, H, mode_hz, weights)
    half = max(BAND_ZETAS * damping_ratio, BAND_MIN) * peak
    return peak - half, peak + half


def level_estimate(frf, mode_hz: float, damping_ratio: float, weights=None, jackknife: bool = False):
    """The apparent mode of one level's FRF set: ``(ModeFit, band_hz)``.

    Frequency: :func:`peak_centroid`; its standard deviation the
    delete-a-group jackknife over the FRF's hit groups (``jackknife`` and at
    least two groups), else that of the one-pole fit. Damping: the one-pole
    fit (:func:`apparent_mode`) in :func:`level_band`, started at the
    centroid (nan when it fails). The same function estimates measured and
    simulated levels.
    """
    f_c = peak_centroid(frf.frequency_hz, frf.H, mode_hz, weights)
    half = max(BAND_ZETAS * damping_ratio, BAND_MIN) * f_c
    band = (f_c - half, f_c + half)
    from guidefit.frf.windows import undo_window_damping

    try:
        pole = apparent_mode(frf.frequency_hz, frf.H, band, initial=(f_c, damping_ratio))
        zeta, std = float(undo_window_damping(pole.frequency_hz, pole.damping_ratio, frf)[1]), pole.frequency_std_hz
    except IdentificationError:
        zeta, std = math.nan, None
    if jackknife and frf.n_groups >= 2:
        reps = np.array([peak_centroid(r.frequency_hz, r.H, mode_hz, weights) for r in frf.leave_one_group_out()])
        std = float(math.sqrt((reps.size - 1) / reps.size * np.sum((reps - reps.mean()) ** 2)))
    return ModeFit(f_c, std, zeta), band


# --------------------------------------------------------------------------- forward model


def _rate_step(setup: LevelSetup) -> int:
    """Integer decimation of the measured sample rate down to at least :data:`SIM_RATE_MIN_HZ`."""
    k = max(1, int(setup.sample_rate_hz // SIM_RATE_MIN_HZ))
    while k > 1 and (setup.n_samples % k or setup.pretrigger_samples % k):
        k -= 1
    return k


def representative_forces(hit_forces_n, n_hits: int = SIM_HITS) -> np.ndarray:
    """Up to ``n_hits`` peak forces standing for a level's hits: their quantiles (N).

    >>> representative_forces([90.0, 100.0, 110.0, 120.0], 2).tolist()
    [97.5, 112.5]
    """
    forces = np.sort(np.asarray(hit_forces_n, float))
    if forces.size <= n_hits:
        return forces
    return np.quantile(forces, (np.arange(n_hits) + 0.5) / n_hits)


def simulate_level(model, level: MeasuredLevel, n_hits: int = SIM_HITS):
    """Ideal records of a level's hits from the model: ``(records (h, n, 1 + R), sample_rate_hz, pretrigger)``.

    ``model``: :func:`guidefit.simulate.build_model` (nonlinear contacts).
    Column 0 is the force, then the response channels of the level's setup;
    the record lasts as long as the measured one, at the measured sample rate
    divided by an integer (:func:`_rate_step`), so the FRF bins coincide.
    """
    from guidefit.simulate import hit_response

    s = level.setup
    k = _rate_step(s)
    fs, n, pre = s.sample_rate_hz / k, s.n_samples // k, s.pretrigger_samples // k
    t = np.arange(n) / fs
    onset = max(pre - 0.5, 0.0) / fs
    records = []
    for force in representative_forces(level.hit_forces_n, n_hits):
        f, acc = hit_response(model, s.hit_position_m, s.hit_direction, [(float(force), onset, s.pulse_s)], t,
                              s.positions_m, s.directions)
        records.append(np.column_stack([f, acc]))
    return np.stack(records), fs, pre


def predict_level(model, level: MeasuredLevel, n_hits: int = SIM_HITS) -> ModeFit:
    """The apparent mode of a level predicted by ``model``: its simulated hits through the measurement's
    windows and estimator and :func:`level_estimate` (the peak searched from the model's small-amplitude
    frequency, the measured reference damping and channel weights)."""
    from guidefit.frf import frf_from_records

    s = level.setup
    records, fs, pre = simulate_level(model, level, n_hits)
    frf = frf_from_records(records, fs, 0, ("force", *s.channel_names), s.estimator, s.window,
                           pretrigger_samples=pre, run=level.run, workers=1)
    sol = model.solution
    f_small = float(sol.frequencies_hz[sol.labels.index(level.label)]) if level.label in sol.labels \
        else level.reference_hz
    return level_estimate(frf, f_small, level.reference_damping, level.weights if level.weights else None)[0]


class ForwardModel:
    """Predicted apparent modes of measured levels for (preload factor, roller-stiffness factor).

    Parameters
    ----------
    guide : Guide or str
    levels : list of MeasuredLevel
    n_hits : int
        Hits simulated per level.
    damping : dict, optional
        Modal damping ratio per mode label (default: each label's measured
        damping on its lowest level, else :data:`guidefit.simulate.DEFAULT_DAMPING`).
    effects : tuple
        Other (linear) effects of the model, e.g. an added mass.

    ``predict(p, k)`` is cached by parameters; ``evaluations`` counts the
    simulations, ``seconds`` their process time.
    """

    def __init__(self, guide, levels, n_hits: int = SIM_HITS, damping: dict | None = None, effects=()):
        from guidefit.model.guides import as_guide

        self.guide = as_guide(guide)
        self.levels = list(levels)
        self.n_hits = int(n_hits)
        self.effects = tuple(effects)
        if damping is None:
            damping = {}
            for lv in sorted(self.levels, key=lambda x: x.peak_force_n, reverse=True):
                if 0 < lv.damping_ratio < 0.5:
                    damping[lv.label] = lv.damping_ratio  # the lowest level comes last and wins
        self.damping = dict(damping)
        self._cache: dict = {}
        self.evaluations = 0
        self.seconds = 0.0

    @property
    def stiffness_slope(self) -> float:
        """d ln K_n / d ln delta of the guide's contact law (:func:`stiffness_slope`: 1/9 rollers, 1/2 balls)."""
        return stiffness_slope(self.guide)

    def model(self, preload_factor: float, kn_factor: float = 1.0):
        """The simulator's model with nonlinear contacts at these parameters."""
        from guidefit.model.effects import Effect
        from guidefit.simulate import build_model

        effects = [*self.effects, Effect("contact_stiffness", {"factor": float(kn_factor)}),
                   Effect("amplitude_dependence", {"preload_factor": float(preload_factor)})]
        return build_model(self.guide, effects, self.damping)

    def predict(self, preload_factor: float, kn_factor: float = 1.0, n_hits: int | None = None) -> list[ModeFit]:
        """Apparent mode of every level (ModeFit list, level order)."""
        n_hits = self.n_hits if n_hits is None else int(n_hits)
        key = (round(math.log(preload_factor), 12), round(math.log(kn_factor), 12), n_hits)
        if key not in self._cache:
            t0 = time.process_time()
            model = self.model(preload_factor, kn_factor)
            self._cache[key] = [predict_level(model, lv, n_hits) for lv in self.levels]
            self.evaluations += 1
            self.seconds += time.process_time() - t0
        return self._cache[key]

    def small_amplitude_hz(self, preload_factor: float, kn_factor: float = 1.0) -> dict:
        """Linearised (small-amplitude) frequency per mode label (Hz)."""
        sol = self.model(preload_factor, kn_factor).solution
        return {lab: float(f) for lab, f in zip(sol.labels, sol.frequencies_hz)}


# --------------------------------------------------------------------------- measured levels


def pulse_duration(force_n, sample_rate_hz: float) -> float:
    """Duration T (s) of the half-sine with the same impulse and peak as a measured pulse.

    ``int F dt = 2 F0 T / pi`` over the main pulse (above 5 % of the peak and
    its continuation down to zero).

    >>> t = np.arange(100) / 200e3
    >>> f = np.where(t < 1e-4, 300.0 * np.sin(np.pi * t / 1e-4), 0.0)
    >>> round(pulse_duration(f, 200e3) * 1e6, 1)  # 20 samples of a 0.1 ms half-sine
    99.8
    """
    f = np.asarray(force_n, float)
    p = int(np.argmax(f))
    if f[p] <= 0:
        raise IdentificationError("no positive force pulse")
    lo = p
    while lo > 0 and f[lo - 1] > 0:
        lo -= 1
    hi = p
    while hi < f.size - 1 and f[hi + 1] > 0:
        hi += 1
    return float(math.pi * np.sum(f[lo:hi + 1]) / sample_rate_hz / (2.0 * f[p]))


def _group_key(run, channels) -> tuple:
    pos = run.excitation_position_m
    pos = None if pos is None else tuple(np.round(np.asarray(pos, float), 4))
    return (pos, tuple(np.round(np.asarray(run.excitation_direction, float), 3)),
            tuple(ch.name for ch in channels), float(run.sample_rate_hz), int(run.n_samples))


def _bins(rows, force_bins: int) -> list:
    """Hit indices and forces of a run's force bins: terciles when the forces spread, else one bin."""
    accepted = [r for r in rows if r["accepted"]]
    forces = np.array([r["peak_force_n"] for r in accepted])
    if forces.size >= 2 * force_bins and forces.max() >= FORCE_RATIO * forces.min():
        parts = np.array_split(np.argsort(forces), force_bins)
    else:
        parts = [np.arange(forces.size)]
    return [({accepted[i]["hit"] for i in part}, forces[part]) for part in parts if part.size]


def _bin_frf(run, rr, wanted: set, whole: bool):
    """FRF of a bin's hits with the run's windows (the run's own FRF when the bin is the run) and
    the bin's pulse duration and (record length, pretrigger) in samples. Always on the record's own
    grid, as the forward model of the level (:class:`LevelSetup`) makes its FRFs: a run zero-padded
    to a common grid with other runs (``record_samples``) is transformed again without the padding."""
    from guidefit import frf as frf_mod
    from guidefit.frf.windows import window_settings_of
    from guidefit.hits import HitSettings, iter_hits

    frf = rr.frf
    whole = whole and frf.record_samples is None
    pulses, hits, shape = [], [], (0, 0)
    for h in iter_hits(run, HitSettings()):
        if h.index in wanted and h.accepted:
            pulses.append(pulse_duration(h.data[:, run.force_index], run.sample_rate_hz))
            shape = (h.data.shape[0], int(h.pretrigger_samples or 0))
            if not whole:
                hits.append(h)
    if not pulses:
        raise IdentificationError(f"run '{run.name}': no accepted hit in the force bin")
    if not whole:
        frf = frf_mod.compute_frf(run, hits, estimator=frf.estimator, window=window_settings_of(frf), workers=1,
                                  max_frequency_hz=frf_mod.top_of(frf))
    return frf, float(np.median(pulses)), shape


def measure_levels(identification, labels=("vertical",), force_bins: int = 3, notes: list | None = None,
                   min_runs: int = 1):
    """The apparent frequency of each labelled mode on each force level of an identification.

    Runs with the same hit point, direction, sensors, sample rate and record
    length are one test; each run is a level, or three (force terciles) when
    its own hit forces spread by :data:`FORCE_RATIO`. A group needs levels
    whose mean forces differ by that factor. A mode is followed from its
    identified frequency and damping on the group's lowest level (label from
    identify); on each level it is fitted by :func:`apparent_mode` in the
    band of :func:`level_band` (channels weighted by the mode's shape).

    ``min_runs``: groups of fewer runs are skipped (explain measures only
    levels across runs; identify gives those within one run). Returns a list
    of :class:`MeasuredLevel` (grouped by test, then label, forces
    increasing); problems go to ``notes``.
    """
    notes = [] if notes is None else notes
    recording = identification.recording  # the recording identify read (its hits are iterated again, not the file)
    if recording is None:
        raise RecordingError(f"{identification.file}: FRFs, no time data: force levels need the hits")
    groups: dict = {}
    for rr in identification.runs:
        run = recording.run(rr.name)
        groups.setdefault(_group_key(run, rr.channels), []).append((run, rr))
    out = []
    for members in groups.values():
        if len(members) < min_runs:
            continue
        bins = [(run, rr, wanted, forces, len(_bins(rr.hits, force_bins)) == 1)
                for run, rr in members for wanted, forces in _bins(rr.hits, force_bins)]
        means = [float(np.mean(b[3])) for b in bins]
        if len(bins) < 2 or max(means) < FORCE_RATIO * min(means):
            continue
        bins = [bins[i] for i in np.argsort(means)]
        low_rr = bins[0][1]
        for label in labels:
            mode = next((m for m in low_rr.modes if m.label == label), None)
            if mode is None:
                notes.append(f"force levels of run '{low_rr.name}': no {label} mode on the lowest level")
                continue
            out += _measure_mode(bins, mode, notes)
    return out


def _measure_mode(bins, mode, notes: list) -> list:
    from guidefit.frf.windows import window_settings_of

    names = [ch.name for ch in bins[0][1].channels]
    weights = np.array([abs(mode.shape.get(n, 0.0)) for n in names]) ** 2
    out = []
    for run, rr, wanted, forces, whole in bins:
        hit = run.hit_position_m  # the contract's hit point: excitation_position_m, else the force channel's
        if hit is None:
            notes.append(f"force level of run '{run.name}' at {np.mean(forces):.0f} N: the hit point is unknown; "
                         "the forward model of the level needs it")
            continue
        try:
            frf, pulse, (n_samples, pretrigger) = _bin_frf(run, rr, wanted, whole)
            fit, band = level_estimate(frf, mode.frequency_hz, mode.damping_ratio, weights, jackknife=True)
        except IdentificationError as exc:
            notes.append(f"force level of run '{run.name}' at {np.mean(forces):.0f} N: {exc}")
            continue
        channels = rr.channels
        setup = LevelSetup(
            sample_rate_hz=float(run.sample_rate_hz), n_samples=int(n_samples),
            pretrigger_samples=int(pretrigger), channel_names=tuple(frf.channels),
            positions_m=np.array([ch.position_m for ch in channels], float),
            directions=np.array([ch.direction for ch in channels], float),
            hit_position_m=tuple(float(x) for x in hit),
            hit_direction=tuple(float(x) for x in run.excitation_direction), pulse_s=pulse,
            window=window_settings_of(frf), estimator=frf.estimator)
        out.append(MeasuredLevel(run.name, mode.label, tuple(float(x) for x in np.sort(forces)),
                                 fit.frequency_hz, fit.frequency_std_hz, fit.damping_ratio,
                                 tuple(float(x) for x in band), setup, float(mode.frequency_hz),
                                 float(mode.damping_ratio), tuple(float(x) for x in weights)))
    return out


# --------------------------------------------------------------------------- test recordings


def simulate_force_levels(guide="MRB35", effects=(), forces_n=(100.0, 1000.0, 5000.0), hits: int = 4,
                          record_s: float = 0.05, spread: float = 0.05, seed: int = 0, ideal: bool = False,
                          run_name: str = "vertical", oversample: int = 4, sensor_layout: str | None = None,
                          acc_range_per_n: float = 0.5):
    """A recording of one hammer set-up hit at several force levels, one run per level.

    Each level is a :func:`guidefit.simulate.simulate` run (``run_name`` of
    :data:`guidefit.simulate.DEFAULT_RUNS`, renamed ``<run>_<F>N``) with peak
    forces drawn in ``F (1 +/- spread)`` and the ADC ranges set as an
    experimenter would for that force (force range the next power of two
    above 1.5 F, at least 2048 N; acceleration range ``acc_range_per_n`` times
    that in m/s^2, default half: a carriage of about 2 kg such as MRB35; a
    lighter carriage needs more, e.g. 4 for a 0.6 kg ball carriage), so
    nothing clips. ``oversample``: the simulator's internal rate / sample
    rate (its RK4 step). Returns ``(RecordingData, truth per level)``.
    """
    from dataclasses import replace

    from guidefit.io import RecordingData
    from guidefit.simulate import DEFAULT_RUNS, SimulationConfig, simulate

    base = {r.name: r for r in DEFAULT_RUNS}
    if run_name not in base:
        raise ModelError(f"run '{run_name}' unknown; have {', '.join(base)}")
    runs, truths = [], {}
    for level, force in enumerate(forces_n):
        full = max(2048.0, 2.0 ** math.ceil(math.log2(1.5 * force)))
        name = f"{run_name}_{force:g}N"
        cfg = SimulationConfig(runs=(replace(base[run_name], name=name),), hits=hits, record_s=record_s,
                               force_n=(force * (1 - spread), force * (1 + spread)),
                               force_range_n=full, acc_range_m_s2=full * acc_range_per_n, oversample=oversample,
                               sensor_layout=sensor_layout)
        data, truth = simulate(guide, effects, cfg.ideal() if ideal else cfg, seed=seed + 1000 * level)
        runs += list(data.runs)
        truths[name] = truth
    guide_name = data.guide
    return RecordingData(runs=tuple(runs), guide=guide_name, description=f"force levels, seed {seed}"), truths


# --------------------------------------------------------------------------- fit


#: First-guess grid of the preload factor (one simulated hit per level each).
PRELOAD_GRID = (0.1, 0.25, 0.5, 1.0, 2.0, 4.0)
PRELOAD_BOUNDS = (0.01, 10.0)
KN_BOUNDS = (0.05, 5.0)


@dataclass(frozen=True)
class NonlinearFit:
    """Preload factor (and roller-stiffness factor) fitted to force levels by the forward model.

    ``predicted``: the apparent mode of every level at the fitted parameters;
    ``sigma_hz``: the levels' uncertainties (:meth:`MeasuredLevel.sigma_hz`);
    ``kn_std`` is None when ``K_n`` was not fitted. ``seconds``: process time
    of the fit, ``evaluations``: forward-model runs.
    """

    preload_factor: float
    preload_std: float
    kn_factor: float
    kn_std: float | None
    levels: tuple
    predicted: tuple
    sigma_hz: tuple
    chi2: float
    dof: int
    evaluations: int
    seconds: float

    @property
    def within_uncertainty(self) -> bool:
        """Every level's residual within 3 of its sigma."""
        return all(abs(p.frequency_hz - lv.frequency_hz) <= 3 * s
                   for lv, p, s in zip(self.levels, self.predicted, self.sigma_hz))

    def rows(self) -> list[dict]:
        """One row per level: run, label, force (N), measured, predicted, sigma (Hz), error (%)."""
        return [{"run": lv.run, "label": lv.label, "peak_force_n": lv.peak_force_n,
                 "measured_hz": lv.frequency_hz, "predicted_hz": p.frequency_hz, "sigma_hz": s,
                 "measured_damping": lv.damping_ratio, "predicted_damping": p.damping_ratio,
                 "error_pct": 100.0 * (p.frequency_hz / lv.frequency_hz - 1.0)}
                for lv, p, s in zip(self.levels, self.predicted, self.sigma_hz)]

    def to_dict(self) -> dict:
        """JSON-ready summary."""
        return {"preload_factor": self.preload_factor, "preload_std": self.preload_std,
                "kn_factor": self.kn_factor, "kn_std": self.kn_std, "chi2": self.chi2, "dof": self.dof,
                "within_uncertainty": self.within_uncertainty, "evaluations": self.evaluations,
                "seconds": self.seconds, "levels": self.rows()}


def stiffness_slope(guide) -> float:
    """d ln K_n / d ln delta of the guide's contact law, ``e - 1`` (:func:`guidefit.model.static.exponent`).

    1/9 for rollers (Eq. 4, ``K_n ~ delta^(1/9)``), 1/2 for balls (Eq. 3,
    ``K_n ~ delta^(1/2)``): a preload factor p scales the small-amplitude
    element stiffness by ``p^slope``.

    >>> from guidefit.model.guides import load_guide
    >>> round(stiffness_slope(load_guide("MRB35")), 4)
    0.1111
    """
    from guidefit.model import static

    return static.exponent(guide) - 1.0


def _params(theta, fit_kn: bool, kn_fixed: float, slope: float) -> tuple[float, float]:
    """(p, k) from the fit coordinates (ln p, ln of the small-amplitude stiffness factor k p^slope),
    ``slope`` the guide's :func:`stiffness_slope`."""
    p = math.exp(theta[0])
    if not fit_kn:
        return p, kn_fixed
    return p, float(np.clip(math.exp(theta[1]) / p**slope, *KN_BOUNDS))


def _residuals(fm: ForwardModel, f_meas, sigma, theta, fit_kn: bool, kn_fixed: float, n_hits=None):
    p, k = _params(theta, fit_kn, kn_fixed, fm.stiffness_slope)
    try:
        pred = fm.predict(p, k, n_hits)
    except (IdentificationError, ModelError):
        return np.full(f_meas.size, 1e3)
    return (np.array([x.frequency_hz for x in pred]) - f_meas) / sigma


def _first_guess(fm: ForwardModel, f_meas, sigma, lowest: int) -> tuple[float, float]:
    """(p, k): the minimum of a spline through the costs on :data:`PRELOAD_GRID` (one hit per level),
    k from the lowest level at small amplitude."""
    label = fm.levels[lowest].label

    def k_of(p):
        return float(np.clip((f_meas[lowest] / fm.small_amplitude_hz(p, 1.0)[label]) ** 2, *KN_BOUNDS))

    costs = []
    for p in PRELOAD_GRID:
        try:
            k = k_of(p)
            r = _residuals(fm, f_meas, sigma, np.log([p, k * p**fm.stiffness_slope]), True, k, n_hits=1)
            costs.append(float(r @ r))
        except ModelError:
            costs.append(math.inf)
    p = _coarse_minimum(np.log(PRELOAD_GRID), np.array(costs))
    return p, k_of(p)


def fit_levels(levels, guide="MRB35", fit_kn: bool = True, kn_factor: float = 1.0, n_hits: int = SIM_HITS,
               effects=(), forward: ForwardModel | None = None) -> NonlinearFit:
    """Fit the preload factor (and ``K_n`` from the lowest level) to measured force levels.

    Parameters
    ----------
    levels : list of MeasuredLevel
        At least two, forces differing by :data:`FORCE_RATIO` (:func:`measure_levels`).
    guide : Guide or str
    fit_kn : bool
        Fit the roller-stiffness factor too (else fixed at ``kn_factor``).
    n_hits, effects
        As for :class:`ForwardModel`.

    Raises :class:`~guidefit.errors.ModelError` for too few levels.
    """
    from scipy.optimize import least_squares

    levels = list(levels)
    if len(levels) < 2 + int(fit_kn) - 1 or len(levels) < 2:
        raise ModelError(f"amplitude_dependence: {len(levels)} force level(s); the fit needs at least 2")
    t0 = time.process_time()
    fm = forward or ForwardModel(guide, levels, n_hits, effects=effects)
    f_meas = np.array([lv.frequency_hz for lv in levels])
    sigma = np.array([lv.sigma_hz() for lv in levels])
    lowest = int(np.argmin([lv.peak_force_n for lv in levels]))
    p0, k0 = _first_guess(fm, f_meas, sigma, lowest)
    # coordinates: ln p and ln of the small-amplitude stiffness factor k p^s, s = e - 1 of the guide's law
    # (Eq. 4 rollers: K_n ~ Delta^(1/9); Eq. 3 balls: K_n ~ Delta^(1/2)), which the lowest level fixes nearly
    # alone: the two are then almost uncorrelated
    s = fm.stiffness_slope
    x0 = np.log([p0, k0 * p0**s]) if fit_kn else np.log([p0])
    lo = np.log([PRELOAD_BOUNDS[0], KN_BOUNDS[0] * PRELOAD_BOUNDS[0] ** s][: x0.size])
    hi = np.log([PRELOAD_BOUNDS[1], KN_BOUNDS[1] * PRELOAD_BOUNDS[1] ** s][: x0.size])
    res = least_squares(lambda th: _residuals(fm, f_meas, sigma, th, fit_kn, kn_factor), np.clip(x0, lo, hi),
                        bounds=(lo, hi), diff_step=1e-2, x_scale=1.0, xtol=1e-3, ftol=1e-6, max_nfev=30)
    chi2 = float(res.fun @ res.fun)
    dof = len(levels) - x0.size
    try:
        cov = np.linalg.inv(res.jac.T @ res.jac) * max(1.0, chi2 / dof if dof > 0 else 1.0)
        std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    except np.linalg.LinAlgError:
        cov = np.full((x0.size, x0.size), math.inf)
        std = np.full(x0.size, math.inf)
    p, k = _params(res.x, fit_kn, kn_factor, s)
    pred = fm.predict(p, k)
    k_std = None
    if fit_kn:  # ln k = theta_1 - s theta_0
        grad = np.array([-s, 1.0])
        k_std = k * math.sqrt(max(float(grad @ cov @ grad), 0.0)) if np.all(np.isfinite(std)) else math.inf
    return NonlinearFit(p, p * float(std[0]), k, k_std, tuple(levels),
                        tuple(pred), tuple(float(s) for s in sigma), chi2, dof, fm.evaluations,
                        time.process_time() - t0)


# --------------------------------------------------------------------------- explain


#: Preload factors at which explain's forward model is simulated; between them the apparent frequency
#: ratio (level / small-amplitude) is interpolated in ln p by a cubic spline.
EXPLAIN_GRID = tuple(float(x) for x in np.geomspace(0.05, 10.0, 11))
#: Around the coarse grid's best preload factor, DENSE_POINTS factors within exp(+/- DENSE_HALF_WIDTH) are
#: simulated with every hit (explain's fit interpolates between them).
DENSE_POINTS, DENSE_HALF_WIDTH = 5, 0.2

def prepare_for_explain(identification, modes, levels, notes: list):
    """Force levels across runs that differ only in hit force, for explain; modes of their harder runs out.

    Each group of runs found by :func:`measure_levels` with two or more
    runs gives :class:`guidefit.explain.ForceLevel` entries (named after its
    lowest run, so they form one trend with the mode identified there), and
    each carries its measured setup for the simulated forward model
    (``amplitude_dependence``'s ``forward``). When the levels change with
    force (p < :data:`TREND_P_VALUE`), every mode, labelled or extra, of the
    group's harder runs is left out: a peak distorted or split by contact
    loss is that level's nonlinear mode, which enters through the level,
    never an extra mode.
    Returns ``(modes, levels)``.
    """
    from guidefit.model.measured import ForceLevel

    if len(identification.runs) < 2:
        return modes, list(levels)
    found = measure_levels(identification, notes=notes, min_runs=2)
    by_group: dict = {}
    for lv in found:
        by_group.setdefault((lv.setup.hit_position_m, lv.setup.hit_direction, lv.label), []).append(lv)
    harder, lowest, out = set(), set(), list(levels)
    for group in by_group.values():
        runs = sorted({lv.run for lv in group}, key=lambda r: min(x.peak_force_n for x in group if x.run == r))
        if len(runs) < 2:
            continue  # one run with a force spread: identify's own force levels cover it
        if _trend_p(group) < TREND_P_VALUE:  # contact loss distorts the harder runs' peaks
            harder.update(runs[1:])
            lowest.add(runs[0])
        out = [x for x in out if x.run not in runs]
        out += [ForceLevel(lv.peak_force_n, lv.label, lv.frequency_hz, lv.frequency_std_hz,
                           hit_position_m=lv.setup.hit_position_m, hit_direction=lv.setup.hit_direction,
                           pulse_s=lv.setup.pulse_s, run=runs[0], hit_forces_n=lv.hit_forces_n,
                           band_hz=lv.band_hz, measured=lv) for lv in group]
    if harder:
        dropped = [m for m in modes if m.run in harder]
        modes = [m for m in modes if m.run not in harder]
        added = _lowest_run_modes(identification, lowest, modes, {m.label for m in dropped})
        notes.append(f"runs {', '.join(sorted(harder))}: force levels of one test (the same hits, harder); "
                     f"their {len(dropped)} mode(s) enter through the levels, not as modes or extra peaks"
                     + (f"; {len(added)} mode(s) of the lowest run instead" if added else ""))
        modes += added
    return modes, out


def _lowest_run_modes(identification, lowest: set, kept: list, labels: set) -> list:
    """The lowest runs' own labelled modes of the labels that identify had taken from a harder run."""
    from guidefit.model.measured import measured_mode

    have = {(m.run, m.label) for m in kept}
    found = [im for rr in identification.runs if rr.name in lowest for im in rr.modes
             if im.label in labels and im.label != "extra" and (rr.name, im.label) not in have]
    return [measured_mode(im, f"{identification.file}: modes entry {k}") for k, im in enumerate(found)]


#: Levels whose de-meaned frequencies have a chi-square p-value below this change with force.
TREND_P_VALUE = 0.01


def _trend_p(group) -> float:
    """p-value of "the frequency does not change with force" over a group of levels."""
    from scipy.stats import chi2 as chi2_dist

    f = np.array([lv.frequency_hz for lv in group])
    s = np.array([lv.sigma_hz() for lv in group])
    w = s**-2.0
    z = (f - np.sum(w * f) / np.sum(w)) / s
    return float(chi2_dist.sf(float(z @ z), len(group) - 1))


def registered_levels(levels_data) -> list | None:
    """The :class:`MeasuredLevel` behind every level explain compares (carried by
    :func:`prepare_for_explain`'s ForceLevels), or None if any level has none."""
    measured = list(getattr(levels_data, "measured", ()) or ())
    if len(measured) != len(levels_data.frequency_hz) or any(lv is None for lv in measured):
        return None
    return measured


def _ratios(fm: ForwardModel, levels, p: float, n_hits: int) -> list:
    small = fm.small_amplitude_hz(p)
    try:
        return [x.frequency_hz / small[lv.label] for lv, x in zip(levels, fm.predict(p, 1.0, n_hits))]
    except IdentificationError:
        return [math.nan] * len(levels)


def _coarse_minimum(x, cost) -> float:
    """Preload factor at the minimum of a cubic spline through the coarse grid's costs."""
    from scipy.interpolate import CubicSpline

    ok = np.isfinite(cost)
    if ok.sum() < 4:
        return float(math.exp(x[int(np.nanargmin(np.where(ok, cost, np.nan)))]))
    fine = np.linspace(x[ok][0], x[ok][-1], 400)
    return float(math.exp(fine[int(np.argmin(CubicSpline(x[ok], np.log1p(cost[ok]))(fine)))]))


def _ratio_cost(levels, ratios) -> np.ndarray:
    """Misfit of each row of ratios, the lowest level anchoring the small-amplitude frequency."""
    f = np.array([lv.frequency_hz for lv in levels])
    sigma = np.array([lv.sigma_hz() for lv in levels])
    low = int(np.argmin([lv.peak_force_n for lv in levels]))
    return np.array([np.nansum(((f[low] / r[low] * r - f) / sigma) ** 2) if np.isfinite(r[low]) else math.inf
                     for r in ratios])


def ratio_table(guide, levels, cache: dict, n_hits: int = SIM_HITS):
    """Apparent / small-amplitude frequency of each level against ln p (cached per explain call).

    A coarse grid (:data:`EXPLAIN_GRID`, one simulated hit per level) finds
    the preload factor p* whose ratios fit the measured levels best (the
    lowest level anchoring the small-amplitude frequency; minimum of a spline
    through the grid's costs); :data:`DENSE_POINTS` factors within
    ``p* exp(+/- DENSE_HALF_WIDTH)`` are then simulated with ``n_hits`` hits,
    and the window is moved (up to three times, points kept) while the
    minimum of their costs lies in its outer fifths. Returns
    ``(coarse ln p, coarse ratios, dense ln p, dense ratios)``; explain scales
    its candidate's small-amplitude frequency by the interpolated ratio.
    """
    key = ("nonlinear-ratio", id(guide), tuple((lv.run, lv.label, round(float(lv.frequency_hz), 6)) for lv in levels))
    if key not in cache:
        fm = ForwardModel(guide, levels, n_hits)
        coarse = np.array([_ratios(fm, levels, p, 1) for p in EXPLAIN_GRID])
        best = _coarse_minimum(np.log(EXPLAIN_GRID), _ratio_cost(levels, coarse))
        xs, rows = [], []
        for _ in range(4):
            for lp in math.log(best) + np.linspace(-DENSE_HALF_WIDTH, DENSE_HALF_WIDTH, DENSE_POINTS):
                if not any(abs(lp - x) < 1e-3 for x in xs):
                    xs.append(float(lp))
                    rows.append(_ratios(fm, levels, math.exp(lp), n_hits))
            order = np.argsort(xs)
            xd, rd = np.array(xs)[order], np.array(rows)[order]
            best = _coarse_minimum(xd, _ratio_cost(levels, rd))
            inner = 0.6 * (xd[-1] - xd[0]) / 2
            if abs(math.log(best) - 0.5 * (xd[0] + xd[-1])) <= inner or not PRELOAD_BOUNDS[0] < best < PRELOAD_BOUNDS[1]:
                break
        cache[key] = (np.log(EXPLAIN_GRID), coarse, xd, rd)
    return cache[key]


def level_predictions(guide, levels, small_hz, preload_factor: float, cache: dict) -> np.ndarray:
    """Predicted apparent frequency (Hz) of each level: ``small_hz`` times the interpolated ratio."""
    from scipy.interpolate import CubicSpline

    xc, rc, xd, rd = ratio_table(guide, levels, cache)
    lp = math.log(preload_factor)
    x, ratios = (xd, rd) if xd[0] <= lp <= xd[-1] else (xc, rc)
    lp = float(np.clip(lp, x[0], x[-1]))
    out = np.full(len(levels), np.nan)
    for k in range(len(levels)):
        ok = np.isfinite(ratios[:, k])
        if ok.sum() >= 4:
            out[k] = small_hz[k] * float(CubicSpline(x[ok], ratios[ok, k])(lp))
    return out
