"""Reading JSON result files: one JSON document, or JSON Lines (``identify --json``)."""

from __future__ import annotations

import json
from pathlib import Path

from guidefit.errors import RecordingError


def read_json_documents(path) -> list:
    """The documents of a JSON file: ``[doc]`` for one JSON document, one per line for JSON Lines.

    Raises :class:`~guidefit.errors.RecordingError` (one line, naming the file
    and the line) for a missing, unreadable, empty or malformed file.

    >>> import tempfile, os
    >>> with tempfile.NamedTemporaryFile("w", suffix=".jsonl", delete=False) as fh:
    ...     _ = fh.write('{"a": 1}\\n{"a": 2}\\n')
    >>> read_json_documents(fh.name)
    [{'a': 1}, {'a': 2}]
    >>> os.remove(fh.name)
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise RecordingError(f"{p}: no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise RecordingError(f"{p}: cannot read ({exc.__class__.__name__})") from None
    if not text.strip():
        raise RecordingError(f"{p}: empty file")
    try:
        return [json.loads(text)]
    except json.JSONDecodeError:
        pass
    except RecursionError:  # the decoder recurses per nesting level
        raise RecordingError(f"{p}: not a result file (arrays or objects nested too deeply)") from None
    docs = []
    for number, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        try:
            docs.append(json.loads(line))
        except json.JSONDecodeError as exc:
            raise RecordingError(f"{p}: line {number}: not JSON ({exc.msg})") from None
        except RecursionError:
            raise RecordingError(f"{p}: line {number}: arrays or objects nested too deeply") from None
    return docs
