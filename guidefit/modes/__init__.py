"""Modes from FRFs: the modal-analysis layer of the flow (FRFs -> modes -> shapes and labels).

========================  =====================================================================
``base``                  Mode and the other result types, mode indicator, peak picking, synthesize
``prominence``            local maxima and their prominence (scipy.signal.find_peaks' numbers)
``halfpower``             the paper's half-power method: -3 dB band, f_n and zeta (Eq. 26-29's input)
``fitcore``               the fitting core shared by the per-run and the global fit (basis, least
                          squares, exact derivatives of the variable projection)
``curvefit``              per-run modal curve fit (variable projection in a band, auto_fit)
``lsq``                   box-bounded Levenberg-Marquardt for small problems
``globalfit``             one modal model of all runs: LSCF diagram, pole selection, global fit, jackknife
``globalvp``              the global fit's variable-projection problem (shared poles, normal equations)
``shapes``                shapes at the sensors: rigid-body motion, energy shares, IdentifiedMode
``labels``                the one labeller and the one sensor matrix: the model's modes through each
                          run's sensors and hit, shape + frequency evidence, one optimal assignment
========================  =====================================================================

The model, the methods and their limits are in :mod:`guidefit.modes.base`'s docstring and in
docs/modes.md. The package's own namespace holds the documented public names of ``base``,
``halfpower`` and ``curvefit`` (``guidefit.modes.fit_band``, ``from guidefit.modes import
half_power``); everything else is imported from its module.
"""

from guidefit.modes import base as _base
from guidefit.modes import curvefit as _curvefit
from guidefit.modes import halfpower as _halfpower
from guidefit.modes.base import (  # noqa: F401
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
from guidefit.modes.curvefit import auto_fit, fit_band, fit_modes  # noqa: F401
from guidefit.modes.halfpower import half_power, half_power_mode, sdof_from_half_power  # noqa: F401

__all__ = [*_base.__all__, *_halfpower.__all__, *_curvefit.__all__]
