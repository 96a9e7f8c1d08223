"""Compatibility: the recording API now lives in :mod:`guidefit.io`.

Every public name this module had is re-exported here, so
``from guidefit.recording import read_recording`` keeps working. New code
imports from :mod:`guidefit.io`.
"""

from guidefit.io import (  # noqa: F401
    ACCELERATION_UNITS,
    FORCE_UNITS,
    FORMAT_NAME,
    FORMAT_VERSION,
    LAYOUTS,
    STANDARD_GRAVITY,
    UNIT_VECTOR_TOLERANCE,
    Channel,
    Recording,
    RecordingData,
    Run,
    RunData,
    RunReader,
    SignalsWriter,
    default_channel_geometry,
    default_points,
    open_reader,
    open_signals_writer,
    read_block,
    read_hit,
    read_recording,
    write_recording,
)
from guidefit.io.watchdog import HDF5_METADATA_TIMEOUT_S  # noqa: F401

__all__ = [
    "ACCELERATION_UNITS",
    "FORCE_UNITS",
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "LAYOUTS",
    "STANDARD_GRAVITY",
    "Channel",
    "Recording",
    "RecordingData",
    "Run",
    "RunData",
    "RunReader",
    "SignalsWriter",
    "default_channel_geometry",
    "default_points",
    "open_reader",
    "open_signals_writer",
    "read_block",
    "read_hit",
    "read_recording",
    "write_recording",
]
