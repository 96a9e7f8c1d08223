"""The recording contract in CSV (``.csv``): one ``signals`` run per file.

``#``-lines of ``key: value`` metadata (``format``, ``run``,
``sample_rate_hz``, ``excitation_direction``, ``units``, ``positions_m``,
...), then a header row of channel names (an optional first column
``time``), then one row of numbers per sample, ``,`` between fields and
``.`` as the decimal mark (``shared/recording-format.md``). Missing
positions and directions come from the guide's default points
(:mod:`guidefit.io.geometry`). The samples are held in memory as float64
(:class:`~guidefit.io.records.ArraySource`).
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from guidefit.errors import GuidefitError, RecordingError
from guidefit.io._checks import (
    _atomic,
    _check_force_axis,
    _check_position,
    _check_pretrigger,
    _check_sample_rate,
    _check_vector,
    _first_line,
    _frozen_array,
    _valid_run_name,
)
from guidefit.io.geometry import _ACC_RE, default_channel_geometry
from guidefit.io.records import (
    FORMAT_NAME,
    FORMAT_VERSION,
    ArraySource,
    Recording,
    RecordingData,
    Run,
    RunData,
    _build_channels,
)
from guidefit.io.registry import FileFormat

__all__ = ["read_csv", "write_csv"]

SUFFIXES = (".csv",)


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


def read_csv(p: Path, display: str) -> Recording:
    """Read and validate a contract CSV recording (``display``: the path as given).

    The text is streamed: the metadata and header lines one by one, then the
    data rows in blocks of :data:`_ROWS_PER_BLOCK` parsed by ``np.loadtxt`` into
    one float64 table allocated once (its rows counted first in a pass over the
    bytes). Peak memory is the table (8 bytes per value, 0.4-1.1 times the file
    for 7-20 characters per value) plus one block, not the file's text several
    times over.
    """
    try:
        with open(p, encoding="utf-8-sig", newline=None) as fh:
            return _read_csv_stream(p, display, fh)
    except UnicodeDecodeError:
        raise RecordingError(
            f"{display}: not UTF-8 text (byte {_first_bad_byte(p)}); expected a CSV text file"
        ) from None


def _first_bad_byte(p: Path) -> int:
    """Offset of the first byte that is not UTF-8 (read in blocks)."""
    import codecs

    decoder = codecs.getincrementaldecoder("utf-8")()
    offset = 0
    with open(p, "rb") as fh:
        while block := fh.read(1 << 20):
            try:
                decoder.decode(block)
            except UnicodeDecodeError as exc:
                return offset + exc.start
            offset += len(block)
    return offset


def _nul_error(display: str) -> RecordingError:
    return RecordingError(
        f"{display}: contains NUL bytes; expected a CSV text file (is it HDF5? use .h5)"
    )


def _count_lines(p: Path) -> int:
    """An upper bound of the file's lines in universal-newline mode (one pass, blocks of 16 MB)."""
    lines = 1
    with open(p, "rb") as fh:
        while block := fh.read(1 << 24):
            lines += block.count(b"\n") + block.count(b"\r") - block.count(b"\r\n")
    return lines


def _read_csv_stream(p: Path, display: str, fh) -> Recording:
    """The recording of the contract CSV text ``fh`` (open on ``p``; ``display``: the path as given).

    The ``# key: value`` lines and the header row (:func:`_csv_metadata`), the
    numbers (:func:`_csv_numbers`), then the metadata checked in the order of
    the contract: format and run (:func:`_csv_identity`), sample rate
    (:func:`_csv_rate`), excitation (:func:`_csv_excitation`), units
    (:func:`_csv_units`), channel geometry (:func:`_csv_channels`) and the
    pre-trigger. The first error found is raised as a
    :class:`~guidefit.errors.RecordingError` that names the line.
    """
    meta, header_line, header_no = _csv_metadata(fh, display)
    names, has_time = _csv_header(header_line.rstrip("\r\n"), header_no, display)
    table = _csv_numbers(fh, header_no + 1, names, display, _count_lines(p) - header_no)
    if table.shape[0] == 0:
        raise RecordingError(f"{display}: no data rows after the header (line {header_no})")
    guide, description, run_name = _csv_identity(meta, p, display)
    rate, table, names = _csv_rate(meta, table, names, has_time, display)
    exc_dir, exc_pos = _csv_excitation(meta, display)
    units = _csv_units(meta, names, has_time, display)
    channels, force_index = _csv_channels(meta, names, units, exc_dir, exc_pos, guide, display)
    _check_force_axis(channels[force_index].direction, exc_dir, display)
    pretrigger = None
    if "pretrigger_samples" in meta:
        where = _csv_line_of(meta, "pretrigger_samples", display)
        pretrigger = _check_pretrigger(_csv_float(meta["pretrigger_samples"][0], where), table.shape[0], where)
    data = table  # (a view without the time column: no second copy of the samples)
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
        source=ArraySource(data),
        force_index=force_index,
        file=display,
        # the contract gives no default hit point: without excitation_position_m or positions_m it is unknown
        force_position_known=exc_pos is not None or "positions_m" in meta,
    )
    return Recording(path=display, guide=guide, description=description, runs=(run,))


def _csv_metadata(fh, display: str) -> tuple[dict[str, tuple[str, int]], str, int]:
    """``(meta, header_line, header_no)``: the known ``# key: value`` lines before the header row,
    as ``{key: (value, line number)}``, and the header row and its line number."""
    meta: dict[str, tuple[str, int]] = {}
    header_line = None
    line_no = 0
    for line in fh:
        line_no += 1
        if "\x00" in line:
            raise _nul_error(display)
        stripped = line.strip()
        if not stripped:
            continue
        if not stripped.startswith("#"):
            header_line = line
            break
        body = stripped[1:].strip()
        if ":" in body:
            key, value = body.split(":", 1)
            key = key.strip().lower()
            if key in _CSV_KEYS:
                if key in meta and meta[key][0] != value.strip():
                    raise RecordingError(
                        f"{display}: line {line_no} '{key}': given again as '{_clip(value.strip())}' (line {meta[key][1]}: "
                        f"'{_clip(meta[key][0])}'); expected each key once"
                    )
                meta.setdefault(key, (value.strip(), line_no))
    if header_line is None:
        raise RecordingError(
            f"{display}: no header row; expected a line of channel names such as 'time,force,acc_A_y'"
        )
    return meta, header_line, line_no


def _csv_line_of(meta, key: str, display: str) -> str:
    """Where a metadata key was given: ``"<file>: line <n> '<key>'"``."""
    return f"{display}: line {meta[key][1]} '{key}'"


def _csv_identity(meta, p: Path, display: str) -> tuple[str | None, str, str]:
    """``(guide, description, run name)`` after the format and version checks."""
    if "format" in meta and meta["format"][0] != FORMAT_NAME:
        raise RecordingError(
            f"{_csv_line_of(meta, 'format', display)}: '{meta['format'][0]}'; expected '{FORMAT_NAME}'"
        )
    if "format_version" in meta:
        value = meta["format_version"][0]
        if value.strip() != str(FORMAT_VERSION):
            raise RecordingError(
                f"{_csv_line_of(meta, 'format_version', display)}: '{value}' is not supported; "
                f"this guidefit reads version {FORMAT_VERSION}"
            )
    guide = meta.get("guide", ("", 0))[0] or None
    description = meta.get("description", ("", 0))[0]
    run_name = meta.get("run", ("", 0))[0] or p.stem
    if not _valid_run_name(run_name):
        raise RecordingError(
            f"{display}: run name '{run_name}' not allowed; expected text without '/'"
        )
    return guide, description, run_name


def _csv_rate(meta, table, names, has_time, display: str):
    """``(sample rate, table, names)``: the rate from ``sample_rate_hz`` and/or the time column,
    and the table and channel names without the time column (a view, no copy)."""
    rate = None
    if "sample_rate_hz" in meta:
        where = _csv_line_of(meta, "sample_rate_hz", display)
        rate = _check_sample_rate(_csv_float(meta["sample_rate_hz"][0], where), where)
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
    return rate, table, names


def _csv_excitation(meta, display: str) -> tuple[np.ndarray, np.ndarray | None]:
    """``(excitation_direction, excitation_position_m or None)``, checked."""
    if "excitation_direction" not in meta:
        raise RecordingError(
            f"{display}: excitation_direction missing; expected a line such as '# excitation_direction: 0 -1 0'"
        )
    exc_dir = _check_vector(
        _csv_floats(*meta["excitation_direction"], display, "excitation_direction"),
        _csv_line_of(meta, "excitation_direction", display),
        "excitation_direction",
        True,
    )
    exc_pos = None
    if "excitation_position_m" in meta:
        line = _csv_line_of(meta, "excitation_position_m", display)
        exc_pos = _check_vector(
            _csv_floats(*meta["excitation_position_m"], display, "excitation_position_m"),
            line,
            "excitation_position_m",
            False,
        )
        exc_pos = _check_position(exc_pos, line, "excitation_position_m")
    return exc_dir, exc_pos


def _csv_units(meta, names, has_time, display: str) -> list[str]:
    """The unit of each channel: from ``units`` (a leading ``s`` of the time column dropped), else
    N for ``force`` and m/s^2 for the rest."""
    n = len(names)
    if "units" not in meta:
        return ["N" if name == "force" else "m/s^2" for name in names]
    units = [u for u in re.split(r"[\s,;]+", meta["units"][0]) if u]
    if has_time and len(units) == n + 1:
        if units[0] != "s":
            raise RecordingError(
                f"{_csv_line_of(meta, 'units', display)}: unit of 'time' is '{units[0]}'; expected 's'"
            )
        units = units[1:]
    if len(units) != n:
        raise RecordingError(
            f"{_csv_line_of(meta, 'units', display)}: {len(units)} units for {n} channels ({', '.join(names)})"
        )
    return units


def _csv_channels(meta, names, units, exc_dir, exc_pos, guide, display: str):
    """``(channels, force_index)``: the channels with their positions and directions, given or
    the guide's defaults (:func:`default_channel_geometry`)."""
    n = len(names)
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
    return _build_channels(display, tuple(names), tuple(units), positions, directions)


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


_ROWS_PER_BLOCK = 65536


def _csv_numbers(fh, first_no: int, names: list[str], display: str, max_rows: int) -> np.ndarray:
    """Parse the data rows from ``fh`` in blocks into one float64 table of at most
    ``max_rows`` rows; on any problem, find the first bad line of its block and name it."""
    import itertools
    import warnings

    n = len(names)
    table = np.empty((max(1, max_rows), n), dtype=np.float64)  # pages are touched as rows arrive
    filled = 0
    block_no = first_no
    while True:
        lines = list(itertools.islice(fh, _ROWS_PER_BLOCK))
        if not lines:
            break
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)  # a block of blank lines: no data
                # quotechar: a field may be quoted ("1.5"), as CSV writers do (QUOTE_ALL, QUOTE_NONNUMERIC)
                block = np.loadtxt(lines, delimiter=",", comments=None, dtype=np.float64, ndmin=2,
                                   quotechar='"')
        except ValueError as exc:
            raise _csv_locate_error(lines, block_no, names, display, exc) from None
        if block.size:
            if block.shape[1] != n:
                raise _csv_locate_error(lines, block_no, names, display, None)
            if filled + block.shape[0] > table.shape[0]:  # cannot happen with the line count; be safe
                table = np.concatenate([table[:filled], np.empty((block.shape[0], n))])
            table[filled : filled + block.shape[0]] = block
            filled += block.shape[0]
        block_no += len(lines)
    return table[:filled]


def _csv_locate_error(data_lines, first_no, names, display, exc) -> RecordingError:
    n = len(names)
    comma_hint = "decimal commas? guidefit expects '.' as the decimal mark and ',' between fields"
    for k, line in enumerate(data_lines):
        if "\x00" in line:
            return _nul_error(display)
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
        tokens = [t[1:-1].strip() if len(t) > 1 and t[0] == t[-1] == '"' else t for t in tokens]
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


_TIME_CHUNK = 1 << 20


def _chunks(n: int):
    for a in range(0, n, _TIME_CHUNK):
        yield a, min(n, a + _TIME_CHUNK)


def _csv_time_rate(time: np.ndarray, rate: float | None, display: str) -> float:
    """The sample rate the ``time`` column gives (least-squares slope of sample number
    over time), checked for uniform spacing and against ``rate``; in chunks, so the
    temporaries stay small beside a long table."""
    where = f"{display}: column 'time'"
    n = time.size
    for a, b in _chunks(n):
        if not np.all(np.isfinite(time[a:b])):
            raise RecordingError(f"{where}: holds non-finite values; expected times in seconds")
    if n < 2:
        if rate is None:
            raise RecordingError(
                f"{where}: one row cannot give a sample rate; add '# sample_rate_hz: ...'"
            )
        return rate
    for a, b in _chunks(n - 1):
        steps = np.diff(time[a : b + 1])
        if np.any(steps <= 0):
            row = a + int(np.flatnonzero(steps <= 0)[0]) + 1
            raise RecordingError(
                f"{where}: not increasing at data row {row + 1}; expected equally spaced times"
            )
    k_mean = (n - 1) / 2.0
    t_mean = float(np.mean(time))
    skk = skt = 0.0
    for a, b in _chunks(n):
        kc = np.arange(a, b, dtype=np.float64) - k_mean
        skk += float(np.dot(kc, kc))
        skt += float(np.dot(kc, time[a:b] - t_mean))
    fs = skk / skt  # least-squares slope of k over t
    deviation = 0.0
    for a, b in _chunks(n):
        kc = np.arange(a, b, dtype=np.float64) - k_mean
        deviation = max(deviation, float(np.max(np.abs(time[a:b] - t_mean - kc / fs))) * fs)
    if deviation > 0.1:
        raise RecordingError(
            f"{where}: spacing not uniform (a sample is {deviation:.2g} sample periods off); expected a constant sample rate"
        )
    if rate is None:
        return fs
    deviation = 0.0
    for a, b in _chunks(n):
        k = np.arange(a, b, dtype=np.float64)
        # in sample periods, without dividing by the rate (a stated 5e-324 Hz would overflow)
        deviation = max(deviation, float(np.max(np.abs((time[a:b] - time[0]) * rate - k))))
    if deviation > 0.5:
        raise RecordingError(
            f"{where}: spacing gives {fs:.6g} Hz but sample_rate_hz says {rate:.6g} Hz; expected them to agree"
        )
    return rate


# ---------------------------------------------------------------------- writing


def write_csv(path, recording, *, compression: str | None = None) -> None:
    """Write one ``signals`` run as contract CSV with a ``time`` column, atomically.

    ``compression`` is accepted for the common writer signature and ignored.
    See :func:`guidefit.io.write_recording`.
    """
    display = os.fspath(path)
    if isinstance(recording, RunData):
        recording = RecordingData((recording,))
    if isinstance(recording, Recording):
        recording = recording.to_data()
    if not isinstance(recording, RecordingData):
        raise TypeError(
            f"recording: expected RecordingData, RunData or Recording, got {type(recording).__name__}"
        )
    _atomic(Path(display), lambda tmp: _write_csv(tmp, display, recording))


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
        raise RecordingError(f"{display}: cannot write ({exc.strerror or _first_line(exc)})") from None



FORMATS = (
    FileFormat(
        name="guidefit recording, CSV",
        suffixes=SUFFIXES,
        kind="recording",
        read=read_csv,
        write=write_csv,
        streaming=False,
    ),
)
