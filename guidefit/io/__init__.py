"""Reading and writing recordings and FRF files: one module per format, a registry by suffix.

Public entry points::

    from guidefit.io import read_recording, open_reader
    rec = read_recording("test.h5")            # any registered suffix; samples stay on disk
    run = rec.runs[0]
    with open_reader(run) as reader:           # one open file for many reads
        block = reader.read_block(0, 4096)     # float64, SI (N, m/s^2)

Modules
-------
========================  ===================================================
``records``               the contract's data classes (:class:`Recording`,
                          :class:`Run`, :class:`Channel`, :class:`RunData`,
                          :class:`RecordingData`) and reading samples through
                          a run's source (:func:`read_block`,
                          :func:`read_hit`, :func:`open_reader`)
``registry``              :class:`FileFormat`, :func:`formats`,
                          :func:`read_recording`, :func:`write_recording`,
                          :func:`write_frfs`: dispatch by suffix
``hdf5``                  the recording contract in HDF5 (streaming reader,
                          writer, :func:`open_signals_writer`)
``csv``                   the recording contract in CSV
``uff``                   UFF-58 time data and FRFs (pyuff, extra ``uff``)
``frf_files``             guidefit's ``frf.csv`` / ``frf.h5``; FRF files as input
                          (``FrfFile``, ``read_input``)
``uff_frf``               UFF-58 FRFs in (function types 4 and 6)
``setup``                 test setups (``.toml``): DAQ files read in place
                          as a :class:`Recording`; :func:`~guidefit.io.setup.convert`
``tdms``, ``mdf``,        the DAQ readers a setup uses (formats of kind
``mat``, ``wav``,         ``"daq"``: NI TDMS, ASAM MDF 4, MATLAB v5/v7.3,
``text``                  WAV, text exports; extra ``daq``)
``_daq``                  what a DAQ reader gives a setup (``DaqFile``,
                          ``ColumnSource``)
``watchdog``              the forked, time-limited HDF5 metadata read
``geometry``              default sensor positions from a guide's points
``_checks``               validation helpers
========================  ===================================================

Adding a format
---------------
Write one module ``guidefit/io/<format>.py`` that imports its library inside
its functions (a missing library is one ``RecordingError`` naming the pip
extra) and declares::

    FORMATS = (FileFormat(name="NI TDMS", suffixes=(".tdms",), kind="recording",
                          read=read_tdms, extra="daq", streaming=True),)

``read(path: Path, display: str) -> Recording`` (``display`` is the path as the
user gave it, for messages; the registry has checked that the file exists and
is not empty). :func:`formats` finds the declaration; nothing else changes.
Add its test and its row in ``docs/recordings.md``.

The sample-source protocol
--------------------------
A :class:`Run` holds metadata and a ``source``; the samples stay where they
are. A source is any object with

``read(index: tuple) -> numpy.ndarray``
    The samples selected by the numpy index tuple ``index``, applied to the
    stored array of shape ``(n_samples, n_channels)`` (layout ``signals``) or
    ``(n_hits, n_samples, n_channels)`` (layout ``hits``), in *file units*
    (volts, counts, g, ...). ``index`` holds slices, integers and (for
    channels, last axis) sorted lists of column indices, as h5py accepts.
``dtype``
    numpy dtype of the stored samples (``Run.sample_dtype``; the FFT
    precision follows it).

and optionally

``open()``
    A context manager giving an object with the same ``read`` and ``dtype``
    that keeps the file open for many reads (:func:`open_reader` uses it),
    and optionally ``read_hits_into(first, out)`` (whole hits straight into
    a C-contiguous array, the fast path of :mod:`guidefit.hits`).

Each :class:`Channel` carries its own ``scale_to_si`` (file unit -> SI),
so a reader of volts gives the sensitivity there (N per V, m/s^2 per V):
:func:`read_block` and friends return ``float64(raw) * scale_to_si``.
``Channel.unit`` stays the channel's physical unit of the contract (``N``,
``m/s^2``, ``g``); ``Run.to_data()`` and the writers convert samples stored
in other units (volts, counts) into it, so a converted file is right.
:meth:`Run.from_header` builds a run from a validated :class:`RunData`
header, a source and the scale factors, e.g. a force sensor of 2.25 mV/N
and an accelerometer of 10.2 mV/(m/s^2), both recorded in volts::

    header = RunData("vertical", 51200.0, [0, -1, 0], ["force", "acc_A_y"],
                     ["N", "m/s^2"], positions_m, directions)       # no data
    run = Run.from_header(header, my_source, n_samples=n, file=display,
                          scale_to_si=[1 / 2.25e-3, 1 / 10.2e-3])  # N/V, (m/s^2)/V Errors a source raises from its
library (``OSError``, ``KeyError``, ``RuntimeError``, ``ValueError``,
``TypeError``) become one ``RecordingError`` naming the file and run.
Built in: :class:`~guidefit.io.records.ArraySource` (in memory: CSV, UFF)
and :class:`~guidefit.io.hdf5.H5Source`.

Nothing here imports h5py, pandas or scipy until a file is read.
"""

from guidefit.io.geometry import default_channel_geometry, default_points
from guidefit.io.hdf5 import SignalsWriter, open_signals_writer
from guidefit.io.records import (
    ACCELERATION_UNITS,
    FORCE_UNITS,
    FORMAT_NAME,
    FORMAT_VERSION,
    LAYOUTS,
    STANDARD_GRAVITY,
    UNIT_VECTOR_TOLERANCE,
    ArraySource,
    Channel,
    Recording,
    RecordingData,
    Run,
    RunData,
    RunReader,
    open_reader,
    read_block,
    read_hit,
)
from guidefit.io.registry import (
    FileFormat,
    format_for,
    formats,
    read_recording,
    write_frfs,
    write_recording,
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
    "FileFormat",
    "Recording",
    "RecordingData",
    "Run",
    "RunData",
    "RunReader",
    "SignalsWriter",
    "default_channel_geometry",
    "default_points",
    "format_for",
    "formats",
    "open_reader",
    "open_signals_writer",
    "read_block",
    "read_hit",
    "read_recording",
    "write_frfs",
    "write_recording",
]
