r"""Close the loop: find the physical effect that the nominal model lacks (issues 5 and 16).

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
Measured modes are paired with model modes by the Hungarian method, per run,
at every model evaluation (:mod:`guidefit.explain.pairing` gives the cost).

Stages
------
The package is the pipeline of :mod:`guidefit.explain.pipeline`, one module per
stage, each returning a frozen dataclass: :mod:`~guidefit.explain.data`
(measured data, floors, force-level trends), :mod:`~guidefit.explain.pairing`
(measured <-> model modes), :mod:`~guidefit.explain.evaluation` (residuals of
one model), :mod:`~guidefit.explain.candidates` (least-squares fits of the
effects' variants and of pairs), :mod:`~guidefit.explain.selection`
(acceptance and BIC ranking, discrete choices counted) and
:mod:`~guidefit.explain.verdict` (adequate / explained / unexplained and the
:class:`Explanation`). The candidates come from the effect registry of
:mod:`guidefit.model.effects`: each effect declares its variants, fit
bounds, gate, forward model and combinations; this package has no rule of
its own for any effect.

Amplitude dependence
--------------------
``amplitude_dependence`` is tried only with force levels whose frequencies
change with hit force, and accepted only when its fit predicts that trend;
its prediction is the ``forward`` that its registry entry declares (the
describing-function model of :mod:`guidefit.model.effects.amplitude_dependence`
until the time-domain model replaces it). A run whose force levels change
with force beyond their uncertainty has responded nonlinearly; the modal fit
of its chirped peaks distorts the mode shapes, so that run's shapes are not
used.

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
Score: BIC = chi2 + k ln n + 2 ln N (k fitted parameters, n data, N the
discrete variants each effect chose among). A model is
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

from guidefit.explain.data import level_shape_scatter as _level_shape_scatter  # noqa: F401 - tests
from guidefit.explain.entry import explain, explain_identification, fitted_spec, identify_for_explain
from guidefit.explain.inputs import Explanation
from guidefit.explain.modes_json import modes_from_result, read_modes_json
from guidefit.explain.pipeline import explain_modes
from guidefit.explain.plot import plot_explanation
from guidefit.explain.settings import (
    ACCEPT_P_VALUE,
    DEFAULT_FREQUENCY_STD,
    DEFAULT_HITS,
    DEFAULT_PULSE_S,
    DEFAULT_SHAPE_STD,
    EQUAL_BIC,
    ESTIMATED_SHAPE_STD_FLOOR,
    FORCE_LEVEL_FLOOR,
    FREQUENCY_FLOOR,
    IDENTIFIABLE_LOG_STD,
    SHAPE_STD_FLOOR,
    UNPAIRED_PENALTY,
)
from guidefit.explain.synthetic import default_sensors, synthetic_modes
from guidefit.model.effects.amplitude_dependence import (
    AMPLITUDE_MODEL_FORM,
    AMPLITUDE_SHIFT_CAP,
    DEFAULT_DECAY_DAMPING,
    effective_force,
)
from guidefit.model.measured import ForceLevel, MeasuredMode, Sensor

__all__ = [
    "ACCEPT_P_VALUE", "AMPLITUDE_MODEL_FORM", "AMPLITUDE_SHIFT_CAP", "DEFAULT_DECAY_DAMPING",
    "DEFAULT_FREQUENCY_STD", "DEFAULT_HITS", "DEFAULT_PULSE_S", "DEFAULT_SHAPE_STD", "EQUAL_BIC",
    "ESTIMATED_SHAPE_STD_FLOOR", "FORCE_LEVEL_FLOOR", "FREQUENCY_FLOOR", "IDENTIFIABLE_LOG_STD", "SHAPE_STD_FLOOR",
    "UNPAIRED_PENALTY", "Explanation", "ForceLevel", "MeasuredMode", "Sensor", "default_sensors",
    "effective_force", "explain", "explain_identification", "explain_modes", "fitted_spec",
    "identify_for_explain", "modes_from_result", "plot_explanation", "read_modes_json", "synthetic_modes",
]

from guidefit._api import make_callable

make_callable(__name__, "explain")
