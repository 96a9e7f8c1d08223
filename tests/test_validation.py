"""The independent validation recordings (``../shared/validation``, a separately written simulator).

Runs the validation's own ``check.py`` on guidefit as installed here (``python -m guidefit``): four
recordings of one MRB35 carriage in four sensor layouts (one axis per run at A-D, side-face lateral
sensors, triaxial at A and C, two sensors per run), f within 0.1 %, K within 0.2 %, zeta and c within
5 %, every std covering its error. Skipped when ``../shared`` is not beside the checkout.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

CHECK = Path(__file__).resolve().parents[2] / "shared" / "validation" / "check.py"


@pytest.mark.skipif(not CHECK.exists(), reason=f"validation recordings not found at {CHECK.parent}")
def test_independent_validation_recordings_pass():
    out = subprocess.run([sys.executable, str(CHECK), "--guidefit", f"{sys.executable} -m guidefit"],
                         check=False, capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, out.stdout + out.stderr
    assert " recordings pass" in out.stdout and "FAIL" not in out.stdout
