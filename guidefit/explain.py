r"""Close the loop: find the physical effect that the nominal model lacks (issue 5).

``guidefit explain`` takes identified modes (frequencies with their
uncertainty, optionally each mode's shape at the sensors and the frequency
per hit-force level), pairs them with the modes of the nominal 5-DOF model of
:mod:`guidefit.model.vibration`, and then fits every candidate effect of the
library :mod:`guidefit.model.effects` by least squares. Model selection picks
the simplest model that agrees with the data within their uncertainty, or says
that none does.

Data and residuals
------------------
Each measured mode ``i`` contributes

* a frequency residual ``(f_model - f_i) / sigma_i`` with
  ``sigma_i = max(std_i, FREQUENCY_FLOOR f_i)``: the floor (0.05 %) stands for
  what the rigid-carriage model cannot be expected to reproduce (model form);
  a mode given without a standard deviation gets ``DEFAULT_FREQUENCY_STD``
  (1 %, the scatter of raw peak picking);
* if it has a shape at the sensors: the component of the measured unit shape
  vector perpendicular to the model's, ``(m - a (a . m)) sqrt(n_ch) / s``,
  whose squared norm is ``(1 - MAC) n_ch / s^2``. ``s`` is the relative
  per-channel noise of the shape (``shape_std``, floor 1 %; when not given,
  estimated from the part of the shape that no rigid carriage motion
  explains, floor 2 %, or 3 % of the RMS amplitude when the sensors do not
  over-determine the motion); these terms are chi-square with ``n_ch - 1``
  degrees of freedom. The model shape at a sensor is
  ``direction . rigid_body_map(position) @ shapes[:5]``;
* if the model has no mode to pair it with: a fixed residual of
  :data:`UNPAIRED_PENALTY` standard deviations (an extra peak that a candidate
  cannot produce; this is what makes ``base_mode`` win when one exists).

Each force level (the frequency of one mode from the hits of one force bin)
adds ``(d - mean_w(d)) / sigma`` with ``d = f_model(F) - f_level``: the
levels of one mode from one run are a trend measured with one estimator, and
only the trend is compared (its weighted mean over the group is removed, one
degree of freedom per group). The estimator of a level (a narrow refit of the
hits of one force bin) may sit off the run's full modal fit by more than its
own standard deviation; the mode itself carries the absolute frequency. A
label's levels are taken from the run that gave its mode. Linear models predict the same
frequency at every force; ``amplitude_dependence`` predicts the describing-
function frequency (below).

Pairing
-------
Measured modes are paired with model modes by the Hungarian method
(:func:`scipy.optimize.linear_sum_assignment`), separately per run, with the
cost ``10 |ln(f_i / f_j)| + label + 5 (1 - MAC)``. The label term is
``10 (1 - share)``, ``share`` the model mode's kinetic-energy share (carriage
only) of the motion the measured label names (v for ``vertical``, theta for
``pitch``, psi for ``yaw``, u+phi for the roll modes), plus 3 between
``roll_low`` and ``roll_high``. A labelled mode may so pair with a mode far
off in frequency (the paper's f_H = 1075 Hz pairs with the model's roll_low at
2496 Hz), while an unlabelled one (``extra``) pairs only within about 35 %
(dummy cost 3; labelled 20). Model modes left over are "not observed" and
carry no residual. The pairing is redone at every model evaluation, since an
effect may reorder modes.

Fitting
-------
Each candidate is a set of effect variants: discrete options are enumerated
(``added_mass`` at ABCD, each of A-D, or the centre; ``row_damage`` rows 1-4;
``support_compliance`` lateral, vertical, roll or lateral+vertical;
``base_mode`` vertical, lateral or both; ``com_offset`` y or xyz), continuous
parameters are fitted by :func:`scipy.optimize.least_squares` in transformed
coordinates (log for stiffnesses, masses and factors) within physical bounds
(:class:`~guidefit.model.effects.Parameter`, narrowed where the library's are
wider than physics allows: a centre of mass inside the carriage). Misfits of
support springs and masses are not convex: a grid of starts across decades
is scored first and the best few are polished. Standard deviations come from
the Jacobian, ``cov = (J^T J)^-1 max(1, chi2/dof)``.

Amplitude dependence
--------------------
Rollers are preloaded Hertz line contacts, ``Q = C delta^(10/9)`` for
``delta > 0`` (:func:`guidefit.model.static.roller_force`, calibration
"nominal": K_n at the guide's preload is the vibration model's). With preload
``Delta' = p Delta`` (``p`` = ``preload_factor``) the small-amplitude roller
stiffness is ``K_n p^(1/9)``. A roller oscillating with amplitude ``a`` has
the describing-function (first-harmonic) stiffness
``k_eq(a) = (1/(pi a)) int Q(Delta' + a sin t) sin t dt = K_n p^(1/9) D(a/Delta')``;
``D`` falls from 1 towards about 0.65 once the roller lifts off (``a > Delta'``).
A hit of peak force F (half-sine of duration T, default 0.1 ms, a steel
tip) leaves every model mode m ringing with modal amplitude
``A_m = |b_m| |P(w_m)| / w_m`` (``P`` the pulse's Fourier transform, ``b_m``
the mode's participation at the hit point and direction, default those of
:data:`guidefit.simulate.DEFAULT_RUNS`), decaying as
``exp(-zeta_m w_m t)`` (damping from the measured partner, else 2 %).
Roller i moves with the RMS sum ``a_i(t) = sqrt(sum_m (g_i . phi_m A_m(t))^2)``,
and mode j's frequency at time t is the Rayleigh quotient with ``k_eq`` of
each roller at ``a_i(t)``: a vertical hit also softens pitch. The
identified frequency is what a single-pole fit of the spectrum of the
resulting chirped decay gives (:func:`_decay_fit_frequency`): a fit of an
FRF weights the slowly sweeping small-amplitude tail most, so it sees
roughly half the drop of the energy-weighted mean of ``w(t)``. Fitted to
the trend over force levels and to the modes, ``p`` tells where rows start
to unload (about 1 kN for the MRB35 at its nominal preload). A mode of a run
without force levels is compared with the small-amplitude model; otherwise
it is predicted at the force-squared RMS of the levels of its label (or,
without those, of its run: the same hits), since H1 averaging weights hits
by F^2. Against identify on RK4-simulated recordings the predicted shift is
good to about a factor 2 (better at drops below 0.3 %), so every predicted
frequency carries a model-form error of :data:`AMPLITUDE_MODEL_FORM` (50 %)
of its predicted shift (capped at :data:`AMPLITUDE_SHIFT_CAP` of the
frequency). A run whose force levels change with force beyond their
uncertainty has responded nonlinearly; the modal fit of its chirped peaks
distorts the mode shapes (overlapping modes are partitioned differently), so
that run's shapes are not used.

Extra peaks
-----------
When no candidate is accepted and some unlabelled modes (extra peaks of the
modal fit) have no partner in the nominal model, the selection is repeated
without them. If an effect then explains every other datum it is named, and
the note and the modes table (``status: "left out"``) say which peaks it
does not produce: a fit artefact (an amplitude-dependent peak fitted with two
poles) or a cause outside the library. A real base body is found in the
first pass (``base_mode`` pairs its peak).

Model selection and verdicts
----------------------------
Score: BIC = chi2 + k ln n (k fitted parameters, n data). A model is
*accepted* when it has at least one degree of freedom left, its chi-square
p-value is at least :data:`ACCEPT_P_VALUE` and every fitted parameter is
identifiable (finite standard deviation below a factor 1.65, not at a
bound). Single effects are tried first; pairs of effects only when no single
effect is accepted (forward selection from the three best singles).

* ``adequate``: the nominal model passes the test; no effect is claimed.
* ``explained``: the accepted model with the fewest effects and the lowest
  BIC; any other accepted model within :data:`EQUAL_BIC` is named in a note
  ("explain the data equally well") and in ``alternatives``. ``effects``
  lists the lowest-BIC one; ``alternatives`` the others.
* ``unexplained``: no candidate is accepted. ``effects`` is empty (contract);
  the best attempt (lowest BIC with a degree of freedom left) is shown as
  ``best_attempt``, not accepted. Models with as many parameters as data
  are "not identifiable from these data".

Examples
--------
The paper's own measurement (f_V = 3450 Hz, f_H = 1075 Hz):

>>> from guidefit.explain import MeasuredMode, explain_modes
>>> paper = [MeasuredMode(3450.0, 0.8, label="vertical"), MeasuredMode(1075.0, 0.9, label="roll_low")]
>>> result = explain_modes(paper, "MRB35")
>>> result.verdict, result.best_attempt["name"]
('unexplained', 'support_compliance')
>>> round(result.best_attempt["effects"][0]["parameters"]["lateral_n_per_m"]["value"] / 1e8, 2)
1.18
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from guidefit.errors import GuidefitError, IdentificationError, ModelError, RecordingError
from guidefit.model.effects import LevelData, Variant
from guidefit.model.effects.amplitude_dependence import (  # noqa: F401 - public here since issue 5
    AMPLITUDE_MODEL_FORM,
    AMPLITUDE_SHIFT_CAP,
    DEFAULT_DECAY_DAMPING,
    effective_force,
)

#: Model-form floor of a mode's relative frequency uncertainty (0.05 %).
FREQUENCY_FLOOR = 5.0e-4
#: Floor of a force level's relative frequency uncertainty (0.1 %): the model-form error of the predicted
#: trend with force (against identify on RK4-simulated recordings: 0.02 % for drops up to 0.3 %, up to 0.15 %
#: for drops near 1 %; see docs/explain.md).
FORCE_LEVEL_FLOOR = 1.0e-3
#: Relative frequency uncertainty of a mode that gives none (1 %, raw peak picking).
DEFAULT_FREQUENCY_STD = 1.0e-2
#: Relative per-channel noise of a mode shape that gives none and whose sensors do not over-determine
#: the carriage motion (3 % of its RMS amplitude); otherwise it is estimated (:func:`_shape_noise`).
DEFAULT_SHAPE_STD = 0.03
#: Floor of the relative shape noise (sensor positions, carriage not quite rigid).
SHAPE_STD_FLOOR = 0.01
#: Floor of a shape noise estimated from the rigid-body residual (2 %): that residual sees random noise,
#: not the systematic errors of a modal fit (overlapping modes partitioned imperfectly, amplitude-dependent
#: peaks); on simulated recordings the MAC of a correctly explained mode was down to 0.9986 (docs/explain.md).
ESTIMATED_SHAPE_STD_FLOOR = 0.02
#: Residual (standard deviations) of a measured mode that the model cannot produce.
UNPAIRED_PENALTY = 1000.0
#: Chi-square p-value from which a model agrees with the data within uncertainty.
ACCEPT_P_VALUE = 0.01
#: BIC difference below which two models explain the data equally well.
EQUAL_BIC = 2.0
#: Largest standard deviation of a log-parameter (a factor 1.65) that still counts as identified.
IDENTIFIABLE_LOG_STD = 0.5
#: Variants of one effect (its best by single fit) tried as the partner of a seed in pairs of effects.
PAIR_PARTNER_VARIANTS = 6
#: Half-sine hammer pulse duration (s) when a force level gives none: 0.1 ms, a steel tip.
DEFAULT_PULSE_S = 1.0e-4

CARRIAGE_LABELS = ("vertical", "pitch", "yaw", "roll_low", "roll_high")
_GROUP = {"vertical": 0, "pitch": 1, "yaw": 2, "roll_low": 3, "roll_high": 3}
_ALIASES = {"v": "vertical", "f_v": "vertical", "h": "roll_low", "f_h": "roll_low",
            "horizontal": "roll_low", "lateral": "roll_low"}
_VERTICAL_HIT = ((0.004, 0.0, 0.008), (0.0, -1.0, 0.0))
_LATERAL_HIT = ((0.05, -0.012, 0.006), (-1.0, 0.0, 0.0))
#: Hit point and direction per mode label when a force level gives none (simulate's DEFAULT_RUNS).
DEFAULT_HITS = {"vertical": _VERTICAL_HIT, "pitch": _VERTICAL_HIT, "yaw": _LATERAL_HIT,
                "roll_low": _LATERAL_HIT, "roll_high": _LATERAL_HIT}
_BAD = 1.0e4  # residual of a model that cannot be evaluated


# --------------------------------------------------------------------------- input types


@dataclass(frozen=True)
class MeasuredMode:
    """An identified mode: frequency with its standard deviation, optional label and shape.

    ``frequency_std_hz=None`` means unknown (:data:`DEFAULT_FREQUENCY_STD` applies).
    ``shape`` maps sensor channel names to modal amplitudes (any scale and phase);
    ``shape_std`` is its relative per-channel noise (default :data:`DEFAULT_SHAPE_STD`).
    Modes of different ``run`` are paired with the model separately.
    """

    frequency_hz: float
    frequency_std_hz: float | None
    damping_ratio: float | None = None
    label: str | None = None
    shape: dict | None = None
    run: str | None = None
    shape_std: float | None = None


@dataclass(frozen=True)
class Sensor:
    """A response channel: name, position (m, carriage frame) and unit direction."""

    name: str
    position_m: tuple
    direction: tuple


@dataclass(frozen=True)
class ForceLevel:
    """The frequency of one mode identified from the hits of one force bin.

    ``hit_position_m``, ``hit_direction`` and ``pulse_s`` describe the hits
    (defaults: :data:`DEFAULT_HITS` for the label and :data:`DEFAULT_PULSE_S`).
    ``hit_forces_n``: the peak force of every hit of the bin (H1 weights a
    hit by its force squared; default: ``peak_force_n`` for all).
    ``band_hz``: the band of the refit that gave the frequency (default
    ``+/- max(3 zeta, 3 %)``). ``frequency_hz`` None: the bin's hits did not
    reproduce the mode (identify's refit moved it by more than its
    half-power half-bandwidth or failed). ``shape``: the mode's modal
    constants per channel from that refit.
    """

    peak_force_n: float
    label: str
    frequency_hz: float | None
    frequency_std_hz: float | None
    hit_position_m: tuple | None = None
    hit_direction: tuple | None = None
    pulse_s: float | None = None
    run: str | None = None
    hit_forces_n: tuple | None = None
    band_hz: tuple | None = None
    shape: dict | None = None


# --------------------------------------------------------------------------- result


def _clean(x):
    """JSON-safe: numpy scalars to Python, non-finite floats to None."""
    if isinstance(x, dict):
        return {k: _clean(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_clean(v) for v in x]
    if isinstance(x, np.generic):
        x = x.item()
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


@dataclass(frozen=True)
class Explanation:
    """The result of :func:`explain_modes`.

    ``verdict`` is ``adequate``, ``explained`` or ``unexplained``;
    ``error_before`` and ``error_after`` hold the RMS relative frequency error
    (%) of the nominal and of the selected model (for ``unexplained``: of the
    best attempt, marked in ``model``); ``effects`` the selected effects with
    parameter values and standard deviations; ``candidates`` every fitted
    model ranked by BIC; ``modes`` one entry per measured mode.
    """

    verdict: str
    guide: str
    error_before: dict
    error_after: dict
    effects: tuple
    candidates: tuple
    modes: tuple
    notes: tuple
    source: str | None = None
    best_attempt: dict | None = None
    alternatives: tuple = ()
    n_data: int = 0
    settings: dict = field(default_factory=dict)
    fitted_effects: tuple = ()  # guidefit.model.effects.Effect of the "after" model

    def to_dict(self) -> dict:
        """The contract's ``explain --json`` object, with optional extra fields."""
        return _clean({
            "file": self.source,
            "guide": self.guide,
            "verdict": self.verdict,
            "error_before": dict(self.error_before),
            "error_after": dict(self.error_after),
            "effects": list(self.effects),
            "modes": list(self.modes),
            "candidates": list(self.candidates),
            "alternatives": list(self.alternatives),
            "best_attempt": self.best_attempt,
            "notes": list(self.notes),
            "n_data": self.n_data,
            "settings": dict(self.settings),
        })

    def to_frame(self):
        """One row per measured mode: frequencies before/after, errors (%) and MAC."""
        import pandas as pd

        cols = ["label", "run", "measured_hz", "measured_std_hz", "sigma_hz", "model_before_hz",
                "model_after_hz", "error_before_pct", "error_after_pct", "mac_before", "mac_after"]
        return pd.DataFrame([{c: m.get(c) for c in cols} for m in self.modes], columns=cols)

    def candidates_frame(self):
        """One row per fitted candidate, best BIC first."""
        import pandas as pd

        cols = ["name", "variant", "n_params", "chi2", "dof", "p_value", "bic", "delta_bic",
                "rms_frequency_error_pct", "accepted", "note"]
        return pd.DataFrame([{c: m.get(c) for c in cols} for m in self.candidates], columns=cols)


# --------------------------------------------------------------------------- prepared data


@dataclass
class _Data:
    f: np.ndarray  # (n,) measured frequencies, Hz
    sigma: np.ndarray  # (n,) used standard deviations, Hz
    labels: list  # canonical carriage label or None
    label_arr: np.ndarray  # the same as an object array
    group: np.ndarray  # (n,) motion group of the label, -1 without
    runs: list  # index arrays, one per run
    shapes: list  # (idx, M, S, scale) per sensor set: modes, unit shapes (g, n_ch), (n_ch, 5), (g,)
    has_shape: np.ndarray  # (n,) bool
    lv_f: np.ndarray  # force levels: frequency, sigma, force, mode index to pair through
    lv_sigma: np.ndarray
    lv_force: np.ndarray
    lv_label: list
    lv_hit: list  # (point, direction, pulse_s)
    lv_groups: list  # index arrays into the levels, one per (run, label): a trend by one estimator
    lv_run: list
    mode_zeta: np.ndarray  # (n,) damping ratio per measured mode (nan: unknown)
    lv_weight: np.ndarray  # H1 weight of a level's hits: sum of their forces squared
    lv_band: list  # relative half-width of the refit band, or None (+/- max(3 zeta, 3 %))
    mode_force: np.ndarray  # (n,) F_eff per measured mode (nan: small amplitude)
    mode_hit: list  # hit geometry per measured mode or None
    mode_levels: list  # per measured mode: level indices whose hits made its FRF, or None
    f_fit: np.ndarray  # (n,) identify's all-hits frequency (f differs where the levels replaced it)
    n_data: int
    n_shape_dof: int
    levels: object = None  # guidefit.model.effects.LevelData: the same levels, for forward models
    mode_run: list = field(default_factory=list)  # run per measured mode


def _canonical(label):
    if label is None:
        return None
    text = str(label).strip()
    low = text.lower()
    if low in CARRIAGE_LABELS:
        return low
    return _ALIASES.get(low)


def _default_sensors(guide, channels) -> dict:
    """Sensors for channel names acc_<point>_<axis> from the guide's measuring points."""
    axes = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}
    out = {}
    for name in channels:
        parts = str(name).split("_")
        if len(parts) == 3 and parts[0] == "acc" and parts[1] in guide.measuring_points_m and parts[2] in axes:
            out[name] = Sensor(name, tuple(guide.measuring_points_m[parts[1]]), axes[parts[2]])
    return out


def _real_unit(values: np.ndarray) -> np.ndarray:
    v = np.asarray(values, dtype=complex)
    angle = 0.5 * np.angle(np.sum(v**2))
    r = np.real(v * np.exp(-1j * angle))
    norm = np.linalg.norm(r)
    return r / norm if norm > 0 else r


def _shape_noise(unit: np.ndarray, s_mat: np.ndarray) -> float:
    """Relative per-channel noise of a unit shape from the part that no rigid carriage motion explains.

    With more channels than observable carriage DOFs (8 channels at A-D in x
    and y observe 5 DOFs: 3 redundant), the residual of the least-squares
    rigid-body fit is noise (or a non-rigid carriage), whatever the model:
    ``s = |m - S q| sqrt(n_ch / (n_ch - rank S))`` relative to the RMS
    amplitude, with the floor :data:`ESTIMATED_SHAPE_STD_FLOOR`. Without redundancy
    :data:`DEFAULT_SHAPE_STD` applies.
    """
    n = unit.size
    rank = int(np.linalg.matrix_rank(s_mat))
    if n <= rank:
        return DEFAULT_SHAPE_STD
    q, *_ = np.linalg.lstsq(s_mat, unit, rcond=None)
    noise = float(np.linalg.norm(unit - s_mat @ q)) * math.sqrt(n / (n - rank))
    return max(noise, ESTIMATED_SHAPE_STD_FLOOR)


def _level_shape_scatter(mode, names, unit: np.ndarray, force_levels) -> float:
    """Relative per-channel scatter of a mode's shape over its force bins (0 without level shapes).

    identify refits each mode on the hits of each force bin; the component
    of a bin's unit shape perpendicular to the all-hits one, RMS over the
    bins, as a per-channel standard deviation
    ``|m_b - a (a . m_b)| sqrt(n_ch / (n_ch - 1))``. With linear contacts it
    is noise (below 0.5 % on simulated recordings, under the 2 % floor);
    when the frequency drifts with amplitude the modal fit of overlapping,
    chirped peaks moves a weak mode's shape with the hit force (pitch in a
    lateral run beside the 10 %-damped roll_low: 6-77 %), which a linear
    model's shape cannot follow.
    """
    lab = _canonical(mode.label)
    perp = []
    for lv in force_levels:
        if (not isinstance(lv, ForceLevel) or lv.frequency_hz is None or not lv.shape or lv.run != mode.run
                or _canonical(lv.label) != lab or not all(c in lv.shape for c in names)):
            continue
        b = np.array([complex(lv.shape[c]) for c in names])
        if not np.all(np.isfinite(b)) or not np.any(b):
            continue
        b = _real_unit(b)
        perp.append(float(np.linalg.norm(b - unit * (unit @ b))))
    if len(perp) < 2 or unit.size < 2:
        return 0.0
    return math.sqrt(float(np.mean(np.square(perp))) * unit.size / (unit.size - 1))


def _nonlinear_runs(groups, f, sigma, runs) -> set:
    """Runs whose force levels, as a whole, change with force beyond their uncertainty (p < ACCEPT_P_VALUE)."""
    chi2: dict = {}
    for g in groups:
        w = sigma[g] ** -2.0
        z = (f[g] - np.sum(w * f[g]) / np.sum(w)) / sigma[g]
        c, n = chi2.get(runs[g[0]], (0.0, 0))
        chi2[runs[g[0]]] = (c + float(z @ z), n + len(g) - 1)
    return {r for r, (c, n) in chi2.items() if n > 0 and _p_value(c, n) < ACCEPT_P_VALUE}


def _finite_positive(x) -> bool:
    return isinstance(x, int | float | np.floating | np.integer) and not isinstance(x, bool) \
        and math.isfinite(float(x)) and float(x) > 0


def _prepare(measured, guide, sensors, force_levels, notes) -> _Data:
    from guidefit.model.vibration import rigid_body_map

    measured = list(measured)
    if not measured:
        raise RecordingError("explain: no measured modes given")
    f, sigma, labels, runs_of = [], [], [], []
    n_default = 0
    for i, m in enumerate(measured):
        if not isinstance(m, MeasuredMode):
            raise RecordingError(f"measured mode {i}: expected a MeasuredMode, got {type(m).__name__}")
        if not _finite_positive(m.frequency_hz):
            raise RecordingError(f"measured mode {i}: frequency_hz must be a positive number, got {m.frequency_hz!r}")
        fi = float(m.frequency_hz)
        std = m.frequency_std_hz
        if std is None:
            n_default += 1
            std = DEFAULT_FREQUENCY_STD * fi
        elif not _finite_positive(std):
            raise RecordingError(f"measured mode {i}: frequency_std_hz must be positive or None, got {std!r}")
        f.append(fi)
        sigma.append(max(float(std), FREQUENCY_FLOOR * fi))
        labels.append(_canonical(m.label))
        runs_of.append(m.run)
    if n_default:
        notes.append(f"{n_default} mode(s) without a frequency uncertainty: {DEFAULT_FREQUENCY_STD:.0%} assumed")
    by_name = {s.name: s for s in sensors}
    channels = {c for m in measured if m.shape for c in m.shape}
    for name, s in _default_sensors(guide, channels).items():
        by_name.setdefault(name, s)
    by_set: dict = {}
    unknown: set = set()
    for i, m in enumerate(measured):
        if not m.shape:
            continue
        names = [c for c in m.shape if c in by_name]
        unknown.update(c for c in m.shape if c not in by_name)
        if len(names) < 2:
            continue
        vals = np.array([complex(m.shape[c]) for c in names])
        if not np.all(np.isfinite(vals)):
            raise RecordingError(f"measured mode {i}: shape values must be finite")
        if not np.any(vals):
            continue
        s_mat = np.array([np.asarray(by_name[c].direction, float) @ rigid_body_map(by_name[c].position_m)
                          for c in names])
        unit = _real_unit(vals)
        s_std = _shape_noise(unit, s_mat) if m.shape_std is None else max(float(m.shape_std), SHAPE_STD_FLOOR)
        s_std = max(s_std, _level_shape_scatter(m, names, unit, force_levels))
        entry = by_set.setdefault(tuple(names), ([], [], s_mat, []))
        entry[0].append(i)
        entry[1].append(unit)
        entry[3].append(math.sqrt(len(names)) / s_std)
    if unknown:
        notes.append(f"shape channels without a sensor position ignored: {', '.join(sorted(unknown))}")
    groups: dict = {}
    for i, r in enumerate(runs_of):
        groups.setdefault(r, []).append(i)
    # force levels
    lv_f, lv_s, lv_force, lv_label, lv_hit, lv_run, lv_w, lv_band = [], [], [], [], [], [], [], []
    lv_raw_s: list = []
    lv_all: list = []
    for j, lv in enumerate(force_levels):
        if not isinstance(lv, ForceLevel):
            raise RecordingError(f"force level {j}: expected a ForceLevel, got {type(lv).__name__}")
        if not _finite_positive(lv.peak_force_n) or not (lv.frequency_hz is None or _finite_positive(lv.frequency_hz)):
            raise RecordingError(f"force level {j}: peak_force_n and frequency_hz must be positive numbers")
        lab = _canonical(lv.label)
        if lab is None:
            raise RecordingError(f"force level {j}: label '{lv.label}' is not a carriage mode label "
                                 f"({', '.join(CARRIAGE_LABELS)})")
        if lv.frequency_hz is None:  # see _unreproduced
            continue
        forces_j = np.asarray(lv.hit_forces_n if lv.hit_forces_n else [lv.peak_force_n], float)
        if forces_j.ndim != 1 or not np.all(np.isfinite(forces_j) & (forces_j > 0)):
            raise RecordingError(f"force level {j}: hit_forces_n must be positive numbers")
        band = None
        if lv.band_hz is not None:
            lo, hi = (float(x) for x in lv.band_hz)
            if not 0 < lo < lv.frequency_hz < hi:
                raise RecordingError(f"force level {j}: band_hz must hold frequency_hz, got {lv.band_hz!r}")
            band = (hi - lo) / (hi + lo)
        std = lv.frequency_std_hz
        if std is None:
            std = DEFAULT_FREQUENCY_STD * lv.frequency_hz
        elif not _finite_positive(std):
            raise RecordingError(f"force level {j}: frequency_std_hz must be positive or None, got {std!r}")
        point, direction = DEFAULT_HITS[lab]
        point = tuple(lv.hit_position_m) if lv.hit_position_m is not None else point
        direction = np.asarray(lv.hit_direction if lv.hit_direction is not None else direction, float)
        direction = direction / (np.linalg.norm(direction) or 1.0)
        pulse = float(lv.pulse_s) if lv.pulse_s is not None else DEFAULT_PULSE_S
        lv_f.append(float(lv.frequency_hz))
        lv_s.append(max(float(std), FORCE_LEVEL_FLOOR * float(lv.frequency_hz)))
        lv_raw_s.append(float(std))
        # H1 = sum X F* / sum |F|^2 averages the hits' FRFs with weights F^2, so the bin's
        # frequency is that of the F^2-weighted hits; with a drop ~ F^2 (the describing function below
        # lift-off) that is the frequency at F_eff = sqrt(sum F^4 / sum F^2), not at the mean force
        lv_force.append(effective_force(forces_j))
        lv_all.append(tuple(float(x) for x in forces_j))
        lv_w.append(float(np.sum(forces_j**2)))
        lv_band.append(band)
        lv_label.append(lab)
        lv_hit.append((tuple(point), direction, pulse))
        lv_run.append(lv.run)
    # A label's levels come from the run that gave its mode (the same hits, the same estimator);
    # each (run, label) group is a trend with force, compared after removing its weighted mean.
    keep = []
    for j, lab in enumerate(lv_label):
        own = {runs_of[i] for i, ll in enumerate(labels) if ll == lab and runs_of[i] is not None}
        has_own = any(lv_run[k] in own for k, ll in enumerate(lv_label) if ll == lab)
        keep.append(not has_own or lv_run[j] in own)
    by_group: dict = {}
    for j, ok in enumerate(keep):
        if ok:
            by_group.setdefault((lv_run[j], lv_label[j]), []).append(j)
    used = sorted(j for g in by_group.values() if len(g) >= 2 for j in g)
    if len(used) < len(lv_f):
        notes.append(f"{len(lv_f) - len(used)} force level(s) not used (another run's estimate of the mode, "
                     "or a single level: no trend)")
    remap = {j: k for k, j in enumerate(used)}
    lv_groups = [np.array([remap[j] for j in g]) for g in by_group.values() if len(g) >= 2]
    lv_f, lv_s, lv_force, lv_raw_s = ([x[j] for j in used] for x in (lv_f, lv_s, lv_force, lv_raw_s))
    lv_label, lv_hit, lv_run = ([x[j] for j in used] for x in (lv_label, lv_hit, lv_run))
    lv_w, lv_band, lv_all = ([x[j] for j in used] for x in (lv_w, lv_band, lv_all))
    mode_zeta = np.array([m.damping_ratio if _finite_positive(m.damping_ratio) else np.nan for m in measured])
    mode_force = np.full(len(f), np.nan)
    mode_hit: list = [None] * len(f)
    mode_levels: list = [None] * len(f)
    f_fit = np.array(f)
    replaced = []
    for i, lab in enumerate(labels):
        js = [j for j, ll in enumerate(lv_label) if ll == lab]
        if not js and runs_of[i] is not None:  # the same hits made every mode of a run
            js = [j for j, rr in enumerate(lv_run) if rr == runs_of[i]]
        if lab is None or not js:
            continue
        w = np.array([lv_w[j] for j in js])
        mode_force[i] = math.sqrt(float(np.sum(w * np.square([lv_force[j] for j in js])) / np.sum(w)))
        mode_hit[i] = lv_hit[js[0]]
        mode_levels[i] = js
        own = [j for j in js if lv_label[j] == lab and lv_run[j] == runs_of[i]]
        if len(own) >= 2:
            # The mode's frequency from its own levels: the same hits (their H1 weights), but the narrow
            # band refit that the amplitude model reproduces. The all-hits fit spans the whole band and,
            # for a frequency that drifts within each hit, sees 1.5-3 times the drop (docs/explain.md).
            w = np.array([lv_w[j] for j in own])
            f_lv = float(np.sum(w * [lv_f[j] for j in own]) / np.sum(w))
            s_lv = float(np.sqrt(np.sum(np.square(w * [lv_raw_s[j] for j in own]))) / np.sum(w))
            f[i] = f_lv
            sigma[i] = max(s_lv, sigma[i] * f_lv / f_fit[i])
            mode_levels[i] = own
            replaced.append(i)
    if replaced:
        notes.append("frequency from the mode's force levels (narrow-band refits of the same hits, H1-weighted): "
                     + ", ".join(f"{labels[i]} ({runs_of[i]} run) {f[i]:.1f} Hz, all-hits fit {f_fit[i]:.1f} Hz"
                                 for i in replaced))
    # A run whose frequencies change with hit force responded nonlinearly: the modal fit of its
    # amplitude-dependent peaks distorts the shapes (overlapping modes partitioned differently), so its
    # shapes are not used; its frequencies and force levels are.
    nonlinear = _nonlinear_runs(lv_groups, np.array(lv_f), np.array(lv_s), lv_run)
    if nonlinear:
        dropped = 0
        for entry in by_set.values():
            keep_k = [k for k, i in enumerate(entry[0]) if runs_of[i] not in nonlinear]
            dropped += len(entry[0]) - len(keep_k)
            entry[0][:], entry[1][:], entry[3][:] = ([x[k] for k in keep_k] for x in (entry[0], entry[1], entry[3]))
        by_set = {key: e for key, e in by_set.items() if e[0]}
        if dropped:
            notes.append(f"run(s) {', '.join(sorted(map(str, nonlinear)))}: the frequency changes with hit force "
                         f"(p < {ACCEPT_P_VALUE}); the shapes of their {dropped} mode(s) are not used")
    shapes = [(np.array(ix), np.array(mm), s_mat, np.array(sc)) for ix, mm, s_mat, sc in by_set.values()]
    has_shape = np.zeros(len(f), bool)
    for ix, *_ in shapes:
        has_shape[ix] = True
    n_shape_dof = sum(mm.shape[0] * (mm.shape[1] - 1) for _, mm, _, _ in shapes)
    levels = LevelData(frequency_hz=np.array(lv_f), sigma_hz=np.array(lv_s), force_n=np.array(lv_force),
                       weight=np.array(lv_w), hit_forces_n=tuple(lv_all), label=tuple(lv_label),
                       run=tuple(lv_run), hit=tuple(lv_hit), band=tuple(lv_band), groups=tuple(lv_groups))
    return _Data(
        f=np.array(f), sigma=np.array(sigma), labels=labels, label_arr=np.array(labels, dtype=object),
        group=np.array([_GROUP.get(lab, -1) if lab else -1 for lab in labels]),
        runs=[np.array(v) for v in groups.values()], shapes=shapes, has_shape=has_shape,
        lv_f=np.array(lv_f), lv_sigma=np.array(lv_s), lv_force=np.array(lv_force), lv_label=lv_label,
        mode_zeta=mode_zeta, lv_hit=lv_hit, lv_groups=lv_groups, lv_run=lv_run, mode_force=mode_force, mode_hit=mode_hit,
        mode_levels=mode_levels, lv_weight=np.array(lv_w), lv_band=lv_band, f_fit=f_fit,
        n_data=len(f) + n_shape_dof + len(lv_f) - len(lv_groups), n_shape_dof=n_shape_dof,
        levels=levels, mode_run=list(runs_of),
    )


# --------------------------------------------------------------------------- model evaluation


@dataclass
class _Eval:
    r: np.ndarray
    pairing: np.ndarray  # (n,) model mode index or -1
    f_pred: np.ndarray  # (n,) predicted frequency of the paired mode (nan unpaired)
    mac: np.ndarray  # (n,) MAC with the paired mode (nan without shape)
    lv_pred: np.ndarray
    sol: object
    ok: bool = True


def _pair(data: _Data, sol) -> tuple[np.ndarray, dict]:
    """Hungarian pairing of measured with model modes (per run).

    Returns the model index per measured mode (-1 unpaired) and
    ``(A, mac)``: per sensor set the model shapes at the sensors (unit
    columns), and the MAC of every measured with every model mode.
    """
    from scipy.optimize import linear_sum_assignment

    fm = sol.frequencies_hz
    nm = fm.size
    energy = np.asarray(sol.energy_fractions)[:, :4]
    share = energy / np.maximum(energy.sum(axis=1, keepdims=True), 1e-300)
    model_labels = np.array(sol.labels, dtype=object)
    model_roll = (model_labels == "roll_low") | (model_labels == "roll_high")
    proj = []
    mac_full = np.zeros((data.f.size, nm))
    for idx, m_hat, s_mat, _ in data.shapes:
        a = s_mat @ sol.shapes[:5]
        norm = np.linalg.norm(a, axis=0)
        a = a / np.where(norm > 0, norm, 1.0)
        mac_full[idx] = (m_hat @ a) ** 2
        proj.append(a)
    pairing = np.full(data.f.size, -1)
    for idx in data.runs:
        n = idx.size
        cost = 10.0 * np.abs(np.log(data.f[idx, None] / fm[None, :]))
        g = data.group[idx]
        has = g >= 0
        if np.any(has):
            cost[has] += 10.0 * (1.0 - share[:, g[has]].T)
            roll = np.flatnonzero(g == 3)
            if roll.size:
                own = data.label_arr[idx[roll]]
                cost[roll] += 3.0 * (model_roll[None, :] & (model_labels[None, :] != own[:, None]))
        cost += 5.0 * (1.0 - mac_full[idx]) * data.has_shape[idx, None]
        dummy = np.full((n, n), 1e9)
        dummy[np.arange(n), np.arange(n)] = np.where(has, 20.0, 3.0)
        rows, cols = linear_sum_assignment(np.hstack([cost, dummy]))
        ok = cols < nm
        pairing[idx[rows[ok]]] = cols[ok]
    return pairing, (proj, mac_full)


def _forward(ctx, data: _Data, effects, spec, sol, pairing):
    """The prediction of a model: the linear one, or that of its effect with a ``forward`` (the registry)."""
    from guidefit.model.effects import EFFECTS, Forward, ForwardRequest, resolve_name

    fm = sol.frequencies_hz
    level_model = np.array([_level_mode(data, pairing, sol, lab) for lab in data.lv_label], dtype=int)
    nonlinear = [e for e in effects if EFFECTS[resolve_name(e.name)].forward is not None]
    if not nonlinear:
        f_pred = np.where(pairing >= 0, fm[np.maximum(pairing, 0)], np.nan)
        lv_pred = np.where(level_model >= 0, fm[np.maximum(level_model, 0)], np.nan)
        return Forward(f_pred, lv_pred, np.zeros(data.f.size), np.zeros(data.lv_f.size))
    if len(nonlinear) > 1:
        raise ModelError("explain: at most one effect with its own forward model per candidate")
    effect = nonlinear[0]
    zetas = np.full(fm.size, np.nan)  # damping of the model modes from their measured partners
    zetas[pairing[pairing >= 0]] = data.mode_zeta[pairing >= 0]
    request = ForwardRequest(
        guide=ctx.guide, spec=spec, solution=sol, parameters=dict(effect.parameters), effects=tuple(effects),
        mode_model=pairing, mode_label=tuple(data.labels), mode_run=tuple(data.mode_run),
        mode_levels=tuple(data.mode_levels), mode_measured_hz=data.f, model_damping=zetas,
        level_model=level_model, levels=data.levels, cache=ctx.cache)
    return EFFECTS[resolve_name(effect.name)].forward(request)


def _evaluate(ctx, data: _Data, effects) -> _Eval:
    from guidefit.model import vibration as vib
    from guidefit.model.effects import apply_effects

    n_r = data.n_data + int(data.has_shape.sum())  # a shape has n_ch residuals for n_ch - 1 dof
    try:
        spec = apply_effects(ctx.spec, ctx.guide, effects) if effects else ctx.spec
        sol = vib.solve_modes(spec)
    except (ModelError, np.linalg.LinAlgError, ValueError):
        n = data.f.size
        return _Eval(np.full(n_r, _BAD), np.full(n, -1), np.full(n, np.nan), np.full(n, np.nan),
                     np.full(data.lv_f.size, np.nan), None, ok=False)
    pairing, proj = _pair(data, sol)
    pred = _forward(ctx, data, effects, spec, sol, pairing)
    f_pred, lv_pred = pred.mode_hz, pred.level_hz
    sigma = np.hypot(data.sigma, pred.mode_std_hz)  # the forward model's own error, in quadrature
    r_f = np.where(pairing >= 0, (f_pred - data.f) / sigma, UNPAIRED_PENALTY)
    r_f = np.nan_to_num(r_f, nan=UNPAIRED_PENALTY)
    blocks = [r_f]
    mac = np.full(data.f.size, np.nan)
    for (idx, m_hat, _, scale), a_set in zip(data.shapes, proj[0]):
        j = pairing[idx]
        ok = j >= 0
        a = a_set[:, np.maximum(j, 0)].T
        block = (m_hat - a * np.sum(a * m_hat, axis=1, keepdims=True)) * scale[:, None]
        block[~ok] = 0.0
        blocks.append(block.ravel())
        mac[idx[ok]] = proj[1][idx[ok], j[ok]]
    r_lv = np.full(data.lv_f.size, UNPAIRED_PENALTY)
    lv_sigma = np.hypot(data.lv_sigma, pred.level_std_hz)
    for g in data.lv_groups:  # the trend within a group: its weighted mean removed (one dof per group)
        d, s = lv_pred[g] - data.lv_f[g], lv_sigma[g]
        w = s ** -2.0
        if np.all(np.isfinite(d)):
            r_lv[g] = (d - np.sum(w * d) / np.sum(w)) / s
    blocks.append(r_lv)
    return _Eval(np.concatenate(blocks), pairing, f_pred, mac, lv_pred, sol)


def _level_mode(data: _Data, pairing, sol, label: str):
    """Model mode that a force level of this label refers to."""
    for i, lab in enumerate(data.labels):
        if lab == label and pairing[i] >= 0:
            return int(pairing[i])
    if label in sol.labels:
        return sol.labels.index(label)
    return -1


# --------------------------------------------------------------------------- candidates


def _level_trend(data: _Data) -> tuple[float, int, float]:
    """(chi2, dof, p) of "the frequency does not change with hit force" over every level group."""
    chi2, dof = 0.0, 0
    for g in data.lv_groups:
        w = data.lv_sigma[g] ** -2.0
        z = (data.lv_f[g] - np.sum(w * data.lv_f[g]) / np.sum(w)) / data.lv_sigma[g]
        chi2 += float(z @ z)
        dof += len(g) - 1
    return chi2, dof, (_p_value(chi2, dof) if dof > 0 else math.nan)


def _variants(guide, data: _Data, names, notes) -> list[Variant]:
    """The candidate library: every registered effect's variants (its ``gate`` may refuse the data)."""
    from guidefit.model.effects import EFFECTS, FitContext, resolve_name

    chi2, dof, p = _level_trend(data)
    ctx = FitContext(guide=guide, extra_frequencies_hz=tuple(float(data.f[i]) for i, lab in enumerate(data.labels)
                                                             if lab is None),
                     n_levels=int(data.lv_f.size), level_trend_chi2=chi2, level_trend_dof=dof, level_trend_p=p)
    out: list[Variant] = []
    for name in names:
        try:
            effect = EFFECTS[resolve_name(name)]
        except ModelError:
            raise ModelError(f"explain: unknown candidate effect '{name}'; have {', '.join(EFFECTS)}") from None
        reason = effect.gate(ctx) if effect.gate is not None else None
        if reason:
            notes.append(f"{effect.name} not tried: {reason}")
            continue
        out += effect.variants(ctx)
    return out


def _compatible(a: Variant, b: Variant) -> bool:
    """Whether two variants may be fitted together: the registry's rule (:func:`~guidefit.model.effects.combinable`)."""
    from guidefit.model.effects import combinable

    return combinable(a.effect, b.effect)


@dataclass
class _Fit:
    variants: tuple
    theta: np.ndarray
    values: list  # physical values per free parameter (flat)
    std: list
    chi2: float
    ev: _Eval
    k: int
    identifiable: list
    at_bound: list


def _effects_of(variants, values) -> list:
    from guidefit.model.effects import Effect

    out, pos = [], 0
    for v in variants:
        params = dict(v.fixed)
        for fr in v.free:
            params[fr.name] = values[pos]
            pos += 1
        out.append(Effect(v.effect, params))
    return out


def _fit(ctx, data: _Data, variants: tuple, starts: list, n_polish: int = 2, max_nfev: int = 60) -> _Fit:
    """Least-squares fit of the free parameters of a combination of variants."""
    from scipy.optimize import least_squares

    free = [fr for v in variants for fr in v.free]
    lo = np.array([fr.bounds[0] for fr in free])
    hi = np.array([fr.bounds[1] for fr in free])

    def decode(theta):
        return [fr.decode(t) for fr, t in zip(free, theta)]

    def fun(theta):
        ctx.n_eval += 1
        return _evaluate(ctx, data, _effects_of(variants, decode(theta))).r

    span = hi - lo
    inner_lo, inner_hi = lo + 1e-6 * span, hi - 1e-6 * span
    scored = []
    for s in starts:
        theta = np.clip([fr.encode(x) for fr, x in zip(free, s)], inner_lo, inner_hi)
        ev = _evaluate(ctx, data, _effects_of(variants, decode(theta)))
        ctx.n_eval += 1
        scored.append((int(np.sum(ev.pairing < 0)), float(ev.r @ ev.r), tuple(theta)))
    scored.sort(key=lambda t: t[:2])
    best = None
    tried = set()
    for _, _, theta0 in scored:
        if len(tried) >= n_polish:
            break
        if theta0 in tried:
            continue
        tried.add(theta0)
        res = least_squares(fun, np.array(theta0), bounds=(lo, hi), method="trf", x_scale=1.0,
                            max_nfev=max_nfev, xtol=1e-10, ftol=1e-10, gtol=1e-10, diff_step=1e-5)
        cost = float(res.fun @ res.fun)
        if best is None or cost < best[0]:
            best = (cost, res)
    cost, res = best
    ev = _evaluate(ctx, data, _effects_of(variants, decode(res.x)))
    chi2 = float(ev.r @ ev.r)
    k = len(free)
    dof = data.n_data - k
    jac = np.asarray(res.jac)
    try:
        cov = np.linalg.pinv(jac.T @ jac) * max(1.0, chi2 / dof if dof > 0 else 1.0)
        std_t = np.sqrt(np.maximum(np.diag(cov), 0.0))
        sv = np.linalg.svd(jac, compute_uv=False)
        if sv.size and sv[-1] <= 1e-8 * max(sv[0], 1e-300):
            std_t = np.where(np.abs(jac).sum(axis=0) > 0, std_t, np.inf)
            std_t = np.full(k, np.inf) if sv[0] == 0 else std_t
    except np.linalg.LinAlgError:
        std_t = np.full(k, np.inf)
    values = decode(res.x)
    std, ident, at_bound = [], [], []
    for fr, t, st, v in zip(free, res.x, std_t, values):
        if fr.kind == "log":
            std.append(v * st if math.isfinite(st) else math.inf)
            ident.append(bool(math.isfinite(st) and st < IDENTIFIABLE_LOG_STD))
        else:
            std.append(fr.scale * st if math.isfinite(st) else math.inf)
            ident.append(bool(math.isfinite(st) and fr.scale * st < 0.25 * (fr.upper - fr.lower)))
        b0, b1 = fr.bounds
        at_bound.append(bool(not fr.bound_is_value and min(t - b0, b1 - t) < 1e-3 * (b1 - b0)))
    return _Fit(tuple(variants), res.x, values, std, chi2, ev, k, ident, at_bound)


def _reduced(fit: _Fit, variants: list):
    """The same combination with a variant whose stiffness went rigid replaced by its simpler form.

    Returns (variants, start values) or None.
    """
    out_variants, out_values, changed, pos = [], [], False, 0
    by_title = {v.title: v for v in variants}
    for v in fit.variants:
        vals = list(fit.values[pos:pos + len(v.free)])
        # a stiffness at (or unidentifiably near) its rigid bound
        sl = slice(pos, pos + len(v.free))
        ups = [fr.name for fr, at, ok, t in zip(v.free, fit.at_bound[sl], fit.identifiable[sl], fit.theta[sl])
               if (at or not ok) and t > 0.5 * sum(fr.bounds)]
        pos += len(v.free)
        target = next((tag for name, tag in v.reduces if name in ups), None)
        simpler = by_title.get(f"{v.effect} ({target})") if target else None
        if simpler is None:
            out_variants.append(v)
            out_values += vals
            continue
        changed = True
        keep = {fr.name: val for fr, val in zip(v.free, vals)}
        out_variants.append(simpler)
        out_values += [keep[fr.name] for fr in simpler.free]
    return (tuple(out_variants), tuple(out_values)) if changed else None


def _fit_pairs(ctx, data: _Data, fits: list, variants: list, bic, progress) -> list:
    """Pairs of effects by forward selection from the three best single effects.

    Every compatible variant is added to each seed and screened by a short
    fit; the six best pairs are refitted fully, and a pair whose stiffness
    went rigid is refitted in its simpler form.
    """
    by_effect: dict = {}
    testable = [f for f in fits if f.k < data.n_data] or fits
    for f in sorted(testable, key=lambda f: round(bic(f), 3)):
        by_effect.setdefault(f.variants[0].effect, []).append(f)
    top = sorted(by_effect.values(), key=lambda fs: round(bic(fs[0]), 3))[:3]
    # each seed effect with its variants that are as good as its best one (at most two)
    seeds = [f for fs in top for f in fs[:2] if bic(f) - bic(fs[0]) < EQUAL_BIC]
    single_of = {f.variants[0].title: f for f in fits}
    # each partner effect with its best PAIR_PARTNER_VARIANTS variants (by their single fits)
    ranked: dict = {}
    for f in sorted(fits, key=lambda f: round(bic(f), 3)):
        ranked.setdefault(f.variants[0].effect, []).append(f.variants[0].title)
    partners = [v for v in variants if v.title in ranked.get(v.effect, [])[:PAIR_PARTNER_VARIANTS]]
    jobs, seen = [], set()
    for seed in seeds:
        for v in partners:
            key = frozenset((seed.variants[0].title, v.title))
            too_many = len(seed.variants[0].free) + len(v.free) > data.n_data
            if _compatible(seed.variants[0], v) and key not in seen and not too_many:
                seen.add(key)
                starts = [tuple(seed.values) + tuple(single_of[v.title].values)]
                starts += [tuple(seed.values) + s for s in _grid_starts(v)]
                jobs.append(((seed.variants[0], v), starts))
    total = len(variants) + len(jobs)
    screened = []
    for n_done, (combo, starts) in enumerate(jobs, start=len(variants) + 1):
        screened.append((_fit(ctx, data, combo, starts, n_polish=1, max_nfev=6), starts))
        if progress is not None:
            progress(n_done, total, " + ".join(v.title for v in combo))
    screened.sort(key=lambda fs: bic(fs[0]))
    out = [f for f, _ in screened[6:]]
    for f, starts in screened[:6]:
        full = _fit(ctx, data, f.variants, [tuple(f.values)] + starts, n_polish=2, max_nfev=80)
        out.append(full)
        red = _reduced(full, variants)
        if red is not None and frozenset(v.title for v in red[0]) not in seen:
            seen.add(frozenset(v.title for v in red[0]))
            out.append(_fit(ctx, data, red[0], [red[1]], n_polish=1, max_nfev=80))
    return out


def _grid_starts(variant: Variant) -> list:
    if variant.starts:
        return [tuple(s) for s in variant.starts]
    import itertools

    return [tuple(p) for p in itertools.product(*[fr.grid for fr in variant.free])]


# --------------------------------------------------------------------------- selection


def _p_value(chi2: float, dof: int) -> float:
    from scipy.special import chdtrc

    return float(chdtrc(dof, chi2)) if dof > 0 else float("nan")


def _param_dict(fit: _Fit) -> list:
    """Effects of a fit as the contract's list of {name, parameters{value, std}}."""
    out, pos = [], 0
    for v in fit.variants:
        params = {}
        for key, val in v.fixed.items():
            params[key] = {"value": val, "std": None, "unit": ""}
        for fr in v.free:
            params[fr.name] = {"value": float(fit.values[pos]), "std": float(fit.std[pos]), "unit": fr.unit,
                               "identifiable": fit.identifiable[pos], "at_bound": fit.at_bound[pos]}
            pos += 1
        out.append({"name": v.effect, "variant": v.tag, "parameters": params})
    return out


def _rms_pct(data: _Data, ev: _Eval) -> tuple[float, list]:
    """RMS relative frequency error (%): paired modes, unpaired ones against the nearest model mode."""
    errs = []
    for i in range(data.f.size):
        if ev.pairing[i] >= 0 and math.isfinite(ev.f_pred[i]):
            errs.append(100.0 * (ev.f_pred[i] - data.f[i]) / data.f[i])
        elif ev.sol is not None:
            fm = ev.sol.frequencies_hz
            j = int(np.argmin(np.abs(np.log(fm / data.f[i]))))
            errs.append(100.0 * (fm[j] - data.f[i]) / data.f[i])
        else:
            errs.append(float("nan"))
    arr = np.array(errs)
    return float(np.sqrt(np.nanmean(arr**2))), errs


def _error_dict(data: _Data, ev: _Eval, chi2: float, k: int, model: str, measured) -> dict:
    rms, errs = _rms_pct(data, ev)
    dof = data.n_data - k
    return {
        "rms_frequency_error_pct": rms,
        "rms_uncertainty_pct": float(100.0 * np.sqrt(np.mean((data.sigma / data.f) ** 2))),
        "chi2": chi2, "n_data": data.n_data, "n_params": k, "dof": dof,
        "p_value": _p_value(chi2, dof),
        "within_uncertainty": bool(dof > 0 and _p_value(chi2, dof) >= ACCEPT_P_VALUE),
        "model": model,
        "per_mode": [{"label": m.label, "run": m.run, "measured_hz": float(fi), "error_pct": e}
                     for m, fi, e in zip(measured, data.f, errs)],
    }


def _n_responsive(data: _Data, nominal: _Eval, ev: _Eval) -> int:
    """How many data the fitted parameters move by more than 3 sigma from the nominal model.

    A measured mode that only the candidate can pair (an extra peak) counts
    twice: its existence and its frequency. A mode shape counts once.
    """
    n = data.f.size
    d = np.abs(ev.r - nominal.r)
    newly = (nominal.pairing < 0) & (ev.pairing >= 0)
    count = int(np.sum(np.where(newly, 2, d[:n] > 3.0)))
    pos = n
    for idx, m_hat, _, _ in data.shapes:
        width = m_hat.shape[1]
        for _ in idx:
            count += int(np.linalg.norm(ev.r[pos:pos + width] - nominal.r[pos:pos + width]) > 3.0)
            pos += width
    return count + int(np.sum(d[pos:] > 3.0))


def _choice_penalty(fit: _Fit, choices: dict) -> float:
    """2 ln N per effect that chose among N discrete variants (a uniform prior over them)."""
    return float(sum(2.0 * math.log(max(1, choices.get(v.effect, 1))) for v in fit.variants))


def _bic(fit: _Fit, data: _Data, choices: dict) -> float:
    """BIC = chi2 + k ln n + 2 ln N_choices: the discrete choices counted (docs/explain.md)."""
    return fit.chi2 + fit.k * math.log(data.n_data) + _choice_penalty(fit, choices)


def _effect_refusals(fit: _Fit, data: _Data) -> list:
    """Reasons of the effects' own ``accept`` rules (e.g. no predicted trend over force levels)."""
    from guidefit.model.effects import EFFECTS, resolve_name

    out = []
    for v in fit.variants:
        rule = EFFECTS[resolve_name(v.effect)].accept
        if rule is not None and fit.ev.ok:
            reason = rule(data.levels, fit.ev.lv_pred)
            if reason:
                out.append(f"{v.effect}: {reason}")
    return out


def _candidate_entry(fit: _Fit, data: _Data, bic_min: float, nominal: _Eval, choices: dict) -> dict:
    dof = data.n_data - fit.k
    p = _p_value(fit.chi2, dof)
    problems = []
    n_resp = _n_responsive(data, nominal, fit.ev)
    if dof <= 0:
        problems.append(f"not identifiable from these data ({data.n_data} data, {fit.k} parameters)")
    elif n_resp <= fit.k and len(fit.variants) > 1:
        problems.append(f"not identifiable from these data: only {n_resp} data respond to its {fit.k} "
                        "parameters, which fit them by construction")
    bad = []
    pos = 0
    for v in fit.variants:
        for fr in v.free:
            if not fit.identifiable[pos] or fit.at_bound[pos]:
                bad.append(f"{v.effect}.{fr.name}" + (" at its bound" if fit.at_bound[pos] else ""))
            pos += 1
    if bad and dof > 0:
        problems.append("not identifiable: " + ", ".join(bad))
    within = dof > 0 and p >= ACCEPT_P_VALUE
    if dof > 0 and not within:
        problems.append(f"misfit beyond uncertainty (chi2 {fit.chi2:.1f} for {dof} dof)")
    combination_ok = len(fit.variants) == 1 or n_resp > fit.k
    refused = _effect_refusals(fit, data)
    problems += refused
    accepted = within and not bad and combination_ok and not refused
    if accepted and n_resp <= fit.k:
        problems.append(f"within uncertainty; it moves {n_resp} data with {fit.k} parameter(s), the data it "
                        "leaves unchanged are its test")
    bic = _bic(fit, data, choices)
    return {
        "name": "+".join(v.effect for v in fit.variants),
        "variant": " + ".join(v.title for v in fit.variants),
        "effects": _param_dict(fit),
        "parameters": {f"{e['name']}.{k}": v for e in _param_dict(fit) for k, v in e["parameters"].items()},
        "n_params": fit.k, "n_choices": int(round(math.exp(_choice_penalty(fit, choices) / 2))),
        "n_responsive": n_resp, "chi2": fit.chi2, "dof": dof, "p_value": p, "bic": bic,
        "delta_bic": bic - bic_min,
        "rms_frequency_error_pct": _rms_pct(data, fit.ev)[0],
        "accepted": bool(accepted),
        "note": "; ".join(problems) if problems else "within uncertainty",
    }


def _fmt_effect(entry: dict) -> str:
    parts = []
    for eff in entry["effects"]:
        ps = []
        for k, p in eff["parameters"].items():
            val = p["value"]
            ps.append(f"{k}={val:.3g}" if isinstance(val, float) else f"{k}={val}")
        parts.append(f"{eff['name']}({', '.join(ps)})")
    return " + ".join(parts)


def _equal_notes(best: dict, others: list, what: str) -> list:
    """Notes naming models within EQUAL_BIC of the best one."""
    if not others:
        return []
    names = [best["variant"]] + [e["variant"] for e in others]
    gap = max(0.0, max(e["bic"] - best["bic"] for e in others))
    same = all(e["name"] == best["name"] for e in others)
    out = [f"{' and '.join(names)} {what} (delta BIC {gap:.1f})"
           + ("" if same else "; the data cannot tell these effects apart")]
    corners = [n for n in names if n in {f"added_mass (at {c})" for c in "ABCD"}]
    if len(corners) > 1:
        out.append("a mass at A, B, C or D gives identical frequencies (mirror symmetry); "
                   "only mode shapes at A-D tell which corner")
    return out


def _trend_notes(data: _Data) -> list:
    """Weighted straight-line trend of frequency with hit force, per (run, label) group."""
    out = []
    for g in data.lv_groups:
        idx, lab = list(g), data.lv_label[g[0]]
        x, y, s = data.lv_force[idx], data.lv_f[idx], data.lv_sigma[idx]
        w = 1.0 / s**2
        xm = np.sum(w * x) / np.sum(w)
        sxx = np.sum(w * (x - xm) ** 2)
        if sxx <= 0:
            continue
        slope = np.sum(w * (x - xm) * y) / sxx
        z = slope * math.sqrt(sxx)
        drop = 100.0 * slope * (x.max() - x.min()) / np.average(y, weights=w)
        run = data.lv_run[g[0]]
        out.append(f"{lab}{f' ({run} run)' if run else ''}: frequency changes {drop:+.2f} % from {x.min():.0f} N to {x.max():.0f} N "
                   f"({abs(z):.1f} sigma{', significant' if abs(z) > 3 else ''})")
    return out


class _Ctx:
    def __init__(self, guide, spec):
        self.guide = guide
        self.spec = spec
        self.n_eval = 0
        self.cache: dict = {}  # forward models' scratch space for one explain call


def explain_modes(measured, guide, sensors=(), force_levels=(), candidates=None, progress=None,
                  source: str | None = None, notes=(), *, drop_unproduced_extras: bool = True) -> Explanation:
    """Pair measured modes with the model, fit candidate effects and select the explanation.

    Parameters
    ----------
    measured : list of MeasuredMode
        Identified modes (frequency, uncertainty, optional label, shape, run).
    guide : str or Guide
        Catalogue name (``"MRB35"``), guide file or :class:`~guidefit.model.guides.Guide`.
    sensors : list of Sensor, optional
        Positions and directions of the shape channels; channels named
        ``acc_<point>_<axis>`` default to the guide's measuring points.
    force_levels : list of ForceLevel, optional
        Frequency per hit-force bin; needed by ``amplitude_dependence``.
    candidates : list of str, optional
        Effect names to try (default: every effect of
        :data:`guidefit.model.effects.EFFECTS`).
    progress : callable, optional
        Called as ``progress(done, total, name)`` after each candidate.
    source : str, optional
        Where the modes came from (the ``file`` of the JSON result).
    notes : list of str, optional
        Notes of the caller to carry into the result.
    drop_unproduced_extras : bool
        When nothing explains the data and some unlabelled modes (extra
        peaks) have no partner in the nominal model, try once more without
        them (see "Extra peaks" in the module documentation).

    Returns
    -------
    Explanation

    Raises
    ------
    RecordingError
        Malformed measured data (names the mode and field).
    ModelError
        Unknown candidate effect.

    Examples
    --------
    >>> from guidefit.model.guides import load_guide
    >>> from guidefit.model.vibration import model_from_guide, solve_modes
    >>> sol = solve_modes(model_from_guide(load_guide("MRB35")))
    >>> modes = [MeasuredMode(f * 1.0004, 0.001 * f, label=lab) for lab, f in zip(sol.labels, sol.frequencies_hz)]
    >>> result = explain_modes(modes, "MRB35", candidates=["contact_stiffness"])
    >>> result.verdict, result.effects
    ('adequate', ())
    """
    from guidefit.model import vibration as vib
    from guidefit.model.effects import EFFECTS
    from guidefit.model.guides import Guide, load_guide

    guide = guide if isinstance(guide, Guide) else load_guide(guide)
    measured = list(measured)
    sensors = list(sensors or ())
    force_levels = list(force_levels or ())
    unreproduced = _unreproduced(measured, force_levels)
    if unreproduced and len(unreproduced) < len(measured):
        return _without_unreproduced(measured, unreproduced, guide, sensors, force_levels, candidates, progress,
                                     source, notes, drop_unproduced_extras)
    caller_notes = tuple(notes)
    notes = list(notes)
    data = _prepare(measured, guide, sensors, force_levels, notes)
    ctx = _Ctx(guide, vib.model_from_guide(guide))
    names = list(EFFECTS) if candidates is None else list(candidates)
    variants = _variants(guide, data, names, notes)
    choices: dict = {}
    for v in variants:
        choices[v.effect] = choices.get(v.effect, 0) + 1

    nominal = _evaluate(ctx, data, [])
    chi2_0 = float(nominal.r @ nominal.r)
    p0 = _p_value(chi2_0, data.n_data)
    nominal_fit = _Fit((), np.zeros(0), [], [], chi2_0, nominal, 0, [], [])

    # single effects
    total = len(variants)
    fits: list[_Fit] = []
    skipped = [v.title for v in variants if len(v.free) > data.n_data]
    if skipped:
        notes.append(f"not fitted (more parameters than the {data.n_data} data): {', '.join(skipped)}")
    variants = [v for v in variants if len(v.free) <= data.n_data]
    for done, v in enumerate(variants, start=1):
        fits.append(_fit(ctx, data, (v,), _grid_starts(v)))
        if progress is not None:
            progress(done, total, v.title)
    def bic(fit):
        return _bic(fit, data, choices)

    def entry(fit):
        return _candidate_entry(fit, data, 0.0, nominal, choices)

    singles_ok = [f for f in fits if entry(f)["accepted"]]
    pairs_tried = False
    if p0 < ACCEPT_P_VALUE and not singles_ok and data.n_data >= 2:
        pairs_tried = True
        fits += _fit_pairs(ctx, data, fits, variants, bic, progress)

    bic_min = min([bic(nominal_fit)] + [bic(f) for f in fits])
    entries = [(f, _candidate_entry(f, data, bic_min, nominal, choices)) for f in fits]
    nominal_entry = {"name": "nominal", "variant": "nominal", "effects": [], "n_params": 0, "chi2": chi2_0,
                     "dof": data.n_data, "p_value": p0, "bic": chi2_0, "delta_bic": chi2_0 - bic_min,
                     "rms_frequency_error_pct": _rms_pct(data, nominal)[0],
                     "accepted": bool(p0 >= ACCEPT_P_VALUE),
                     "note": "within uncertainty" if p0 >= ACCEPT_P_VALUE else
                     f"misfit beyond uncertainty (chi2 {chi2_0:.1f} for {data.n_data} dof)"}
    entries.sort(key=lambda fe: round(fe[1]["bic"], 3))  # stable: ties keep the library's order
    ranked = [nominal_entry] + [e for _, e in entries]
    ranked.sort(key=lambda e: round(e["bic"], 3))

    # nominal pairing facts
    for i in np.flatnonzero(nominal.pairing < 0):
        notes.append(f"measured mode at {data.f[i]:.1f} Hz ({measured[i].label or 'unlabelled'}) has no partner "
                     "in the nominal model: an extra peak (evidence for a base or rail body, base_mode)")
    observed = set(nominal.pairing[nominal.pairing >= 0].tolist())
    missing = [f"{lab} {f:.0f} Hz" for j, (lab, f) in enumerate(zip(nominal.sol.labels, nominal.sol.frequencies_hz))
               if j not in observed]
    if missing:
        notes.append("model modes not observed (no residual): " + ", ".join(missing))
    notes += _trend_notes(data)

    alternatives, best_attempt = [], None
    if p0 >= ACCEPT_P_VALUE:
        verdict = "adequate"
        notes.insert(0, f"the nominal model agrees within uncertainty (chi2 {chi2_0:.1f} for {data.n_data} data, "
                        f"p = {p0:.2f}); no effect is claimed")
        better = [e for _, e in entries if e["accepted"] and e["bic"] < chi2_0 - 10.0]
        if better:
            notes.append(f"{better[0]['variant']} would lower the BIC by {chi2_0 - better[0]['bic']:.1f}, "
                         "but the nominal model needs no effect; not claimed")
        after_fit, after_entry = nominal_fit, nominal_entry
    else:
        accepted = [(f, e) for f, e in entries if e["accepted"]]
        if accepted:
            verdict = "explained"
            n_min = min(len(f.variants) for f, _ in accepted)
            simplest = [(f, e) for f, e in accepted if len(f.variants) == n_min]  # entries are BIC-ranked
            after_fit, after_entry = simplest[0]
            alternatives = [e for _, e in simplest[1:] if e["bic"] - after_entry["bic"] < EQUAL_BIC]
            notes.insert(0, f"explained by {_fmt_effect(after_entry)}: chi2 {after_entry['chi2']:.1f} for "
                            f"{after_entry['dof']} dof (p = {after_entry['p_value']:.2f}); nominal chi2 "
                            f"{chi2_0:.1f}")
            notes += _equal_notes(after_entry, alternatives, "explain the data equally well")
        else:
            verdict = "unexplained"
            testable = [(f, e) for f, e in entries if e["dof"] > 0]
            after_fit, after_entry = (testable or entries or [(nominal_fit, nominal_entry)])[0]
            best_attempt = dict(after_entry, accepted=False)
            alternatives = [dict(e, accepted=False) for _, e in testable[1:]
                            if e["bic"] - after_entry["bic"] < EQUAL_BIC]
            notes.insert(0, "no candidate brings the model within uncertainty with identifiable parameters; "
                            f"best attempt (not accepted): {_fmt_effect(after_entry)}, chi2 {after_entry['chi2']:.1f} "
                            f"for {after_entry['dof']} dof ({after_entry['note']}); nominal chi2 {chi2_0:.1f}")
            notes += _equal_notes(after_entry, alternatives, "are equally good (not accepted) attempts")
            order = {id(f): k for k, f in enumerate(fits)}
            exact = [(order[id(f)], e) for f, e in entries
                     if e["dof"] <= 0 and e["chi2"] < max(1.0, 1e-3 * after_entry["chi2"])]
            exact.sort(key=lambda oe: (after_entry["variant"] not in oe[1]["variant"], oe[1]["n_params"], oe[0]))
            first: dict = {}
            for _, e in exact:  # one per effect combination
                first.setdefault(e["name"], e)
            exact = list(first.values())
            if exact:
                notes.append(f"models with as many parameters as data ({data.n_data}) fit exactly "
                             "but are not identifiable from these data, e.g. "
                             + "; ".join(_fmt_effect(e) for e in exact[:4]))
            if not pairs_tried and data.n_data >= 2:
                notes.append("pairs of effects were not tried")
    if verdict != "adequate":
        unident = [e for _, e in entries if "not identifiable: " in e["note"] and e["chi2"] <= after_entry["chi2"]
                   and e["dof"] > 0]
        for e in unident[:3]:
            notes.append(f"{e['variant']}: {e['note'].split('; ')[0]} (not supported, not excluded)")
    # per-mode table
    after = after_fit.ev
    modes_out = []
    for i, m in enumerate(measured):
        jb, ja = int(nominal.pairing[i]), int(after.pairing[i])
        modes_out.append({
            "label": m.label if m.label is not None else (nominal.sol.labels[jb] if jb >= 0 else "extra"),
            "run": m.run, "measured_hz": float(data.f[i]),
            "measured_std_hz": None if m.frequency_std_hz is None else float(m.frequency_std_hz),
            "identified_hz": float(m.frequency_hz),
            "sigma_hz": float(data.sigma[i]),
            "model_before_hz": float(nominal.f_pred[i]) if jb >= 0 else None,
            "model_before_label": nominal.sol.labels[jb] if jb >= 0 else None,
            "model_after_hz": float(after.f_pred[i]) if ja >= 0 else None,
            "model_after_label": after.sol.labels[ja] if ja >= 0 and after.sol is not None else None,
            "error_before_pct": (100.0 * (nominal.f_pred[i] - data.f[i]) / data.f[i]) if jb >= 0 else None,
            "error_after_pct": (100.0 * (after.f_pred[i] - data.f[i]) / data.f[i]) if ja >= 0 else None,
            "mac_before": None if math.isnan(nominal.mac[i]) else float(nominal.mac[i]),
            "mac_after": None if math.isnan(after.mac[i]) else float(after.mac[i]),
            "status": "paired" if ja >= 0 else "extra",
        })
    after_model = {"adequate": "nominal", "explained": "selected",
                   "unexplained": "best attempt (not accepted)"}[verdict]
    err_before = _error_dict(data, nominal, chi2_0, 0, "nominal", measured)
    err_after = _error_dict(data, after, after_fit.chi2, after_fit.k, after_model, measured)
    effects_out = tuple(after_entry["effects"]) if verdict == "explained" else ()
    settings = {"frequency_floor_pct": 100 * FREQUENCY_FLOOR, "default_frequency_std_pct": 100 * DEFAULT_FREQUENCY_STD,
                "default_shape_std_pct": 100 * DEFAULT_SHAPE_STD, "accept_p_value": ACCEPT_P_VALUE,
                "equal_bic": EQUAL_BIC, "unpaired_penalty_sigma": UNPAIRED_PENALTY, "score": "BIC = chi2 + k ln n",
        "force_level_floor_pct": 100 * FORCE_LEVEL_FLOOR,
                "estimated_shape_std_floor_pct": 100 * ESTIMATED_SHAPE_STD_FLOOR,
                "amplitude_model_form": AMPLITUDE_MODEL_FORM,
                "model_evaluations": ctx.n_eval}
    result = Explanation(
        verdict=verdict, guide=guide.name, error_before=err_before, error_after=err_after,
        effects=effects_out, candidates=tuple(ranked), modes=tuple(modes_out), notes=tuple(notes),
        source=source, best_attempt=best_attempt, alternatives=tuple(alternatives), n_data=data.n_data,
        settings=settings, fitted_effects=tuple(_effects_of(after_fit.variants, after_fit.values)),
    )
    extras = [i for i in range(data.f.size) if data.labels[i] is None and nominal.pairing[i] < 0]
    if verdict == "unexplained" and extras and drop_unproduced_extras and len(extras) < data.f.size:
        return _without_extras(result, measured, extras, guide, sensors, force_levels, candidates, progress,
                               source, caller_notes)
    return result


def _unreproduced(measured, force_levels) -> list:
    """Modes whose frequency the hits of their force bins do not reproduce.

    identify refits every mode on the hits of each force bin; a level
    without a frequency means the refit moved the pole by more than the
    mode's half-power half-bandwidth (``zeta f``) or failed. A mode with such
    levels and fewer than two good ones (a weak mode on the flank of a
    strong, amplitude-dependent neighbour: pitch in a lateral run next to
    the 10 %-damped roll_low) has an all-hits frequency that depends on which
    hits are averaged by more than its bandwidth; its fit standard deviation
    (a few Hz) does not say so.
    """
    good: dict = {}
    bad: set = set()
    for lv in force_levels:
        if not isinstance(lv, ForceLevel):
            continue
        key = (lv.run, _canonical(lv.label))
        if lv.frequency_hz is None:
            bad.add(key)
        else:
            good[key] = good.get(key, 0) + 1
    return [i for i, m in enumerate(measured) if isinstance(m, MeasuredMode)
            and (m.run, _canonical(m.label)) in bad and good.get((m.run, _canonical(m.label)), 0) < 2]


def _left_out_row(mode) -> dict:
    """The result row of a measured mode left out of the explanation (no model pairing, no error)."""
    return {"label": mode.label or "extra", "run": mode.run, "measured_hz": float(mode.frequency_hz),
            "measured_std_hz": mode.frequency_std_hz, "identified_hz": float(mode.frequency_hz),
            "sigma_hz": None, "model_before_hz": None, "model_before_label": None, "model_after_hz": None,
            "model_after_label": None, "error_before_pct": None, "error_after_pct": None,
            "mac_before": None, "mac_after": None, "status": "left out"}


def _without_unreproduced(measured, drop, guide, sensors, force_levels, candidates, progress, source, notes,
                          drop_unproduced_extras) -> Explanation:
    """Explain without the modes of :func:`_unreproduced`; they are listed with status ``left out``."""
    from dataclasses import replace

    keep = [m for i, m in enumerate(measured) if i not in set(drop)]
    text = ", ".join(f"{measured[i].label} ({measured[i].run} run) {measured[i].frequency_hz:.1f} Hz" for i in drop)
    note = (f"left out: {text}: the hits of its force bins do not reproduce it (identify's refit moved it by more "
            "than its half-power half-bandwidth), so its frequency depends on which hits are averaged")
    sub = explain_modes(keep, guide, sensors, force_levels, candidates=candidates, progress=progress,
                        source=source, notes=(*notes, note), drop_unproduced_extras=drop_unproduced_extras)
    left = [_left_out_row(measured[i]) for i in drop]
    return replace(sub, modes=tuple(sub.modes) + tuple(left),
                   settings={**sub.settings, "left_out_unreproduced_hz": [float(measured[i].frequency_hz)
                                                                          for i in drop]})


def _without_extras(result, measured, extras, guide, sensors, force_levels, candidates, progress, source,
                    notes) -> Explanation:
    """Explain again without unlabelled extra peaks that no accepted model produces.

    An extra peak of the modal fit is weak evidence: real (a base body, which
    ``base_mode`` would then have explained) or a fit artefact, e.g. a
    carriage mode whose frequency sweeps with amplitude fitted by two poles.
    If an effect explains every other datum, it is named, and the extra
    peaks are listed as not explained by it.
    """
    from dataclasses import replace

    keep = [m for i, m in enumerate(measured) if i not in set(extras)]
    sub = explain_modes(keep, guide, sensors, force_levels, candidates=candidates, progress=progress,
                        source=source, notes=(), drop_unproduced_extras=False)
    if sub.verdict != "explained":
        return result
    text = ", ".join(f"{measured[i].frequency_hz:.1f} Hz" for i in extras)
    note = (f"extra peak(s) at {text} (unlabelled) left out: no candidate produces them together with the "
            "carriage modes; the effect below explains everything else (the peaks are a fit artefact, e.g. an "
            "amplitude-dependent peak fitted by two poles, or a cause outside the library)")
    ignored = [_left_out_row(measured[i]) for i in extras]
    return replace(sub, notes=(note, *sub.notes, *notes), modes=tuple(sub.modes) + tuple(ignored),
                   settings={**sub.settings, "left_out_extra_hz": [float(measured[i].frequency_hz) for i in extras]})


# --------------------------------------------------------------------------- synthetic data


def default_sensors(guide, axes: str = "xy") -> list:
    """Accelerometers at the guide's measuring points along the given axes (``acc_A_x``, ...).

    >>> from guidefit.model.guides import load_guide
    >>> [s.name for s in default_sensors(load_guide("MRB35"), "y")]
    ['acc_A_y', 'acc_B_y', 'acc_C_y', 'acc_D_y']
    """
    unit = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}
    return [Sensor(f"acc_{p}_{a}", tuple(pos), unit[a]) for p, pos in guide.measuring_points_m.items() for a in axes]


def synthetic_modes(guide, effects=(), sensors=None, frequency_std: float = 1e-3, shape_std: float | None = 0.01,
                    seed: int = 0, forces=(), solution=None):
    """Measured modes with known truth: the model with effects, plus noise.

    Parameters
    ----------
    guide : str or Guide
    effects : list of Effect or "NAME:param=value" strings
        Applied with :func:`guidefit.model.effects.apply_effects`;
        ``amplitude_dependence`` also makes the frequency fall with ``forces``.
    sensors : list of Sensor, optional
        Default :func:`default_sensors` (A-D, x and y).
    frequency_std : float
        Relative standard deviation of the frequency noise (and the one reported).
    shape_std : float or None
        Relative per-channel shape noise; None: no shapes.
    seed : int
    forces : sequence of float
        Peak forces (N) of force levels for the vertical and roll_low modes; none by default.
    solution : ModalSolution, optional
        Use these modes instead of solving the model (cases outside the library).

    Returns
    -------
    (list of MeasuredMode, list of Sensor, list of ForceLevel)
        Modes that the model labels ``support_*`` come unlabelled (an extra peak).

    Examples
    --------
    >>> modes, sensors, levels = synthetic_modes("MRB35", ["contact_stiffness:factor=0.81"], seed=1)
    >>> [m.label for m in modes]
    ['yaw', 'pitch', 'roll_low', 'vertical', 'roll_high']
    """
    from guidefit.model import vibration as vib
    from guidefit.model.effects import Effect, apply_effects, make_effect, parse_effect
    from guidefit.model.effects.amplitude_dependence import amplitude_frequency, roller_modal
    from guidefit.model.guides import Guide, load_guide

    guide = guide if isinstance(guide, Guide) else load_guide(guide)
    effects = [parse_effect(e) if isinstance(e, str) else make_effect(e.name, e.parameters) if isinstance(
        e, Effect) else make_effect(*e) for e in effects]
    sensors = default_sensors(guide) if sensors is None else list(sensors)
    rng = np.random.default_rng(seed)
    spec = apply_effects(vib.model_from_guide(guide), guide, effects)
    sol = vib.solve_modes(spec) if solution is None else solution
    amp = next((e.parameters["preload_factor"] for e in effects if e.name == "amplitude_dependence"), None)
    forces = [float(f) for f in forces]
    c_all = roller_modal(spec, sol) if amp is not None and solution is None else None
    levels = []

    def freq_at(j, label, force):
        if amp is None or c_all is None:
            return float(sol.frequencies_hz[j])
        point, direction = DEFAULT_HITS[label]
        return amplitude_frequency(guide, spec, sol, j, force, (point, np.asarray(direction, float),
                                                                DEFAULT_PULSE_S), amp, c_all)

    labels = list(sol.labels)
    for lab in ("vertical", "roll_low") if forces else ():
        j = labels.index(lab)
        for force in forces:
            f = freq_at(j, lab, force)
            levels.append(ForceLevel(force, lab, f * (1 + frequency_std * rng.standard_normal()), frequency_std * f))
    w2 = np.square(forces)
    modes = []
    for j, lab in enumerate(labels):
        if forces and lab in ("vertical", "roll_low"):  # H1 over all hits: the F^2-weighted mean
            f = float(np.sum(w2 * [freq_at(j, lab, force) for force in forces]) / np.sum(w2))
        else:
            f = float(sol.frequencies_hz[j])
        shape = None
        if shape_std is not None and sensors:
            a = np.array([np.asarray(sn.direction, float) @ vib.rigid_body_map(sn.position_m) @ sol.shapes[:5, j]
                          for sn in sensors])
            a = a + shape_std * np.linalg.norm(a) / math.sqrt(a.size) * rng.standard_normal(a.size)
            shape = {sn.name: float(x) for sn, x in zip(sensors, a)}
        modes.append(MeasuredMode(f * (1 + frequency_std * rng.standard_normal()), frequency_std * f,
                                  label=None if lab.startswith("support") else lab, shape=shape,
                                  shape_std=shape_std))
    return modes, sensors, levels


# --------------------------------------------------------------------------- reading modes


def _number(value, what: str, positive: bool = True, allow_none: bool = False):
    if value is None and allow_none:
        return None
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value) \
            or (positive and value <= 0):
        kind = "a positive number" if positive else "a finite number"
        raise RecordingError(f"{what} must be {kind}{' or null' if allow_none else ''}, got {value!r}")
    return float(value)


def _vector3(value, what: str) -> tuple:
    if not isinstance(value, list | tuple) or len(value) != 3:
        raise RecordingError(f"{what} must be a list of 3 numbers, got {value!r}")
    return tuple(_number(v, what, positive=False) for v in value)


def _shape(value, what: str) -> dict | None:
    if value is None:
        return None
    if not isinstance(value, dict):
        raise RecordingError(f"{what} must be an object of channel: amplitude, got {type(value).__name__}")
    out = {}
    for name, v in value.items():
        if isinstance(v, list | tuple) and len(v) == 2:
            out[str(name)] = complex(_number(v[0], f"{what} '{name}'", positive=False),
                                     _number(v[1], f"{what} '{name}'", positive=False))
        elif isinstance(v, dict) and set(v) <= {"re", "im"}:
            out[str(name)] = complex(_number(v.get("re", 0.0), f"{what} '{name}'", positive=False),
                                     _number(v.get("im", 0.0), f"{what} '{name}'", positive=False))
        else:
            out[str(name)] = complex(_number(v, f"{what} '{name}'", positive=False))
    return out


def _std_of(entry: dict, what: str):
    for key in ("frequency_std_hz", "std_hz", "std"):
        if key in entry:
            return _number(entry[key], f"{what}: '{key}'", allow_none=True)
    return None


def _mode_from(entry, what: str, default_label: str | None = None) -> MeasuredMode:
    if not isinstance(entry, dict):
        raise RecordingError(f"{what}: expected an object, got {type(entry).__name__}")
    if "frequency_hz" not in entry:
        raise RecordingError(f"{what}: 'frequency_hz' missing")
    label = entry.get("label", default_label)
    if label is not None and not isinstance(label, str):
        raise RecordingError(f"{what}: 'label' must be a string, got {label!r}")
    run = entry.get("run")
    return MeasuredMode(
        frequency_hz=_number(entry["frequency_hz"], f"{what}: 'frequency_hz'"),
        frequency_std_hz=_std_of(entry, what),
        damping_ratio=_number(entry.get("damping_ratio"), f"{what}: 'damping_ratio'", positive=False,
                              allow_none=True),
        label=label,
        shape=_shape(entry.get("shape"), f"{what}: 'shape'"),
        run=None if run is None else str(run),
        shape_std=_number(entry.get("shape_std"), f"{what}: 'shape_std'", allow_none=True),
    )


def _level_from(entry, what: str) -> ForceLevel:
    if not isinstance(entry, dict):
        raise RecordingError(f"{what}: expected an object, got {type(entry).__name__}")
    for key in ("peak_force_n", "label", "frequency_hz"):
        if key not in entry:
            raise RecordingError(f"{what}: '{key}' missing")
    if _canonical(entry["label"]) is None:
        raise RecordingError(f"{what}: 'label' must be one of {', '.join(CARRIAGE_LABELS)}, got {entry['label']!r}")
    pos, direction = entry.get("hit_position_m"), entry.get("hit_direction")
    forces, band = entry.get("hit_forces_n"), entry.get("band_hz")
    if forces is not None and (not isinstance(forces, list) or not forces):
        raise RecordingError(f"{what}: 'hit_forces_n' must be a list of positive numbers, got {forces!r}")
    if band is not None and (not isinstance(band, list) or len(band) != 2):
        raise RecordingError(f"{what}: 'band_hz' must be [low, high], got {band!r}")
    # frequency_hz null: identify's refit of the bin's hits did not reproduce the mode
    return ForceLevel(
        peak_force_n=_number(entry["peak_force_n"], f"{what}: 'peak_force_n'"),
        label=str(entry["label"]),
        frequency_hz=_number(entry["frequency_hz"], f"{what}: 'frequency_hz'", allow_none=True),
        frequency_std_hz=None if entry["frequency_hz"] is None else _std_of(entry, what),
        hit_forces_n=None if forces is None else tuple(_number(x, f"{what}: 'hit_forces_n'") for x in forces),
        band_hz=None if band is None else tuple(_number(x, f"{what}: 'band_hz'") for x in band),
        shape=_shape(entry.get("shape"), f"{what}: 'shape'"),
        hit_position_m=None if pos is None else _vector3(pos, f"{what}: 'hit_position_m'"),
        hit_direction=None if direction is None else _vector3(direction, f"{what}: 'hit_direction'"),
        pulse_s=_number(entry.get("pulse_s"), f"{what}: 'pulse_s'", allow_none=True),
        run=None if entry.get("run") is None else str(entry["run"]),
    )


def modes_from_result(obj, where: str = "modes"):
    """Measured modes, guide name, sensors and force levels from a parsed result.

    ``obj`` is an ``identify --json`` object (``modes`` with label,
    frequency_hz, damping_ratio and optional frequency_std_hz, shape, run;
    optional ``extra_modes``, ``sensors``, ``force_levels`` and
    ``parameters`` f_V/f_H, whose value and std complete the vertical and
    roll_low modes), an object with just ``modes``, or a plain list of modes.
    Standard deviations may be named ``frequency_std_hz``, ``std_hz`` or ``std``.

    Examples
    --------
    >>> modes, guide, sensors, levels = modes_from_result(
    ...     [{"label": "vertical", "frequency_hz": 3450.0, "std_hz": 0.8}])
    >>> modes[0].frequency_std_hz, guide
    (0.8, None)
    """
    if isinstance(obj, list):
        root, entries = {}, obj
    elif isinstance(obj, dict):
        root, entries = obj, obj.get("modes", [])
        if not isinstance(entries, list):
            raise RecordingError(f"{where}: 'modes' must be a list")
    else:
        raise RecordingError(f"{where}: expected a list of modes or an object with 'modes', got {type(obj).__name__}")
    modes = [_mode_from(e, f"{where}: modes entry {k}") for k, e in enumerate(entries)]
    extras = root.get("extra_modes") or []
    if not isinstance(extras, list):
        raise RecordingError(f"{where}: 'extra_modes' must be a list")
    modes += [_mode_from(e, f"{where}: extra_modes entry {k}", "extra") for k, e in enumerate(extras)]
    params = root.get("parameters") or {}
    if not isinstance(params, dict):
        raise RecordingError(f"{where}: 'parameters' must be an object")
    for key, label in (("f_V", "vertical"), ("f_H", "roll_low")):
        p = params.get(key)
        if not isinstance(p, dict) or p.get("value") is None:
            continue
        value = _number(p["value"], f"{where}: parameters '{key}' value")
        std = _number(p.get("std"), f"{where}: parameters '{key}' std", allow_none=True)
        same = [k for k, m in enumerate(modes) if _canonical(m.label) == label]
        if not same:
            modes.append(MeasuredMode(value, std, label=label))
        elif std is not None:
            for k in same:
                if modes[k].frequency_std_hz is None and abs(modes[k].frequency_hz - value) <= 1e-6 * value:
                    m = modes[k]
                    modes[k] = MeasuredMode(m.frequency_hz, std, m.damping_ratio, m.label, m.shape, m.run,
                                            m.shape_std)
    if not modes:
        raise RecordingError(f"{where}: no modes")
    guide = root.get("guide")
    if guide is not None and not isinstance(guide, str):
        raise RecordingError(f"{where}: 'guide' must be a string, got {guide!r}")
    sensors = []
    for k, s in enumerate(root.get("sensors") or []):
        what = f"{where}: sensors entry {k}"
        if not isinstance(s, dict) or "name" not in s:
            raise RecordingError(f"{what}: expected an object with name, position_m, direction")
        d = np.asarray(_vector3(s.get("direction"), f"{what}: 'direction'"))
        if not np.linalg.norm(d) > 0:
            raise RecordingError(f"{what}: 'direction' must not be zero")
        sensors.append(Sensor(str(s["name"]), _vector3(s.get("position_m"), f"{what}: 'position_m'"),
                              tuple(d / np.linalg.norm(d))))
    levels = [_level_from(e, f"{where}: force_levels entry {k}") for k, e in enumerate(root.get("force_levels") or [])]
    return modes, guide, sensors, levels


def read_modes_json(path):
    """Read identified modes from JSON: ``identify --json`` output or a hand-written list.

    Accepts one JSON document (a list of modes, or an object with ``modes``)
    or JSON Lines holding exactly one object (``identify FILE --json``).

    Returns
    -------
    (list of MeasuredMode, guide name or None, list of Sensor, list of ForceLevel)

    Raises
    ------
    RecordingError
        One line naming the file and the entry at fault.

    Examples
    --------
    >>> import json, tempfile, os
    >>> with tempfile.NamedTemporaryFile("w", suffix=".json", delete=False) as fh:
    ...     json.dump([{"label": "vertical", "frequency_hz": 3450.0, "std_hz": 0.8},
    ...                {"label": "roll_low", "frequency_hz": 1075.0, "std_hz": 0.9}], fh)
    >>> modes, guide, sensors, levels = read_modes_json(fh.name)
    >>> [(m.label, m.frequency_hz) for m in modes]
    [('vertical', 3450.0), ('roll_low', 1075.0)]
    >>> os.remove(fh.name)
    """
    from guidefit.jsonio import read_json_documents

    p = Path(path)
    docs = read_json_documents(p)
    if len(docs) != 1:
        raise RecordingError(f"{p}: {len(docs)} JSON lines (one per recording); explain takes one")
    obj = docs[0]
    return modes_from_result(obj, str(p))


# --------------------------------------------------------------------------- entry points


def explain_identification(identification, candidates=None, progress=None) -> Explanation:
    """Explain the modes of an :class:`~guidefit.identify.Identification` (modes, extra modes,
    sensors and force levels of its JSON form)."""
    data = identification.to_dict()
    where = str(identification.file)
    raw_levels = data.pop("force_levels", None) or []
    modes, _, sensors, _ = modes_from_result(data, where)
    levels, notes = [], []
    for k, entry in enumerate(raw_levels):
        try:
            levels.append(_level_from(entry, f"{where}: force_levels entry {k}"))
        except RecordingError as exc:
            notes.append(f"force level skipped: {exc}")
    try:  # runs that differ only in hit force: levels of one test, compared by the nonlinear forward model
        from guidefit import nonlinear

        modes, levels = nonlinear.prepare_for_explain(identification, modes, levels, notes)
    except (GuidefitError, IdentificationError, OSError) as exc:
        notes.append(f"force levels across runs not measured: {exc}")
    return explain_modes(modes, identification.guide, sensors, levels, candidates=candidates,
                         progress=progress, source=where, notes=notes)


def explain(source, guide=None, candidates=None, progress=None, settings=None) -> Explanation:
    """Explain a recording (identified first), a modes JSON file or an Identification.

    Parameters
    ----------
    source : str, Path or Identification
        ``.h5``/``.hdf5``/``.csv`` recording, ``.json``/``.jsonl`` modes file
        (:func:`read_modes_json`), or an identification result.
    guide : str or Guide, optional
        Overrides the guide named by the source (default MRB35).
    settings : IdentifySettings, optional
        How a recording is identified (estimator, windows, ...); force levels
        are always on. ``guidefit report`` passes the same settings.
    """
    from guidefit.model.guides import load_guide

    if hasattr(source, "to_dict") and hasattr(source, "modes"):
        return explain_identification(source, candidates, progress)
    path = Path(source)
    if path.suffix.lower() in (".json", ".jsonl", ".ndjson"):
        modes, name, sensors, levels = read_modes_json(path)
        g = guide if guide is not None else (name or "MRB35")
        g = g if not isinstance(g, str | Path) else load_guide(g)
        return explain_modes(modes, g, sensors, levels, candidates=candidates, progress=progress,
                             source=str(path))
    ident = identify_for_explain(path, guide=guide, settings=settings)
    return explain_identification(ident, candidates, progress)


def identify_for_explain(path, guide=None, settings=None):
    """The identification ``explain`` starts from: :func:`~guidefit.identify.identify` with force levels on."""
    from dataclasses import replace

    from guidefit.identify import IdentifySettings, identify

    # force levels feed the amplitude_dependence candidate
    return identify(path, guide=guide, settings=replace(settings or IdentifySettings(), force_levels=True))


def fitted_spec(explanation: Explanation, guide=None):
    """The (small-amplitude) model spec behind ``model_after_hz``: the guide with the fitted effects.

    Use it with :func:`guidefit.model.vibration.solve_modes` and
    :func:`~guidefit.model.vibration.accelerance` for FRF overlays.
    """
    from guidefit.model import vibration as vib
    from guidefit.model.effects import apply_effects
    from guidefit.model.guides import Guide, load_guide

    g = guide if isinstance(guide, Guide) else load_guide(guide or explanation.guide)
    return apply_effects(vib.model_from_guide(g), g, list(explanation.fitted_effects))


def plot_explanation(explanation: Explanation, path, frf=None) -> str:
    """Plot measured vs model frequencies before and after, and optional FRF overlays.

    Left: frequency per measured mode (measured with its 1-sigma bar, nominal
    model, fitted model). Right: relative error (%) before and after with the
    uncertainty band. ``frf``, if given, is a dict with ``frequency_hz`` and
    any of ``measured``, ``before``, ``after`` (complex or magnitude arrays of
    one FRF) and an optional ``title``: a third panel of magnitudes.

    Returns the path written.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    modes = list(explanation.modes)
    n_panels = 3 if frf else 2
    fig, axes = plt.subplots(1, n_panels, figsize=(5.2 * n_panels, 4.2))
    x = np.arange(len(modes))
    names = [f"{m['label']}" + (f"\n{m['run']}" if m.get("run") else "") for m in modes]

    def col(key):
        return np.array([np.nan if m.get(key) is None else m[key] for m in modes], dtype=float)

    ax = axes[0]
    ax.errorbar(x, col("measured_hz"), yerr=col("sigma_hz"), fmt="o", color="k", capsize=4, label="measured")
    ax.plot(x - 0.15, col("model_before_hz"), "x", color="tab:red", ms=9, label="model before")
    after_label = {"explained": "model after", "adequate": "model (nominal)"}.get(
        explanation.verdict, "best attempt (not accepted)")
    ax.plot(x + 0.15, col("model_after_hz"), "s", mfc="none", color="tab:blue", ms=8, label=after_label)
    ax.set_xticks(x, names, fontsize=8)
    ax.set_ylabel("frequency (Hz)")
    ax.set_title(f"verdict: {explanation.verdict}")
    ax.legend(fontsize=8)
    ax = axes[1]
    sig = 100 * col("sigma_hz") / col("measured_hz")
    ax.fill_between(np.r_[x - 0.4, x[-1:] + 0.4] if len(x) else x, 0, 0, color="none")
    ax.bar(x - 0.2, col("error_before_pct"), width=0.4, color="tab:red", alpha=0.7,
           label=f"before (RMS {explanation.error_before['rms_frequency_error_pct']:.2f} %)")
    ax.bar(x + 0.2, col("error_after_pct"), width=0.4, color="tab:blue", alpha=0.7,
           label=f"after (RMS {explanation.error_after['rms_frequency_error_pct']:.2f} %)")
    ax.errorbar(x + 0.2, np.zeros(len(x)), yerr=sig, fmt="none", color="k", capsize=4, label="1 sigma")
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set_xticks(x, names, fontsize=8)
    ax.set_ylabel("model - measured (%)")
    ax.set_yscale("symlog", linthresh=0.1)
    ax.legend(fontsize=8)
    if frf:
        ax = axes[2]
        f = np.asarray(frf["frequency_hz"], float)
        for key, style in (("measured", "k-"), ("before", "r--"), ("after", "b-")):
            if frf.get(key) is not None:
                ax.semilogy(f, np.abs(np.asarray(frf[key])), style, lw=1.0, label=key)
        ax.set_xlabel("frequency (Hz)")
        ax.set_ylabel("|H|")
        ax.set_title(frf.get("title", "FRF"))
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return str(path)


from guidefit._api import make_callable  # noqa: E402

make_callable(__name__, "explain")
