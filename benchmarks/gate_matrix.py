"""Sensor consistency and the plausibility gate over the effect matrix and the sensor faults.

Each case is a seeded simulated MRB35 hammer test (:func:`guidefit.simulate.simulate`,
3 hits of 20 ms per run, sensors A-D in x and y, seed 2) with the effects of
``benchmarks/explain_matrix.py`` (the test object has them, identify is not
told), then identified (no jackknife). The fault rows take the nominal
recording (seed 1, also z sensors) and change one channel's samples
afterwards: negate, scale, or take another axis's samples. One Markdown row
per case: the relative RMS rigid-fit residual of all mode shapes before any
correction, the faults named (channel, kind, factor), the gate, the errors
of f_V and f_H against the truth and identify's wall time.

Expected: every effect row silent (no fault, no gate), every fault row one
fault with the right channel and size and f within 0.02 %.

Run: ``python benchmarks/gate_matrix.py [--quick]`` (quick: four effect rows, two faults).
"""

from __future__ import annotations

import argparse
import math
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

EFFECT_CASES = [
    ("nominal", []),
    ("added_mass ABCD 0.1 kg", ["added_mass:mass_kg=0.1,at=ABCD"]),
    ("added_mass A 0.1 kg", ["added_mass:mass_kg=0.1,at=A"]),
    ("added_mass A 0.3 kg", ["added_mass:mass_kg=0.3,at=A"]),
    ("support lateral 1.2e8 (paper)", ["support_compliance:lateral_n_per_m=1.2e8"]),
    ("support lateral + rail 1 kg", ["support_compliance:lateral_n_per_m=1.2e8,mass_kg=1.0"]),
    ("support vertical 5e9", ["support_compliance:vertical_n_per_m=5e9"]),
    ("support roll 4e5", ["support_compliance:roll_nm_per_rad=4e5"]),
    ("contact_stiffness 0.8", ["contact_stiffness:factor=0.8"]),
    ("base vertical 3 kg", ["base_mode:mass_kg=3.0,vertical_n_per_m=3e9"]),
    ("base lateral 1.5 kg", ["base_mode:mass_kg=1.5,lateral_n_per_m=2e9"]),
    ("row_damage row 2 x0.5", ["row_damage:row=2,factor=0.5"]),
    ("row_damage row 1 x0.2", ["row_damage:row=1,factor=0.2"]),
    ("com_offset y -12 mm", ["com_offset:y_m=-0.012"]),
    ("support lateral + added_mass", ["support_compliance:lateral_n_per_m=1.2e8", "added_mass:mass_kg=0.1,at=ABCD"]),
    ("contact 0.9 + row 3 x0.6", ["contact_stiffness:factor=0.9", "row_damage:row=3,factor=0.6"]),
    ("amplitude_dependence 0.5", ["amplitude_dependence:preload_factor=0.5"]),
]

G = 9.80665
FAULT_CASES = [
    ("acc_B_y sign", "acc_B_y", -1.0, None),
    ("acc_C_y x9.81", "acc_C_y", G, None),
    ("acc_A_x x1000", "acc_A_x", 1000.0, None),
    ("acc_D_x x1/9.81", "acc_D_x", 1 / G, None),
    ("acc_A_x sign", "acc_A_x", -1.0, None),
    ("acc_D_y x10", "acc_D_y", 10.0, None),
    ("acc_A_y reads z", "acc_A_y", 1.0, "acc_A_z"),
    ("acc_B_x reads y", "acc_B_x", 1.0, "acc_B_y"),
    ("acc_B_y sign + acc_D_x x9.81", ("acc_B_y", "acc_D_x"), (-1.0, G), None),
]


def _edit(data, channel=None, factor=1.0, take_from=None):
    if isinstance(channel, tuple):  # several channels, one factor each
        for ch, fac in zip(channel, factor):
            data = _edit(data, ch, fac)
        return data
    runs = []
    for run in data.runs:
        names = list(run.channel_names)
        d = np.array(run.data, dtype=np.float64)
        if channel in names:
            j = names.index(channel)
            if take_from:
                d[..., j] = d[..., names.index(take_from)]
            d[..., j] *= factor
        keep = [i for i, n in enumerate(names) if not n.endswith("_z")]
        runs.append(replace(run, data=d[..., keep], channel_names=tuple(names[i] for i in keep),
                            units=tuple(run.units[i] for i in keep), positions_m=np.asarray(run.positions_m)[keep],
                            directions=np.asarray(run.directions)[keep]))
    return replace(data, runs=tuple(runs))


def _relres(result, path) -> float:
    from guidefit import consistency as cons
    from guidefit.io import read_recording

    modes = [m for run in result.runs for m in run.modes]
    sets = cons._normalised(cons.shape_sets(result.runs, modes, cons._hit_points(read_recording(path))))
    res, energy = cons._total(sets)
    return math.sqrt(res / energy) if energy else math.nan


def row(name, data, truth, folder: Path) -> str:
    from guidefit.identify import IdentifySettings, identify
    from guidefit.io import write_recording

    path = folder / f"{abs(hash(name))}.h5"
    write_recording(path, data)
    started = time.perf_counter()
    result = identify(path, settings=IdentifySettings(jackknife=False))
    wall = time.perf_counter() - started
    # before any correction: the residual of the modes as the first fit saw them (faulty files) is in the fault
    before = result.sensor_faults[0].relres_before if result.sensor_faults else _relres(result, path)
    faults = "; ".join(f"{f.channel} {f.kind} {f.axis or ''}{f.factor:+.4g}" + (" or " + ",".join(f.alternatives)
                       if f.alternatives else "") for f in result.sensor_faults) or "-"
    p, t = result.parameters, truth["parameters"]
    err = [f"{100 * (p[k]['value'] / t[k]['value'] - 1):+.4f}" if p[k]["value"] else "-" for k in ("f_V", "f_H")]
    return f"| {name} | {100 * before:.3f} | {faults} | {result.gate or '-'} | {err[0]} | {err[1]} | {wall:.2f} |"


def main() -> None:
    from guidefit.simulate import SimulationConfig, simulate

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args()
    effects = EFFECT_CASES[:4] if args.quick else EFFECT_CASES
    faults = FAULT_CASES[:2] if args.quick else FAULT_CASES
    print("| case | rigid residual % | faults named | gate | f_V err % | f_H err % | identify s |")
    print("|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for name, eff in effects:
            data, truth = simulate("MRB35", eff, config=SimulationConfig(hits=3, record_s=0.02), seed=2)
            print(row(name, data, truth, folder), flush=True)
        base, truth = simulate("MRB35", config=SimulationConfig(hits=3, record_s=0.02, axes="xyz"), seed=1)
        for name, channel, factor, take_from in faults:
            print(row(name, _edit(base, channel, factor, take_from), truth, folder), flush=True)


if __name__ == "__main__":
    main()
