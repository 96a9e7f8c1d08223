"""Reading JSON result files: one JSON document, or JSON Lines (``identify --json``)."""

from __future__ import annotations

import json
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
