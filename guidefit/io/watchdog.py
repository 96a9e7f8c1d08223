"""Run a metadata read of a possibly damaged file in a forked child with a deadline.

Some damaged HDF5 files make the HDF5 library itself loop (a corrupted
global heap: minutes or forever, holding the GIL, so no Python thread can
stop it) or allocate gigabytes. :func:`in_child` runs ``function(path,
display)`` in a forked child and gives up on it after the deadline, or when
it dies, with one :class:`~guidefit.errors.RecordingError`. Used by
:mod:`guidefit.io.hdf5`; nothing here is HDF5-specific.

Hand-written because neither the standard library nor h5py offers a
deadline on a C call: ``concurrent.futures``/``multiprocessing`` would pickle
the function and start an interpreter (~100 ms) where a fork costs ~30 ms,
and cannot kill a child that holds no Python lock any faster.
"""

from __future__ import annotations

import contextlib
import os
import time
from pathlib import Path

from guidefit.errors import GuidefitError, RecordingError
from guidefit.errors import first_line as _first_line

__all__ = ["HDF5_METADATA_TIMEOUT_S", "call_guarded", "in_child", "read_guarded", "timeout_s"]


#: Seconds the HDF5 library may take to read a recording's metadata (attributes, groups,
#: a probe of the samples) before the file counts as damaged; env GUIDEFIT_HDF5_TIMEOUT_S
#: wins. 0: no guard, the metadata is read in this process. The command line sets 30 s;
#: the library default is 0, because the guard forks, and a fork is unsafe in a program
#: whose other threads may hold locks (the child would wait on them for good).
HDF5_METADATA_TIMEOUT_S = 0.0

_CHILDREN: list[int] = []  # forked readers not reaped yet

#: Modules the parent imports while a forked reader reads (the command line names those its next
#: steps import anyway: the wait for the child then does their work). Imported on the calling thread
#: after the fork, never by a thread before it (a fork while another thread imports can leave the
#: child an import lock held for good).
IMPORTS_WHILE_WAITING: tuple[str, ...] = ()


def _import_while_waiting() -> None:
    """Import :data:`IMPORTS_WHILE_WAITING`; one that fails is left to its real import to report."""
    import importlib

    for name in IMPORTS_WHILE_WAITING:
        try:
            importlib.import_module(name)
        except Exception:  # noqa: BLE001 - an optional head start, not the import that counts
            continue


def timeout_s() -> float:
    """The deadline in force: env ``GUIDEFIT_HDF5_TIMEOUT_S``, else :data:`HDF5_METADATA_TIMEOUT_S`."""
    return float(os.environ.get("GUIDEFIT_HDF5_TIMEOUT_S", HDF5_METADATA_TIMEOUT_S))


def can_fork() -> bool:
    """True where the guard can run (Linux with ``os.fork``)."""
    import sys

    return sys.platform.startswith("linux") and hasattr(os, "fork")


def _reap(wait: bool, pid: int | None = None) -> int:
    """Reap finished forked readers (``wait``: all of them, or ``pid``, blocking); the
    wait status of ``pid`` (0 if not asked for)."""
    status_of_pid = 0
    for child in list(_CHILDREN):
        if pid is not None and child != pid:
            continue
        try:
            done, status = os.waitpid(child, 0 if wait else os.WNOHANG)
        except ChildProcessError:  # reaped elsewhere (e.g. a SIGCHLD handler)
            done, status = child, 0
        if done:
            _CHILDREN.remove(child)
            if child == pid:
                status_of_pid = status
    return status_of_pid


def in_child(function, p: Path, display: str, timeout: float):
    """``function(p, display)`` in a forked child, its result or GuidefitError returned
    or raised here; a child that does not answer in time, or dies, is a RecordingError."""
    import pickle
    import select
    import signal

    _reap(wait=False)
    read_end, write_end = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: answer through the pipe, then leave without any cleanup
        status = 0
        try:
            os.close(read_end)
            from guidefit.workers import parent_death_signal

            parent_death_signal()  # a reader looping on a damaged file dies with its (waiting) parent
            with contextlib.suppress(ValueError):  # SIGTERM ends the reader, not the command's handler
                signal.signal(signal.SIGTERM, signal.SIG_DFL)
            try:
                answer = ("value", function(p, display))
            except GuidefitError as exc:
                answer = ("error", exc)
            except BaseException as exc:  # noqa: BLE001 - reported to the parent as it is
                answer = ("other", f"{type(exc).__name__}: {_first_line(exc)}")
            with os.fdopen(write_end, "wb") as out:
                pickle.dump(answer, out, protocol=pickle.HIGHEST_PROTOCOL)
        except BaseException:  # noqa: BLE001 - the parent sees an empty answer
            status = 1
        finally:
            os._exit(status)
    os.close(write_end)
    _CHILDREN.append(pid)
    chunks = []
    deadline = time.monotonic() + timeout
    answered = False
    try:
        with os.fdopen(read_end, "rb") as answer_file:
            _import_while_waiting()
            while True:
                left = deadline - time.monotonic()
                ready = select.select([answer_file], [], [], left)[0] if left > 0 else []
                if not ready:
                    raise RecordingError(
                        f"{display}: damaged HDF5 file (the HDF5 library did not finish reading "
                        f"its metadata in {timeout:g} s)"
                    )
                chunk = os.read(answer_file.fileno(), 1 << 20)
                if not chunk:
                    break
                chunks.append(chunk)
        answered = True
    finally:
        if not answered:  # a timeout, or an interrupt: a looping child must not outlive us
            os.kill(pid, signal.SIGKILL)
            _reap(wait=True, pid=pid)
    if not chunks:
        status = _reap(wait=True, pid=pid)
        how = (f"signal {os.WTERMSIG(status)}" if os.WIFSIGNALED(status)
               else f"status {os.WEXITSTATUS(status)}")
        raise RecordingError(
            f"{display}: damaged HDF5 file (reading its metadata ended the reader with {how}; "
            "out of memory?)"
        )
    _reap(wait=False)  # the child is usually still tearing down: reaped by a later call
    kind, value = pickle.loads(b"".join(chunks))
    if kind == "value":
        return value
    if kind == "error":
        raise value
    raise RecordingError(f"{display}: damaged HDF5 file ({value})")


def call_guarded(function, p: Path, display: str):
    """``function(p, display)`` in a time-limited forked child where the guard is on
    (:func:`timeout_s` > 0 and the platform can fork, :func:`in_child`), else here."""
    timeout = timeout_s()
    if timeout > 0 and can_fork():
        return in_child(function, p, display, timeout)
    return function(p, display)


def read_guarded(read, p: Path, display: str, what: str):
    """:func:`call_guarded` of a metadata reader whose library errors (h5py raises OSError,
    RuntimeError, KeyError, ValueError or TypeError on damaged files) become one
    ``RecordingError``: ``<display>: damaged <what> (<first line>)``."""

    def checked(p: Path, display: str):
        try:
            return read(p, display)
        except RecordingError:
            raise
        except (OSError, RuntimeError, KeyError, ValueError, TypeError) as exc:
            raise RecordingError(f"{display}: damaged {what} ({_first_line(exc)})") from None

    return call_guarded(checked, p, display)
