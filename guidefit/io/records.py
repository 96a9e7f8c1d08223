"""The recording contract's data classes and reading samples through a run's source.

:class:`Recording` (root metadata and runs), :class:`Run` (one excitation
set-up: channels, layout, and a *source* that holds the samples),
:class:`Channel`; :class:`RecordingData` and :class:`RunData` hold a
recording in memory for the writers. :func:`read_block`, :func:`read_hit`
and :func:`open_reader` read a run's samples as float64 SI arrays, whatever
its source (an HDF5 dataset, an in-memory array, or a source a format module
provides: the protocol is in :mod:`guidefit.io`).

:class:`Channel`, :class:`ArraySource`, :class:`RunData` and
:class:`RecordingData` (values only, no reading) are defined in
:mod:`guidefit.io.record_data` and importable from here.

This module reads no file format itself and imports no format module.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from guidefit.errors import RecordingError
from guidefit.io._checks import UNIT_VECTOR_TOLERANCE, _first_line

# the in-memory data types moved to record_data (issue 22); importable from here as before
from guidefit.io.record_data import (  # noqa: F401
    ACCELERATION_UNITS,
    FORCE_UNITS,
    FORMAT_NAME,
    FORMAT_VERSION,
    LAYOUTS,
    STANDARD_GRAVITY,
    ArraySource,
    Channel,
    RecordingData,
    RunData,
    _ArraySource,
    _build_channels,
)

__all__ = [
    "ACCELERATION_UNITS",
    "FORCE_UNITS",
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "LAYOUTS",
    "STANDARD_GRAVITY",
    "UNIT_VECTOR_TOLERANCE",
    "ArraySource",
    "Channel",
    "Recording",
    "RecordingData",
    "Run",
    "RunData",
    "RunReader",
    "open_reader",
    "read_block",
    "read_hit",
]

_READ_ERRORS = (OSError, KeyError, RuntimeError, ValueError, TypeError)


# --------------------------------------------------------------------------- data


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
        Where the samples are: any object with ``read(index) -> ndarray`` (file
        units; ``index`` a numpy index tuple into the stored ``(n_samples,
        n_channels)`` or ``(n_hits, n_samples, n_channels)`` array) and
        ``dtype``, optionally ``open()`` (see :mod:`guidefit.io`).
    force_index : int
        Column of the force channel.
    file : str
        The recording's path as given to :func:`read_recording` (for messages).
    force_position_known : bool
        Whether the force channel's position is the hit point (the contract's
        meaning, True); False when the reader had no position for the hammer
        and only placed the force channel somewhere (a UFF file without
        coordinates of the reference node): the hit point is then unknown
        (:attr:`hit_position_m` None).
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
    force_position_known: bool = True

    @classmethod
    def from_header(
        cls,
        header: RunData,
        source,
        *,
        n_samples: int,
        n_hits_stored: int = 0,
        file: str = "",
        scale_to_si=None,
    ) -> Run:
        """A run whose metadata a validated :class:`RunData` gives and whose samples ``source`` holds.

        What a format module builds: ``header`` (``data=None`` or the samples)
        carries the checked names, units, geometry and layout; ``source``
        follows the sample-source protocol of :mod:`guidefit.io`.

        Parameters
        ----------
        header : RunData
        source : object
            ``read(index) -> ndarray`` in file units, and ``dtype``.
        n_samples : int
            Samples per record (the whole run for ``signals``).
        n_hits_stored : int
            Stored hit records (``hits`` layout), else 0.
        file : str
            The path as the user gave it (for messages).
        scale_to_si : sequence of float, optional
            Factor from file units to SI per channel (e.g. N per V from a
            sensitivity); default from the units (1, or 9.80665 for ``g``).

        Examples
        --------
        >>> header = RunData("vertical", 1000.0, [0, -1, 0], ["force", "acc_A_y"], ["N", "g"],
        ...                  [[0, 0, 0], [0.03, 0, 0.045]], [[0, -1, 0], [0, 1, 0]])
        >>> data = np.array([[1.0, 2.0], [3.0, 4.0]])
        >>> run = Run.from_header(header, ArraySource(data), n_samples=2)
        >>> run.read_block(1, 2).round(5).tolist()
        [[3.0, 39.2266]]
        """
        units = header.units
        if scale_to_si is None:
            scale_to_si = [
                (FORCE_UNITS if n == "force" else ACCELERATION_UNITS)[u]
                for n, u in zip(header.channel_names, units)
            ]
        scale = [float(v) for v in scale_to_si]
        if len(scale) != header.n_channels or not all(np.isfinite(scale)) or 0.0 in scale:
            raise RecordingError(
                f"run '{header.name}': scale_to_si {scale}: expected {header.n_channels} finite, "
                "non-zero factors"
            )
        channels = tuple(
            Channel(n, u, pos, d, k)
            for n, u, pos, d, k in zip(
                header.channel_names, units, header.positions_m, header.directions, scale
            )
        )
        return cls(
            name=header.name,
            sample_rate_hz=header.sample_rate_hz,
            excitation_direction=header.excitation_direction,
            excitation_position_m=header.excitation_position_m,
            channels=channels,
            layout=header.layout,
            n_samples=int(n_samples),
            n_hits_stored=int(n_hits_stored) if header.layout == "hits" else 0,
            pretrigger_samples=header.pretrigger_samples,
            source=source,
            force_index=header.channel_names.index("force"),
            file=file,
        )

    @property
    def n_channels(self) -> int:
        """Number of channels (columns)."""
        return len(self.channels)

    @property
    def channel_names(self) -> tuple[str, ...]:
        """Channel names in column order."""
        return tuple(ch.name for ch in self.channels)

    @property
    def hit_position_m(self) -> np.ndarray | None:
        """The hit point, m, where the file gives it: ``excitation_position_m``, else the force
        channel's position unless :attr:`force_position_known` is False; None when unknown.

        Examples
        --------
        >>> header = RunData("vertical", 1000.0, [0, -1, 0], ["force", "acc_A_y"], ["N", "g"],
        ...                  [[0.01, 0, 0.02], [0.03, 0, 0.045]], [[0, -1, 0], [0, 1, 0]])
        >>> run = Run.from_header(header, ArraySource(np.zeros((2, 2))), n_samples=2)
        >>> from dataclasses import replace
        >>> run.hit_position_m.tolist(), replace(run, force_position_known=False).hit_position_m
        ([0.01, 0.0, 0.02], None)
        """
        if self.excitation_position_m is not None:
            return self.excitation_position_m
        return self.force_channel.position_m if self.force_position_known else None

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
        return np.dtype(getattr(self.source, "dtype", np.float64))

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
            the file's dtype, so ``write_recording`` reproduces the file (samples
            stored as counts or volts with a scale: float64 values in the units).
            True: float64 samples in SI and units ``N``/``m/s^2``.
        """
        if self.layout == "signals":
            data = _raw_read(self, (slice(0, self.n_samples), slice(None)))
        else:
            data = _raw_read(self, (slice(0, self.n_hits_stored), slice(None), slice(None)))
        units = tuple(ch.unit for ch in self.channels)
        if not si:
            data = _in_units(self, data)  # counts or volts: values in the declared units
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

# ------------------------------------------------------------ sample access


def _read_error(run: Run, exc: BaseException) -> RecordingError:
    return RecordingError(
        f"{run.file or getattr(run.source, 'path', '?')}: run '{run.name}': cannot read samples "
        f"({_first_line(exc)})"
    )


def _checked_read(run: Run, handle, index: tuple) -> np.ndarray:
    """``handle.read(index)``; a library error becomes one RecordingError naming the run."""
    if isinstance(handle, ArraySource):
        return handle.read(index)
    try:
        return handle.read(index)
    except RecordingError:
        raise
    except _READ_ERRORS as exc:
        raise _read_error(run, exc) from None


def _in_units(run: Run, raw):
    """``raw`` (file units) in each channel's declared unit (``Channel.unit``).

    The same array when every channel's ``scale_to_si`` is just its unit's factor
    (the file stores values in the unit); else float64 times the per-count factor
    (integer counts with a ``sample_scale``, volts with a sensitivity). With
    ``raw=None``: None when no conversion is needed, else the factors.
    """
    unit = np.array([
        (FORCE_UNITS if ch.kind == "force" else ACCELERATION_UNITS).get(ch.unit, ch.scale_to_si)
        for ch in run.channels
    ])
    factors = run.scale_to_si / unit
    if np.all(factors == 1.0):
        return None if raw is None else raw
    if raw is None:
        return factors
    return np.asarray(raw, dtype=np.float64) * factors


def _raw_read(run: Run, index: tuple) -> np.ndarray:
    """Samples in file units with the file's dtype; ``index`` as for the stored array."""
    source = run.source
    if not callable(getattr(source, "read", None)):
        raise TypeError(f"run '{run.name}': unknown sample source {type(source).__name__}")
    return _checked_read(run, source, index)


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

    def __init__(self, run: Run, handle=None):
        self._run = run
        # what ``open()`` of the run's source gave (or the source itself): has read(index),
        # dtype, and optionally read_hits_into(first, out)
        self._handle = run.source if handle is None else handle

    @property
    def run(self) -> Run:
        """The run being read."""
        return self._run

    def _raw(self, index: tuple) -> np.ndarray:
        return _checked_read(self._run, self._handle, index)

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
        if not isinstance(self._handle, ArraySource) and cols != slice(None):
            # files store whole samples (all channels) together: reading them and
            # selecting columns here is faster than a strided selection (HDF5)
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
            if isinstance(self._handle, ArraySource):  # a view of in-memory samples: read-only
                raw = np.asarray(raw).view()
                raw.flags.writeable = False
            return raw
        if out.shape != (int(last) - int(first), n, run.n_channels):
            raise ValueError(
                f"out has shape {out.shape}; expected {(int(last) - int(first), n, run.n_channels)}"
            )
        read_into = getattr(self._handle, "read_hits_into", None)
        if read_into is None or n != run.n_samples:
            np.copyto(out, self._raw(index))
            return out
        if not out.flags.c_contiguous:
            raise ValueError("out must be C-contiguous")
        try:
            read_into(int(first), out)
        except RecordingError:
            raise
        except _READ_ERRORS as exc:
            raise _read_error(run, exc) from None
        return out

    @property
    def dtype(self) -> np.dtype:
        """dtype of the stored samples."""
        return np.dtype(self._handle.dtype)


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
    >>> from guidefit.io import read_recording, write_recording
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
    if not callable(getattr(source, "read", None)):
        raise TypeError(f"run '{run.name}': unknown sample source {type(source).__name__}")
    opener = getattr(source, "open", None)
    if opener is None:
        yield RunReader(run)
        return
    with contextlib.ExitStack() as stack:
        try:
            handle = stack.enter_context(opener())
        except RecordingError:
            raise
        except _READ_ERRORS as exc:
            raise _read_error(run, exc) from None
        yield RunReader(run, handle)


def hit_point_of(run) -> np.ndarray | None:
    """A run's hit point, m: the contract's (``excitation_position_m``, else the force channel's
    position: :attr:`guidefit.io.records.Run.hit_position_m`); None when the file does not give it."""
    pos = run.hit_position_m if hasattr(run, "hit_position_m") else getattr(run, "excitation_position_m", None)
    return None if pos is None else np.asarray(pos, dtype=float)
