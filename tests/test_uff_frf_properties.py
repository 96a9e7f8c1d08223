"""Property tests of the UFF-58 FRF reader (issue 21): fields of guidefit's own FRF file rewritten with
hostile values, a few at a time, through pyuff as another program would write them.

The promise: :func:`guidefit.io.frf_files.read_frf_file` refuses the file with guidefit's input error in
one line, or gives FRFs whose frequency axis, values and response directions are what the file holds:
finite, increasing frequencies from the abscissa start and step, finite FRFs, one channel per response
DOF. Any other exception (an internal error) fails the test.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from guidefit.errors import GuidefitError

pyuff = pytest.importorskip("pyuff")

#: hostile values of one dataset-58 field
FIELDS = {
    "abscissa_inc": [0.0, -50.0, math.nan, math.inf, 1e-320],
    "abscissa_min": [-100.0, math.nan, math.inf, 1e300],
    "rsp_dir": [0, 4, -7, 9],
    "ref_dir": [0, 5, -6],
    "func_type": [1, 2, 6, 0],
    "ordinate_spec_data_type": [0, 8, 11, 99],
    "orddenom_spec_data_type": [0, 12, 99],
    "rsp_node": [-1, 0],
}
DATA = ["nan", "inf", "zeros", "huge"]


@pytest.fixture(scope="module")
def uff_sets(tmp_path_factory):
    from guidefit.frf import compute_frf
    from guidefit.hits import iter_hits
    from guidefit.io import read_recording, write_recording
    from guidefit.io.uff import write_frf_uff
    from guidefit.simulate import SimulationConfig, simulate

    folder = tmp_path_factory.mktemp("uff_props")
    data, _ = simulate("MRB35", config=SimulationConfig(hits=3, record_s=0.02, sensor_layout="default"), seed=4)
    write_recording(folder / "rec.h5", data)
    recording = read_recording(folder / "rec.h5")
    frfs = [compute_frf(run, iter_hits(run)) for run in recording.runs]
    path = folder / "frf.uff"
    write_frf_uff(path, frfs, recording=recording)
    return pyuff.UFF(str(path)).read_sets()


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(changes=st.dictionaries(st.sampled_from(sorted(FIELDS)), st.integers(0, 4), max_size=2),
       data=st.none() | st.sampled_from(DATA), which=st.integers(0, 15))
def test_uff_frfs_are_read_as_written_or_refused_in_one_line(uff_sets, tmp_path_factory, changes, data, which):
    from guidefit.io.frf_files import read_frf_file

    sets = [dict(s) for s in uff_sets]
    frf_sets = [k for k, s in enumerate(sets) if s.get("type") == 58]
    k = frf_sets[which % len(frf_sets)]
    target = sets[k]
    for name, pick in changes.items():
        options = FIELDS[name]
        target[name] = options[pick % len(options)]
    if data is not None:
        values = np.array(target["data"], dtype=complex)
        values[len(values) // 2] = {"nan": complex(math.nan, 0), "inf": complex(math.inf, 0), "zeros": 0,
                                     "huge": 1e300}[data]
        if data == "zeros":
            values[:] = 0
        target["data"] = values
    path = tmp_path_factory.mktemp("case") / "frf.uff"
    try:
        pyuff.UFF(str(path)).write_sets(sets, mode="add")
    except Exception:  # noqa: BLE001 - pyuff cannot write this value: nothing to read
        return
    try:
        got = read_frf_file(path)
    except GuidefitError as exc:
        assert "\n" not in str(exc) and str(exc)
        return
    for run, frf in zip(got.recording.runs, got.frfsets):
        f = np.asarray(frf.frequency_hz, float)
        assert np.all(np.isfinite(f)) and f[0] >= 0 and np.all(np.diff(f) > 0), run.name
        assert np.all(np.isfinite(frf.H)), run.name
        assert len(set(frf.channels)) == len(frf.channels) == np.shape(frf.H)[1]
        for ch in run.channels:
            d = np.asarray(ch.direction, float)
            assert d.shape == (3,) and abs(np.linalg.norm(d) - 1) < 1e-6, ch.name
