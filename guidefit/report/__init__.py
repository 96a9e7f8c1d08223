"""Rendering: rich tables, JSON and plots. Display units live here, numerics do not."""

from __future__ import annotations

import json
import math
import sys


def _console(stderr: bool = False):
    from rich.console import Console

    return Console(stderr=stderr, highlight=False)


def fmt(value, unit: str = "", digits: int = 4) -> str:
    """Engineering display of a number: ``fmt(1.03e9, 'N/m') -> '1.030e+09 N/m'``.

    >>> fmt(3529.03, "Hz")
    '3529 Hz'
    >>> fmt(None)
    '-'
    """
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    if isinstance(value, str):
        return f"{value} {unit}".strip()
    value = float(value)
    if value != 0 and (abs(value) >= 1e5 or abs(value) < 1e-2):
        text = f"{value:.{digits - 1}e}"
    else:
        text = f"{value:.{digits}g}"
    return f"{text} {unit}".strip()


def dump_json(obj) -> str:
    """One-line JSON with NaN/inf written as null (strict JSON)."""

    def clean(o):
        if isinstance(o, float) and not math.isfinite(o):
            return None
        if isinstance(o, dict):
            return {k: clean(v) for k, v in o.items()}
        if isinstance(o, list | tuple):
            return [clean(v) for v in o]
        if hasattr(o, "item"):
            return clean(o.item())
        return o

    return json.dumps(clean(obj))


def print_guides(guides) -> None:
    """Table of the catalogue."""
    from rich.table import Table

    table = Table(title="guide catalogue")
    for col in ("name", "M (kg)", "rows at (mm)", "beta", "Z_L x span", "K_n (N/m)", "description"):
        table.add_column(col)
    for g in guides:
        table.add_row(
            g.name, f"{g.mass_kg:g}", f"+/-{g.row_offset_m * 1e3:g}, -{g.h1_m * 1e3:g}/-{g.h3_m * 1e3:g}",
            f"{g.contact_angle_deg:g} deg", f"{g.rollers_per_row} x {g.roller_span_m * 1e3:g} mm",
            fmt(g.roller_stiffness_n_per_m), g.description,
        )
    _console().print(table)


def _narrow_table(title: str | None = None):
    """A rich table that fits 80 columns: no outer edge padding, light borders."""
    from rich import box
    from rich.table import Table

    return Table(title=title, box=box.SIMPLE_HEAD, pad_edge=False, collapse_padding=True)


def render_prediction(result, as_json: bool = False, plot_path: str | None = None, console=None) -> None:
    """Print a :class:`guidefit.predict.Prediction` as tables (readable at 80 columns) or one JSON
    document; optional plot. Each stiffness is named for what it is."""
    data = result.to_dict()
    if plot_path:
        _save_figure(lambda path: plot_prediction(result, path), plot_path)
    if as_json:
        print(dump_json(data))
        return
    console = console or _console()
    fv, fh, m = result.load
    st = data["stiffness"]
    table = _narrow_table(f"{result.guide.name} stiffness, load F_V={fv:g} N, F_H={fh:g} N, M={m:g} N m "
                          f"({result.calibration} K_n)")
    table.add_column("stiffness")
    for head in ("K_V (N/m)", "K_H (N/m)", "K_gamma (N m/rad)"):
        table.add_column(head, justify="right")
    table.add_column("Eq.")

    def value(block, key):
        return fmt(block[key]["value"]) if key in block else "-"

    for key, label, eq in (("static_zero_load", "static tangent, zero load", "2"),
                           ("static_at_load", "static tangent, this load", "1-4"),
                           ("apparent_single_dof", "apparent 1-DOF (identify)", "24-25")):
        block = st[key]
        table.add_row(label, value(block, "K_V"), value(block, "K_H"), value(block, "K_gamma"), eq)
    console.print(table)
    console.print(f"K_n {fmt(st['K_n']['value'], 'N/m')} per roller (Eq. 3-4). apparent 1-DOF: 4 pi^2 M f^2 of "
                  "the vertical and roll_low modes, what identify reports; not the static stiffness.",
                  highlight=False)
    modes = _narrow_table(f"{result.guide.name} natural frequencies (Eq. 5-23)")
    modes.add_column("mode")
    modes.add_column("f (Hz)", justify="right")
    modes.add_column("closed form (Hz)", justify="right")
    modes.add_column("Eq.")
    eq = {"vertical": "15", "pitch": "16", "yaw": "17", "roll_low": "18-23", "roll_high": "18-23"}
    for mode in data["modes"]:
        closed = data["closed_form_hz"].get(mode["label"])
        modes.add_row(mode["label"], f"{mode['frequency_hz']:.1f}", "-" if closed is None else f"{closed:.1f}",
                      eq.get(mode["label"], "assembled"))
    console.print(modes)
    if data["rows_lifted"]:
        console.print(f"rows lifted off: {', '.join(map(str, data['rows_lifted']))} (contacts carry compression only)")
    if plot_path:
        console.print(f"plot written to {plot_path}")


#: Sweep table columns: (frame column, heading, digits); the full set is in --json.
_SWEEP_COLUMNS = (("K_V_static_n_per_m", "K_V stat", 3), ("K_H_static_n_per_m", "K_H stat", 3),
                  ("K_V_apparent_n_per_m", "K_V app", 3), ("K_H_apparent_n_per_m", "K_H app", 3),
                  ("f_vertical_hz", "f_V", 4), ("f_roll_low_hz", "f_H", 4), ("rows_lifted", "lifted", 0))


def _sweep_axis(frame) -> tuple[str, str, str]:
    """(column, label, unit) of the swept load."""
    sweep = frame.attrs.get("sweep", {})
    column = sweep.get("column", frame.columns[0])
    unit = sweep.get("unit", "N m" if column.endswith("_nm") else "N")
    names = {"F_V_n": "F_V", "F_H_n": "F_H", "M_gamma_nm": "M_gamma", "load_n": "load", "load_nm": "moment"}
    return column, names.get(column, column), unit


def render_sweep(frame, as_json: bool = False, plot_path: str | None = None, guide_name: str = "",
                 calibration: str = "nominal", console=None) -> None:
    """Print a load sweep (:func:`guidefit.predict.predict_sweep`) as a table readable at 80
    columns, or as ONE JSON document (:func:`guidefit.predict.sweep_document`); optional plot."""
    from guidefit.predict import sweep_document

    limit = frame.attrs.get("limit")
    if plot_path:
        _save_figure(lambda path: plot_sweep(frame, path), plot_path)
    if as_json:
        print(dump_json(sweep_document(frame, guide_name, calibration)))
        if limit:  # stdout is the one JSON document; the user still reads why the sweep is short
            print(f"warning: {limit['message']}", file=sys.stderr)
        return
    console = console or _console()
    column, label, unit = _sweep_axis(frame)
    table = _narrow_table(f"{guide_name} load sweep: K in N/m, f in Hz (all columns: --json)".strip())
    table.add_column(f"{label} ({unit})", justify="right")
    for _, head, _ in _SWEEP_COLUMNS:
        table.add_column(head, justify="right")
    for _, row in frame.iterrows():
        cells = [f"{row[column]:.5g}"]
        for key, _, digits in _SWEEP_COLUMNS:
            v = row[key]
            cells.append(str(v or "-") if not digits else (f"{v:.{digits - 1}e}" if digits == 3 else f"{v:.0f}"))
        table.add_row(*cells)
    console.print(table)
    console.print("stat: static tangent stiffness at the load (Eq. 1-4); app: apparent 1-DOF 4 pi^2 M f^2 "
                  "(Eq. 24-25, what identify reports); f_H: the roll_low mode.", highlight=False)
    if limit:
        console.print(limit["message"], highlight=False, markup=False, soft_wrap=True)
    if plot_path:
        console.print(f"plot written to {plot_path}")


def _save_figure(draw, path) -> None:
    """``draw(tmp)`` writes a figure to a temporary file renamed onto ``path`` when complete."""
    from guidefit.outputs import replacing

    with replacing(path) as tmp:
        draw(tmp)


def _figure(n_rows: int = 1, n_cols: int = 1, size=(8, 5)):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt.subplots(n_rows, n_cols, figsize=size, squeeze=False)


def plot_prediction(result, path: str) -> None:
    """Load-deflection curves (the paper's Figure 3) and the mode frequencies."""
    import matplotlib.pyplot as plt

    from guidefit.model import static

    fig, axes = _figure(1, 2, (11, 4.5))
    for direction, ax_label in (("V", "vertical"), ("H", "lateral")):
        frame = static.load_deflection(result.guide, direction=direction, calibration=result.calibration)
        axes[0, 0].plot(frame.iloc[:, 1] * 1e6, frame.iloc[:, 0] / 1e3, label=ax_label)
    axes[0, 0].set_xlabel("displacement (um)")
    axes[0, 0].set_ylabel("load (kN)")
    axes[0, 0].set_title("load-deflection (Eq. 1-4)")
    axes[0, 0].legend()
    axes[0, 0].grid(True, alpha=0.3)
    modes = result.modes
    order = sorted(range(len(modes.labels)), key=lambda i: modes.frequencies_hz[i])
    axes[0, 1].barh([modes.labels[i] for i in order], [modes.frequencies_hz[i] for i in order])
    axes[0, 1].set_xlabel("natural frequency (Hz)")
    axes[0, 1].set_title(f"{result.guide.name} modes (Eq. 5-23)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_sweep(frame, path: str) -> None:
    """Frequencies (Hz) and the static and apparent stiffnesses (N/m) against the swept load."""
    import matplotlib.pyplot as plt

    column, label, unit = _sweep_axis(frame)
    fig, axes = _figure(1, 2, (11, 4.5))
    load = frame[column]
    for col in frame.columns:
        if col.startswith("f_") and col.endswith("_hz"):
            axes[0, 0].plot(load, frame[col], label=col[2:-3])
    styles = {"static": "-", "apparent": "--"}
    for kind, style in styles.items():
        for key in ("V", "H"):
            axes[0, 1].plot(load, frame[f"K_{key}_{kind}_n_per_m"], style, label=f"K_{key} {kind}")
    axes[0, 0].set_xlabel(f"{label} ({unit})")
    axes[0, 0].set_ylabel("natural frequency (Hz)")
    axes[0, 0].legend()
    axes[0, 1].set_xlabel(f"{label} ({unit})")
    axes[0, 1].set_ylabel("stiffness (N/m)")
    axes[0, 1].set_yscale("log")
    axes[0, 1].set_title("static tangent (Eq. 1-4) and apparent 1-DOF (Eq. 24-25)", fontsize=9)
    limit = frame.attrs.get("limit")
    if limit:  # the sweep ended where the static model can no longer hold the load
        for ax in axes[0]:
            ax.axvline(limit["value"], color="k", linestyle=":",
                       label=f"limit {limit['value']:.4g} {limit['unit']}")
        fig.suptitle(limit["message"], fontsize=8)
    axes[0, 1].legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# --------------------------------------------------------------------------- plan


def render_plan(result, as_json: bool = False, plot_path: str | None = None, console=None) -> None:
    """Print a :class:`guidefit.plan.Plan`: per mode what each run excites and reads and what will
    decide its label, the auto-MAC, the best layout; or one JSON document; optional auto-MAC plot."""
    data = result.to_dict()
    if plot_path:
        _save_figure(lambda path: plot_plan(result, path), plot_path)
    if as_json:
        print(dump_json(data))
        return
    console = console or _console()
    runs = [r["name"] for r in data["runs"]]
    for r in data["runs"]:
        hit = "unknown" if r["excitation_position_m"] is None else \
            "(" + ", ".join(f"{1e3 * x:.1f}" for x in r["excitation_position_m"]) + ") mm"
        console.print(f"run {r['name']}: hit along ({', '.join(f'{x:g}' for x in r['excitation_direction'])}) at "
                      f"{hit}; sensors {', '.join(s['name'] for s in r['sensors']) or 'none'}", highlight=False)
    table = _narrow_table(f"{data['guide']} modes as this test will see them")
    table.add_column("mode")
    table.add_column("f (Hz)", justify="right")
    for r in runs:
        table.add_column(f"{r}: hit/read", justify="right")
    table.add_column("label by")
    top_p = max((p for m in data["modes"] for p in m["participation"].values() if p is not None), default=0) or 1
    top_r = max((x for m in data["modes"] for x in m["readings"].values()), default=0) or 1
    for m in data["modes"]:
        cells = [m["label"], f"{m['frequency_hz']:.0f}"]
        for r in runs:
            p = m["participation"][r]
            cells.append(("?" if p is None else f"{100 * p / top_p:.0f}%") + f"/{100 * m['readings'][r] / top_r:.0f}%")
        cells.append(m["label_basis"])
        table.add_row(*cells)
    console.print(table)
    console.print("hit: participation |g.phi| of the mode at the hit point; read: size of its modal constants at "
                  "the run's sensors (both relative to the largest). label by: what will name the mode from "
                  "this test's data (shape: the readings alone; frequency: only its place near the model's).",
                  highlight=False)
    for m in data["modes"]:
        if m["label_basis"] not in ("shape", "shape+frequency"):
            console.print(f"  {m['label']}: {m['note']}", highlight=False)
    mac = data["auto_mac"]
    mt = _narrow_table("auto-MAC of the model modes on these sensors (1: they look alike)")
    mt.add_column("")
    for lab in mac["labels"]:
        mt.add_column(lab[:9], justify="right")
    for lab, row in zip(mac["labels"], mac["matrix"]):
        mt.add_row(lab, *(f"{x:.2f}" for x in row))
    console.print(mt)
    best = data.get("best")
    if best:
        hits = "; ".join(f"{r} at (" + ", ".join(f"{1e3 * x:.1f}" for x in h) + ") mm" for r, h in best["hits"].items())
        console.print(f"best among the guide's points with at most {best['budget_sensors_per_run']} sensors per "
                      f"run: layout {best['layout']} with hits {hits}: {best['decided_by_shape']} of "
                      f"{len(data['modes'])} labels decided by shape alone (this plan: "
                      f"{len(data['decided_by_shape'])})", highlight=False)
        more = [x for x in best["layouts"] if x["sensors_per_run"] > best["budget_sensors_per_run"]
                and x["decided_by_shape"] > best["decided_by_shape"]]
        if more:
            console.print(f"with more channels: {more[0]['layout']} ({more[0]['sensors_per_run']} per run) decides "
                          f"{more[0]['decided_by_shape']} by shape", highlight=False)
    if plot_path:
        console.print(f"plot written to {plot_path}")


def plot_plan(result, path: str) -> None:
    """The auto-MAC matrix of the model modes on the planned sensors."""
    import matplotlib.pyplot as plt

    v = result.view
    fig, axes = _figure(1, 1, (5.5, 4.8))
    ax = axes[0, 0]
    im = ax.imshow(v.auto_mac, vmin=0.0, vmax=1.0, cmap="viridis")
    ax.set_xticks(range(len(v.labels)), v.labels, rotation=45, ha="right")
    ax.set_yticks(range(len(v.labels)), v.labels)
    for i in range(len(v.labels)):
        for j in range(len(v.labels)):
            ax.text(j, i, f"{v.auto_mac[i, j]:.2f}", ha="center", va="center",
                    color="black" if v.auto_mac[i, j] > 0.5 else "white", fontsize=8)
    ax.set_title(f"{result.guide}: auto-MAC on the planned sensors")
    fig.colorbar(im, ax=ax)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# --------------------------------------------------------------------------- identify

_PARAM_ORDER = ("f_V", "zeta_V", "K_V", "c_V", "f_H", "zeta_H", "K_H", "c_H")


def significant_digits(value, std) -> int:
    """Digits that show a value to about a tenth of its standard deviation (4 to 10).

    >>> significant_digits(3529.02, 0.02), significant_digits(1.03e9, 5e5)
    (7, 5)
    """
    if std is None or not std or not value or not math.isfinite(std) or not math.isfinite(value):
        return 4
    return int(min(10, max(4, math.ceil(math.log10(abs(value) / abs(std))) + 1)))


def _pm(value, std, unit="", sep=" ± ") -> str:
    if value is None:
        return "-"
    if isinstance(value, str):
        return value
    if std is None:
        return fmt(value, unit)
    return f"{fmt(value, digits=significant_digits(value, std))}{sep}{fmt(std, digits=2)} {unit}".strip()


def render_identification(result, console=None) -> None:
    """Rich tables of one identification: parameters, modes, rejected hits, warnings."""
    from rich.table import Table

    console = console or _console()
    table = Table(title=f"{result.file}  (guide {result.guide.name}, M = {result.guide.mass_kg:g} kg)")
    table.add_column("parameter")
    table.add_column("value ± 1 std", justify="right")
    table.add_column("equation")
    eqs = {"f_V": "|p|/2pi, curve fit", "f_H": "|p|/2pi, curve fit", "K_V": "Eq. (24)", "K_H": "Eq. (25)",
           "zeta_V": "curve fit (Eq. 26 beside)", "zeta_H": "curve fit (Eq. 28 beside)",
           "c_V": "Eq. (27)", "c_H": "Eq. (29)"}
    gate = getattr(result, "gate", None)
    if gate is None:
        for name in _PARAM_ORDER:
            p = result.parameters[name]
            table.add_row(name, _pm(p["value"], p["std"], p["unit"]), eqs[name])
        console.print(table)
    else:  # the plausibility gate: modes below, no joint parameters
        from rich.markup import escape

        console.print(f"{escape(str(result.file))}  (guide {escape(result.guide.name)}): [red]no joint parameters:"
                      f"[/red] {escape(gate)}", markup=True, highlight=False, soft_wrap=True)
    from rich import box

    kind = "global fit of all runs" if getattr(result, "modal", None) is not None else "curve fit"
    modes = Table(title=f"modes (f_n, zeta: {kind}; hp: half-power Eq. 26/28, bins in band)",
                  box=box.SIMPLE_HEAD, pad_edge=False)
    for col in ("label", "run", "f_n (Hz)", "zeta", "model (Hz)", "coh.", "hp zeta"):
        modes.add_column(col, justify="right" if col != "label" else "left")
    short = {"frequency": " (freq.)", "shape+frequency": " (both)"}
    for m in list(result.modes) + list(result.extra_modes):
        hp = m.half_power
        label = m.label
        if getattr(m, "candidates", ()):
            label += ": " + "/".join(str(c[0]) for c in m.candidates)
        label += short.get(getattr(m, "label_basis", None), "")
        modes.add_row(
            label, m.run, _pm(m.frequency_hz, m.frequency_std_hz),
            _pm(m.damping_ratio, m.damping_std),
            "-" if m.model_frequency_hz is None else f"{m.model_frequency_hz:.1f}", f"{m.coherence:.3f}",
            "-" if hp is None else f"{hp['zeta_window_corrected']:.4f} ({hp['bins_in_band']})",
        )
    console.print(modes)
    console.print("labels: named by the mode's shape at the sensors; (freq.) by its frequency near the model's "
                  "alone; (both) by the two together", highlight=False)
    for m in result.modes:
        if getattr(m, "label_basis", None) == "frequency":
            console.print(f"  {m.label} at {m.frequency_hz:.0f} Hz: {m.label_note}", highlight=False)
    all_hits = result.hit_rows()
    rejected = [h for h in all_hits if not h["accepted"]]
    n_hits = len(all_hits)
    if getattr(result, "hits_checked", True):
        console.print(f"hits: {n_hits - len(rejected)} accepted, {len(rejected)} rejected")
    else:
        console.print("hits: not checked (FRF input: no time data)")
    if rejected:
        hits = Table(title="rejected hits")
        for col in ("run", "hit", "peak force (N)", "reason"):
            hits.add_column(col)
        for h in rejected:
            hits.add_row(h["run"], str(h["hit"]), fmt(h["peak_force_n"]), h["reason"] or "")
        console.print(hits)
    for w in result.warnings:
        console.print(f"[yellow]warning:[/yellow] {w}")


def write_summary_csv(rows: list[dict], path: str) -> None:
    """One row per file (pandas-readable; units in the column names)."""
    import pandas as pd

    pd.DataFrame(rows).to_csv(path, index=False)


def plot_identification(result, path: str) -> None:
    """FRF magnitude, phase and coherence per run with picked modes and half-power bands.

    For a global identification (``result.modal``): the fitted model of each
    run drawn over its measured FRFs (magnitude and phase, dashed), and the
    stabilisation diagram of the global fit under them.
    """
    if getattr(result, "modal", None) is not None:
        _plot_global(result, path)
        return
    import numpy as np

    n_runs = len(result.runs)
    fig, axes = _figure(3, n_runs, (6.5 * n_runs, 9))
    for j, run in enumerate(result.runs):
        frf = run.frf
        f = frf.frequency_hz
        band = f <= min(f[-1], 1.4 * max(m.frequency_hz for m in result.modes) if result.modes else f[-1])
        for k, name in enumerate(frf.channels):
            axes[0, j].semilogy(f[band], np.abs(frf.H[band, k]), lw=0.8, label=name)
            axes[1, j].plot(f[band], np.degrees(np.angle(frf.H[band, k])), lw=0.6)
            axes[2, j].plot(f[band], frf.coherence[band, k], lw=0.6)
        for m in list(run.modes):
            for ax in axes[:, j]:
                ax.axvline(m.frequency_hz, color="k", ls="--", lw=0.6)
            axes[0, j].annotate(m.label, (m.frequency_hz, 1), xycoords=("data", "axes fraction"),
                                rotation=90, va="top", fontsize=7)
            if m.half_power:
                axes[0, j].axvspan(m.half_power["f1_hz"], m.half_power["f2_hz"], color="C1", alpha=0.15)
        axes[0, j].set_title(f"run '{run.name}' ({frf.estimator}, {frf.n_averages} hits)")
        axes[0, j].set_ylabel("|H| ((m/s^2)/N)")
        axes[1, j].set_ylabel("phase (deg)")
        axes[2, j].set_ylabel("coherence")
        axes[2, j].set_ylim(0, 1.05)
        axes[2, j].set_xlabel("frequency (Hz)")
        axes[0, j].legend(fontsize=6, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def _plot_global(result, path: str) -> None:
    """Per run: measured vs fitted magnitude and phase, coherence; below: the stabilisation diagram."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    fit = result.modal.fit
    runs = [r for r in result.runs if r.name in fit.runs]
    n = max(len(runs), 1)
    fig = plt.figure(figsize=(6.5 * n, 12))
    grid = fig.add_gridspec(4, n, height_ratios=(3, 2, 1.2, 2.6))
    lo, hi = fit.band_hz
    for j, run in enumerate(runs):
        frf = run.frf
        f = np.asarray(frf.frequency_hz)
        sel = (f >= 0.8 * lo) & (f <= 1.1 * hi)
        model = fit.synthesize(run.name, frf.exp_window_tau_s)  # as measured: through the run's window
        ax_m, ax_p, ax_c = (fig.add_subplot(grid[i, j]) for i in range(3))
        for k, name in enumerate(frf.channels):
            color = f"C{k % 10}"
            ax_m.semilogy(f[sel], np.abs(frf.H[sel, k]), lw=0.8, color=color, label=name)
            ax_m.semilogy(fit.frequency_hz, np.abs(model[:, k]), "--", lw=0.9, color="k", alpha=0.7)
            ax_p.plot(f[sel], np.degrees(np.angle(frf.H[sel, k])), lw=0.6, color=color)
            ax_p.plot(fit.frequency_hz, np.degrees(np.angle(model[:, k])), "--", lw=0.6, color="k", alpha=0.7)
            ax_c.plot(f[sel], frf.coherence[sel, k], lw=0.6, color=color)
        for m in run.modes:
            for ax in (ax_m, ax_p, ax_c):
                ax.axvline(m.frequency_hz, color="k", ls=":", lw=0.6)
            ax_m.annotate(m.label, (m.frequency_hz, 1), xycoords=("data", "axes fraction"), rotation=90,
                          va="top", fontsize=7)
        for ax in (ax_m, ax_p, ax_c):
            ax.axvspan(lo, hi, color="C2", alpha=0.04)
        windowed = " (through the run's window, as measured)" if frf.exp_window_tau_s else ""
        ax_m.set_title(f"run '{run.name}' ({frf.estimator}, {frf.n_averages} hits): measured, global fit "
                       f"dashed{windowed}", fontsize=9)
        ax_m.set_ylabel("|H| ((m/s^2)/N)")
        ax_p.set_ylabel("phase (deg)")
        ax_c.set_ylabel("coherence")
        ax_c.set_ylim(0, 1.05)
        ax_c.set_xlabel("frequency (Hz)")
        ax_m.legend(fontsize=6, ncol=2)
    d = fit.diagram
    ax = fig.add_subplot(grid[3, :])
    styles = ((~d.stable_f, "o", "0.75", "new"), (d.stable_f & ~d.stable, "x", "C1", "stable f"),
              (d.stable, "+", "C0", "stable f, zeta, participation"))
    for mask, marker, color, label in styles:
        ax.plot(d.frequency_hz[mask], d.orders[mask], marker, ms=4, color=color, ls="none", label=label)
    for c in fit.selection.chosen:
        ax.axvline(c.frequency_hz, color="C3", lw=0.8, alpha=0.6)
    for m in list(result.modes) + list(result.extra_modes):
        ax.annotate(f"{m.label} {m.frequency_hz:.0f}", (m.frequency_hz, 1), xycoords=("data", "axes fraction"),
                    rotation=90, va="top", fontsize=7)
    ax.set_xlim(lo, hi)
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel("model order (poles)")
    ax.set_title("stabilisation diagram (poly-reference LSCF, all runs); red: selected poles")
    ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def render_batch_summary(rows: list[dict], outcomes: list, console=None) -> None:
    """One line per file: K_V, K_H, c_V, c_H and the check outcome."""
    from rich.table import Table

    console = console or _console()
    table = Table(title=f"batch summary ({len(rows)} files)")
    for col in ("file", "K_V (N/m)", "K_H (N/m)", "c_V (N s/m)", "c_H (N s/m)", "outcome"):
        table.add_column(col)
    for row, (_, violations, error) in zip(rows, outcomes):
        outcome = "rejected" if row.get("gate") else "error" if error else (
            "out of tolerance" if violations else "ok")
        table.add_row(row["file"], fmt(row.get("K_V_n_per_m")), fmt(row.get("K_H_n_per_m")),
                      fmt(row.get("c_V_ns_per_m")), fmt(row.get("c_H_ns_per_m")), outcome)
    console.print(table)


def render_frf_summary(frfsets, console=None) -> None:
    """Per run: resolution, averages and the coherence at the strongest peaks."""
    import numpy as np
    from rich.table import Table

    console = console or _console()
    table = Table(title="FRFs")
    for col in ("run", "channels", "estimator", "hits", "resolution (Hz)", "strongest peak (Hz)",
                "coherence there"):
        table.add_column(col)
    for frf in frfsets:
        power = np.sum(np.abs(frf.H) ** 2, axis=1)
        power[frf.frequency_hz < 20] = 0
        i = int(np.argmax(power))
        table.add_row(frf.run, str(len(frf.channels)), frf.estimator, str(frf.n_averages),
                      f"{frf.resolution_hz:.3g}" + (" (padded)" if frf.record_samples else ""),
                      f"{frf.frequency_hz[i]:.1f}",
                      f"{float(np.mean(frf.coherence[i])):.3f}")
    console.print(table)


# --------------------------------------------------------------------------- explain


def render_explanation(result, console=None) -> None:
    """Verdict, effects with uncertainties, per-mode errors and the ranked candidates."""
    from rich.table import Table

    console = console or _console()
    data = result.to_dict()
    colour = {"adequate": "green", "explained": "cyan", "unexplained": "red"}.get(data["verdict"], "white")
    before = data["error_before"].get("rms_frequency_error_pct")
    after = data["error_after"].get("rms_frequency_error_pct")
    console.print(f"[bold]{data.get('file') or 'modes'}[/bold] (guide {data['guide']}): verdict "
                  f"[bold {colour}]{data['verdict']}[/bold {colour}]; RMS frequency error "
                  f"{fmt(before)} % before, {fmt(after)} % after")
    for eff in data["effects"]:
        params = ", ".join(f"{k} = {_pm(v.get('value'), v.get('std'))}"
                           for k, v in eff.get("parameters", {}).items() if isinstance(v, dict))
        console.print(f"  effect [bold]{eff['name']}[/bold]: {params}")
    modes = Table(title="modes")
    for col in ("label", "run", "measured (Hz)", "model before (Hz)", "model after (Hz)", "error before %",
                "error after %"):
        modes.add_column(col, justify="left" if col == "label" else "right")
    for m in data["modes"]:
        modes.add_row(str(m.get("label")), str(m.get("run") or ""), _pm(m.get("measured_hz"), m.get("measured_std_hz")),
                      fmt(m.get("model_before_hz")), fmt(m.get("model_after_hz")), fmt(m.get("error_before_pct")),
                      fmt(m.get("error_after_pct")))
    console.print(modes)
    cands = Table(title="candidates (best first)")
    for col in ("candidate", "k", "chi2/dof", "dBIC", "RMS err %", "accepted"):
        cands.add_column(col, justify="left" if col == "candidate" else "right")
    for c in data["candidates"][:10]:
        dof = c.get("dof") or 0
        chi = c.get("chi2")
        cands.add_row(str(c.get("variant") or c.get("name")), str(c.get("n_params")),
                      "-" if chi is None else (f"{chi / dof:.3g}" if dof else "no dof"),
                      fmt(c.get("delta_bic")), fmt(c.get("rms_frequency_error_pct")),
                      "yes" if c.get("accepted") else f"no: {c.get('note') or ''}"[:40])
    console.print(cands)
    for note in data["notes"]:
        console.print(f"note: {note}")


def plot_explanation_with_frf(result, path, identification=None) -> None:
    """The explain plot; with the identification it explained, its FRF against the model before and after."""
    from guidefit.explain import plot_explanation

    overlay = None
    if identification is not None:
        try:
            overlay = frf_overlay(identification, result)
        except Exception as exc:  # noqa: BLE001 - the overlay is optional; say why it is missing
            _console(stderr=True).print(f"note: FRF overlay left out ({type(exc).__name__}: {exc})")
    plot_explanation(result, path, frf=overlay)


def frf_overlay(identification, explanation) -> dict:
    """The FRF panel of the explain plot, from the identification itself: no FRF is recomputed.

    The measured FRF is the first run's channel with the largest response;
    the model before (nominal) and after (fitted effects, when explained)
    uses the identified damping ratio of each labelled mode (the mean of them
    for modes not identified), over the band the identify plot shows.
    """
    import numpy as np

    from guidefit.explain import fitted_spec
    from guidefit.io.frf_files import read_metadata
    from guidefit.model import vibration as vib

    ident = identification
    run = ident.runs[0]
    frf = run.frf
    k = int(np.argmax(np.max(np.abs(frf.H), axis=0)))
    ch = run.channels[k]
    rec_run = read_metadata(ident.file).run(run.name)  # metadata only (recording or FRF file): the hit point
    hit = rec_run.hit_position_m  # excitation_position_m, else the force channel's; None: unknown
    zeta = {}
    for m in ident.modes:
        if getattr(m, "level", None) is None:
            zeta.setdefault(m.label, m.damping_ratio)
    fill = float(np.mean(list(zeta.values()))) if zeta else 0.02
    f = frf.frequency_hz
    top = min(f[-1], 1.4 * max((m.frequency_hz for m in ident.modes), default=f[-1]))
    band = (f > 0) & (f <= top)

    def model(spec):
        sol = vib.solve_modes(spec)
        z = [zeta.get(lab, fill) for lab in sol.labels]
        return vib.accelerance(sol, spec, f[band], z, hit, run.excitation_direction, [ch.position_m],
                               [ch.direction])[:, 0]

    out = {"frequency_hz": f[band], "measured": frf.H[band, k],
           "title": f"run '{run.name}', {ch.name} (identified damping)"}
    if hit is None:  # no model FRF without the hit point: the measured one alone, and why
        out["title"] += "; no model curve: the hit point is unknown"
        return out
    out["before"] = model(vib.model_from_guide(ident.guide))
    if explanation.verdict == "explained":
        out["after"] = model(fitted_spec(explanation, ident.guide))
    return out
