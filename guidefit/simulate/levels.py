"""The hammer the simulator chooses for a carriage: force levels and force range.

A test engineer picks the hammer for the object under test: hard enough for a
clean signal, soft enough that the accelerometers stay well inside their
range. The simulator does the same when the force levels are not given
(``SimulationConfig.force_n`` is None): hits of :data:`DEFAULT_FORCE_N`
(200-500 N, right for a carriage of about 2 kg such as MRB35) unless their
hardest hit would drive an accelerometer of the test past :data:`PEAK_LIMIT`
of its range. Then the forces are scaled down by a round factor (1, 2 or 5
times a power of ten) until the peak is inside the limit, and the force
channel's range by the power of two that keeps the hammer's headroom (a more
sensitive hammer for a softer hit; the LSB stays a power of two). A 0.6 kg
ball carriage gets 40-100 N on +/-512 N, a 34 g miniature carriage 2-5 N on
+/-32 N. Forces given explicitly are used as given: clipping is then the
user's choice.

The peak is that of the exact linear response of the model with its effects
(:func:`guidefit.simulate.physics.linear_acceleration`) at every sensor of every
run, for the hardest hit, over the first :data:`PEAK_WINDOW_S` of the record.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from guidefit.simulate.physics import linear_acceleration

#: Hit forces (min, max) in N when none are given and the carriage allows them.
DEFAULT_FORCE_N = (200.0, 500.0)
#: Largest peak acceleration allowed for the chosen forces, as a fraction of the range.
PEAK_LIMIT = 0.5
#: Time after the hit over which the peak response is taken (s).
PEAK_WINDOW_S = 0.02


@dataclass(frozen=True)
class ForceChoice:
    """What :func:`choose_forces` decided when it stepped in.

    ``default_peak_m_s2`` is the peak acceleration the default forces would give,
    ``peak_m_s2`` that of the chosen ones, ``scale`` the factor on the forces.
    """

    force_n: tuple[float, float]
    force_range_n: float
    scale: float
    default_peak_m_s2: float
    peak_m_s2: float
    acc_range_m_s2: float

    def message(self) -> str:
        """One line for the user and the truth file."""
        lo, hi = self.force_n
        d_lo, d_hi = DEFAULT_FORCE_N
        return (f"hammer chosen for this carriage: hits of {lo:g}-{hi:g} N (force range +/-{self.force_range_n:g} N); "
                f"{d_lo:g}-{d_hi:g} N would peak at {self.default_peak_m_s2:.3g} m/s^2, past "
                f"{PEAK_LIMIT:.0%} of the accelerometers' +/-{self.acc_range_m_s2:g} m/s^2 "
                f"(now {self.peak_m_s2:.3g} m/s^2, {self.peak_m_s2 / self.acc_range_m_s2:.0%}); "
                f"give --force to choose")


def round_down(x: float) -> float:
    """The largest 1, 2 or 5 times a power of ten not above ``x`` (> 0).

    >>> round_down(0.289), round_down(0.01176), round_down(0.2), round_down(3.0)
    (0.2, 0.01, 0.2, 2.0)
    """
    k = math.floor(math.log10(x))
    mantissa = x / 10.0**k
    step = max(m for m in (1.0, 2.0, 5.0, 10.0) if m <= mantissa * (1 + 1e-9))
    return step * 10.0**k if k >= 0 else step / 10.0**-k


def peak_acceleration(model, config, sensors: dict, force_n: float) -> float:
    """Largest |acceleration| (m/s^2) at any sensor of any run for a hit of ``force_n``.

    ``sensors`` maps a run name to its sensors' (positions (n, 3), unit directions (n, 3)).
    """
    rate = config.sample_rate_hz * config.oversample
    t = np.arange(round(min(config.record_s, PEAK_WINDOW_S) * rate)) / rate
    pulses = [(force_n, 0.0, config.pulse_s)]
    peak = 0.0
    for run in config.runs:
        positions, directions = sensors[run.name]
        acc = linear_acceleration(model, run.position_m, run.direction, pulses, t, positions, directions)
        peak = max(peak, float(np.abs(acc).max(initial=0.0)))
    return peak


def choose_forces(config, model, sensors: dict):
    """The config with its hit forces set, and the :class:`ForceChoice` (None when the defaults fit).

    Parameters
    ----------
    config : SimulationConfig
        ``force_n`` None asks for the choice; given forces are kept as they are.
    model : the simulator's model (:func:`guidefit.simulate.physics.build_model`)
    sensors : dict
        Run name -> (positions (n, 3), unit directions (n, 3)) of its accelerometers.

    Returns
    -------
    (SimulationConfig, ForceChoice or None)
        The defaults (200-500 N, ``force_range_n`` as set) unless they would drive
        a sensor past :data:`PEAK_LIMIT` of ``acc_range_m_s2``; an ideal chain
        (``adc_bits`` None) never clips, so it keeps them.
    """
    if config.force_n is not None:
        return config, None
    lo, hi = DEFAULT_FORCE_N
    limit = PEAK_LIMIT * config.acc_range_m_s2
    if config.adc_bits is None:
        return replace(config, force_n=DEFAULT_FORCE_N), None
    peak = peak_acceleration(model, config, sensors, hi)
    if peak <= limit:
        return replace(config, force_n=DEFAULT_FORCE_N), None
    scale = round_down(limit / peak)
    force_n = (lo * scale, hi * scale)
    force_range = config.force_range_n * 2.0 ** math.ceil(math.log2(scale))
    choice = ForceChoice(force_n, force_range, scale, peak, peak * scale, config.acc_range_m_s2)
    return replace(config, force_n=force_n, force_range_n=force_range), choice
