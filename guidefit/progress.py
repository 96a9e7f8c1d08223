"""The one progress protocol of guidefit's long-running commands.

A command opens :func:`progress_bar` and hands the :class:`Bar` it yields to
the library as its ``progress`` argument. A library function reports in
either of two ways, whichever fits its loop:

- ``progress.advance()`` (or ``advance(n)``): ``n`` more items done
  (simulated hits, files identified, ccx runs);
- ``progress(done, total, name)``: ``done`` of ``total`` items, now at
  ``name`` (explain's candidate effects, export's carriages); ``total`` may
  be None (not known yet).

The bar is drawn with rich on stderr (or the console given), and removed
when done. When it is not enabled, or stderr is not a terminal (a pipe, a
log, a test), the same object does nothing and writes nothing: callers never
check. Library functions keep ``progress=None`` as their default and call it
only when given.

Examples
--------
>>> with progress_bar("simulating hits", total=3, enabled=False) as bar:
...     for _ in range(3):
...         bar.advance()
...     bar(3, 3, "done")
>>> bar.shown
False
"""

from __future__ import annotations

from contextlib import contextmanager

__all__ = ["Bar", "progress_bar"]


class Bar:
    """A progress bar on a rich console, or nothing (``shown`` False): the same two calls either way."""

    def __init__(self, description: str, progress=None, task=None):
        self._description, self._progress, self._task = description, progress, task

    @property
    def shown(self) -> bool:
        """Whether a bar is drawn (False: disabled, or not on a terminal)."""
        return self._progress is not None

    def advance(self, n: int = 1) -> None:
        """``n`` more items done."""
        if self._progress is not None:
            self._progress.advance(self._task, n)

    def __call__(self, done, total=None, name: str = "") -> None:
        """``done`` of ``total`` items (None: unknown), now at ``name`` (shown after the description)."""
        if self._progress is not None:
            self._progress.update(self._task, completed=done, total=total,
                                  description=f"{self._description}: {name}" if name else self._description)


@contextmanager
def progress_bar(description: str, total: int | None = None, enabled: bool = True, console=None):
    """A :class:`Bar` for the ``with`` block, drawn on stderr when enabled and on a terminal.

    Parameters
    ----------
    description : str
        Shown before the bar ("files", "simulating hits", "explaining").
    total : int, optional
        Items to do; None: not known (yet), the bar pulses.
    enabled : bool
        False: nothing is drawn (``--json`` on stdout, a single file, a library call).
    console : rich.console.Console, optional
        Where to draw; default a console on stderr. Nothing is drawn when it is not a
        terminal (a pipe or a log gets no bar, nor the blank line a bar leaves).

    Yields
    ------
    Bar
    """
    if not enabled:
        yield Bar(description)
        return
    from rich.console import Console

    console = console or Console(stderr=True, highlight=False)
    if not console.is_terminal:
        yield Bar(description)
        return
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    progress = Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                        TimeRemainingColumn(), console=console, transient=True)
    task = progress.add_task(description, total=total)
    progress.start()
    try:
        yield Bar(description, progress, task)
    finally:
        progress.stop()
