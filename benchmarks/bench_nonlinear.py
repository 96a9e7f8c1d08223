"""Nonlinear contacts: forward model vs describing function vs the full time-domain simulation.

A recording of the vertical hammer run at three force levels (default 100,
1000 and 5000 N, one run each, ``guidefit.nonlinear.simulate_force_levels``:
the simulator's RK4 integration of the preloaded Hertz rollers at 4x the
sample rate, anti-alias filter, sensor noise, 16-bit ADC) is the "truth".
Its levels are measured by ``guidefit.nonlinear.measure_levels`` (windows,
H1, one-pole fit). At the true preload factor the script predicts every
level with the forward model (``ForwardModel.predict``) and with the
describing function of ``amplitude_dependence`` (which models a one-pole
fit, not the peak centroid: compared as drops from the lowest level), then fits the preload
factor (and K_n) with ``fit_levels`` and runs ``guidefit.explain`` on the
file. Prints markdown tables (docs/explain.md, "Nonlinear contacts: the
forward model").

    python benchmarks/bench_nonlinear.py [--preload 1.0] [--hits 6] [--record 0.05] [--seed 0] [--no-explain]
"""

from __future__ import annotations

import argparse
import math
import tempfile
import time
from pathlib import Path

import numpy as np


def lost_contact(model, level, force: float) -> int:
    """Rollers that lose contact at any instant after one hit of ``force`` (N)."""
    from guidefit.model import vibration as vib
    from guidefit.simulate import integrate_contacts

    s = level.setup
    c = model.contacts
    d = np.asarray(s.hit_direction, float)
    b = np.zeros(c.M.shape[0])
    b[:5] = d / np.linalg.norm(d) @ vib.rigid_body_map(s.hit_position_m)
    t = np.arange(int(0.01 * 200e3)) / 200e3
    _, dq, _ = integrate_contacts(c, b, [(force, 1e-4, s.pulse_s)], t, tolerance=0.0, return_states=True)
    delta = c.delta0[None, :] - (c.q0[None, :] + dq) @ c.G.T
    return int(np.count_nonzero(np.any(delta <= 0, axis=0)))


def describing_function(guide, level, preload: float) -> float:
    """The describing-function prediction of explain's amplitude_dependence for a level (Hz)."""
    from guidefit.model import vibration as vib
    from guidefit.model.effects import amplitude_dependence as ad

    spec = ad.apply(vib.model_from_guide(guide), guide, {"preload_factor": preload})
    sol = vib.solve_modes(spec)
    j = sol.labels.index(level.label)
    lo, hi = level.band_hz
    d = np.asarray(level.setup.hit_direction, float)
    hit = (level.setup.hit_position_m, d / np.linalg.norm(d), level.setup.pulse_s)
    zetas = np.full(sol.frequencies_hz.size, np.nan)
    zetas[j] = level.reference_damping
    return ad.amplitude_frequency(guide, spec, sol, j, ad.effective_force(level.hit_forces_n), hit, preload,
                                  zetas=zetas, band=(hi - lo) / (hi + lo))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--preload", type=float, default=1.0)
    ap.add_argument("--forces", default="100,1000,5000")
    ap.add_argument("--hits", type=int, default=6)
    ap.add_argument("--record", type=float, default=0.05)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--no-explain", action="store_true")
    args = ap.parse_args()

    from guidefit.explain import explain, identify_for_explain
    from guidefit.io import write_recording
    from guidefit.model.guides import load_guide
    from guidefit.nonlinear import ForwardModel, fit_levels, measure_levels, simulate_force_levels

    guide = load_guide("MRB35")
    forces = [float(x) for x in args.forces.split(",")]
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "levels.h5"
        t0 = time.process_time()
        data, _ = simulate_force_levels(guide, [f"amplitude_dependence:preload_factor={args.preload}"], forces,
                                        hits=args.hits, record_s=args.record, seed=args.seed)
        write_recording(path, data)
        t_sim = time.process_time() - t0
        t0 = time.process_time()
        ident = identify_for_explain(path)
        t_id = time.process_time() - t0
        notes: list = []
        levels = measure_levels(ident, notes=notes)
        fm = ForwardModel(guide, levels)
        t0 = time.process_time()
        pred = fm.predict(args.preload)
        t_fwd = time.process_time() - t0
        model = fm.model(args.preload)
        print(f"simulation {t_sim:.1f} s, identify {t_id:.1f} s, one forward-model evaluation "
              f"({len(levels)} levels x {fm.n_hits} hits) {t_fwd:.2f} s CPU; notes: {notes}\n")
        print("| level | rollers losing contact (of 84) | truth (full chain) | forward model | error | "
              "drop from the lowest level: truth | forward model | describing function |")
        print("|---|---|---|---|---|---|---|---|")
        dfs = [describing_function(guide, lv, args.preload) for lv in levels]
        for lv, p, df in zip(levels, pred, dfs):
            n_lost = lost_contact(model, lv, float(np.max(lv.hit_forces_n)))
            print(f"| {lv.peak_force_n:.0f} N | {n_lost} | {lv.frequency_hz:.1f} Hz | {p.frequency_hz:.1f} Hz | "
                  f"{100 * (p.frequency_hz / lv.frequency_hz - 1):+.3f} % | "
                  f"{100 * (lv.frequency_hz / levels[0].frequency_hz - 1):+.3f} % | "
                  f"{100 * (p.frequency_hz / pred[0].frequency_hz - 1):+.3f} % | {100 * (df / dfs[0] - 1):+.3f} % |")
        fit = fit_levels(levels, guide)
        print(f"\nfit_levels: preload factor {fit.preload_factor:.4f} +/- {fit.preload_std:.4f} "
              f"(truth {args.preload}), K_n factor {fit.kn_factor:.4f} +/- {fit.kn_std:.4f}, chi2 {fit.chi2:.2f} "
              f"for {fit.dof} dof, {fit.evaluations} evaluations, {fit.seconds:.1f} s CPU")
        print("\n| level | measured | fitted model | sigma | error / sigma |\n|---|---|---|---|---|")
        for row in fit.rows():
            print(f"| {row['peak_force_n']:.0f} N | {row['measured_hz']:.2f} Hz | {row['predicted_hz']:.2f} Hz | "
                  f"{row['sigma_hz']:.2f} Hz | {(row['predicted_hz'] - row['measured_hz']) / row['sigma_hz']:+.2f} |")
        if not args.no_explain:
            t0 = time.process_time()
            result = explain(ident)
            t_ex = time.process_time() - t0
            d = result.to_dict()
            eff = [(e["name"], {k: (round(v["value"], 4), round(v["std"] or math.nan, 4))
                                for k, v in e["parameters"].items()}) for e in d["effects"]]
            print(f"\nexplain: {d['verdict']} {eff}; RMS error before {d['error_before']['rms_frequency_error_pct']:.3f} %, "
                  f"after {d['error_after']['rms_frequency_error_pct']:.4f} % (uncertainty "
                  f"{d['error_after']['rms_uncertainty_pct']:.3f} %), chi2 {d['error_after']['chi2']:.2f} for "
                  f"{d['error_after']['dof']} dof; {t_ex:.1f} s CPU")
            amp = [e for e in d["effects"] if e["name"] == "amplitude_dependence"]
            if amp:
                p_ex = amp[0]["parameters"]["preload_factor"]["value"]
                print("\n| level | measured | model at explain's preload | sigma | error / sigma |\n|---|---|---|---|---|")
                for lv, x in zip(levels, fm.predict(p_ex)):
                    print(f"| {lv.peak_force_n:.0f} N | {lv.frequency_hz:.2f} Hz | {x.frequency_hz:.2f} Hz | "
                          f"{lv.sigma_hz():.2f} Hz | {(x.frequency_hz - lv.frequency_hz) / lv.sigma_hz():+.2f} |")


if __name__ == "__main__":
    main()
