"""Worker processes that die with the command that started them.

``identify --jobs N`` runs files in a :class:`concurrent.futures.ProcessPoolExecutor`.
Should the parent end without shutting its pool down (``kill -9``, an
out-of-memory kill, a crash), its workers would otherwise live on for good:
each waits on the pool's call queue, or on a write of its result into the
result pipe, whose read end the other orphaned workers still hold open
(issue 21, item 9: 120 MB each, forever).

:func:`init_worker` is the pool's initializer. On Linux it asks the kernel to
send the worker ``SIGKILL`` when its parent dies (``prctl(PR_SET_PDEATHSIG)``,
through :mod:`ctypes`: neither the standard library nor a kept package offers
it); elsewhere, or where the call fails, a daemon thread polls the parent
every :data:`PARENT_POLL_S` seconds. ``SIGTERM`` of the parent is handled in
the parent (:func:`guidefit.outputs.install_interrupt_handler`: the registered
workers are killed, then the parent ends with 143).
"""

from __future__ import annotations

import os
import sys

__all__ = ["PARENT_POLL_S", "die_with_parent", "init_worker", "parent_death_signal", "quiet_worker"]

#: Seconds between two looks at the parent where the kernel cannot watch it (not Linux).
PARENT_POLL_S = 0.5

_PR_SET_PDEATHSIG = 1  # <linux/prctl.h>


def parent_death_signal() -> bool:
    """Ask Linux to ``SIGKILL`` this process when the thread that forked it ends; True if armed.

    The request holds for the parent *thread*: call it in a process forked by a
    thread that lives as long as the child matters (a pool's submitting thread,
    a reader waiting on its child).
    """
    if not sys.platform.startswith("linux"):
        return False
    import ctypes
    import signal

    try:
        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0) == 0
    except (OSError, AttributeError):  # no C library to call (a static or an unusual build)
        return False


def _parent_alive(parent_pid: int, first_ppid: int) -> bool:
    if os.getppid() != first_ppid:  # re-parented: the parent is gone
        return False
    try:
        os.kill(parent_pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # alive, owned by another user (cannot happen for our parent; be lenient)
        return True
    return not _zombie(parent_pid)


def _zombie(pid: int) -> bool:
    """True when ``pid`` has ended but is not reaped yet (Linux ``/proc``): a parent killed while this
    worker started still answers ``kill(pid, 0)`` until its own parent waits for it."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as stat:
            state = stat.read().rsplit(b")", 1)[-1].split()[0]
    except (OSError, IndexError):  # no /proc (not Linux), or the process is gone between the calls
        return False
    return state in (b"Z", b"X")


def _poll_parent(parent_pid: int, first_ppid: int) -> None:
    import time

    while _parent_alive(parent_pid, first_ppid):
        time.sleep(PARENT_POLL_S)
    os._exit(1)


def die_with_parent(parent_pid: int) -> None:
    """End this process when ``parent_pid`` ends: at once if it is gone already, else when it dies.

    Parameters
    ----------
    parent_pid : int
        The process that started this one (the command, not a fork server in between).
    """
    import threading

    first_ppid = os.getppid()
    armed = parent_death_signal()
    if not _parent_alive(parent_pid, first_ppid):  # it died before the kernel was asked to watch
        os._exit(1)
    if not armed:
        threading.Thread(target=_poll_parent, args=(parent_pid, first_ppid), name="guidefit-parent",
                         daemon=True).start()


def quiet_worker() -> None:
    """Initializer of worker processes: Ctrl-C is the parent's to handle (no tracebacks from workers)."""
    import contextlib
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    with contextlib.suppress(ValueError, OSError):
        signal.set_wakeup_fd(-1)


def init_worker(parent_pid: int) -> None:
    """Initializer of the ``--jobs`` workers: Ctrl-C and ``SIGTERM`` are the parent's to handle,
    and the worker dies with its parent (:func:`die_with_parent`).

    Parameters
    ----------
    parent_pid : int
        ``os.getpid()`` of the command that creates the pool.
    """
    import signal

    quiet_worker()
    signal.signal(signal.SIGTERM, signal.SIG_DFL)  # not the parent's handler, inherited by the fork
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGTERM})  # blocked while the parent forked
    die_with_parent(parent_pid)
