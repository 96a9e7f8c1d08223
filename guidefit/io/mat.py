"""MATLAB .mat files (MATLAB, Simcenter, Data Physics exports) as a test setup's DAQ files.

Versions 5 to 7 are read with :func:`scipy.io.loadmat` (only the variables a
run uses, held in memory: the format does not stream); version 7.3 is HDF5
and read with h5py in slices (bounded memory). A setup's ``source`` is a
variable name (a vector) or ``variable:k`` for column ``k`` (0-based) of a
2-D array whose rows are samples (MATLAB's ``n x channels``). A run's
``group`` is the name of a struct whose fields are the variables. The sample
rate comes from a scalar variable ``fs``, ``Fs`` or ``sample_rate_hz``, or a
time vector ``t`` or ``time`` (seconds, uniformly spaced); if both exist
they must agree, and a time vector must hold one time per sample of every
channel a run reads (a time vector of another length describes other data).
Variables of three or more dimensions are no channels: a ``source`` that
names one is told so. .mat files state no units.

MATLAB stores arrays column-major: in a v7.3 (HDF5) file an ``n x k``
MATLAB array is a dataset of shape ``(k, n)``, so column ``k`` of the
MATLAB array is row ``k`` of the dataset, and a vector is ``(1, n)`` or
``(n, 1)``. The HDF5 file is checked as the recording contract's is
(links, external storage, virtual datasets; :mod:`guidefit.io.hdf5`).

Examples
--------
>>> import os, tempfile
>>> import numpy as np
>>> import scipy.io
>>> from guidefit.io._daq import RunOptions
>>> with tempfile.TemporaryDirectory() as folder:
...     path = os.path.join(folder, "hit.mat")
...     scipy.io.savemat(path, {"data": np.arange(12.0).reshape(6, 2), "fs": 51200.0})
...     daq = open_daq(Path(path), "hit.mat", RunOptions("test.toml: runs.a"))
...     ch = daq.find("data:1")
...     block = daq.make_source((ch,), np.float64).read((slice(0, 3), slice(None)))
>>> daq.sample_rate_hz, [c.name for c in daq.channels], block[:, 0].tolist()
(51200.0, ['data:0', 'data:1'], [1.0, 3.0, 5.0])
"""

from __future__ import annotations

import contextlib
import functools
import math
from pathlib import Path

import numpy as np

from guidefit.errors import RecordingError
from guidefit.io._checks import _first_line
from guidefit.io._daq import ColumnSource, DaqChannel, DaqFile, RunOptions, nice_rate, rate_from_time, same_rate
from guidefit.io.registry import FileFormat

__all__ = ["MatH5Source", "MatSource", "open_daq"]

SUFFIXES = (".mat",)
RATE_NAMES = ("fs", "Fs", "sample_rate_hz")
TIME_NAMES = ("t", "time")
_HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
_NUMERIC_CLASSES = {"double", "single", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64"}


def _is_v73(path: Path) -> bool:
    """Whether the file is HDF5 (MATLAB 7.3 puts the signature after a 512-byte header)."""
    with open(path, "rb") as fh:
        head = fh.read(520)
    return head[:8] == _HDF5_SIGNATURE or head[512:520] == _HDF5_SIGNATURE


# --------------------------------------------------------------------- sources


class MatSource(ColumnSource):
    """Variables of a MAT v5 file (loaded once, only those a run uses); keys are (variable, column or None)."""

    def _arrays(self) -> dict:
        cache = getattr(self, "_cache", None)
        if cache is None:
            cache = _load_v5(self.facts["path"], self.facts["group"], sorted({k[0] for k in self.keys}))
            self._cache = cache
        return cache

    def _read(self, handle, start, stop, keys):
        arrays = self._arrays()
        for name, _ in keys:
            if np.asarray(arrays[name]).dtype.kind not in "fiu":  # whosmat calls complex arrays 'double'
                raise RecordingError(f"{self.facts.get('display', self.facts['path'])}: variable '{name}' holds "
                                     f"{np.asarray(arrays[name]).dtype.name} numbers; expected real samples")
        return [_v5_column(arrays[name], col)[start:stop] for name, col in keys]


class MatH5Source(ColumnSource):
    """Variables of a MAT v7.3 (HDF5) file read in slices; keys are (dataset path, row or None)."""

    @contextlib.contextmanager
    def _open(self):
        import h5py

        with h5py.File(self.facts["path"], "r") as f:
            yield f

    def _read(self, handle, start, stop, keys):
        return [_h5_slice(handle[name], row, start, stop) for name, row in keys]


def _h5_slice(ds, row, start, stop):
    if row is not None:
        return ds[row, start:stop]
    return ds[0, start:stop] if ds.shape[0] == 1 else ds[start:stop, 0]


# ------------------------------------------------------------------- version 5


def _load_v5(path: str, group, names) -> dict:
    import scipy.io

    if group is None:
        return scipy.io.loadmat(path, variable_names=list(names))
    struct = scipy.io.loadmat(path, variable_names=[group], simplify_cells=True)[group]
    return {name: np.asarray(struct[name]) for name in names if name in struct}


def _v5_column(arr, col):
    arr = np.asarray(arr)
    if col is None:
        return arr.reshape(-1)
    return arr[:, col]


def _numeric(arr) -> bool:
    return isinstance(arr, np.ndarray) and arr.dtype.kind in "fiu" and arr.size > 0


def _v5_variables(path: Path, display: str, options: RunOptions) -> dict:
    """name -> (shape, dtype, array or None): the file's numeric variables (of the struct ``group``)."""
    import scipy.io

    try:
        listing = scipy.io.whosmat(str(path))
        if options.group is None:
            small = [n for n, shape, _ in listing if n in RATE_NAMES + TIME_NAMES]
            loaded = scipy.io.loadmat(str(path), variable_names=small) if small else {}
            out = {}
            for name, shape, cls in listing:
                if cls in _NUMERIC_CLASSES:
                    out[name] = (tuple(shape), np.dtype(np.float32 if cls == "single" else np.float64),
                                 loaded.get(name))
            return out
        group = str(options.group)
        structs = [n for n, _, cls in listing if cls == "struct"]
        if group not in structs:
            raise RecordingError(
                f"{options.where}: group '{group}' is not a struct in {display}; the file has "
                f"{'structs ' + ', '.join(structs) if structs else 'no structs'}"
            )
        struct = scipy.io.loadmat(str(path), variable_names=[group], simplify_cells=True)[group]
    except RecordingError:
        raise
    except (ValueError, TypeError, OSError, KeyError, NotImplementedError, EOFError) as exc:
        raise RecordingError(f"{display}: not a readable MAT file ({_first_line(exc)})") from None
    if not isinstance(struct, dict):
        raise RecordingError(f"{options.where}: group '{group}' in {display} is a struct array; expected one struct")
    out = {}
    for name, value in struct.items():
        arr = np.asarray(value) if not isinstance(value, (str, dict, list)) else None
        if arr is not None and _numeric(arr):
            arr2 = arr.reshape(-1, 1) if arr.ndim <= 1 else arr  # 3-D and more: explained if named
            out[name] = (arr2.shape, np.dtype(np.float32 if arr.dtype == np.float32 else np.float64), arr2)
    return out


# ----------------------------------------------------------------- version 7.3


def _v73_variables(p: Path, display: str, group) -> dict:
    """name -> (MATLAB shape, dtype, dataset path, value of a scalar or None), metadata only.

    Run in a forked child with a deadline when the HDF5 guard is on (damaged HDF5
    metadata can make the library loop; :mod:`guidefit.io.watchdog`).
    """
    import h5py

    from guidefit.io.hdf5 import _check_storage, _get_checked, _h5_open_error

    try:
        f = h5py.File(p, "r")
    except OSError as exc:
        raise _h5_open_error(p, display, exc) from None
    with f:
        node = f
        if group is not None:
            node = _get_checked(f, str(group), f"{display}: group '{group}'")
            if not isinstance(node, h5py.Group):
                structs = [k for k in f if isinstance(f.get(k), h5py.Group) and not k.startswith("#")]
                raise RecordingError(
                    f"{display}: '{group}' is not a struct; the file has "
                    f"{'structs ' + ', '.join(structs) if structs else 'no structs'}"
                )
        out = {}
        for name in node:
            if name.startswith("#"):
                continue
            obj = _get_checked(node, name, f"{display}: variable '{name}'")
            if not isinstance(obj, h5py.Dataset):
                continue
            cls = obj.attrs.get("MATLAB_class", b"")
            cls = cls.decode() if isinstance(cls, bytes) else str(cls)
            if cls not in _NUMERIC_CLASSES or obj.dtype.kind not in "fiu" or obj.size == 0:
                continue
            if bool(obj.attrs.get("MATLAB_empty", 0)):
                continue
            _check_storage(obj, p, f"{display}: variable '{name}'")
            shape = tuple(int(d) for d in reversed(obj.shape))  # MATLAB's rows x columns (x pages...)
            value = float(obj[0, 0]) if obj.size == 1 else None
            out[name] = (shape, np.dtype(np.float32 if obj.dtype == np.float32 else np.float64), obj.name, value)
        return out


def _v73_metadata(p: Path, display: str, group) -> dict:
    from guidefit.io.watchdog import read_guarded

    return read_guarded(functools.partial(_v73_variables, group=group), p, display, "MAT 7.3 (HDF5) file")


# ------------------------------------------------------------------- channels


_MAX_EXPLAINED_COLUMNS = 1024


def _shown(shape) -> str:
    return " x ".join(str(d) for d in shape)


def _channels(variables: dict, key_of) -> tuple[list, dict, dict]:
    """DaqChannels of the vectors and of the columns of 2-D arrays; ``name:0`` of a column
    vector (n x 1, a 2-D array in MATLAB); wide arrays and arrays of more dimensions (not
    channels, but a ``source`` that names one is told why) explained."""
    channels, ambiguous, aliases = [], {}, {}
    for name, (shape, dtype, *_rest) in variables.items():
        if name in RATE_NAMES + TIME_NAMES:
            continue
        if len(shape) != 2:
            why = (f"variable '{name}' is {_shown(shape)}; a channel is a vector or a column of a 2-D array "
                   "whose rows are samples")
            ambiguous[name] = why
            ambiguous.update({f"{name}:{k}": why for k in range(min(shape[1] if len(shape) > 1 else 1,
                                                                    _MAX_EXPLAINED_COLUMNS))})
            continue
        rows, cols = shape
        if rows == 1 or cols == 1:
            channels.append(DaqChannel(name, key_of(name, None, shape), max(rows, cols), dtype=dtype))
            if cols == 1:
                aliases[f"{name}:0"] = channels[-1]
        elif rows >= cols:
            channels.extend(
                DaqChannel(f"{name}:{k}", key_of(name, k, shape), rows, dtype=dtype) for k in range(cols)
            )
        else:
            for k in range(cols):
                ambiguous[f"{name}:{k}"] = (
                    f"variable '{name}' is {rows} x {cols}; '{name}:k' is column k of an array whose rows "
                    f"are samples: transpose it ({name}.') where it is written"
                )
    return channels, ambiguous, aliases


def _scalar_rate(variables: dict, display: str) -> tuple[float | None, str]:
    """The rate of the variables ``fs``, ``Fs``, ``sample_rate_hz`` (all that exist must agree)."""
    rate, origin = None, ""
    for name in RATE_NAMES:
        if name in variables:
            shape, _, *rest = variables[name]
            value = rest[-1]
            if isinstance(value, np.ndarray):
                value = value.reshape(-1)[0] if value.size == 1 and value.dtype.kind in "fiu" else None
            if shape not in ((1, 1),) or value is None or not math.isfinite(value) or value <= 0:
                raise RecordingError(f"{display}: variable '{name}' must be one positive number (Hz)")
            value = nice_rate(float(value))
            if rate is not None and not same_rate(rate, value):
                raise RecordingError(f"{display}: {origin} says {rate:.9g} Hz but variable '{name}' {value:.9g} Hz")
            rate, origin = (rate, origin) if rate is not None else (value, f"variable '{name}'")
    return rate, origin


def _file_rate(variables: dict, display: str, rate_of_time) -> tuple[float | None, str, str | None, int]:
    """(rate, where it comes from, the time variable, its length) of a .mat file: every rate
    variable and every time variable (``rate_of_time(name, n)`` reads its rate) must agree."""
    rate, origin = _scalar_rate(variables, display)
    time_name, n_time = None, 0
    for name in TIME_NAMES:
        if name not in variables:
            continue
        n = _check_time_shape(display, name, variables[name][0])
        fs_time = rate_of_time(name, n)
        if rate is not None and not same_rate(rate, fs_time):
            raise RecordingError(f"{display}: time variable '{name}' gives {fs_time:.9g} Hz but {origin} says "
                                 f"{rate:.9g} Hz")
        if time_name is not None and n != n_time:
            raise RecordingError(f"{display}: time variables '{time_name}' ({n_time} times) and '{name}' ({n}) "
                                 "differ in length")
        rate, origin = (rate, origin) if rate is not None else (fs_time, f"time variable '{name}'")
        time_name, n_time = (time_name, n_time) if time_name is not None else (name, n)
    return rate, origin, time_name, n_time


def _check_time_shape(display: str, name: str, shape) -> int:
    """The number of times of a time variable; one line if it is not a vector."""
    if len(shape) != 2 or (shape[0] != 1 and shape[1] != 1):
        raise RecordingError(f"{display}: time variable '{name}' is {_shown(shape)}; expected a vector")
    return max(shape)


def _rate_for(display: str, time_name: str | None, n_time: int, rate: float | None):
    """``DaqFile.rate_for`` of a .mat file: the file's rate, once every channel of the run has
    one sample per time of the time vector (a time vector of another length describes
    other data: its rate is not theirs)."""

    def rate_for(chans) -> float | None:
        for ch in chans if time_name is not None else ():
            if ch.n_samples != n_time:
                raise RecordingError(
                    f"{display}: time variable '{time_name}' holds {n_time} times but channel '{ch.name}' "
                    f"{ch.n_samples} samples; a time vector needs one time per sample"
                )
        return rate

    return rate_for


def open_daq(path: Path, display: str, options: RunOptions) -> DaqFile:
    """The variables of a .mat file (v5-v7: scipy.io; v7.3: h5py) for a setup's run.

    Raises
    ------
    RecordingError
        Not a MAT file; an unknown struct; a rate variable that is not one
        positive number; a time variable that is not a vector, not uniform or
        disagrees with the rate variable (and, from ``rate_for``, one whose
        length is not the run's channels').
    """
    if _is_v73(path):
        return _open_v73(path, display, options)
    variables = _v5_variables(path, display, options)
    group = None if options.group is None else str(options.group)

    def rate_of_time(name: str, n: int) -> float:
        arr = variables[name][2]
        if arr is None:
            arr = _load_v5(str(path), group, [name])[name]
        if np.asarray(arr).dtype.kind not in "fiu":
            raise RecordingError(f"{display}: time variable '{name}' holds {np.asarray(arr).dtype.name}; "
                                 "expected real times in seconds")
        t = np.asarray(arr, dtype=np.float64).reshape(-1)
        return rate_from_time(lambda a, b: t[a:b], t.size, f"{display}: time variable '{name}'")

    rate, origin, time_name, n_time = _file_rate(variables, display, rate_of_time)
    channels, ambiguous, aliases = _channels(variables, lambda name, col, shape: (name, col))
    return DaqFile(
        display=display,
        channels=tuple(channels),
        ambiguous=ambiguous,
        aliases=aliases,
        sample_rate_hz=rate,
        rate_origin=origin,
        rate_for=_rate_for(display, time_name, n_time, rate),
        make_source=lambda chans, dtype: MatSource(
            keys=[ch.key for ch in chans], n_samples=chans[0].n_samples, dtype=dtype, path=str(path), group=group,
            display=display,
        ),
    )


def _open_v73(path: Path, display: str, options: RunOptions) -> DaqFile:
    import h5py

    variables = _v73_metadata(path, display, options.group)

    def rate_of_time(name: str, n: int) -> float:
        with h5py.File(path, "r") as f:
            ds = f[variables[name][2]]
            return rate_from_time(lambda a, b: _h5_slice(ds, None, a, b), n, f"{display}: time variable '{name}'")

    rate, origin, time_name, n_time = _file_rate(variables, display, rate_of_time)
    channels, ambiguous, aliases = _channels(variables, lambda name, col, shape: (variables[name][2], col))
    return DaqFile(
        display=display,
        channels=tuple(channels),
        ambiguous=ambiguous,
        aliases=aliases,
        note="" if channels else "no numeric MATLAB variables (datasets with a MATLAB_class attribute)",
        sample_rate_hz=rate,
        rate_origin=origin,
        rate_for=_rate_for(display, time_name, n_time, rate),
        make_source=lambda chans, dtype: MatH5Source(
            keys=[ch.key for ch in chans], n_samples=chans[0].n_samples, dtype=dtype, path=str(path)
        ),
    )


FORMATS = (
    FileFormat(name="MATLAB .mat (v5-v7.3)", suffixes=SUFFIXES, kind="daq", read=open_daq, streaming=False),
)
