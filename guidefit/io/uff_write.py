"""UFF-58 writing: guidefit's FRFs, coherences and time recordings as ASCII datasets 58.

:func:`write_frf_uff` and :func:`write_uff_recording` with their dataset
builders (ID lines, provenance, the units dataset 164, one dataset 58) and the
atomic file write. They are separate from the reader (:mod:`guidefit.io.uff`)
because writing and reading share only the codes and numbering
(:mod:`guidefit.io.uff_codes`): each can be read and changed alone. The
numbering and the fields written are described in the docstring of
:mod:`guidefit.io.uff`; both functions stay importable from there.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

import numpy as np

from guidefit.errors import GuidefitError, RecordingError
from guidefit.io.records import ACCELERATION_UNITS, FORCE_UNITS, Recording, RecordingData, RunData
from guidefit.io.uff_codes import (
    _ACC_RE,
    _AXIS_CODES,
    _ID_WIDTH,
    _MARK,
    FUNCTION_COHERENCE,
    FUNCTION_FRF,
    FUNCTION_TIME,
    REFERENCE_NODE_BASE,
    SPEC_ACCELERATION,
    SPEC_FORCE,
    SPEC_FREQUENCY,
    SPEC_GENERAL,
    SPEC_TIME,
    SPEC_UNKNOWN,
    _check_suffix,
    _first_line,
    _pyuff,
    direction_code,
    point_nodes,
)


def _id_line(text: str) -> str:
    text = " ".join(str(text).splitlines()).rstrip()
    return (text or "NONE")[:_ID_WIDTH]


def _provenance(**items) -> str:
    """ID line 5: ``guidefit key=value ...``; ``guide`` last and dropped if too long."""
    guide = items.pop("guide", None)
    text = " ".join([_MARK] + [f"{k}={v}" for k, v in items.items() if v is not None])
    if guide and len(text) + len(" guide=") + len(str(guide)) <= _ID_WIDTH:
        text += f" guide={guide}"
    return text


def _units_set(pyuff) -> dict:
    return pyuff.prepare_164(
        units_code=1,
        units_description="SI: Meter (newton)",
        temp_mode=2,
        length=1.0,
        force=1.0,
        temp=1.0,
        temp_offset=273.15,
    )


def _even_spacing(x: np.ndarray, where: str) -> int:
    if x.size < 2:
        raise RecordingError(f"{where}: {x.size} abscissa value(s); UFF-58 needs at least 2")
    if not np.all(np.isfinite(x)):
        raise RecordingError(f"{where}: abscissa has non-finite values")
    step = np.diff(x)
    return int(bool(step[0] > 0 and np.allclose(step, step[0], rtol=1e-9, atol=0.0)))


def _set58(pyuff, *, func_type, ids, rsp, ref, x, data, spacing, abscissa, ordinate, denominator,
           id4="NONE"):
    """One dataset 58 dict; ``abscissa``/``ordinate``/``denominator`` are (spec type, label, units)."""
    values = np.asarray(data)
    values = np.where(np.isfinite(values), values, 0)  # UFF has no NaN
    dset = pyuff.prepare_58(
        binary=0,
        id1=_id_line(ids[0]),
        id2=_id_line(ids[1]),
        id3="NONE",
        id4=_id_line(id4),
        id5=_id_line(ids[2]),
        func_type=func_type,
        rsp_ent_name="NONE",
        rsp_node=int(rsp[0]),
        rsp_dir=int(rsp[1]),
        ref_ent_name="NONE",
        ref_node=int(ref[0]),
        ref_dir=int(ref[1]),
        abscissa_spacing=spacing,
        abscissa_spec_data_type=abscissa[0],
        abscissa_axis_units_lab=abscissa[2],
        ordinate_spec_data_type=ordinate[0],
        ordinate_axis_units_lab=ordinate[2],
        orddenom_spec_data_type=denominator[0],
        orddenom_axis_units_lab=denominator[2],
        data=values,
        x=np.asarray(x, dtype=np.float64),
    )
    dset["abscissa_axis_lab"] = abscissa[1]
    dset["ordinate_axis_lab"] = ordinate[1]
    dset["orddenom_axis_lab"] = denominator[1]
    return dset


def _write_sets(display: str, sets: list) -> None:
    """Write ASCII datasets to ``<path>.part`` (a fresh file) and move it over ``path``."""
    pyuff = _pyuff(display)
    p = Path(display)
    tmp = p.with_name(p.name + ".part")
    try:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        pyuff.UFF(os.fspath(tmp)).write_sets(sets, mode="overwrite")
        os.replace(tmp, p)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            tmp.unlink()
        if isinstance(exc, Exception) and not isinstance(exc, GuidefitError):
            raise RecordingError(f"{display}: cannot write UFF ({_first_line(exc)})") from None
        raise


def write_frf_uff(path, frfsets, *, recording=None) -> None:
    """Write FRFs and coherences as UFF-58 (ASCII), two datasets per response channel and run.

    See the module docstring for the numbering and the fields. Without
    ``recording`` the FRF sets do not say which way the hammer and the sensors
    pointed: the response direction is then +axis of the channel name and the
    reference direction 0 (scalar, unknown).

    Parameters
    ----------
    path : str or path-like
        ``.uff`` or ``.unv``; replaced if it exists.
    frfsets : FrfSet or sequence of FrfSet
        From :func:`guidefit.frf.compute_frf`; response channels named
        ``acc_<point>_<axis>``. The i-th set is run i (reference node 100 + i).
    recording : Recording or str or path-like, optional
        The recording the FRFs came from: its runs (matched by name) give the
        reference direction (excitation direction) and the sign of each
        response direction.

    Raises
    ------
    RecordingError
        pyuff missing, a channel without point and axis, a direction not along
        an axis, a run missing from ``recording``, or the file cannot be written.

    Examples
    --------
    >>> import os, tempfile
    >>> import numpy as np
    >>> from guidefit.frf import frf_from_records
    >>> rec = np.random.default_rng(5).normal(size=(2, 8, 2))
    >>> frf = frf_from_records(rec, 8.0, channel_names=("force", "acc_A_y"), run="vertical")
    >>> path = os.path.join(tempfile.mkdtemp(), "frf.uff")
    >>> write_frf_uff(path, frf)
    >>> import pyuff
    >>> sets = pyuff.UFF(path).read_sets()
    >>> [(s["type"], s.get("func_type"), s.get("rsp_node"), s.get("ref_node")) for s in sets]
    [(164, None, None, None), (58, 4, 1, 101), (58, 6, 1, 101)]
    """
    display = os.fspath(path)
    _check_suffix(display)
    from guidefit.frfset import FrfSet

    items = [frfsets] if isinstance(frfsets, FrfSet) else list(frfsets)
    if not items:
        raise RecordingError(f"{display}: no FRF sets to write")
    runs = _runs_by_name(recording)
    recording_guide = _guide_of(recording)
    nodes = point_nodes(_point_names(display, items))
    pyuff = _pyuff(display)
    sets = [_units_set(pyuff)]
    for i, frf in enumerate(items, start=1):
        sets.extend(_run_sets(pyuff, f"{display}: run '{frf.run}'", REFERENCE_NODE_BASE + i, frf, runs,
                              recording_guide, nodes))
    _write_sets(display, sets)


def _point_names(display: str, items) -> list[str]:
    """The point of every response channel of the FRF sets (``acc_<point>_<axis>``), in order."""
    names = []
    for frf in items:
        for channel in frf.channels:
            if not _ACC_RE.match(channel):
                raise RecordingError(
                    f"{display}: run '{frf.run}': channel '{channel}' is not 'acc_<point>_<axis>'; "
                    "UFF-58 needs a point and an axis"
                )
            names.append(_ACC_RE.match(channel).group(1))
    return names


def _run_sets(pyuff, where: str, ref_node: int, frf, runs, recording_guide, nodes) -> list:
    """The UFF-58 datasets of one FRF set: an FRF and a coherence per response channel, the
    reference ``ref_node`` and, with the recording's ``runs``, the measured directions."""
    f = np.asarray(frf.frequency_hz, dtype=np.float64).reshape(-1)
    H = np.asarray(frf.H)
    coh = np.asarray(frf.coherence)
    shape = (f.size, len(frf.channels))
    if H.shape != shape or coh.shape != shape:
        raise RecordingError(
            f"{where}: H {H.shape} and coherence {coh.shape}; expected {shape} "
            "(frequencies, channels)"
        )
    spacing = _even_spacing(f, where)
    run = None
    if runs is not None:
        run = runs.get(frf.run)
        if run is None:
            raise RecordingError(
                f"{where}: the recording has no run of that name; have {', '.join(runs)}"
            )
    ref = (ref_node, 0)
    if run is not None:
        ref = (
            ref[0],
            direction_code(run.excitation_direction, None, f"{where}: excitation_direction"),
        )
    provenance = _provenance(
        estimator=frf.estimator,
        n_averages=frf.n_averages,
        sample_rate_hz=getattr(frf, "sample_rate_hz", None),
    )
    tau = getattr(frf, "exp_window_tau_s", None)
    windows = _provenance(
        exp_window_tau_s="none" if tau is None else f"{tau:.12g}",
        guide=None if recording_guide is None else recording_guide,
    )
    sets = []
    for k, channel in enumerate(frf.channels):
        point, axis = _ACC_RE.match(channel).groups()
        code = _AXIS_CODES[axis]
        if run is not None:
            if channel not in run.channel_names:
                raise RecordingError(f"{where}: channel '{channel}' not in the recording's run")
            sensor = run.channels[run.channel_names.index(channel)]
            code = direction_code(sensor.direction, axis, f"{where}: channel '{channel}'")
        common = {"rsp": (nodes[point], code), "ref": ref, "x": f, "spacing": spacing,
                  "abscissa": (SPEC_FREQUENCY, "Frequency", "Hz"), "id4": windows}
        sets.append(
            _set58(
                pyuff,
                func_type=FUNCTION_FRF,
                ids=(f"{frf.estimator} {channel}/force", frf.run, provenance),
                data=H[:, k].astype(np.complex128),
                ordinate=(SPEC_ACCELERATION, "Accelerance", "m/s^2"),
                denominator=(SPEC_FORCE, "Force", "N"),
                **common,
            )
        )
        sets.append(
            _set58(
                pyuff,
                func_type=FUNCTION_COHERENCE,
                ids=(f"coherence {channel}/force", frf.run, provenance),
                data=coh[:, k].real.astype(np.float64),
                ordinate=(SPEC_GENERAL, "Coherence", "NONE"),
                denominator=(SPEC_UNKNOWN, "NONE", "NONE"),
                **common,
            )
        )
    return sets


def _guide_of(recording) -> str | None:
    if recording is None:
        return None
    if isinstance(recording, Recording):
        return recording.guide
    from guidefit.io.registry import read_recording

    return read_recording(recording).guide


def _runs_by_name(recording) -> dict | None:
    if recording is None:
        return None
    from guidefit.io.registry import read_recording

    if not isinstance(recording, Recording):
        recording = read_recording(recording)
    return {run.name: run for run in recording.runs}


def write_uff_recording(path, recording) -> None:
    """Write a recording's time data as UFF-58 (ASCII), one dataset per channel and run.

    Each run becomes one continuous record per channel (a ``hits`` run: its
    hit records back to back), in SI units (an acceleration stored in g is
    converted to m/s^2). The force is written at the reference DOF (node
    100 + i, the excitation direction) with ordinate type 13; accelerations
    at their point's node with type 12. Positions are not written (UFF-58 has
    none). See the module docstring for the numbering and the fields.

    Parameters
    ----------
    path : str or path-like
        ``.uff`` or ``.unv``; replaced if it exists.
    recording : RecordingData, RunData or Recording
        In memory (e.g. from :func:`guidefit.simulate.simulate`) or read from a file.

    Raises
    ------
    RecordingError
        pyuff missing, a direction not along an axis, a run without data, or
        the file cannot be written.

    Examples
    --------
    >>> import os, tempfile
    >>> import numpy as np
    >>> from guidefit.io import RunData
    >>> from guidefit.io.uff import read_uff_recording
    >>> run = RunData("vertical", 1000.0, [0, -1, 0], ["force", "acc_A_y"], ["N", "m/s^2"],
    ...               [[0, 0, 0], [0.03, 0, 0.045]], [[0, -1, 0], [0, 1, 0]],
    ...               data=np.array([[0.0, 1.0], [2.0, 3.0], [4.0, 5.0]]))
    >>> path = os.path.join(tempfile.mkdtemp(), "rec.uff")
    >>> write_uff_recording(path, run)
    >>> back = read_uff_recording(path).runs[0]
    >>> back.name, back.sample_rate_hz, back.channel_names, back.read_block().tolist()
    ('vertical', 1000.0, ('force', 'acc_A_y'), [[0.0, 1.0], [2.0, 3.0], [4.0, 5.0]])
    """
    display = os.fspath(path)
    _check_suffix(display)
    if isinstance(recording, Recording):
        recording = recording.to_data()
    elif isinstance(recording, RunData):
        recording = RecordingData((recording,))
    if not isinstance(recording, RecordingData):
        raise TypeError(
            f"recording: expected RecordingData, RunData or Recording, got {type(recording).__name__}"
        )
    names = [
        _ACC_RE.match(name).group(1)
        for run in recording.runs
        for name in run.channel_names
        if name != "force"
    ]
    nodes = point_nodes(names)
    pyuff = _pyuff(display)
    sets = [_units_set(pyuff)]
    time = (SPEC_TIME, "Time", "s")
    for i, run in enumerate(recording.runs, start=1):
        where = f"{display}: run '{run.name}'"
        if run.data is None:
            raise RecordingError(f"{where}: no data to write")
        samples = np.asarray(run.data, dtype=np.float64).reshape(-1, run.n_channels)
        scale = np.array(
            [
                FORCE_UNITS[u] if name == "force" else ACCELERATION_UNITS[u]
                for name, u in zip(run.channel_names, run.units)
            ]
        )
        samples = samples * scale
        x = np.arange(samples.shape[0]) / run.sample_rate_hz
        _even_spacing(x, where)
        ref = (
            REFERENCE_NODE_BASE + i,
            direction_code(run.excitation_direction, None, f"{where}: excitation_direction"),
        )
        provenance = _provenance(sample_rate_hz=repr(run.sample_rate_hz), guide=recording.guide)
        for c, name in enumerate(run.channel_names):
            if name == "force":
                rsp, ordinate = ref, (SPEC_FORCE, "Force", "N")
            else:
                point, axis = _ACC_RE.match(name).groups()
                code = direction_code(run.directions[c], axis, f"{where}: channel '{name}'")
                rsp, ordinate = (nodes[point], code), (SPEC_ACCELERATION, "Acceleration", "m/s^2")
            sets.append(
                _set58(
                    pyuff,
                    func_type=FUNCTION_TIME,
                    ids=(name, run.name, provenance),
                    rsp=rsp,
                    ref=ref,
                    x=x,
                    data=samples[:, c],
                    spacing=1,
                    abscissa=time,
                    ordinate=ordinate,
                    denominator=(SPEC_UNKNOWN, "NONE", "NONE"),
                )
            )
    _write_sets(display, sets)
