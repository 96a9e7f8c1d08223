"""Test-wide fixtures."""

import os

import pytest


@pytest.fixture(autouse=True)
def _command_line_environment_stays_in_its_test():
    """The command line sets GUIDEFIT_HDF5_TIMEOUT_S (and the BLAS thread counts) with
    ``os.environ.setdefault``; a CliRunner test runs it in this process, so put the
    environment back after each test: other tests call the library as a library."""
    names = ("GUIDEFIT_HDF5_TIMEOUT_S", "OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
    before = {name: os.environ.get(name) for name in names}
    yield
    for name, value in before.items():
        if value is None:
            os.environ.pop(name, None)
        else:
            os.environ[name] = value
