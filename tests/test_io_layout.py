"""The I/O package's layout: no import cycle, each module importable alone, the registry."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import numpy as np
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


#: The numerics of guidefit: signal processing, modal fitting, identification, the physical model.
NUMERICS = (
    "guidefit.frf", "guidefit.frf.spectra", "guidefit.frf.windows", "guidefit.hits", "guidefit.hit_checks",
    "guidefit.modes.prominence", "guidefit.modes", "guidefit.modes.base", "guidefit.modes.curvefit", "guidefit.modes.halfpower",
    "guidefit.modes.lsq", "guidefit.modes.globalfit", "guidefit.modes.globalvp", "guidefit.modal_stage", "guidefit.modes.shapes",
    "guidefit.modes.labels", "guidefit.consistency", "guidefit.identify", "guidefit.identify_runs",
    "guidefit.nonlinear", "guidefit.explain", "guidefit.simulate", "guidefit.simulate.physics", "guidefit.predict",
    "guidefit.machine.update", "guidefit.machine.correlate", "guidefit.model.static", "guidefit.model.vibration",
    "guidefit.model.contact", "guidefit.model.effects",
)
#: What guidefit.io may import outside itself: errors and data types. ``model.guides`` is the
#: guide catalogue, read for a named guide's measuring points (io.geometry.default_points).
IO_MAY_IMPORT = {"guidefit.errors", "guidefit.frfset", "guidefit.outputs", "guidefit.workers",
                 "guidefit.model.guides"}


def _is_numerics(module: str) -> bool:
    return any(module == n or module.startswith(n + ".") for n in NUMERICS)


def test_io_imports_no_numerics():
    """guidefit.io reads and writes files; no import of it (module level or inside a
    function) reaches the numerics: frf.h5 is read into the FrfSet of guidefit.frfset."""
    mods = _modules()
    edges = _import_graph(mods)
    assert "guidefit.frfset" in edges["guidefit.io.frf_files"]  # the graph sees real imports
    assert all(m in mods or any(k.startswith(m + ".") for k in mods) for m in NUMERICS), "a stale name"
    wrong = {(m, t) for m in edges if m.startswith("guidefit.io")
             for t in edges[m] if not t.startswith("guidefit.io")
             and (_is_numerics(t) or t not in IO_MAY_IMPORT)}
    assert sorted(wrong) == []
    assert not any(_is_numerics(t) for t in edges["guidefit.frfset"])


def test_the_numerics_check_sees_a_function_level_import(tmp_path):
    (tmp_path / "pkg" / "io").mkdir(parents=True)
    (tmp_path / "pkg" / "io" / "a.py").write_text("def f():\n    from pkg.frf import x\n")
    (tmp_path / "pkg" / "frf.py").write_text("x = 1\n")
    mods = {"pkg.io.a": tmp_path / "pkg" / "io" / "a.py", "pkg.frf": tmp_path / "pkg" / "frf.py"}
    assert _import_graph(mods)["pkg.io.a"] == {"pkg.frf"}


def test_frf_does_no_file_io():
    """The FRF numerics write and read no file: frf.csv and frf.h5 live in guidefit.io.frf_files."""
    import guidefit.frf
    import guidefit.io.frf_files

    for path in (PACKAGE / "frf").glob("*.py"):
        text = path.read_text(encoding="utf-8")
        assert "h5py" not in text and "open(" not in text, path.name
    for name in ("read_frf_h5", "write_frf_csv", "write_frf_h5"):  # documented names of the old home
        assert getattr(guidefit.frf, name) is getattr(guidefit.io.frf_files, name)


def _reachable(edges: dict[str, set[str]], start) -> set[str]:
    """Every module imported, directly or through others, by the modules ``start``."""
    seen: set[str] = set()
    stack = list(start)
    while stack:
        for w in edges[stack.pop()]:
            if w not in seen:
                seen.add(w)
                stack.append(w)
    return seen


def test_the_model_does_not_depend_on_explain():
    """The model (guides, static, vibration, effects, the measured data's types) stands beside the flow:
    no module of guidefit.model imports guidefit.explain, not even through another module (amplitude_dependence
    -> nonlinear -> explain.inputs was such a path), at module level or inside a function."""
    edges = _import_graph(_modules())
    model = [m for m in edges if m == "guidefit.model" or m.startswith("guidefit.model.")]
    assert "guidefit.nonlinear" in _reachable(edges, model)  # the graph sees the function-level imports
    explain = sorted(m for m in _reachable(edges, model) if m == "guidefit.explain" or m.startswith("guidefit.explain."))
    assert explain == []


def test_the_graph_check_finds_a_cycle():
    edges = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert _cycles(edges) == [["a", "b", "c"]]


def test_each_io_module_imports_alone():
    """Each module of guidefit.io (and the compatibility modules) imports first in a
    fresh interpreter, and none pulls in h5py, pandas or scipy on import."""
    names = sorted(m for m in _modules() if m.startswith("guidefit.io"))
    names += ["guidefit.io", "guidefit.io.uff", "guidefit.io.registry"]
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
    import guidefit.io
    import guidefit.io.registry
    import guidefit.io.uff

    for name in guidefit.io.__all__:
        assert getattr(guidefit.io, name) is getattr(guidefit.io, name)
    for name in guidefit.io.uff.__all__:
        assert getattr(guidefit.io.uff, name) is getattr(guidefit.io.uff, name)
    assert guidefit.io.registry.write_frfs is guidefit.io.write_frfs
    assert guidefit.read_recording is guidefit.io.read_recording


class _VoltSource:
    """A source that is not built in: only ``read(index)`` and ``dtype`` (the protocol)."""

    def __init__(self, volts):
        self._volts = volts
        self.dtype = volts.dtype
        self.reads = 0

    def read(self, index):
        self.reads += 1
        return self._volts[index]


def test_a_source_with_read_and_dtype_only_works_everywhere(tmp_path):
    """Volts in the file, the sensitivities in scale_to_si: every reader path, the hit
    check and a conversion to the contract give SI / contract units."""
    from guidefit.hits import iter_hits
    from guidefit.io import Recording, Run, RunData, open_reader, read_hit, read_recording, write_recording

    rng = np.random.default_rng(0)
    n, fs = 2000, 50_000.0
    t = np.arange(n) / fs
    force_n = np.where((t > 1e-3) & (t < 1.2e-3), 200 * np.sin(np.pi * (t - 1e-3) / 2e-4), 0.0)
    acc = np.where(t > 1e-3, 30 * np.exp(-(t - 1e-3) / 4e-3) * np.sin(2 * np.pi * 2500 * (t - 1e-3)), 0.0)
    si = np.stack([np.column_stack([force_n, acc]) * g for g in (1.0, 0.8, 1.2)])
    si += rng.normal(0, 1e-3, si.shape)
    sensitivity = np.array([2.25e-3, 10.2e-3])  # V/N, V/(m/s^2)
    source = _VoltSource((si * sensitivity).astype(np.float32))
    header = RunData("vertical", fs, [0, -1, 0], ["force", "acc_A_y"], ["N", "m/s^2"],
                     [[0, 0, 0], [0.03, 0, 0.045]], [[0, -1, 0], [0, 1, 0]], layout="hits",
                     pretrigger_samples=40)
    run = Run.from_header(header, source, n_samples=n, n_hits_stored=3, file="volts.tdms",
                          scale_to_si=1 / sensitivity)
    assert run.sample_dtype == np.float32
    np.testing.assert_allclose(read_hit(run, 1), si[1], rtol=1e-6, atol=1e-6)
    with open_reader(run) as reader:
        out = np.empty((2, n, 2), dtype=np.float32)
        raw = reader.read_hits_raw(1, 3, out=out)
        np.testing.assert_allclose(raw.astype(float) * run.scale_to_si, si[1:], rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(reader.read_hits(0, 3, [1]), si[:, :, 1:], rtol=1e-6, atol=1e-6)
    hits = list(iter_hits(run))
    assert [h.accepted for h in hits] == [True, True, True], [h.reason for h in hits]
    write_recording(tmp_path / "converted.h5", Recording("volts.tdms", "MRB35", "", (run,)))
    back = read_recording(tmp_path / "converted.h5").runs[0]
    assert [ch.unit for ch in back.channels] == ["N", "m/s^2"] and back.scale_to_si.tolist() == [1.0, 1.0]
    np.testing.assert_allclose(read_hit(back, 2), si[2], rtol=1e-6, atol=1e-6)
    with pytest.raises(RecordingError, match="scale_to_si"):
        Run.from_header(header, source, n_samples=n, scale_to_si=[1.0, 0.0])


#: the longest a function may be (lines from ``def`` to its end, docstring included) without a reason
MAX_FUNCTION_LINES = 100
#: the longest a module may be (lines) without a reason (a comment ``# long because: ...`` in its first 30 lines)
MAX_MODULE_LINES = 1000


def _long_functions(source: str, limit: int = MAX_FUNCTION_LINES) -> list[tuple[str, int, bool]]:
    """``(name, lines, has_reason)`` of every function longer than ``limit`` lines in ``source``.

    A reason is a comment ``# long because: ...`` between the ``def`` and the function's first
    statement after its docstring.
    """
    lines = source.splitlines()
    out = []
    for node in ast.walk(ast.parse(source)):
        if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        n = node.end_lineno - node.lineno + 1
        if n <= limit:
            continue
        body = node.body
        has_doc = isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant) \
            and isinstance(body[0].value.value, str)
        first = body[1] if has_doc and len(body) > 1 else body[0]
        head = lines[node.lineno - 1:first.lineno - 1]
        out.append((node.name, n, any(line.strip().startswith("# long because:") for line in head)))
    return out


def test_no_function_over_100_lines_without_a_reason():
    """Every function of guidefit (issue 22)."""
    mods = _modules()
    found = {mod: _long_functions(mods[mod].read_text(encoding="utf-8")) for mod in mods}
    unexplained = [f"{mod}.{name} ({n} lines)" for mod, funcs in found.items() for name, n, why in funcs if not why]
    assert not unexplained, "functions over 100 lines without a '# long because:' comment: " + ", ".join(unexplained)


def test_no_module_over_1000_lines_without_a_reason():
    long = []
    for mod, path in _modules().items():
        lines = path.read_text(encoding="utf-8").splitlines()
        if len(lines) > MAX_MODULE_LINES and not any(x.strip().startswith("# long because:") for x in lines[:30]):
            long.append(f"{mod} ({len(lines)} lines)")
    assert not long, "modules over 1000 lines without a '# long because:' comment: " + ", ".join(long)


def test_the_length_check_finds_a_long_function_and_reads_its_reason():
    body = "".join(f"    x{i} = {i}\n" for i in range(100))
    plain = "def f():\n    \"\"\"Doc.\"\"\"\n" + body
    reasoned = "def g():\n    \"\"\"Doc.\"\"\"\n    # long because: a table\n" + body
    short = "def h():\n" + "".join(f"    y{i} = {i}\n" for i in range(99))
    assert _long_functions(plain) == [("f", 102, False)]
    assert _long_functions(reasoned) == [("g", 103, True)]
    assert _long_functions(short) == []


#: The layers of guidefit, bottom to top (issue 22). A module may import its own layer and the layers
#: below it, never a layer above: the flow recording -> hits -> FRFs -> modes -> parameters ->
#: residuals -> report, with the model beside it (below everything that compares with it).
LAYERS = (
    ("core", ("guidefit", "guidefit._api", "guidefit.errors", "guidefit.jsonio", "guidefit.progress",
              "guidefit.workers", "guidefit.frfset")),
    ("model", ("guidefit.model",)),
    ("io", ("guidefit.io", "guidefit.outputs")),
    ("signal", ("guidefit.hits", "guidefit.hit_checks", "guidefit.frf")),
    ("modes", ("guidefit.modes",)),
    ("simulate", ("guidefit.simulate",)),
    ("identify", ("guidefit.identify", "guidefit.identify_runs", "guidefit.modal_stage", "guidefit.consistency",
                  "guidefit.sensor_signs", "guidefit.hammer_check", "guidefit.plan", "guidefit.predict")),
    ("explain", ("guidefit.nonlinear", "guidefit.explain")),
    ("products", ("guidefit.report", "guidefit.export", "guidefit.machine")),
    ("command", ("guidefit.cli", "guidefit.batch", "guidefit.__main__")),
)
#: Imports that go up a layer, each with its reason.
UPWARD_ALLOWED = {
    ("guidefit.model.effects.amplitude_dependence", "guidefit.nonlinear"):
        "the effect's forward model of force levels simulates hits through the measurement chain "
        "(called only when explain measured levels)",
}


def _layer_of(module: str) -> int:
    best, level = "", None
    for k, (_, prefixes) in enumerate(LAYERS):
        for p in prefixes:
            if (module == p or module.startswith(p + ".")) and len(p) > len(best):
                best, level = p, k
    assert level is not None, f"{module} is in no layer of LAYERS"
    return level


def test_imports_go_down_the_layers():
    """No import (module level or inside a function) reaches a layer above its module's."""
    edges = _import_graph(_modules())
    up = sorted((a, b) for a, targets in edges.items() for b in targets
                if _layer_of(b) > _layer_of(a) and (a, b) not in UPWARD_ALLOWED)
    assert up == [], "imports up the layers: " + ", ".join(f"{a} -> {b}" for a, b in up)
    assert all(b in edges[a] for a, b in UPWARD_ALLOWED), "an allowed upward import that no longer exists"


def test_the_layer_check_sees_an_upward_import():
    assert _layer_of("guidefit.io.hdf5") < _layer_of("guidefit.frf.spectra") < _layer_of("guidefit.modes.labels")
    assert _layer_of("guidefit.model.static") < _layer_of("guidefit.io") < _layer_of("guidefit.report.html")
