"""FRF files: guidefit's own ``frf.csv`` and ``frf.h5`` written and read; FRF files as input.

The layouts are documented with their writers here, :func:`write_frf_csv`
and :func:`write_frf_h5` (importable from :mod:`guidefit.frf` as well, their
documented old home); :func:`read_frf_h5_file` is the one frf.h5 reader
(:func:`read_frf_h5` gives its FrfSets alone). This module declares them to the registry, so :func:`guidefit.io.write_frfs`
picks the writer by suffix. ``frf.h5`` written through the registry (``guidefit
frf rec.h5 --out frf.h5``) also carries what the recording knew about each run
(optional attributes, format version unchanged)::

    /frf                         attrs guide (str), source_file (str)
    /frf/<run>                   attrs excitation_direction (3,), excitation_position_m (3,) NaN if unknown,
                                       positions_m (R, 3), directions (R, 3): the columns of H

FRFs as input
-------------
:func:`read_input` opens what ``guidefit identify`` / ``explain`` / ``report``
are given: a recording (time data, :func:`guidefit.io.read_recording`) or an
:class:`FrfFile`, i.e. FRFs measured elsewhere or by ``guidefit frf``:

* ``frf.h5`` (guidefit's own, :func:`read_frf_h5_file`): the FrfSets exactly
  as written, with their jackknife group sums when the file has them;
* UFF-58 function type 4 records (:mod:`guidefit.io.uff_frf`), with the
  coherences (type 6) at the same DOFs where present.

An :class:`FrfFile` holds one ``FrfSet`` per run and a metadata-only
:class:`~guidefit.io.records.Recording` (runs with the force and response
channels, their positions and directions, the excitation direction, the sample
rate; no samples: reading one is a ``RecordingError``), so the modal stage of
:mod:`guidefit.identify` runs on it as on FRFs computed from a recording.
``notes`` say what the file does not carry (hit checks are never possible).

guidefit's ``frf.csv`` is refused as input with one line: it carries no
excitation direction, no sensor geometry, no number of averages and no
exponential-window time constant (so the damping could not be corrected).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from guidefit.errors import RecordingError
from guidefit.frfset import ESTIMATORS, FrfSet
from guidefit.io.registry import FileFormat

__all__ = [
    "FrfFile",
    "frf_run",
    "holds_frfs",
    "infer_excitation_direction",
    "read_frf_file",
    "read_frf_h5",
    "read_frf_h5_file",
    "read_input",
    "read_metadata",
    "write_frf_csv",
    "write_frf_csv_file",
    "write_frf_h5",
    "write_frf_h5_file",
]

FRF_H5_FORMAT = "guidefit-frf"
MIN_FRF_BINS = 8
"""Fewer frequency bins than this in an FRF is refused."""

NOTE_NO_HITS = "no hit checks were possible: the input holds FRFs, not time data"
NOTE_FIT_STD = ("the std is the modal fit's own standard error: hit-to-hit scatter is not included, so it can be "
                "several times too small (benchmarks/bench_frf_input.py: about 2.2-2.4x for the horizontal mode)")


@dataclass(frozen=True, eq=False)
class FrfFile:
    """FRFs read from a file, one ``FrfSet`` per run, with their run and channel metadata.

    Attributes
    ----------
    path : str
        The path as given.
    format : str
        The :class:`~guidefit.io.registry.FileFormat` name.
    recording : guidefit.io.records.Recording
        Metadata only (layout ``"frf"``, no samples): per run the force and
        response channels with positions and directions, the excitation
        direction and the sample rate.
    frfsets : tuple of guidefit.frf.FrfSet
        In the order of ``recording.runs`` (same run names); accelerance in
        (m/s^2)/N.
    notes : tuple of str
        What the file does not carry, one sentence each (shown as warnings).
    """

    path: str
    format: str
    recording: object
    frfsets: tuple
    notes: tuple = ()

    @property
    def guide(self) -> str | None:
        """The guide the file names (None if it names none)."""
        return self.recording.guide

    def has_group_sums(self) -> bool:
        """Every run carries jackknife group sums (>= 3 groups): hit-to-hit scatter is available."""
        return all(getattr(f, "n_groups", 0) >= 3 for f in self.frfsets)


class _NoSamples:
    """The source of a metadata-only run: an FRF file holds no time data."""

    dtype = np.dtype(np.float64)

    def __init__(self, display: str):
        self.display = display

    def read(self, index):
        raise RecordingError(f"{self.display}: holds FRFs, not time data; no samples to read")


# ------------------------------------------------------------------ metadata


def infer_excitation_direction(frf) -> np.ndarray:
    """+x or +y: the axis whose response channels carry most of the FRF energy.

    For files that do not say which way the hammer pointed. Only the sign
    convention of the shapes and which run is preferred for a mode depend on it.

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> frf = SimpleNamespace(channels=("acc_A_x", "acc_A_y"), H=np.array([[1.0, 3.0], [1.0, 2.0]]))
    >>> infer_excitation_direction(frf).tolist()
    [0.0, 1.0, 0.0]
    """
    magnitude = np.abs(np.asarray(frf.H))
    top = float(magnitude.max(initial=0.0))
    energy = np.sum((magnitude / top) ** 2, axis=0) if 0 < top < math.inf else np.sum(magnitude, axis=0)
    by_axis = {"x": 0.0, "y": 0.0}
    for name, e in zip(frf.channels, energy):
        axis = name.rsplit("_", 1)[-1]
        if axis in by_axis:
            by_axis[axis] += float(e)
    vec = np.zeros(3)
    vec[0 if by_axis["x"] > by_axis["y"] else 1] = 1.0
    return vec


def frf_run(display: str, name: str, sample_rate_hz: float, excitation_direction, channels,
            positions_m=None, directions=None, excitation_position_m=None, guide=None):
    """A metadata-only :class:`~guidefit.io.records.Run` for the FRFs of ``channels``.

    ``positions_m`` / ``directions`` (R, 3) of the response channels; None: the
    guide's default points and +axis of each name
    (:func:`guidefit.io.geometry.default_channel_geometry`). The force channel
    sits at the hit point (origin if unknown), along the excitation direction.

    Raises
    ------
    RecordingError
        A channel name without point and axis, a direction not a unit vector, ...
        (one line naming the file and the run).
    """
    from guidefit.io.geometry import default_channel_geometry
    from guidefit.io.records import Run, RunData

    names = ["force", *channels]
    where = f"{display}: run '{name}'"
    try:
        if positions_m is None or directions is None:
            pos, dirs = default_channel_geometry(names, excitation_direction, excitation_position_m,
                                                 guide=_known_guide(guide))
            positions_m = pos[1:] if positions_m is None else positions_m
            directions = dirs[1:] if directions is None else directions
        hit = np.zeros(3) if excitation_position_m is None else np.asarray(excitation_position_m, float)
        header = RunData(name, sample_rate_hz, excitation_direction, names,
                         ["N"] + ["m/s^2"] * len(channels),
                         np.vstack([hit, np.asarray(positions_m, float).reshape(-1, 3)]),
                         np.vstack([np.asarray(excitation_direction, float),
                                    np.asarray(directions, float).reshape(-1, 3)]),
                         layout="signals", excitation_position_m=excitation_position_m)
    except RecordingError as exc:
        text = str(exc)
        raise RecordingError(text if text.startswith(display) else f"{where}: {text}") from None
    run = Run.from_header(header, _NoSamples(display), n_samples=0, file=display)
    # without a hit point the force channel only sits at the origin: the hit point is unknown, not there
    return replace(run, layout="frf", force_position_known=excitation_position_m is not None)


def _known_guide(guide):
    """The guide name if this installation knows it, else None (MRB35's points)."""
    if not guide:
        return None
    from guidefit.errors import GuidefitError
    from guidefit.io.geometry import default_points

    try:
        default_points(guide)
    except GuidefitError:
        return None
    return guide


def check_frf_arrays(where: str, frequency_hz, H, coherence, channels) -> tuple:
    """Validated (frequency_hz, H, coherence) of one run: shapes, finite values, increasing axis.

    Raises
    ------
    RecordingError
        One line naming ``where`` and what is wrong.

    Examples
    --------
    >>> f = np.arange(10.0); H = np.ones((10, 1), complex); H[3, 0] = np.nan
    >>> check_frf_arrays("x.h5: run 'v'", f, H, np.ones((10, 1)), ("acc_A_y",))
    Traceback (most recent call last):
    ...
    guidefit.errors.RecordingError: x.h5: run 'v': H of 'acc_A_y' has 1 non-finite value(s) (first at 3 Hz); an FRF file must hold numbers
    """
    f = np.asarray(frequency_hz)
    if f.ndim != 1 or not np.issubdtype(f.dtype, np.number) or np.iscomplexobj(f):
        raise RecordingError(f"{where}: frequency_hz has shape {f.shape} ({f.dtype}); expected (F,) real")
    f = f.astype(np.float64)
    n_resp = len(channels)
    H = np.asarray(H)
    if H.shape != (f.size, n_resp) or not np.issubdtype(H.dtype, np.number):
        raise RecordingError(f"{where}: H has shape {H.shape}; expected ({f.size}, {n_resp}) "
                             "(frequencies, response channels)")
    if not np.iscomplexobj(H):
        raise RecordingError(f"{where}: H is real ({H.dtype}); an FRF is complex (magnitude and phase)")
    H = H.astype(np.complex128)
    coh = np.asarray(coherence)
    if coh.shape != H.shape or np.iscomplexobj(coh) or not np.issubdtype(coh.dtype, np.number):
        raise RecordingError(f"{where}: coherence has shape {coh.shape} ({coh.dtype}); expected real {H.shape}")
    coh = coh.astype(np.float64)
    if f.size < MIN_FRF_BINS:
        raise RecordingError(f"{where}: {f.size} frequencies; an FRF needs at least {MIN_FRF_BINS}")
    if not np.all(np.isfinite(f)) or f[0] < 0 or not np.all(np.diff(f) > 0):
        raise RecordingError(f"{where}: frequency_hz is not finite, non-negative and increasing")
    for what, values in (("H", H), ("coherence", coh)):
        bad = ~np.isfinite(values)
        if np.any(bad):
            col = int(np.nonzero(bad.any(axis=0))[0][0])
            first = float(f[np.nonzero(bad[:, col])[0][0]])
            raise RecordingError(f"{where}: {what} of '{channels[col]}' has {int(bad[:, col].sum())} "
                                 f"non-finite value(s) (first at {first:g} Hz); an FRF file must hold numbers")
    if np.any((coh < -1e-9) | (coh > 1 + 1e-9)):
        raise RecordingError(f"{where}: coherence outside [0, 1] ({coh.min():g} to {coh.max():g})")
    if not np.any(H):
        raise RecordingError(f"{where}: H is zero everywhere")
    return _frozen(f), _frozen(H), _frozen(np.clip(coh, 0.0, 1.0))


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.array(a)
    a.flags.writeable = False
    return a


# ------------------------------------------------------------------ frf.csv / frf.h5 writers


def _as_list(frfsets) -> list:
    items = [frfsets] if isinstance(frfsets, FrfSet) else list(frfsets)
    if not items:
        raise ValueError("frfsets is empty; need at least one FrfSet")
    return items


def write_frf_csv(path, frfsets) -> None:
    """Write FRFs as CSV: ``frequency_hz``, then ``<channel>_re``, ``_im``, ``_coherence``.

    One row per frequency bin and run. With several runs a first column ``run``
    is added and the rows of each run follow one another; a channel missing
    from a run leaves its cells empty. Numbers are written in Python's shortest
    round-trip form (``repr``: lossless; ``nan`` where undefined).

    Parameters
    ----------
    path : str or path-like
        Output file.
    frfsets : FrfSet or sequence of FrfSet

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> from guidefit.frf import frf_from_records
    >>> rec = np.random.default_rng(5).normal(size=(2, 8, 2))
    >>> frf = frf_from_records(rec, 8.0, channel_names=("force", "acc_A_y"))
    >>> path = os.path.join(tempfile.mkdtemp(), "frf.csv")
    >>> write_frf_csv(path, frf)
    >>> open(path).readline().strip()
    'frequency_hz,acc_A_y_re,acc_A_y_im,acc_A_y_coherence'
    """
    items = _as_list(frfsets)
    channels: list[str] = []
    for frf in items:
        channels += [c for c in frf.channels if c not in channels]
    header = ["frequency_hz"] + [f"{c}_{part}" for c in channels
                                 for part in ("re", "im", "coherence")]
    multi = len(items) > 1
    if multi:
        header = ["run"] + header

    def fmt(a) -> list[str]:
        return [repr(v) for v in np.asarray(a, dtype=float).tolist()]

    with open(path, "w", encoding="utf-8", newline="") as fh:
        fh.write(",".join(header) + "\n")
        for frf in items:
            F = len(frf.frequency_hz)
            cols = [fmt(frf.frequency_hz)]
            for c in channels:
                if c in frf.channels:
                    k = frf.channels.index(c)
                    cols += [fmt(frf.H[:, k].real), fmt(frf.H[:, k].imag),
                             fmt(frf.coherence[:, k])]
                else:
                    cols += [[""] * F] * 3
            if multi:
                cols = [[_csv_field(frf.run)] * F] + cols
            fh.writelines(",".join(row) + "\n" for row in zip(*cols))


def _csv_field(text: str) -> str:
    if any(ch in text for ch in ',"\n'):
        return '"' + text.replace('"', '""') + '"'
    return text


def _nan_if_none(value):
    return np.nan if value is None else float(value)


def write_frf_h5(path, frfsets, include_group_sums: bool = True) -> None:
    """Write FRFs to HDF5, one group ``/frf/<run>`` per FrfSet.

    Layout::

        /frf                         attrs format="guidefit-frf", format_version=1
        /frf/<run>/frequency_hz      (F,) float64, Hz
        /frf/<run>/H                 (F, R) complex128, (m/s^2)/N
        /frf/<run>/coherence         (F, R) float64
        /frf/<run>/group_sums/Sff    (G, F)      (optional)
        /frf/<run>/group_sums/Sxx    (G, F, R)
        /frf/<run>/group_sums/Sfx    (G, F, R) complex128
        /frf/<run>/group_sums/n_hits (G,)

    Attributes of ``/frf/<run>``: ``estimator``, ``channels`` (str array, the
    columns of H), ``n_averages``, ``exp_window_tau_s``, ``force_window_s``,
    ``force_taper_s``, ``trigger_s``, ``sample_rate_hz`` (NaN where not
    applicable, e.g. no exponential window), ``fft_precision`` (absent in
    files written before it existed: read as ``"double"``), and
    ``record_samples`` only for a run whose windowed records (of that many
    samples) were zero-padded to a common frequency grid with longer runs
    (:func:`guidefit.frf.common_grid`).

    Parameters
    ----------
    path : str or path-like
        Output file (overwritten).
    frfsets : FrfSet or sequence of FrfSet
        Run names must be distinct and contain no ``/``.
    include_group_sums : bool
        Also store the jackknife group sums (O(G F R) numbers).

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> from guidefit.frf import frf_from_records
    >>> rec = np.random.default_rng(6).normal(size=(3, 16, 3))
    >>> frf = frf_from_records(rec, 16.0, run="vertical")
    >>> path = os.path.join(tempfile.mkdtemp(), "frf.h5")
    >>> write_frf_h5(path, [frf])
    >>> back, = read_frf_h5(path)
    >>> back.run, back.channels, bool(np.array_equal(back.H, frf.H))
    ('vertical', ('ch1', 'ch2'), True)
    """
    import h5py

    items = _as_list(frfsets)
    names = [frf.run for frf in items]
    for name in names:
        if "/" in name or not name or names.count(name) > 1:
            raise ValueError(f"run name {name!r} not usable as an HDF5 group (empty, '/' or repeated)")
    with h5py.File(path, "w") as f:
        root = f.create_group("frf")
        root.attrs["format"] = "guidefit-frf"
        root.attrs["format_version"] = 1
        for frf in items:
            g = root.create_group(frf.run)
            g.create_dataset("frequency_hz", data=np.asarray(frf.frequency_hz, dtype=float))
            g.create_dataset("H", data=np.asarray(frf.H, dtype=complex))
            g.create_dataset("coherence", data=np.asarray(frf.coherence, dtype=float))
            g.attrs["estimator"] = frf.estimator
            g.attrs["channels"] = np.array(frf.channels, dtype=h5py.string_dtype())
            g.attrs["n_averages"] = int(frf.n_averages)
            g.attrs["fft_precision"] = frf.fft_precision
            for key in ("exp_window_tau_s", "force_window_s", "force_taper_s", "trigger_s",
                        "sample_rate_hz"):
                g.attrs[key] = _nan_if_none(getattr(frf, key))
            if frf.record_samples is not None:
                g.attrs["record_samples"] = int(frf.record_samples)
            if include_group_sums and frf.group_sums:
                s = g.create_group("group_sums")
                for key in ("Sff", "Sxx", "Sfx", "n_hits"):
                    s.create_dataset(key, data=np.asarray(frf.group_sums[key]))




def write_frf_csv_file(path, frfsets, *, recording=None) -> None:
    """:func:`write_frf_csv` (``recording`` is not used by CSV), written whole."""
    from guidefit.io._checks import _atomic

    _atomic(Path(os.fspath(path)), lambda tmp: write_frf_csv(tmp, frfsets))


def write_frf_h5_file(path, frfsets, *, recording=None) -> None:
    """:func:`write_frf_h5`, plus the recording's geometry of each run (module docstring).

    Written whole (a temporary file renamed when complete); the HDF5 image is
    built in memory and written with one plain write, because a disk write
    failing inside libhdf5 (full disk, file-size limit) leaves h5py objects
    that crash the interpreter when freed. ``recording`` (a
    :class:`~guidefit.io.records.Recording` or a path) gives each run's
    excitation direction and hit point and the response channels' positions
    and directions; without it the file holds the FRFs only.
    """
    from guidefit.io._checks import _atomic

    runs = _runs_of(recording)

    def write(tmp: Path) -> None:
        import io

        image = io.BytesIO()
        write_frf_h5(image, frfsets)
        if runs is not None:
            _add_geometry(image, runs)
        with open(tmp, "wb") as out:
            out.write(image.getbuffer())

    _atomic(Path(os.fspath(path)), write)


def _add_geometry(image, runs: dict) -> None:
    """Each run's excitation and the sensors' positions and directions as attributes of its group."""
    import h5py

    with h5py.File(image, "r+") as f:
        root = f["frf"]
        if runs["guide"]:
            root.attrs["guide"] = runs["guide"]
        root.attrs["source_file"] = runs["file"]
        for name, g in root.items():
            run = runs["runs"].get(name)
            if run is None:
                continue
            by_name = {ch.name: ch for ch in run.channels}
            names = [c.decode() if isinstance(c, bytes) else str(c) for c in g.attrs["channels"]]
            if not all(n in by_name for n in names):
                continue
            g.attrs["excitation_direction"] = np.asarray(run.excitation_direction, float)
            hit = run.excitation_position_m
            g.attrs["excitation_position_m"] = np.full(3, np.nan) if hit is None else np.asarray(hit, float)
            g.attrs["positions_m"] = np.array([by_name[n].position_m for n in names], float)
            g.attrs["directions"] = np.array([by_name[n].direction for n in names], float)


def _runs_of(recording) -> dict | None:
    if recording is None:
        return None
    from guidefit.io.records import Recording
    from guidefit.io.registry import read_recording

    if not isinstance(recording, Recording):
        recording = read_recording(recording)
    return {"guide": recording.guide, "file": os.path.basename(recording.path),
            "runs": {run.name: run for run in recording.runs}}


# ------------------------------------------------------------------ frf.h5 reader


def read_frf_h5_file(p: Path, display: str) -> FrfFile:
    """Read guidefit's ``frf.h5`` as an :class:`FrfFile` (in a time-limited child where possible).

    Runs without stored geometry get the guide's default points, +axis sensor
    directions and an excitation direction inferred from the responses
    (:func:`infer_excitation_direction`), each said in ``notes``.

    Raises
    ------
    RecordingError
        Not HDF5, no ``/frf`` group of format ``guidefit-frf``, a run without
        ``H``/``coherence``/``frequency_hz`` or with mismatched shapes,
        non-finite values, links or storage outside the file's folder: one line.

    Examples
    --------
    >>> import tempfile
    >>> from guidefit.frf import frf_from_records
    >>> t = np.arange(256) / 2000.0
    >>> force = np.where(t < 2e-3, np.sin(np.pi * t / 2e-3), 0.0)
    >>> acc = np.convolve(force, np.exp(-40 * t) * np.sin(2 * np.pi * 300 * t))[:256]
    >>> frf = frf_from_records(np.stack([force, acc], -1)[None], 2000.0, run="vertical",
    ...                        channel_names=("force", "acc_A_y"))
    >>> path = Path(tempfile.mkdtemp()) / "frf.h5"
    >>> write_frf_h5_file(path, [frf])
    >>> got = read_frf_h5_file(path, str(path))
    >>> got.recording.runs[0].name, got.frfsets[0].channels, bool(np.allclose(got.frfsets[0].H, frf.H))
    ('vertical', ('acc_A_y',), True)
    """
    from guidefit.io.watchdog import read_guarded

    return read_guarded(_read_frf_h5, p, display, "FRF file")


def read_frf_h5(path) -> tuple:
    """The FrfSets of guidefit's ``frf.h5`` (layout at :func:`write_frf_h5`), one per run.

    The one frf.h5 reader of :func:`read_frf_h5_file` (in a time-limited child
    where possible), without the run metadata and notes it adds: the FRFs are
    checked the same way, and any channel names are taken.

    Raises
    ------
    RecordingError
        The file is not guidefit's frf.h5 or holds a malformed run: one line naming it.

    Examples
    --------
    See :func:`write_frf_h5`.
    """
    from guidefit.io.watchdog import read_guarded

    display = os.fspath(path)
    return read_guarded(_read_frf_h5_sets, Path(display), display, "FRF file")


def _read_frf_h5_sets(p: Path, display: str) -> tuple:
    """The checked FrfSets of an frf.h5 alone (no run metadata, so any channel names)."""
    return _read_frf_h5(p, display, metadata=False)


def _read_frf_h5(p: Path, display: str, metadata: bool = True):
    """The one frf.h5 reader: an FrfFile, or with ``metadata=False`` the tuple of its FrfSets."""
    import h5py

    from guidefit.io.hdf5 import _h5_open_error

    try:
        f = h5py.File(p, "r")
    except OSError as exc:
        raise _h5_open_error(p, display, exc) from None
    with f:
        if "frf" not in f or not isinstance(f["frf"], h5py.Group):
            raise RecordingError(f"{display}: no group '/frf'; expected guidefit FRFs "
                                 "(written by 'guidefit frf ... --out frf.h5')")
        root = f["frf"]
        fmt = _text(root.attrs.get("format"))
        if fmt != FRF_H5_FORMAT:
            raise RecordingError(f"{display}: /frf attribute 'format' is {fmt!r}; expected '{FRF_H5_FORMAT}'")
        guide = _text(root.attrs.get("guide")) or None
        names = list(root.keys())
        if not names:
            raise RecordingError(f"{display}: /frf holds no run")
        if not metadata:
            return tuple(_read_h5_frfset(display, root, name)[0] for name in names)
        frfsets, runs, notes = [], [], []
        for name in names:
            frf, run, run_notes = _read_h5_run(display, root, name, guide)
            frfsets.append(frf)
            runs.append(run)
            notes += run_notes
    from guidefit.io.records import Recording

    if not all(s.n_groups >= 3 for s in frfsets):
        notes.append(f"{NOTE_FIT_STD} (the file has no jackknife group sums of >= 3 groups)")
    recording = Recording(path=display, guide=guide, description="FRFs (guidefit frf.h5)", runs=tuple(runs))
    return FrfFile(display, "guidefit FRFs, HDF5", recording, tuple(frfsets), (NOTE_NO_HITS, *notes))


def _text(value) -> str:
    if value is None:
        return ""
    if isinstance(value, bytes):
        return value.decode("utf-8", "replace")
    if isinstance(value, np.ndarray) and value.size == 1:
        return _text(value.reshape(-1)[0])
    return str(value)


def _dataset(g, key: str, where: str):
    import h5py

    from guidefit.io.hdf5 import _check_storage, _get_checked

    if key not in g:
        raise RecordingError(f"{where}: dataset '{key}' missing")
    ds = _get_checked(g, key, f"{where}: '{key}'")
    if not isinstance(ds, h5py.Dataset):
        raise RecordingError(f"{where}: '{key}' is not a dataset")
    _check_storage(ds, Path(g.file.filename), f"{where}: '{key}'")
    return ds[()]


def _optional_float(attrs, key: str, where: str = "") -> float | None:
    """A number attribute, None when absent or NaN (what the writer stores for "none")."""
    if key not in attrs:
        return None
    value = np.asarray(attrs[key])
    try:
        if value.size != 1:
            raise ValueError
        v = float(value.reshape(-1)[0])
    except (TypeError, ValueError):  # text, or several numbers where one belongs: never the first of them
        raise RecordingError(f"{where or 'frf file'}: attribute '{key}' is not a number") from None
    return None if math.isnan(v) else v


def _optional_seconds(attrs, key: str, where: str) -> float | None:
    """A time constant or width (s): absent/NaN is None, else it must be finite and > 0 (the UFF reader's rule:
    an exponential window of tau <= 0 would make every damping correction wrong)."""
    v = _optional_float(attrs, key, where)
    if v is not None and not (math.isfinite(v) and v > 0):
        raise RecordingError(f"{where}: attribute '{key}' = {v!r}; expected seconds > 0 (or absent: none)")
    return v


def _read_h5_run(display: str, root, name: str, guide):
    """The FrfSet of run ``name`` and its metadata-only Run (:func:`_h5_run_metadata`), with notes."""
    frf, notes = _read_h5_frfset(display, root, name)
    run, more = _h5_run_metadata(display, root[name].attrs, frf, guide)
    return frf, run, notes + more


def _read_h5_frfset(display: str, root, name: str):
    """The checked FrfSet of run ``name`` of ``/frf`` and the notes on what the file lacked."""
    import h5py

    from guidefit.io.hdf5 import _get_checked

    where = f"{display}: run '{name}'"
    g = _get_checked(root, name, where)  # links checked before they are followed
    if not isinstance(g, h5py.Group):
        raise RecordingError(f"{where}: /frf/{name} is not a group")
    a = g.attrs
    if "channels" not in a:
        raise RecordingError(f"{where}: attribute 'channels' missing (the response channel of each column of H)")
    channels = tuple(_text(c) for c in np.asarray(a["channels"]).reshape(-1))
    if "force" in channels or len(set(channels)) != len(channels) or not channels:
        raise RecordingError(f"{where}: channels {list(channels)}; expected distinct response channels "
                             "(the force is the reference of every FRF)")
    f, H, coh = check_frf_arrays(where, _dataset(g, "frequency_hz", where), _dataset(g, "H", where),
                                 _dataset(g, "coherence", where), channels)
    sums = {}
    if "group_sums" in g:
        holder = _get_checked(g, "group_sums", f"{where}: group_sums")
        if not isinstance(holder, h5py.Group):
            raise RecordingError(f"{where}: group_sums is not a group")
        sums = {k: _dataset(holder, k, f"{where}: group_sums") for k in ("Sff", "Sxx", "Sfx", "n_hits")}
        G = np.asarray(sums["n_hits"]).shape[0]
        want = {"Sff": (G, f.size), "Sxx": (G, f.size, len(channels)), "Sfx": (G, f.size, len(channels))}
        for k, shape in want.items():
            if np.shape(sums[k]) != shape or not np.all(np.isfinite(sums[k])):
                raise RecordingError(f"{where}: group_sums/{k} has shape {np.shape(sums[k])} or non-finite "
                                     f"values; expected finite {shape}")
    notes = []
    estimator = _text(a.get("estimator"))
    if not estimator:
        estimator = "H1"
        notes.append(f"run '{name}': no estimator in the file; its FRFs taken as H1")
    elif estimator not in ESTIMATORS:
        raise RecordingError(f"{where}: estimator {estimator!r} is not one of H1, H2, Hv")
    n_avg = _count(a.get("n_averages", 0), f"{where}: n_averages")
    rate = _optional_float(a, "sample_rate_hz", where)
    if rate is None:
        rate = 2.0 * float(f[-1])
        notes.append(f"run '{name}': no sample rate in the file; taken as twice the highest frequency ({rate:g} Hz)")
    elif not (math.isfinite(rate) and rate > 2.0 * float(f[-1]) * (1 - 1e-9)):
        raise RecordingError(f"{where}: sample_rate_hz {rate:g} is not a rate above twice the highest "
                             f"frequency ({f[-1]:g} Hz)")
    frf = FrfSet(run=name, frequency_hz=f, channels=channels, H=H, coherence=coh, estimator=estimator,
                 n_averages=n_avg, group_sums=sums, exp_window_tau_s=_optional_seconds(a, "exp_window_tau_s", where),
                 force_window_s=_optional_seconds(a, "force_window_s", where),
                 force_taper_s=_optional_float(a, "force_taper_s", where),
                 trigger_s=_optional_float(a, "trigger_s", where),
                 sample_rate_hz=rate, fft_precision=_text(a.get("fft_precision")) or "double",
                 record_samples=_record_samples(a, f, rate, where))
    return frf, notes


def _record_samples(a, f, rate: float, where: str) -> int | None:
    """``record_samples`` of a zero-padded run (None when absent): a count no longer than ``fs / df``."""
    if "record_samples" not in a:
        return None
    n = _count(a["record_samples"], f"{where}: record_samples")
    if not 2 <= n <= rate / float(f[1] - f[0]) * (1 + 1e-9):
        raise RecordingError(f"{where}: record_samples {n} is not a record length of at least 2 samples that "
                             f"fits the bins ({rate / float(f[1] - f[0]):.0f} samples at most)")
    return n


def _h5_run_metadata(display: str, a, frf, guide):
    """The metadata-only Run of ``frf`` from its group's attributes ``a`` (geometry stored or defaulted)."""
    name, channels, notes = frf.run, frf.channels, []
    where = f"{display}: run '{name}'"
    geometry = {}
    for key, shape in (("excitation_direction", (3,)), ("positions_m", (len(channels), 3)),
                       ("directions", (len(channels), 3)), ("excitation_position_m", (3,))):
        if key in a:
            value = np.asarray(a[key], dtype=float)
            if value.shape != shape:
                raise RecordingError(f"{where}: attribute '{key}' has shape {value.shape}; expected {shape}")
            geometry[key] = value
    hit = geometry.get("excitation_position_m")
    if hit is not None and not np.all(np.isfinite(hit)):
        hit = None
    excitation = geometry.get("excitation_direction")
    if excitation is None:
        excitation = infer_excitation_direction(frf)
        notes.append(f"run '{name}': the file does not say the hammer direction; taken as "
                     f"{'+x' if excitation[0] else '+y'} from the responses")
    if "positions_m" not in geometry or "directions" not in geometry:
        notes.append(f"run '{name}': no sensor geometry in the file; the guide's default points and +axis "
                     "directions from the channel names")
    run = frf_run(display, name, frf.sample_rate_hz, excitation, channels, geometry.get("positions_m"),
                  geometry.get("directions"), hit, guide)
    return run, notes


# ------------------------------------------------------------------ input dispatch


def _csv_is_frf(p: Path) -> bool:
    with open(p, encoding="utf-8", errors="replace") as fh:
        for line in fh:
            if line.strip() and not line.lstrip().startswith("#"):
                head = [c.strip().strip('"').lower() for c in line.split(",")[:2]]
                return head[0] == "frequency_hz" or head[:2] == ["run", "frequency_hz"]
    return False


def _h5_has_frf_group(p: Path, display: str) -> bool:
    import h5py

    try:
        with h5py.File(p, "r") as f:
            link = f.get("frf", getlink=True)
            return isinstance(link, h5py.HardLink) and f.get("runs", getlink=True) is None
    except (OSError, RuntimeError, ValueError, KeyError):
        return False


def _h5_is_frf(p: Path) -> bool:
    """``/frf`` and no ``/runs``; read in the time-limited child where possible (a damaged file can hang HDF5)."""
    from guidefit.io.watchdog import call_guarded

    try:
        return call_guarded(_h5_has_frf_group, p, os.fspath(p))
    except RecordingError:
        return False  # the recording reader says what is wrong with the file


def holds_frfs(path) -> bool:
    """Whether ``path`` is an FRF file (frf.h5, frf.csv, UFF-58 with FRFs and no time data).

    Decided from the content, not the suffix alone (``.h5``, ``.csv`` and
    ``.uff`` may hold either); a file that cannot be opened is not an FRF file
    (its recording reader then says why).

    Examples
    --------
    >>> holds_frfs("no_such_file.h5")
    False
    """
    display = os.fspath(path)
    p = Path(display)
    if not p.is_file() or p.stat().st_size == 0:
        return False
    suffix = p.suffix.lower()
    if suffix == ".csv":
        return _csv_is_frf(p)
    if suffix in (".h5", ".hdf5"):
        return _h5_is_frf(p)
    if suffix in (".uff", ".unv"):
        from guidefit.io.uff import uff_function_types

        try:
            types = uff_function_types(display)
        except RecordingError:
            return False
        return 4 in types and 1 not in types
    return False


def _count(value, where: str) -> int:
    """A non-negative whole number of an attribute (n_averages), or one RecordingError."""
    v = np.asarray(value).reshape(-1)
    try:
        x = float(v[0]) if v.size == 1 else math.nan
    except (TypeError, ValueError):
        x = math.nan
    if not (math.isfinite(x) and x >= 0 and x == int(x)):
        raise RecordingError(f"{where}: {v.tolist() if v.size < 5 else v.shape} is not a count (a whole number >= 0)")
    return int(x)


def read_frf_file(path) -> FrfFile:
    """Read an FRF file (frf.h5 or UFF-58 FRFs) as an :class:`FrfFile`; the suffix chooses the reader.

    Raises
    ------
    RecordingError
        guidefit's frf.csv (it lacks what identification needs), or anything
        malformed: one line naming the file.
    """
    from guidefit.io.registry import _checked_input, format_for

    display = os.fspath(path)
    p = _checked_input(display, "FRF")
    if p.suffix.lower() == ".csv":
        raise RecordingError(
            f"{display}: guidefit's frf.csv has no excitation direction, sensor geometry, number of averages "
            "or exponential-window time constant; identify from the recording, or write the FRFs with "
            "'guidefit frf REC --out frf.h5' (or frf.uff)")
    fmt = format_for(display, "frf", "read")
    return fmt.read(p, display)


def read_input(path):
    """What identify starts from: a :class:`~guidefit.io.records.Recording` or an :class:`FrfFile`.

    Examples
    --------
    >>> import tempfile
    >>> from guidefit.io import RunData, write_recording
    >>> run = RunData("v", 1000.0, [0, -1, 0], ["force", "acc_A_y"], ["N", "g"],
    ...               [[0, 0, 0], [0.03, 0, 0.045]], [[0, -1, 0], [0, 1, 0]], data=np.zeros((4, 2)))
    >>> path = Path(tempfile.mkdtemp()) / "rec.h5"
    >>> write_recording(path, run)
    >>> type(read_input(path)).__name__
    'Recording'
    """
    from guidefit.io.axes import map_input, reading
    from guidefit.io.registry import read_recording

    # a recording is read at no extra cost; the content of a file no recording reader takes is looked at then
    with reading() as rot:  # an input axis map in force (guidefit.io.axes.input_axes): applied once, here
        try:
            return map_input(read_recording(path), rot, os.fspath(path))
        except RecordingError:
            if holds_frfs(path):
                return map_input(read_frf_file(path), rot, os.fspath(path))
            raise


def read_metadata(path):
    """The run and channel metadata of a recording or an FRF file (a ``Recording``; samples not read)."""
    source = read_input(path)
    return source.recording if isinstance(source, FrfFile) else source


FORMATS = (
    FileFormat(name="guidefit FRFs, CSV", suffixes=(".csv",), kind="frf", write=write_frf_csv_file),
    FileFormat(
        name="guidefit FRFs, HDF5",
        suffixes=(".h5", ".hdf5"),
        kind="frf",
        read=read_frf_h5_file,
        write=write_frf_h5_file,
    ),
)
