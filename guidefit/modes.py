"""Modal parameters from FRFs: the names of :mod:`guidefit.modal_base` (result types, mode
indicator, peak picking, synthesis), :mod:`guidefit.halfpower` (the paper's half-power method) and
:mod:`guidefit.curvefit` (per-run modal curve fits) in one place.

The model, the methods and their limits are described in :mod:`guidefit.modal_base`'s docstring
and in docs/modes.md. This module only gathers the names, so that ``guidefit.modes.fit_band`` and
``from guidefit.modes import half_power`` keep working as they did before the split.
"""

from guidefit import curvefit as _curvefit
from guidefit import halfpower as _halfpower
from guidefit import modal_base as _modal_base

# the public names (each module's __all__); the fitting core the global fit shares with the
# curve fit is the declared module guidefit.fitcore, not private names here
from guidefit.curvefit import auto_fit, fit_band, fit_modes  # noqa: F401
from guidefit.halfpower import half_power, half_power_mode, sdof_from_half_power  # noqa: F401
from guidefit.modal_base import (  # noqa: F401
    BandFit,
    HalfPower,
    HalfPowerWarning,
    Mode,
    ModeFitWarning,
    Peaks,
    SdofEstimate,
    find_peaks,
    mode_indicator,
    modes_to_frame,
    natural_from_peak_frequency,
    prominent_peaks,
    synthesize,
)

__all__ = [*_modal_base.__all__, *_halfpower.__all__, *_curvefit.__all__]
