"""WAV files (audio-interface DAQs, recorders) as a test setup's DAQ files, read with soundfile.

A setup's ``source`` is the channel index ``0``, ``1``, ... (0-based); the
sample rate is the WAV header's. soundfile gives integer PCM samples as
fractions of full scale (-1 to 1) and float WAV samples as stored, so a
setup gives each channel's ``scale`` (its unit per full scale, from the
interface's calibration) or ``sensitivity_mv`` (when full scale is 1 V). The
WAV header states no unit. Samples are read in slices (seek and read), so
memory is bounded by the block a caller asks for.

Examples
--------
>>> import os, tempfile
>>> import numpy as np
>>> import soundfile
>>> from guidefit.io._daq import RunOptions
>>> with tempfile.TemporaryDirectory() as folder:
...     path = os.path.join(folder, "hit.wav")
...     soundfile.write(path, np.array([[0.0, 0.5], [0.25, -0.5], [0.5, 0.0]]), 48000, subtype="FLOAT")
...     daq = open_daq(Path(path), "hit.wav", RunOptions("test.toml: runs.a"))
...     ch = daq.find("1")
...     block = daq.make_source((ch,), ch.dtype).read((slice(0, 2), slice(None)))
>>> daq.sample_rate_hz, [c.name for c in daq.channels], block[:, 0].tolist()
(48000.0, ['0', '1'], [0.5, -0.5])
"""

from __future__ import annotations

import contextlib
from pathlib import Path

import numpy as np

from guidefit.errors import RecordingError
from guidefit.io._checks import _first_line, _require
from guidefit.io._daq import ColumnSource, DaqChannel, DaqFile, RunOptions
from guidefit.io.registry import FileFormat

__all__ = ["WavSource", "open_daq"]

SUFFIXES = (".wav",)
_DOUBLE_SUBTYPES = ("PCM_32", "DOUBLE")  # more than float32's 24 bits of mantissa


class WavSource(ColumnSource):
    """Channels of a WAV file by index, read frame range by frame range."""

    @contextlib.contextmanager
    def _open(self):
        import soundfile

        with soundfile.SoundFile(self.facts["path"]) as f:
            yield f

    def _read(self, handle, start, stop, keys):
        handle.seek(start)
        frames = handle.read(stop - start, dtype="float64" if self.dtype == np.float64 else "float32",
                             always_2d=True)
        return [frames[:, k] for k in keys]


def open_daq(path: Path, display: str, options: RunOptions) -> DaqFile:
    """The channels of a WAV file (its header) for a setup's run.

    Raises
    ------
    RecordingError
        soundfile missing, not a sound file soundfile reads, a ``group`` given.
    """
    soundfile = _require("soundfile", "daq", display, "WAV")
    if options.group is not None:
        raise RecordingError(f"{options.where}: group: a WAV file holds one run; remove the key")
    try:
        info = soundfile.info(str(path))
    except (RuntimeError, OSError, ValueError, TypeError) as exc:
        raise RecordingError(f"{display}: not a readable WAV file ({_first_line(exc)})") from None
    dtype = np.dtype(np.float64 if info.subtype in _DOUBLE_SUBTYPES else np.float32)
    channels = tuple(
        DaqChannel(name=str(k), key=k, n_samples=int(info.frames), dtype=dtype) for k in range(int(info.channels))
    )
    return DaqFile(
        display=display,
        channels=channels,
        sample_rate_hz=float(info.samplerate),
        rate_origin="the WAV header",
        make_source=lambda chans, dt: WavSource(
            keys=[ch.key for ch in chans], n_samples=chans[0].n_samples, dtype=dt, path=str(path)
        ),
    )


FORMATS = (
    FileFormat(name="WAV", suffixes=SUFFIXES, kind="daq", read=open_daq, extra="daq", streaming=True),
)
