"""Reading JSON result files: one JSON document, or JSON Lines (``identify --json``).

Every number must be a finite float: ``NaN``/``Infinity`` (not JSON, though
Python writes them; guidefit writes ``null``) and numbers beyond the float
range (``1e999``, an integer of 400 digits) are refused in one line naming
the key, not read as ``inf`` or left to fail later as an internal error.
"""

from __future__ import annotations

import json
import math
import stat
from pathlib import Path

from guidefit.errors import RecordingError

#: a result file larger than this is refused before it is read (a batch of ten thousand
#: recordings' JSON Lines is about 1 GB less than this; JSON text takes ~10x its size in memory)
MAX_JSON_BYTES = 2 * 2**30


def read_json_documents(path) -> list:
    """The documents of a JSON file: ``[doc]`` for one JSON document, one per line for JSON Lines.

    Raises :class:`~guidefit.errors.RecordingError` (one line, naming the file
    and the line) for a missing, unreadable, empty or malformed file, for
    something that is not a regular file (a FIFO or a device would block or
    never end) and for a file over :data:`MAX_JSON_BYTES`.

    >>> import tempfile, os
    >>> with tempfile.NamedTemporaryFile("w", suffix=".jsonl", delete=False) as fh:
    ...     _ = fh.write('{"a": 1}\\n{"a": 2}\\n')
    >>> read_json_documents(fh.name)
    [{'a': 1}, {'a': 2}]
    >>> os.remove(fh.name)
    """
    p = Path(path)
    try:
        info = p.stat()
    except FileNotFoundError:
        raise RecordingError(f"{p}: no such file") from None
    except OSError as exc:
        raise RecordingError(f"{p}: cannot read ({exc.__class__.__name__})") from None
    if stat.S_ISDIR(info.st_mode):
        raise RecordingError(f"{p}: is a directory; expected a JSON result file")
    if not stat.S_ISREG(info.st_mode):
        raise RecordingError(f"{p}: not a regular file; expected a JSON result file")
    if info.st_size > MAX_JSON_BYTES:
        raise RecordingError(f"{p}: {info.st_size / 2**30:.1f} GB, larger than the {MAX_JSON_BYTES / 2**30:.0f} GB "
                             "a JSON result file may have; not a result file?")
    try:
        text = p.read_text(encoding="utf-8-sig")  # a byte-order mark (PowerShell, Notepad) is not JSON text
    except FileNotFoundError:
        raise RecordingError(f"{p}: no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise RecordingError(f"{p}: cannot read ({exc.__class__.__name__})") from None
    if not text.strip():
        raise RecordingError(f"{p}: empty file")
    try:
        return [_loads(text, f"{p}")]
    except json.JSONDecodeError:
        pass
    except RecursionError:  # the decoder recurses per nesting level
        raise RecordingError(f"{p}: not a result file (arrays or objects nested too deeply)") from None
    docs = []
    for number, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        try:
            docs.append(_loads(line, f"{p}: line {number}"))
        except json.JSONDecodeError as exc:
            raise RecordingError(f"{p}: line {number}: not JSON ({exc.msg})") from None
        except RecursionError:
            raise RecordingError(f"{p}: line {number}: arrays or objects nested too deeply") from None
    return docs


class _NotFinite(str):
    """A number of the JSON text that is no finite float (its text), found after parsing."""


def _loads(text: str, where: str):
    """``json.loads`` with every number a finite float or an int a float can hold.

    Raises :class:`RecordingError` ``"<where>: <key>: <number> is not a finite number (...)"``
    for ``NaN``, ``Infinity``, ``1e999`` or an integer beyond the float range (Python's
    4300-digit limit on integer text included).

    >>> _loads('{"a": [1, 2.5]}', "r.json")
    {'a': [1, 2.5]}
    >>> try:
    ...     _loads('{"p": {"K_V": {"value": 1e999}}}', "r.json")
    ... except RecordingError as exc:
    ...     print(exc)
    r.json: p.K_V.value: 1e999 is not a finite number (too large for a float)
    """
    found = []

    def number(kind):
        def parse(token: str):
            try:
                value = kind(token) if len(token) <= 4000 else math.inf
                if not math.isfinite(float(value)):
                    raise OverflowError
            except (OverflowError, ValueError):
                found.append(token)
                return _NotFinite(token)
            return value
        return parse

    def constant(token: str):
        found.append(token)
        return _NotFinite(token)

    doc = json.loads(text, parse_float=number(float), parse_int=number(int), parse_constant=constant)
    if found:
        key, token = _first_not_finite(doc)
        shown = token if len(token) <= 24 else f"{token[:12]}...({len(token)} characters)"
        why = ("not JSON; write null for a missing value" if token in ("NaN", "Infinity", "-Infinity")
               else "too large for a float")
        raise RecordingError(f"{where}: {key or 'the document'}: {shown} is not a finite number ({why})")
    return doc


def _first_not_finite(doc, key: str = ""):
    """(key path such as ``parameters.K_V.value`` or ``modes[2].frequency_hz``, text) of the first
    :class:`_NotFinite` in ``doc``, or None."""
    stack = [(key, doc)]
    while stack:
        key, item = stack.pop()
        if isinstance(item, _NotFinite):
            return key, str(item)
        if isinstance(item, dict):
            stack.extend((f"{key}.{k}" if key else str(k), v) for k, v in reversed(item.items()))
        elif isinstance(item, list):
            stack.extend((f"{key}[{k}]", v) for k, v in reversed(list(enumerate(item))))
    return None


#: the contract's unit of each kind of identify parameter (recording-format.md, "Machine-readable
#: results") and the factor from each other spelling read (spaces, '*' and '.' dropped) to it
_UNIT_FACTORS = {
    "f": ("Hz", {"Hz": 1.0, "hz": 1.0, "kHz": 1e3}),
    "zeta": ("1", {"1": 1.0, "": 1.0, "-": 1.0}),
    "K": ("N/m", {"N/m": 1.0, "N/mm": 1e3, "N/um": 1e6, "N/µm": 1e6, "N/μm": 1e6, "kN/m": 1e3,
                  "kN/mm": 1e6, "MN/m": 1e6}),
    "c": ("N*s/m", {"Ns/m": 1.0, "Ns/mm": 1e3, "kNs/m": 1e3}),
}


def parameter_factor(name: str, param: dict, where: str) -> float:
    """The factor taking parameter ``name``'s ``value`` (and ``std``) in its ``unit`` to the contract's.

    A parameter without ``unit`` is in the contract's unit; a unit of another
    scale (``N/mm``, ``kHz``) is converted; any other unit is refused
    (:class:`~guidefit.errors.RecordingError`, exit 2) rather than read as if
    it were SI: a hand-edited ``"K_H": {"value": 541328, "unit": "N/mm"}``
    was exported as 5.4e5 N/m. Parameters of no known kind are returned as they are.

    >>> parameter_factor("K_H", {"value": 541328.4, "unit": "N/mm"}, "r.json")
    1000.0
    >>> parameter_factor("f_V", {"value": 3450.0}, "r.json")
    1.0
    """
    kind = name.split("_", 1)[0]
    if kind not in _UNIT_FACTORS or "_" not in name:
        return 1.0
    unit = param.get("unit") if isinstance(param, dict) else None
    if unit is None:
        return 1.0
    si, factors = _UNIT_FACTORS[kind]
    key = str(unit).replace(" ", "").replace("*", "").replace("·", "").replace(".", "")
    if key not in factors:
        raise RecordingError(f"{where}: parameter '{name}' in unit {str(unit)[:20]!r}; "
                             f"expected {si} (or one of {', '.join(u for u in factors if u)})")
    return factors[key]
