"""``guidefit report``: one self-contained HTML file per recording, rendered from one pipeline.

The report computes nothing of its own. :func:`report_results` makes the
calls ``guidefit explain RECORDING`` makes, with the same settings:
:func:`guidefit.explain.identify_for_explain` (``identify`` with force levels
on; its parameters and modes are those of ``identify --json`` with the same
options, force levels only add data) and :func:`guidefit.explain.explain` of
that identification. The page then renders those two results:

- provenance: date (UTC), guidefit version, the input file's SHA-256 and
  size, the guide, every setting (identify and explain) and the equivalent
  command lines;
- the runs and the sensors with their positions and directions;
- the joint parameters with uncertainties;
- the ``identify --plot`` figure (:func:`guidefit.report.plot_identification`:
  FRFs, fitted model, stabilisation diagram where the estimator has one);
- the modes, and their shapes at the sensors (points A-D) as a table and a
  figure of the measured modal constants;
- the explain result: verdict, RMS error before and after, the effects, the
  per-mode table, the ranked candidates and the ``explain --plot`` figure
  (:func:`guidefit.report.plot_explanation_with_frf`: its FRF panel uses the
  identification's FRF and its identified damping ratios);
- the joint ``guidefit export`` writes (:func:`guidefit.export.explained_joint`):
  apparent Eq. (24)-(29) values beside the explained joint with the rig
  removed, and its 6x6 stiffness and damping;
- every hit with its reason if rejected, and the warnings.

The results themselves are embedded as JSON (``<script type="application/json"
id="guidefit-results">``, the ``identify --json`` and ``explain --json``
objects) so that a reader or a test can compare them with the commands'
output. Every text from the input (file name, description, channel names,
warnings) is HTML-escaped; images are PNG data URIs: no external CSS,
fonts or scripts.
"""

from __future__ import annotations

import base64
import hashlib
import html
import io
import json
import math
from dataclasses import dataclass

_STYLE = """
body{font-family:system-ui,sans-serif;margin:2em;max-width:1150px;color:#222}
table{border-collapse:collapse;margin:1em 0}th,td{border:1px solid #bbb;padding:3px 8px;text-align:right}
th{background:#eee}td:first-child,th:first-child{text-align:left}.warn{color:#a60}.bad{color:#b00}
img{max-width:100%;border:1px solid #ddd}code{background:#f4f4f4;padding:1px 4px}
.meta td{text-align:left}
"""


@dataclass(frozen=True)
class ReportResults:
    """What a report renders: the identification and explanation, and how they were made."""

    path: str
    identification: object  # guidefit.identify.Identification
    explanation: object | None  # guidefit.explain.Explanation
    explain_error: str | None
    settings: object  # guidefit.identify.IdentifySettings
    candidates: tuple | None
    guide_option: str | None


def file_sha256(path) -> str:
    """SHA-256 of a file, read in 1 MiB blocks.

    >>> import tempfile, os
    >>> with tempfile.NamedTemporaryFile(delete=False) as fh:
    ...     _ = fh.write(b"abc")
    >>> file_sha256(fh.name)[:16]
    'ba7816bf8f01cfea'
    >>> os.remove(fh.name)
    """
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def report_results(path, *, guide=None, settings=None, candidates=None, progress=None) -> ReportResults:
    """Identify and explain ``path`` exactly as ``guidefit explain`` does (same functions, same settings).

    A failed explanation (no usable modes for it, a model error) is kept as
    its one-line message; a failed identification raises as in ``identify``.
    ``progress`` is called as ``progress(done, total, name)`` after each
    candidate effect (a :class:`guidefit.progress.Bar`, the one progress protocol).
    """
    from dataclasses import replace

    from guidefit.errors import GuidefitError
    from guidefit.explain import explain, identify_for_explain
    from guidefit.identify import IdentifySettings

    settings = settings or IdentifySettings()
    ident = identify_for_explain(path, guide=guide, settings=settings)
    explanation, error = None, None
    if ident.gate is not None:  # as explain: the modes are not those of a carriage on the guide
        error = f"identification rejected: {ident.gate}"
    else:
        try:
            explanation = explain(ident, candidates=candidates, progress=progress)
        except GuidefitError as exc:
            error = str(exc)
    return ReportResults(str(path), ident, explanation, error, replace(settings, force_levels=True),
                         None if candidates is None else tuple(candidates), None if guide is None else str(guide))


# --------------------------------------------------------------------------- pieces


def _e(text) -> str:
    return html.escape(str(text), quote=True)


def _table(header: list[str], rows: list[list], cls: list[str] | None = None, table_cls: str = "") -> str:
    head = f"<tr>{''.join(f'<th>{_e(h)}</th>' for h in header)}</tr>" if header else ""
    body = []
    for i, row in enumerate(rows):
        attr = f' class="{cls[i]}"' if cls and cls[i] else ""
        body.append(f"<tr{attr}>" + "".join(f"<td>{_e(c)}</td>" for c in row) + "</tr>")
    attr = f' class="{table_cls}"' if table_cls else ""
    return f"<table{attr}>{head}{''.join(body)}</table>"


def _img(png: bytes, alt: str) -> str:
    return f"<img alt='{_e(alt)}' src='data:image/png;base64,{base64.b64encode(png).decode('ascii')}'>"


def _figure_png(draw) -> bytes:
    """PNG bytes of a figure drawn by ``draw(path_or_buffer)`` (the functions the commands use)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    buffer = io.BytesIO()
    try:
        draw(buffer)
    finally:
        plt.close("all")
    return buffer.getvalue()


def _json_script(obj) -> str:
    """Embedded JSON that no file name can close: <, >, & escaped as JSON unicode escapes."""
    from guidefit.report import dump_json

    text = dump_json(obj).replace("<", "\\u003c").replace(">", "\\u003e").replace("&", "\\u0026")
    return f"<script type='application/json' id='guidefit-results'>{text}</script>"


def _settings_rows(res: ReportResults) -> list[list]:
    from dataclasses import fields

    s = res.settings
    rows = [[f"identify {f.name}", "auto" if getattr(s, f.name) is None else repr(getattr(s, f.name))]
            for f in fields(s)]
    rows.append(["guide (option)", res.guide_option or "(the file's, else MRB35)"])
    rows.append(["explain candidates", ", ".join(res.candidates) if res.candidates else "(the whole library)"])
    if res.explanation is not None:
        for key, value in res.explanation.settings.items():
            rows.append([f"explain {key}", value])
    return rows


def _command_lines(res: ReportResults) -> list[str]:
    import shlex

    opts = []
    if res.guide_option:
        opts += ["--guide", res.guide_option]
    opts += ["--estimator", res.settings.estimator, "--fft-precision", res.settings.fft_precision]
    if not res.settings.jackknife:
        opts.append("--no-jackknife")
    path = shlex.quote(res.path)
    explain_opts = opts + (["--candidates", ",".join(res.candidates)] if res.candidates else [])
    return [f"guidefit identify {path} --json {' '.join(map(shlex.quote, opts))}",
            f"guidefit explain {path} --json {' '.join(map(shlex.quote, explain_opts))}"]


def _daq_rows(path) -> list[list[str]]:
    """Provenance of the DAQ files a test setup (``.toml``) points at: each file's name, SHA-256 and
    size, once per file (the setup's own hash says nothing of the data it reads)."""
    import os

    if not str(path).lower().endswith(".toml"):
        return []
    from guidefit.io.setup import load_setup

    rows, seen = [], set()
    for run in load_setup(path).runs:
        key = os.path.realpath(run.path)
        if key in seen:
            continue
        seen.add(key)
        rows.append([f"DAQ file ({run.name})", f"{run.file}: SHA-256 {file_sha256(run.path)}, "
                     f"{os.path.getsize(run.path)} bytes"])
    return rows


def _header(res: ReportResults) -> list[str]:
    import datetime
    import os

    from guidefit import __version__
    from guidefit.io.frf_files import read_metadata

    ident = res.identification
    rec = read_metadata(res.path)  # a recording's or an FRF file's runs and channels
    now = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M:%S UTC")
    meta = [["file", res.path], ["SHA-256", file_sha256(res.path)], ["size", f"{os.path.getsize(res.path)} bytes"],
            *_daq_rows(res.path),
            ["description", rec.description or "-"], ["guide", f"{ident.guide.name} (M = {ident.guide.mass_kg:g} kg)"],
            ["date", now], ["guidefit", __version__]]
    gate = getattr(ident, "gate", None)
    banner = ([f"<p class='warn'><b>Identification rejected</b> (identify and explain exit 1): {_e(gate)}. "
               "No joint parameters and no explanation are given; the modes found are listed below.</p>"]
              if gate else [])
    banner += [f"<p class='warn'><b>Identification incomplete</b> (identify, explain and report exit 1): "
               f"{_e(line)}</p>" for line in getattr(ident, "unidentified", ()) or ()]
    parts = [f"<h1>guidefit report: {_e(res.path)}</h1>", *banner, "<h2>Provenance</h2>",
             _table([], meta, table_cls="meta"),
             "<p>The same results as these commands (the report runs their calls with these settings):</p>",
             "<ul>" + "".join(f"<li><code>{_e(c)}</code></li>" for c in _command_lines(res)) + "</ul>",
             "<h2>Settings</h2>", _table(["setting", "value"], _settings_rows(res), table_cls="meta")]
    from guidefit.io.records import hit_point_of

    runs = [[r.name, f"{r.sample_rate_hz:g}", " ".join(f"{x:g}" for x in r.excitation_direction),
             "-" if hit_point_of(r) is None else " ".join(f"{1e3 * x:g}" for x in hit_point_of(r)),
             r.layout, r.n_hits_stored or "-"] for r in rec.runs]
    parts += ["<h2>Runs and sensors</h2>",
              _table(["run", "sample rate (Hz)", "excitation direction", "hit point (mm)", "layout", "stored hits"],
                     runs)]
    sensors = [[ch.name, ch.unit, *(f"{1e3 * x:.2f}" for x in ch.position_m), " ".join(f"{x:g}" for x in ch.direction)]
               for r in rec.runs for ch in r.channels]
    seen, unique = set(), []
    for row in sensors:
        if tuple(row) not in seen:
            seen.add(tuple(row))
            unique.append(row)
    parts.append(_table(["channel", "unit", "x (mm)", "y (mm)", "z (mm)", "direction"], unique))
    return parts


def _parameters_and_modes(res: ReportResults) -> list[str]:
    from guidefit.report import fmt, plot_identification, significant_digits

    ident = res.identification
    rows = [[name, fmt(p["value"], p["unit"], significant_digits(p["value"], p["std"])), fmt(p["std"], p["unit"], 2)]
            for name, p in ident.parameters.items()]
    gate = getattr(ident, "gate", None)
    rejected = ([f"<p class='warn'><b>Identification rejected</b>: {_e(gate)}. No joint parameters are given; "
                 "the modes found are listed below.</p>"] if gate else [])
    parts = ["<h2>Joint parameters (Eq. 24-29, apparent)</h2>", *rejected, _table(["parameter", "value", "std (1 sigma)"], rows),
             "<p>f: undamped natural frequency |p|/2&pi; of the modal fit; zeta: viscous damping ratio after the "
             "exponential-window correction; K, c: Eq. (24)-(29) with the guide's mass (apparent single-DOF "
             "values: rig effects such as sensor mass or a soft support are in them; see the explanation).</p>",
             "<h2>FRFs and fitted modes</h2><p>The <code>identify --plot</code> figure.</p>",
             _img(_figure_png(lambda buf: plot_identification(ident, buf)), "identify --plot figure")]
    mode_rows = []
    for m in list(ident.modes) + list(ident.extra_modes):
        hp = m.half_power
        level = getattr(m, "level", None)
        mode_rows.append([m.label if level is None else f"{m.label} (level {level})", m.run, fmt(m.frequency_hz, "Hz", significant_digits(m.frequency_hz,
                                                                                       m.frequency_std_hz)),
                          fmt(m.frequency_std_hz, "Hz", 2), f"{m.damping_ratio:.4f}", fmt(m.damping_std, "", 2),
                          fmt(m.model_frequency_hz, "Hz"), f"{m.coherence:.3f}",
                          "-" if hp is None else f"{hp['zeta_window_corrected']:.4f}", _named_by(m)])
    parts += ["<h2>Modes</h2>",
              _table(["label", "run", "f_n", "std", "zeta", "zeta std", "model", "coherence", "half-power zeta",
                      "named by"], mode_rows),
              "<p>named by: what gave the label at these sensors (shape, frequency or both); an "
              "<i>ambiguous</i> mode lists its candidate labels with their probabilities and gives no joint "
              "parameter, force level or damping of a model mode; an <i>extra</i> mode is a peak the model does "
              "not predict.</p>"]
    if ident.missing_modes:
        parts.append(f"<p class='warn'>model modes not observed: {_e(', '.join(map(str, ident.missing_modes)))}</p>")
    return parts


def _named_by(mode) -> str:
    """The label's basis (``shape``, ``frequency``, ``shape+frequency``) or an ambiguous mode's candidates."""
    cands = getattr(mode, "candidates", ()) or ()
    if mode.label == "ambiguous" and cands:
        def one(c):
            if isinstance(c, dict):
                name, p = c.get("label"), c.get("probability")
            else:
                name, p = c[0], (c[1] if len(c) > 1 else None)
            known = p is not None and math.isfinite(float(p))
            return f"{name}" + (f" ({100 * float(p):.0f} %)" if known else "")
        return "ambiguous: " + " or ".join(one(c) for c in cands)
    basis = getattr(mode, "label_basis", None)
    return basis or ("-" if mode.label != "extra" else "not a model mode")


def _shapes(res: ReportResults) -> list[str]:
    """Mode shapes at the sensors (A-D): the real modal constants per channel, table and figure."""
    ident = res.identification
    modes = _shape_modes(ident)
    channels = []
    for m in modes:
        for name in m.shape:
            if name not in channels:
                channels.append(name)
    rows = []
    for m in modes:
        values = [float(getattr(m.shape.get(c), "real", m.shape.get(c))) if c in m.shape else None for c in channels]
        rows.append([f"{m.label} ({m.run}, {m.frequency_hz:.1f} Hz)",
                     *("-" if v is None else f"{v:.4g}" for v in values)])
    parts = ["<h2>Mode shapes at the measuring points</h2>",
             "<p>Real modal constants (1/kg) per channel, from the modal fit of the run that gave the mode; "
             "the figure draws each sensor's value as an arrow along its direction at its position (each mode "
             "scaled to its largest value).</p>",
             _table(["mode", *channels], rows)]
    if modes:
        parts.append(_img(_figure_png(lambda buf: plot_shapes(ident, buf)), "mode shapes at the sensors"))
    return parts


def _shape_modes(identification) -> list:
    """The modes whose shapes are drawn: each mode once (force-level estimates of a mode left out)."""
    return [m for m in list(identification.modes) + list(identification.extra_modes)
            if getattr(m, "level", None) is None]


def plot_shapes(identification, path) -> None:
    """One 3-D panel per mode: the sensors' modal constants as arrows along their directions at A-D."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    modes = _shape_modes(identification)
    sensors = {}
    for run in identification.runs:
        for ch in run.channels:
            sensors.setdefault(ch.name, (np.asarray(ch.position_m, float), np.asarray(ch.direction, float)))
    n = len(modes)
    cols = min(n, 3)
    rows = -(-n // cols)
    fig = plt.figure(figsize=(4.2 * cols, 3.8 * rows))
    pts = np.array([p for p, _ in sensors.values()]) if sensors else np.zeros((1, 3))
    span = max(float(np.ptp(pts[:, 0])), float(np.ptp(pts[:, 2])), 0.02)
    for k, m in enumerate(modes):
        ax = fig.add_subplot(rows, cols, k + 1, projection="3d")
        values = {c: float(np.real(v)) for c, v in m.shape.items() if c in sensors}
        scale = 0.4 * span / max((abs(v) for v in values.values()), default=1.0) if values else 1.0
        corners = {}
        for c, (p, _) in sensors.items():
            corners.setdefault(c.split("_")[1] if c.count("_") >= 2 else c, p)
        outline = np.array(list(corners.values()))
        if len(outline) >= 3:
            order = np.argsort(np.arctan2(outline[:, 2], outline[:, 0]))
            loop = outline[np.r_[order, order[:1]]]
            ax.plot(loop[:, 0], loop[:, 2], loop[:, 1], color="0.6", lw=1)
        for name, p in corners.items():
            ax.text(p[0], p[2], p[1], f" {name}", fontsize=8)
        for c, v in values.items():
            p, d = sensors[c]
            vec = d * v * scale
            ax.quiver(p[0], p[2], p[1], vec[0], vec[2], vec[1], color="tab:red" if v >= 0 else "tab:blue",
                      arrow_length_ratio=0.25)
        ax.set_title(f"{m.label} ({m.run}) {m.frequency_hz:.1f} Hz", fontsize=9)
        ax.set_xlabel("x (m)", fontsize=7)
        ax.set_ylabel("z (m)", fontsize=7)
        ax.set_zlabel("y (m)", fontsize=7)
        ax.tick_params(labelsize=6)
        lim = 0.8 * span
        ax.set_xlim(-lim, lim)
        ax.set_ylim(-lim, lim)
        ax.set_zlim(-lim, lim)
    fig.tight_layout()
    fig.savefig(path, format="png", dpi=90)
    plt.close(fig)


def _explanation(res: ReportResults) -> list[str]:
    from guidefit.explain import plot_explanation
    from guidefit.report import fmt, frf_overlay

    parts = ["<h2>Explanation of the model-measurement residual</h2>"]
    if res.explanation is None:
        return parts + [f"<p class='warn'>explain gave no result: {_e(res.explain_error or 'no result')}</p>"]
    data = res.explanation.to_dict()
    before = data["error_before"].get("rms_frequency_error_pct")
    after = data["error_after"].get("rms_frequency_error_pct")
    parts.append(f"<p>verdict: <b id='verdict'>{_e(data['verdict'])}</b>; RMS frequency error "
                 f"<b id='rms-before'>{_e(fmt(before))}</b> % before, <b id='rms-after'>{_e(fmt(after))}</b> % "
                 f"after (model: {_e(data['error_after'].get('model', '-'))})</p>")
    eff_rows = []
    for eff in data.get("effects", []):
        for key, v in (eff.get("parameters") or {}).items():
            v = v if isinstance(v, dict) else {"value": v}
            eff_rows.append([eff["name"], eff.get("variant") or "", key, fmt(v.get("value")), fmt(v.get("std")),
                             v.get("unit") or ""])
    if eff_rows:
        parts += ["<h3>Effects of the selected model</h3>",
                  _table(["effect", "variant", "parameter", "value", "std", "unit"], eff_rows)]
    parts += ["<h3>Modes before and after</h3>", _table(
        ["mode", "run", "measured (Hz)", "sigma (Hz)", "model before (Hz)", "model after (Hz)", "error before %",
         "error after %", "MAC before", "MAC after"],
        [[m.get("label"), m.get("run") or "", fmt(m.get("measured_hz"), "", 7), fmt(m.get("sigma_hz")),
          fmt(m.get("model_before_hz"), "", 7), fmt(m.get("model_after_hz"), "", 7), fmt(m.get("error_before_pct")),
          fmt(m.get("error_after_pct")), fmt(m.get("mac_before")), fmt(m.get("mac_after"))]
         for m in data.get("modes", [])])]
    parts += ["<h3>Candidates (best BIC first)</h3>", _table(
        ["candidate", "k", "chi2", "dof", "BIC", "dBIC", "RMS error %", "accepted", "note"],
        [[c.get("variant") or c.get("name"), c.get("n_params"), fmt(c.get("chi2")), c.get("dof"), fmt(c.get("bic")),
          fmt(c.get("delta_bic")), fmt(c.get("rms_frequency_error_pct")), "yes" if c.get("accepted") else "no",
          c.get("note") or ""] for c in data.get("candidates", [])], table_cls="candidates")]
    for note in data.get("notes", []):
        parts.append(f"<p>{_e(note)}</p>")
    try:
        overlay = frf_overlay(res.identification, res.explanation)
    except Exception as exc:  # noqa: BLE001 - the FRF panel is optional; say why it is missing
        overlay = None
        parts.append(f"<p class='warn'>FRF panel left out ({_e(type(exc).__name__)}: {_e(exc)})</p>")
    parts.append(_img(_figure_png(lambda buf: plot_explanation(res.explanation, buf, frf=overlay)),
                      "explain figure: measured vs model before and after"))
    return parts


def _joint(res: ReportResults) -> list[str]:
    """The joint ``guidefit export`` writes for these results (:func:`guidefit.export.explained_joint`)."""
    from guidefit.errors import GuidefitError
    from guidefit.export import DOF_NAMES, explained_joint
    from guidefit.report import fmt

    parts = ["<h2>Joint for the machine model (guidefit export)</h2>"]
    if res.explanation is None:
        return parts + ["<p class='warn'>no explanation: only the apparent Eq. 24-29 values exist</p>"]
    try:
        joint = explained_joint(res.identification.to_dict(), res.explanation.to_dict(),
                                res.identification.guide, "report")
    except GuidefitError as exc:
        return parts + [f"<p class='warn'>{_e(exc)}</p>"]
    a, e = joint.apparent, joint.explained
    parts.append(_table(["quantity", "apparent (Eq. 24-29 of the test)", "explained joint (rig removed)"], [
        ["vertical stiffness", fmt(a["K_V"], "N/m", 5), fmt(e["K_V"], "N/m", 5)],
        ["lateral stiffness", fmt(a["K_H"], "N/m", 5), fmt(e["K_H"], "N/m", 5)],
        ["vertical damping", fmt(a["c_V"], "N s/m", 5), fmt(e["c_V"], "N s/m", 5)],
        ["lateral damping", fmt(a["c_H"], "N s/m", 5), fmt(e["c_H"], "N s/m", 5)],
        ["f_V, f_H (Hz)", f"{res.identification.parameters['f_V']['value'] or float('nan'):.1f}, "
                          f"{res.identification.parameters['f_H']['value'] or float('nan'):.1f}",
         f"{e['f_V']:.1f}, {e['f_H']:.1f} (rig-free model)"]]))
    parts.append(f"<p>rig effects removed: {_e('; '.join(joint.removed) or 'none')}; joint effects kept: "
                 f"{_e('; '.join(joint.kept) or 'none (nominal K_n)')}</p>")
    for note in joint.notes:
        if not note.startswith("rig effects removed"):  # said above
            parts.append(f"<p>{_e(note)}</p>")
    for title, m in (("stiffness (SI)", joint.stiffness), ("damping (SI)", joint.damping)):
        parts += [f"<h3>6x6 {title} at the carriage origin</h3>",
                  _table(["", *DOF_NAMES], [[DOF_NAMES[i], *(f"{v:.6g}" for v in m[i])] for i in range(6)])]
    return parts


def _hits(res: ReportResults) -> list[str]:
    ident = res.identification
    hits = ident.hit_rows()  # runs that gave no FRF included
    if not getattr(ident, "hits_checked", True):
        parts = ["<h2>Hits</h2><p>No hit checks were possible: the input holds FRFs, not time data.</p>"]
    else:
        parts = _hit_table(hits)
    if ident.warnings:
        parts.append("<h2>Warnings</h2><ul>" + "".join(
            f"<li class='warn'>{_e(w)}</li>" for w in ident.warnings) + "</ul>")
    return parts


def _hit_table(hits) -> list[str]:
    from guidefit.report import fmt

    parts = [f"<h2>Hits</h2><p>{sum(h['accepted'] for h in hits)} accepted, "
             f"{sum(not h['accepted'] for h in hits)} rejected</p>",
             _table(["run", "hit", "start sample", "peak force (N)", "accepted", "reason"],
                    [[h["run"], h["hit"], h.get("start_sample", "-"), fmt(h["peak_force_n"]),
                      "yes" if h["accepted"] else "no", h["reason"] or ""] for h in hits],
                    ["" if h["accepted"] else "bad" for h in hits])]
    return parts


def render_html(res: ReportResults) -> str:
    """The HTML text of a :class:`ReportResults`."""
    ident = res.identification
    identify_json = ident.to_dict()
    identify_json.pop("force_levels", None)  # identify --json has none; they are explain's input
    embedded = {"identify": identify_json,
                "explain": None if res.explanation is None else res.explanation.to_dict(),
                "force_levels": ident.to_dict().get("force_levels", [])}
    parts = [f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>guidefit report: {_e(res.path)}</title>"
             f"<style>{_STYLE}</style></head><body>"]
    parts += _header(res)
    parts += _parameters_and_modes(res)
    parts += _shapes(res)
    parts += _explanation(res)
    parts += _joint(res)
    parts += _hits(res)
    parts.append(_json_script(embedded))
    parts.append("</body></html>")
    return "\n".join(parts)


def write_report(path, out_path, guide=None, settings=None, candidates=None, progress=None) -> ReportResults:
    """Identify and explain one recording (:func:`report_results`) and write the HTML report whole.

    Never onto an input (the recording, a guide TOML): :class:`guidefit.outputs.OutputError`
    before any work. The file is written to a temporary file and renamed when complete
    (:func:`guidefit.outputs.write_text`). Returns the results it rendered.
    """
    import os

    from guidefit.outputs import refuse_inputs, write_text

    refuse_inputs([out_path], [path, guide if isinstance(guide, (str, os.PathLike)) else None])
    results = report_results(path, guide=guide, settings=settings, candidates=candidates, progress=progress)
    write_text(out_path, render_html(results))
    return results


def loads_embedded(text: str) -> dict:
    """The results a report embeds (``identify``, ``explain``, ``force_levels``), from its HTML text."""
    start = text.index("id='guidefit-results'>") + len("id='guidefit-results'>")
    return json.loads(text[start:text.index("</script>", start)])
