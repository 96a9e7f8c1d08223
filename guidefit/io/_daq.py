"""What every DAQ file reader gives a test setup: the file's channels and a sample source.

A DAQ reader (:mod:`guidefit.io.tdms`, :mod:`~guidefit.io.mdf`,
:mod:`~guidefit.io.mat`, :mod:`~guidefit.io.wav`, :mod:`~guidefit.io.text`,
UFF-58 time data through :mod:`guidefit.io.setup`) declares a
:class:`~guidefit.io.registry.FileFormat` of kind ``"daq"`` whose ``read``
is ``open_daq(path, display, options) -> DaqFile``: it reads the file's
metadata (channel names, lengths, units, the sample rate) and no sample but a
time axis. :class:`DaqFile` finds the channel a setup's ``source`` names and
makes the run's sample source (:class:`ColumnSource`): the samples stay in
the DAQ file and are read in slices where the library allows it.

The format modules import their library inside their functions, so this
module and they are cheap to import.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from guidefit.errors import RecordingError

__all__ = ["ColumnSource", "DaqChannel", "DaqFile", "RunOptions", "rate_from_time", "same_rate"]

RATE_TOLERANCE = 1e-5
"""Largest relative difference between two sample rates that "agree" (a setup's
``sample_rate_hz`` and the file's): 2 Hz at 200 kHz."""


@dataclass(frozen=True)
class RunOptions:
    """What a setup's run table tells a reader about its file (besides the channels).

    Attributes
    ----------
    where : str
        ``"test.toml: runs.lateral"``, for messages about the run table.
    group : str or int or None
        ``group`` of the run table: TDMS group, MDF channel-group index,
        MATLAB struct name, UFF run name.
    delimiter, decimal : str or None
        Text exports: the field delimiter (``","``, ``";"``, ``"\\t"``,
        ``" "`` for any run of spaces) and decimal mark (``"."`` or ``","``),
        when the run table gives them.
    """

    where: str
    group: str | int | None = None
    delimiter: str | None = None
    decimal: str | None = None


@dataclass(frozen=True)
class DaqChannel:
    """One channel of a DAQ file.

    Attributes
    ----------
    name : str
        The channel's name as the file gives it (``"Hammer"``, ``"vertical/Hammer"``,
        ``"data:2"``, ``"1"``).
    key : object
        What the format's source needs to read it (picklable: names, indices).
    n_samples : int
        Its number of samples.
    unit : str or None
        The unit the file states for it (``"V"``), if any.
    sample_rate_hz : float or None
        Its own sample rate, where the format keeps one per channel (TDMS).
    dtype : numpy.dtype
        dtype of the samples as the library returns them.
    start : tuple of (int, float) or None
        When its first sample was taken, where the format says per channel (TDMS
        ``wf_start_time`` in ns since 1970 and ``wf_start_offset`` in s); the
        channels of a run must start together.
    """

    name: str
    key: object
    n_samples: int
    unit: str | None = None
    sample_rate_hz: float | None = None
    dtype: np.dtype = field(default_factory=lambda: np.dtype(np.float64))
    start: tuple | None = None


@dataclass(frozen=True)
class DaqFile:
    """A DAQ file's channels and how to read them; made by a reader's ``open_daq``.

    Attributes
    ----------
    display : str
        The file as the user sees it (``"lateral.tdms"``), for messages.
    channels : tuple of DaqChannel
        Every channel a ``source`` may name, in file order (shown in errors).
    aliases : mapping of str to DaqChannel
        Other texts that name a channel (``"Hammer"`` for ``"vertical/Hammer"``,
        ``"Hammer [V]"`` for ``"Hammer"``, column indices).
    ambiguous : mapping of str to str
        Texts that would name several channels, with the one-line reason.
    sample_rate_hz : float or None
        The file's sample rate (None: the file has neither a rate nor a time axis).
    rate_origin : str
        Where the rate came from (``"wf_increment"``, ``"the time channel"``).
    make_source : callable
        ``make_source(channels: tuple of DaqChannel, dtype) -> source`` (the
        sample-source protocol of :mod:`guidefit.io`).
    rate_for : callable or None
        ``rate_for(channels) -> float or None``: the sample rate of a run made
        of ``channels`` where it depends on them (an MDF channel group's time
        channel); None: the channels' own rates, else :attr:`sample_rate_hz`.
    """

    display: str
    channels: tuple[DaqChannel, ...]
    make_source: Callable = field(repr=False)
    aliases: Mapping[str, DaqChannel] = field(default_factory=dict)
    ambiguous: Mapping[str, str] = field(default_factory=dict)
    sample_rate_hz: float | None = None
    rate_origin: str = ""
    rate_for: Callable | None = field(default=None, repr=False)
    note: str = ""
    count_rows: Callable | None = field(default=None, repr=False)

    def find(self, source: str) -> DaqChannel | None:
        """The channel ``source`` names, or None; RecordingError if it names several.

        Examples
        --------
        >>> a = DaqChannel("Hammer", 0, 10)
        >>> f = DaqFile("x.tdms", (a,), make_source=None, aliases={"0": a})
        >>> f.find("Hammer") is a, f.find("0") is a, f.find("A_Y")
        (True, True, None)
        """
        if source in self.ambiguous:
            raise RecordingError(f"{self.display}: {self.ambiguous[source]}")
        for ch in self.channels:
            if ch.name == source:
                return ch
        return self.aliases.get(source)

    def missing(self, source: str) -> RecordingError:
        """The one-line error for a ``source`` the file lacks (names what the file has).

        Examples
        --------
        >>> chans = tuple(DaqChannel(n, n, 10) for n in ("Hammer", "AccA_Y", "AccB_Y"))
        >>> str(DaqFile("lateral.tdms", chans, make_source=None).missing("A_Y"))
        "lateral.tdms: no channel 'A_Y'; the file has Hammer, AccA_Y, AccB_Y"
        >>> str(DaqFile("lateral.tdms", chans, make_source=None).missing("hammer "))
        "lateral.tdms: no channel 'hammer '; the file has Hammer, AccA_Y, AccB_Y; did you mean 'Hammer' (names \
are matched exactly: case and spaces count)?"
        """
        names = [ch.name for ch in self.channels]
        shown = ", ".join(names[:40]) + (f", ... ({len(names)} in all)" if len(names) > 40 else "")
        note = f" ({self.note})" if self.note else ""
        near = [n for n in names if " ".join(n.split()).casefold() == " ".join(source.split()).casefold()]
        hint = f"; did you mean {near[0]!r} (names are matched exactly: case and spaces count)?" if near else ""
        return RecordingError(
            f"{self.display}: no channel '{source}'; the file has {shown or 'no channels'}{note}{hint}"
        )


class ColumnSource:
    """Base of the DAQ sample sources: a ``(n_samples, n_channels)`` array read column by column.

    A subclass holds only picklable facts (path, channel keys) and implements
    ``_open()`` (a context manager giving the library's open file) and
    ``_read(handle, start, stop, keys) -> list of 1-D arrays``. This class turns
    the numpy index tuples of the sample-source protocol into those calls.

    Examples
    --------
    >>> class Ramp(ColumnSource):
    ...     def _read(self, handle, start, stop, keys):
    ...         return [np.arange(start, stop) * (k + 1.0) for k in keys]
    >>> src = Ramp(keys=(0, 1, 2), n_samples=5)
    >>> src.read((slice(1, 3), slice(None))).tolist()
    [[1.0, 2.0, 3.0], [2.0, 4.0, 6.0]]
    >>> src.read((slice(0, 2), [0, 2])).tolist(), src.read((slice(4, 5), slice(1, 2))).tolist()
    ([[0.0, 0.0], [1.0, 3.0]], [[8.0]])
    """

    def __init__(self, *, keys: Sequence, n_samples: int, dtype=np.float64, **facts):
        self.keys = tuple(keys)
        self.n_samples = int(n_samples)
        self.dtype = np.dtype(dtype)
        self.facts = dict(facts)

    def __reduce__(self):  # picklable with the facts that make it (forked readers, process pools)
        return (_rebuild, (type(self), self.keys, self.n_samples, self.dtype.str, self.facts))

    @contextlib.contextmanager
    def _open(self) -> Iterator[object]:
        yield None

    def _read(self, handle, start: int, stop: int, keys: Sequence) -> list:
        raise NotImplementedError

    def read(self, index: tuple) -> np.ndarray:
        """Samples ``index`` (rows, columns) in file units; opens the file for this call only."""
        with self.open() as handle:
            return handle.read(index)

    @contextlib.contextmanager
    def open(self) -> Iterator[_OpenColumns]:
        """The file open for many reads (what :func:`guidefit.io.open_reader` uses)."""
        with self._open() as handle:
            yield _OpenColumns(self, handle)

    def _rows_cols(self, index: tuple):
        if not isinstance(index, tuple):
            index = (index,)
        if len(index) == 1:
            index = (index[0], slice(None))
        if len(index) != 2:
            raise IndexError(f"index {index!r}: expected (rows, columns) of a signals run")
        rows, cols = index
        squeeze_row = isinstance(rows, (int, np.integer))
        if squeeze_row:
            r = int(rows) + (self.n_samples if rows < 0 else 0)
            if not 0 <= r < self.n_samples:
                raise IndexError(f"row {rows} outside 0..{self.n_samples - 1}")
            start, stop = r, r + 1
        elif isinstance(rows, slice):
            start, stop, step = rows.indices(self.n_samples)
            if step != 1:
                raise IndexError("row slices with a step are not supported")
            stop = max(start, stop)
        else:
            raise IndexError(f"rows {rows!r}: expected a slice or an integer")
        squeeze_col = isinstance(cols, (int, np.integer))
        if isinstance(cols, slice):
            picked = list(range(len(self.keys)))[cols]
        elif squeeze_col:
            picked = [list(range(len(self.keys)))[int(cols)]]
        else:
            picked = [int(c) for c in np.asarray(cols).reshape(-1)]
        return start, stop, picked, squeeze_row, squeeze_col


def _rebuild(cls, keys, n_samples, dtype, facts):
    return cls(keys=keys, n_samples=n_samples, dtype=np.dtype(dtype), **facts)


class _OpenColumns:
    """An open DAQ file: ``read(index)`` and ``dtype`` (see :class:`ColumnSource`)."""

    def __init__(self, source: ColumnSource, handle):
        self._source = source
        self._handle = handle
        self.dtype = source.dtype

    def read(self, index: tuple) -> np.ndarray:
        src = self._source
        start, stop, picked, squeeze_row, squeeze_col = src._rows_cols(index)
        out = np.empty((stop - start, len(picked)), dtype=src.dtype)
        if stop > start and picked:
            columns = src._read(self._handle, start, stop, [src.keys[k] for k in picked])
            for j, column in enumerate(columns):
                column = np.asarray(column).reshape(-1)
                if column.size != stop - start:
                    raise OSError(
                        f"channel {src.keys[picked[j]]!r} gave {column.size} samples for rows "
                        f"{start}:{stop}; the file changed or is damaged"
                    )
                out[:, j] = column
        if squeeze_row:
            out = out[0]
        if squeeze_col:
            out = out[..., 0]
        return out


@contextlib.contextmanager
def quiet_logger(name: str) -> Iterator[None]:
    """A library's log messages below ERROR held back while it reads (npTDMS and asammdf log
    warnings about damaged files to stderr; guidefit reports what matters in one line).

    >>> import logging
    >>> with quiet_logger("nptdms"):
    ...     logging.getLogger("nptdms").level
    40
    """
    import logging

    names = [name] + [n for n in list(logging.Logger.manager.loggerDict) if n.startswith(name + ".")]
    loggers = [logging.getLogger(n) for n in names]
    levels = [logger.level for logger in loggers]
    for logger in loggers:
        logger.setLevel(max(logger.level, logging.ERROR))
    try:
        yield
    finally:
        for logger, level in zip(loggers, levels):
            logger.setLevel(level)


def common_dtype(dtypes) -> np.dtype:
    """float32 when every channel is float32, else float64 (integers are read as float64).

    >>> common_dtype([np.float32, np.float32]), common_dtype([np.float32, np.int16])
    (dtype('float32'), dtype('float64'))
    """
    dts = [np.dtype(d) for d in dtypes]
    return np.dtype(np.float32) if dts and all(d == np.float32 for d in dts) else np.dtype(np.float64)


def same_rate(a: float, b: float) -> bool:
    """Whether two sample rates agree within :data:`RATE_TOLERANCE` (relative).

    >>> same_rate(51200.0, 51200.3), same_rate(200000.0, 199990.0)
    (True, False)
    """
    return abs(a - b) <= RATE_TOLERANCE * max(abs(a), abs(b))


def nice_rate(rate: float) -> float:
    """``rate``, or the whole number of Hz it is within 1e-9 of (``1/5e-6`` -> 200000.0).

    >>> nice_rate(1 / 1.953125e-05), nice_rate(1 / 3e-6) == 1 / 3e-6
    (51200.0, True)
    """
    whole = round(rate)
    return float(whole) if whole > 0 and abs(rate - whole) <= 1e-9 * rate else float(rate)


_TIME_CHUNK = 1 << 20


def rate_from_time(read: Callable[[int, int], np.ndarray], n: int, where: str,
                   resolution_s: float | np.ndarray = 0.0) -> float:
    """The sample rate of a time axis read in chunks: least-squares slope, checked for uniform spacing.

    ``read(start, stop)`` gives times (s) ``start:stop``; memory is one chunk.
    ``resolution_s`` is the step of times written with few digits (a text export's
    ``12.34568``: 1e-5 s), one number for all times or one per time (``%g`` writes
    ``0.5`` and ``0.500013``): each time may be off by half of its own step besides
    0.1 sample period. A time further off than that is refused; when a jump between
    two consecutive times explains it (a gap, two records joined), the message names
    where.

    Raises
    ------
    RecordingError
        Fewer than two samples, non-finite or decreasing times, a jump, or spacing
        that deviates from uniform by more than 0.1 sample period (plus rounding).

    Examples
    --------
    >>> t = np.arange(1000) / 51200.0
    >>> rate_from_time(lambda a, b: t[a:b], t.size, "x.mf4: time")
    51200.0
    >>> t[600:] += 0.01
    >>> rate_from_time(lambda a, b: t[a:b], t.size, "x.mf4: time")
    Traceback (most recent call last):
    ...
    guidefit.errors.RecordingError: x.mf4: time: times jump by 0.0100195 s, from 0.0116992188 s to 0.02171875 s \
between samples 600 and 601; expected equally spaced times (a gap in the record?)
    """
    if n < 2:
        raise RecordingError(f"{where}: {n} sample(s); a time axis needs two to give a sample rate")
    per_row = np.ndim(resolution_s) > 0
    if per_row and np.shape(resolution_s) != (n,):
        raise ValueError(f"resolution_s: {np.shape(resolution_s)} values for {n} times")

    def res(a: int, b: int):
        return np.asarray(resolution_s[a:b], dtype=np.float64) if per_row else float(resolution_s)

    k_mean = (n - 1) / 2.0
    t0 = None  # times are taken relative to the first (MDF time channels may hold epoch seconds)
    previous = previous_r = None
    t_sum = skk = skt = 0.0
    for a in range(0, n, _TIME_CHUNK):  # pass 1: checks and the least-squares sums
        t = np.asarray(read(a, min(n, a + _TIME_CHUNK)), dtype=np.float64).reshape(-1)
        r = np.broadcast_to(res(a, a + t.size), t.shape)
        if not np.all(np.isfinite(t)):
            raise RecordingError(f"{where}: holds non-finite times")
        joined = t if previous is None else np.concatenate([[previous], t])
        joined_r = r if previous is None else np.concatenate([[previous_r], r])
        steps = np.diff(joined)
        # times written to a step coarser than the sample period repeat; they never decrease
        bad = np.where(joined_r[1:] + joined_r[:-1] > 0, steps < 0, steps <= 0)
        if np.any(bad):
            k = a + int(np.flatnonzero(bad)[0]) - (previous is not None)
            raise RecordingError(
                f"{where}: times not increasing at sample {k + 1}; expected equally spaced times"
            )
        previous, previous_r = t[-1], r[-1]
        t0 = t[0] if t0 is None else t0
        kc = np.arange(a, a + t.size, dtype=np.float64) - k_mean
        skk += float(kc @ kc)
        skt += float(kc @ (t - t0))  # = sum (k - k_mean)(t - t_mean): sum (k - k_mean) is 0
        t_sum += float(np.sum(t - t0))
    if not skt > 0:
        raise RecordingError(f"{where}: all times equal; expected equally spaced times")
    fs = skk / skt
    worst, jump = _worst_deviation(read, res, n, t0, t_sum / n, k_mean, fs)
    if worst[0] > 0:
        if jump[0] > 0:
            _, k, before, after = jump
            raise RecordingError(
                f"{where}: times jump by {after - before:.6g} s, from {before:.9g} s to {after:.9g} s between "
                f"samples {k} and {k + 1}; expected equally spaced times (a gap in the record?)"
            )
        _, k, off, allowed, step = worst
        printed = f", {allowed - 0.1:.2g} of them from the {step:.3g} s the time is written to" if step else ""
        raise RecordingError(
            f"{where}: spacing not uniform (sample {k + 1} is {off:.2g} sample periods off the line, {allowed:.2g} "
            f"allowed{printed}); expected a constant sample rate"
        )
    return nice_rate(fs)


def _worst_deviation(read, res, n: int, t0: float, t_mean: float, k_mean: float, fs: float):
    """Pass 2 of :func:`rate_from_time`: the time furthest off the fitted line beyond what it
    may be off (excess in sample periods, sample, periods off, periods allowed, its printed step) and
    the jump between consecutive times furthest beyond its allowance (excess, later sample
    (0-based), the two times): each time may be off 0.1 period plus half its printed step, so two
    consecutive times' step may be off 0.2 period plus half of both steps (a jump beyond that
    is beyond the line's tolerance too)."""
    worst = (-np.inf, 0, 0.0, 0.0, 0.0)
    jump = (-np.inf, 0, 0.0, 0.0)
    previous = previous_r = None
    for a in range(0, n, _TIME_CHUNK):
        t = np.asarray(read(a, min(n, a + _TIME_CHUNK)), dtype=np.float64).reshape(-1) - t0
        r = np.broadcast_to(res(a, a + t.size), t.shape)
        kc = np.arange(a, a + t.size, dtype=np.float64) - k_mean
        off = np.abs(t - t_mean - kc / fs) * fs
        allowed = 0.1 + 0.5 * r * fs
        i = int(np.argmax(off - allowed))
        if off[i] - allowed[i] > worst[0]:
            worst = (off[i] - allowed[i], a + i, off[i], allowed[i], r[i])
        joined = t if previous is None else np.concatenate([[previous], t])
        joined_r = r if previous is None else np.concatenate([[previous_r], r])
        excess = np.abs(np.diff(joined) * fs - 1.0) - (0.2 + 0.5 * (joined_r[1:] + joined_r[:-1]) * fs)
        if excess.size:
            j = int(np.argmax(excess))
            if excess[j] > jump[0]:
                k = a + j + (previous is None)  # 0-based index of the later time
                jump = (excess[j], k, joined[j] + t0, joined[j + 1] + t0)
        previous, previous_r = t[-1], r[-1]
    return worst, jump
