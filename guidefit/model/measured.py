"""What was measured, as the model is compared with it: modes, sensors, force levels (checked).

The types :mod:`guidefit.explain` takes (:class:`MeasuredMode`,
:class:`Sensor`, :class:`ForceLevel`) live here, beside the model, so that an
effect that gathers its own data (``amplitude_dependence`` through
:mod:`guidefit.nonlinear`) builds them without depending on ``explain``; explain
imports them from here (``guidefit.explain.MeasuredMode`` etc. stay its names).
The ``checked_*`` helpers are the one-line checks of their values, shared by
explain's JSON reader (:mod:`guidefit.explain.modes_json`) and
:func:`measured_mode`, which builds a measured mode from an identified one.

Examples
--------
>>> checked_number(3450, "frequency_hz"), checked_vector3([0, 1, 0], "direction")
(3450.0, (0.0, 1.0, 0.0))
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from guidefit.errors import RecordingError


@dataclass(frozen=True)
class MeasuredMode:
    """An identified mode: frequency with its standard deviation, optional label and shape.

    ``frequency_std_hz=None`` means unknown (:data:`~guidefit.explain.settings.DEFAULT_FREQUENCY_STD` applies).
    ``shape`` maps sensor channel names to modal amplitudes (any scale and phase);
    ``shape_std`` is its relative per-channel noise (default: estimated, see docs/explain.md).
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
    (defaults: :data:`~guidefit.explain.settings.DEFAULT_HITS` for the label and
    :data:`~guidefit.explain.settings.DEFAULT_PULSE_S`).
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
    measured: object = field(default=None, repr=False, compare=False)  # guidefit.nonlinear.MeasuredLevel


# --------------------------------------------------------------------------- checks


def checked_number(value, what: str, positive: bool = True, allow_none: bool = False):
    """``value`` as a float; :class:`~guidefit.errors.RecordingError` naming ``what`` unless it is a
    (positive) finite number, or None with ``allow_none``."""
    if value is None and allow_none:
        return None
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value) \
            or (positive and value <= 0):
        kind = "a positive number" if positive else "a finite number"
        raise RecordingError(f"{what} must be {kind}{' or null' if allow_none else ''}, got {value!r}")
    return float(value)


def checked_vector3(value, what: str) -> tuple:
    """Three finite numbers as a tuple of floats (RecordingError naming ``what`` otherwise)."""
    if not isinstance(value, list | tuple) or len(value) != 3:
        raise RecordingError(f"{what} must be a list of 3 numbers, got {value!r}")
    return tuple(checked_number(v, what, positive=False) for v in value)


def checked_shape(value, what: str) -> dict | None:
    """Channel -> complex amplitude from a mapping of numbers, ``[re, im]`` pairs or ``{re, im}`` objects."""
    if value is None:
        return None
    if not isinstance(value, dict):
        raise RecordingError(f"{what} must be an object of channel: amplitude, got {type(value).__name__}")
    out = {}
    for name, v in value.items():
        if isinstance(v, list | tuple) and len(v) == 2:
            out[str(name)] = complex(checked_number(v[0], f"{what} '{name}'", positive=False),
                                     checked_number(v[1], f"{what} '{name}'", positive=False))
        elif isinstance(v, dict) and set(v) <= {"re", "im"}:
            out[str(name)] = complex(checked_number(v.get("re", 0.0), f"{what} '{name}'", positive=False),
                                     checked_number(v.get("im", 0.0), f"{what} '{name}'", positive=False))
        else:
            out[str(name)] = complex(checked_number(v, f"{what} '{name}'", positive=False))
    return out


def checked_sensor(name, position_m, direction, what: str) -> Sensor:
    """A :class:`Sensor` with its direction scaled to unit length (RecordingError for a zero direction)."""
    import numpy as np

    d = np.asarray(checked_vector3(direction, f"{what}: 'direction'"))
    if not np.linalg.norm(d) > 0:
        raise RecordingError(f"{what}: 'direction' must not be zero")
    return Sensor(str(name), checked_vector3(position_m, f"{what}: 'position_m'"), tuple(d / np.linalg.norm(d)))


def measured_mode(mode, what: str) -> MeasuredMode:
    """The :class:`MeasuredMode` of an identified mode (:class:`guidefit.modes.shapes.IdentifiedMode`).

    Its label, run, frequency, damping and standard deviation, and the real
    part of its modal constants as the shape (what ``identify --json``
    writes; :func:`guidefit.explain.modes_from_result` reads that back to the
    same mode), with the same checks.

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> m = SimpleNamespace(label="vertical", run="v", frequency_hz=3450.0, frequency_std_hz=0.8,
    ...                     damping_ratio=0.02, shape={"acc_A_y": 1 + 0.1j})
    >>> measured_mode(m, "mode 0")
    MeasuredMode(frequency_hz=3450.0, frequency_std_hz=0.8, damping_ratio=0.02, label='vertical', shape={'acc_A_y': (1+0j)}, run='v', shape_std=None)
    """
    label = mode.label
    if label is not None and not isinstance(label, str):
        raise RecordingError(f"{what}: 'label' must be a string, got {label!r}")
    shape = None if mode.shape is None else {k: float(complex(v).real) for k, v in mode.shape.items()}
    return MeasuredMode(
        frequency_hz=checked_number(mode.frequency_hz, f"{what}: 'frequency_hz'"),
        frequency_std_hz=checked_number(mode.frequency_std_hz, f"{what}: 'frequency_std_hz'", allow_none=True),
        damping_ratio=checked_number(mode.damping_ratio, f"{what}: 'damping_ratio'", positive=False,
                                     allow_none=True),
        label=label,
        shape=checked_shape(shape, f"{what}: 'shape'"),
        run=None if mode.run is None else str(mode.run),
    )
