r"""UFF-58 FRFs in: function type 4 records (and type 6 coherences) as an :class:`~guidefit.io.frf_files.FrfFile`.

The writer is :func:`guidefit.io.uff.write_frf_uff`; this module reads what it
writes, and FRFs that other programs (ME'scope, Simcenter Testlab, pyuff
scripts, sdypy-EMA) write, mapping nodes and directions to guidefit channels
the way :func:`guidefit.io.uff.read_uff_recording` maps time data:

* **Runs**: one per reference DOF (node and direction), in order of first
  appearance; name from ID line 2 of a guidefit file, else ``ref<node><dir>``
  (``ref101-Y``). Excitation direction: the reference direction code; 0
  (unknown, e.g. written without the recording) is inferred from the
  responses (:func:`~guidefit.io.frf_files.infer_excitation_direction`) and
  said in the notes.
* **Channels**: one per FRF record, ``acc_<point>_<axis>``: point A-D for
  nodes 1-4, ``N<node>`` otherwise, axis and sign from the response
  direction code; a guidefit file keeps its channel names (ID line 1
  ``H1 acc_A_y/force``). Positions: node coordinates from a dataset 15 or
  2411 in the file where present, else the guide's default point for A-D
  and the origin otherwise (said in the notes). Directions: a node's
  displacement coordinate system (datasets 18, 2420) is applied, so the axis
  is the global one (:mod:`guidefit.io.uff_geometry`; a direction that is
  not along a global axis is refused).
* **Hit point**: the reference node's coordinates where the file gives them;
  else unknown (never the origin): identify warns, the plausibility gate
  expects every mode the sensors see, and the labels do without the
  hammer's participation.
* **Coherence**: the type 6 record at the same response and reference DOF,
  if any; without one the coherence is NaN (no coherence check).
* **Accelerance**: ordinate acceleration (12) over excitation force (13).
  Mobility (velocity 11) is converted by :math:`i\omega`, receptance
  (displacement 8) by :math:`-\omega^2` (said in the notes); an ordinate in
  ``g`` is scaled to m/s^2. Anything else (no force reference: a
  transmissibility or an unknown denominator; a real-valued or unknown
  ordinate) is refused with one line.
* **Frequencies**: the abscissa (Hz); every FRF and coherence of a run must
  share it. A guidefit file's exact sample rate (ID line 5) restores the bin
  spacing the E13.5 increment rounds; others: twice the highest frequency.
* **Windows**: guidefit's ID line 4 gives the exponential-window time
  constant (the damping is corrected for it); UFF-58 has no field for it,
  so for other files the notes say that the damping includes any window
  damping the other program applied.

UFF-58 carries no hit records and no jackknife sums: the notes say that no
hit checks were possible and that the std is the modal fit's own.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from guidefit.errors import RecordingError
from guidefit.io.frf_files import (
    NOTE_FIT_STD,
    NOTE_NO_HITS,
    FrfFile,
    check_frf_arrays,
    frf_run,
    infer_excitation_direction,
)
from guidefit.io.registry import FileFormat
from guidefit.io.uff import (
    _ACC_LABELS,
    _E13_5,
    _FORCE_LABELS,
    _SPEC_NAMES,
    FUNCTION_COHERENCE,
    FUNCTION_FRF,
    FUNCTION_TIME,
    NOTE_FRAMES,
    SPEC_ACCELERATION,
    SPEC_FORCE,
    SPEC_FREQUENCY,
    SPEC_UNKNOWN,
    UFF_SUFFIXES,
    _check_units,
    _count_delimiters,
    _default_points,
    _derived_channel,
    _describe,
    _direction_label,
    _provenance_of,
    _read_set,
    direction_vector,
    open_uff,
    to_global,
)
from guidefit.io.uff_geometry import UffGeometry, read_geometry

__all__ = ["read_uff_frfs"]

SPEC_DISPLACEMENT = 8
SPEC_VELOCITY = 11
G_M_S2 = 9.80665

_NUMERATORS = {  # spec type -> (name, power of i omega to accelerance, units labels -> factor)
    SPEC_ACCELERATION: ("acceleration", 0, {k: (G_M_S2 if v == "g" else 1.0) for k, v in _ACC_LABELS.items()}),
    SPEC_VELOCITY: ("velocity (mobility)", 1, {"": 1.0, "none": 1.0, "m/s": 1.0}),
    SPEC_DISPLACEMENT: ("displacement (receptance)", 2, {"": 1.0, "none": 1.0, "m": 1.0}),
}
_FREQUENCY_LABELS = ("", "none", "hz", "1/s")


def _label(dset: dict, key: str) -> str:
    text = str(dset.get(key, "")).strip().lower().replace(" ", "")
    return text[:-2] if text.endswith("/n") else text


def _abscissa(i: int, dset: dict, n: int, where: str) -> np.ndarray:
    spec = int(dset.get("abscissa_spec_data_type", 0))
    if spec not in (SPEC_UNKNOWN, SPEC_FREQUENCY):
        raise RecordingError(f"{where}: abscissa is {_SPEC_NAMES.get(spec, 'type')} ({spec}); "
                             "expected frequency (18)")
    units = _label(dset, "abscissa_axis_units_lab")
    if units not in _FREQUENCY_LABELS:
        raise RecordingError(f"{where}: abscissa units '{dset.get('abscissa_axis_units_lab')}'; expected Hz")
    if int(dset.get("abscissa_spacing", 1)) == 1:
        return float(dset.get("abscissa_min", 0.0)) + float(dset.get("abscissa_inc", 0.0)) * np.arange(n)
    x = np.asarray(dset.get("x"), dtype=np.float64).reshape(-1)
    if x.size != n:
        raise RecordingError(f"{where}: {x.size} abscissa values for {n} ordinates")
    return x


def _values(i: int, dset: dict, where: str, complex_: bool) -> np.ndarray:
    ord_type = int(dset.get("ord_data_type", 0))
    if complex_ and ord_type not in (5, 6):
        raise RecordingError(f"{where}: FRF with real values (ordinate data type {ord_type}); an FRF is complex "
                             "(5 or 6): magnitude and phase")
    if not complex_ and ord_type in (5, 6):
        raise RecordingError(f"{where}: complex coherence (ordinate data type {ord_type}); expected real (2 or 4)")
    data = np.asarray(dset.get("data"), dtype=np.complex128 if complex_ else np.float64).reshape(-1)
    n_header = int(dset.get("num_pts", data.size))
    if data.size != n_header:
        raise RecordingError(f"{where}: {data.size} values for the {n_header} its header gives")
    return data


def _frf_record(i: int, dset: dict, display: str) -> dict:
    """One type 4 dataset: validated, converted to accelerance in (m/s^2)/N."""
    where = f"{display}: set {i}"
    data = _values(i, dset, where, True)
    f = _abscissa(i, dset, data.size, where)
    den = int(dset.get("orddenom_spec_data_type", 0))
    den_units = _label(dset, "orddenom_axis_units_lab")
    if not (den == SPEC_FORCE or (den == SPEC_UNKNOWN and den_units == "n")):
        raise RecordingError(
            f"{where}: FRF without a force reference (denominator {_SPEC_NAMES.get(den, 'type')} ({den}), "
            f"units '{dset.get('orddenom_axis_units_lab', '')}'); guidefit needs response over excitation force (13)")
    if den_units not in _FORCE_LABELS:
        raise RecordingError(f"{where}: force unit '{dset.get('orddenom_axis_units_lab')}' unsupported; expected N")
    num = int(dset.get("ordinate_spec_data_type", 0))
    if num not in _NUMERATORS:
        raise RecordingError(
            f"{where}: FRF of {_SPEC_NAMES.get(num, 'type')} ({num}) over force; guidefit reads accelerance "
            "(acceleration 12), and converts mobility (velocity 11) and receptance (displacement 8)")
    name, power, labels = _NUMERATORS[num]
    units = _label(dset, "ordinate_axis_units_lab")
    if units not in labels:
        raise RecordingError(f"{where}: {name} unit '{dset.get('ordinate_axis_units_lab')}' unsupported; "
                             f"expected SI ({', '.join(k for k in labels if k not in ('', 'none'))})")
    H = data * labels[units] * (2j * np.pi * f) ** power
    return {"set": i, "f": f, "H": H, "spec": num, "rsp": (int(dset.get("rsp_node", 0)), int(dset.get("rsp_dir", 0))),
            "ref": (int(dset.get("ref_node", 0)), int(dset.get("ref_dir", 0))), "id1": str(dset.get("id1", "")).strip(),
            "id2": str(dset.get("id2", "")).strip(), "provenance": _provenance_of(dset),
            "windows": _provenance_of({"id5": dset.get("id4", "")}), "name": name}


def _coherence_record(i: int, dset: dict, display: str) -> dict:
    where = f"{display}: set {i}"
    data = _values(i, dset, where, False)
    return {"set": i, "f": _abscissa(i, dset, data.size, where), "values": data,
            "rsp": (int(dset.get("rsp_node", 0)), int(dset.get("rsp_dir", 0))),
            "ref": (int(dset.get("ref_node", 0)), int(dset.get("ref_dir", 0)))}


def _scan(display: str) -> tuple[list, list, UffGeometry]:
    """(FRF records, coherence records, geometry) of a UFF file; directions in the global frame."""
    uff, kinds = open_uff(display)
    if not kinds:
        raise RecordingError(f"{display}: no UFF datasets (blocks between '    -1' lines); expected UFF-58 FRFs")
    if _count_delimiters(Path(display).read_bytes()) % 2:
        raise RecordingError(f"{display}: set {len(kinds) + 1} is truncated (no closing '    -1' line)")
    frfs, cohs, functions = [], [], []
    for i, kind in enumerate(kinds, start=1):
        if kind == 164:
            _check_units(_read_set(uff, i, kind, display), i, display)
        elif kind == 58:
            head = _read_set(uff, i, kind, display, header_only=True)
            functions.append(int(head.get("func_type", -1)))
            if functions[-1] == FUNCTION_FRF:
                frfs.append(_frf_record(i, _read_set(uff, i, kind, display), display))
            elif functions[-1] == FUNCTION_COHERENCE:
                cohs.append(_coherence_record(i, _read_set(uff, i, kind, display), display))
    if FUNCTION_TIME in functions:
        raise RecordingError(f"{display}: holds time data (function type 1); it is read as a recording")
    if not frfs:
        raise RecordingError(f"{display}: no FRFs (dataset 58, function type 4); found {_describe(kinds, functions)}")
    geometry = read_geometry(uff, kinds, display, _read_set)
    to_global(frfs + cohs, geometry, display)
    return frfs, cohs, geometry


def _same_axis(a: np.ndarray, b: np.ndarray) -> bool:
    return a.size == b.size and bool(np.allclose(a, b, rtol=0.0, atol=2 * _E13_5 * max(abs(a[-1]), 1.0)))


def _exact_axis(f: np.ndarray, rate: str | None) -> np.ndarray:
    """guidefit's bins ``k fs / n`` when its exact sample rate matches the rounded increment, else ``f``."""
    if rate is None or f.size < 2:
        return f
    try:
        fs = float(rate)
    except ValueError:
        return f
    inc = float(f[1] - f[0])
    for n in (2 * (f.size - 1), 2 * f.size - 1):
        if fs > 0 and abs(fs / n - inc) <= 2 * _E13_5 * inc and abs(f[0]) <= _E13_5 * inc:
            return np.arange(f.size) * (fs / n)
    return f


def _channel_name(record: dict) -> str:
    id1 = record["id1"].split()
    derived = _derived_channel(record)
    if record["provenance"] and len(id1) == 2 and id1[1].endswith("/force") and id1[1][-7] == derived[-1]:
        return id1[1][: -len("/force")]  # guidefit's name, its axis that of the (global) direction
    return derived


def _group(frfs: list, display: str) -> list[dict]:
    runs: dict[tuple, list] = {}
    for r in frfs:
        runs.setdefault(r["ref"], []).append(r)
    out = []
    for ref, members in runs.items():
        ref_text = f"reference node {ref[0]} direction {_direction_label(ref[1])}"
        if abs(ref[1]) > 3:
            raise RecordingError(f"{display}: set {members[0]['set']}: {ref_text} is a rotation; "
                                 "the hammer force is a translation +-1, +-2 or +-3")
        first = members[0]
        seen = {}
        for r in members:
            if abs(r["rsp"][1]) not in (1, 2, 3):
                raise RecordingError(f"{display}: set {r['set']}: response direction {r['rsp'][1]}; "
                                     "an acceleration needs a translation +-1, +-2 or +-3")
            if not _same_axis(r["f"], first["f"]):
                raise RecordingError(
                    f"{display}: set {r['set']}: {r['f'].size} frequencies {r['f'][0]:g}-{r['f'][-1]:g} Hz, set "
                    f"{first['set']} of the same run ({ref_text}) {first['f'].size} frequencies "
                    f"{first['f'][0]:g}-{first['f'][-1]:g} Hz; the FRFs of a run must share one frequency axis")
            key = (r["rsp"][0], abs(r["rsp"][1]))
            if key in seen:
                raise RecordingError(f"{display}: sets {seen[key]} and {r['set']}: two FRFs of response node "
                                     f"{key[0]} direction {_direction_label(r['rsp'][1])} for {ref_text}")
            seen[key] = r["set"]
        out.append({"ref": ref, "members": members, "ref_text": ref_text})
    return out


def _coherence_of(run: dict, cohs: list, display: str) -> np.ndarray | None:
    f = run["members"][0]["f"]
    by_dof = {(c["rsp"], c["ref"]): c for c in cohs if c["ref"] == run["ref"]}
    columns = []
    for r in run["members"]:
        c = by_dof.get((r["rsp"], r["ref"]))
        if c is None:
            return None
        if not _same_axis(c["f"], f):
            raise RecordingError(f"{display}: set {c['set']}: coherence on other frequencies than its FRF "
                                 f"(set {r['set']}); expected the same axis")
        columns.append(c["values"])
    return np.column_stack(columns)


def read_uff_frfs(p: Path, display: str) -> FrfFile:
    """Read the UFF-58 FRFs of a file as an :class:`~guidefit.io.frf_files.FrfFile` (module docstring).

    Raises
    ------
    RecordingError
        pyuff missing; not UFF; no FRF; an FRF that is not response over force,
        real-valued, of an unsupported unit, with NaNs, or on another frequency
        axis than the rest of its run; two FRFs at one DOF; non-SI units:
        one line naming the file and the set.

    Examples
    --------
    >>> import os, tempfile
    >>> from guidefit.frf import frf_from_records
    >>> from guidefit.io.uff import write_frf_uff
    >>> t = np.arange(256) / 2000.0
    >>> force = np.where(t < 2e-3, np.sin(np.pi * t / 2e-3), 0.0)
    >>> acc = np.convolve(force, np.exp(-40 * t) * np.sin(2 * np.pi * 300 * t))[:256]
    >>> frf = frf_from_records(np.stack([force, acc], -1)[None], 2000.0, run="vertical",
    ...                        channel_names=("force", "acc_A_y"))
    >>> path = os.path.join(tempfile.mkdtemp(), "frf.uff")
    >>> write_frf_uff(path, frf)
    >>> got = read_uff_frfs(Path(path), path)
    >>> got.recording.runs[0].name, got.frfsets[0].channels, bool(np.allclose(got.frfsets[0].H, frf.H))
    ('vertical', ('acc_A_y',), True)
    """
    from guidefit.io.records import Recording

    frfs, cohs, geometry = _scan(display)
    nodes = geometry.nodes
    guide = next((r["windows"].get("guide") for r in frfs if r["windows"].get("guide")), None)
    points = _default_points(guide)
    notes: list[str] = [NOTE_NO_HITS]
    if geometry.rotated:
        notes.append(NOTE_FRAMES)
    frfsets, runs, used = [], [], set()
    for g in _group(frfs, display):
        members = g["members"]
        ids = {r["id2"] for r in members}
        name = ids.pop() if (all(r["provenance"] for r in members) and len(ids) == 1) else None
        if not name or name in used or "/" in name:
            name = f"ref{g['ref'][0]}{_direction_label(g['ref'][1])}"
        used.add(name)
        frf = _run_frfset(g, cohs, name, display, notes)
        code = g["ref"][1]
        if code == 0:
            excitation = infer_excitation_direction(frf)
            notes.append(f"run '{name}': reference direction 0 (unknown); the hammer direction is taken as "
                         f"{'+x' if excitation[0] else '+y'} from the responses")
        else:
            excitation = direction_vector(code)
        positions = _positions(members, frf.channels, nodes, points, name, notes)
        directions = [direction_vector(r["rsp"][1]) for r in members]
        runs.append(frf_run(display, name, frf.sample_rate_hz, excitation, frf.channels, positions, directions,
                            nodes.get(g["ref"][0]), guide))
        frfsets.append(frf)
    notes.append(f"{NOTE_FIT_STD} (UFF-58 carries no hits or jackknife sums; guidefit's frf.h5 keeps them)")
    recording = Recording(path=display, guide=guide, description="FRFs (UFF-58)", runs=tuple(runs))
    return FrfFile(display, "UFF-58 FRFs", recording, tuple(frfsets), tuple(notes))


def _number(text, kind, default):
    try:
        return kind(text) if text is not None else default
    except ValueError:
        return default


def _run_frfset(g: dict, cohs: list, name: str, display: str, notes: list):
    """The FrfSet of one reference DOF's FRF records (and coherences); what is missing goes to ``notes``."""
    from guidefit.frfset import FrfSet

    members = g["members"]
    first = members[0]
    prov = first["provenance"]
    where = f"{display}: run '{name}' (set {first['set']}...)"
    channels = [_channel_name(r) for r in members]
    if len(set(channels)) != len(channels):
        channels = [_derived_channel(r) for r in members]
    coh = _coherence_of(g, cohs, display)
    if coh is None:
        notes.append(f"run '{name}': no coherence in the file (NaN); the coherence check is not possible")
    f = _exact_axis(first["f"], prov.get("sample_rate_hz"))
    f, H, coh_checked = check_frf_arrays(where, f, np.column_stack([r["H"] for r in members]),
                                         np.ones((f.size, len(members))) if coh is None else coh, channels)
    if coh is None:
        coh_checked = np.full(H.shape, np.nan)
        coh_checked.flags.writeable = False
    converted = sorted({r["name"] for r in members if r["spec"] != SPEC_ACCELERATION})
    if converted:
        notes.append(f"run '{name}': {', '.join(converted)} FRFs converted to accelerance")
    tau_text = first["windows"].get("exp_window_tau_s")
    tau = None
    if tau_text not in (None, "none"):
        tau = _number(tau_text, float, None)
        if tau is None or not tau > 0:
            raise RecordingError(f"{where}: ID line 4 exp_window_tau_s={tau_text!r}; expected seconds > 0")
    if not first["windows"]:
        notes.append(f"run '{name}': the file does not say whether an exponential window was applied; the "
                     "damping includes any window damping of the program that computed the FRFs")
    rate = _number(prov.get("sample_rate_hz"), float, None)
    if rate is None or not rate > 0:
        rate = 2.0 * float(f[-1])
        notes.append(f"run '{name}': no sample rate in the file; taken as twice the highest frequency ({rate:g} Hz)")
    return FrfSet(run=name, frequency_hz=f, channels=tuple(channels), H=H, coherence=coh_checked,
                  estimator=prov.get("estimator", "unknown"), n_averages=_number(prov.get("n_averages"), int, 0),
                  group_sums={}, exp_window_tau_s=tau, force_window_s=None, sample_rate_hz=rate)


def _positions(members: list, channels, nodes: dict, points: dict, name: str, notes: list) -> list:
    """Each channel's position: the node's coordinates in the file, else the guide's point, else the origin."""
    positions, missing = [], []
    for channel, r in zip(channels, members):
        point = channel.split("_")[1] if channel.count("_") >= 2 else ""
        if r["rsp"][0] in nodes:
            positions.append(nodes[r["rsp"][0]])
        elif point in points:
            positions.append(np.asarray(points[point], float))
        else:
            positions.append(np.zeros(3))
            missing.append(channel)
    if missing:
        notes.append(f"run '{name}': no position for {', '.join(missing)} (no node coordinates in the file): "
                     "taken at the origin; mode labels from shapes at the sensors may be wrong")
    return positions


FORMATS = (
    FileFormat(
        name="UFF-58 FRFs",
        suffixes=UFF_SUFFIXES,
        kind="frf",
        read=read_uff_frfs,  # the writer, write_frf_uff, is declared in guidefit.io.uff
        extra="uff",
    ),
)
