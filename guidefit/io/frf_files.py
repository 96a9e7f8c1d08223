"""FRF files: guidefit's own ``frf.csv`` and ``frf.h5`` (UFF-58 FRFs: :mod:`guidefit.io.uff`).

The layouts are documented with their writers,
:func:`guidefit.frf.write_frf_csv` and :func:`guidefit.frf.write_frf_h5`
(reader :func:`guidefit.frf.read_frf_h5`); this module declares them to the
registry, so :func:`guidefit.io.write_frfs` picks the writer by suffix.
"""

from __future__ import annotations

from guidefit.io.registry import FileFormat

__all__ = ["write_frf_csv_file", "write_frf_h5_file"]


def write_frf_csv_file(path, frfsets, *, recording=None) -> None:
    """:func:`guidefit.frf.write_frf_csv` (``recording`` is not used by CSV)."""
    from guidefit.frf import write_frf_csv

    write_frf_csv(path, frfsets)


def write_frf_h5_file(path, frfsets, *, recording=None) -> None:
    """:func:`guidefit.frf.write_frf_h5` (``recording`` is not used by HDF5).

    The file is built in memory and written with one plain write: a disk write failing
    inside libhdf5 (full disk, file-size limit) leaves h5py objects that crash the
    interpreter when freed; a failing Python write is one OSError.
    """
    import io

    from guidefit.frf import write_frf_h5

    image = io.BytesIO()
    write_frf_h5(image, frfsets)
    with open(path, "wb") as out:
        out.write(image.getbuffer())


FORMATS = (
    FileFormat(name="guidefit FRFs, CSV", suffixes=(".csv",), kind="frf", write=write_frf_csv_file),
    FileFormat(
        name="guidefit FRFs, HDF5",
        suffixes=(".h5", ".hdf5"),
        kind="frf",
        write=write_frf_h5_file,
    ),
)
