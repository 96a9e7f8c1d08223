"""The types of the effect library: one :class:`EffectDef` per effect, and what explain hands its fit.

An effect module of :mod:`guidefit.model.effects` defines one (or, for one
structure with two names, two) :class:`EffectDef` and nothing else that
other modules need: its parameters with their bounds, the model transform
(``apply``), the discrete variants and fit bounds that ``explain`` tries
(``variants``), when it is tried at all (``gate``), what it may combine
with (``structure``, ``excludes``), how its model is evaluated (``forward``;
``None`` = the linear small-amplitude eigen-solution) and its row of the
table in docs/explain.md (``doc``).

How an effect declares its fit
------------------------------
``explain`` evaluates a candidate model (a combination of variants with
parameter values) in three steps:

1. ``spec = apply(spec, guide, parameters)`` for every effect in order
   (:func:`guidefit.model.effects.apply_effects`): the linear,
   small-amplitude model; ``solve_modes(spec)`` gives its modes, which are
   paired with the measured modes (Hungarian method, see docs/explain.md).
2. If an effect of the combination has a ``forward``, explain calls it with
   a :class:`ForwardRequest` (the model, its modes, the pairing, the force
   levels and the effect's parameters) and uses the returned
   :class:`Forward`: the predicted frequency of every measured mode and
   every force level, and the model-form standard deviation that the
   forward model adds (in quadrature) to each. At most one effect of a
   combination may have a forward (``nonlinear=True`` effects are mutually
   exclusive). Without a forward the prediction is the paired model mode's
   frequency for every mode and level (a linear model predicts no trend
   with force).
3. The residuals (frequencies, shapes, de-meaned level trends) are formed
   from that prediction; ``least_squares`` varies the variant's free
   parameters (:class:`Free`, in log or linear coordinates within bounds).

A forward is a plain function ``forward(request: ForwardRequest) -> Forward``.
It must be deterministic and cheap enough to be called some hundred times
per fit (the describing-function model takes about 1 ms per level).
``request.cache`` is a dict that lives for one explain call: keep tables
there (e.g. a describing function per guide), never in module globals that
depend on the request.

Examples
--------
>>> from guidefit.model.effects import EFFECTS
>>> EFFECTS["row_damage"].parameters["factor"].unit
'1'
>>> EFFECTS["support_compliance"].structure == EFFECTS["base_mode"].structure
True
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class Effect:
    """One effect: its name and parameters (floats in SI, or strings such as point names)."""

    name: str
    parameters: dict = field(default_factory=dict)

    def __str__(self) -> str:
        body = ",".join(f"{k}={v}" for k, v in self.parameters.items())
        return f"{self.name}:{body}" if body else self.name


@dataclass(frozen=True)
class Parameter:
    """A parameter of an effect: unit, default (None = required, inf = rigid), meaning and bounds.

    ``unit == ""`` marks a text parameter (point names); ``integer`` one that
    takes whole numbers (a row, a roller).
    """

    unit: str
    default: float | str | None
    meaning: str
    lower: float = 0.0
    upper: float = math.inf
    integer: bool = False


@dataclass(frozen=True)
class Free:
    """A parameter that explain fits: transform, physical bounds and start grid (physical values).

    ``kind`` "log" (masses, stiffnesses, factors: fitted as ln x) or "lin"
    (offsets, positions: fitted as x / ``scale``). ``bound_is_value``: the
    bounds are physical values the parameter may take (the first roller of a
    row), not limits where the effect vanishes or diverges (a rigid spring),
    so a fit at the bound is not flagged "at its bound".
    """

    name: str
    unit: str
    kind: str
    lower: float
    upper: float
    grid: tuple = ()
    scale: float = 0.01
    bound_is_value: bool = False

    def encode(self, value: float) -> float:
        return math.log(value) if self.kind == "log" else value / self.scale

    def decode(self, theta: float) -> float:
        return math.exp(theta) if self.kind == "log" else theta * self.scale

    @property
    def bounds(self) -> tuple[float, float]:
        return self.encode(self.lower), self.encode(self.upper)


def log_free(name: str, unit: str, lower: float, upper: float, grid=()) -> Free:
    """A log-transformed fitted parameter (masses, stiffnesses, factors)."""
    return Free(name, unit, "log", lower, upper, tuple(grid))


@dataclass(frozen=True)
class Variant:
    """One effect with its discrete options fixed and its continuous parameters free.

    ``fixed``: the discrete options (``{"row": 2}``); ``free``: the fitted
    parameters; ``starts``: explicit start points (tuples of physical values,
    default the product of the grids); ``reduces``: ``(parameter, tag)``
    pairs: when that parameter goes to its upper (rigid) bound in a pair fit,
    the variant becomes its variant ``tag``.

    ``whole``: names of free parameters that take whole numbers only (the
    ends of a roller segment). explain fits them continuously first (to find
    the basin), then profiles them: every whole-number combination within
    one of the continuous optimum's floor and ceiling is a discrete choice,
    the other parameters refitted for each, the best one kept
    (:func:`guidefit.explain.candidates.profile_whole`). They then count as
    discrete choices, not fitted parameters: ``choices`` is the number of
    whole-number combinations the variant stands for (counted in the BIC as
    ``2 ln N``, like the variants themselves).
    """

    effect: str
    tag: str
    fixed: dict
    free: tuple
    starts: tuple = ()
    reduces: tuple = ()
    whole: tuple = ()
    choices: int = 1

    @property
    def title(self) -> str:
        return f"{self.effect} ({self.tag})" if self.tag else self.effect


@dataclass(frozen=True)
class FitContext:
    """What an effect's ``variants`` and ``gate`` may look at (built once per explain call).

    ``extra_frequencies_hz``: unlabelled measured modes (extra peaks);
    ``n_levels``: force levels used (in trend groups); ``level_trend_p``:
    the p-value of "the frequency does not change with hit force" over
    those levels (nan without levels).
    """

    guide: object
    extra_frequencies_hz: tuple = ()
    n_levels: int = 0
    level_trend_chi2: float = math.nan
    level_trend_dof: int = 0
    level_trend_p: float = math.nan


@dataclass(frozen=True)
class LevelData:
    """The force levels explain compares (one entry per level used; see docs/explain.md).

    ``force_n``: the level's effective force ``sqrt(sum F^4 / sum F^2)``;
    ``weight``: its H1 weight ``sum F^2``; ``hit_forces_n``: every hit's
    peak force; ``hit``: (point_m, unit direction, pulse_s); ``band``: the
    relative half-width of identify's refit (None: +/- max(3 zeta, 3 %));
    ``groups``: index arrays, one per (run, label) trend; ``measured``: the
    measured setup of each level where :mod:`guidefit.nonlinear` made it.
    """

    frequency_hz: np.ndarray
    sigma_hz: np.ndarray
    force_n: np.ndarray
    weight: np.ndarray
    hit_forces_n: tuple
    label: tuple
    run: tuple
    hit: tuple
    band: tuple
    groups: tuple
    measured: tuple = ()  # per level its guidefit.nonlinear.MeasuredLevel (or None): the measured hits

    @property
    def size(self) -> int:
        return int(self.frequency_hz.size)


@dataclass(frozen=True)
class ForwardRequest:
    """What explain hands an effect's ``forward`` at one model evaluation.

    ``spec``/``solution``: the small-amplitude model with every effect of
    the candidate applied and its modes; ``parameters``: this effect's
    parameters; ``mode_model``: per measured mode the paired model mode
    (-1 unpaired); ``mode_label``/``mode_run``: the measured modes'
    canonical labels and runs; ``mode_levels``: per measured mode the level
    indices whose hits made its FRF (None: small amplitude);
    ``mode_measured_hz``: the measured frequencies; ``model_damping``: per
    model mode the damping ratio of its measured partner (nan unknown);
    ``level_model``: per level the model mode it refers to (-1 none);
    ``levels``: the force levels compared (:class:`LevelData`);
    ``guide``: the guide; ``effects``: every effect of the candidate
    (:class:`Effect`, this one included); ``cache``: scratch space for one
    explain call.
    """

    guide: object
    spec: object
    solution: object
    parameters: dict
    effects: tuple
    mode_model: np.ndarray
    mode_label: tuple
    mode_run: tuple
    mode_levels: tuple
    mode_measured_hz: np.ndarray
    model_damping: np.ndarray
    level_model: np.ndarray
    levels: LevelData
    cache: dict


@dataclass(frozen=True)
class Forward:
    """A forward model's prediction: per measured mode and per force level (Hz), with model-form stds.

    ``mode_hz`` nan where the mode is unpaired; ``level_hz`` nan where the
    level has no model mode. ``mode_std_hz``/``level_std_hz``: the forward
    model's own error, added in quadrature to the measurement's (zeros for
    an exact model); a level's is that of its de-meaned trend.
    """

    mode_hz: np.ndarray
    level_hz: np.ndarray
    mode_std_hz: np.ndarray
    level_std_hz: np.ndarray


@dataclass(frozen=True)
class DocRow:
    """The effect's row of the library table in docs/explain.md (markdown cells)."""

    variants: str
    fitted: str
    meaning: str


@dataclass(frozen=True)
class EffectDef:
    """Everything about one effect, in one place (see the module docstring).

    Parameters
    ----------
    name : str
        The effect's name (``--effect NAME:...``, explain's output).
    meaning : str
        One line: what physical cause it stands for.
    parameters : dict of str -> Parameter
        Its parameters (SI) with defaults and bounds.
    apply : callable
        ``apply(spec, guide, parameters) -> ModelSpec``: the linear
        (small-amplitude) model transform.
    variants : callable
        ``variants(ctx: FitContext) -> list[Variant]``: the discrete options
        explain tries, with fit bounds and start grids.
    doc : DocRow
        Its row of the library table of docs/explain.md.
    order : int
        Position in the library (ties in model selection keep this order).
    structure : str, optional
        Effects of one structure never combine (one body between rail and
        ground has one mass).
    excludes : frozenset of str
        Other effects it does not combine with (checked both ways).
    gate : callable, optional
        ``gate(ctx) -> str | None``: why the effect is not tried on these
        data (None: it is tried).
    forward : callable, optional
        ``forward(ForwardRequest) -> Forward`` for effects whose prediction is
        not the linear eigen-solution (``nonlinear`` effects).
    accept : callable, optional
        ``accept(levels: LevelData, level_hz) -> str | None``: why a fitted
        candidate with this effect is not accepted beyond the chi-square and
        identifiability tests (e.g. no trend over force levels), given the
        fitted model's prediction of every force level.
    prepare : callable, optional
        ``prepare(identification, modes, levels, notes) -> (modes, levels)``:
        data the effect gathers from an :class:`~guidefit.identify.Identification`
        beyond identify's modes and force levels (``amplitude_dependence``:
        force levels across runs that differ only in hit force); called by
        :func:`guidefit.explain.explain_identification` for every candidate
        effect, in library order. ``modes`` are
        :class:`~guidefit.model.measured.MeasuredMode`, ``levels``
        :class:`~guidefit.model.measured.ForceLevel` (the model's own types, no import of explain); a
        :class:`~guidefit.errors.GuidefitError` becomes a note.
    ambiguity : callable, optional
        ``ambiguity(tags) -> str | None``: a note for when several of its
        variants (their tags) explain the data equally well (e.g. the
        mirror-symmetric corners of ``added_mass``).
    aliases : tuple of str
        Other names ``--effect``, ``make_effect`` and JSON readers accept.
    nonlinear : bool
        The effect's model depends on the hit force.
    """

    name: str
    meaning: str
    parameters: dict
    apply: Callable
    variants: Callable
    doc: DocRow
    order: int = 100
    structure: str | None = None
    excludes: frozenset = frozenset()
    gate: Callable | None = None
    forward: Callable | None = None
    accept: Callable | None = None
    prepare: Callable | None = None
    ambiguity: Callable | None = None
    aliases: tuple = ()
    nonlinear: bool = False

