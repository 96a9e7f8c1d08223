"""Modal parameters from FRFs: the names of :mod:`guidefit.modal_base` (result types, mode
indicator, peak picking, synthesis), :mod:`guidefit.halfpower` (the paper's half-power method) and
:mod:`guidefit.curvefit` (per-run modal curve fits) in one place.

The model, the methods and their limits are described in :mod:`guidefit.modal_base`'s docstring
and in docs/modes.md. This module only gathers the names, so that ``guidefit.modes.fit_band`` and
``from guidefit.modes import half_power`` keep working as they did before the split.
"""

from guidefit.curvefit import (  # noqa: F401  (private names: used by the global fit and the tests)
    _basis,
    _cholesky_lapack,
    _covariance,
    _ls_fit,
    _ls_residual,
    _ls_solver,
    _pole_derivatives,
    _poles,
    _Problem,
    _projected_jacobian,
    _solve,
    _stack,
    _suspicious,
    _unpack,
    auto_fit,
    fit_band,
    fit_modes,
)
from guidefit.halfpower import half_power, half_power_mode, sdof_from_half_power
from guidefit.modal_base import (  # noqa: F401  (private names: used by the global fit and the tests)
    _DEFAULT_RESIDUALS,
    _KINDS,
    _PEAK_INTERPOLATIONS,
    _RESIDUAL_TERMS,
    BandFit,
    HalfPower,
    HalfPowerWarning,
    Mode,
    ModeFitWarning,
    Peaks,
    SdofEstimate,
    _as_frequency,
    _as_frf,
    _noise_power,
    find_peaks,
    mode_indicator,
    modes_to_frame,
    natural_from_peak_frequency,
    prominent_peaks,
    synthesize,
)

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
