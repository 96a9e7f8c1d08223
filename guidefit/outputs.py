"""Output files written whole, never over an input, and interrupts that end cleanly.

Every file guidefit writes (tables, plots, FRFs, reports, decks, recordings)
goes through :func:`replacing`: the writer writes a temporary file in the
destination's folder, and only a complete file is renamed onto the
destination with :func:`os.replace`. A kill, a full disk or a file-size limit
therefore leaves the destination as it was (or absent) and no temporary file
behind, never a truncated file that looks complete. ``os.replace`` renames
onto the destination's *name*: a symbolic link there is replaced by the new
file, its target is not written through.

:func:`refuse_inputs` is the guard every command runs before it starts: an
output that is one of the files the command reads (:func:`files_read`: the
inputs named on the command line, a test setup's DAQ files, the files an HDF5
file's external links, external raw storage and virtual datasets name; the
same path, a hard link, a symbolic link to one of them) is a one-line
:class:`OutputError` (exit 2), and so are two outputs onto one file.

:func:`install_interrupt_handler` is the command line's Ctrl-C: the main
thread gets ``KeyboardInterrupt`` (the command unwinds, temporary files are
removed, exit 130 with one line); should the process still be alive a moment
later (a C call that does not return, an exit handler waiting on a worker),
a watchdog thread removes the pending temporary files, kills the registered
worker processes, says ``guidefit: interrupted`` and ends the process.
``SIGTERM`` (``kill``, ``timeout``) ends the program at once the same way:
``guidefit: terminated``, exit 143 (workers die with their parent even when it
is killed outright: :mod:`guidefit.workers`).
"""

from __future__ import annotations

import contextlib
import os
import sys
import threading
from pathlib import Path

from guidefit.errors import GuidefitError

__all__ = [
    "INTERRUPT_GRACE_S",
    "OutputError",
    "files_read",
    "handler_installed",
    "install_interrupt_handler",
    "interrupted",
    "interrupted_exit",
    "one_line_warning",
    "quiet_unraisable",
    "refuse_inputs",
    "register_children",
    "replacing",
    "terminated_exit",
    "write_bytes",
    "write_text",
]

#: Seconds between Ctrl-C and the watchdog ending a process that has not ended by itself.
INTERRUPT_GRACE_S = 0.3

_PENDING: set[str] = set()  # temporary files being written (removed by the interrupt watchdog)
_CHILDREN: set[int] = set()  # worker processes the interrupt watchdog kills
_LOCK = threading.Lock()
_SAID = threading.Event()  # "guidefit: interrupted" written (once per process)
_INSTALLED = threading.Event()  # install_interrupt_handler ran (the guidefit program)


class OutputError(GuidefitError, ValueError):
    """An output cannot be written where asked (it is an input, or its folder is missing)."""


def _same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:  # one of them does not exist (or cannot be inspected): compare resolved names
        return os.path.realpath(a) == os.path.realpath(b)


def refuse_inputs(outputs, inputs) -> None:
    """Raise :class:`OutputError` when an output is a file the inputs read, or two outputs are one file.

    ``outputs`` and ``inputs`` are paths (``None`` entries are ignored); every
    file the inputs read is compared (:func:`files_read`: a setup's DAQ files,
    an HDF5 file's linked files). Same file means the same inode
    (:func:`os.path.samefile`: hard links and symbolic links to an input
    count), or the same resolved name (:func:`os.path.realpath`) where one of
    them does not exist. Nothing is resolved when there is no output.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     rec = pathlib.Path(folder) / "rec.h5"
    ...     _ = rec.write_bytes(b"x")
    ...     refuse_inputs([pathlib.Path(folder) / "out.csv"], [rec])   # fine
    ...     try:
    ...         refuse_inputs([rec], [rec])
    ...     except OutputError as exc:
    ...         print(str(exc).split(": ", 1)[1].split(" (")[0])
    is an input of this command
    """
    outs = [Path(os.fspath(p)) for p in outputs if p is not None]
    if not outs:
        return
    for k, out in enumerate(outs):
        for other in outs[:k]:  # two outputs onto one file: the second would replace the first
            if _same_file(out, other):
                raise OutputError(f"{out}: is given for two outputs of this command ({other}); "
                                  "choose different files")
    read = files_read(inputs)
    for out in outs:
        for src, reader in read:
            if _same_file(out, src):
                through = f", read through {reader}" if reader is not None else ""
                raise OutputError(f"{out}: is an input of this command ({src}{through}); choose another output file")


# ------------------------------------------------------------------ what the inputs read

#: at most this many files are followed from a command's inputs (links of links of ...)
MAX_FILES_READ = 4096
#: at most this many objects of one HDF5 file are looked at for links to other files
MAX_HDF5_OBJECTS = 100_000
#: a TOML input larger than this is not parsed for a setup's runs (readers cap their own inputs)
MAX_SETUP_BYTES = 16 * 2**20

_HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"


def files_read(inputs) -> list[tuple[Path, Path | None]]:
    """Every file reading ``inputs`` may read: ``(path, the file that names it or None)``.

    Each input, and what it names, followed to any depth (each file once):

    * a TOML file with a ``[runs.<name>]`` table (a test setup,
      ``test-setup-format.md``): each run's ``file``, relative to the setup;
    * an HDF5 file (by its signature: contract recordings, ``frf.h5``, MAT
      v7.3): the files its external links, external raw storage and virtual
      dataset sources name, relative to the folder of the file that holds them
      (as :mod:`guidefit.io.hdf5` reads them);
    * a TDMS file: its ``.tdms_index`` beside it;
    * a guide TOML an input names for itself (``guide`` of a setup, an HDF5
      recording's root attribute, a CSV recording's ``# guide:`` line, a
      ``"guide"`` of a JSON input): a name that is a file is read as the
      guide, as ``--guide`` would be (relative to the working directory).

    Only regular files are opened (a FIFO would block); a file that cannot be
    parsed names nothing here (its reader says what is wrong). The HDF5
    metadata is read under the reader's deadline
    (:func:`guidefit.io.watchdog.call_guarded`): a damaged file that makes the
    HDF5 library loop is the reader's one-line error, not a hang.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     setup = pathlib.Path(folder) / "test.toml"
    ...     _ = setup.write_text('[runs.vertical]\\nfile = "vertical.csv"\\n')
    ...     print([(p.name, r and r.name) for p, r in files_read([setup, None])])
    [('test.toml', None), ('vertical.csv', 'test.toml')]
    """
    queue = [(Path(os.fspath(p)), None) for p in inputs if p is not None]
    seen, found = set(), []
    while queue and len(found) < MAX_FILES_READ:
        path, reader = queue.pop(0)
        key = os.path.realpath(path)
        if key in seen:
            continue
        seen.add(key)
        found.append((path, reader))
        queue.extend((named, path) for named in _named_by(path))
    return found


def _named_by(path: Path) -> list[Path]:
    """The files the regular file ``path`` makes its reader read (none for another file)."""
    import stat

    try:
        info = os.stat(path)
    except (OSError, ValueError):
        return []
    if not stat.S_ISREG(info.st_mode):
        return []
    suffix = path.suffix.lower()
    if suffix == ".toml":
        return _setup_files(path, info.st_size)
    if suffix in (".json", ".jsonl", ".csv"):
        return _guides_in_text(path, suffix)
    named = []
    if suffix == ".tdms" and os.path.isfile(f"{path}_index"):
        named.append(Path(f"{path}_index"))
    if _is_hdf5(path, info.st_size):
        from guidefit.io.watchdog import call_guarded

        named += [Path(p) for p in call_guarded(_hdf5_files, path, os.fspath(path))]
    return named


def _setup_files(path: Path, size: int) -> list[Path]:
    """The runs' files of a test setup (TOML that cannot be read names nothing)."""
    import tomllib

    if size > MAX_SETUP_BYTES:
        return []
    try:
        with open(path, "rb") as handle:
            data = tomllib.load(handle)
    except (OSError, ValueError, RecursionError):  # TOMLDecodeError and UnicodeDecodeError are ValueErrors
        return []
    named = _guide_file(data.get("guide"))
    runs = data.get("runs")
    if not isinstance(runs, dict):
        return named
    return named + [path.parent / run["file"] for run in runs.values()
                    if isinstance(run, dict) and isinstance(run.get("file"), str) and run["file"]
                    and "\0" not in run["file"]]


def _guide_file(name) -> list[Path]:
    """``[Path(name)]`` when ``name`` (a guide an input names) is a file: ``load_guide`` reads it."""
    if not isinstance(name, str) or not name.strip() or "\0" in name:
        return []
    try:
        return [Path(name)] if os.path.isfile(name) else []
    except (OSError, ValueError):
        return []


#: the part of a JSON or CSV input looked at for a guide it names (a JSON result holds it near the start)
_GUIDE_SCAN_BYTES = 64 * 2**20


def _guides_in_text(path: Path, suffix: str) -> list[Path]:
    """Guide files named by ``"guide": "..."`` in a JSON input or ``# guide: ...`` in a CSV recording."""
    import json
    import re

    try:
        with open(path, "rb") as handle:
            text = handle.read(_GUIDE_SCAN_BYTES if suffix != ".csv" else 2**16).decode("utf-8", "replace")
    except OSError:
        return []
    if suffix == ".csv":
        names = re.findall(r"(?m)^\s*#\s*guide\s*:\s*(.*?)\s*$", text)
    else:
        names = []
        for literal in set(re.findall(r'"guide"\s*:\s*("(?:[^"\\]|\\.)*")', text)):
            try:
                names.append(json.loads(literal))
            except ValueError:
                continue
    return [found for name in names for found in _guide_file(name)]


def _is_hdf5(path: Path, size: int) -> bool:
    """The HDF5 signature at offset 0, 512, 1024, 2048, ... (after a user block, as in MAT v7.3)."""
    try:
        with open(path, "rb") as handle:
            offset = 0
            while offset + len(_HDF5_SIGNATURE) <= size:
                handle.seek(offset)
                if handle.read(len(_HDF5_SIGNATURE)) == _HDF5_SIGNATURE:
                    return True
                offset = 512 if offset == 0 else 2 * offset
    except OSError:
        return False
    return False


def _hdf5_files(path: Path, display: str) -> list[str]:
    """The files an HDF5 file names: external links, external raw storage, virtual dataset sources.

    Relative names are taken in the folder of the file as named and, where it
    differs, as resolved (HDF5 and :mod:`guidefit.io.hdf5` look there). Errors
    of a damaged file end the search with what was found.
    """
    import h5py

    named: list[str] = []

    def near(name) -> None:
        name = os.fsdecode(name)
        if os.path.isabs(name):
            named.append(name)
            return
        named.append(os.path.join(os.path.dirname(os.fspath(path)), name))  # as the reader names it
        real = os.path.join(os.path.dirname(os.path.realpath(path)), name)
        if os.path.realpath(named[-1]) != os.path.realpath(real):  # the file reached through a symbolic link
            named.append(real)

    def look(name, obj):
        if isinstance(obj, h5py.Group):
            for key in obj:
                link = obj.get(key, getlink=True)
                if isinstance(link, h5py.ExternalLink):
                    near(link.filename)
        elif isinstance(obj, h5py.Dataset):
            for file_name, _, _ in obj.external or ():
                near(file_name)
            if obj.is_virtual:
                for source in obj.virtual_sources():
                    if source.file_name != ".":
                        near(source.file_name)
        count[0] += 1
        return True if count[0] > MAX_HDF5_OBJECTS else None

    count = [0]
    try:
        with h5py.File(path, "r") as handle:
            guide = handle.attrs.get("guide")
            if isinstance(guide, bytes | str):  # a guide TOML the recording names, as --guide would
                named += [os.fspath(p) for p in _guide_file(os.fsdecode(guide))]
            if look("/", handle) is None:
                handle.visititems(look)
    except Exception:  # noqa: BLE001 - a damaged file: its reader reports it
        pass
    return named
def _temp_name(p: Path) -> tuple[int, Path]:
    """A new temporary file beside ``p`` with the same suffix (writers choose formats by suffix)."""
    import tempfile

    folder = p.parent if str(p.parent) else Path(".")
    if not folder.is_dir():
        raise OutputError(f"{p}: folder '{folder}' does not exist")
    fd, name = tempfile.mkstemp(prefix=f".{p.name}.", suffix=f".tmp{p.suffix}", dir=folder)
    return fd, Path(name)


@contextlib.contextmanager
def replacing(path):
    """Context manager: a temporary path to write, renamed onto ``path`` when the block ends.

    The temporary file is in the same folder (so the rename is atomic) and has
    the same suffix. On any exception (interrupt included) it is removed and
    ``path`` is untouched. The new file keeps the permissions of the regular
    file it replaces, or gets those ``open()`` would give it (``0o666`` less
    the umask). A write that fails for lack of room (full disk, quota,
    file-size limit, read-only file system) is :class:`OutputError`
    ``"<path>: cannot write (<reason>)"``.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     out = pathlib.Path(folder) / "table.csv"
    ...     with replacing(out) as tmp:
    ...         _ = tmp.write_text("a,b\\n1,2\\n")
    ...     print(out.read_text().splitlines(), sorted(q.name for q in out.parent.iterdir()))
    ['a,b', '1,2'] ['table.csv']
    """
    p = Path(path)
    fd, tmp = _temp_name(p)
    os.close(fd)
    with _LOCK:
        _PENDING.add(str(tmp))
    try:
        try:
            yield tmp
        except (OSError, RuntimeError) as exc:
            reason = _write_failure(exc)
            if reason is None:
                raise
            raise OutputError(f"{p}: cannot write ({reason})") from None
        os.chmod(tmp, _mode_for(p))
        os.replace(tmp, p)
    finally:
        with _LOCK:
            _PENDING.discard(str(tmp))
        with contextlib.suppress(OSError):
            tmp.unlink()


def _mode_for(p: Path) -> int:
    """Permissions of the new file: those of the regular file it replaces, else what ``open()``
    would give (0o666 less the umask), never mkstemp's 0o600."""
    import stat

    try:
        st = os.lstat(p)
        if stat.S_ISREG(st.st_mode):
            return stat.S_IMODE(st.st_mode)
    except OSError:
        pass
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


def _write_failure(exc: BaseException) -> str | None:
    """The reason of a failed write (full disk, file-size limit, ...), or None for another error.

    h5py reports libhdf5's failures as OSError or RuntimeError with the errno in the text.

    >>> _write_failure(OSError(28, "No space left on device"))
    'No space left on device'
    >>> _write_failure(RuntimeError("Can't decrement id ref count (unable to extend file properly, errno = 27, ...)"))
    'File too large'
    >>> _write_failure(OSError(2, "No such file or directory")) is None
    True
    """
    import errno
    import re

    number = getattr(exc, "errno", None)
    if number is None:
        found = re.search(r"errno = (\d+)", str(exc))
        number = int(found.group(1)) if found else None
    if number in (errno.ENOSPC, errno.EFBIG, errno.EDQUOT, errno.EROFS):
        return os.strerror(number)
    return None


def write_bytes(path, data: bytes) -> None:
    """Write ``data`` to ``path`` whole (:func:`replacing`)."""
    with replacing(path) as tmp, open(tmp, "wb") as handle:
        handle.write(data)


def write_text(path, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` whole (:func:`replacing`)."""
    write_bytes(path, text.encode("utf-8"))


# ------------------------------------------------------------------ interrupts


def register_children(pids) -> None:
    """Worker processes the interrupt watchdog kills should the command not end in time."""
    with _LOCK:
        _CHILDREN.update(int(p) for p in pids if p)


def _cleanup_and_say(message: bytes = b"guidefit: interrupted") -> None:
    import signal

    # (a thread stopped inside a signal handler may hold the lock: go on without it after a while)
    locked = _LOCK.acquire(timeout=0.2)
    try:
        pending, children = list(_PENDING), list(_CHILDREN)
    finally:
        if locked:
            _LOCK.release()
    for pid in children:
        with contextlib.suppress(OSError):
            os.kill(pid, signal.SIGKILL)
    for pid in children:  # reaped here: where nothing reaps orphans they would stay as zombies
        with contextlib.suppress(OSError):
            os.waitpid(pid, 0)
    with contextlib.suppress(OSError):
        while os.waitpid(-1, os.WNOHANG)[0]:  # children that have already ended (forked readers)
            pass
    for name in pending:
        with contextlib.suppress(OSError):
            os.unlink(name)
    if not _SAID.is_set():
        _SAID.set()
        with contextlib.suppress(OSError):
            # on a terminal a progress bar may have hidden the cursor and left a partial line
            prefix = b"\r\x1b[2K\x1b[?25h" if os.isatty(2) else b""
            os.write(2, prefix + message + b"\n")


def interrupted_exit() -> None:
    """Say ``guidefit: interrupted`` (once), kill registered workers and end with 130 now.

    ``os._exit``: exit handlers (a process pool joining its workers) cannot
    make an interrupted command wait.
    """
    with contextlib.suppress(Exception):
        sys.stdout.flush()
    _cleanup_and_say()
    os._exit(130)


def terminated_exit() -> None:
    """``SIGTERM``: say ``guidefit: terminated`` (once), kill registered workers, remove pending
    temporary files and end with 143 (128 + SIGTERM) now, from any thread.

    Standard output is not flushed: the main thread may be stopped holding its lock."""
    _TERMINATING.set()
    _cleanup_and_say(b"guidefit: terminated")
    os._exit(143)


def _watchdog(read_fd: int) -> None:
    import signal
    import time

    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})  # signals go to the main thread
    while True:
        try:
            data = os.read(read_fd, 512)
        except OSError:
            return
        if not data:
            return
        if signal.SIGTERM in data:  # no grace: whoever sent it wants the process gone
            terminated_exit()
        if signal.SIGINT in data:
            _INTERRUPTED.set()
            time.sleep(INTERRUPT_GRACE_S)
            interrupted_exit()


_INTERRUPTED = threading.Event()  # SIGINT received (install_interrupt_handler's handler ran)


def interrupted() -> bool:
    """True once Ctrl-C was received: an error seen after it (an import that the interrupt broke,
    say, reported as ImportError) is the interrupt, not a fault of the input."""
    return _INTERRUPTED.is_set()


def _raise_interrupt(signum, frame):
    _INTERRUPTED.set()
    raise KeyboardInterrupt


_TERMINATING = threading.Event()  # SIGTERM received: the process is ending


def _stop_main_thread(signum, frame):
    """``SIGTERM``'s Python handler: stop the main thread here for good. The wake-up pipe has told
    the watchdog thread, which ends the process; the main thread must not meanwhile report the
    workers it kills as an error (a broken pool) or exit with another code. (The cleanup is not
    done here: the main thread may hold a lock it needs.)"""
    _TERMINATING.set()
    threading.Event().wait()


def install_interrupt_handler() -> None:
    """The command line's Ctrl-C and ``SIGTERM``: see the module docstring. Main thread only.

    A C-level wake-up pipe (:func:`signal.set_wakeup_fd`) tells the watchdog
    thread at once, even while the main thread is in a long C call.
    """
    import signal

    if threading.current_thread() is not threading.main_thread():
        return
    read_fd, write_fd = os.pipe()
    os.set_blocking(write_fd, False)
    try:
        signal.set_wakeup_fd(write_fd, warn_on_full_buffer=False)
    except (ValueError, OSError):
        os.close(read_fd)
        os.close(write_fd)
        return
    signal.signal(signal.SIGINT, _raise_interrupt)
    signal.signal(signal.SIGTERM, _stop_main_thread)
    _INSTALLED.set()
    threading.Thread(target=_watchdog, args=(read_fd,), name="guidefit-interrupt", daemon=True).start()


def handler_installed() -> bool:
    """True in the ``guidefit`` program (:func:`install_interrupt_handler` ran), not under a test runner."""
    return _INSTALLED.is_set()


def quiet_unraisable(*args) -> None:
    """``sys.unraisablehook`` and ``sys.excepthook`` of the program: a failure while an object
    is freed after the error was reported (h5py closing a file on a full disk, a generator
    closed by Ctrl-C) adds no traceback; the command's own message has said what went wrong.
    (Every exception of a command is turned into one line by the command line itself.)"""


def one_line_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """``warnings.showwarning`` of the command line: ``guidefit: warning: <text> (<category>)``.

    Python's form (file path, line number, source line) is not for the user.

    Examples
    --------
    >>> import io
    >>> out = io.StringIO()
    >>> one_line_warning(RuntimeWarning("invalid value\\nencountered"), RuntimeWarning, "/x/y.py", 3, out)
    >>> out.getvalue()
    'guidefit: warning: invalid value encountered (RuntimeWarning)\\n'
    """
    text = " ".join(str(message).split()) or category.__name__
    target = sys.stderr if file is None else file
    with contextlib.suppress(Exception):
        target.write(f"guidefit: warning: {text} ({category.__name__})\n")


def one_line_logging() -> None:
    """Library log records that reach Python's last-resort handler (warnings and errors of
    matplotlib, h5py, ... when nobody configured logging) as ``guidefit: warning: <text>``."""
    import logging

    handler = logging.StreamHandler()
    handler.setLevel(logging.WARNING)
    handler.setFormatter(_OneLineFormatter())
    logging.lastResort = handler


class _OneLineFormatter:
    def format(self, record) -> str:
        text = " ".join(record.getMessage().split())
        return f"guidefit: warning: {text} ({record.name})"
