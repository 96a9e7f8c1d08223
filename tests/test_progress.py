"""The one progress protocol (guidefit.progress): a bar on a terminal, nothing elsewhere."""

from __future__ import annotations

import io
from pathlib import Path

import guidefit
from guidefit.progress import Bar, progress_bar


def _console(terminal: bool):
    from rich.console import Console

    return Console(file=io.StringIO(), force_terminal=terminal, width=80)


def test_a_bar_is_drawn_on_a_terminal_and_takes_both_calls():
    console = _console(True)
    with progress_bar("files", 3, console=console) as bar:
        assert isinstance(bar, Bar) and bar.shown
        bar.advance()
        bar.advance(2)
        bar(3, 4, "run 'v'")
        assert bar._progress.tasks[0].completed == 3 and bar._progress.tasks[0].total == 4
        assert bar._progress.tasks[0].description == "files: run 'v'"
    assert "files" in console.file.getvalue()


def test_nothing_is_written_off_a_terminal_or_when_disabled():
    for console, enabled in ((_console(False), True), (_console(True), False)):
        with progress_bar("simulating hits", 2, enabled=enabled, console=console) as bar:
            bar.advance()
            bar(2, None, "x")
            assert not bar.shown
        assert console.file.getvalue() == ""


def test_only_the_progress_module_draws_bars():
    """One protocol: no other module of guidefit makes a rich Progress of its own."""
    package = Path(guidefit.__file__).resolve().parent
    users = sorted(str(p.relative_to(package)) for p in package.rglob("*.py")
                   if "rich.progress" in p.read_text(encoding="utf-8"))
    assert users == ["progress.py"]
