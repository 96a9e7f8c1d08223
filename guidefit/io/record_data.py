"""The recording contract's in-memory data: channels, array sources, RunData and RecordingData.

:class:`Channel` (one channel's name, unit, position, direction and scale),
:class:`ArraySource` (samples held in memory, the simplest run source),
:class:`RunData` and :class:`RecordingData` (a recording in memory, for the
writers), the unit tables and the channel-list check they share. They are
separate from :mod:`guidefit.io.records`, which holds the file-backed
:class:`~guidefit.io.records.Run` and :class:`~guidefit.io.records.Recording`
and reads samples through a run's source, because these types hold values
only: they read nothing, and nothing here imports :mod:`guidefit.io.records`.
Every name stays importable from :mod:`guidefit.io.records` (and
:mod:`guidefit.io`) as before.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from guidefit.errors import RecordingError
from guidefit.io._checks import (
    UNIT_VECTOR_TOLERANCE,
    _as_str_tuple,
    _check_data_array,
    _check_force_axis,
    _check_position,
    _check_pretrigger,
    _check_sample_rate,
    _check_vector,
    _fields_equal,
    _fmt_vec,
    _frozen_array,
    _table,
    _valid_run_name,
)

FORMAT_NAME = "guidefit-recording"
FORMAT_VERSION = 1
STANDARD_GRAVITY = 9.80665
"""m/s^2 per g (the conventional standard gravity)."""
LAYOUTS = ("signals", "hits")
FORCE_UNITS = {"N": 1.0}
"""Allowed units of the force channel and their factor to SI."""
ACCELERATION_UNITS = {"m/s^2": 1.0, "g": STANDARD_GRAVITY}
"""Allowed units of acceleration channels and their factor to SI."""

_ACC_RE = re.compile(r"^acc_([A-Za-z0-9]+)_([xyz])\Z")


# --------------------------------------------------------------------------- data


@dataclass(frozen=True, eq=False)
class Channel:
    """One measured channel of a run.

    Attributes
    ----------
    name : str
        ``"force"`` or ``"acc_<point>_<axis>"`` (e.g. ``"acc_A_y"``).
    unit : str
        Unit as stored in the file: ``"N"``, ``"m/s^2"`` or ``"g"``.
    position_m : ndarray, shape (3,)
        Sensor location in the carriage frame, m (for ``force``: the hit point).
    direction : ndarray, shape (3,)
        Unit vector of the sensor's positive axis.
    scale_to_si : float
        Factor from the stored unit to SI: 9.80665 for ``"g"``, else 1.0.

    Examples
    --------
    >>> ch = Channel("acc_A_y", "g", [0.03, 0.0, 0.045], [0, 1, 0], 9.80665)
    >>> ch.kind, ch.point, ch.axis, ch.unit_si
    ('acceleration', 'A', 'y', 'm/s^2')
    """

    name: str
    unit: str
    position_m: np.ndarray
    direction: np.ndarray
    scale_to_si: float

    def __post_init__(self):
        object.__setattr__(self, "position_m", _frozen_array(self.position_m))
        object.__setattr__(self, "direction", _frozen_array(self.direction))
        object.__setattr__(self, "scale_to_si", float(self.scale_to_si))

    __eq__ = _fields_equal
    __hash__ = None

    @property
    def kind(self) -> str:
        """``"force"`` or ``"acceleration"``."""
        return "force" if self.name == "force" else "acceleration"

    @property
    def point(self) -> str | None:
        """Measuring point of an acceleration channel (``"A"``), else None."""
        match = _ACC_RE.match(self.name)
        return match.group(1) if match else None

    @property
    def axis(self) -> str | None:
        """Axis letter of an acceleration channel (``"x"``, ``"y"``, ``"z"``), else None."""
        match = _ACC_RE.match(self.name)
        return match.group(2) if match else None

    @property
    def unit_si(self) -> str:
        """SI unit of the values returned by :func:`read_block`: ``"N"`` or ``"m/s^2"``."""
        return "N" if self.kind == "force" else "m/s^2"


@dataclass(frozen=True, eq=False)
class ArraySource:
    """Samples held in memory, in file units (CSV and UFF recordings).

    The simplest sample source (protocol in :mod:`guidefit.io`): ``read(index)``
    indexes the array, ``dtype`` is its dtype. The array should be read-only.

    Examples
    --------
    >>> src = ArraySource(np.arange(6.0).reshape(3, 2))
    >>> src.read((slice(1, 3), slice(None))).tolist(), src.dtype
    ([[2.0, 3.0], [4.0, 5.0]], dtype('float64'))
    """

    data: np.ndarray

    @property
    def dtype(self) -> np.dtype:
        """dtype of the stored samples."""
        return np.asarray(self.data).dtype

    def read(self, index: tuple) -> np.ndarray:
        """``data[index]`` (a view where numpy gives one)."""
        return self.data[index]


_ArraySource = ArraySource  # the name the UFF reader used before guidefit.io


@dataclass(frozen=True, eq=False)
class RunData:
    """One run held in memory, for :func:`write_recording` (e.g. built by the simulator).

    Parameters
    ----------
    name : str
        Run name; no ``/``, no line breaks, no surrounding white space.
    sample_rate_hz : float
        Sampling rate, Hz, > 0.
    excitation_direction : array_like, shape (3,)
        Unit vector; a positive force sample pushes the carriage along it.
    channel_names : sequence of str
        Exactly one ``"force"``; accelerations ``"acc_<point>_<axis>"``.
    units : sequence of str
        One per channel: ``"N"`` for force, ``"m/s^2"`` or ``"g"`` for accelerations.
    positions_m : array_like, shape (n_channels, 3)
        Sensor locations, m (see :func:`default_channel_geometry`).
    directions : array_like, shape (n_channels, 3)
        Unit vectors of the sensors' positive axes.
    data : ndarray or None
        Samples in the units of ``units``: ``(n_samples, n_channels)`` for
        ``signals``, ``(n_hits, n_samples, n_channels)`` for ``hits``. Real
        floats or integers; kept as given (not copied). None for a header only
        (for :func:`open_signals_writer`).
    layout : {"signals", "hits"} or None
        None: from ``data.ndim`` (2 -> signals, 3 -> hits; signals without data).
    excitation_position_m : array_like, shape (3,), optional
        Hit point, m.
    pretrigger_samples : int, optional
        Samples before the trigger in each hit.

    Equality compares every field by value (arrays with NaN == NaN, dtype ignored).

    Examples
    --------
    >>> import numpy as np
    >>> run = RunData("vertical", 200_000.0, [0, -1, 0], ["force", "acc_A_y"], ["N", "g"],
    ...               [[0, 0, 0], [0.03, 0, 0.045]], [[0, -1, 0], [0, 1, 0]],
    ...               data=np.zeros((4, 2)))
    >>> run.layout, run.n_samples, run.n_channels
    ('signals', 4, 2)
    """

    name: str
    sample_rate_hz: float
    excitation_direction: np.ndarray
    channel_names: tuple[str, ...]
    units: tuple[str, ...]
    positions_m: np.ndarray
    directions: np.ndarray
    data: np.ndarray | None = None
    layout: str | None = None
    excitation_position_m: np.ndarray | None = None
    pretrigger_samples: int | None = None

    def __post_init__(self):
        name = self.name
        if not isinstance(name, str) or not _valid_run_name(name):
            raise RecordingError(
                f"run name {name!r}: expected non-empty text without '/', line breaks "
                "or surrounding white space"
            )
        where = f"run '{name}'"
        set_ = object.__setattr__
        set_(self, "sample_rate_hz", _check_sample_rate(self.sample_rate_hz, where))
        set_(
            self,
            "excitation_direction",
            _frozen_array(
                _check_vector(self.excitation_direction, where, "excitation_direction", True)
            ),
        )
        if self.excitation_position_m is not None:
            pos = _check_vector(self.excitation_position_m, where, "excitation_position_m", False)
            pos = _check_position(pos, where, "excitation_position_m")
            set_(self, "excitation_position_m", _frozen_array(pos))
        names = _as_str_tuple(self.channel_names, where, "channel_names")
        units = _as_str_tuple(self.units, where, "units")
        channels, force_index = _build_channels(where, names, units, self.positions_m, self.directions)
        _check_force_axis(channels[force_index].direction, self.excitation_direction, where)
        set_(self, "channel_names", names)
        set_(self, "units", units)
        set_(self, "positions_m", _frozen_array([ch.position_m for ch in channels]))
        set_(self, "directions", _frozen_array([ch.direction for ch in channels]))
        layout = self.layout
        data = self.data
        if layout is None:
            layout = "hits" if data is not None and np.ndim(data) == 3 else "signals"
        if layout not in LAYOUTS:
            raise RecordingError(
                f"{where}: layout {layout!r} unknown; expected 'signals' or 'hits'"
            )
        set_(self, "layout", layout)
        if data is not None:
            data = np.asarray(data)
            _check_data_array(data, layout, len(names), where)
            set_(self, "data", data)
        if self.pretrigger_samples is not None:
            n = None if data is None else data.shape[-2]
            set_(self, "pretrigger_samples", _check_pretrigger(self.pretrigger_samples, n, where))

    __eq__ = _fields_equal
    __hash__ = None

    @property
    def n_channels(self) -> int:
        """Number of channels."""
        return len(self.channel_names)

    @property
    def n_samples(self) -> int | None:
        """Samples per record (None without data)."""
        return None if self.data is None else int(self.data.shape[-2])


@dataclass(frozen=True, eq=False)
class RecordingData:
    """A recording held in memory, for :func:`write_recording`.

    Parameters
    ----------
    runs : sequence of RunData
        At least one; names unique.
    guide : str or None
        Catalogue name of the guideway (``"MRB35"``); ``""`` is taken as None.
    description : str
        Free text.
    """

    runs: tuple[RunData, ...]
    guide: str | None = None
    description: str = ""

    def __post_init__(self):
        runs = self.runs
        if isinstance(runs, RunData):
            runs = (runs,)
        runs = tuple(runs)
        if not runs:
            raise RecordingError("recording: no runs; expected at least one RunData")
        for run in runs:
            if not isinstance(run, RunData):
                raise RecordingError(f"recording: runs must be RunData, got {type(run).__name__}")
        names = [r.name for r in runs]
        for name in names:
            if names.count(name) > 1:
                raise RecordingError(
                    f"recording: {names.count(name)} runs named '{name}'; names must be unique"
                )
        object.__setattr__(self, "runs", runs)
        guide = self.guide
        if guide is not None and not isinstance(guide, str):
            raise RecordingError(f"recording: guide must be text, got {guide!r}")
        object.__setattr__(self, "guide", guide or None)
        if not isinstance(self.description, str):
            raise RecordingError(f"recording: description must be text, got {self.description!r}")

    __eq__ = _fields_equal
    __hash__ = None


def _build_channels(where, names, units, positions, directions) -> tuple[tuple[Channel, ...], int]:
    """Validate the channel table; return the channels and the force column."""
    for name in names:
        if name == "force" or _ACC_RE.match(name):
            continue
        hint = ""
        if name.lower() == "force" or re.match(r"^acc_[a-z0-9]+_[xyz]$", name, re.IGNORECASE):
            hint = " (names are case-sensitive)"
        elif name == "time":
            hint = " (a CSV's 'time' column must be its first column)"
        shown = f"'{name}'" if name.isprintable() else repr(name)  # a line break in a name: one line still
        raise RecordingError(
            f"{where}: channel {shown} not recognised; expected 'force' or 'acc_<point>_<axis>' "
            f"with axis x, y or z, e.g. 'acc_A_y'{hint}"
        )
    n_force = names.count("force")
    if n_force == 0:
        raise RecordingError(f"{where}: channel 'force' missing; have {', '.join(names)}")
    if n_force > 1:
        raise RecordingError(f"{where}: {n_force} channels named 'force'; expected exactly one")
    for name in names:
        if names.count(name) > 1:
            raise RecordingError(
                f"{where}: channel '{name}' appears {names.count(name)} times; names must be unique"
            )
    n = len(names)
    if len(units) != n:
        raise RecordingError(f"{where}: {len(units)} units for {n} channels ({', '.join(names)})")
    scales = []
    for name, unit in zip(names, units):
        allowed = FORCE_UNITS if name == "force" else ACCELERATION_UNITS
        if unit not in allowed:
            expected = " or ".join(f"'{u}'" for u in allowed)
            raise RecordingError(
                f"{where}: channel '{name}': unit '{unit}' unknown; expected {expected}"
            )
        scales.append(allowed[unit])
    pos = _table(positions, n, where, "positions_m")
    for name, p in zip(names, pos):
        _check_position(p, where, f"channel '{name}': position")
    dirs = _table(directions, n, where, "directions")
    for name, d in zip(names, dirs):
        norm = float(np.linalg.norm(d))
        if abs(norm - 1.0) > UNIT_VECTOR_TOLERANCE:
            raise RecordingError(
                f"{where}: channel '{name}': direction {_fmt_vec(d)} has length {norm:.4g}; "
                f"expected a unit vector (tolerance {UNIT_VECTOR_TOLERANCE:g})"
            )
    channels = tuple(
        Channel(name, unit, p, d, s) for name, unit, p, d, s in zip(names, units, pos, dirs, scales)
    )
    return channels, names.index("force")
