"""Text exports of any DAQ (``.csv``, ``.txt``, ``.tsv``) as a test setup's DAQ files.

DAQ software writes text in many dialects. This reader detects them from the
first lines of the file (:func:`detect_dialect`):

- the field delimiter (``,`` ``;`` tab or runs of spaces) and the decimal mark
  (``.`` or ``,``): every candidate pair is tried on the first lines, the
  data block is the longest run of consecutive lines that all parse as the
  same number (>= 2) of numbers, and the candidates that find a block must
  agree on its numbers (``1;2`` reads the same with either decimal mark);
- comment and preamble lines before the header (anything above the data
  block and its header) are skipped;
- the header is the line above the data block with as many fields; a unit
  row between header and data (``s;V;V``) and units in the header
  (``Hammer [V]``, ``Hammer (V)``) are understood;
- a time column (``time``, ``t``, ``Time [s]``, ``Zeit``..., in s, ms or us)
  gives the sample rate (least-squares slope, checked for uniform spacing).

When the candidates disagree, or the line above the data does not split into
the data's number of fields, the reader cannot be sure and says so in one
line that names the run-table keys ``delimiter`` / ``decimal`` that settle it.
A setup's ``source`` is a column's header (with or without its unit) or its
index (0-based, the time column included). The file's text is read in blocks
of :data:`ROWS_PER_BLOCK` lines and only the columns a run uses are kept, as
one float64 table (8 bytes per value and column used): text does not allow
reading a slice without reading what comes before it.

A ``.csv`` given to a command directly is the recording contract's CSV
(:mod:`guidefit.io.csv`); through a setup it is read here.

Examples
--------
>>> import os, tempfile
>>> from guidefit.io._daq import RunOptions
>>> text = "Exported by DAQ 7.1\\nDate;2026-11-20\\n\\nTime;Hammer;A_Y\\ns;V;V\\n"
>>> text += "".join(f"{k / 1000:.3f};{k},5;-{k},25\\n".replace(".", ",", 1) for k in range(5))
>>> with tempfile.TemporaryDirectory() as folder:
...     path = os.path.join(folder, "hit.csv")
...     with open(path, "w") as fh:
...         _ = fh.write(text)
...     daq = open_daq(Path(path), "hit.csv", RunOptions("test.toml: runs.a"))
...     chans = (daq.find("Hammer"), daq.find("A_Y [V]"))
...     rate = daq.rate_for(chans)
...     block = daq.make_source(chans, np.float64).read((slice(1, 3), slice(None)))
>>> rate, [(c.name, c.unit) for c in chans], block.tolist()
(1000.0, [('Hammer', 'V'), ('A_Y', 'V')], [[1.5, -1.25], [2.5, -2.25]])
"""

from __future__ import annotations

import itertools
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from guidefit.errors import RecordingError
from guidefit.io._checks import _first_line
from guidefit.io._daq import ColumnSource, DaqChannel, DaqFile, RunOptions, rate_from_time
from guidefit.io.registry import FileFormat

__all__ = ["Dialect", "TextSource", "detect_dialect", "open_daq"]

SUFFIXES = (".csv", ".txt", ".tsv")
ROWS_PER_BLOCK = 65536
_HEAD_LINES = 2000
_HEAD_BYTES = 4 << 20
DELIMITERS = {",": ",", ";": ";", "\t": "\t", "tab": "\t", " ": " ", "space": " ", "spaces": " ", "whitespace": " "}
"""Values of a run table's ``delimiter`` key and the delimiter they mean (``" "``: runs of spaces or tabs)."""
DECIMALS = (".", ",")
_CANDIDATES = ((",", "."), (";", ","), (";", "."), ("\t", "."), ("\t", ","), (" ", "."), (" ", ","))
_NUMBER_RE = re.compile(r"^[+-]?((\d+\.?\d*|\.\d+)([eE][+-]?\d+)?|nan|inf|infinity)$", re.IGNORECASE)
_UNIT_IN_NAME_RE = re.compile(r"^(?P<name>.*?)\s*(\[(?P<u1>[^\[\]]*)\]|\((?P<u2>[^()]*)\))\s*$")
_UNIT_RE = re.compile(r"^[\[(]?\s*[A-Za-zµμ°%/^*.·²³0-9 _-]{0,16}\s*[\])]?$")
_TIME_RE = re.compile(r"^(time|t|zeit|temps|tiempo|tempo|time_s|t_s|x_value)$", re.IGNORECASE)
_TIME_UNITS = {None: 1.0, "": 1.0, "s": 1.0, "sec": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6, "μs": 1e-6}
_SHOWN = {",": "','", ";": "';'", "\t": "tab", " ": "spaces"}


@dataclass(frozen=True)
class Dialect:
    """How a text export is written: where its data start and how its fields read.

    Attributes
    ----------
    delimiter : str
        ``","``, ``";"``, ``"\\t"`` or ``" "`` (any run of spaces and tabs).
    decimal : str
        ``"."`` or ``","``.
    n_fields : int
        Fields per data row.
    data_line : int
        1-based line number of the first data row.
    header : tuple of str or None
        Column names (units removed), None without a header row.
    units : tuple of (str or None)
        Each column's unit from the header or the unit row.
    header_text : tuple of str or None
        The header fields as written (``"Hammer [V]"``).
    note : str
        Why there is no header, when there is none.
    quoted : bool
        The data rows put numbers in double quotes (removed before parsing).
    """

    delimiter: str
    decimal: str
    n_fields: int
    data_line: int
    header: tuple[str, ...] | None
    units: tuple[str | None, ...]
    header_text: tuple[str, ...] | None = None
    note: str = ""
    quoted: bool = False


def _split(line: str, delimiter: str) -> list[str]:
    line = line.rstrip("\r\n")
    if delimiter == " ":
        return line.split()
    fields = [f.strip() for f in line.split(delimiter)]
    if len(fields) > 1 and fields[-1] == "":  # a delimiter at the end of each row
        fields.pop()
    return fields


def _unquote(field: str) -> str:
    field = field.strip()
    if len(field) >= 2 and field[0] == field[-1] and field[0] in "\"'":
        return field[1:-1].strip()
    return field


def _number(field: str, decimal: str) -> float | None:
    field = _unquote(field)
    if decimal == ",":
        if "." in field:
            return None
        field = field.replace(",", ".")
    elif "," in field:
        return None
    return float(field) if _NUMBER_RE.match(field) else None


def _data_block(lines: list[tuple[int, str]], delimiter: str, decimal: str):
    """(n_fields, index of the block's first line, numbers of the block): the longest run of
    consecutive lines that all read as the same number (>= 2) of numbers (the later one of
    equal runs), or None. Lines after it (a footer) fail later with their line number."""
    best = None
    run: list[list[float]] = []
    n_fields = first = None
    for i, (_, text) in enumerate(lines + [(0, "")]):
        fields = _split(text, delimiter) if text else []
        values = [_number(f, decimal) for f in fields]
        ok = len(fields) >= 2 and all(v is not None for v in values)
        if ok and run and len(fields) == n_fields:
            run.append(values)
            continue
        if run and (best is None or len(run) >= len(best[2])):
            best = (n_fields, first, run)
        run, n_fields, first = ([values], len(fields), i) if ok else ([], None, None)
    if best is None:
        return None
    return best[0], best[1], np.array(best[2])


def _check_not_inside_data(lines, first, d, m, n_fields, display) -> None:
    """The line taken for the header sits between rows of ``n_fields`` numbers: it is a data row with a
    text cell (``OVL``, ``#N/A``, a second export's header), not a header; taking it as one would drop
    every row above it without a word (a hit among them). One line naming it."""
    if first < 2:
        return
    row = [_number(f, m) for f in _split(lines[first - 2][1], d)]
    if len(row) != n_fields or any(v is None for v in row):
        return
    no, text = lines[first - 1]
    fields = _split(text, d)
    bad = next(((k, f) for k, f in enumerate(fields) if _number(f, m) is None), (0, text))
    raise RecordingError(
        f"{display}: line {no}: {_clip(_unquote(bad[1]).strip())!r} (field {bad[0]}) is not a number, between rows "
        f"of numbers above and below (decimal mark '{m}'): a bad sample or two exports joined; write it as 'nan', "
        "or cut the file there"
    )


def _looks_like_units(fields: list[str]) -> bool:
    texts = [_unquote(f) for f in fields]
    return any(texts) and all(_UNIT_RE.match(t) and _number(t, ".") is None for t in texts)


def _name_and_unit(field: str) -> tuple[str, str | None]:
    text = _unquote(field)
    match = _UNIT_IN_NAME_RE.match(text)
    if match and match.group("name"):
        unit = match.group("u1") if match.group("u1") is not None else match.group("u2")
        return match.group("name").strip(), unit.strip() or None
    return text, None


def detect_dialect(lines: list[tuple[int, str]], display: str, where: str,
                   delimiter: str | None = None, decimal: str | None = None) -> Dialect:
    """Delimiter, decimal mark, data start, header and units of a text export from its first lines.

    Parameters
    ----------
    lines : list of (int, str)
        The non-blank lines of the file's head with their 1-based line numbers.
    display, where : str
        The file and the run table (``"test.toml: runs.a"``), for messages.
    delimiter, decimal : str, optional
        What the run table says; detected when None.

    Raises
    ------
    RecordingError
        No data block, or candidates that read the data differently, or a header
        that does not fit the data: one line naming the keys that settle it.

    Examples
    --------
    >>> rows = ["Hammer [V]\\tA_Y [V]", "1,5\\t2", "2,5\\t3"]
    >>> d = detect_dialect(list(enumerate(rows, 1)), "x.txt", "t.toml: runs.a")
    >>> d.delimiter == "\\t", d.decimal, d.data_line, d.header, d.units
    (True, ',', 2, ('Hammer', 'A_Y'), ('V', 'V'))
    """
    keys = f"give delimiter = ';' / ',' / '\\t' / ' ' and decimal = '.' / ',' in {where}"
    candidates = [
        c for c in _CANDIDATES
        if (delimiter is None or c[0] == delimiter) and (decimal is None or c[1] == decimal)
    ]
    if delimiter is not None and decimal is not None and (delimiter, decimal) not in candidates:
        candidates = [(delimiter, decimal)]
    found = []
    for d, m in candidates:
        block = _data_block(lines, d, m)
        if block is not None:
            found.append((d, m, *block))
    if not found:
        return _no_block(lines, display, keys, delimiter, decimal)
    longest = max(len(f[4]) for f in found)  # a reading that stops early (at '1,5' for '.') is not one
    found = [f for f in found if len(f[4]) == longest]
    d, m, n_fields, first, numbers = found[0]
    for d2, m2, n2, first2, numbers2 in found[1:]:
        same = n2 == n_fields and first2 == first and np.array_equal(numbers2, numbers, equal_nan=True)
        if not same:
            raise RecordingError(
                f"{display}: cannot tell how the text is written: with {_SHOWN[d]} between fields and '{m}' as "
                f"decimal mark it has {n_fields} columns from line {lines[first][0]}, with {_SHOWN[d2]} and "
                f"'{m2}' {n2} from line {lines[first2][0]}; {keys}"
            )
    return _header(lines, first, d, m, n_fields, display, keys)


def _no_block(lines, display, keys, delimiter, decimal) -> Dialect:
    if not lines:
        raise RecordingError(f"{display}: no text lines; expected a header and rows of numbers")
    told = ""
    if delimiter is not None or decimal is not None:
        told = f" with {'delimiter ' + _SHOWN.get(delimiter, repr(delimiter)) if delimiter else ''}" \
               f"{' and ' if delimiter and decimal else ''}{'decimal ' + repr(decimal) if decimal else ''}"
    no, last = lines[-1]
    raise RecordingError(
        f"{display}: no rows of two or more numbers found{told} (last line read: {no} '{_clip(last.strip())}'); "
        f"if the data are there, {keys}"
    )


def _header(lines, first, d, m, n_fields, display, keys) -> Dialect:
    data_line = lines[first][0]
    above = [_split(text, d) for _, text in lines[max(0, first - 2):first]]
    _check_not_inside_data(lines, first, d, m, n_fields, display)
    if above and all(_number(f, ".") is not None or _number(f, ",") is not None for f in above[-1]):
        raise RecordingError(
            f"{display}: line {lines[first - 1][0]} above the data rows is numbers too, but does not read "
            f"with {_SHOWN[d]} between fields and '{m}' as decimal mark like the rows below; {keys}"
        )
    header = units = header_text = None
    note = ""
    if above and len(above[-1]) == n_fields and _looks_like_units(above[-1]) and len(above) == 2 \
            and len(above[0]) == n_fields:
        header_text = tuple(_unquote(f) for f in above[0])
        units = tuple(_unquote(f).strip("[]()").strip() or None for f in above[-1])
    elif above and len(above[-1]) == n_fields:
        header_text = tuple(_unquote(f) for f in above[-1])
    elif above:
        no = lines[first - 1][0]
        note = (
            f"line {no} above the data has {len(above[-1])} field(s) with {_SHOWN[d]} between fields, "
            f"the data rows {n_fields}; if it is the header, {keys}, or name the columns by index (0-based)"
        )
    if header_text is not None:
        pairs = [_name_and_unit(f) for f in header_text]
        header = tuple(p[0] for p in pairs)
        header_units = tuple(p[1] for p in pairs)
        units = tuple((u or h) for u, h in zip(units or (None,) * n_fields, header_units))
    quoted = any('"' in text for _, text in lines[first:])
    return Dialect(d, m, n_fields, data_line, header, units or (None,) * n_fields, header_text, note, quoted)


def _clip(text: str, width: int = 40) -> str:
    return text if len(text) <= width else text[: width - 3] + "..."


# ------------------------------------------------------------------ reading


def _encoding(path: Path, display: str) -> str:
    """UTF-16 with its byte-order mark ("Unicode text" of Windows programs); utf-8 (with or
    without BOM) if the head decodes as such; else cp1252 (Windows exports)."""
    with open(path, "rb") as fh:
        head = fh.read(_HEAD_BYTES)
    if head[:2] in (b"\xff\xfe", b"\xfe\xff"):
        return "utf-16"
    if b"\x00" in head:
        raise RecordingError(f"{display}: contains NUL bytes; expected a text export")
    try:
        head.decode("utf-8")
    except UnicodeDecodeError as exc:
        if exc.start < len(head) - 4:  # not merely a character cut at the end of the sample
            return "cp1252"
    return "utf-8-sig"


def _head(path: Path, encoding: str) -> list[tuple[int, str]]:
    lines, size = [], 0
    with open(path, encoding=encoding, errors="replace", newline=None) as fh:
        for no, line in enumerate(fh, 1):
            size += len(line)
            if line.strip():
                lines.append((no, line))
            if no >= _HEAD_LINES or size >= _HEAD_BYTES:
                break
    return lines


def _count_lines(path: Path) -> int:
    lines = 1
    with open(path, "rb") as fh:
        while block := fh.read(1 << 24):
            lines += block.count(b"\n") + block.count(b"\r") - block.count(b"\r\n")
    return lines


def parse_columns(path: Path, display: str, dialect: Dialect, columns: list[int], encoding: str,
                  names: list[str]) -> np.ndarray:
    """The numbers of ``columns`` (0-based) from the data rows, as one float64 table, read in blocks.

    Raises
    ------
    RecordingError
        A row that is not numbers where a used column is: one line naming the
        line, the column and the text.
    """
    return parse_with_steps(path, display, dialect, columns, encoding, names)[0]


def parse_with_steps(path: Path, display: str, dialect: Dialect, columns: list[int], encoding: str,
                     names: list[str], step_column: int | None = None) -> tuple[np.ndarray, np.ndarray | None]:
    """:func:`parse_columns`, and the step each row writes column ``step_column`` to (its
    printed precision, :func:`_printed_steps`), or None without ``step_column``."""
    import warnings

    max_rows = max(1, _count_lines(path) - dialect.data_line + 1)
    table = np.empty((max_rows, len(columns)), dtype=np.float64)
    steps = [] if step_column is not None else None
    filled = 0
    delimiter = None if dialect.delimiter == " " else dialect.delimiter
    with open(path, encoding=encoding, errors="replace", newline=None) as fh:
        fh = itertools.islice(fh, dialect.data_line - 1, None)
        line_no = dialect.data_line
        while True:
            lines = list(itertools.islice(fh, ROWS_PER_BLOCK))
            if not lines:
                break
            text = [ln.replace('"', "") for ln in lines] if dialect.quoted else lines
            text = [ln.replace(",", ".") for ln in text] if dialect.decimal == "," else text
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", UserWarning)  # a block of blank lines
                    block = np.loadtxt(text, delimiter=delimiter, usecols=columns, dtype=np.float64,
                                       comments=None, ndmin=2)
                    if steps is not None and block.size:
                        steps.append(_printed_steps(np.loadtxt(text, delimiter=delimiter, usecols=[step_column],
                                                               dtype=str, comments=None, ndmin=1)))
            except (ValueError, IndexError) as exc:
                raise _locate(lines, line_no, dialect, columns, names, display, exc) from None
            if block.size:
                if filled + block.shape[0] > table.shape[0]:
                    table = np.concatenate([table[:filled], np.empty((block.shape[0], len(columns)))])
                table[filled:filled + block.shape[0]] = block
                filled += block.shape[0]
            line_no += len(lines)
    if steps is not None:
        steps = np.concatenate(steps) if steps else np.zeros(0)
    return table[:filled], steps


def _locate(lines, first_no, dialect, columns, names, display, exc) -> RecordingError:
    for k, line in enumerate(lines):
        if not line.strip():
            continue
        fields = _split(line, dialect.delimiter)
        where = f"{display}: line {first_no + k}"
        for c in columns:
            if c >= len(fields):
                return RecordingError(
                    f"{where}: {len(fields)} fields, the data rows have {dialect.n_fields} "
                    f"(with {_SHOWN[dialect.delimiter]} between fields)"
                )
            if _number(fields[c], dialect.decimal) is None:
                return RecordingError(
                    f"{where}, column '{names[c]}': '{_clip(fields[c], 30)}' is not a number "
                    f"(decimal mark '{dialect.decimal}')"
                )
    return RecordingError(f"{display}: cannot read the data rows ({_first_line(exc)})")


def _step_of(text: str, decimal: str) -> float:
    """The step between numbers written like ``text``: ``12,34568`` -> 1e-5, ``2.5e+01`` -> 1.0.

    >>> _step_of("12,34568", ","), _step_of("2.5e+01", "."), _step_of("7", ".")
    (1e-05, 1.0, 1.0)
    """
    text = _unquote(text).strip().lstrip("+-")
    mantissa, _, exponent = text.lower().partition("e")
    digits = len(mantissa.partition(decimal)[2])
    try:
        power = int(exponent) if exponent else 0
    except ValueError:
        return 0.0
    return float(f"1e{power - digits}")


def _printed_steps(fields: np.ndarray) -> np.ndarray:
    """The step each of ``fields`` (numbers as written, ``.`` as decimal mark) is written to,
    row by row: ``%g`` writes ``0.5`` (0.1) and ``0.500013`` (1e-6) in one column, so no
    one row tells the column's precision.

    >>> _printed_steps(np.array(["0.5", " 0.500013", "2.5E+01", "7", "-1.25e-3"])).tolist()
    [0.1, 1e-06, 1.0, 1.0, 1e-05]
    """
    text = np.char.lower(np.char.strip(np.asarray(fields, dtype=str)))
    parts = np.char.partition(text, "e")
    mantissa, exponent = parts[..., 0], parts[..., 2]
    dot = np.char.find(mantissa, ".")
    digits = np.where(dot >= 0, np.char.str_len(mantissa) - dot - 1, 0)
    try:
        power = np.where(exponent == "", "0", exponent).astype(np.int64)
    except (ValueError, OverflowError):  # not numbers: the caller reads them as such
        return np.array([_step_of(f, ".") for f in text])
    exponents, index = np.unique(power - digits, return_inverse=True)
    return np.array([float(f"1e{e}") for e in exponents])[index.reshape(-1)]


class TextSource(ColumnSource):
    """Columns of a text export, parsed once into memory (only those a run uses)."""

    def _table(self) -> np.ndarray:
        table = getattr(self, "_cache", None)
        if table is None:
            f = self.facts
            table = parse_columns(Path(f["path"]), f["display"], f["dialect"], list(f["columns"]),
                                  f["encoding"], list(f["names"]))
            self._cache = table
        return table

    def _read(self, handle, start, stop, keys):
        table = self._table()
        index = {c: j for j, c in enumerate(self.facts["columns"])}
        return [table[start:stop, index[k]] for k in keys]


def open_daq(path: Path, display: str, options: RunOptions) -> DaqFile:
    """The columns of a text export for a setup's run (dialect detected from its head).

    Raises
    ------
    RecordingError
        A ``group`` given (one run per file); the dialect cannot be detected
        (names ``delimiter`` / ``decimal``); a time column with an unknown unit.
    """
    if options.group is not None:
        raise RecordingError(f"{options.where}: group: a text export holds one run; remove the key")
    encoding = _encoding(path, display)
    dialect = detect_dialect(_head(path, encoding), display, options.where, options.delimiter, options.decimal)
    n = dialect.n_fields
    names = list(dialect.header) if dialect.header else [str(k) for k in range(n)]
    time_col = None
    if dialect.header and _TIME_RE.match(names[0].replace(" ", "_")):
        time_col = 0
    elif dialect.header:
        time_col = next((k for k, name in enumerate(names) if _TIME_RE.match(name.replace(" ", "_"))), None)
    time_factor = 1.0
    if time_col is not None:
        unit = dialect.units[time_col]
        if unit not in _TIME_UNITS:
            raise RecordingError(
                f"{display}: time column '{names[time_col]}' in '{unit}'; expected s, ms or us"
            )
        time_factor = _TIME_UNITS[unit]
    parsed: dict[tuple, tuple] = {}

    def parse(columns: tuple) -> tuple:
        if columns not in parsed:
            parsed.clear()  # one table at a time
            parsed[columns] = parse_with_steps(path, display, dialect, list(columns), encoding, names,
                                               step_column=time_col if time_col in columns else None)
        return parsed[columns]

    def table(columns: tuple) -> np.ndarray:
        return parse(columns)[0]

    def with_time(chans) -> tuple:
        return tuple(sorted({ch.key for ch in chans} | ({time_col} if time_col is not None else set())))

    channels, aliases, ambiguous, seen = [], {}, {}, {}
    for k in range(n):
        if k == time_col:
            continue
        ch = DaqChannel(name=names[k], key=k, n_samples=-1, unit=dialect.units[k])
        channels.append(ch)
        aliases[str(k)] = ch
        if dialect.header_text:
            aliases.setdefault(dialect.header_text[k], ch)
            if dialect.units[k]:
                aliases.setdefault(f"{names[k]} [{dialect.units[k]}]", ch)
        seen.setdefault(names[k], []).append(k)
    for name, cols in seen.items():
        if len(cols) > 1:
            ambiguous[name] = f"{len(cols)} columns are called '{name}' ({', '.join(map(str, cols))}); give the index"

    def rate_for(chans):
        if time_col is None:
            return None
        cols = with_time(chans)
        data, steps = parse(cols)
        t = data[:, cols.index(time_col)] * time_factor
        return rate_from_time(lambda a, b: t[a:b], t.size, f"{display}: time column '{names[time_col]}'",
                              resolution_s=steps * time_factor)

    def make_source(chans, dtype):
        cols = with_time(chans)
        data = table(cols)
        source = TextSource(keys=[ch.key for ch in chans], n_samples=data.shape[0], dtype=np.float64,
                            path=str(path), display=display, dialect=dialect, columns=cols, encoding=encoding,
                            names=tuple(names))
        source._cache = data
        return source

    return DaqFile(
        display=display,
        channels=tuple(channels),
        aliases=aliases,
        ambiguous=ambiguous,
        sample_rate_hz=None,
        rate_origin="the time column" if time_col is not None else "",
        rate_for=rate_for,
        make_source=make_source,
        note=dialect.note,
        count_rows=lambda chans: table(with_time(chans)).shape[0],
    )


FORMATS = (
    FileFormat(name="text export (DAQ)", suffixes=SUFFIXES, kind="daq", read=open_daq, streaming=False),
)
