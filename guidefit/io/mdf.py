"""ASAM MDF 4 files (Vector, HBM, Dewesoft, CSS) as a test setup's DAQ files, read with asammdf.

An MDF file holds channel groups, each with its own time channel (the
master) and a number of records (cycles). A setup's ``source`` is a
channel's name; a run's ``group`` is the channel-group index (0-based) of a
file that holds several runs, or of a name that several groups share. A
run's channels must come from one channel group; its sample rate is that
group's time channel's (least-squares slope of sample number over time,
checked for uniform spacing, read in chunks). The unit the file states is
the channel's unit. Opening the setup reads the metadata and the time
channel; samples are read per call (``record_offset`` / ``record_count``),
the channel's conversion applied as asammdf applies it.

Examples
--------
>>> import os, tempfile
>>> import numpy as np
>>> from asammdf import MDF, Signal
>>> from guidefit.io._daq import RunOptions
>>> t = np.arange(8) / 51200.0
>>> with tempfile.TemporaryDirectory() as folder:
...     path = os.path.join(folder, "hit.mf4")
...     with MDF(version="4.10") as mdf:
...         _ = mdf.append([Signal(np.arange(8.0), t, name="Hammer", unit="V")])
...         _ = mdf.save(path)
...     daq = open_daq(Path(path), "hit.mf4", RunOptions("test.toml: runs.a"))
...     ch = daq.find("Hammer")
...     rate = daq.rate_for((ch,))
...     block = daq.make_source((ch,), np.float64).read((slice(2, 5), slice(None)))
>>> rate, ch.unit, block[:, 0].tolist()
(51200.0, 'V', [2.0, 3.0, 4.0])
"""

from __future__ import annotations

import contextlib
from pathlib import Path

import numpy as np

from guidefit.errors import RecordingError
from guidefit.io._checks import _first_line, _require
from guidefit.io._daq import ColumnSource, DaqChannel, DaqFile, RunOptions, quiet_logger, rate_from_time
from guidefit.io.registry import FileFormat

__all__ = ["MdfSource", "open_daq"]

SUFFIXES = (".mf4", ".mdf")
_MASTER_TYPES = (2, 3)  # MDF 4 channel types: master, virtual master
_FLOAT_TYPES = (4, 5)  # MDF 4 data types: IEEE float, little and big endian


class MdfSource(ColumnSource):
    """Channels of one MDF channel group, read record range by record range; keys are (group, index)."""

    @contextlib.contextmanager
    def _open(self):
        from asammdf import MDF

        with quiet_logger("asammdf"):
            mdf = MDF(self.facts["path"])
            try:
                yield mdf
            finally:
                mdf.close()

    def _read(self, handle, start, stop, keys):
        return [
            handle.get(group=g, index=i, record_offset=start, record_count=stop - start, samples_only=True)[0]
            for g, i in keys
        ]


def _group_index(options: RunOptions, n_groups: int, display: str) -> int | None:
    group = options.group
    if group is None:
        return None
    if isinstance(group, str) and group.strip().isdigit():
        group = int(group)
    if not isinstance(group, int) or isinstance(group, bool) or not 0 <= group < n_groups:
        raise RecordingError(
            f"{options.where}: group {group!r}: expected a channel-group index 0..{n_groups - 1} of {display}"
        )
    return group


def open_daq(path: Path, display: str, options: RunOptions) -> DaqFile:
    """The channels of an MDF file (metadata only) for a setup's run.

    Parameters
    ----------
    path : pathlib.Path
    display : str
        The file as the user sees it, for messages.
    options : RunOptions
        ``group``: the channel-group index of this run (default: every group).

    Raises
    ------
    RecordingError
        asammdf missing, not an MDF file, a group index outside the file.
    """
    asammdf = _require("asammdf", "daq", display, "ASAM MDF")
    try:
        with quiet_logger("asammdf"):
            mdf = asammdf.MDF(str(path))
    except Exception as exc:  # noqa: BLE001 - asammdf raises its own MdfException and others
        raise RecordingError(f"{display}: not a readable MDF file ({_first_line(exc)})") from None
    try:
        groups = list(mdf.groups)
        masters = dict(mdf.masters_db)  # group index -> index of its time channel (MDF 3 and 4 alike)
        version4 = str(mdf.version) >= "4"
        only = _group_index(options, len(groups), display)
        channels, aliases, ambiguous, by_name = [], {}, {}, {}
        for gi, group in enumerate(groups):
            if only is not None and gi != only:
                continue
            n = int(group.channel_group.cycles_nr)
            for ci, c in enumerate(group.channels):
                if masters.get(gi) == ci or (version4 and c.channel_type in _MASTER_TYPES):
                    continue
                is_float32 = version4 and c.data_type in _FLOAT_TYPES and c.bit_count == 32 and c.conversion is None
                ch = DaqChannel(
                    name=c.name,
                    key=(gi, ci),
                    n_samples=n,
                    unit=(str(c.unit).strip() or None) if c.unit else None,
                    dtype=np.dtype(np.float32 if is_float32 else np.float64),
                )
                channels.append(ch)
                by_name.setdefault(c.name, []).append(ch)
                aliases.setdefault(f"{gi}/{c.name}", ch)
    finally:
        mdf.close()
    for name, chs in by_name.items():
        if len(chs) > 1:
            ambiguous[name] = (
                f"channel '{name}' is in channel groups {', '.join(str(ch.key[0]) for ch in chs)}; "
                "give the run's group (the channel-group index)"
            )

    def rate_for(chans) -> float:
        groups_used = sorted({ch.key[0] for ch in chans})
        if len(groups_used) > 1:
            raise RecordingError(
                f"{display}: the run's channels lie in channel groups {', '.join(map(str, groups_used))}, "
                "each with its own time channel; give the run's group"
            )
        return _group_rate(str(path), display, groups_used[0], chans[0].n_samples)

    return DaqFile(
        display=display,
        channels=tuple(channels),
        aliases=aliases,
        ambiguous=ambiguous,
        rate_origin="the channel group's time channel",
        rate_for=rate_for,
        make_source=lambda chans, dtype: MdfSource(
            keys=[ch.key for ch in chans], n_samples=chans[0].n_samples, dtype=dtype, path=str(path)
        ),
    )


def _group_rate(path: str, display: str, group: int, n: int) -> float:
    """The sample rate of channel group ``group`` from its time channel, read in chunks."""
    from asammdf import MDF

    where = f"{display}: channel group {group}: time channel"
    with quiet_logger("asammdf"):
        mdf = MDF(path)
        try:
            def read(a, b):
                return mdf.get_master(group, record_offset=a, record_count=b - a)

            try:
                return rate_from_time(read, n, where)
            except RecordingError:
                raise
            except Exception as exc:  # noqa: BLE001 - asammdf's own errors on a damaged block
                raise RecordingError(f"{where}: cannot be read ({_first_line(exc)})") from None
        finally:
            mdf.close()


FORMATS = (
    FileFormat(
        name="ASAM MDF 4", suffixes=SUFFIXES, kind="daq", read=open_daq, extra="daq", streaming=True
    ),
)
