"""The forked metadata reader of the command line (guidefit.io.watchdog) and what the parent does meanwhile."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from guidefit.io import watchdog

SAMPLE = Path(__file__).resolve().parents[1] / "sample_data" / "mrb35_sample.h5"

pytestmark = pytest.mark.skipif(not watchdog.can_fork(), reason="the guard forks (Linux)")


def test_the_parent_imports_while_the_child_reads_and_skips_what_fails():
    """In a fresh interpreter: the guarded read gives the unguarded read's recording, and the modules of
    IMPORTS_WHILE_WAITING are imported meanwhile (one that does not exist is skipped, not an error)."""
    code = (
        "import sys\n"
        "from guidefit.io import watchdog, read_recording\n"
        "assert 'xml.dom.minidom' not in sys.modules\n"
        "watchdog.IMPORTS_WHILE_WAITING = ('xml.dom.minidom', 'no_such_module_of_guidefit')\n"
        f"rec = read_recording({str(SAMPLE)!r})\n"
        "print('xml.dom.minidom' in sys.modules, [r.name for r in rec.runs], rec.runs[0].n_hits_stored)\n"
    )
    env = {**os.environ, "GUIDEFIT_HDF5_TIMEOUT_S": "30"}
    guarded = subprocess.run([sys.executable, "-c", code], check=False, capture_output=True, text=True, env=env, timeout=120)
    assert guarded.returncode == 0, guarded.stderr
    env["GUIDEFIT_HDF5_TIMEOUT_S"] = "0"  # no fork: nothing is imported while waiting
    plain = subprocess.run([sys.executable, "-c", code], check=False, capture_output=True, text=True, env=env, timeout=120)
    assert plain.returncode == 0, plain.stderr
    assert guarded.stdout.split(" ", 1)[0] == "True" and plain.stdout.split(" ", 1)[0] == "False"
    assert guarded.stdout.split(" ", 1)[1] == plain.stdout.split(" ", 1)[1]  # the same recording


def test_the_identify_commands_name_modules_that_exist():
    import importlib.util

    from guidefit.cli import AFTER_METADATA_IMPORTS

    assert all(importlib.util.find_spec(name) is not None for name in AFTER_METADATA_IMPORTS)
