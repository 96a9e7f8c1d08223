"""Floors, thresholds and defaults of ``guidefit explain`` (docs/explain.md says where each comes from)."""

from __future__ import annotations

from guidefit.model.vibration import MODE_LABELS

#: Model-form floor of a mode's relative frequency uncertainty (0.05 %).
FREQUENCY_FLOOR = 5.0e-4
#: Floor of a force level's relative frequency uncertainty (0.1 %): the model-form error of the predicted
#: trend with force (against identify on RK4-simulated recordings: 0.02 % for drops up to 0.3 %, up to 0.15 %
#: for drops near 1 %; see docs/explain.md).
FORCE_LEVEL_FLOOR = 1.0e-3
#: Relative frequency uncertainty of a mode that gives none (1 %, raw peak picking).
DEFAULT_FREQUENCY_STD = 1.0e-2
#: Relative per-channel noise of a mode shape that gives none and whose sensors do not over-determine
#: the carriage motion (3 % of its RMS amplitude); otherwise it is estimated (:func:`~guidefit.explain.data.shape_noise`).
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

#: Motion group of a label (v, theta, psi, u+phi): the energy share the pairing compares.
LABEL_GROUP = {"vertical": 0, "pitch": 1, "yaw": 2, "roll_low": 3, "roll_high": 3}
LABEL_ALIASES = {"v": "vertical", "f_v": "vertical", "h": "roll_low", "f_h": "roll_low",
                 "horizontal": "roll_low", "lateral": "roll_low"}
_VERTICAL_HIT = ((0.004, 0.0, 0.008), (0.0, -1.0, 0.0))
_LATERAL_HIT = ((0.05, -0.012, 0.006), (-1.0, 0.0, 0.0))
#: Hit point and direction per mode label when a force level gives none (simulate's DEFAULT_RUNS).
DEFAULT_HITS = {"vertical": _VERTICAL_HIT, "pitch": _VERTICAL_HIT, "yaw": _LATERAL_HIT,
                "roll_low": _LATERAL_HIT, "roll_high": _LATERAL_HIT}
#: Residual of a model that cannot be evaluated.
BAD_RESIDUAL = 1.0e4


def canonical_label(label):
    """A carriage mode label (``vertical``, ``pitch``, ``yaw``, ``roll_low``, ``roll_high``) or None.

    >>> canonical_label("f_V"), canonical_label("extra")
    ('vertical', None)
    """
    if label is None:
        return None
    low = str(label).strip().lower()
    if low in MODE_LABELS:
        return low
    return LABEL_ALIASES.get(low)

#: whole-number ends (``Variant.whole``) are kept only while their best fit is within this chi2 of the
#: continuous fit (the chi-square with 2 dof at p = 0.01): above it the data say the ends are fractional
#: (a roller partly on the damage) and the continuous fit stands
WHOLE_MISFIT_CHI2 = 9.21
