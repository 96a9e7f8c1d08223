"""Test setups (``.toml``): a DAQ's own files made into a recording, read in place.

A hammer test is recorded by a data-acquisition system in volts or
engineering units under the DAQ's own channel names, one file (or group) per
run. A test setup (``shared/test-setup-format.md``, version 1) says which
channel is the hammer, which accelerometer sits where, each sensor's
sensitivity and how each run was excited. :func:`read_setup` (what
:func:`guidefit.io.read_recording` calls for ``.toml``) checks the whole
setup first (:func:`load_setup`: every problem one line naming the setup
file, its table and key), then opens each run's DAQ file through the reader
its suffix selects (the registry's formats of kind ``daq``:
:mod:`~guidefit.io.tdms`, :mod:`~guidefit.io.mdf`, :mod:`~guidefit.io.mat`,
:mod:`~guidefit.io.wav`, :mod:`~guidefit.io.text`, and UFF-58 time data
through :mod:`~guidefit.io.uff`), and gives the same
:class:`~guidefit.io.records.Recording` a contract file gives: layout
``signals`` (the hits are found by :mod:`guidefit.hits`), samples left in
the DAQ file in file units, each channel's ``scale_to_si`` carrying its
sensitivity::

    scale_to_si = unit_factor * (1000 / sensitivity_mv  or  scale  or  1)

with ``unit_factor`` 1 for ``N`` and ``m/s^2`` and 9.80665 for ``g`` (the
channel keeps ``unit = "g"``, so :func:`convert` writes values in g, as the
recording contract allows).

Checks beyond the types of the keys, so that a setup that does not fit its
files stops with one line instead of giving a wrong number: a unit the DAQ
file states must fit the setup (volts need ``sensitivity_mv`` or ``scale``;
``sensitivity_mv`` needs volts; a file in ``g`` is not ``m/s^2``); a run's
channels must have one length and one sample rate; the setup's
``sample_rate_hz`` must agree with the file's (within 1e-5); unknown keys
are refused (a misspelt ``sensitivity_mV`` would otherwise be ignored).

Examples
--------
>>> import os, tempfile
>>> from guidefit.io import read_recording
>>> setup = '''
... format = "guidefit-setup"
... format_version = 1
... [channels.force]
... source = "Hammer"
... unit = "N"
... sensitivity_mv = 2.0
... [channels.acc_A_y]
... source = "A_Y"
... unit = "g"
... sensitivity_mv = 10.0
... [runs.vertical]
... file = "vertical.txt"
... excitation_direction = [0.0, -1.0, 0.0]
... '''
>>> rows = "".join(f"{k * 1e-4:.4f}\\t{k * 0.002:.3f}\\t{k * 0.01:.2f}\\n" for k in range(4))
>>> with tempfile.TemporaryDirectory() as folder:
...     for name, text in (("test.toml", setup), ("vertical.txt", "t\\tHammer\\tA_Y\\n" + rows)):
...         with open(os.path.join(folder, name), "w") as fh:
...             _ = fh.write(text)
...     run = read_recording(os.path.join(folder, "test.toml")).runs[0]
...     block = run.read_block(1, 3)
>>> run.sample_rate_hz, run.channel_names, [ch.unit for ch in run.channels]
(10000.0, ('force', 'acc_A_y'), ['N', 'g'])
>>> block.round(4).tolist()  # 2 mV/N and 10 mV/g: N and m/s^2
[[1.0, 9.8066], [2.0, 19.6133]]
"""

from __future__ import annotations

import difflib
import math
import os
import stat
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from guidefit.errors import GuidefitError, RecordingError
from guidefit.io._checks import MAX_POSITION_M, UNIT_VECTOR_TOLERANCE, _first_line, _valid_run_name
from guidefit.io._daq import ColumnSource, DaqChannel, DaqFile, RunOptions, common_dtype, same_rate
from guidefit.io.geometry import _ACC_RE, default_channel_geometry
from guidefit.io.records import ACCELERATION_UNITS, FORCE_UNITS, Recording, Run, RunData
from guidefit.io.registry import FileFormat, formats

__all__ = ["Setup", "SetupChannel", "SetupError", "SetupRun", "convert", "load_setup", "read_setup"]

SETUP_FORMAT = "guidefit-setup"
SETUP_VERSION = 1
SUFFIXES = (".toml",)
ROOT_KEYS = ("format", "format_version", "guide", "description", "channels", "runs")
CHANNEL_KEYS = ("source", "unit", "sensitivity_mv", "scale", "position_m", "direction")
RUN_KEYS = ("file", "group", "excitation_direction", "excitation_position_m", "sample_rate_hz", "channels",
            "delimiter", "decimal")
_TEXT_KEYS = ("delimiter", "decimal")

# what a DAQ file's unit text may say for each guidefit unit (compared in lower case)
_UNIT_SPELLINGS = {
    "N": {"n", "newton", "newtons"},
    "m/s^2": {"m/s^2", "m/s²", "m/s2", "m/s**2", "m*s^-2", "m s^-2", "m/s/s", "ms^-2", "m·s^-2", "m·s⁻²"},
    "g": {"g", "gn", "g0"},
}
_VOLTS = {"v", "volt", "volts"}


class SetupError(RecordingError):
    """A test setup does not follow ``test-setup-format.md`` or does not fit its DAQ files (exit 2)."""


# ------------------------------------------------------------------ the setup


@dataclass(frozen=True)
class SetupChannel:
    """One ``[channels.<name>]`` table, checked.

    Attributes
    ----------
    name : str
        guidefit channel name (``force``, ``acc_A_y``).
    source : str
        The channel's name (or index, as text) in the DAQ files.
    unit : str
        ``N``, ``m/s^2`` or ``g``.
    factor : float
        Value in ``unit`` per file value: ``1000 / sensitivity_mv``, ``scale`` or 1.
    given : str or None
        ``"sensitivity_mv"``, ``"scale"`` or None (the file is in ``unit``).
    position_m, direction : ndarray, shape (3,), or None
        As given; None: from the guide's points and the name's axis.
    """

    name: str
    source: str
    unit: str
    factor: float
    given: str | None
    position_m: np.ndarray | None
    direction: np.ndarray | None


@dataclass(frozen=True)
class SetupRun:
    """One ``[runs.<name>]`` table, checked (its file exists; nothing read from it yet)."""

    name: str
    file: str
    path: Path
    display: str
    group: str | int | None
    excitation_direction: np.ndarray
    excitation_position_m: np.ndarray | None
    sample_rate_hz: float | None
    channels: tuple[str, ...] | None
    delimiter: str | None
    decimal: str | None
    format: FileFormat


@dataclass(frozen=True)
class Setup:
    """A checked test setup: root fields, channels by name (file order), runs (file order)."""

    path: str
    guide: str | None
    description: str
    channels: dict
    runs: tuple[SetupRun, ...]


def _show(value) -> str:
    if isinstance(value, str):
        return repr(value)
    if isinstance(value, dict):
        return "a table"
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _unknown_keys(table: dict, allowed: tuple, where: str) -> None:
    for key in table:
        if key not in allowed:
            close = difflib.get_close_matches(key, allowed, n=1, cutoff=0.6)
            if not close:
                close = [k for k in allowed if k.lower() == str(key).lower()]
            hint = f" (did you mean '{close[0]}'?)" if close else ""
            raise SetupError(f"{where}: unknown key '{key}'{hint}; expected {', '.join(allowed)}")


def _vector(value, where: str, key: str, unit_vector: bool) -> np.ndarray:
    ok = isinstance(value, list) and len(value) == 3 and all(_is_number(v) for v in value)
    what = "a unit vector of 3 numbers" if unit_vector else "3 numbers (m)"
    if not ok:
        raise SetupError(f"{where}: {key} must be {what}, got {_show(value)}")
    vec = np.array(value, dtype=np.float64)
    if unit_vector:
        norm = float(np.linalg.norm(vec))
        if abs(norm - 1.0) > UNIT_VECTOR_TOLERANCE:
            raise SetupError(f"{where}: {key} must be {what}, got {_show(value)} (length {norm:.4g})")
    elif float(np.linalg.norm(vec)) > MAX_POSITION_M:
        raise SetupError(f"{where}: {key} must be metres within {MAX_POSITION_M:g} m of the carriage origin, "
                         f"got {_show(value)} ({float(np.linalg.norm(vec)):.3g} m; millimetres given?)")
    return vec


def _text(value, where: str, key: str) -> str:
    if not isinstance(value, str) or not value.strip():
        raise SetupError(f"{where}: {key} must be non-empty text, got {_show(value)}")
    return value


def _check_channel(name: str, table, display: str) -> SetupChannel:
    where = f"{display}: channels.{name}"
    if name != "force" and not _ACC_RE.match(name):
        raise SetupError(
            f"{where}: not a guidefit channel name; expected 'force' or 'acc_<point>_<axis>' with axis x, y or z, "
            "e.g. 'acc_A_y'"
        )
    if not isinstance(table, dict):
        raise SetupError(f"{where}: expected a table with source and unit, got {_show(table)}")
    _unknown_keys(table, CHANNEL_KEYS, where)
    if "source" not in table:
        raise SetupError(f"{where}: source missing; expected the channel's name in the DAQ file")
    source = table["source"]
    if isinstance(source, int) and not isinstance(source, bool) and source >= 0:
        source = str(source)
    source = _text(source, where, "source")
    allowed = FORCE_UNITS if name == "force" else ACCELERATION_UNITS
    expected = " or ".join(f"'{u}'" for u in allowed)
    if "unit" not in table:
        raise SetupError(f"{where}: unit missing; expected {expected}")
    unit = table["unit"]
    if unit not in allowed:
        hint = ""
        if isinstance(unit, str) and unit.strip().lower() in _VOLTS | {"mv"}:
            hint = " (the engineering unit; a file in volts takes sensitivity_mv or scale)"
        raise SetupError(f"{where}: unit must be {expected}, got {_show(unit)}{hint}")
    if "sensitivity_mv" in table and "scale" in table:
        raise SetupError(f"{where}: sensitivity_mv and scale both given; expected at most one")
    factor, given = 1.0, None
    if "sensitivity_mv" in table:
        value = table["sensitivity_mv"]
        if not _is_number(value) or value <= 0:
            raise SetupError(f"{where}: sensitivity_mv must be a positive number, got {_show(value)}")
        factor, given = 1000.0 / float(value), "sensitivity_mv"
    elif "scale" in table:
        value = table["scale"]
        if not _is_number(value) or value == 0:
            raise SetupError(f"{where}: scale must be a finite, non-zero number, got {_show(value)}")
        factor, given = float(value), "scale"
    position = _vector(table["position_m"], where, "position_m", False) if "position_m" in table else None
    direction = _vector(table["direction"], where, "direction", True) if "direction" in table else None
    return SetupChannel(name, source, unit, factor, given, position, direction)


def _daq_formats() -> dict:
    return {s: f for f in formats("daq") if f.read for s in f.suffixes}


def _check_file(value, where: str, setup_path: Path, setup_display: str,
                planning: bool = False) -> tuple[Path, str, FileFormat]:
    if value is None:
        raise SetupError(f"{where}: file missing; expected the run's DAQ file, relative to the setup")
    text = _text(value, where, "file")
    path = setup_path.parent / text
    display = os.path.join(os.path.dirname(setup_display), text)
    suffix = Path(text).suffix.lower()
    known = _daq_formats()
    if suffix not in known:
        hint = ""
        if suffix in (".h5", ".hdf5"):
            hint = " (a contract recording is read directly: guidefit identify " + text + ")"
        raise SetupError(
            f"{where}: file '{text}' has suffix '{Path(text).suffix}', not a DAQ file type; expected "
            f"{', '.join(sorted(known))}{hint}"
        )
    if planning:  # guidefit plan: the test has not been made yet
        return path, display, known[suffix]
    try:
        mode = os.stat(path).st_mode
    except OSError:
        raise SetupError(f"{where}: file '{text}' not found next to the setup") from None
    if stat.S_ISDIR(mode):
        raise SetupError(f"{where}: file '{text}' is a directory; expected a DAQ file")
    if not stat.S_ISREG(mode):
        raise SetupError(f"{where}: file '{text}' is not a regular file (a device or FIFO?)")
    if os.stat(path).st_size == 0:
        raise SetupError(f"{where}: file '{text}' is empty")
    return path, display, known[suffix]


def _check_run(name: str, table, channels: dict, setup_path: Path, display: str, planning: bool = False) -> SetupRun:
    where = f"{display}: runs.{name}"
    if not _valid_run_name(name):
        raise SetupError(f"{where}: run name not allowed; expected text without '/', line breaks or outer spaces")
    if not isinstance(table, dict):
        raise SetupError(f"{where}: expected a table with file and excitation_direction, got {_show(table)}")
    _unknown_keys(table, RUN_KEYS, where)
    if "file" not in table:
        raise SetupError(f"{where}: file missing; expected the run's DAQ file, relative to the setup")
    path, file_display, fmt = _check_file(table["file"], where, setup_path, display, planning)
    group = table.get("group")
    if group is not None and not (isinstance(group, str) and group.strip()) and not (
        isinstance(group, int) and not isinstance(group, bool) and group >= 0
    ):
        raise SetupError(f"{where}: group must be a name or a channel-group index (>= 0), got {_show(group)}")
    if "excitation_direction" not in table:
        raise SetupError(f"{where}: excitation_direction missing; expected a unit vector such as [0.0, -1.0, 0.0]")
    exc_dir = _vector(table["excitation_direction"], where, "excitation_direction", True)
    exc_pos = None
    if "excitation_position_m" in table:
        exc_pos = _vector(table["excitation_position_m"], where, "excitation_position_m", False)
    rate = None
    if "sample_rate_hz" in table:
        rate = table["sample_rate_hz"]
        if not _is_number(rate) or rate <= 0:
            raise SetupError(f"{where}: sample_rate_hz must be a positive number (Hz), got {_show(rate)}")
        rate = float(rate)
    names = None
    if "channels" in table:
        names = _run_channels(table["channels"], channels, where)
    delimiter, decimal = _text_keys(table, fmt, file_display, where)
    return SetupRun(name, str(table["file"]), path, file_display, group, exc_dir, exc_pos, rate, names,
                    delimiter, decimal, fmt)


def _run_channels(value, channels: dict, where: str) -> tuple[str, ...]:
    if not isinstance(value, list) or not value or not all(isinstance(v, str) for v in value):
        raise SetupError(f"{where}: channels must be a list of channel names, got {_show(value)}")
    for v in value:
        if v not in channels:
            raise SetupError(
                f"{where}: channels: '{v}' has no [channels.{v}] table; have {', '.join(channels)}"
            )
        if value.count(v) > 1:
            raise SetupError(f"{where}: channels: '{v}' listed {value.count(v)} times")
    if "force" not in value:
        raise SetupError(f"{where}: channels must include 'force', got {_show(value)}")
    if len(value) < 2:
        raise SetupError(f"{where}: channels must include an acceleration besides 'force'")
    return tuple(value)


def _text_keys(table: dict, fmt: FileFormat, file_display: str, where: str):
    from guidefit.io.text import DECIMALS, DELIMITERS

    given = [k for k in _TEXT_KEYS if k in table]
    if given and not fmt.module.endswith(".text"):
        raise SetupError(
            f"{where}: {given[0]} applies to text exports (.csv, .txt, .tsv); '{file_display}' is {fmt.name}"
        )
    delimiter = decimal = None
    if "delimiter" in table:
        value = table["delimiter"]
        if not isinstance(value, str) or (value.lower() not in DELIMITERS and value not in DELIMITERS):
            raise SetupError(
                f"{where}: delimiter must be ',', ';', '\\t' (tab) or ' ' (spaces), got {_show(value)}"
            )
        delimiter = DELIMITERS.get(value, DELIMITERS.get(value.lower()))
    if "decimal" in table:
        value = table["decimal"]
        if value not in DECIMALS:
            raise SetupError(f"{where}: decimal must be '.' or ',', got {_show(value)}")
        decimal = value
    if delimiter == "," and decimal == ",":
        raise SetupError(f"{where}: delimiter and decimal are both ','; a text export cannot use both")
    return delimiter, decimal


def load_setup(path, planning: bool = False) -> Setup:
    """Parse and check a test setup; no DAQ file is opened (only their existence is checked).

    Parameters
    ----------
    path : str or path-like
        The ``.toml`` setup.
    planning : bool
        The DAQ files need not exist yet (``guidefit plan`` before the test).

    Raises
    ------
    SetupError
        One line naming the setup file, the table and the key
        (``test.toml: channels.acc_A_y: sensitivity_mv must be a positive number, got -10.2``).
    """
    import tomllib

    display = os.fspath(path)
    p = Path(display)
    try:
        with open(p, "rb") as fh:
            data = tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        raise SetupError(f"{display}: not valid TOML ({_first_line(exc)})") from None
    except UnicodeDecodeError:
        raise SetupError(f"{display}: not UTF-8 text; expected a TOML test setup") from None
    _unknown_keys(data, ROOT_KEYS, display)
    if "format" not in data:
        raise SetupError(f"{display}: format missing; expected format = \"{SETUP_FORMAT}\"")
    if data["format"] != SETUP_FORMAT:
        raise SetupError(f"{display}: format must be \"{SETUP_FORMAT}\", got {_show(data['format'])}")
    if "format_version" not in data:
        raise SetupError(f"{display}: format_version missing; expected format_version = {SETUP_VERSION}")
    version = data["format_version"]
    if isinstance(version, bool) or not isinstance(version, int):
        raise SetupError(f"{display}: format_version must be an integer, got {_show(version)}")
    if version != SETUP_VERSION:
        raise SetupError(
            f"{display}: format_version {version} is not supported; this guidefit reads version {SETUP_VERSION}"
        )
    guide = data.get("guide")
    if guide is not None:
        guide = _text(guide, display, "guide")
    description = data.get("description", "")
    if not isinstance(description, str):
        raise SetupError(f"{display}: description must be text, got {_show(description)}")
    channels_table = data.get("channels")
    if channels_table is None:
        raise SetupError(
            f"{display}: channels missing; expected one table per guidefit channel ([channels.force], "
            "[channels.acc_A_y], ...)"
        )
    if not isinstance(channels_table, dict) or not channels_table:
        raise SetupError(f"{display}: channels must hold tables [channels.<name>], got {_show(channels_table)}")
    channels = {name: _check_channel(name, table, display) for name, table in channels_table.items()}
    if "force" not in channels:
        raise SetupError(f"{display}: channels: no [channels.force]; expected exactly one force channel (the hammer)")
    if len(channels) < 2:
        raise SetupError(f"{display}: channels: no acceleration; expected at least one [channels.acc_<point>_<axis>]")
    runs_table = data.get("runs")
    if runs_table is None:
        raise SetupError(
            f"{display}: runs missing; expected one table per hammer run ([runs.vertical] with file and "
            "excitation_direction)"
        )
    if not isinstance(runs_table, dict) or not runs_table:
        raise SetupError(f"{display}: runs must hold tables [runs.<name>], got {_show(runs_table)}")
    runs = tuple(_check_run(name, table, channels, p, display, planning) for name, table in runs_table.items())
    return Setup(display, guide, description, channels, runs)


# ---------------------------------------------------------------- to a recording


def _unit_kind(text: str | None) -> str | None:
    """``"V"``, ``"mV"``, a guidefit unit, ``"other"``, or None for no unit."""
    if text is None or not str(text).strip():
        return None
    low = str(text).strip().lower()
    if low in _VOLTS:
        return "V"
    if low == "mv":
        return "mV"
    for unit, spellings in _UNIT_SPELLINGS.items():
        if low in spellings:
            return unit
    return "other"


def _check_units(ch: SetupChannel, dc: DaqChannel, daq: DaqFile, display: str) -> None:
    kind = _unit_kind(dc.unit)
    where = f"{display}: channels.{ch.name}"
    gives = f"{daq.display} gives '{dc.name}' in '{dc.unit}'"
    if kind is None or ch.given == "scale":
        return
    if ch.given == "sensitivity_mv":
        if kind != "V":
            use = "use scale (unit per mV)" if kind == "mV" else "remove it, or use scale"
            raise SetupError(f"{where}: sensitivity_mv expects the file in volts, but {gives}; {use}")
        return
    if kind == ch.unit:
        return
    if kind in ("V", "mV"):
        raise SetupError(f"{where}: {gives}; give sensitivity_mv (mV per {ch.unit}) or scale")
    raise SetupError(
        f"{where}: unit is '{ch.unit}' but {gives}; set the unit, or give scale (scale = 1.0 if it is "
        f"already in {ch.unit})"
    )


def _select(setup: Setup, run: SetupRun, daq: DaqFile) -> list[tuple[SetupChannel, DaqChannel]]:
    """The run's channels: those it lists (each must be in the file), else every channel
    of the setup whose source the file has."""
    names = run.channels or tuple(setup.channels)
    picked = []
    for name in names:
        ch = setup.channels[name]
        dc = daq.find(ch.source)
        if dc is None:
            if run.channels is not None or name == "force":
                raise daq.missing(ch.source)
            continue
        picked.append((ch, dc))
    if len(picked) < 2:
        first = next(setup.channels[n] for n in names if n != "force")
        raise daq.missing(first.source)
    _check_distinct_sources(setup, run, daq, picked)
    for _, dc in picked:
        if np.dtype(dc.dtype).kind not in "fiu":
            raise SetupError(f"{daq.display}: channel '{dc.name}' holds {np.dtype(dc.dtype)}, not numbers")
    return picked


def _check_distinct_sources(setup: Setup, run: SetupRun, daq: DaqFile, picked) -> None:
    """Two guidefit channels of one run that read the same DAQ channel: a sensor moved between runs
    under the same DAQ name (``acc_A_y`` and ``acc_A_x`` both ``Acc1``) read twice, which would make
    the run's layout up. One line naming both and the key that settles it (the run's ``channels``)."""
    seen: dict = {}
    for ch, dc in picked:
        key = (dc.name, repr(dc.key))
        if key in seen:
            fix = (f"list the channels this run recorded (runs.{run.name}.channels = [...]): a sensor moved "
                   "between runs keeps its DAQ name" if run.channels is None
                   else "a sensor is one channel")
            raise SetupError(f"{setup.path}: runs.{run.name}: channels '{seen[key]}' and '{ch.name}' both read "
                             f"'{dc.name}' of {daq.display}; {fix}")
        seen[key] = ch.name


def _has(daq: DaqFile, source: str) -> bool:
    try:
        return daq.find(source) is not None
    except RecordingError:  # names several channels: it is there
        return True


def _check_all_found(setup: Setup, opened: list) -> None:
    """A channel no run's file has is a typo, not a sensor moved between runs: one line naming
    the first file that should have had it."""
    found = {ch.name for _, _, picked in opened for ch, _ in picked}
    for name, ch in setup.channels.items():
        if name in found or any(_has(daq, ch.source) for _, daq, _ in opened):
            continue
        for run, daq, _ in opened:
            if run.channels is None:
                raise daq.missing(ch.source)


def _check_runs_apart(setup: Setup, opened: list) -> None:
    """Two runs whose hammer is the same channel of the same file (and group) would read the same hits
    twice under two excitations (a run's file copied into the next run's table): one line naming both
    and the key that settles it (each run its own ``file``, or ``group`` in a file of several runs)."""
    seen: dict = {}
    for run, daq, picked in opened:
        force = next(dc for ch, dc in picked if ch.name == "force")
        st = os.stat(run.path)
        key = (st.st_dev, st.st_ino, force.name, repr(force.key))
        if key in seen:
            raise SetupError(
                f"{setup.path}: runs.{run.name}: reads the hammer '{force.name}' of {daq.display} as runs.{seen[key]} "
                "does; each run is its own hammer run: give it its own file (or group, in a file of several runs)"
            )
        seen[key] = run.name


def _run_length(picked, daq: DaqFile) -> int:
    chans = tuple(dc for _, dc in picked)
    if daq.count_rows is not None:
        n = int(daq.count_rows(chans))
    else:
        n = chans[0].n_samples
        for dc in chans[1:]:
            if dc.n_samples != n:
                raise SetupError(
                    f"{daq.display}: channels '{chans[0].name}' ({n} samples) and '{dc.name}' ({dc.n_samples}) "
                    "differ in length; a run's channels need one time base"
                )
    if n < 2:
        raise SetupError(f"{daq.display}: channel '{chans[0].name}' holds {n} sample(s); expected a record")
    return n


def _check_starts(picked, daq: DaqFile, rate: float) -> None:
    """Channels that say when they started must start within half a sample of each other."""
    starts = [(dc, dc.start) for _, dc in picked if dc.start is not None]
    for dc, (ns, offset) in starts[1:]:
        first, (ns0, offset0) = starts[0]
        apart = (ns - ns0) * 1e-9 + (offset - offset0)
        if not math.isfinite(apart):
            raise SetupError(
                f"{daq.display}: channels '{first.name}' and '{dc.name}': start times (wf_start_time, "
                "wf_start_offset) that are not finite numbers; a run's channels need one time base"
            )
        if abs(apart) * rate > 0.5:
            raise SetupError(
                f"{daq.display}: channels '{first.name}' and '{dc.name}' start {apart * 1e3:.6g} ms apart "
                "(wf_start_time, wf_start_offset); a run's channels need one time base"
            )


def _run_rate(picked, daq: DaqFile, run: SetupRun, display: str) -> float:
    chans = tuple(dc for _, dc in picked)
    if daq.rate_for is not None:
        file_rate = daq.rate_for(chans)
    else:
        own = [(dc, dc.sample_rate_hz) for dc in chans if dc.sample_rate_hz is not None]
        for dc, r in own:
            if not (math.isfinite(r) and r > 0):  # the file states a rate that is none: not taken from elsewhere
                raise SetupError(
                    f"{daq.display}: channel '{dc.name}': {daq.rate_origin} gives no sample rate (0, negative, "
                    "not finite or not a number); expected the time step in s"
                )
        for dc, r in own[1:]:
            if not same_rate(r, own[0][1]):
                raise SetupError(
                    f"{daq.display}: channels '{own[0][0].name}' ({own[0][1]:.9g} Hz) and '{dc.name}' ({r:.9g} Hz) "
                    f"differ in sample rate ({daq.rate_origin})"
                )
        file_rate = own[0][1] if own else daq.sample_rate_hz
    where = f"{display}: runs.{run.name}"
    if file_rate is not None and run.sample_rate_hz is not None and not same_rate(file_rate, run.sample_rate_hz):
        raise SetupError(
            f"{where}: sample_rate_hz {run.sample_rate_hz:.9g} disagrees with {file_rate:.9g} Hz from "
            f"{daq.display} ({daq.rate_origin}); correct or remove the key"
        )
    if file_rate is None and run.sample_rate_hz is None:
        raise SetupError(
            f"{where}: sample_rate_hz missing; {daq.display} has neither a sample rate nor a time axis"
        )
    return float(file_rate if file_rate is not None else run.sample_rate_hz)


def _geometry(setup: Setup, run: SetupRun, chans: list[SetupChannel]):
    """Each channel's position and direction: as given, else from the guide's points and its name."""
    from guidefit.errors import GuideError

    positions, directions = [], []
    for ch in chans:
        pos, direction = ch.position_m, ch.direction
        if pos is None or direction is None:
            match = _ACC_RE.match(ch.name)
            points = {match.group(1): pos} if pos is not None and match else None  # only the axis is needed
            try:
                dpos, ddir = default_channel_geometry([ch.name], run.excitation_direction,
                                                      run.excitation_position_m, guide=setup.guide, points=points)
            except GuideError as exc:
                raise SetupError(f"{setup.path}: guide: {exc}") from None
            except GuidefitError as exc:
                text = str(exc).replace("give positions_m", "give position_m")
                raise SetupError(f"{setup.path}: channels.{ch.name}: {text}") from None
            pos = dpos[0] if pos is None else pos
            direction = ddir[0] if direction is None else direction
        positions.append(pos)
        directions.append(direction)
    return positions, directions


def _open_daq(setup: Setup, run: SetupRun):
    options = RunOptions(f"{setup.path}: runs.{run.name}", run.group, run.delimiter, run.decimal)
    daq = run.format.read(run.path, run.display, options)
    return run, daq, _select(setup, run, daq)


def _make_run(setup: Setup, run: SetupRun, daq: DaqFile, picked) -> Run:
    for ch, dc in picked:
        _check_units(ch, dc, daq, setup.path)
    n = _run_length(picked, daq)
    rate = _run_rate(picked, daq, run, setup.path)
    _check_starts(picked, daq, rate)
    chans = [ch for ch, _ in picked]
    positions, directions = _geometry(setup, run, chans)
    try:
        header = RunData(run.name, rate, run.excitation_direction, [ch.name for ch in chans],
                         [ch.unit for ch in chans], positions, directions, layout="signals",
                         excitation_position_m=run.excitation_position_m)
    except RecordingError as exc:
        raise SetupError(f"{setup.path}: runs.{run.name}: {exc}") from None
    dcs = tuple(dc for _, dc in picked)
    source = daq.make_source(dcs, common_dtype(dc.dtype for dc in dcs))
    scale = [(FORCE_UNITS if ch.name == "force" else ACCELERATION_UNITS)[ch.unit] * ch.factor for ch in chans]
    made = Run.from_header(header, source, n_samples=n, file=run.display, scale_to_si=scale)
    # the contract gives no default hit point: with neither excitation_position_m nor the force
    # channel's position_m it is unknown (not the origin the force channel is placed at)
    known = run.excitation_position_m is not None or any(ch.name == "force" and ch.position_m is not None
                                                          for ch in chans)
    return made if known else replace(made, force_position_known=False)


def read_setup(p: Path, display: str) -> Recording:
    """A test setup as a :class:`~guidefit.io.records.Recording` (the registry's reader for ``.toml``).

    The setup is checked whole first (:func:`load_setup`), then each run's DAQ
    file is opened (metadata and time axis only; samples stay in the file).
    A run without a ``channels`` list takes every channel whose source its file
    has (a sensor moved between runs); a channel that no run's file has is an
    error (a misspelt source would otherwise drop a sensor silently).

    Raises
    ------
    SetupError, RecordingError
        One line: the setup file, table and key, or the DAQ file and what it lacks
        (``lateral.tdms: no channel 'A_Y'; the file has Hammer, AccA_Y, AccB_Y``).
    """
    setup = load_setup(display)
    opened = [_open_daq(setup, run) for run in setup.runs]
    _check_all_found(setup, opened)
    _check_runs_apart(setup, opened)
    runs = tuple(_make_run(setup, run, daq, picked) for run, daq, picked in opened)
    return Recording(path=display, guide=setup.guide, description=setup.description, runs=runs)


# ---------------------------------------------------------------- converting


def convert(path, out, *, compression: str | None = None) -> Recording:
    """Write any recording (a test setup, or a file of any readable format) to the recording contract.

    The samples are copied block by block in their units (volts become N,
    m/s^2 or g through each channel's sensitivity) by
    :func:`guidefit.io.write_recording`, which writes ``out`` whole (a
    temporary file renamed at the end).

    Parameters
    ----------
    path : str or path-like
        The input: a ``.toml`` setup or any recording suffix.
    out : str or path-like
        ``.h5``/``.hdf5`` (any runs), ``.csv`` (one run) or ``.uff``/``.unv``.
    compression : str, optional
        HDF5 filter (``"gzip"``).

    Returns
    -------
    Recording
        The input as read (for a summary).

    Raises
    ------
    RecordingError
        Bad input, or an output format that cannot hold it.
    guidefit.outputs.OutputError
        ``out`` is a file the input reads (the setup, a run's DAQ file, a file an
        HDF5 recording links to; :func:`guidefit.outputs.refuse_inputs`): refused
        before anything is read or written.
    """
    from guidefit.io.registry import format_for, read_recording, write_recording
    from guidefit.outputs import refuse_inputs

    out_display = os.fspath(out)
    refuse_inputs([out_display], [os.fspath(path)])
    format_for(out_display, "recording", "write")  # an unknown output type fails before any reading
    recording = read_recording(path)
    write_recording(out_display, recording, compression=compression)
    return recording


# ------------------------------------------------------------- UFF time data


class UffColumns(ColumnSource):
    """Channels of one run of a UFF-58 time-data file (held in memory, as :mod:`guidefit.io.uff` reads it)."""

    def _data(self):
        data = getattr(self, "_cache", None)
        if data is None:
            data = _uff_run(self.facts["path"], self.facts["run"]).source.read((slice(None), slice(None)))
            self._cache = data
        return data

    def _read(self, handle, start, stop, keys):
        data = self._data()
        return [data[start:stop, k] for k in keys]


def _uff_run(display: str, group):
    from guidefit.io.uff import read_uff_recording

    runs = read_uff_recording(display).runs
    if group is None:
        return runs[0]
    return next(r for r in runs if r.name == str(group))


def open_uff(path: Path, display: str, options: RunOptions) -> DaqFile:
    """The channels of a UFF-58 time-data file for a setup's run: the channel names
    :func:`guidefit.io.uff.read_uff_recording` gives; ``group`` is its run name."""
    from guidefit.io.uff import read_uff_recording

    runs = read_uff_recording(display).runs
    names = [r.name for r in runs]
    if options.group is not None:
        if str(options.group) not in names:
            raise SetupError(f"{options.where}: group '{options.group}' is not in {display}; the file has runs "
                             f"{', '.join(names)}")
        run = runs[names.index(str(options.group))]
    elif len(runs) > 1:
        raise SetupError(f"{options.where}: group missing; {display} holds runs {', '.join(names)}")
    else:
        run = runs[0]
    channels = tuple(
        DaqChannel(ch.name, k, run.n_samples, unit=ch.unit, dtype=run.sample_dtype)
        for k, ch in enumerate(run.channels)
    )

    def make_source(chans, dtype):
        source = UffColumns(keys=[ch.key for ch in chans], n_samples=run.n_samples, dtype=dtype, path=display,
                            run=run.name if options.group is not None else None)
        source._cache = run.source.read((slice(None), slice(None)))
        return source

    return DaqFile(display=display, channels=channels, sample_rate_hz=run.sample_rate_hz,
                   rate_origin="the UFF records", make_source=make_source)


FORMATS = (
    FileFormat(name="guidefit test setup", suffixes=SUFFIXES, kind="recording", read=read_setup, streaming=True),
    FileFormat(name="UFF-58 time data", suffixes=(".uff", ".unv"), kind="daq", read=open_uff, extra="uff"),
)
