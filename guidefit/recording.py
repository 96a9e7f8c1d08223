"""Read and write hammer-test recordings in the guidefit recording contract.

A recording is one file (HDF5 ``.h5``/``.hdf5`` or ``.csv``) holding one or
more *runs*; a run is one excitation set-up (hammer location and direction)
with a force channel and acceleration channels, stored either as one
continuous record (layout ``"signals"``, shape ``(n_samples, n_channels)``) or
as one pre-triggered record per hit (layout ``"hits"``, shape
``(n_hits, n_samples, n_channels)``). The contract is
``shared/recording-format.md``; ``docs/recordings.md`` is its user-facing
version.

This module does no signal processing. :func:`read_recording` validates the
whole file against the contract and returns a :class:`Recording` that holds
only metadata: the samples stay on disk and are read in slices by
:func:`read_block` (signals layout) and :func:`read_hit` (hits layout), which
open the file for each call, so a 4 GB recording is processed in bounded
memory; :func:`open_reader` keeps the file open for many such reads (what
:func:`guidefit.hits.iter_hits` uses). Both return float64 arrays in SI units
(N, m/s^2): a channel stored in ``g`` is multiplied by 9.80665 on read
(:attr:`Channel.scale_to_si`).
Non-finite samples (NaN, Inf) are *not* a reading error; they are found per
hit by :mod:`guidefit.hits`.

:func:`write_recording` writes the contract format from in-memory data
(:class:`RecordingData` of :class:`RunData`), and :func:`open_signals_writer`
writes one continuous run block by block, so a long recording can be
simulated without holding it in memory.

Every malformed input raises :class:`~guidefit.errors.RecordingError` with a
one-line message naming the file, the run, the channel or field, and what was
expected.
"""

from __future__ import annotations

import contextlib
import math
import os
import re
import sys
import time
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from guidefit.errors import GuidefitError, RecordingError

__all__ = [
    "ACCELERATION_UNITS",
    "FORCE_UNITS",
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "LAYOUTS",
    "STANDARD_GRAVITY",
    "Channel",
    "Recording",
    "RecordingData",
    "Run",
    "RunData",
    "RunReader",
    "SignalsWriter",
    "default_channel_geometry",
    "default_points",
    "open_reader",
    "open_signals_writer",
    "read_block",
    "read_hit",
    "read_recording",
    "write_recording",
]

FORMAT_NAME = "guidefit-recording"
FORMAT_VERSION = 1
STANDARD_GRAVITY = 9.80665
"""m/s^2 per g (the conventional standard gravity)."""
LAYOUTS = ("signals", "hits")
FORCE_UNITS = {"N": 1.0}
"""Allowed units of the force channel and their factor to SI."""
ACCELERATION_UNITS = {"m/s^2": 1.0, "g": STANDARD_GRAVITY}
"""Allowed units of acceleration channels and their factor to SI."""
UNIT_VECTOR_TOLERANCE = 1e-3
"""Largest allowed | |d| - 1 | of a direction vector."""

_HDF5_SUFFIXES = (".h5", ".hdf5")
_CSV_SUFFIXES = (".csv",)
_ACC_RE = re.compile(r"^acc_([A-Za-z0-9]+)_([xyz])$")
_AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}
_CHUNK_BYTES = 1 << 20  # target size of one HDF5 chunk
_COPY_ROWS = 1 << 18  # rows per block when copying a signals run

# Measuring points A-D of the MRB35 nominal model (physics notes, paper Figure 7).
_MRB35_POINTS_M = {
    "A": (0.030, 0.0, 0.045),
    "B": (-0.030, 0.0, 0.045),
    "C": (-0.030, 0.0, -0.045),
    "D": (0.030, 0.0, -0.045),
}


# --------------------------------------------------------------------------- data


def _frozen_array(value, dtype=np.float64) -> np.ndarray:
    arr = np.array(value, dtype=dtype, copy=True)
    arr.setflags(write=False)
    return arr


def _same(a: Any, b: Any) -> bool:
    """Equality that treats arrays by value (NaN equal to NaN)."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        if a is None or b is None:
            return False
        a, b = np.asarray(a), np.asarray(b)
        if a.shape != b.shape:
            return False
        if a.dtype.kind in "fc" or b.dtype.kind in "fc":
            return bool(np.array_equal(a, b, equal_nan=True))
        return bool(np.array_equal(a, b))
    if isinstance(a, tuple) and isinstance(b, tuple):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    return bool(a == b)


def _fields_equal(a, b) -> bool:
    if type(a) is not type(b):
        return NotImplemented
    return all(_same(getattr(a, f.name), getattr(b, f.name)) for f in fields(a))


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


@dataclass(frozen=True)
class _H5Source:
    """Where a run's samples live in an HDF5 file."""

    path: str  # absolute
    dataset: str  # e.g. "/runs/vertical/signals"
    dtype: str = "<f8"  # of the stored samples (numpy dtype string)


@dataclass(frozen=True, eq=False)
class _ArraySource:
    """Samples held in memory (CSV recordings), in file units."""

    data: np.ndarray


@dataclass(frozen=True, eq=False)
class Run:
    """One excitation set-up of a recording: metadata and a handle to its samples.

    The samples are not held in memory. Read them with :func:`read_block`
    (``layout == "signals"``) or :func:`read_hit` (``layout == "hits"``), or the
    equivalent methods :meth:`read_block` and :meth:`read_hit`.

    Attributes
    ----------
    name : str
        Run name (the HDF5 group name; for CSV the ``# run:`` line or the file stem).
    sample_rate_hz : float
        Sampling rate, Hz.
    excitation_direction : ndarray, shape (3,)
        Unit vector; a positive force sample pushes the carriage along it.
    excitation_position_m : ndarray, shape (3,), or None
        Hit point in the carriage frame, m, if the file gives it.
    channels : tuple of Channel
        In the column order of the data.
    layout : str
        ``"signals"`` (one continuous record) or ``"hits"`` (one record per hit).
    n_samples : int
        Samples per record: the whole run for ``signals``, per hit for ``hits``.
    n_hits_stored : int
        Number of stored hit records (``hits`` layout), 0 for ``signals``.
    pretrigger_samples : int or None
        Samples before the trigger in each stored hit, if the file says.
    source : object
        Private handle to the samples (file path and dataset, or an array).
    force_index : int
        Column of the force channel.
    file : str
        The recording's path as given to :func:`read_recording` (for messages).
    """

    name: str
    sample_rate_hz: float
    excitation_direction: np.ndarray
    excitation_position_m: np.ndarray | None
    channels: tuple[Channel, ...]
    layout: str
    n_samples: int
    n_hits_stored: int
    pretrigger_samples: int | None
    source: object = field(repr=False)
    force_index: int
    file: str = ""

    @property
    def n_channels(self) -> int:
        """Number of channels (columns)."""
        return len(self.channels)

    @property
    def channel_names(self) -> tuple[str, ...]:
        """Channel names in column order."""
        return tuple(ch.name for ch in self.channels)

    @property
    def force_channel(self) -> Channel:
        """The force channel."""
        return self.channels[self.force_index]

    @property
    def response_indices(self) -> tuple[int, ...]:
        """Columns of the acceleration channels."""
        return tuple(i for i, ch in enumerate(self.channels) if ch.kind == "acceleration")

    @property
    def sample_dtype(self) -> np.dtype:
        """dtype of the stored samples (float64 for CSV, whose text is parsed as float64)."""
        source = self.source
        if isinstance(source, _H5Source):
            return np.dtype(source.dtype)
        data = getattr(source, "data", None)
        return np.dtype(getattr(data, "dtype", np.float64))

    @property
    def scale_to_si(self) -> np.ndarray:
        """(n_channels,) factors from file units to SI."""
        return np.array([ch.scale_to_si for ch in self.channels])

    @property
    def duration_s(self) -> float:
        """Length of one record in seconds (the whole run for ``signals``)."""
        return self.n_samples / self.sample_rate_hz

    def read_block(self, start: int = 0, stop: int | None = None, channels=None) -> np.ndarray:
        """Same as :func:`read_block` ``(self, start, stop, channels)``."""
        return read_block(self, start, stop, channels)

    def read_hit(self, index: int, channels=None) -> np.ndarray:
        """Same as :func:`read_hit` ``(self, index, channels)``."""
        return read_hit(self, index, channels)

    def to_frame(self):
        """Channel table as a pandas DataFrame, one row per channel.

        Columns: ``name, kind, unit, scale_to_si, point, axis, x_m, y_m, z_m,
        dir_x, dir_y, dir_z``.
        """
        import pandas as pd

        rows = [
            {
                "name": ch.name,
                "kind": ch.kind,
                "unit": ch.unit,
                "scale_to_si": ch.scale_to_si,
                "point": ch.point,
                "axis": ch.axis,
                "x_m": ch.position_m[0],
                "y_m": ch.position_m[1],
                "z_m": ch.position_m[2],
                "dir_x": ch.direction[0],
                "dir_y": ch.direction[1],
                "dir_z": ch.direction[2],
            }
            for ch in self.channels
        ]
        return pd.DataFrame(rows)

    def to_data(self, si: bool = False) -> RunData:
        """Load the whole run into a :class:`RunData` (the samples in memory).

        Parameters
        ----------
        si : bool
            False (default): samples and ``units`` as stored in the file, with
            the file's dtype, so ``write_recording`` reproduces the file.
            True: float64 samples in SI and units ``N``/``m/s^2``.
        """
        if self.layout == "signals":
            data = _raw_read(self, (slice(0, self.n_samples), slice(None)))
        else:
            data = _raw_read(self, (slice(0, self.n_hits_stored), slice(None), slice(None)))
        units = tuple(ch.unit for ch in self.channels)
        if si:
            data = np.asarray(data, dtype=np.float64) * self.scale_to_si
            units = tuple(ch.unit_si for ch in self.channels)
        return RunData(
            name=self.name,
            sample_rate_hz=self.sample_rate_hz,
            excitation_direction=self.excitation_direction,
            channel_names=self.channel_names,
            units=units,
            positions_m=np.array([ch.position_m for ch in self.channels]),
            directions=np.array([ch.direction for ch in self.channels]),
            data=data,
            layout=self.layout,
            excitation_position_m=self.excitation_position_m,
            pretrigger_samples=self.pretrigger_samples,
        )


@dataclass(frozen=True, eq=False)
class Recording:
    """A validated recording file: root metadata and its runs.

    Attributes
    ----------
    path : str
        The path as given to :func:`read_recording`.
    guide : str or None
        Catalogue name of the guideway under test (``"MRB35"``), if given.
    description : str
        Free text, ``""`` if absent.
    runs : tuple of Run
        In file order.
    """

    path: str
    guide: str | None
    description: str
    runs: tuple[Run, ...]

    def run(self, name: str) -> Run:
        """The run called ``name``; RecordingError naming the runs there are."""
        for run in self.runs:
            if run.name == name:
                return run
        have = ", ".join(r.name for r in self.runs)
        raise RecordingError(f"{self.path}: no run '{name}'; have {have}")

    def to_frame(self):
        """Run table as a pandas DataFrame, one row per run."""
        import pandas as pd

        rows = []
        for run in self.runs:
            d = run.excitation_direction
            rows.append(
                {
                    "run": run.name,
                    "layout": run.layout,
                    "sample_rate_hz": run.sample_rate_hz,
                    "n_samples": run.n_samples,
                    "n_hits_stored": run.n_hits_stored,
                    "duration_s": run.duration_s,
                    "n_channels": run.n_channels,
                    "channels": " ".join(run.channel_names),
                    "excitation_direction": f"{d[0]:g} {d[1]:g} {d[2]:g}",
                }
            )
        return pd.DataFrame(rows)

    def to_data(self, si: bool = False) -> RecordingData:
        """Load every run into memory as :class:`RecordingData` (see :meth:`Run.to_data`)."""
        return RecordingData(
            runs=tuple(run.to_data(si=si) for run in self.runs),
            guide=self.guide,
            description=self.description,
        )


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
            set_(self, "excitation_position_m", _frozen_array(pos))
        names = _as_str_tuple(self.channel_names, where, "channel_names")
        units = _as_str_tuple(self.units, where, "units")
        channels, _ = _build_channels(where, names, units, self.positions_m, self.directions)
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


# ------------------------------------------------------------------ validation


def _valid_run_name(name: str) -> bool:
    return (
        bool(name)
        and name == name.strip()
        and "/" not in name
        and "\n" not in name
        and "\r" not in name
        and name not in (".", "..")
    )


def _check_sample_rate(value, where: str) -> float:
    arr = _numbers(value)
    if arr is None or arr.size != 1:
        raise RecordingError(
            f"{where}: sample_rate_hz is {_show(value)}; expected one positive number (Hz)"
        )
    rate = float(arr.reshape(-1)[0])
    if not math.isfinite(rate) or rate <= 0:
        raise RecordingError(
            f"{where}: sample_rate_hz is {rate:g}; expected a positive, finite number (Hz)"
        )
    return rate


def _check_vector(value, where: str, name: str, unit: bool) -> np.ndarray:
    arr = _numbers(value)
    if arr is None or arr.size != 3:
        raise RecordingError(f"{where}: {name} is {_show(value)}; expected 3 numbers")
    vec = arr.reshape(3)
    if not np.all(np.isfinite(vec)):
        raise RecordingError(f"{where}: {name} is {_fmt_vec(vec)}; expected finite numbers")
    if unit:
        norm = float(np.linalg.norm(vec))
        if abs(norm - 1.0) > UNIT_VECTOR_TOLERANCE:
            raise RecordingError(
                f"{where}: {name} {_fmt_vec(vec)} has length {norm:.4g}; expected a unit vector "
                f"(tolerance {UNIT_VECTOR_TOLERANCE:g})"
            )
    return vec


def _check_pretrigger(value, n_samples: int | None, where: str) -> int:
    arr = _numbers(value)
    ok = arr is not None and arr.size == 1 and float(arr.reshape(-1)[0]).is_integer()
    if ok:
        pre = int(arr.reshape(-1)[0])
        ok = pre >= 0 and (n_samples is None or pre < n_samples)
    if not ok:
        limit = "" if n_samples is None else f" below {n_samples}"
        raise RecordingError(
            f"{where}: pretrigger_samples is {_show(value)}; expected an integer >= 0{limit}"
        )
    return pre


def _check_data_array(data: np.ndarray, layout: str, n_channels: int, where: str) -> None:
    kind = data.dtype.kind
    if kind not in "fiu":
        raise RecordingError(
            f"{where}: data has dtype {data.dtype}; expected real numbers (float32, float64 or integers)"
        )
    want = 2 if layout == "signals" else 3
    shape_text = (
        "(n_samples, n_channels)" if layout == "signals" else "(n_hits, n_samples, n_channels)"
    )
    if data.ndim != want:
        raise RecordingError(
            f"{where}: {layout} data has shape {data.shape}; expected {shape_text}"
        )
    if data.shape[-1] != n_channels:
        raise RecordingError(
            f"{where}: {layout} data has {data.shape[-1]} columns for {n_channels} channel names"
        )


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
        raise RecordingError(
            f"{where}: channel '{name}' not recognised; expected 'force' or 'acc_<point>_<axis>' "
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


def _table(value, n: int, where: str, name: str) -> np.ndarray:
    arr = _numbers(value)
    if arr is None:
        raise RecordingError(f"{where}: {name} is {_show(value)}; expected numbers, shape ({n}, 3)")
    if arr.shape != (n, 3):
        raise RecordingError(
            f"{where}: {name} has shape {arr.shape}; expected ({n}, 3), one row per channel"
        )
    if not np.all(np.isfinite(arr)):
        row = int(np.flatnonzero(~np.all(np.isfinite(arr), axis=1))[0])
        raise RecordingError(
            f"{where}: {name} row {row} is {_fmt_vec(arr[row])}; expected finite numbers"
        )
    return arr


def _numbers(value) -> np.ndarray | None:
    """float64 array from a numeric value, or None if it is not real numbers."""
    if value is None or isinstance(value, (str, bytes, np.str_, np.bytes_)):
        return None
    try:
        arr = np.asarray(value)
    except (ValueError, TypeError):
        return None
    if arr.dtype.kind == "O":
        try:
            arr = np.asarray(value, dtype=np.float64)
        except (ValueError, TypeError):
            return None
    if arr.dtype.kind not in "iuf":
        return None
    return arr.astype(np.float64)


def _decode(value, where: str, name: str) -> str:
    if isinstance(value, (bytes, np.bytes_)):
        try:
            return bytes(value).decode("utf-8")
        except UnicodeDecodeError:
            raise RecordingError(f"{where}: {name} is not UTF-8 text") from None
    return str(value)


def _strings(value, where: str, name: str) -> list[str] | None:
    """Text attribute values as a list of str (h5py gives str, bytes or object arrays)."""
    if isinstance(value, (str, bytes, np.str_, np.bytes_)):
        return [_decode(value, where, name)]
    try:
        arr = np.asarray(value)
    except (ValueError, TypeError):
        return None
    if arr.dtype.kind not in "SUO" or arr.ndim > 1:
        return None
    out = []
    for item in arr.reshape(-1):
        if not isinstance(item, (str, bytes, np.str_, np.bytes_)):
            return None
        out.append(_decode(item, where, name))
    return out


def _as_str_tuple(value, where: str, name: str) -> tuple[str, ...]:
    if isinstance(value, (list, tuple)) and all(isinstance(v, str) for v in value):
        return tuple(value)
    out = _strings(value, where, name)
    if out is None:
        raise RecordingError(f"{where}: {name} is {_show(value)}; expected a list of text")
    return tuple(out)


def _show(value) -> str:
    if isinstance(value, (np.ndarray, np.generic)):
        value = value.tolist()
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _fmt_vec(vec) -> str:
    return "(" + ", ".join(f"{float(v):.6g}" for v in np.asarray(vec).reshape(-1)) + ")"


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else exc.__class__.__name__


# ------------------------------------------------------------- default layout


def default_points(guide_name: str | None = None) -> dict[str, np.ndarray]:
    """Default measuring points of a guide, for recordings that give no positions.

    Uses ``measuring_points_m`` of :func:`guidefit.model.guides.load_guide`
    when that module is present and the guide defines points; otherwise (and
    for ``guide_name=None``) the MRB35 layout of the nominal model:
    A (+0.030, 0, +0.045), B (-0.030, 0, +0.045), C (-0.030, 0, -0.045),
    D (+0.030, 0, -0.045) m.

    Parameters
    ----------
    guide_name : str or None
        Catalogue name (``"MRB35"``) or guide TOML path; None means MRB35.

    Returns
    -------
    dict of str to ndarray, shape (3,)
        Point name -> position in the carriage frame, m.

    Raises
    ------
    GuideError
        The guide catalogue exists but does not know ``guide_name``.

    Examples
    --------
    >>> pts = default_points()
    >>> sorted(pts), pts["A"].tolist()
    (['A', 'B', 'C', 'D'], [0.03, 0.0, 0.045])
    """
    load_guide = _guide_loader()
    if load_guide is not None:
        guide = load_guide(guide_name or "MRB35")
        points = getattr(guide, "measuring_points_m", None)
        if points:
            return {str(k): np.asarray(v, dtype=np.float64).reshape(3) for k, v in points.items()}
    return {k: np.array(v) for k, v in _MRB35_POINTS_M.items()}


def _guide_loader():
    """``guidefit.model.guides.load_guide`` if that module exists, else None."""
    import importlib
    import importlib.util

    try:
        spec = importlib.util.find_spec("guidefit.model.guides")
    except ModuleNotFoundError:
        return None
    if spec is None:
        return None
    return importlib.import_module("guidefit.model.guides").load_guide


def default_channel_geometry(
    channel_names: Sequence[str],
    excitation_direction,
    excitation_position_m=None,
    guide: str | None = None,
    points: Mapping[str, Any] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Positions and directions of channels from their names (the CSV defaults).

    ``acc_<point>_<axis>`` sits at the guide's default point (see
    :func:`default_points`) and points along +axis; ``force`` sits at
    ``excitation_position_m`` (the origin if None) and points along
    ``excitation_direction``.

    Parameters
    ----------
    channel_names : sequence of str
    excitation_direction : array_like, shape (3,)
    excitation_position_m : array_like, shape (3,), optional
    guide : str, optional
        Guide whose default points to use (None: MRB35).
    points : mapping, optional
        Point name -> position, m; overrides the guide's points.

    Returns
    -------
    positions_m, directions : ndarray, shape (n_channels, 3)

    Raises
    ------
    RecordingError
        A channel name does not follow the convention or names an unknown point.

    Examples
    --------
    >>> pos, dirs = default_channel_geometry(["force", "acc_B_x"], [0, -1, 0])
    >>> pos.tolist(), dirs.tolist()
    ([[0.0, 0.0, 0.0], [-0.03, 0.0, 0.045]], [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0]])
    """
    pts = (
        None if points is None else {k: np.asarray(v, float).reshape(3) for k, v in points.items()}
    )
    positions, directions = [], []
    for name in channel_names:
        if name == "force":
            pos = (
                np.zeros(3)
                if excitation_position_m is None
                else np.asarray(excitation_position_m, float)
            )
            positions.append(pos.reshape(3))
            directions.append(np.asarray(excitation_direction, float).reshape(3))
            continue
        match = _ACC_RE.match(name)
        if not match:
            raise RecordingError(
                f"channel '{name}' not recognised; expected 'force' or 'acc_<point>_<axis>' with axis x, y or z"
            )
        if pts is None:
            pts = default_points(guide)
        point, axis = match.groups()
        if point not in pts:
            raise RecordingError(
                f"channel '{name}': point '{point}' has no default position for guide "
                f"{guide or 'MRB35'} (known: {', '.join(sorted(pts))}); give positions_m"
            )
        positions.append(pts[point])
        directions.append(np.array(_AXES[axis]))
    return np.array(positions, dtype=float).reshape(-1, 3), np.array(
        directions, dtype=float
    ).reshape(-1, 3)


# --------------------------------------------------------------------- reading


def read_recording(path: str | os.PathLike) -> Recording:
    """Open and validate a recording; the samples stay on disk.

    Parameters
    ----------
    path : str or path-like
        ``.h5``/``.hdf5`` (HDF5, any number of runs) or ``.csv`` (one run).

    Returns
    -------
    Recording
        Metadata and one :class:`Run` per run; read samples with
        :func:`read_block` / :func:`read_hit`.

    Raises
    ------
    RecordingError
        Anything that does not follow the recording contract, as one line
        naming the file, the run, the channel or field and what was expected.

    Examples
    --------
    >>> import os, tempfile
    >>> import numpy as np
    >>> run = RunData("vertical", 1000.0, [0, -1, 0], ["force", "acc_A_y"], ["N", "g"],
    ...               [[0, 0, 0], [0.03, 0, 0.045]], [[0, -1, 0], [0, 1, 0]],
    ...               data=np.array([[0.0, 1.0], [2.0, 3.0], [4.0, 5.0]]))
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     path = os.path.join(folder, "rec.h5")
    ...     write_recording(path, RecordingData([run], guide="MRB35"))
    ...     rec = read_recording(path)
    ...     block = read_block(rec.runs[0], 1, 3)
    >>> rec.guide, rec.runs[0].name, rec.runs[0].layout, rec.runs[0].n_samples
    ('MRB35', 'vertical', 'signals', 3)
    >>> block.round(6).tolist()  # the acceleration was stored in g
    [[2.0, 29.41995], [4.0, 49.03325]]
    """
    display = os.fspath(path)
    p = Path(display)
    suffix = p.suffix.lower()
    if suffix in (".uff", ".unv"):  # UFF-58 time data, optional extra pyuff
        from guidefit.uff import read_uff_recording

        return read_uff_recording(path)
    if suffix not in _HDF5_SUFFIXES + _CSV_SUFFIXES:
        raise RecordingError(
            f"{display}: unknown file type '{p.suffix}'; expected .h5, .hdf5, .csv, .uff or .unv"
        )
    if not p.exists():
        raise RecordingError(f"{display}: no such file")
    if p.is_dir():
        raise RecordingError(f"{display}: is a directory; expected a recording file")
    if p.stat().st_size == 0:
        raise RecordingError(f"{display}: file is empty")
    if suffix in _CSV_SUFFIXES:
        return _read_csv(p, display)
    return _read_hdf5(p, display)


def _h5_open_error(p: Path, display: str, exc: OSError) -> RecordingError:
    import h5py

    message = _first_line(exc)
    truncated = re.search(r"truncated file: eof = (\d+).*stored_eof = (\d+)", message)
    if truncated:
        have, need = truncated.groups()
        return RecordingError(f"{display}: truncated HDF5 file: {have} of {need} bytes present")
    try:
        signature = h5py.is_hdf5(os.fspath(p))
    except OSError:
        signature = True
    if not signature:
        head = p.open("rb").read(64)
        hint = (
            " (it looks like text; a CSV recording needs the .csv suffix)" if _is_text(head) else ""
        )
        return RecordingError(f"{display}: not an HDF5 file (no HDF5 signature){hint}")
    return RecordingError(f"{display}: cannot open as HDF5 ({message})")


def _is_text(head: bytes) -> bool:
    try:
        head.decode("utf-8")
    except UnicodeDecodeError:
        return False
    return b"\x00" not in head


#: Seconds the HDF5 library may take to read a recording's metadata (attributes, groups,
#: a probe of the samples) before the file counts as damaged; env GUIDEFIT_HDF5_TIMEOUT_S
#: wins. 0: no guard, the metadata is read in this process. The command line sets 30 s;
#: the library default is 0, because the guard forks, and a fork is unsafe in a program
#: whose other threads may hold locks (the child would wait on them for good).
HDF5_METADATA_TIMEOUT_S = 0.0


def _read_hdf5(p: Path, display: str) -> Recording:
    """Read the structure; HDF5 library errors on a damaged file become one RecordingError.

    Some damaged files make the HDF5 library itself loop (a corrupted global
    heap: minutes or forever, holding the GIL, so no Python thread can stop
    it) or allocate gigabytes. With a timeout set (``HDF5_METADATA_TIMEOUT_S``
    or ``GUIDEFIT_HDF5_TIMEOUT_S``; the command line sets 30 s) and where the
    platform can fork (Linux), the metadata is read in a forked child that
    the parent gives up on after the timeout, or when it dies, with one
    RecordingError. The fork costs about 30 ms per file on the development
    machine (42 against 8 ms for the sample recording).
    """
    timeout = float(os.environ.get("GUIDEFIT_HDF5_TIMEOUT_S", HDF5_METADATA_TIMEOUT_S))
    if timeout > 0 and sys.platform.startswith("linux") and hasattr(os, "fork"):
        return _in_child(_read_hdf5_checked, p, display, timeout)
    return _read_hdf5_checked(p, display)


def _read_hdf5_checked(p: Path, display: str) -> Recording:
    try:
        return _read_hdf5_structure(p, display)
    except RecordingError:
        raise
    except (OSError, RuntimeError, KeyError, ValueError, TypeError) as exc:
        raise RecordingError(f"{display}: damaged HDF5 file ({_first_line(exc)})") from None


_CHILDREN: list[int] = []  # forked readers not reaped yet


def _reap(wait: bool, pid: int | None = None) -> int:
    """Reap finished forked readers (``wait``: all of them, or ``pid``, blocking); the
    wait status of ``pid`` (0 if not asked for)."""
    status_of_pid = 0
    for child in list(_CHILDREN):
        if pid is not None and child != pid:
            continue
        try:
            done, status = os.waitpid(child, 0 if wait else os.WNOHANG)
        except ChildProcessError:  # reaped elsewhere (e.g. a SIGCHLD handler)
            done, status = child, 0
        if done:
            _CHILDREN.remove(child)
            if child == pid:
                status_of_pid = status
    return status_of_pid


def _in_child(function, p: Path, display: str, timeout: float):
    """``function(p, display)`` in a forked child, its result or GuidefitError returned
    or raised here; a child that does not answer in time, or dies, is a RecordingError."""
    import pickle
    import select
    import signal

    _reap(wait=False)
    read_end, write_end = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: answer through the pipe, then leave without any cleanup
        status = 0
        try:
            os.close(read_end)
            try:
                answer = ("value", function(p, display))
            except GuidefitError as exc:
                answer = ("error", exc)
            except BaseException as exc:  # noqa: BLE001 - reported to the parent as it is
                answer = ("other", f"{type(exc).__name__}: {_first_line(exc)}")
            with os.fdopen(write_end, "wb") as out:
                pickle.dump(answer, out, protocol=pickle.HIGHEST_PROTOCOL)
        except BaseException:  # noqa: BLE001 - the parent sees an empty answer
            status = 1
        finally:
            os._exit(status)
    os.close(write_end)
    _CHILDREN.append(pid)
    chunks = []
    deadline = time.monotonic() + timeout
    answered = False
    try:
        with os.fdopen(read_end, "rb") as answer_file:
            while True:
                left = deadline - time.monotonic()
                ready = select.select([answer_file], [], [], left)[0] if left > 0 else []
                if not ready:
                    raise RecordingError(
                        f"{display}: damaged HDF5 file (the HDF5 library did not finish reading "
                        f"its metadata in {timeout:g} s)"
                    )
                chunk = os.read(answer_file.fileno(), 1 << 20)
                if not chunk:
                    break
                chunks.append(chunk)
        answered = True
    finally:
        if not answered:  # a timeout, or an interrupt: a looping child must not outlive us
            os.kill(pid, signal.SIGKILL)
            _reap(wait=True, pid=pid)
    if not chunks:
        status = _reap(wait=True, pid=pid)
        how = (f"signal {os.WTERMSIG(status)}" if os.WIFSIGNALED(status)
               else f"status {os.WEXITSTATUS(status)}")
        raise RecordingError(
            f"{display}: damaged HDF5 file (reading its metadata ended the reader with {how}; "
            "out of memory?)"
        )
    _reap(wait=False)  # the child is usually still tearing down: reaped by a later call
    kind, value = pickle.loads(b"".join(chunks))
    if kind == "value":
        return value
    if kind == "error":
        raise value
    raise RecordingError(f"{display}: damaged HDF5 file ({value})")


def _read_hdf5_structure(p: Path, display: str) -> Recording:
    import h5py

    try:
        f = h5py.File(p, "r")
    except OSError as exc:
        raise _h5_open_error(p, display, exc) from None
    with f:
        attrs = f.attrs
        if "format" not in attrs:
            raise RecordingError(
                f"{display}: root attribute 'format' missing; expected '{FORMAT_NAME}'"
            )
        fmt = _strings(attrs["format"], display, "format")
        if fmt is None or len(fmt) != 1 or fmt[0] != FORMAT_NAME:
            shown = _show(fmt[0] if fmt and len(fmt) == 1 else attrs["format"])
            raise RecordingError(
                f"{display}: root attribute 'format' is {shown}; expected '{FORMAT_NAME}'"
            )
        if "format_version" not in attrs:
            raise RecordingError(
                f"{display}: root attribute 'format_version' missing; expected {FORMAT_VERSION}"
            )
        _check_version(attrs["format_version"], display)
        guide = _optional_text(attrs, "guide", display) or None
        description = _optional_text(attrs, "description", display)
        runs_group = f.get("runs")
        if runs_group is None:
            raise RecordingError(
                f"{display}: group '/runs' missing; expected one group per run under /runs"
            )
        if not isinstance(runs_group, h5py.Group):
            raise RecordingError(
                f"{display}: '/runs' is not a group; expected one group per run under /runs"
            )
        names = list(runs_group.keys())
        if not names:
            raise RecordingError(
                f"{display}: '/runs' holds no runs; expected at least one run group"
            )
        runs = tuple(_read_hdf5_run(p, display, runs_group, name) for name in names)
    return Recording(path=display, guide=guide, description=description, runs=runs)


def _check_hit_range(run, first, last) -> None:
    """Stored hits ``first:last`` must be a non-empty integer range of the run's hits."""
    if not (
        isinstance(first, (int, np.integer))
        and isinstance(last, (int, np.integer))
        and 0 <= first < last <= run.n_hits_stored
    ):
        raise ValueError(
            f"first={first!r}, last={last!r}: expected 0 <= first < last <= {run.n_hits_stored} (run '{run.name}')"
        )


def _check_n_samples(run, n_samples) -> int:
    """Samples per hit to read: all (``None``) or 1..run.n_samples."""
    n = run.n_samples if n_samples is None else int(n_samples)
    if not 0 < n <= run.n_samples:
        raise ValueError(f"n_samples={n_samples!r}: expected 1..{run.n_samples} (run '{run.name}')")
    return n


def _check_version(value, where: str) -> None:
    arr = _numbers(value)
    if arr is None or arr.size != 1 or not float(arr.reshape(-1)[0]).is_integer():
        raise RecordingError(
            f"{where}: root attribute 'format_version' is {_show(value)}; expected {FORMAT_VERSION}"
        )
    version = int(arr.reshape(-1)[0])
    if version != FORMAT_VERSION:
        raise RecordingError(
            f"{where}: format_version {version} is not supported; this guidefit reads version {FORMAT_VERSION}"
        )


def _optional_text(attrs, name: str, where: str) -> str:
    import h5py

    if name not in attrs or isinstance(attrs[name], h5py.Empty):  # absent, or present without a value
        return ""
    text = _strings(attrs[name], where, name)
    if text is None or len(text) != 1:
        raise RecordingError(
            f"{where}: root attribute '{name}' is {_show(attrs[name])}; expected text"
        )
    return text[0]


def _read_hdf5_run(p: Path, display: str, runs_group, name: str) -> Run:
    import h5py

    where = f"{display}: run '{name}'"
    group = runs_group.get(name)
    if not isinstance(group, h5py.Group):
        raise RecordingError(
            f"{where}: not a group; expected a group holding a 'signals' or 'hits' dataset"
        )
    attrs = group.attrs
    if "sample_rate_hz" not in attrs:
        raise RecordingError(
            f"{where}: attribute 'sample_rate_hz' missing; expected the sampling rate in Hz"
        )
    rate = _check_sample_rate(attrs["sample_rate_hz"], where)
    if "excitation_direction" not in attrs:
        raise RecordingError(
            f"{where}: attribute 'excitation_direction' missing; expected a unit vector (3 numbers)"
        )
    exc_dir = _check_vector(attrs["excitation_direction"], where, "excitation_direction", True)
    exc_pos = None
    if "excitation_position_m" in attrs:
        exc_pos = _check_vector(
            attrs["excitation_position_m"], where, "excitation_position_m", False
        )
    present = [k for k in LAYOUTS if k in group]
    if not present:
        have = ", ".join(group.keys()) or "nothing"
        raise RecordingError(f"{where}: no dataset 'signals' or 'hits'; have {have}")
    if len(present) == 2:
        raise RecordingError(
            f"{where}: has both 'signals' and 'hits'; expected exactly one of them"
        )
    layout = present[0]
    ds = group.get(layout)
    if not isinstance(ds, h5py.Dataset):
        raise RecordingError(f"{where}: '{layout}' is not a dataset")
    if ds.dtype.kind not in "fiu":
        raise RecordingError(
            f"{where}: dataset '{layout}' has dtype {ds.dtype}; expected float32 or float64 "
            "(integers are accepted)"
        )
    want = 2 if layout == "signals" else 3
    if ds.ndim != want:
        shape_text = (
            "(n_samples, n_channels)" if layout == "signals" else "(n_hits, n_samples, n_channels)"
        )
        raise RecordingError(
            f"{where}: dataset '{layout}' has shape {ds.shape}; expected {shape_text}"
        )
    if 0 in ds.shape:
        raise RecordingError(
            f"{where}: dataset '{layout}' has shape {ds.shape}; it holds no samples"
        )
    n_channels = ds.shape[-1]
    dwhere = f"{where}: dataset '{layout}'"
    texts = {}
    for attr in ("channel_names", "units"):
        if attr not in ds.attrs:
            what = "channel name" if attr == "channel_names" else "unit"
            raise RecordingError(
                f"{dwhere}: attribute '{attr}' missing; expected one {what} per column"
            )
        values = _strings(ds.attrs[attr], dwhere, attr)
        if values is None:
            raise RecordingError(
                f"{dwhere}: attribute '{attr}' is {_show(ds.attrs[attr])}; expected a list of text"
            )
        if len(values) != n_channels:
            raise RecordingError(f"{dwhere}: {len(values)} {attr} for {n_channels} data columns")
        texts[attr] = values
    tables = {}
    for attr in ("positions_m", "directions"):
        if attr not in ds.attrs:
            raise RecordingError(
                f"{dwhere}: attribute '{attr}' missing; expected shape ({n_channels}, 3)"
            )
        tables[attr] = ds.attrs[attr]
    names = tuple(texts["channel_names"])
    channels, force_index = _build_channels(
        where, names, tuple(texts["units"]), tables["positions_m"], tables["directions"]
    )
    pretrigger = None
    if "pretrigger_samples" in ds.attrs:
        pretrigger = _check_pretrigger(ds.attrs["pretrigger_samples"], ds.shape[-2], dwhere)
    try:  # a cheap probe for data missing from a damaged file
        ds[(0,) * (ds.ndim - 1)]
        ds[tuple(s - 1 for s in ds.shape[:-1])]
    except (OSError, RuntimeError, KeyError) as exc:
        raise RecordingError(f"{dwhere}: samples cannot be read ({_first_line(exc)})") from None
    return Run(
        name=name,
        sample_rate_hz=rate,
        excitation_direction=_frozen_array(exc_dir),
        excitation_position_m=None if exc_pos is None else _frozen_array(exc_pos),
        channels=channels,
        layout=layout,
        n_samples=int(ds.shape[-2]),
        n_hits_stored=int(ds.shape[0]) if layout == "hits" else 0,
        pretrigger_samples=pretrigger,
        source=_H5Source(os.path.abspath(p), ds.name, ds.dtype.str),
        force_index=force_index,
        file=display,
    )


# ------------------------------------------------------------ sample access


def _raw_read(run: Run, index: tuple) -> np.ndarray:
    """Samples in file units with the file's dtype; ``index`` as for the dataset."""
    source = run.source
    if isinstance(source, _ArraySource):
        return source.data[index]
    if isinstance(source, _H5Source):
        import h5py

        try:
            with h5py.File(source.path, "r") as f:
                return f[source.dataset][index]
        except (OSError, KeyError, RuntimeError, ValueError, TypeError) as exc:
            raise RecordingError(
                f"{run.file or source.path}: run '{run.name}': cannot read samples ({_first_line(exc)})"
            ) from None
    raise TypeError(f"run '{run.name}': unknown sample source {type(source).__name__}")


def _column_index(run: Run, channels) -> tuple[Any, np.ndarray | None, np.ndarray]:
    """(index into the last axis, reorder or None, SI scale of the selected columns)."""
    scale = run.scale_to_si
    if channels is None:
        return slice(None), None, scale
    idx = np.asarray(channels, dtype=np.int64).reshape(-1)
    if idx.size == 0 or np.any(idx < 0) or np.any(idx >= run.n_channels):
        raise ValueError(
            f"channels={list(np.asarray(channels).reshape(-1))}: expected column indices in "
            f"0..{run.n_channels - 1} of run '{run.name}'"
        )
    if idx.size == 1:
        k = int(idx[0])
        return slice(k, k + 1), None, scale[idx]
    uniq, inverse = np.unique(idx, return_inverse=True)
    reorder = None if np.array_equal(uniq, idx) else inverse
    return list(uniq), reorder, scale[idx]


def _to_si(raw: np.ndarray, reorder, scale: np.ndarray) -> np.ndarray:
    out = np.asarray(raw, dtype=np.float64)
    if reorder is not None:
        out = out[..., reorder]
    if np.any(scale != 1.0):
        out = out * scale
    elif out is raw:
        out = out.copy()
    return np.ascontiguousarray(out)


def read_block(
    run: Run, start: int = 0, stop: int | None = None, channels: Sequence[int] | None = None
) -> np.ndarray:
    """Samples ``start:stop`` of a ``signals`` run, float64, SI units.

    Opens the file for this call only; memory is that of the block.

    Parameters
    ----------
    run : Run
        A run with ``layout == "signals"``.
    start, stop : int
        Sample range, ``0 <= start <= stop <= run.n_samples``; ``stop=None``
        means the end of the run.
    channels : sequence of int, optional
        Column indices to read (e.g. ``[run.force_index]``); all by default.

    Returns
    -------
    ndarray, shape (stop - start, n_selected_channels)
        float64, force in N, accelerations in m/s^2.

    Raises
    ------
    ValueError
        Wrong layout or a range outside the run.
    RecordingError
        The file can no longer be read.
    """
    if run.layout != "signals":
        raise ValueError(
            f"run '{run.name}' has layout '{run.layout}'; read its records with read_hit"
        )
    stop = run.n_samples if stop is None else stop
    if not (isinstance(start, (int, np.integer)) and isinstance(stop, (int, np.integer))):
        raise TypeError(f"start={start!r}, stop={stop!r}: expected integers")
    if not 0 <= start <= stop <= run.n_samples:
        raise ValueError(
            f"start={start}, stop={stop}: expected 0 <= start <= stop <= {run.n_samples} (run '{run.name}')"
        )
    cols, reorder, scale = _column_index(run, channels)
    raw = _raw_read(run, (slice(int(start), int(stop)), cols))
    return _to_si(raw, reorder, scale)


def read_hit(run: Run, index: int, channels: Sequence[int] | None = None) -> np.ndarray:
    """Stored hit record ``index`` of a ``hits`` run, float64, SI units.

    Parameters
    ----------
    run : Run
        A run with ``layout == "hits"``.
    index : int
        ``0 <= index < run.n_hits_stored``.
    channels : sequence of int, optional
        Column indices to read; all by default.

    Returns
    -------
    ndarray, shape (run.n_samples, n_selected_channels)
        float64, force in N, accelerations in m/s^2.

    Raises
    ------
    ValueError
        Wrong layout or index.
    RecordingError
        The file can no longer be read.
    """
    if run.layout != "hits":
        raise ValueError(f"run '{run.name}' has layout '{run.layout}'; read it with read_block")
    if not isinstance(index, (int, np.integer)):
        raise TypeError(f"index={index!r}: expected an integer")
    if not 0 <= index < run.n_hits_stored:
        raise ValueError(
            f"index={index!r}: expected an integer in 0..{run.n_hits_stored - 1} (run '{run.name}')"
        )
    cols, reorder, scale = _column_index(run, channels)
    raw = _raw_read(run, (int(index), slice(None), cols))
    return _to_si(raw, reorder, scale)



class RunReader:
    """Reads many blocks or hits of one run through one open file; see :func:`open_reader`.

    :meth:`read_block` and :meth:`read_hit` take the same arguments, check them
    the same way and return the same float64 SI arrays as the module functions
    :func:`read_block` and :func:`read_hit`; :meth:`read_hits` reads several
    stored hits at once.
    """

    def __init__(self, run: Run, dataset=None, direct=None):
        self._run = run
        self._ds = dataset  # open h5py dataset, or None for in-memory samples
        self._direct = direct  # low-level h5py DatasetID for read_hits_raw(out=...), or None

    @property
    def run(self) -> Run:
        """The run being read."""
        return self._run

    def _raw(self, index: tuple) -> np.ndarray:
        run = self._run
        if self._ds is None:
            return _raw_read(run, index)
        try:
            return self._ds[index]
        except (OSError, KeyError, RuntimeError, ValueError, TypeError) as exc:
            raise RecordingError(
                f"{run.file or run.source.path}: run '{run.name}': cannot read samples ({_first_line(exc)})"
            ) from None

    def read_block(
        self, start: int = 0, stop: int | None = None, channels: Sequence[int] | None = None
    ) -> np.ndarray:
        """Same as :func:`read_block` ``(run, start, stop, channels)``."""
        run = self._run
        if run.layout != "signals":
            raise ValueError(
                f"run '{run.name}' has layout '{run.layout}'; read its records with read_hit"
            )
        stop = run.n_samples if stop is None else stop
        if not (isinstance(start, (int, np.integer)) and isinstance(stop, (int, np.integer))):
            raise TypeError(f"start={start!r}, stop={stop!r}: expected integers")
        if not 0 <= start <= stop <= run.n_samples:
            raise ValueError(
                f"start={start}, stop={stop}: expected 0 <= start <= stop <= {run.n_samples} (run '{run.name}')"
            )
        cols, reorder, scale = _column_index(run, channels)
        return _to_si(self._raw((slice(int(start), int(stop)), cols)), reorder, scale)

    def read_hit(self, index: int, channels: Sequence[int] | None = None) -> np.ndarray:
        """Same as :func:`read_hit` ``(run, index, channels)``."""
        return self.read_hits(index, index + 1, channels, _name=index)[0]

    def read_hits(
        self,
        first: int,
        last: int,
        channels: Sequence[int] | None = None,
        n_samples: int | None = None,
        *,
        _name=None,
    ) -> np.ndarray:
        """Stored hits ``first:last`` of a ``hits`` run in one read, float64, SI units.

        Parameters
        ----------
        first, last : int
            ``0 <= first < last <= run.n_hits_stored``.
        channels : sequence of int, optional
            Column indices to read; all by default.
        n_samples : int, optional
            Read only the first ``n_samples`` samples of each hit (all by default).

        Returns
        -------
        ndarray, shape (last - first, n_samples, n_selected_channels)
            ``out[k]`` equals ``read_hit(run, first + k, channels)[:n_samples]``.
        """
        run = self._run
        if run.layout != "hits":
            raise ValueError(f"run '{run.name}' has layout '{run.layout}'; read it with read_block")
        if _name is not None:  # read_hit: its own messages
            if not isinstance(_name, (int, np.integer)):
                raise TypeError(f"index={_name!r}: expected an integer")
            if not 0 <= _name < run.n_hits_stored:
                raise ValueError(
                    f"index={_name!r}: expected an integer in 0..{run.n_hits_stored - 1} (run '{run.name}')"
                )
        else:
            _check_hit_range(run, first, last)
        n = _check_n_samples(run, n_samples)
        cols, reorder, scale = _column_index(run, channels)
        rows = slice(None) if n == run.n_samples else slice(0, n)
        if self._ds is not None and cols != slice(None):
            # HDF5 stores whole samples (all channels) together: reading them and
            # selecting columns here is faster than a strided HDF5 selection
            raw = self._raw((slice(int(first), int(last)), rows))[..., cols]
        else:
            raw = self._raw((slice(int(first), int(last)), rows, cols))
        return _to_si(raw, reorder, scale)

    def read_hits_raw(
        self, first: int, last: int, n_samples: int | None = None, out: np.ndarray | None = None
    ) -> np.ndarray:
        """Stored hits ``first:last`` as stored: all channels, file units and dtype.

        For callers that convert the samples themselves (e.g. straight into
        channel rows): ``float64(raw) * run.scale_to_si`` is, value for value,
        what :meth:`read_hits` returns.

        Parameters
        ----------
        first, last, n_samples
            As in :meth:`read_hits`.
        out : ndarray, optional
            C-contiguous array of shape (last - first, n_samples, n_channels)
            to read into (reused between calls, it saves allocating and
            first-touching a new array per read); its dtype should be the
            file's (:attr:`dtype`).

        Returns
        -------
        ndarray, shape (last - first, n_samples, n_channels)
            ``out`` if given; else a new array, or a read-only view of
            in-memory samples.
        """
        run = self._run
        if run.layout != "hits":
            raise ValueError(f"run '{run.name}' has layout '{run.layout}'; read it with read_block")
        _check_hit_range(run, first, last)
        n = _check_n_samples(run, n_samples)
        rows = slice(None) if n == run.n_samples else slice(0, n)
        index = (slice(int(first), int(last)), rows)
        if out is None:
            raw = self._raw(index)
            if self._ds is None:  # a view of the in-memory samples: read-only
                raw = np.asarray(raw).view()
                raw.flags.writeable = False
            return raw
        if out.shape != (int(last) - int(first), n, run.n_channels):
            raise ValueError(
                f"out has shape {out.shape}; expected {(int(last) - int(first), n, run.n_channels)}"
            )
        if self._ds is None:
            np.copyto(out, self._raw(index))
            return out
        if not out.flags.c_contiguous:
            raise ValueError("out must be C-contiguous")
        import h5py

        try:  # h5py's low-level read: a hyperslab of whole hits straight into ``out``
            dataset = self._direct if self._direct is not None else self._ds.id
            selection = dataset.get_space()
            selection.select_hyperslab((int(first), 0, 0), out.shape)
            dataset.read(h5py.h5s.create_simple(out.shape), selection, out)
        except (OSError, KeyError, RuntimeError, ValueError, TypeError) as exc:
            raise RecordingError(
                f"{run.file or run.source.path}: run '{run.name}': cannot read samples ({_first_line(exc)})"
            ) from None
        return out

    @property
    def dtype(self) -> np.dtype:
        """dtype of the stored samples."""
        if self._ds is not None:
            return self._ds.dtype
        return np.asarray(self._run.source.data).dtype


@contextlib.contextmanager
def open_reader(run: Run) -> Iterator[RunReader]:
    """Open ``run``'s file once for many reads (bounded memory, like :func:`read_block`).

    :func:`read_block` and :func:`read_hit` open the file for every call, which
    costs about as much as reading a short record; inside ``with
    open_reader(run) as reader:`` the calls ``reader.read_block(...)``,
    ``reader.read_hit(...)`` and ``reader.read_hits(...)`` share one open
    file and return exactly what the module functions return.

    Raises
    ------
    RecordingError
        The file can no longer be opened.

    Examples
    --------
    >>> import os, tempfile
    >>> import numpy as np
    >>> header = RunData("vertical", 1000.0, [0, -1, 0], ["force", "acc_A_y"], ["N", "g"],
    ...                  [[0, 0, 0], [0.03, 0, 0.045]], [[0, -1, 0], [0, 1, 0]],
    ...                  data=np.ones((3, 4, 2)), layout="hits")
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     write_recording(os.path.join(folder, "hits.h5"), header)
    ...     run = read_recording(os.path.join(folder, "hits.h5")).runs[0]
    ...     with open_reader(run) as reader:
    ...         one = reader.read_hit(2)
    ...         forces = reader.read_hits(0, 3, [run.force_index], n_samples=2)
    ...     same = np.array_equal(one, read_hit(run, 2))
    >>> same, forces.shape, one[0].tolist()
    (True, (3, 2, 1), [1.0, 9.80665])
    """
    source = run.source
    if not isinstance(source, _H5Source):
        if not isinstance(source, _ArraySource):
            raise TypeError(f"run '{run.name}': unknown sample source {type(source).__name__}")
        yield RunReader(run)
        return
    import h5py

    try:
        f = h5py.File(source.path, "r")
        try:
            ds = f[source.dataset]
            direct = None
            chunks = ds.chunks
            if run.layout == "hits" and chunks is not None and chunks[0] == 1 and chunks[2] == ds.shape[2]:
                # hits are read whole, so each chunk (consecutive samples of
                # one hit, all channels) is read once: without a chunk cache
                # HDF5 reads it straight into the output array instead of
                # through the cache (one copy less)
                access = h5py.h5p.create(h5py.h5p.DATASET_ACCESS)
                access.set_chunk_cache(0, 0, 1.0)
                direct = h5py.h5d.open(f.id, source.dataset.encode(), dapl=access)
        except BaseException:
            f.close()
            raise
    except (OSError, KeyError, RuntimeError, ValueError, TypeError) as exc:
        raise RecordingError(
            f"{run.file or source.path}: run '{run.name}': cannot read samples ({_first_line(exc)})"
        ) from None
    try:
        yield RunReader(run, ds, direct)
    finally:
        f.close()


# ------------------------------------------------------------------------- CSV

_NUMBER_RE = re.compile(
    r"^[+-]?((\d+\.?\d*|\.\d+)([eE][+-]?\d+)?|nan|inf|infinity)$", re.IGNORECASE
)
_DECIMAL_COMMA_RE = re.compile(r"^[+-]?\d+,\d+([eE][+-]?\d+)?$")
_CSV_KEYS = (
    "format",
    "format_version",
    "guide",
    "description",
    "run",
    "sample_rate_hz",
    "excitation_direction",
    "excitation_position_m",
    "units",
    "positions_m",
    "directions",
    "pretrigger_samples",
)


def _read_csv(p: Path, display: str) -> Recording:
    raw = p.read_bytes()
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise RecordingError(
            f"{display}: not UTF-8 text (byte {exc.start}); expected a CSV text file"
        ) from None
    if "\x00" in text:
        raise RecordingError(
            f"{display}: contains NUL bytes; expected a CSV text file (is it HDF5? use .h5)"
        )
    lines = text.splitlines()
    meta: dict[str, tuple[str, int]] = {}
    i = 0
    while i < len(lines):
        stripped = lines[i].strip()
        if not stripped:
            i += 1
            continue
        if not stripped.startswith("#"):
            break
        body = stripped[1:].strip()
        if ":" in body:
            key, value = body.split(":", 1)
            key = key.strip().lower()
            if key in _CSV_KEYS:
                if key in meta and meta[key][0] != value.strip():
                    raise RecordingError(
                        f"{display}: line {i + 1} '{key}': given again as '{_clip(value.strip())}' (line {meta[key][1]}: "
                        f"'{_clip(meta[key][0])}'); expected each key once"
                    )
                meta.setdefault(key, (value.strip(), i + 1))
        i += 1
    if i >= len(lines):
        raise RecordingError(
            f"{display}: no header row; expected a line of channel names such as 'time,force,acc_A_y'"
        )
    header_no = i + 1
    names, has_time = _csv_header(lines[i], header_no, display)
    data_lines = lines[i + 1 :]
    if not any(line.strip() for line in data_lines):
        raise RecordingError(f"{display}: no data rows after the header (line {header_no})")
    table = _csv_numbers(data_lines, header_no + 1, names, display)

    def line_of(key):
        return f"{display}: line {meta[key][1]} '{key}'"

    if "format" in meta and meta["format"][0] != FORMAT_NAME:
        raise RecordingError(
            f"{line_of('format')}: '{meta['format'][0]}'; expected '{FORMAT_NAME}'"
        )
    if "format_version" in meta:
        value = meta["format_version"][0]
        if value.strip() != str(FORMAT_VERSION):
            raise RecordingError(
                f"{line_of('format_version')}: '{value}' is not supported; this guidefit reads version {FORMAT_VERSION}"
            )
    guide = meta.get("guide", ("", 0))[0] or None
    description = meta.get("description", ("", 0))[0]
    run_name = meta.get("run", ("", 0))[0] or p.stem
    if not _valid_run_name(run_name):
        raise RecordingError(
            f"{display}: run name '{run_name}' not allowed; expected text without '/'"
        )

    rate = None
    if "sample_rate_hz" in meta:
        rate = _check_sample_rate(
            _csv_float(meta["sample_rate_hz"][0], line_of("sample_rate_hz")),
            line_of("sample_rate_hz"),
        )
    if has_time:
        rate = _csv_time_rate(table[:, 0], rate, display)
        table = table[:, 1:]
        names = names[1:]
    elif rate is None:
        raise RecordingError(
            f"{display}: sample rate unknown; expected a '# sample_rate_hz: ...' line or a first column 'time'"
        )
    if not names:
        raise RecordingError(
            f"{display}: no channels besides 'time'; expected 'force' and accelerations"
        )
    if "excitation_direction" not in meta:
        raise RecordingError(
            f"{display}: excitation_direction missing; expected a line such as '# excitation_direction: 0 -1 0'"
        )
    exc_dir = _check_vector(
        _csv_floats(*meta["excitation_direction"], display, "excitation_direction"),
        line_of("excitation_direction"),
        "excitation_direction",
        True,
    )
    exc_pos = None
    if "excitation_position_m" in meta:
        exc_pos = _check_vector(
            _csv_floats(*meta["excitation_position_m"], display, "excitation_position_m"),
            line_of("excitation_position_m"),
            "excitation_position_m",
            False,
        )
    n = len(names)
    if "units" in meta:
        units = [u for u in re.split(r"[\s,;]+", meta["units"][0]) if u]
        if has_time and len(units) == n + 1:
            if units[0] != "s":
                raise RecordingError(
                    f"{line_of('units')}: unit of 'time' is '{units[0]}'; expected 's'"
                )
            units = units[1:]
        if len(units) != n:
            raise RecordingError(
                f"{line_of('units')}: {len(units)} units for {n} channels ({', '.join(names)})"
            )
    else:
        units = ["N" if name == "force" else "m/s^2" for name in names]

    # names and units first, so their errors win over a missing default point
    placeholder = np.tile([1.0, 0.0, 0.0], (n, 1))
    _build_channels(display, tuple(names), tuple(units), placeholder, placeholder)
    if "positions_m" in meta:
        positions = _csv_floats(*meta["positions_m"], display, "positions_m", 3 * n).reshape(n, 3)
        known = {m.group(1): (0.0, 0.0, 0.0) for m in map(_ACC_RE.match, names) if m}
    else:
        positions = known = None
    try:  # `known` stands in for the guide's points when the positions are given
        default_pos, default_dir = default_channel_geometry(
            names, exc_dir, exc_pos, guide=guide, points=known
        )
    except GuidefitError as exc:
        raise RecordingError(f"{display}: {exc}") from None
    if positions is None:
        positions = default_pos
    if "directions" in meta:
        directions = _csv_floats(*meta["directions"], display, "directions", 3 * n).reshape(n, 3)
    else:
        directions = default_dir
    channels, force_index = _build_channels(
        display, tuple(names), tuple(units), positions, directions
    )
    pretrigger = None
    if "pretrigger_samples" in meta:
        value = _csv_float(meta["pretrigger_samples"][0], line_of("pretrigger_samples"))
        pretrigger = _check_pretrigger(value, table.shape[0], line_of("pretrigger_samples"))
    data = np.ascontiguousarray(table)
    data.setflags(write=False)
    run = Run(
        name=run_name,
        sample_rate_hz=rate,
        excitation_direction=_frozen_array(exc_dir),
        excitation_position_m=None if exc_pos is None else _frozen_array(exc_pos),
        channels=channels,
        layout="signals",
        n_samples=int(data.shape[0]),
        n_hits_stored=0,
        pretrigger_samples=pretrigger,
        source=_ArraySource(data),
        force_index=force_index,
        file=display,
    )
    return Recording(path=display, guide=guide, description=description, runs=(run,))


def _csv_header(line: str, line_no: int, display: str) -> tuple[list[str], bool]:
    where = f"{display}: line {line_no} (header)"
    if ";" in line:
        raise RecordingError(
            f"{where}: fields separated by ';'; expected ',' between fields and '.' as decimal mark"
        )
    fields_ = [f.strip().strip('"').strip("'").strip() for f in line.split(",")]
    if len(fields_) == 1 and "\t" in line:
        raise RecordingError(f"{where}: fields separated by tabs; expected ',' between fields")
    if _NUMBER_RE.match(fields_[0]) or _DECIMAL_COMMA_RE.match(fields_[0]):
        raise RecordingError(
            f"{where}: starts with a number; expected a header row of channel names such as 'time,force,acc_A_y'"
        )
    if len(fields_) == 1 and len(line.split()) > 1:
        raise RecordingError(f"{where}: fields separated by spaces; expected ',' between fields")
    for k, name in enumerate(fields_):
        if not name:
            raise RecordingError(f"{where}: column {k + 1} has no name; expected a channel name")
    has_time = fields_[0].lower() == "time"
    if has_time:
        fields_[0] = "time"
    return fields_, has_time


def _csv_numbers(
    data_lines: list[str], first_no: int, names: list[str], display: str
) -> np.ndarray:
    """Parse the data rows; on any problem, find the first bad line and name it."""
    n = len(names)
    try:
        table = np.loadtxt(data_lines, delimiter=",", comments=None, dtype=np.float64, ndmin=2)
    except ValueError as exc:
        raise _csv_locate_error(data_lines, first_no, names, display, exc) from None
    if table.shape[1] != n:
        raise _csv_locate_error(data_lines, first_no, names, display, None)
    return table


def _csv_locate_error(data_lines, first_no, names, display, exc) -> RecordingError:
    n = len(names)
    comma_hint = "decimal commas? guidefit expects '.' as the decimal mark and ',' between fields"
    for k, line in enumerate(data_lines):
        stripped = line.strip()
        if not stripped:
            continue
        no = first_no + k
        where = f"{display}: line {no}"
        if stripped.startswith("#"):
            return RecordingError(
                f"{where}: '#' line after the header; metadata lines must come before the header"
            )
        if ";" in stripped:
            return RecordingError(
                f"{where}: fields separated by ';'; expected ',' between fields and '.' as decimal mark"
            )
        tokens = [t.strip() for t in line.split(",")]
        if len(tokens) != n:
            hint = (
                comma_hint
                if len(tokens) > n and re.search(r"\d,\d", line)
                else "expected one value per column"
            )
            return RecordingError(f"{where}: {len(tokens)} fields, header has {n} ({hint})")
        for name, token in zip(names, tokens):
            cwhere = f"{where}, column '{name}'"
            if not token:
                return RecordingError(
                    f"{cwhere}: missing value; expected a number (write 'nan' for a bad sample)"
                )
            if not _NUMBER_RE.match(token):
                return RecordingError(f"{cwhere}: '{_clip(token)}' is not a number")
    detail = _first_line(exc) if exc is not None else "unexpected table shape"
    return RecordingError(f"{display}: cannot read the data rows ({detail})")


def _clip(text: str, width: int = 30) -> str:
    return text if len(text) <= width else text[: width - 3] + "..."


def _csv_float(value: str, where: str) -> float:
    token = value.strip()
    if _NUMBER_RE.match(token):
        return float(token)
    if _DECIMAL_COMMA_RE.match(token):
        raise RecordingError(
            f"{where}: '{token}' has a decimal comma; expected '.' as the decimal mark"
        )
    raise RecordingError(f"{where}: '{_clip(token)}' is not a number")


def _csv_floats(value: str, line_no: int, display: str, key: str, count: int = 3) -> np.ndarray:
    where = f"{display}: line {line_no} '{key}'"
    tokens = [t for t in re.split(r"[\s,;]+", value.strip().strip("[]()")) if t]
    bad = [t for t in tokens if not _NUMBER_RE.match(t)]
    if bad:
        raise RecordingError(
            f"{where}: '{_clip(bad[0])}' is not a number; expected {count} numbers"
        )
    if len(tokens) != count:
        hint = " (decimal commas? use '.')" if "," in value else ""
        raise RecordingError(f"{where}: {len(tokens)} numbers; expected {count}{hint}")
    return np.array([float(t) for t in tokens])


def _csv_time_rate(time: np.ndarray, rate: float | None, display: str) -> float:
    where = f"{display}: column 'time'"
    if not np.all(np.isfinite(time)):
        raise RecordingError(f"{where}: holds non-finite values; expected times in seconds")
    if time.size < 2:
        if rate is None:
            raise RecordingError(
                f"{where}: one row cannot give a sample rate; add '# sample_rate_hz: ...'"
            )
        return rate
    steps = np.diff(time)
    if np.any(steps <= 0):
        row = int(np.flatnonzero(steps <= 0)[0]) + 1
        raise RecordingError(
            f"{where}: not increasing at data row {row + 1}; expected equally spaced times"
        )
    k = np.arange(time.size, dtype=np.float64)
    kc = k - k.mean()
    tc = time - time.mean()
    fs = float(np.dot(kc, kc) / np.dot(kc, tc))  # least-squares slope of k over t
    deviation = float(np.max(np.abs(tc - kc / fs))) * fs
    if deviation > 0.1:
        raise RecordingError(
            f"{where}: spacing not uniform (a sample is {deviation:.2g} sample periods off); expected a constant sample rate"
        )
    if rate is None:
        return fs
    deviation = float(np.max(np.abs(time - time[0] - k / rate))) * rate
    if deviation > 0.5:
        raise RecordingError(
            f"{where}: spacing gives {fs:.6g} Hz but sample_rate_hz says {rate:.6g} Hz; expected them to agree"
        )
    return rate


# ---------------------------------------------------------------------- writing


def write_recording(path: str | os.PathLike, recording, *, compression: str | None = None) -> None:
    """Write a recording in the contract format (HDF5 or CSV by suffix).

    The file is written under a temporary name and renamed when complete, so
    a failed write leaves no partial file.

    Parameters
    ----------
    path : str or path-like
        ``.h5``/``.hdf5`` (any number of runs, both layouts) or ``.csv`` (one
        ``signals`` run; a ``time`` column is written as well).
    recording : RecordingData, RunData or Recording
        In-memory data (a single RunData is one run), or a recording read with
        :func:`read_recording` (copied in blocks for HDF5, samples in their
        stored units).
    compression : str, optional
        HDF5 filter for the datasets, e.g. ``"gzip"``.

    Raises
    ------
    RecordingError
        The data cannot be written in that format.

    Examples
    --------
    >>> import os, tempfile
    >>> import numpy as np
    >>> run = RunData("lateral", 200_000.0, [1, 0, 0], ["force", "acc_A_x"], ["N", "m/s^2"],
    ...               [[0, 0, 0], [0.03, 0, 0.045]], [[1, 0, 0], [1, 0, 0]],
    ...               data=np.zeros((3, 16, 2), dtype=np.float32), pretrigger_samples=4)
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     write_recording(os.path.join(folder, "rec.h5"), run)
    ...     back = read_recording(os.path.join(folder, "rec.h5")).to_data()
    >>> back.runs[0] == run
    True
    """
    display = os.fspath(path)
    p = Path(display)
    suffix = p.suffix.lower()
    if suffix not in _HDF5_SUFFIXES + _CSV_SUFFIXES:
        raise RecordingError(
            f"{display}: unknown file type '{p.suffix}'; expected .h5, .hdf5 or .csv"
        )
    if isinstance(recording, RunData):
        recording = RecordingData((recording,))
    if suffix in _CSV_SUFFIXES:
        if isinstance(recording, Recording):
            recording = recording.to_data()
        if not isinstance(recording, RecordingData):
            raise TypeError(
                f"recording: expected RecordingData, RunData or Recording, got {type(recording).__name__}"
            )
        _atomic(p, lambda tmp: _write_csv(tmp, display, recording))
        return
    if not isinstance(recording, (RecordingData, Recording)):
        raise TypeError(
            f"recording: expected RecordingData, RunData or Recording, got {type(recording).__name__}"
        )
    _atomic(p, lambda tmp: _write_hdf5(tmp, display, recording, compression))


def _atomic(p: Path, write) -> None:
    tmp = p.with_name(p.name + ".part")
    try:
        write(tmp)
        os.replace(tmp, p)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


def _chunk_rows(n_channels: int, itemsize: int) -> int:
    return max(1, _CHUNK_BYTES // max(1, n_channels * itemsize))


def _file_dtype(dtype) -> np.dtype:
    dtype = np.dtype(dtype)
    if dtype == np.float32 or dtype == np.float64:
        return dtype
    return (
        np.dtype(np.float32) if dtype.kind == "f" and dtype.itemsize < 4 else np.dtype(np.float64)
    )


def _write_root(f, guide: str | None, description: str) -> None:
    f.attrs["format"] = FORMAT_NAME
    f.attrs["format_version"] = np.int64(FORMAT_VERSION)
    if guide:
        f.attrs["guide"] = guide
    if description:
        f.attrs["description"] = description


def _create_run(runs_group, header, layout: str, shape: tuple, dtype, compression, resizable=False):
    """Create /runs/<name> and its dataset with the contract's attributes."""
    import h5py

    group = runs_group.create_group(header["name"])
    group.attrs["sample_rate_hz"] = np.float64(header["sample_rate_hz"])
    group.attrs["excitation_direction"] = np.asarray(header["excitation_direction"], np.float64)
    if header["excitation_position_m"] is not None:
        group.attrs["excitation_position_m"] = np.asarray(
            header["excitation_position_m"], np.float64
        )
    n_channels = shape[-1]
    rows = _chunk_rows(n_channels, dtype.itemsize)
    if not resizable:
        rows = min(max(1, shape[-2]), rows)
    if resizable:
        ds = group.create_dataset(
            layout,
            shape=shape,
            maxshape=(None, n_channels),
            dtype=dtype,
            chunks=(rows, n_channels),
            compression=compression,
        )
    else:
        chunks = (rows, n_channels) if layout == "signals" else (1, rows, n_channels)
        ds = group.create_dataset(
            layout, shape=shape, dtype=dtype, chunks=chunks, compression=compression
        )
    text = h5py.string_dtype()
    ds.attrs.create("channel_names", list(header["channel_names"]), dtype=text)
    ds.attrs.create("units", list(header["units"]), dtype=text)
    ds.attrs["positions_m"] = np.asarray(header["positions_m"], np.float64)
    ds.attrs["directions"] = np.asarray(header["directions"], np.float64)
    if header["pretrigger_samples"] is not None:
        ds.attrs["pretrigger_samples"] = np.int64(header["pretrigger_samples"])
    return ds


def _header(run) -> dict:
    if isinstance(run, RunData):
        return {
            "name": run.name,
            "sample_rate_hz": run.sample_rate_hz,
            "excitation_direction": run.excitation_direction,
            "excitation_position_m": run.excitation_position_m,
            "channel_names": run.channel_names,
            "units": run.units,
            "positions_m": run.positions_m,
            "directions": run.directions,
            "pretrigger_samples": run.pretrigger_samples,
        }
    return {
        "name": run.name,
        "sample_rate_hz": run.sample_rate_hz,
        "excitation_direction": run.excitation_direction,
        "excitation_position_m": run.excitation_position_m,
        "channel_names": run.channel_names,
        "units": tuple(ch.unit for ch in run.channels),
        "positions_m": np.array([ch.position_m for ch in run.channels]),
        "directions": np.array([ch.direction for ch in run.channels]),
        "pretrigger_samples": run.pretrigger_samples,
    }


def _write_hdf5(tmp: Path, display: str, recording, compression) -> None:
    import h5py

    try:
        f = h5py.File(tmp, "w")
    except OSError as exc:
        raise RecordingError(f"{display}: cannot create file ({_first_line(exc)})") from None
    with f:
        _write_root(f, recording.guide, recording.description)
        runs_group = f.create_group("runs", track_order=True)
        for run in recording.runs:
            if isinstance(run, RunData):
                if run.data is None:
                    raise RecordingError(f"{display}: run '{run.name}': no data to write")
                data = run.data
                if 0 in data.shape:
                    raise RecordingError(
                        f"{display}: run '{run.name}': data has shape {data.shape}; it holds no samples"
                    )
                dtype = _file_dtype(data.dtype)
                ds = _create_run(
                    runs_group, _header(run), run.layout, data.shape, dtype, compression
                )
                ds[...] = data
            else:  # a Run read from a file: copy block by block in stored units
                dtype = _file_dtype(_source_dtype(run))
                if run.layout == "signals":
                    shape = (run.n_samples, run.n_channels)
                    ds = _create_run(runs_group, _header(run), "signals", shape, dtype, compression)
                    for start in range(0, run.n_samples, _COPY_ROWS):
                        stop = min(run.n_samples, start + _COPY_ROWS)
                        ds[start:stop] = _raw_read(run, (slice(start, stop), slice(None)))
                else:
                    shape = (run.n_hits_stored, run.n_samples, run.n_channels)
                    ds = _create_run(runs_group, _header(run), "hits", shape, dtype, compression)
                    for i in range(run.n_hits_stored):
                        ds[i] = _raw_read(run, (i, slice(None), slice(None)))


def _source_dtype(run: Run) -> np.dtype:
    source = run.source
    if isinstance(source, _ArraySource):
        return source.data.dtype
    import h5py

    with h5py.File(source.path, "r") as f:
        return f[source.dataset].dtype


def _write_csv(tmp: Path, display: str, recording: RecordingData) -> None:
    if len(recording.runs) != 1:
        raise RecordingError(
            f"{display}: a CSV file holds one run, the recording has {len(recording.runs)}; write .h5 or one CSV per run"
        )
    run = recording.runs[0]
    if run.layout != "signals":
        raise RecordingError(
            f"{display}: run '{run.name}': CSV holds one continuous record; write 'hits' runs to .h5"
        )
    if run.data is None or run.data.shape[0] == 0:
        raise RecordingError(f"{display}: run '{run.name}': no samples to write")
    for key, value in (("guide", recording.guide or ""), ("description", recording.description)):
        if "\n" in value or "\r" in value:
            raise RecordingError(
                f"{display}: {key} contains a line break; CSV metadata is one line each"
            )

    def vec(v) -> str:
        return " ".join(repr(float(x)) for x in np.asarray(v).reshape(-1))

    lines = [f"# format: {FORMAT_NAME}", f"# format_version: {FORMAT_VERSION}"]
    if recording.guide:
        lines.append(f"# guide: {recording.guide}")
    if recording.description:
        lines.append(f"# description: {recording.description}")
    lines.append(f"# run: {run.name}")
    lines.append(f"# sample_rate_hz: {run.sample_rate_hz!r}")
    lines.append(f"# excitation_direction: {vec(run.excitation_direction)}")
    if run.excitation_position_m is not None:
        lines.append(f"# excitation_position_m: {vec(run.excitation_position_m)}")
    lines.append(f"# units: {' '.join(run.units)}")
    lines.append("# positions_m: " + "; ".join(vec(row) for row in run.positions_m))
    lines.append("# directions: " + "; ".join(vec(row) for row in run.directions))
    if run.pretrigger_samples is not None:
        lines.append(f"# pretrigger_samples: {run.pretrigger_samples}")
    lines.append(",".join(("time",) + run.channel_names))
    data = np.asarray(run.data, dtype=np.float64)
    time = np.arange(data.shape[0]) / run.sample_rate_hz
    try:
        with open(tmp, "w", encoding="utf-8", newline="\n") as fh:
            fh.write("\n".join(lines) + "\n")
            np.savetxt(
                fh,
                np.column_stack([time, data]),
                delimiter=",",
                fmt=["%.10g"] + ["%.17g"] * data.shape[1],
            )
    except OSError as exc:
        raise RecordingError(f"{display}: cannot write ({_first_line(exc)})") from None


class SignalsWriter:
    """Appends sample blocks to a ``signals`` run; made by :func:`open_signals_writer`."""

    def __init__(self, dataset, run: RunData, display: str):
        self._ds = dataset
        self._run = run
        self._display = display

    @property
    def n_samples(self) -> int:
        """Samples written so far."""
        return int(self._ds.shape[0])

    def append(self, block) -> None:
        """Append ``block`` of shape (n, n_channels), in the run's units.

        Raises
        ------
        RecordingError
            Wrong shape or dtype.
        """
        block = np.asarray(block)
        where = f"{self._display}: run '{self._run.name}'"
        if block.dtype.kind not in "fiu":
            raise RecordingError(f"{where}: block has dtype {block.dtype}; expected real numbers")
        n_channels = self._run.n_channels
        if block.ndim != 2 or block.shape[1] != n_channels:
            raise RecordingError(
                f"{where}: block has shape {block.shape}; expected (n, {n_channels})"
            )
        if block.shape[0] == 0:
            return
        n = self._ds.shape[0]
        self._ds.resize(n + block.shape[0], axis=0)
        self._ds[n:] = block


@contextlib.contextmanager
def open_signals_writer(
    path: str | os.PathLike,
    run: RunData,
    *,
    guide: str | None = None,
    description: str = "",
    mode: str = "w",
    dtype=None,
    compression: str | None = None,
) -> Iterator[SignalsWriter]:
    """Write one ``signals`` run block by block (bounded memory), HDF5 only.

    Parameters
    ----------
    path : str or path-like
        ``.h5`` or ``.hdf5``.
    run : RunData
        Header of the run (``layout="signals"``); its ``data``, if any, is
        written first.
    guide, description : str, optional
        Root attributes (``mode="w"`` only).
    mode : {"w", "a"}
        ``"w"``: a new file, which appears under ``path`` only when the block
        ends without error. ``"a"``: add the run to an existing recording (on
        error the run is removed again).
    dtype : dtype, optional
        float32 or float64 on disk; default that of ``run.data``, else float64.
    compression : str, optional
        HDF5 filter, e.g. ``"gzip"``.

    Yields
    ------
    SignalsWriter
        Call ``append(block)`` with blocks of shape (n, n_channels).

    Raises
    ------
    RecordingError
        Bad header, an existing run of that name, or no samples written.

    Examples
    --------
    >>> import os, tempfile
    >>> import numpy as np
    >>> header = RunData("vertical", 1000.0, [0, -1, 0], ["force", "acc_A_y"], ["N", "m/s^2"],
    ...                  [[0, 0, 0], [0.03, 0, 0.045]], [[0, -1, 0], [0, 1, 0]])
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     path = os.path.join(folder, "long.h5")
    ...     with open_signals_writer(path, header) as writer:
    ...         for k in range(3):
    ...             writer.append(np.full((100, 2), float(k)))
    ...     run = read_recording(path).runs[0]
    ...     last = read_block(run, 299, 300)
    >>> run.n_samples, last.tolist()
    (300, [[2.0, 2.0]])
    """
    import h5py

    display = os.fspath(path)
    p = Path(display)
    if p.suffix.lower() not in _HDF5_SUFFIXES:
        raise RecordingError(
            f"{display}: open_signals_writer writes HDF5; expected a .h5 or .hdf5 path"
        )
    if not isinstance(run, RunData):
        raise TypeError(f"run: expected RunData, got {type(run).__name__}")
    if run.layout != "signals":
        raise RecordingError(
            f"{display}: run '{run.name}': layout '{run.layout}'; the writer writes 'signals'"
        )
    if mode not in ("w", "a"):
        raise ValueError(f"mode={mode!r}: expected 'w' or 'a'")
    if dtype is None:
        dtype = np.float64 if run.data is None else run.data.dtype
    dtype = _file_dtype(dtype)
    target = p.with_name(p.name + ".part") if mode == "w" else p
    if mode == "w":
        f = h5py.File(target, "w")
        _write_root(f, guide or None, description)
        runs_group = f.create_group("runs", track_order=True)
    else:
        read_recording(p)  # must already be a valid recording
        f = h5py.File(target, "r+")
        runs_group = f["runs"]
        if run.name in runs_group:
            f.close()
            raise RecordingError(f"{display}: run '{run.name}' already exists")
    ok = False
    try:
        ds = _create_run(
            runs_group,
            _header(run),
            "signals",
            (0, run.n_channels),
            dtype,
            compression,
            resizable=True,
        )
        writer = SignalsWriter(ds, run, display)
        if run.data is not None:
            writer.append(run.data)
        yield writer
        if writer.n_samples == 0:
            raise RecordingError(f"{display}: run '{run.name}': no samples were appended")
        ok = True
    finally:
        if not ok and mode == "a":
            with contextlib.suppress(Exception):
                del runs_group[run.name]
        f.close()
        if mode == "w":
            if ok:
                os.replace(target, p)
            else:
                with contextlib.suppress(OSError):
                    target.unlink()
