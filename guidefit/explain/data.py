"""Stage 0 of explain: the measured data as the residuals need them (:class:`PreparedData`).

Checks the measured modes and force levels (one-line errors naming the entry),
applies the uncertainty floors, projects each mode shape on its sensors,
groups the force levels into per-(run, label) trends, replaces a mode's
frequency by its force levels' H1-weighted mean where it has two or more of
its own, and leaves out the shapes of runs that responded nonlinearly. See
docs/explain.md, "Input" and "Residuals".
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from guidefit.errors import RecordingError
from guidefit.explain.settings import (
    ACCEPT_P_VALUE,
    DEFAULT_FREQUENCY_STD,
    DEFAULT_HITS,
    DEFAULT_PULSE_S,
    DEFAULT_SHAPE_STD,
    ESTIMATED_SHAPE_STD_FLOOR,
    FORCE_LEVEL_FLOOR,
    FREQUENCY_FLOOR,
    LABEL_GROUP,
    SHAPE_STD_FLOOR,
    canonical_label,
)
from guidefit.model.effects import LevelData
from guidefit.model.effects.amplitude_dependence import effective_force
from guidefit.model.measured import ForceLevel, MeasuredMode
from guidefit.model.vibration import MODE_LABELS


@dataclass(frozen=True)
class ShapeSet:
    """The modes measured on one set of sensor channels.

    ``index``: the measured modes; ``unit``: (g, n_ch) real unit shapes;
    ``rigid_map``: (n_ch, 5) carriage DOFs to channel; ``scale``: (g,)
    ``sqrt(n_ch) / s`` with ``s`` the mode's relative per-channel noise.
    """

    index: np.ndarray
    unit: np.ndarray
    rigid_map: np.ndarray
    scale: np.ndarray

    def __iter__(self):  # (idx, M, S, scale), the order the residual code unpacks
        return iter((self.index, self.unit, self.rigid_map, self.scale))


@dataclass(frozen=True)
class PreparedData:
    """The measured modes, shapes and force levels as the residuals use them.

    Per measured mode i: ``f`` and ``sigma`` (Hz, floored), ``f_fit``
    (identify's all-hits frequency: ``f`` differs where the mode's own force
    levels replaced it), ``labels`` (canonical or None), ``group`` (motion
    group of the label, -1 without), ``mode_run``, ``mode_zeta`` (nan:
    unknown), ``mode_levels`` (level indices whose hits made its FRF, or
    None), ``mode_force`` (their effective force, nan: small amplitude),
    ``has_shape``. ``runs``: index arrays, one per run; ``shapes``: one
    :class:`ShapeSet` per sensor set; ``levels``: the force levels used.
    ``n_data`` counts frequencies, shape degrees of freedom and levels less
    one per trend group.
    """

    f: np.ndarray
    sigma: np.ndarray
    f_fit: np.ndarray
    labels: list
    label_arr: np.ndarray
    group: np.ndarray
    mode_run: list
    mode_zeta: np.ndarray
    mode_levels: list
    mode_force: np.ndarray
    runs: list
    shapes: list
    has_shape: np.ndarray
    levels: LevelData
    n_data: int
    n_shape_dof: int

    # the levels' arrays under the names the residual code uses
    @property
    def lv_f(self) -> np.ndarray:
        return self.levels.frequency_hz

    @property
    def lv_sigma(self) -> np.ndarray:
        return self.levels.sigma_hz

    @property
    def lv_force(self) -> np.ndarray:
        return self.levels.force_n

    @property
    def lv_label(self) -> tuple:
        return self.levels.label

    @property
    def lv_run(self) -> tuple:
        return self.levels.run

    @property
    def lv_groups(self) -> tuple:
        return self.levels.groups


@dataclass(frozen=True)
class _Level:
    """One checked force level before grouping."""

    frequency_hz: float
    std_hz: float  # as given (or the default)
    sigma_hz: float  # with the floor
    force_n: float  # effective force of its hits
    weight: float  # sum of the hits' forces squared (H1)
    hit_forces_n: tuple
    band: float | None
    label: str
    hit: tuple
    run: str | None
    explicit_hit: bool  # hit point and direction given (else the label's default)
    measured: object = None  # the MeasuredLevel behind it (guidefit.nonlinear), for the simulated forward


def finite_positive(x) -> bool:
    return isinstance(x, int | float | np.floating | np.integer) and not isinstance(x, bool) \
        and math.isfinite(float(x)) and float(x) > 0


def default_sensor_map(guide, channels) -> dict:
    """Sensors for channel names acc_<point>_<axis> from the guide's measuring points."""
    from guidefit.model.measured import Sensor

    axes = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}
    out = {}
    for name in channels:
        parts = str(name).split("_")
        if len(parts) == 3 and parts[0] == "acc" and parts[1] in guide.measuring_points_m and parts[2] in axes:
            out[name] = Sensor(name, tuple(guide.measuring_points_m[parts[1]]), axes[parts[2]])
    return out


def real_unit(values: np.ndarray) -> np.ndarray:
    """A complex shape rotated to its best real phase and scaled to unit length."""
    v = np.asarray(values, dtype=complex)
    angle = 0.5 * np.angle(np.sum(v**2))
    r = np.real(v * np.exp(-1j * angle))
    norm = np.linalg.norm(r)
    return r / norm if norm > 0 else r


def shape_noise(unit: np.ndarray, s_mat: np.ndarray) -> float:
    """Relative per-channel noise of a unit shape from the part that no rigid carriage motion explains.

    With more channels than observable carriage DOFs (8 channels at A-D in x
    and y observe 5 DOFs: 3 redundant), the residual of the least-squares
    rigid-body fit is noise (or a non-rigid carriage), whatever the model:
    ``s = |m - S q| sqrt(n_ch / (n_ch - rank S))`` relative to the RMS
    amplitude, with the floor :data:`~guidefit.explain.settings.ESTIMATED_SHAPE_STD_FLOOR`.
    Without redundancy :data:`~guidefit.explain.settings.DEFAULT_SHAPE_STD` applies.
    """
    n = unit.size
    rank = int(np.linalg.matrix_rank(s_mat))
    if n <= rank:
        return DEFAULT_SHAPE_STD
    q, *_ = np.linalg.lstsq(s_mat, unit, rcond=None)
    noise = float(np.linalg.norm(unit - s_mat @ q)) * math.sqrt(n / (n - rank))
    return max(noise, ESTIMATED_SHAPE_STD_FLOOR)


def level_shape_scatter(mode, names, unit: np.ndarray, force_levels) -> float:
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
    lab = canonical_label(mode.label)
    perp = []
    for lv in force_levels:
        if (not isinstance(lv, ForceLevel) or lv.frequency_hz is None or not lv.shape or lv.run != mode.run
                or canonical_label(lv.label) != lab or not all(c in lv.shape for c in names)):
            continue
        b = np.array([complex(lv.shape[c]) for c in names])
        if not np.all(np.isfinite(b)) or not np.any(b):
            continue
        b = real_unit(b)
        perp.append(float(np.linalg.norm(b - unit * (unit @ b))))
    if len(perp) < 2 or unit.size < 2:
        return 0.0
    return math.sqrt(float(np.mean(np.square(perp))) * unit.size / (unit.size - 1))


def p_value(chi2: float, dof: int) -> float:
    """Chi-square upper tail probability (nan without degrees of freedom)."""
    from scipy.special import chdtrc

    return float(chdtrc(dof, chi2)) if dof > 0 else float("nan")


def _checked_frequencies(measured, notes) -> tuple[list, list]:
    f, sigma = [], []
    n_default = 0
    for i, m in enumerate(measured):
        if not isinstance(m, MeasuredMode):
            raise RecordingError(f"measured mode {i}: expected a MeasuredMode, got {type(m).__name__}")
        if not finite_positive(m.frequency_hz):
            raise RecordingError(f"measured mode {i}: frequency_hz must be a positive number, got {m.frequency_hz!r}")
        fi = float(m.frequency_hz)
        std = m.frequency_std_hz
        if std is None:
            n_default += 1
            std = DEFAULT_FREQUENCY_STD * fi
        elif not finite_positive(std):
            raise RecordingError(f"measured mode {i}: frequency_std_hz must be positive or None, got {std!r}")
        f.append(fi)
        sigma.append(max(float(std), FREQUENCY_FLOOR * fi))
    if n_default:
        notes.append(f"{n_default} mode(s) without a frequency uncertainty: {DEFAULT_FREQUENCY_STD:.0%} assumed")
    return f, sigma


def _shape_sets(measured, guide, sensors, force_levels, notes) -> dict:
    """{channel names: ([mode index], [unit shape], rigid map, [scale])} of the modes with shapes."""
    from guidefit.modes.labels import sensor_matrix

    by_name = {s.name: s for s in sensors}
    channels = {c for m in measured if m.shape for c in m.shape}
    for name, s in default_sensor_map(guide, channels).items():
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
        s_mat = sensor_matrix([by_name[c] for c in names])
        unit = real_unit(vals)
        s_std = shape_noise(unit, s_mat) if m.shape_std is None else max(float(m.shape_std), SHAPE_STD_FLOOR)
        s_std = max(s_std, level_shape_scatter(m, names, unit, force_levels))
        entry = by_set.setdefault(tuple(names), ([], [], s_mat, []))
        entry[0].append(i)
        entry[1].append(unit)
        entry[3].append(math.sqrt(len(names)) / s_std)
    if unknown:
        notes.append(f"shape channels without a sensor position ignored: {', '.join(sorted(unknown))}")
    return by_set


def _checked_level(j: int, lv) -> _Level | None:
    """One force level checked (None: the bin's hits did not reproduce the mode, see ``_unreproduced``)."""
    if not isinstance(lv, ForceLevel):
        raise RecordingError(f"force level {j}: expected a ForceLevel, got {type(lv).__name__}")
    if not finite_positive(lv.peak_force_n) or not (lv.frequency_hz is None or finite_positive(lv.frequency_hz)):
        raise RecordingError(f"force level {j}: peak_force_n and frequency_hz must be positive numbers")
    lab = canonical_label(lv.label)
    if lab is None:
        raise RecordingError(f"force level {j}: label '{lv.label}' is not a carriage mode label "
                             f"({', '.join(MODE_LABELS)})")
    if lv.frequency_hz is None:
        return None
    forces = np.asarray(lv.hit_forces_n if lv.hit_forces_n else [lv.peak_force_n], float)
    if forces.ndim != 1 or not np.all(np.isfinite(forces) & (forces > 0)):
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
    elif not finite_positive(std):
        raise RecordingError(f"force level {j}: frequency_std_hz must be positive or None, got {std!r}")
    point, direction = DEFAULT_HITS[lab]
    point = tuple(lv.hit_position_m) if lv.hit_position_m is not None else point
    direction = np.asarray(lv.hit_direction if lv.hit_direction is not None else direction, float)
    direction = direction / (np.linalg.norm(direction) or 1.0)
    pulse = float(lv.pulse_s) if lv.pulse_s is not None else DEFAULT_PULSE_S
    f = float(lv.frequency_hz)
    # H1 = sum X F* / sum |F|^2 averages the hits' FRFs with weights F^2, so the bin's frequency is that
    # of the F^2-weighted hits; with a drop ~ F^2 (the describing function below lift-off) that is the
    # frequency at F_eff = sqrt(sum F^4 / sum F^2), not at the mean force
    return _Level(f, float(std), max(float(std), FORCE_LEVEL_FLOOR * f), effective_force(forces),
                  float(np.sum(forces**2)), tuple(float(x) for x in forces), band, lab,
                  (tuple(point), direction, pulse), lv.run,
                  lv.hit_position_m is not None and lv.hit_direction is not None, lv.measured)


def experiments(levels: list) -> dict:
    """Run -> experiment: runs whose hits share point and direction (they differ only in hit force) are one.

    Their force levels are one trend (the issue-16 "levels of one test"): a
    carriage hit at 100 N, 1 kN and 5 kN in three runs. Without an explicit
    hit point and direction a run is its own experiment.
    """
    out: dict = {}
    for lv in levels:
        if lv.explicit_hit:
            key = ("hit", tuple(np.round(np.asarray(lv.hit[0], float), 4)),
                   tuple(np.round(np.asarray(lv.hit[1], float), 3)))
        else:
            key = ("run", lv.run)
        out.setdefault(lv.run, key)
    return out


def _grouped_levels(levels: list, labels, runs, notes) -> tuple[LevelData, list]:
    """The levels used, in (experiment, label) trend groups of two or more, and their standard deviations as given.

    A label's levels come from the experiment (:func:`experiments`: a run, or
    runs that differ only in hit force) that gave its mode: the same hits,
    the same estimator; each (experiment, label) group is a trend with
    force, compared after removing its weighted mean.
    """
    exp = experiments(levels)

    def experiment(run):
        return exp.get(run, ("run", run))

    by_group: dict = {}
    for j, lv in enumerate(levels):
        own = {experiment(runs[i]) for i, ll in enumerate(labels) if ll == lv.label and runs[i] is not None}
        has_own = any(experiment(other.run) in own for other in levels if other.label == lv.label)
        if not has_own or experiment(lv.run) in own:
            by_group.setdefault((experiment(lv.run), lv.label), []).append(j)
    used = sorted(j for g in by_group.values() if len(g) >= 2 for j in g)
    if len(used) < len(levels):
        notes.append(f"{len(levels) - len(used)} force level(s) not used (another run's estimate of the mode, "
                     "or a single level: no trend)")
    remap = {j: k for k, j in enumerate(used)}
    kept = [levels[j] for j in used]
    return LevelData(
        frequency_hz=np.array([lv.frequency_hz for lv in kept]), sigma_hz=np.array([lv.sigma_hz for lv in kept]),
        force_n=np.array([lv.force_n for lv in kept]), weight=np.array([lv.weight for lv in kept]),
        hit_forces_n=tuple(lv.hit_forces_n for lv in kept), label=tuple(lv.label for lv in kept),
        run=tuple(lv.run for lv in kept), hit=tuple(lv.hit for lv in kept), band=tuple(lv.band for lv in kept),
        groups=tuple(np.array([remap[j] for j in g]) for g in by_group.values() if len(g) >= 2),
        measured=tuple(lv.measured for lv in kept),
    ), [levels[j].std_hz for j in used]


def _levels_of_modes(f, sigma, labels, runs, levels: LevelData, raw_std, notes):
    """Per mode: the levels whose hits made its FRF, their effective force, and its frequency from its own.

    A mode with at least two levels of its own run is compared through them:
    its frequency is their H1-weighted mean (the narrow-band refit that the
    amplitude model reproduces; the all-hits fit spans the whole band and,
    for a frequency that drifts within each hit, sees 1.5-3 times the drop),
    its standard deviation the larger of theirs and its own.
    """
    f, sigma = np.array(f), np.array(sigma)
    f_fit = f.copy()
    mode_force = np.full(f.size, np.nan)
    mode_levels: list = [None] * f.size
    replaced = []
    for i, lab in enumerate(labels):
        js = [j for j, ll in enumerate(levels.label) if ll == lab]
        if not js and runs[i] is not None:  # the same hits made every mode of a run
            js = [j for j, rr in enumerate(levels.run) if rr == runs[i]]
        if lab is None or not js:
            continue
        own = [j for j in js if levels.label[j] == lab and levels.run[j] == runs[i]]
        js = own or js  # the hits that made the mode's FRF: its run's levels when it has any
        w = levels.weight[js]
        mode_force[i] = math.sqrt(float(np.sum(w * np.square(levels.force_n[js])) / np.sum(w)))
        mode_levels[i] = js
        if len(own) >= 2:
            w = levels.weight[own]
            f_lv = float(np.sum(w * levels.frequency_hz[own]) / np.sum(w))
            s_lv = float(np.sqrt(np.sum(np.square(w * [raw_std[j] for j in own]))) / np.sum(w))
            f[i] = f_lv
            sigma[i] = max(s_lv, sigma[i] * f_lv / f_fit[i])
            mode_levels[i] = own
            replaced.append(i)
    if replaced:
        notes.append("frequency from the mode's force levels (narrow-band refits of the same hits, H1-weighted): "
                     + ", ".join(f"{labels[i]} ({runs[i]} run) {f[i]:.1f} Hz, all-hits fit {f_fit[i]:.1f} Hz"
                                 for i in replaced))
    return f, sigma, f_fit, mode_force, mode_levels


def nonlinear_runs(levels: LevelData) -> set:
    """Runs whose force levels, as a whole, change with force beyond their uncertainty (p < ACCEPT_P_VALUE)."""
    chi2: dict = {}
    f, sigma = levels.frequency_hz, levels.sigma_hz
    for g in levels.groups:  # a group of several runs (one experiment) counts for each of them
        w = sigma[g] ** -2.0
        z = (f[g] - np.sum(w * f[g]) / np.sum(w)) / sigma[g]
        for run in {levels.run[j] for j in g}:
            c, n = chi2.get(run, (0.0, 0))
            chi2[run] = (c + float(z @ z), n + len(g) - 1)
    return {r for r, (c, n) in chi2.items() if n > 0 and p_value(c, n) < ACCEPT_P_VALUE}


def _linear_shapes(by_set: dict, runs, levels: LevelData, notes) -> list:
    """The shape sets without the modes of runs that responded nonlinearly.

    A run whose frequencies change with hit force responded nonlinearly: the
    modal fit of its amplitude-dependent peaks distorts the shapes
    (overlapping modes partitioned differently), so its shapes are not used;
    its frequencies and force levels are.
    """
    nonlinear = nonlinear_runs(levels)
    out, dropped = [], 0
    for idx, units, s_mat, scales in by_set.values():
        keep = [k for k, i in enumerate(idx) if runs[i] not in nonlinear]
        dropped += len(idx) - len(keep)
        if keep:
            out.append(ShapeSet(np.array([idx[k] for k in keep]), np.array([units[k] for k in keep]), s_mat,
                                np.array([scales[k] for k in keep])))
    if dropped:
        notes.append(f"run(s) {', '.join(sorted(map(str, nonlinear)))}: the frequency changes with hit force "
                     f"(p < {ACCEPT_P_VALUE}); the shapes of their {dropped} mode(s) are not used")
    return out


def prepare(measured, guide, sensors, force_levels, notes: list) -> PreparedData:
    """Check and arrange the measured data (see the module docstring); notes are appended to ``notes``."""
    measured = list(measured)
    if not measured:
        raise RecordingError("explain: no measured modes given")
    f, sigma = _checked_frequencies(measured, notes)
    labels = [canonical_label(m.label) for m in measured]
    runs = [m.run for m in measured]
    by_set = _shape_sets(measured, guide, sensors, force_levels, notes)
    checked = [_checked_level(j, lv) for j, lv in enumerate(force_levels)]
    levels, raw_std = _grouped_levels([lv for lv in checked if lv is not None], labels, runs, notes)
    f, sigma, f_fit, mode_force, mode_levels = _levels_of_modes(f, sigma, labels, runs, levels, raw_std, notes)
    shapes = _linear_shapes(by_set, runs, levels, notes)
    has_shape = np.zeros(f.size, bool)
    for s in shapes:
        has_shape[s.index] = True
    n_shape_dof = sum(s.unit.shape[0] * (s.unit.shape[1] - 1) for s in shapes)
    groups: dict = {}
    for i, r in enumerate(runs):
        groups.setdefault(r, []).append(i)
    return PreparedData(
        f=f, sigma=sigma, f_fit=f_fit, labels=labels, label_arr=np.array(labels, dtype=object),
        group=np.array([LABEL_GROUP.get(lab, -1) if lab else -1 for lab in labels]), mode_run=runs,
        mode_zeta=np.array([m.damping_ratio if finite_positive(m.damping_ratio) else np.nan for m in measured]),
        mode_levels=mode_levels, mode_force=mode_force, runs=[np.array(v) for v in groups.values()],
        shapes=shapes, has_shape=has_shape, levels=levels,
        n_data=f.size + n_shape_dof + levels.size - len(levels.groups), n_shape_dof=n_shape_dof,
    )
