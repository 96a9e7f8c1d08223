"""Validation and formatting helpers shared by the recording readers and writers.

Pure functions on numbers and text (numpy only); every one raises
:class:`~guidefit.errors.RecordingError` with a one-line message naming
``where`` (file, run, channel) and what was expected.
"""

from __future__ import annotations

import math
from dataclasses import fields
from typing import Any

import numpy as np

from guidefit.errors import RecordingError, first_line

UNIT_VECTOR_TOLERANCE = 1e-3
"""Largest allowed | |d| - 1 | of a direction vector."""

MAX_POSITION_M = 1.0
"""Largest allowed distance (m) of a sensor or hit point from the carriage origin: a carriage is
centimetres across, so a point metres away is a length in millimetres (1000x) read as metres."""


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


def _check_position(vec, where: str, name: str) -> np.ndarray:
    """``vec`` (3 finite numbers, m) if within :data:`MAX_POSITION_M` of the carriage origin, else one
    :class:`RecordingError` naming the likely cause (millimetres given as metres)."""
    dist = float(np.linalg.norm(vec))
    if dist > MAX_POSITION_M:
        raise RecordingError(
            f"{where}: {name} {_fmt_vec(vec)} is {dist:.3g} m from the carriage origin; positions are "
            f"metres in the carriage frame, at most {MAX_POSITION_M:g} m (millimetres given?)"
        )
    return vec


def _check_force_axis(force_direction, excitation_direction, where: str) -> None:
    """One :class:`RecordingError` when the force channel's direction and ``excitation_direction``
    are different axes: both are the hammer's line of action (a positive force sample pushes the
    carriage along ``excitation_direction``), so a file that gives two says one of them wrong.
    Opposite signs of one axis pass (the sign of the load cell's axis is a convention; the force
    samples' sign is checked per hit)."""
    f = np.asarray(force_direction, float)
    e = np.asarray(excitation_direction, float)
    if abs(float(f @ e)) < 1.0 - UNIT_VECTOR_TOLERANCE:
        raise RecordingError(
            f"{where}: channel 'force' has direction {_fmt_vec(f)}, excitation_direction is {_fmt_vec(e)}; "
            "both are the hammer's line of action: correct the one that is wrong"
        )


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


_first_line = first_line  # the one helper, in guidefit.errors


# ------------------------------------------------------------- default layout


def _atomic(p, write) -> None:
    """``write(tmp)`` to a temporary file beside ``p`` (same suffix), then rename it over ``p``;
    on any error (an interrupt included) no file is left and ``p`` is untouched.

    The shared helper of every output file: :func:`guidefit.outputs.replacing`.
    """
    from guidefit.outputs import replacing

    with replacing(p) as tmp:
        write(tmp)


def _require(module: str, extra: str, display: str, what: str):
    """``importlib.import_module(module)``, or one RecordingError naming the pip extra.

    For format modules whose library is optional: ``_require("nptdms", "daq",
    display, "NI TDMS")`` gives ``<file>: reading NI TDMS needs the package
    'nptdms': pip install 'guidefit[daq]'``.

    Examples
    --------
    >>> _require("math", "daq", "x.tdms", "NI TDMS").sqrt(4.0)
    2.0
    >>> _require("no_such_module_x", "daq", "x.tdms", "NI TDMS")
    Traceback (most recent call last):
    ...
    guidefit.errors.RecordingError: x.tdms: reading NI TDMS needs the package 'no_such_module_x': pip install 'guidefit[daq]'
    """
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError:
        raise RecordingError(
            f"{display}: reading {what} needs the package '{module}': pip install 'guidefit[{extra}]'"
        ) from None
