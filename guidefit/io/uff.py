r"""Universal File Format (UFF) dataset 58 interchange: FRFs and time data.

UFF dataset 58 ("function at nodal DOF") is the file most modal-analysis
software reads and writes (ME'scope, Simcenter Testlab, I-DEAS, sdypy-EMA).
One dataset holds one function of one response DOF (node and direction)
against one reference DOF. This module writes guidefit's FRFs and coherences
(:func:`write_frf_uff`) and time recordings (:func:`write_uff_recording`) as
ASCII UFF-58, and reads UFF-58 time data as a :class:`~guidefit.io.records.Recording`
(:func:`read_uff_recording`; :func:`guidefit.io.read_recording` calls
it for ``.uff`` and ``.unv`` files). It uses the optional package ``pyuff``
(``pip install 'guidefit[uff]'``), imported only when a UFF file is touched.

Numbering
---------
UFF-58 knows nodes and the six directions +-X, +-Y, +-Z (codes +-1, +-2, +-3;
rotations +-4..+-6 are not used here). guidefit numbers them so that the same
measuring point has the same node in every run and every file:

* response node of point A, B, C, D: 1, 2, 3, 4 (:data:`POINT_NODES`); any
  other point name: 10 + k, where k counts the other names (1, 2, ...) in the
  order they first appear in the file (:func:`point_nodes`);
* reference node (the hammer) of the i-th run (i = 1, 2, ...): 100 + i;
* direction: the channel's axis letter, x = 1, y = 2, z = 3, negative when the
  sensor's positive axis points along the negative carriage axis
  (:func:`direction_code`); the reference direction is the run's excitation
  direction in the same code. Directions must lie along an axis (within
  :data:`DIRECTION_TOLERANCE`).

Fields written
--------------
Every file starts with a units dataset 164 (SI: metre, newton, factors 1).
Then one dataset 58 per function, ASCII, double precision (each value in
E20.12 with 12 significant digits; the abscissa minimum and increment in
E13.5, 6 significant digits):

===================  ==========================  ===========================  ======================
field                FRF                         coherence                    time data
===================  ==========================  ===========================  ======================
function type        4 (FRF)                     6 (coherence)                1 (time response)
ordinate data type   6 (complex double)          4 (real double)              4 (real double)
abscissa             18 frequency, ``Hz``        18 frequency, ``Hz``         17 time, ``s``
ordinate numerator   12 acceleration, ``m/s^2``  1 general, dimensionless     12 acc. ``m/s^2`` or 13 force ``N``
ordinate denominator 13 force, ``N``             0 (unused)                   0 (unused)
===================  ==========================  ===========================  ======================

ID lines: 1 the function (``H1 acc_A_y/force``, ``coherence acc_A_y/force``,
``acc_A_y``, ``force``), 2 the run name, 3 ``NONE``, 4 ``NONE`` for time
data and for FRFs ``guidefit exp_window_tau_s=<s or none> guide=<name>``
(the exponential window, whose damping identification takes out again), 5
provenance ``guidefit key=value ...`` (estimator, averages and sample rate
of an FRF; the exact ``sample_rate_hz`` of time data, which the E13.5
increment cannot carry, and the ``guide``). Entity names are ``NONE``. The format has no NaN: an
undefined value (e.g. the coherence where no force was measured) is written
as 0.

Reading FRFs: :mod:`guidefit.io.uff_frf` (function types 4 and 6).

Reading time data
-----------------
:func:`read_uff_recording` reads the datasets 58 of function type 1 and
ignores the others (geometry, FRFs, ...). One run per reference DOF (node
and direction), in the order they first appear. In a run, the force channel
is the record whose ordinate is excitation force (specific data type 13),
or, if none is, the record at the reference DOF itself (of type unknown 0,
general 1 or reaction force 9: a displacement there is no force); every other record
must be an acceleration (type 12) and becomes ``acc_<point>_<axis>``: point
A-D for nodes 1-4, ``N<node>`` otherwise (``acc_N12_z``), the axis from the
direction code. A file written by guidefit (ID line 5 starts with
``guidefit``) keeps its run and channel names, its exact sample rate and its
guide. Positions, which UFF-58 does not carry: a node's coordinates from a
dataset 15 or 2411 in the file, else the guide's default point for A-D
(:func:`guidefit.io.geometry.default_points`; MRB35 when the file names no
guide), else the origin. The hit point: the reference node's coordinates, else
unknown (``excitation_position_m`` None and ``force_position_known`` False:
the force channel only sits at the origin). Directions: each node's
displacement coordinate system (datasets 18, 2420) turns its direction codes
into the global frame (:mod:`guidefit.io.uff_geometry`). Sample rate: the reciprocal of the abscissa
increment, or the whole number of Hz whose reciprocal the 6-digit increment
shows (51200 for ``1.95312e-05``), or guidefit's exact rate. Layout
``signals``: one continuous record per run, in which :mod:`guidefit.hits`
finds the hits. Units: SI (a dataset 164 with other factors is refused);
an acceleration with units label ``g`` is kept in g.

pyuff's sharp edges, handled here: its binary writer in overwrite mode
leaves a 7-byte file, and its ASCII writer appends to an existing file, so
files are written as ASCII to ``<path>.part`` (removed first) and moved over
``path`` at the end; ``read_sets`` returns a dict for one set and a list for
several; ``prepare_58`` wants a denominator type even for time data; it
reads a truncated last dataset silently (counted here) and does not check
the number of values against the header (checked here).

References
----------
.. [1] Structural Dynamics Research Lab, University of Cincinnati, "Universal
   File Format: dataset 58, function at nodal DOF; dataset 164, units".
.. [2] pyuff, https://pypi.org/project/pyuff/ (GPL-3.0; used as a library).
"""

from __future__ import annotations

import contextlib
import os
import re
from dataclasses import replace
from pathlib import Path

import numpy as np

from guidefit.errors import GuidefitError, RecordingError
from guidefit.io.geometry import default_points
from guidefit.io.records import (
    ArraySource,
    Recording,
    Run,
    RunData,
)
from guidefit.io.registry import FileFormat

# the codes and numbering (uff_codes) and the writer (uff_write) moved out (issue 22); importable from here as before
from guidefit.io.uff_codes import (
    _ACC_LABELS,
    _ACC_RE,
    _E13_5,
    _FORCE_LABELS,
    _FUNCTION_NAMES,
    _MARK,
    _REFERENCE_FORCE_SPECS,
    _SPEC_NAMES,
    FUNCTION_COHERENCE,
    FUNCTION_FRF,
    FUNCTION_TIME,
    OTHER_POINT_NODE_BASE,
    POINT_NODES,
    REFERENCE_NODE_BASE,
    SPEC_ACCELERATION,
    SPEC_FORCE,
    SPEC_FREQUENCY,
    SPEC_GENERAL,
    SPEC_TIME,
    SPEC_UNKNOWN,
    UFF_SUFFIXES,
    _check_suffix,
    _first_line,
    _pyuff,
    direction_code,
    direction_vector,
    point_nodes,
)
from guidefit.io.uff_geometry import DIRECTION_TOLERANCE, _direction_label
from guidefit.io.uff_write import write_frf_uff, write_uff_recording

__all__ = [
    "DIRECTION_TOLERANCE",
    "FUNCTION_COHERENCE",
    "FUNCTION_FRF",
    "FUNCTION_TIME",
    "OTHER_POINT_NODE_BASE",
    "POINT_NODES",
    "REFERENCE_NODE_BASE",
    "SPEC_ACCELERATION",
    "SPEC_FORCE",
    "SPEC_FREQUENCY",
    "SPEC_GENERAL",
    "SPEC_TIME",
    "UFF_SUFFIXES",
    "direction_code",
    "direction_vector",
    "point_nodes",
    "read_uff_recording",
    "uff_function_types",
    "write_frf_uff",
    "write_uff_recording",
]

# ------------------------------------------------------------------- reading


def _count_delimiters(raw: bytes) -> int:
    """Number of ``    -1`` dataset delimiters, found as pyuff finds them."""
    count = 0
    n = len(raw)
    index = raw.find(b"    -1")
    while index != -1:
        end = index + 6
        if end == n or raw[end] in (10, 13) or raw[end : index + 80] == b" " * 74:
            count += 1
        index = raw.find(b"    -1", index + 1)
    return count


def _read_set(uff, i: int, kind: int, display: str, header_only: bool = False) -> dict:
    try:
        with np.errstate(all="ignore"):  # pyuff's abscissa of an inf increment: no warning line before the refusal
            out = uff.read_sets(i - 1, header_only=header_only)
    except Exception as exc:  # noqa: BLE001 - pyuff raises bare Exception
        raise RecordingError(
            f"{display}: set {i} (dataset {kind}): cannot be read ({_first_line(exc)})"
        ) from None
    if isinstance(out, list):  # pyuff: a dict for one set, a list for several
        out = out[0]
    return out


def _describe(kinds: list[int], functions: list[int]) -> str:
    parts = []
    for f in sorted(set(functions)):
        parts.append(
            f"{functions.count(f)} dataset(s) 58 of function type {f} "
            f"({_FUNCTION_NAMES.get(f, 'other')})"
        )
    others = sorted({k for k in kinds if k != 58})
    if others:
        parts.append("datasets " + ", ".join(str(k) for k in others))
    return "; ".join(parts) or "nothing"


def uff_function_types(display: str) -> list[int]:
    """Function types of the datasets 58 of a UFF file (headers only), in file order.

    Raises
    ------
    RecordingError
        pyuff missing, or not a readable UFF file.
    """
    uff, kinds = open_uff(display)
    return [int(_read_set(uff, i, 58, display, header_only=True).get("func_type", -1))
            for i, kind in enumerate(kinds, start=1) if kind == 58]


def open_uff(display: str):
    """``(pyuff.UFF, dataset types)`` of a UFF file; a file pyuff cannot read is one-line RecordingError."""
    pyuff = _pyuff(display)
    try:
        uff = pyuff.UFF(display)
        kinds = [int(k) for k in uff.get_set_types()]
    except Exception as exc:  # noqa: BLE001 - pyuff raises bare Exception
        raise RecordingError(f"{display}: not a readable UFF file ({_first_line(exc)})") from None
    return uff, kinds


NOTE_FRAMES = ("directions turned from the nodes' displacement coordinate systems (datasets 18, 2420) into the "
               "global frame")


def to_global(records: list[dict], geometry, display: str) -> None:
    """Turn each record's response and reference direction codes into the global frame (in place)."""
    for r in records:
        where = f"{display}: set {r['set']}"
        r["rsp"] = (r["rsp"][0], geometry.global_code(r["rsp"][0], r["rsp"][1], where))
        r["ref"] = (r["ref"][0], geometry.global_code(r["ref"][0], r["ref"][1], where))


def _sets_of(display: str):
    """The time datasets of a UFF file as (1-based set number, dataset dict), and its geometry."""
    uff, kinds = open_uff(display)
    if not kinds:
        raise RecordingError(
            f"{display}: no UFF datasets (blocks between '    -1' lines); expected UFF-58 time data or FRFs"
        )
    if _count_delimiters(Path(display).read_bytes()) % 2:
        raise RecordingError(
            f"{display}: set {len(kinds) + 1} is truncated (no closing '    -1' line)"
        )
    time_sets: list[int] = []
    functions: list[int] = []
    for i, kind in enumerate(kinds, start=1):
        if kind == 164:
            _check_units(_read_set(uff, i, kind, display), i, display)
        elif kind == 58:
            head = _read_set(uff, i, kind, display, header_only=True)
            functions.append(int(head.get("func_type", -1)))
            if functions[-1] == FUNCTION_TIME:
                time_sets.append(i)
    if not time_sets:
        raise RecordingError(
            f"{display}: no time data (dataset 58, function type 1); found "
            f"{_describe(kinds, functions)}. guidefit reads UFF-58 time records as a recording "
            "(identify, explain and report also take FRFs: function type 4)"
        )
    from guidefit.io.uff_geometry import read_geometry

    geometry = read_geometry(uff, kinds, display, _read_set)
    return [(i, _read_set(uff, i, 58, display)) for i in time_sets], geometry


def _check_units(dset: dict, i: int, display: str) -> None:
    length, force = float(dset.get("length", 1.0)), float(dset.get("force", 1.0))
    if not (np.isclose(length, 1.0, rtol=1e-9) and np.isclose(force, 1.0, rtol=1e-9)):
        raise RecordingError(
            f"{display}: set {i} (units, dataset 164): '{dset.get('units_description', '')}' has "
            f"length factor {length:g} and force factor {force:g}; guidefit reads SI (factors 1)"
        )


def _provenance_of(dset: dict) -> dict:
    text = str(dset.get("id5", ""))
    if not text.startswith(_MARK + " ") and text != _MARK:
        return {}
    out = {}
    head, _, guide = text.partition(" guide=")
    for key, value in re.findall(r"(\w+)=(\S+)", head):
        out[key] = value
    if guide:
        out["guide"] = guide.strip()
    out[_MARK] = True
    return out


def _sample_rate(inc: float, exact: str | None) -> float:
    """Sample rate from an E13.5 increment: guidefit's exact rate, a whole number of Hz, or 1/inc."""
    if exact is not None:
        with contextlib.suppress(ValueError):
            rate = float(exact)
            if rate > 0 and abs(1.0 / rate - inc) <= _E13_5 * inc:
                return rate
    whole = round(1.0 / inc)
    if whole > 0 and abs(1.0 / whole - inc) <= _E13_5 * inc:
        return float(whole)
    return 1.0 / inc


def _record(i: int, dset: dict, display: str) -> dict:
    """Validate one time dataset; return what a run needs of it."""
    where = f"{display}: set {i}"
    ord_type = int(dset.get("ord_data_type", 0))
    if ord_type in (5, 6):
        raise RecordingError(
            f"{where}: complex time data (ordinate data type {ord_type}); "
            "expected real values (2 or 4)"
        )
    abscissa = int(dset.get("abscissa_spec_data_type", 0))
    if abscissa not in (SPEC_UNKNOWN, SPEC_TIME):
        raise RecordingError(
            f"{where}: abscissa is {_SPEC_NAMES.get(abscissa, 'type')} "
            f"({abscissa}); expected time (17)"
        )
    data = np.asarray(dset.get("data"), dtype=np.float64).reshape(-1)
    n_header = int(dset.get("num_pts", data.size))
    if data.size != n_header:
        raise RecordingError(f"{where}: {data.size} values for the {n_header} its header gives")
    if data.size < 2:
        raise RecordingError(f"{where}: {data.size} value(s); a time record needs at least 2")
    if int(dset.get("abscissa_spacing", 1)) == 1:
        inc = float(dset.get("abscissa_inc", 0.0))
        start = float(dset.get("abscissa_min", 0.0))
    else:
        x = np.asarray(dset.get("x"), dtype=np.float64).reshape(-1)
        step = np.diff(x)
        inc = float((x[-1] - x[0]) / (x.size - 1))
        if not np.allclose(step, inc, rtol=1e-4, atol=0.0):
            raise RecordingError(
                f"{where}: uneven time steps ({step.min():g} to {step.max():g} s); "
                "expected one sample rate"
            )
        start = float(x[0])
    if not (np.isfinite(inc) and inc > 0 and np.isfinite(1.0 / inc)):
        raise RecordingError(
            f"{where}: abscissa increment {inc:g} s; expected a positive time step"
        )
    if not np.isfinite(start):  # the records of a run are compared by it: NaN would pass any comparison
        raise RecordingError(f"{where}: abscissa minimum {start:g} s; expected a finite start time")
    spec = int(dset.get("ordinate_spec_data_type", 0))
    label = str(dset.get("ordinate_axis_units_lab", "")).strip()
    return {
        "set": i,
        "data": data,
        "inc": inc,
        "start": start,
        "spec": spec,
        "label": label,
        "rsp": (int(dset.get("rsp_node", 0)), int(dset.get("rsp_dir", 0))),
        "ref": (int(dset.get("ref_node", 0)), int(dset.get("ref_dir", 0))),
        "id1": str(dset.get("id1", "")).strip(),
        "id2": str(dset.get("id2", "")).strip(),
        "provenance": _provenance_of(dset),
    }


def _unit(record: dict, force: bool, display: str) -> str:
    table = _FORCE_LABELS if force else _ACC_LABELS
    key = record["label"].lower().replace(" ", "")
    if key not in table:
        allowed = "N" if force else "m/s^2 or g"
        raise RecordingError(
            f"{display}: set {record['set']}: {'force' if force else 'acceleration'} unit "
            f"'{record['label']}' unsupported; expected {allowed}"
        )
    return table[key]


def _derived_channel(record: dict) -> str:
    node, code = record["rsp"]
    point = "ABCD"[node - 1] if 1 <= node <= 4 else f"N{node}"
    return f"acc_{point}_{'xyz'[abs(code) - 1]}"


def _group_runs(records: list[dict], display: str) -> list[dict]:
    """Records grouped by reference DOF, force and accelerations named and checked."""
    groups: dict[tuple[int, int], list[dict]] = {}
    for record in records:
        groups.setdefault(record["ref"], []).append(record)
    runs = []
    for ref, members in groups.items():
        ref_text = f"reference node {ref[0]} direction {_direction_label(ref[1])}"
        first = members[0]
        for r in members[1:]:
            if r["data"].size != first["data"].size:
                raise RecordingError(
                    f"{display}: set {r['set']}: {r['data'].size} samples, set {first['set']} of "
                    f"the same run ({ref_text}) has {first['data'].size}; expected equal lengths"
                )
            if abs(r["inc"] - first["inc"]) > 1e-9 * first["inc"]:
                raise RecordingError(
                    f"{display}: set {r['set']}: time step {r['inc']:g} s, set {first['set']} of "
                    f"the same run ({ref_text}) has {first['inc']:g} s"
                )
            if abs(r["start"] - first["start"]) > 0.5 * first["inc"]:
                raise RecordingError(
                    f"{display}: set {r['set']}: starts at {r['start']:g} s, set {first['set']} of "
                    f"the same run ({ref_text}) at {first['start']:g} s; records must be simultaneous"
                )
        forces = [r for r in members if r["spec"] == SPEC_FORCE]
        if not forces:
            # only an ordinate that may be a force: a displacement or velocity there is no hammer
            forces = [r for r in members if r["rsp"] == ref and r["spec"] in _REFERENCE_FORCE_SPECS]
        if not forces:
            raise RecordingError(
                f"{display}: run at {ref_text} (set {first['set']}...): no force record "
                "(ordinate type 13, or a record of type 0, 1 or 9 at the reference DOF)"
            )
        if len(forces) > 1:
            sets = ", ".join(str(r["set"]) for r in forces)
            raise RecordingError(
                f"{display}: sets {sets}: {len(forces)} force records for {ref_text}; expected one"
            )
        force = forces[0]
        code = ref[1] if ref[1] != 0 else force["rsp"][1]
        if abs(code) not in (1, 2, 3):
            raise RecordingError(
                f"{display}: set {force['set']}: {ref_text} gives no hammer direction; "
                "expected a translation +-1, +-2 or +-3"
            )
        for r in members:
            if r is force:
                continue
            if r["spec"] != SPEC_ACCELERATION:
                raise RecordingError(
                    f"{display}: set {r['set']}: ordinate is {_SPEC_NAMES.get(r['spec'], 'type')} "
                    f"({r['spec']}); guidefit reads acceleration (12) and force (13)"
                )
            if abs(r["rsp"][1]) not in (1, 2, 3):
                raise RecordingError(
                    f"{display}: set {r['set']}: response direction {r['rsp'][1]}; an acceleration "
                    "needs a translation +-1, +-2 or +-3"
                )
        runs.append({"ref": ref, "code": code, "members": members, "force": force})
    return runs


def _names(run: dict) -> tuple[str | None, list[str]]:
    """(run name or None, channel names) from guidefit's ID lines, else derived ones."""
    members = run["members"]
    derived = ["force" if r is run["force"] else _derived_channel(r) for r in members]
    if not all(r["provenance"] for r in members):
        return None, derived
    names = [r["id1"] for r in members]
    ok = all(
        (name == "force") == (r is run["force"])
        and (name == "force" or (_ACC_RE.match(name) and name[-1] == _derived_channel(r)[-1]))
        for name, r in zip(names, members)
    )
    if not ok or len(set(names)) != len(names):
        names = derived
    run_names = {r["id2"] for r in members}
    return (run_names.pop() if len(run_names) == 1 else None), names


def read_uff_recording(path) -> Recording:
    """Read UFF-58 time data as a recording (one continuous run per reference DOF).

    See the module docstring for how runs, channels, positions and the sample
    rate follow from the datasets. The samples are held in memory (the text
    file is parsed whole), like a CSV recording's.

    Parameters
    ----------
    path : str or path-like
        ``.uff`` or ``.unv`` with datasets 58 of function type 1.

    Returns
    -------
    guidefit.io.records.Recording
        Layout ``signals``; read samples with ``run.read_block()``.

    Raises
    ------
    RecordingError
        pyuff missing; the file is not UFF, holds no time data, or a dataset
        does not fit (complex, not time, not force or acceleration, unequal
        lengths or rates in a run, no or two force records, non-SI units): one
        line naming the file and the set.

    Examples
    --------
    See :func:`write_uff_recording`.
    """
    display = os.fspath(path)
    _check_suffix(display)
    p = Path(display)
    if not p.exists():
        raise RecordingError(f"{display}: no such file")
    if p.is_dir():
        raise RecordingError(f"{display}: is a directory; expected a UFF file")
    if p.stat().st_size == 0:
        raise RecordingError(f"{display}: file is empty")
    sets, geometry = _sets_of(display)
    records = [_record(i, dset, display) for i, dset in sets]
    to_global(records, geometry, display)
    groups = _group_runs(records, display)
    guide = next((r["provenance"].get("guide") for r in records if r["provenance"]), None)
    points = _default_points(guide)

    runs = []
    used: set[str] = set()
    for run in groups:
        ref = run["ref"]
        members = run["members"]
        force = run["force"]
        derived_run = f"ref{ref[0]}{_direction_label(run['code'])}"
        name, channel_names = _names(run)
        if not name or name in used:
            name = derived_run
        used.add(name)
        where = f"{display}: run '{name}' (set {members[0]['set']}...)"
        excitation = direction_vector(run["code"])
        units, positions, directions = [], [], []
        hit = geometry.nodes.get(ref[0])
        for channel, r in zip(channel_names, members):
            if r is force:
                units.append(_unit(r, True, display))
                positions.append(np.zeros(3) if hit is None else hit)
                directions.append(excitation)
            else:
                units.append(_unit(r, False, display))
                point = _ACC_RE.match(channel).group(1)
                node_xyz = geometry.nodes.get(r["rsp"][0])
                positions.append(node_xyz if node_xyz is not None else points.get(point, np.zeros(3)))
                directions.append(direction_vector(r["rsp"][1]))
        data = np.ascontiguousarray(np.column_stack([r["data"] for r in members]))
        data.setflags(write=False)
        provenance = force["provenance"]
        rate = _sample_rate(force["inc"], provenance.get("sample_rate_hz"))
        try:
            checked = RunData(
                name,
                rate,
                excitation,
                channel_names,
                units,
                positions,
                directions,
                data=data,
                layout="signals",
                excitation_position_m=hit,
            )
        except RecordingError as exc:
            raise RecordingError(f"{where}: {exc}") from None
        # in memory, as for CSV recordings; without the reference node's coordinates the hit point is unknown
        source = ArraySource(data)
        run = Run.from_header(checked, source, n_samples=int(data.shape[0]), file=display)
        runs.append(replace(run, force_position_known=hit is not None))
    return Recording(path=display, guide=guide, description="", runs=tuple(runs))


def _default_points(guide: str | None) -> dict[str, np.ndarray]:
    try:
        return default_points(guide)
    except GuidefitError:  # a guide this installation does not know: MRB35's A-D
        return default_points(None)


FORMATS = (
    FileFormat(
        name="UFF-58 time data",
        suffixes=UFF_SUFFIXES,
        kind="recording",
        read=lambda p, display: read_uff_recording(display),
        write=write_uff_recording,
        extra="uff",
    ),
    FileFormat(
        name="UFF-58 FRFs",
        suffixes=UFF_SUFFIXES,
        kind="frf",
        write=write_frf_uff,
        extra="uff",
    ),
)
# the reader of UFF-58 FRFs is declared in guidefit.io.uff_frf
