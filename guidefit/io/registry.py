"""The registry of file formats by suffix, and the readers and writers that dispatch on it.

Every module of the package :mod:`guidefit.io` may declare the formats it
reads or writes in a module-level tuple ``FORMATS`` of :class:`FileFormat`;
:func:`formats` finds them by importing the package's modules (each imports
its heavy library only inside its functions, so this is cheap), the way
scikit-rf keeps one module per format in ``skrf/io``. Adding a format is one
new module (with its ``FORMATS``), its test and its row in
``docs/recordings.md``: nothing here changes.

This module imports no format module by name, so no format module can be in
an import cycle through it.
"""

from __future__ import annotations

import importlib
import os
import pkgutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from guidefit.errors import RecordingError

__all__ = ["FileFormat", "format_for", "formats", "read_recording", "write_frfs", "write_recording"]

KINDS = ("recording", "frf", "daq")
_PACKAGE = __name__.rpartition(".")[0]  # guidefit.io: its modules are found by path, not imported
_PACKAGE_DIR = Path(__file__).resolve().parent
_NOT_FORMATS = {"registry", "records", "geometry", "watchdog"}  # modules without FORMATS


@dataclass(frozen=True)
class FileFormat:
    """One file format a module of :mod:`guidefit.io` reads and/or writes.

    Attributes
    ----------
    name : str
        Shown in messages and in ``docs/recordings.md`` (``"NI TDMS"``).
    suffixes : tuple of str
        Lower-case file suffixes with the dot (``(".tdms",)``).
    kind : {"recording", "frf", "daq"}
        What the file holds: time data (a :class:`~guidefit.io.records.Recording`),
        FRFs (``FrfSet`` objects), or a DAQ's time data that only a test setup
        can make a recording of (:mod:`guidefit.io.setup`).
    read : callable or None
        ``read(path: pathlib.Path, display: str)``: a ``Recording`` (kind
        ``recording``) or a :class:`~guidefit.io.frf_files.FrfFile` (kind ``frf``:
        the ``FrfSet`` of each run with its run and channel metadata); kind ``daq``:
        ``read(path, display, options)`` gives a :class:`~guidefit.io._daq.DaqFile`. ``display``
        is the path as the user gave it, for messages. The registry has
        already checked that the file exists, is a file and is not empty.
        Every malformed input raises one-line ``RecordingError``.
    write : callable or None
        ``write(path, data, **options)``, atomic (no partial file on error).
    extra : str or None
        The pip extra that installs the format's library (``"daq"``); the
        module names it in its one-line error when the library is missing.
    streaming : bool
        The reader leaves the samples on disk and reads them in slices
        (bounded memory); False: it loads them into memory.
    module : str
        Filled in by :func:`formats`: the module that declared the format.
    """

    name: str
    suffixes: tuple[str, ...]
    kind: str = "recording"
    read: Callable | None = None
    write: Callable | None = None
    extra: str | None = None
    streaming: bool = False
    module: str = ""

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"FileFormat {self.name!r}: kind {self.kind!r}; expected one of {KINDS}")
        for suffix in self.suffixes:
            if not suffix.startswith(".") or suffix != suffix.lower():
                raise ValueError(
                    f"FileFormat {self.name!r}: suffix {suffix!r}; expected lower case with a dot"
                )


_FORMATS: tuple[FileFormat, ...] | None = None
_MODULE_FORMATS: dict[str, tuple[FileFormat, ...]] = {}


def _module_names() -> list[str]:
    """The format modules of :mod:`guidefit.io`, in name order (nothing imported)."""
    return [f"{_PACKAGE}.{info.name}" for info in sorted(pkgutil.iter_modules([str(_PACKAGE_DIR)]),
                                                         key=lambda m: m.name)
            if not info.name.startswith("_") and info.name not in _NOT_FORMATS]


def _formats_of(name: str) -> tuple[FileFormat, ...]:
    """The formats module ``name`` declares (imported on first use)."""
    if name not in _MODULE_FORMATS:
        found = []
        for fmt in getattr(importlib.import_module(name), "FORMATS", ()):
            if not isinstance(fmt, FileFormat):
                raise TypeError(f"{name}.FORMATS holds {type(fmt).__name__}; expected FileFormat")
            found.append(FileFormat(**{**fmt.__dict__, "module": name}))
        _MODULE_FORMATS[name] = tuple(found)
    return _MODULE_FORMATS[name]


def formats(kind: str | None = None) -> tuple[FileFormat, ...]:
    """Every format the modules of :mod:`guidefit.io` declare (of ``kind``, if given).

    Examples
    --------
    >>> sorted(s for f in formats("recording") if f.read for s in f.suffixes)[:3]
    ['.csv', '.h5', '.hdf5']
    """
    global _FORMATS
    if _FORMATS is None:
        _FORMATS = tuple(fmt for name in _module_names() for fmt in _formats_of(name))
    if kind is None:
        return _FORMATS
    return tuple(f for f in _FORMATS if f.kind == kind)


def _suffix_list(candidates) -> str:
    suffixes = sorted({s for f in candidates for s in f.suffixes})
    if len(suffixes) == 1:
        return suffixes[0]
    return ", ".join(suffixes[:-1]) + " or " + suffixes[-1]


def format_for(path, kind: str, action: str) -> FileFormat:
    """The format that can ``action`` (``"read"`` or ``"write"``) a ``kind`` file at ``path``.

    Raises
    ------
    RecordingError
        No format of that kind handles the suffix: one line listing those that do.
    """
    display = os.fspath(path)
    suffix = Path(display).suffix.lower()
    # the modules in the order formats() lists them, imported only up to the first that takes the
    # suffix (an .h5 recording does not import the TDMS, MDF, MAT, WAV, text and UFF readers)
    for name in _module_names():
        for fmt in _formats_of(name):
            if fmt.kind == kind and getattr(fmt, action) is not None and suffix in fmt.suffixes:
                return fmt
    candidates = [f for f in formats(kind) if getattr(f, action) is not None]
    for fmt in candidates:
        if suffix in fmt.suffixes:
            return fmt
    what = "file type" if kind == "recording" else f"{kind.upper()} {'output' if action == 'write' else 'input'} type"
    raise RecordingError(
        f"{display}: unknown {what} '{Path(display).suffix}'; expected {_suffix_list(candidates)}"
    )


def _checked_input(display: str, what: str) -> Path:
    p = Path(display)
    if not p.exists():
        raise RecordingError(f"{display}: no such file")
    if p.is_dir():
        raise RecordingError(f"{display}: is a directory; expected a {what} file")
    if p.stat().st_size == 0:
        raise RecordingError(f"{display}: file is empty")
    return p


def read_recording(path):
    """Open and validate a recording in any registered format; the samples stay on disk where the format allows.

    Parameters
    ----------
    path : str or path-like
        The suffix chooses the reader (:func:`formats`): ``.h5``/``.hdf5``
        and ``.csv`` (the recording contract), ``.uff``/``.unv`` (UFF-58
        time data), and the DAQ formats and test setups the package declares.

    Returns
    -------
    Recording
        Metadata and one :class:`~guidefit.io.records.Run` per run; read
        samples with :func:`~guidefit.io.read_block` /
        :func:`~guidefit.io.read_hit` / :func:`~guidefit.io.open_reader`.

    Raises
    ------
    RecordingError
        Anything that does not follow the format, as one line naming the
        file, the run, the channel or field and what was expected.

    Examples
    --------
    >>> import os, tempfile
    >>> import numpy as np
    >>> from guidefit.io import RecordingData, RunData, read_block
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
    from guidefit.io.axes import map_input, reading

    display = os.fspath(path)
    fmt = format_for(display, "recording", "read")
    p = _checked_input(display, "recording")
    with reading() as rot:  # an input axis map in force (guidefit.io.axes.input_axes): applied once, here
        return map_input(fmt.read(p, display), rot, display)


def write_recording(path, recording, *, compression: str | None = None) -> None:
    """Write a recording in the format its suffix chooses (contract HDF5 or CSV, UFF-58).

    The file is written under a temporary name and renamed when complete, so
    a failed write leaves no partial file.

    Parameters
    ----------
    path : str or path-like
        ``.h5``/``.hdf5`` (any number of runs, both layouts), ``.csv`` (one
        ``signals`` run; a ``time`` column is written as well), ``.uff``/``.unv``.
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
    >>> from guidefit.io import RunData
    >>> run = RunData("lateral", 200_000.0, [1, 0, 0], ["force", "acc_A_x"], ["N", "m/s^2"],
    ...               [[0, 0, 0], [0.03, 0, 0.045]], [[1, 0, 0], [1, 0, 0]],
    ...               data=np.zeros((3, 16, 2), dtype=np.float32), pretrigger_samples=4)
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     write_recording(os.path.join(folder, "rec.h5"), run)
    ...     back = read_recording(os.path.join(folder, "rec.h5")).to_data()
    >>> back.runs[0] == run
    True
    """
    fmt = format_for(path, "recording", "write")
    if compression is not None:
        fmt.write(path, recording, compression=compression)
    else:
        fmt.write(path, recording)


def write_frfs(path, frfsets, recording=None) -> None:
    """Write FRF sets to ``path``; the suffix chooses the format (.csv, .h5/.hdf5, .uff/.unv).

    ``recording`` (the source :class:`~guidefit.io.records.Recording`) gives UFF
    files the exact excitation and sensor directions.
    """
    fmt = format_for(path, "frf", "write")
    fmt.write(path, frfsets, recording=recording)
