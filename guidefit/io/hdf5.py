"""The recording contract in HDF5 (``.h5``, ``.hdf5``): reader, writer, sample source.

Layout (``shared/recording-format.md``): root attributes ``format =
"guidefit-recording"``, ``format_version``, ``guide``, ``description``; one
group ``/runs/<name>`` per run with attributes ``sample_rate_hz``,
``excitation_direction`` (and ``excitation_position_m``), holding one
dataset ``signals`` ``(n_samples, n_channels)`` or ``hits`` ``(n_hits,
n_samples, n_channels)`` whose attributes name the channels, units and
geometry. :func:`read_hdf5` validates the structure and returns runs whose
:class:`H5Source` reads the samples in slices (bounded memory);
:func:`write_hdf5` and :func:`open_signals_writer` write the format.

With a timeout set (``GUIDEFIT_HDF5_TIMEOUT_S``; the command line sets 30 s)
the metadata is read in a forked child (:mod:`guidefit.io.watchdog`), so a
damaged file that makes the HDF5 library loop is one error, not a hang.
"""

from __future__ import annotations

import contextlib
import os
import re
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from guidefit.errors import RecordingError
from guidefit.io._checks import (
    _atomic,
    _check_force_axis,
    _check_position,
    _check_pretrigger,
    _check_sample_rate,
    _check_vector,
    _first_line,
    _frozen_array,
    _numbers,
    _show,
    _strings,
)
from guidefit.io.records import (
    FORMAT_NAME,
    FORMAT_VERSION,
    LAYOUTS,
    Channel,
    Recording,
    RecordingData,
    Run,
    RunData,
    _build_channels,
    _in_units,
    _raw_read,
)
from guidefit.io.registry import FileFormat
from guidefit.io.watchdog import read_guarded

__all__ = ["H5Source", "SignalsWriter", "open_signals_writer", "read_hdf5", "write_hdf5"]

SUFFIXES = (".h5", ".hdf5")
SAMPLE_SCALE = "sample_scale"
"""Dataset attribute (an extension of the contract): the value of one stored count in
each channel's unit, one number or one per channel. Required for integer samples."""
_CHUNK_BYTES = 1 << 20  # target size of one HDF5 chunk
_COPY_ROWS = 1 << 18  # rows per block when copying a signals run


# ------------------------------------------------------------------ the source


@dataclass(frozen=True)
class H5Source:
    """Where a run's samples live in an HDF5 file (the sample-source protocol of :mod:`guidefit.io`).

    Attributes
    ----------
    path : str
        Absolute path of the file that holds the dataset (for a run reached
        through an external link: the linked file).
    dataset : str
        Path of the dataset in that file, e.g. ``"/runs/vertical/signals"``.
    dtype_str : str
        numpy dtype string of the stored samples.
    """

    path: str
    dataset: str
    dtype_str: str = "<f8"

    @property
    def dtype(self) -> np.dtype:
        """dtype of the stored samples."""
        return np.dtype(self.dtype_str)

    def read(self, index: tuple) -> np.ndarray:
        """Samples ``index`` in file units; opens the file for this call only."""
        with self.open() as handle:
            return handle.read(index)

    @contextlib.contextmanager
    def open(self) -> Iterator[_H5Handle]:
        """The file open for many reads (what :func:`guidefit.io.open_reader` uses)."""
        import h5py

        f = h5py.File(self.path, "r")
        try:
            yield _H5Handle(f, self)
        finally:
            f.close()


class _H5Handle:
    """An open dataset: ``read(index)``, ``dtype``, ``read_hits_into(first, out)``."""

    def __init__(self, f, source: H5Source):
        ds = _open_dataset(f, source.dataset)
        self._ds = ds
        self.dtype = ds.dtype
        self._direct = None
        chunks = ds.chunks
        if ds.ndim == 3 and chunks is not None and chunks[0] == 1 and chunks[2] == ds.shape[2]:
            # hits are read whole, so each chunk (consecutive samples of one hit,
            # all channels) is read once: without a chunk cache HDF5 reads it
            # straight into the output array instead of through the cache (one copy less)
            self._direct = _open_dataset(f, source.dataset, chunk_cache=False).id

    def read(self, index: tuple) -> np.ndarray:
        return self._ds[index]

    def read_hits_into(self, first: int, out: np.ndarray) -> None:
        """Whole hits ``first:first + len(out)`` straight into C-contiguous ``out``."""
        import h5py

        dataset = self._direct if self._direct is not None else self._ds.id
        selection = dataset.get_space()
        selection.select_hyperslab((int(first), 0, 0), out.shape)
        dataset.read(h5py.h5s.create_simple(out.shape), selection, out)


def _open_dataset(f, path: str, chunk_cache: bool = True):
    """The dataset at ``path`` (links followed, as HDF5 does).

    A dataset with external raw storage or virtual-dataset sources is opened with
    those resolved against the folder of the file that holds it (``${ORIGIN}``),
    never against the current working directory. Others are opened plainly (HDF5
    refuses a second open of a dataset with another external-file prefix, so a
    caller holding the dataset open through h5py keeps working).
    """
    import h5py

    plain = h5py.h5d.open(f.id, path.encode())
    create = plain.get_create_plist()
    special = create.get_layout() == h5py.h5d.VIRTUAL or create.get_external_count() > 0
    if not special and chunk_cache:
        return h5py.Dataset(plain)
    del plain, create  # closed: the open below may set other access properties
    access = h5py.h5p.create(h5py.h5p.DATASET_ACCESS)
    if special:
        access.set_efile_prefix(b"${ORIGIN}")
        access.set_virtual_prefix(b"${ORIGIN}")
    if not chunk_cache:
        access.set_chunk_cache(0, 0, 1.0)
    return h5py.Dataset(h5py.h5d.open(f.id, path.encode(), dapl=access))


# --------------------------------------------------------------------- reading


def _h5_open_error(p: Path, display: str, exc: OSError) -> RecordingError:
    import h5py

    message = _first_line(exc)
    truncated = re.search(r"truncated file: eof = (\d+).*stored_eof = (\d+)", message)
    if truncated:
        have, need = truncated.groups()
        return RecordingError(f"{display}: truncated HDF5 file: {have} of {need} bytes present")
    try:
        signature = h5py.is_hdf5(os.fspath(p))
    except OSError:
        signature = True
    if not signature:
        head = p.open("rb").read(64)
        hint = (
            " (it looks like text; a CSV recording needs the .csv suffix)" if _is_text(head) else ""
        )
        return RecordingError(f"{display}: not an HDF5 file (no HDF5 signature){hint}")
    return RecordingError(f"{display}: cannot open as HDF5 ({message})")


def _is_text(head: bytes) -> bool:
    try:
        head.decode("utf-8")
    except UnicodeDecodeError:
        return False
    return b"\x00" not in head


def read_hdf5(p: Path, display: str) -> Recording:
    """Read and validate a contract HDF5 recording's structure (``display``: the path as given).

    HDF5 library errors on a damaged file become one RecordingError.

    Some damaged files make the HDF5 library itself loop (a corrupted global
    heap: minutes or forever, holding the GIL, so no Python thread can stop
    it) or allocate gigabytes. With a timeout set (:data:`guidefit.io.watchdog.HDF5_METADATA_TIMEOUT_S`
    or ``GUIDEFIT_HDF5_TIMEOUT_S``; the command line sets 30 s) and where the
    platform can fork (Linux), the metadata is read in a forked child that
    the parent gives up on after the timeout, or when it dies, with one
    RecordingError. The fork costs about 30 ms per file on the development
    machine (42 against 8 ms for the sample recording).
    """
    import h5py  # noqa: F401 - here, before a guard forks: else the child imports it too (25 ms on the critical path)

    return read_guarded(_read_hdf5_structure, p, display, "HDF5 file")


def _read_hdf5_structure(p: Path, display: str) -> Recording:
    import h5py

    try:
        f = h5py.File(p, "r")
    except OSError as exc:
        raise _h5_open_error(p, display, exc) from None
    with f:
        attrs = f.attrs
        if "format" not in attrs:
            raise RecordingError(
                f"{display}: root attribute 'format' missing; expected '{FORMAT_NAME}'"
            )
        fmt = _strings(attrs["format"], display, "format")
        if fmt is None or len(fmt) != 1 or fmt[0] != FORMAT_NAME:
            shown = _show(fmt[0] if fmt and len(fmt) == 1 else attrs["format"])
            raise RecordingError(
                f"{display}: root attribute 'format' is {shown}; expected '{FORMAT_NAME}'"
            )
        if "format_version" not in attrs:
            raise RecordingError(
                f"{display}: root attribute 'format_version' missing; expected {FORMAT_VERSION}"
            )
        _check_version(attrs["format_version"], display)
        guide = _optional_text(attrs, "guide", display) or None
        description = _optional_text(attrs, "description", display)
        runs_group = _get_checked(f, "runs", f"{display}: group '/runs'")
        if runs_group is None:
            raise RecordingError(
                f"{display}: group '/runs' missing; expected one group per run under /runs"
            )
        if not isinstance(runs_group, h5py.Group):
            raise RecordingError(
                f"{display}: '/runs' is not a group; expected one group per run under /runs"
            )
        names = list(runs_group.keys())
        if not names:
            raise RecordingError(
                f"{display}: '/runs' holds no runs; expected at least one run group"
            )
        runs = tuple(_read_hdf5_run(p, display, f, runs_group, name) for name in names)
    return Recording(path=display, guide=guide, description=description, runs=runs)


def _check_version(value, where: str) -> None:
    arr = _numbers(value)
    if arr is None or arr.size != 1 or not float(arr.reshape(-1)[0]).is_integer():
        raise RecordingError(
            f"{where}: root attribute 'format_version' is {_show(value)}; expected {FORMAT_VERSION}"
        )
    version = int(arr.reshape(-1)[0])
    if version != FORMAT_VERSION:
        raise RecordingError(
            f"{where}: format_version {version} is not supported; this guidefit reads version {FORMAT_VERSION}"
        )


def _optional_text(attrs, name: str, where: str) -> str:
    import h5py

    if name not in attrs or isinstance(attrs[name], h5py.Empty):  # absent, or present without a value
        return ""
    text = _strings(attrs[name], where, name)
    if text is None or len(text) != 1:
        raise RecordingError(
            f"{where}: root attribute '{name}' is {_show(attrs[name])}; expected text"
        )
    return text[0]


def _linked_file(link_file: str, holder: str) -> Path:
    """Where HDF5 finds the file ``link_file`` named by an external link or a virtual
    source in the file ``holder``: as given if absolute, else in ``holder``'s folder."""
    target = Path(os.fsdecode(link_file))
    return target if target.is_absolute() else Path(holder).resolve().parent / target


def _regular_file(target: Path, where: str, what: str) -> None:
    """``target`` must exist and be a regular file (a device or FIFO would block or never end)."""
    import stat

    try:
        mode = os.stat(target).st_mode
    except OSError:
        raise RecordingError(f"{where}: {what} '{target}' does not exist") from None
    if not stat.S_ISREG(mode):
        raise RecordingError(f"{where}: {what} '{target}' is not a regular file (a device or FIFO?)")


def _scaled(channels, value, where: str):
    """Channels whose ``scale_to_si`` includes the per-count ``sample_scale`` attribute."""
    arr = _numbers(value)
    n = len(channels)
    if arr is None or arr.size not in (1, n):
        raise RecordingError(
            f"{where}: attribute '{SAMPLE_SCALE}' is {_show(value)}; expected one number or {n} "
            "(the value of one stored count in each channel's unit)"
        )
    factors = np.broadcast_to(arr.reshape(-1), (n,))
    if not np.all(np.isfinite(factors)) or np.any(factors == 0):
        raise RecordingError(
            f"{where}: attribute '{SAMPLE_SCALE}' is {_show(value)}; expected finite, non-zero numbers"
        )
    return tuple(
        Channel(ch.name, ch.unit, ch.position_m, ch.direction, ch.scale_to_si * float(k))
        for ch, k in zip(channels, factors)
    )


def _check_link(parent, key: str, where: str, depth: int = 0) -> None:
    """An external link ``parent/key`` must lead to an existing regular file.

    Checked before anything follows the link (a FIFO would block the reader); a
    soft link is checked along the path it names. The object is then reached
    through the link under the name it has in ``parent``'s file: a master file
    may link runs of other files under other names.
    """
    import h5py

    if depth > 16:
        raise RecordingError(f"{where}: links nested more than 16 deep; refused")
    try:
        link = parent.get(key, getlink=True)
    except (KeyError, RuntimeError, OSError, ValueError):
        return
    if isinstance(link, h5py.ExternalLink):
        target = _linked_file(link.filename, parent.file.filename)
        _regular_file(target, where, f"external link '{key}' to file")
    elif isinstance(link, h5py.SoftLink):
        path = link.path if link.path.startswith("/") else f"{parent.name.rstrip('/')}/{link.path}"
        node = parent.file
        for part in [c for c in path.split("/") if c]:
            _check_link(node, part, where, depth + 1)
            try:
                node = node.get(part)
            except (KeyError, RuntimeError, OSError, ValueError):
                return
            if not isinstance(node, h5py.Group):
                return


def _get_checked(parent, key: str, where: str):
    """``parent.get(key)`` after :func:`_check_link`; a link that cannot be followed is one error."""
    _check_link(parent, key, where)
    try:
        return parent.get(key)
    except (KeyError, OSError, RuntimeError) as exc:
        raise RecordingError(f"{where}: cannot be opened ({_first_line(exc)})") from None


def _check_storage(ds, recording: Path, where: str, depth: int = 0) -> None:
    """Refuse samples HDF5 would read from outside the file silently wrong.

    External raw storage (``ds.external``) must lie in the recording's folder (or that
    of the linked file holding the dataset), be regular files and hold every byte of
    the dataset (HDF5 reads a missing or short file as zeros). A virtual dataset's
    sources must exist, and together cover the whole dataset (h5py fills what no
    source gives with the fill value).
    """
    holder = ds.file.filename
    if ds.external:
        _check_external(ds, recording, holder, where)
    if ds.is_virtual:
        _check_virtual(ds, recording, holder, where, depth)


def _check_external(ds, recording: Path, holder: str, where: str) -> None:
    import h5py

    folders = {Path(recording).resolve().parent, Path(holder).resolve().parent}
    need = int(ds.size) * ds.dtype.itemsize
    for name, offset, size in ds.external:
        name = os.fsdecode(name)
        target = _linked_file(name, holder)
        real = target.resolve()
        if not any(real.is_relative_to(folder) for folder in folders):
            raise RecordingError(
                f"{where}: external raw storage '{name}' lies outside the recording's folder; "
                "refused (copy the samples into the file or beside it)"
            )
        _regular_file(real, where, "external raw storage")
        segment = need if size == h5py.h5f.UNLIMITED else min(int(size), need)
        have = max(0, os.stat(real).st_size - int(offset))
        if have < segment:
            raise RecordingError(
                f"{where}: external raw storage '{name}' holds {have} bytes from offset {offset}, "
                f"the dataset needs {segment}; HDF5 would read the rest as zeros"
            )
        need -= segment
        if need <= 0:
            break
    if need > 0:
        raise RecordingError(
            f"{where}: external raw storage holds {int(ds.size) * ds.dtype.itemsize - need} of the "
            f"{int(ds.size) * ds.dtype.itemsize} bytes of the dataset"
        )


def _source_short(source, src) -> bool:
    """True when the dataset ``src`` is smaller than the part of it a virtual source maps.

    A source mapped whole (``layout[...] = VirtualSource(...)``: an "all" selection,
    which h5py reads back without bounds) must hold as many values as the virtual
    selection it fills.
    """
    import h5py

    space = source.src_space
    if space.get_select_type() == h5py.h5s.SEL_ALL:
        return int(np.prod(src.shape, dtype=np.int64)) < int(source.vspace.get_select_npoints())
    if space.get_select_npoints() == 0:
        return False
    _, end = space.get_select_bounds()
    return len(end) != src.ndim or any(e >= n for e, n in zip(end, src.shape))


def _check_virtual(ds, recording: Path, holder: str, where: str, depth: int) -> None:
    import h5py

    if depth > 4:
        raise RecordingError(f"{where}: virtual datasets nested more than 4 deep; refused")
    covered = 0
    for source in ds.virtual_sources():
        file_name, dset_name = source.file_name, source.dset_name
        what = f"virtual dataset source '{file_name}:{dset_name}'"
        if "%" in file_name or "%" in dset_name:
            raise RecordingError(f"{where}: {what} is a name pattern; not supported")
        covered += int(source.vspace.get_select_npoints())
        if file_name == ".":
            f_source, close = ds.file, False
        else:
            target = _linked_file(file_name, holder)
            _regular_file(target, where, f"{what}: file")
            try:
                f_source, close = h5py.File(target, "r"), True
            except OSError as exc:
                raise RecordingError(f"{where}: {what} cannot be opened ({_first_line(exc)})") from None
        try:
            try:
                src = _open_dataset(f_source, dset_name)
            except (KeyError, OSError, RuntimeError, ValueError):
                raise RecordingError(
                    f"{where}: {what} is missing; HDF5 would read it as fill values"
                ) from None
            if _source_short(source, src):
                raise RecordingError(
                    f"{where}: {what} has shape {src.shape}, smaller than the part mapped "
                    "from it; HDF5 would read the rest as fill values"
                )
            _check_storage(src, recording, where, depth + 1)
        finally:
            if close:
                f_source.close()
    if covered < ds.size:
        raise RecordingError(
            f"{where}: virtual dataset maps {covered} of its {int(ds.size)} values to sources; "
            "the rest would read as fill values"
        )


def _read_hdf5_run(p: Path, display: str, root, runs_group, name: str) -> Run:
    """The :class:`Run` ``name`` of the open recording ``root`` (``p`` its file, ``display`` its path
    as given): attributes (:func:`_run_attributes`), the one data layout (:func:`_run_layout`), its
    dataset (:func:`_check_run_dataset`), channels (:func:`_run_channels`) and a read probe. The
    samples stay in the file (:class:`H5Source`)."""
    import h5py

    where = f"{display}: run '{name}'"
    group = _get_checked(runs_group, name, where)
    if not isinstance(group, h5py.Group):
        raise RecordingError(
            f"{where}: not a group; expected a group holding a 'signals' or 'hits' dataset"
        )
    rate, exc_dir, exc_pos = _run_attributes(group.attrs, where)
    layout = _run_layout(group, where)
    access_path = f"/runs/{name}/{layout}"  # in the recording's own file: links are followed on every read
    ds = _open_dataset(root, access_path)
    _check_run_dataset(ds, p, where, layout)
    dwhere = f"{where}: dataset '{layout}'"
    channels, force_index = _run_channels(ds, where, dwhere)
    _check_force_axis(channels[force_index].direction, exc_dir, where)
    pretrigger = None
    if "pretrigger_samples" in ds.attrs:
        pretrigger = _check_pretrigger(ds.attrs["pretrigger_samples"], ds.shape[-2], dwhere)
    try:  # a cheap probe for data missing from a damaged file
        ds[(0,) * (ds.ndim - 1)]
        ds[tuple(s - 1 for s in ds.shape[:-1])]
    except (OSError, RuntimeError, KeyError) as exc:
        raise RecordingError(f"{dwhere}: samples cannot be read ({_first_line(exc)})") from None
    return Run(
        name=name,
        sample_rate_hz=rate,
        excitation_direction=_frozen_array(exc_dir),
        excitation_position_m=None if exc_pos is None else _frozen_array(exc_pos),
        channels=channels,
        layout=layout,
        n_samples=int(ds.shape[-2]),
        n_hits_stored=int(ds.shape[0]) if layout == "hits" else 0,
        pretrigger_samples=pretrigger,
        source=H5Source(os.path.abspath(p), access_path, ds.dtype.str),
        force_index=force_index,
        file=display,
    )


def _run_attributes(attrs, where: str):
    """``(sample_rate_hz, excitation_direction, excitation_position_m or None)`` of a run group."""
    if "sample_rate_hz" not in attrs:
        raise RecordingError(
            f"{where}: attribute 'sample_rate_hz' missing; expected the sampling rate in Hz"
        )
    rate = _check_sample_rate(attrs["sample_rate_hz"], where)
    if "excitation_direction" not in attrs:
        raise RecordingError(
            f"{where}: attribute 'excitation_direction' missing; expected a unit vector (3 numbers)"
        )
    exc_dir = _check_vector(attrs["excitation_direction"], where, "excitation_direction", True)
    exc_pos = None
    if "excitation_position_m" in attrs:
        exc_pos = _check_vector(
            attrs["excitation_position_m"], where, "excitation_position_m", False
        )
        exc_pos = _check_position(exc_pos, where, "excitation_position_m")
    return rate, exc_dir, exc_pos


def _run_layout(group, where: str) -> str:
    """``"signals"`` or ``"hits"``: the run group's one data dataset."""
    import h5py

    for key in LAYOUTS:
        _check_link(group, key, f"{where}: dataset '{key}'")
    present = [k for k in LAYOUTS if k in group]
    if not present:
        have = ", ".join(group.keys()) or "nothing"
        raise RecordingError(f"{where}: no dataset 'signals' or 'hits'; have {have}")
    if len(present) == 2:
        raise RecordingError(
            f"{where}: has both 'signals' and 'hits'; expected exactly one of them"
        )
    layout = present[0]
    if group.get(layout, getclass=True) is not h5py.Dataset:
        raise RecordingError(f"{where}: '{layout}' is not a dataset")
    return layout


def _check_run_dataset(ds, p: Path, where: str, layout: str) -> None:
    """The data dataset's storage, dtype (float, or integer counts with a scale) and shape."""
    _check_storage(ds, p, f"{where}: dataset '{layout}'")
    if ds.dtype.kind not in "fiu":
        raise RecordingError(
            f"{where}: dataset '{layout}' has dtype {ds.dtype}; expected float32 or float64"
        )
    if ds.dtype.kind in "iu" and SAMPLE_SCALE not in ds.attrs:
        raise RecordingError(
            f"{where}: dataset '{layout}' has integer dtype {ds.dtype}; expected float32 or float64, "
            f"or integer counts with attribute '{SAMPLE_SCALE}' (the value of one count in each "
            "channel's unit)"
        )
    want = 2 if layout == "signals" else 3
    if ds.ndim != want:
        shape_text = (
            "(n_samples, n_channels)" if layout == "signals" else "(n_hits, n_samples, n_channels)"
        )
        raise RecordingError(
            f"{where}: dataset '{layout}' has shape {ds.shape}; expected {shape_text}"
        )
    if 0 in ds.shape:
        raise RecordingError(
            f"{where}: dataset '{layout}' has shape {ds.shape}; it holds no samples"
        )


def _run_channels(ds, where: str, dwhere: str):
    """``(channels, force_index)`` from the data dataset's channel attributes (names, units,
    positions, directions; scaled when the samples are integer counts)."""
    n_channels = ds.shape[-1]
    texts = {}
    for attr in ("channel_names", "units"):
        if attr not in ds.attrs:
            what = "channel name" if attr == "channel_names" else "unit"
            raise RecordingError(
                f"{dwhere}: attribute '{attr}' missing; expected one {what} per column"
            )
        values = _strings(ds.attrs[attr], dwhere, attr)
        if values is None:
            raise RecordingError(
                f"{dwhere}: attribute '{attr}' is {_show(ds.attrs[attr])}; expected a list of text"
            )
        if len(values) != n_channels:
            raise RecordingError(f"{dwhere}: {len(values)} {attr} for {n_channels} data columns")
        texts[attr] = values
    tables = {}
    for attr in ("positions_m", "directions"):
        if attr not in ds.attrs:
            raise RecordingError(
                f"{dwhere}: attribute '{attr}' missing; expected shape ({n_channels}, 3)"
            )
        tables[attr] = ds.attrs[attr]
    names = tuple(texts["channel_names"])
    channels, force_index = _build_channels(
        where, names, tuple(texts["units"]), tables["positions_m"], tables["directions"]
    )
    if SAMPLE_SCALE in ds.attrs:
        channels = _scaled(channels, ds.attrs[SAMPLE_SCALE], dwhere)
    return channels, force_index


# --------------------------------------------------------------------- writing

def _chunk_rows(n_channels: int, itemsize: int) -> int:
    return max(1, _CHUNK_BYTES // max(1, n_channels * itemsize))


def _file_dtype(dtype) -> np.dtype:
    dtype = np.dtype(dtype)
    if dtype == np.float32 or dtype == np.float64:
        return dtype
    return (
        np.dtype(np.float32) if dtype.kind == "f" and dtype.itemsize < 4 else np.dtype(np.float64)
    )


def _write_root(f, guide: str | None, description: str) -> None:
    f.attrs["format"] = FORMAT_NAME
    f.attrs["format_version"] = np.int64(FORMAT_VERSION)
    if guide:
        f.attrs["guide"] = guide
    if description:
        f.attrs["description"] = description


def _create_run(runs_group, header, layout: str, shape: tuple, dtype, compression, resizable=False):
    """Create /runs/<name> and its dataset with the contract's attributes."""
    import h5py

    group = runs_group.create_group(header["name"])
    group.attrs["sample_rate_hz"] = np.float64(header["sample_rate_hz"])
    group.attrs["excitation_direction"] = np.asarray(header["excitation_direction"], np.float64)
    if header["excitation_position_m"] is not None:
        group.attrs["excitation_position_m"] = np.asarray(
            header["excitation_position_m"], np.float64
        )
    n_channels = shape[-1]
    rows = _chunk_rows(n_channels, dtype.itemsize)
    if not resizable:
        rows = min(max(1, shape[-2]), rows)
    if resizable:
        ds = group.create_dataset(
            layout,
            shape=shape,
            maxshape=(None, n_channels),
            dtype=dtype,
            chunks=(rows, n_channels),
            compression=compression,
        )
    else:
        chunks = (rows, n_channels) if layout == "signals" else (1, rows, n_channels)
        ds = group.create_dataset(
            layout, shape=shape, dtype=dtype, chunks=chunks, compression=compression
        )
    text = h5py.string_dtype()
    ds.attrs.create("channel_names", list(header["channel_names"]), dtype=text)
    ds.attrs.create("units", list(header["units"]), dtype=text)
    ds.attrs["positions_m"] = np.asarray(header["positions_m"], np.float64)
    ds.attrs["directions"] = np.asarray(header["directions"], np.float64)
    if header["pretrigger_samples"] is not None:
        ds.attrs["pretrigger_samples"] = np.int64(header["pretrigger_samples"])
    return ds


def _header(run) -> dict:
    if isinstance(run, RunData):
        return {
            "name": run.name,
            "sample_rate_hz": run.sample_rate_hz,
            "excitation_direction": run.excitation_direction,
            "excitation_position_m": run.excitation_position_m,
            "channel_names": run.channel_names,
            "units": run.units,
            "positions_m": run.positions_m,
            "directions": run.directions,
            "pretrigger_samples": run.pretrigger_samples,
        }
    return {
        "name": run.name,
        "sample_rate_hz": run.sample_rate_hz,
        "excitation_direction": run.excitation_direction,
        "excitation_position_m": run.excitation_position_m,
        "channel_names": run.channel_names,
        "units": tuple(ch.unit for ch in run.channels),
        "positions_m": np.array([ch.position_m for ch in run.channels]),
        "directions": np.array([ch.direction for ch in run.channels]),
        "pretrigger_samples": run.pretrigger_samples,
    }


def write_hdf5(path, recording, *, compression: str | None = None) -> None:
    """Write ``recording`` (RecordingData, RunData or Recording) as contract HDF5, atomically.

    See :func:`guidefit.io.write_recording`.
    """
    display = os.fspath(path)
    if isinstance(recording, RunData):
        recording = RecordingData((recording,))
    if not isinstance(recording, (RecordingData, Recording)):
        raise TypeError(
            f"recording: expected RecordingData, RunData or Recording, got {type(recording).__name__}"
        )
    for run in recording.runs:
        if isinstance(run, Run) and run.hit_position_m is None:  # read from a file that does not say where
            raise RecordingError(
                f"{display}: run '{run.name}': the hit point is unknown (the source file gives neither "
                "excitation_position_m nor the force channel's position, nor the reference node's coordinates); "
                "a recording would put it at the force channel's position. Give it: excitation_position_m (a "
                "test setup's run table or a CSV '# excitation_position_m:' line, docs/recordings.md), or the "
                "node's coordinates in the file"
            )
    _atomic(Path(display), lambda tmp: _write_hdf5(tmp, display, recording, compression))


def _write_hdf5(tmp: Path, display: str, recording, compression) -> None:
    import io

    import h5py

    # Samples already in memory: the file is built in memory and written in one plain write.
    # A failing disk write inside libhdf5 (full disk, file-size limit) leaves h5py objects that
    # crash the interpreter when freed (segfault, tracebacks); a failing Python write is one error.
    in_memory = all(isinstance(run, RunData) for run in recording.runs)
    image = io.BytesIO() if in_memory else None
    try:
        f = h5py.File(image if in_memory else tmp, "w")
    except OSError as exc:
        raise RecordingError(f"{display}: cannot create file ({_first_line(exc)})") from None
    with f:
        _write_hdf5_runs(f, display, recording, compression)
    if in_memory:
        try:
            with open(tmp, "wb") as out:
                out.write(image.getbuffer())
        except OSError as exc:
            raise RecordingError(f"{display}: cannot write ({exc.strerror or _first_line(exc)})") from None


def _write_hdf5_runs(f, display: str, recording, compression) -> None:
    _write_root(f, recording.guide, recording.description)
    runs_group = f.create_group("runs", track_order=True)
    for run in recording.runs:
        if isinstance(run, RunData):
            if run.data is None:
                raise RecordingError(f"{display}: run '{run.name}': no data to write")
            data = run.data
            if 0 in data.shape:
                raise RecordingError(
                    f"{display}: run '{run.name}': data has shape {data.shape}; it holds no samples"
                )
            dtype = _file_dtype(data.dtype)
            ds = _create_run(
                runs_group, _header(run), run.layout, data.shape, dtype, compression
            )
            ds[...] = data
        else:  # a Run read from a file: copy block by block in stored units
            dtype = _file_dtype(run.sample_dtype if _in_units(run, None) is None else np.float64)
            if run.layout == "signals":
                shape = (run.n_samples, run.n_channels)
                ds = _create_run(runs_group, _header(run), "signals", shape, dtype, compression)
                for start in range(0, run.n_samples, _COPY_ROWS):
                    stop = min(run.n_samples, start + _COPY_ROWS)
                    ds[start:stop] = _in_units(run, _raw_read(run, (slice(start, stop), slice(None))))
            else:
                shape = (run.n_hits_stored, run.n_samples, run.n_channels)
                ds = _create_run(runs_group, _header(run), "hits", shape, dtype, compression)
                for i in range(run.n_hits_stored):
                    ds[i] = _in_units(run, _raw_read(run, (i, slice(None), slice(None))))


class SignalsWriter:
    """Appends sample blocks to a ``signals`` run; made by :func:`open_signals_writer`."""

    def __init__(self, dataset, run: RunData, display: str):
        self._ds = dataset
        self._run = run
        self._display = display

    @property
    def n_samples(self) -> int:
        """Samples written so far."""
        return int(self._ds.shape[0])

    def append(self, block) -> None:
        """Append ``block`` of shape (n, n_channels), in the run's units.

        Raises
        ------
        RecordingError
            Wrong shape or dtype.
        """
        block = np.asarray(block)
        where = f"{self._display}: run '{self._run.name}'"
        if block.dtype.kind not in "fiu":
            raise RecordingError(f"{where}: block has dtype {block.dtype}; expected real numbers")
        n_channels = self._run.n_channels
        if block.ndim != 2 or block.shape[1] != n_channels:
            raise RecordingError(
                f"{where}: block has shape {block.shape}; expected (n, {n_channels})"
            )
        if block.shape[0] == 0:
            return
        n = self._ds.shape[0]
        self._ds.resize(n + block.shape[0], axis=0)
        self._ds[n:] = block


@contextlib.contextmanager
def open_signals_writer(
    path: str | os.PathLike,
    run: RunData,
    *,
    guide: str | None = None,
    description: str = "",
    mode: str = "w",
    dtype=None,
    compression: str | None = None,
) -> Iterator[SignalsWriter]:
    """Write one ``signals`` run block by block (bounded memory), HDF5 only.

    Parameters
    ----------
    path : str or path-like
        ``.h5`` or ``.hdf5``.
    run : RunData
        Header of the run (``layout="signals"``); its ``data``, if any, is
        written first.
    guide, description : str, optional
        Root attributes (``mode="w"`` only).
    mode : {"w", "a"}
        ``"w"``: a new file, which appears under ``path`` only when the block
        ends without error. ``"a"``: add the run to an existing recording (on
        error the run is removed again).
    dtype : dtype, optional
        float32 or float64 on disk; default that of ``run.data``, else float64.
    compression : str, optional
        HDF5 filter, e.g. ``"gzip"``.

    Yields
    ------
    SignalsWriter
        Call ``append(block)`` with blocks of shape (n, n_channels).

    Raises
    ------
    RecordingError
        Bad header, an existing run of that name, or no samples written.

    Examples
    --------
    >>> import os, tempfile
    >>> import numpy as np
    >>> from guidefit.io import read_block, read_recording
    >>> header = RunData("vertical", 1000.0, [0, -1, 0], ["force", "acc_A_y"], ["N", "m/s^2"],
    ...                  [[0, 0, 0], [0.03, 0, 0.045]], [[0, -1, 0], [0, 1, 0]])
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     path = os.path.join(folder, "long.h5")
    ...     with open_signals_writer(path, header) as writer:
    ...         for k in range(3):
    ...             writer.append(np.full((100, 2), float(k)))
    ...     run = read_recording(path).runs[0]
    ...     last = read_block(run, 299, 300)
    >>> run.n_samples, last.tolist()
    (300, [[2.0, 2.0]])
    """
    display = os.fspath(path)
    p = Path(display)
    _check_writer_arguments(display, p, run, mode)
    if dtype is None:
        dtype = np.float64 if run.data is None else run.data.dtype
    dtype = _file_dtype(dtype)
    target = p.with_name(p.name + ".part") if mode == "w" else p
    f, runs_group = _open_for_run(p, target, display, run, mode, guide, description)
    ok = False
    try:
        ds = _create_run(
            runs_group,
            _header(run),
            "signals",
            (0, run.n_channels),
            dtype,
            compression,
            resizable=True,
        )
        writer = SignalsWriter(ds, run, display)
        if run.data is not None:
            writer.append(run.data)
        yield writer
        if writer.n_samples == 0:
            raise RecordingError(f"{display}: run '{run.name}': no samples were appended")
        ok = True
    finally:
        _close_written(f, runs_group, run.name, mode, target, p, ok)


def _check_writer_arguments(display: str, p: Path, run, mode: str) -> None:
    """:func:`open_signals_writer`'s path suffix, run header type and layout, and mode."""
    if p.suffix.lower() not in SUFFIXES:
        raise RecordingError(
            f"{display}: open_signals_writer writes HDF5; expected a .h5 or .hdf5 path"
        )
    if not isinstance(run, RunData):
        raise TypeError(f"run: expected RunData, got {type(run).__name__}")
    if run.layout != "signals":
        raise RecordingError(
            f"{display}: run '{run.name}': layout '{run.layout}'; the writer writes 'signals'"
        )
    if mode not in ("w", "a"):
        raise ValueError(f"mode={mode!r}: expected 'w' or 'a'")


def _open_for_run(p: Path, target: Path, display: str, run, mode: str, guide, description):
    """``(file, runs group)`` open for a new run: a new file ``target`` with the root attributes
    (``mode="w"``), or the existing recording ``p``, checked first (``mode="a"``)."""
    import h5py

    if mode == "w":
        f = h5py.File(target, "w")
        _write_root(f, guide or None, description)
        return f, f.create_group("runs", track_order=True)
    from guidefit.io.registry import read_recording

    read_recording(p)  # must already be a valid recording
    f = h5py.File(target, "r+")
    runs_group = f["runs"]
    if run.name in runs_group:
        f.close()
        raise RecordingError(f"{display}: run '{run.name}' already exists")
    return f, runs_group


def _close_written(f, runs_group, name: str, mode: str, target: Path, p: Path, ok: bool) -> None:
    """Close the file of :func:`open_signals_writer`; unless the run was written completely
    (``ok``) and the file closed, remove the run (``mode="a"``) or the partial file (``"w"``),
    else move the new file into place."""
    if not ok and mode == "a":
        with contextlib.suppress(Exception):
            del runs_group[name]
    try:
        f.close()
    except BaseException:
        ok = False  # a close that fails (full disk) leaves an incomplete file
        raise
    finally:
        if mode == "w":
            if ok:
                os.replace(target, p)
            else:
                with contextlib.suppress(OSError):
                    target.unlink()


FORMATS = (
    FileFormat(
        name="guidefit recording, HDF5",
        suffixes=SUFFIXES,
        kind="recording",
        read=read_hdf5,
        write=write_hdf5,
        streaming=True,
    ),
)
