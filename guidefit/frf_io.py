"""Writing FRF sets by file type: CSV, HDF5 (:mod:`guidefit.frf`) and UFF-58 (:mod:`guidefit.uff`)."""

from __future__ import annotations

from pathlib import Path

from guidefit.errors import RecordingError


def write_frfs(path, frfsets, recording=None) -> None:
    """Write FRF sets to ``path``; the suffix chooses the format (.csv, .h5/.hdf5, .uff/.unv).

    ``recording`` (the source :class:`~guidefit.recording.Recording`) gives UFF
    files the exact excitation and sensor directions.
    """
    suffix = Path(path).suffix.lower()
    if suffix == ".csv":
        from guidefit.frf import write_frf_csv

        write_frf_csv(path, frfsets)
    elif suffix in (".h5", ".hdf5"):
        from guidefit.frf import write_frf_h5

        write_frf_h5(path, frfsets)
    elif suffix in (".uff", ".unv"):
        from guidefit.uff import write_frf_uff

        write_frf_uff(path, frfsets, recording=recording)
    else:
        raise RecordingError(f"{path}: unknown FRF output type '{suffix}'; use .csv, .h5 or .uff")
