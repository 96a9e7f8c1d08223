"""Test-wide fixtures."""

import os

import pytest
from hypothesis import settings

# The property tests draw the same examples on every run by default, so that a red CI means that a
# change broke something, not that a new random draw found an old defect (one did: every sensor at
# one point, now a fixed example of test_input_properties). HYPOTHESIS_PROFILE=explore draws new
# examples each run: the way to hunt for hostile inputs (README, "Tests").
settings.register_profile("ci", derandomize=True)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))


@pytest.fixture(autouse=True)
def _command_line_environment_stays_in_its_test():
    """The command line sets GUIDEFIT_HDF5_TIMEOUT_S (and the BLAS thread counts) with
    ``os.environ.setdefault``; a CliRunner test runs it in this process, so put the
    environment back after each test: other tests call the library as a library."""
    names = ("GUIDEFIT_HDF5_TIMEOUT_S", "OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
    before = {name: os.environ.get(name) for name in names}
    from guidefit.io import watchdog

    imports = watchdog.IMPORTS_WHILE_WAITING  # the identify commands set them
    yield
    watchdog.IMPORTS_WHILE_WAITING = imports
    for name, value in before.items():
        if value is None:
            os.environ.pop(name, None)
        else:
            os.environ[name] = value
