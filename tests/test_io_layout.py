"""The I/O package's layout: no import cycle, each module importable alone, the registry."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

import guidefit
from guidefit.errors import RecordingError
from guidefit.io import FileFormat, format_for, formats

PACKAGE = Path(guidefit.__file__).resolve().parent


def _modules() -> dict[str, Path]:
    mods = {}
    for path in PACKAGE.rglob("*.py"):
        parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        mods[".".join(parts)] = path
    return mods


def _import_graph(mods: dict[str, Path]) -> dict[str, set[str]]:
    """Every import statement (module level or inside a function) between guidefit modules."""

    def resolve(name: str) -> str:
        while name and name not in mods:
            name = name.rpartition(".")[0]
        return name

    edges: dict[str, set[str]] = {m: set() for m in mods}
    for mod, path in mods.items():
        package = mod if path.name == "__init__.py" else mod.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            targets = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    parent = package
                    for _ in range(node.level - 1):
                        parent = parent.rpartition(".")[0]
                    base = parent + ("." + base if base else "")
                targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in mods else base
                           for a in node.names]
            for target in map(resolve, targets):
                if target and target != mod:
                    edges[mod].add(target)
    return edges


def _cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in edges[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    for v in edges:
        if v not in index:
            visit(v)
    return found


def test_no_import_cycle_in_guidefit():
    """frf -> hits -> recording -> uff -> frf was a cycle; no import (even one inside a
    function) may close a loop between guidefit modules."""
    edges = _import_graph(_modules())
    assert "guidefit.io.records" in edges["guidefit.hits"]  # the graph sees real imports
    assert _cycles(edges) == []


def test_the_graph_check_finds_a_cycle():
    edges = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert _cycles(edges) == [["a", "b", "c"]]


def test_each_io_module_imports_alone():
    """Each module of guidefit.io (and the compatibility modules) imports first in a
    fresh interpreter, and none pulls in h5py, pandas or scipy on import."""
    names = sorted(m for m in _modules() if m.startswith("guidefit.io"))
    names += ["guidefit.recording", "guidefit.uff", "guidefit.frf_io"]
    code = (
        "import importlib, subprocess, sys\n"
        "for name in sys.argv[1:]:\n"
        "    out = subprocess.run([sys.executable, '-c', "
        "'import importlib, sys; importlib.import_module(sys.argv[1]); "
        "print(sorted({\"h5py\", \"pandas\", \"scipy\"} & set(sys.modules)))', name],"
        " capture_output=True, text=True, check=False)\n"
        "    print(name, out.returncode, out.stdout.strip(), out.stderr.strip()[-200:])\n"
    )
    done = subprocess.run([sys.executable, "-c", code, *names], capture_output=True, text=True,
                          check=True, timeout=300)
    lines = done.stdout.strip().splitlines()
    assert len(lines) == len(names)
    for line in lines:
        assert line.split()[1:] == ["0", "[]"], line


def test_registry_dispatches_by_suffix_and_names_the_choices():
    recording_readers = {s: f for f in formats("recording") if f.read for s in f.suffixes}
    assert {".h5", ".hdf5", ".csv", ".uff", ".unv"} <= set(recording_readers)
    assert recording_readers[".h5"].module == "guidefit.io.hdf5"
    assert recording_readers[".csv"].module == "guidefit.io.csv"
    assert format_for("x.UFF", "frf", "write").module == "guidefit.io.uff"
    for kind in ("recording", "frf"):
        for action in ("read", "write"):
            seen: dict[str, str] = {}
            for fmt in formats(kind):
                if getattr(fmt, action) is None:
                    continue
                for suffix in fmt.suffixes:  # one format per suffix, kind and action
                    assert suffix not in seen, (suffix, seen[suffix], fmt.module)
                    seen[suffix] = fmt.module
    with pytest.raises(RecordingError, match=r"unknown file type '\.xyz'; expected .*\.csv.*\.h5"):
        format_for("rec.xyz", "recording", "read")
    with pytest.raises(ValueError, match="lower case"):
        FileFormat("bad", (".H5",))


def test_compatibility_modules_keep_every_public_name():
    import guidefit.frf_io
    import guidefit.io
    import guidefit.io.uff
    import guidefit.recording
    import guidefit.uff

    for name in guidefit.recording.__all__:
        assert getattr(guidefit.recording, name) is getattr(guidefit.io, name)
    for name in guidefit.io.uff.__all__:
        assert getattr(guidefit.uff, name) is getattr(guidefit.io.uff, name)
    assert guidefit.frf_io.write_frfs is guidefit.io.write_frfs
    assert guidefit.read_recording is guidefit.io.read_recording
