"""NI TDMS files (LabVIEW, DAQmx, FlexLogger) as a test setup's DAQ files, read with npTDMS.

A TDMS file holds groups of channels. A setup's ``source`` is a channel's
name, or ``group/channel``; a run's ``group`` picks one group of a file that
holds several runs (``test-setup-format.md``). The sample rate is
``1 / wf_increment`` of the channels (every channel of a run must agree);
the unit the file states is the channel property ``unit_string``. Only the
metadata is read when the setup is opened; samples are read in slices
through npTDMS's streaming mode (:meth:`nptdms.TdmsFile.open`), so memory
is bounded by the block a caller asks for. DAQmx raw data with scaling
information is read scaled, as npTDMS gives it.

Examples
--------
>>> import os, tempfile
>>> import numpy as np
>>> from nptdms import ChannelObject, TdmsWriter
>>> from guidefit.io._daq import RunOptions
>>> with tempfile.TemporaryDirectory() as folder:
...     path = os.path.join(folder, "hit.tdms")
...     with TdmsWriter(path) as writer:
...         writer.write_segment([ChannelObject("run1", "Hammer", np.arange(8.0),
...                               properties={"wf_increment": 1 / 51200, "unit_string": "V"})])
...     daq = open_daq(Path(path), "hit.tdms", RunOptions("test.toml: runs.a"))
...     ch = daq.find("Hammer")
...     block = daq.make_source((ch,), np.float64).read((slice(2, 5), slice(None)))
>>> ch.sample_rate_hz, ch.unit, block[:, 0].tolist()
(51200.0, 'V', [2.0, 3.0, 4.0])
"""

from __future__ import annotations

import contextlib
import math
from pathlib import Path

import numpy as np

from guidefit.errors import RecordingError
from guidefit.io._checks import _first_line, _require
from guidefit.io._daq import ColumnSource, DaqChannel, DaqFile, RunOptions, nice_rate, quiet_logger
from guidefit.io.registry import FileFormat

__all__ = ["TdmsSource", "open_daq"]

SUFFIXES = (".tdms",)


class TdmsSource(ColumnSource):
    """Channels of a TDMS file, read in slices (npTDMS streaming mode); keys are (group, channel)."""

    @contextlib.contextmanager
    def _open(self):
        from nptdms import TdmsFile

        with quiet_logger("nptdms"), TdmsFile.open(self.facts["path"]) as f:
            yield f

    def _read(self, handle, start, stop, keys):
        return [handle[group][channel][start:stop] for group, channel in keys]


def _rate(channel) -> float | None:
    """``1 / wf_increment``; None when the channel has no ``wf_increment``, NaN when it has one that
    is no time step (0, negative, not finite, text, or too small for its reciprocal to be finite):
    the setup refuses a run that uses such a channel rather than take the rate from elsewhere."""
    if "wf_increment" not in channel.properties:
        return None
    try:
        inc = float(channel.properties["wf_increment"])
    except (TypeError, ValueError):
        return math.nan
    if not math.isfinite(inc) or inc <= 0 or not math.isfinite(1.0 / inc):
        return math.nan
    return nice_rate(1.0 / inc)


def _start(channel) -> tuple | None:
    """(wf_start_time in ns since 1970, wf_start_offset in s), or None when neither is given; an offset
    of NaN when one is given that is no time (text, NaN): the setup cannot compare it, and refuses."""
    props = channel.properties
    if "wf_start_time" not in props and "wf_start_offset" not in props:
        return None
    try:
        ns = int(np.datetime64(props.get("wf_start_time", np.datetime64(0, "ns")), "ns").astype(np.int64))
        offset = float(props.get("wf_start_offset", 0.0))
    except (TypeError, ValueError):
        return 0, math.nan
    return ns, offset


def _dtype(channel) -> np.dtype:
    scaled = any(str(k).startswith("NI_Scal") or str(k) == "NI_Number_Of_Scales" for k in channel.properties)
    try:
        dt = np.dtype(channel.dtype)
    except TypeError:
        return np.dtype(object)
    if dt.kind in "iub" or scaled:
        return np.dtype(np.float64) if dt.kind in "iubf" else dt
    return dt


def open_daq(path: Path, display: str, options: RunOptions) -> DaqFile:
    """The channels of a TDMS file (metadata only) for a setup's run.

    Parameters
    ----------
    path : pathlib.Path
    display : str
        The file as the user sees it, for messages.
    options : RunOptions
        ``group``: the TDMS group of this run (default: every group).

    Raises
    ------
    RecordingError
        npTDMS missing, not a TDMS file, an unknown group, channels of the
        run's group with different ``wf_increment``.
    """
    nptdms = _require("nptdms", "daq", display, "NI TDMS")
    try:
        with quiet_logger("nptdms"):
            f = nptdms.TdmsFile.read_metadata(str(path))
        groups = list(f.groups())
    except (ValueError, KeyError, OSError, EOFError, RuntimeError, TypeError) as exc:
        raise RecordingError(f"{display}: not a readable TDMS file ({_first_line(exc)})") from None
    names = [g.name for g in groups]
    if options.group is not None:
        group = str(options.group)
        if group not in names:
            raise RecordingError(
                f"{options.where}: group '{group}' is not in {display}; the file has groups "
                f"{', '.join(names) or '(none)'}"
            )
        groups = [g for g in groups if g.name == group]
    several = len(groups) > 1
    channels, aliases, ambiguous, by_name = [], {}, {}, {}
    for g in groups:
        for c in g.channels():
            ch = DaqChannel(
                name=f"{g.name}/{c.name}" if several else c.name,
                key=(g.name, c.name),
                n_samples=len(c),
                unit=str(c.properties.get("unit_string", "")).strip() or None,
                sample_rate_hz=_rate(c),
                dtype=_dtype(c),
                start=_start(c),
            )
            channels.append(ch)
            aliases[f"{g.name}/{c.name}"] = ch
            by_name.setdefault(c.name, []).append(ch)
    for name, chs in by_name.items():
        if len(chs) == 1:
            aliases.setdefault(name, chs[0])
        else:
            ambiguous[name] = (
                f"channel '{name}' is in groups {', '.join(ch.key[0] for ch in chs)}; "
                "give the run's group or 'group/channel' as source"
            )
    return DaqFile(
        display=display,
        channels=tuple(channels),
        aliases=aliases,
        ambiguous=ambiguous,
        sample_rate_hz=None,  # one per channel (wf_increment); the setup checks a run's agree
        rate_origin="wf_increment",
        make_source=lambda chans, dtype: TdmsSource(
            keys=[ch.key for ch in chans], n_samples=chans[0].n_samples, dtype=dtype, path=str(path)
        ),
    )


FORMATS = (
    FileFormat(name="NI TDMS", suffixes=SUFFIXES, kind="daq", read=open_daq, extra="daq", streaming=True),
)
