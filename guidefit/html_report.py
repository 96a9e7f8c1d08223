"""``guidefit report``: one self-contained HTML file per recording.

The page holds the FRF, phase and coherence plots (PNG embedded as base64,
so the file travels alone), the picked modes, the joint parameters with
their uncertainties, the hit table with every rejected hit and its reason,
and the result of ``explain``. No external CSS, fonts or scripts.
"""

from __future__ import annotations

import base64
import html
import io

_STYLE = """
body{font-family:system-ui,sans-serif;margin:2em;max-width:1100px;color:#222}
table{border-collapse:collapse;margin:1em 0}th,td{border:1px solid #bbb;padding:3px 8px;text-align:right}
th{background:#eee}td:first-child,th:first-child{text-align:left}.warn{color:#a60}.bad{color:#b00}
img{max-width:100%;border:1px solid #ddd}
"""


def _png(fig) -> str:
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=90)
    return base64.b64encode(buffer.getvalue()).decode("ascii")


def _table(header: list[str], rows: list[list], cls: list[str] | None = None) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = []
    for i, row in enumerate(rows):
        attr = f' class="{cls[i]}"' if cls and cls[i] else ""
        body.append(f"<tr{attr}>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in row) + "</tr>")
    return f"<table><tr>{head}</tr>{''.join(body)}</table>"


def render_html(identification, explanation=None, explain_error: str | None = None) -> str:
    """The HTML text for an :class:`~guidefit.identify.Identification` (and optional explanation)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from guidefit.report import fmt, plot_identification, significant_digits

    result = identification
    buffer = io.BytesIO()
    plot_identification(result, buffer)
    frf_png = base64.b64encode(buffer.getvalue()).decode("ascii")
    plt.close("all")
    parts = [f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>guidefit report: "
             f"{html.escape(result.file)}</title><style>{_STYLE}</style></head><body>",
             f"<h1>guidefit report</h1><p>file <b>{html.escape(result.file)}</b>, guide "
             f"<b>{html.escape(result.guide.name)}</b> (M = {result.guide.mass_kg:g} kg)</p>",
             "<h2>Joint parameters</h2>"]
    rows = [[name, fmt(p["value"], p["unit"], significant_digits(p["value"], p["std"])), fmt(p["std"], p["unit"], 2)]
            for name, p in result.parameters.items()]
    parts.append(_table(["parameter", "value", "std (1 sigma)"], rows))
    parts.append("<p>f: undamped natural frequency |p|/2&pi; of the modal curve fit; zeta: viscous damping ratio "
                 "after the exponential-window correction; K, c: Eq. (24)-(29).</p>")
    parts.append("<h2>FRFs and coherence</h2>")
    parts.append(f"<img alt='FRF magnitude, phase and coherence per run' src='data:image/png;base64,{frf_png}'>")
    parts.append("<h2>Modes</h2>")
    mode_rows = []
    for m in list(result.modes) + list(result.extra_modes):
        hp = m.half_power
        mode_rows.append([m.label, m.run, fmt(m.frequency_hz, "Hz", significant_digits(m.frequency_hz, m.frequency_std_hz)),
                          fmt(m.frequency_std_hz, "Hz", 2),
                          f"{m.damping_ratio:.4f}", fmt(m.model_frequency_hz, "Hz"), f"{m.coherence:.3f}",
                          "-" if hp is None else f"{hp['zeta_window_corrected']:.4f}"])
    parts.append(_table(["label", "run", "f_n", "std", "zeta", "model", "coherence", "half-power zeta"], mode_rows))
    hits = result.hit_rows()  # runs that gave no FRF included
    parts.append(f"<h2>Hits</h2><p>{sum(h['accepted'] for h in hits)} accepted, "
                 f"{sum(not h['accepted'] for h in hits)} rejected</p>")
    parts.append(_table(["run", "hit", "peak force (N)", "accepted", "reason"],
                        [[h["run"], h["hit"], fmt(h["peak_force_n"]), "yes" if h["accepted"] else "no",
                          h["reason"] or ""] for h in hits],
                        ["" if h["accepted"] else "bad" for h in hits]))
    if result.warnings:
        parts.append("<h2>Warnings</h2><ul>" + "".join(
            f"<li class='warn'>{html.escape(w)}</li>" for w in result.warnings) + "</ul>")
    parts.append("<h2>Explanation of the model-measurement residual</h2>")
    if explanation is None:
        parts.append(f"<p class='warn'>explain was not run: {html.escape(explain_error or 'no result')}</p>")
    else:
        data = explanation.to_dict()
        parts.append(f"<p>verdict: <b>{html.escape(data['verdict'])}</b>; RMS frequency error "
                     f"{fmt(data['error_before']['rms_frequency_error_pct'])} % before, "
                     f"{fmt(data['error_after']['rms_frequency_error_pct'])} % after</p>")
        for eff in data.get("effects", []):
            params = ", ".join(f"{k} = {fmt(v.get('value'))} ± {fmt(v.get('std'))}"
                               for k, v in eff.get("parameters", {}).items())
            parts.append(f"<p>effect <b>{html.escape(eff['name'])}</b>: {html.escape(params)}</p>")
        parts.append(_table(["mode", "measured (Hz)", "model before (Hz)", "model after (Hz)"],
                            [[m.get("label"), fmt(m.get("measured_hz")), fmt(m.get("model_before_hz")),
                              fmt(m.get("model_after_hz"))] for m in data.get("modes", [])]))
        for note in data.get("notes", []):
            parts.append(f"<p>{html.escape(str(note))}</p>")
    parts.append("</body></html>")
    return "\n".join(parts)


def write_report(path, out_path, guide=None) -> None:
    """Identify (and explain) one recording and write the HTML report."""
    from guidefit.errors import GuidefitError
    from guidefit.identify import identify

    result = identify(path, guide=guide)
    explanation, error = None, None
    try:
        from guidefit.explain import explain_identification

        explanation = explain_identification(result)
    except (GuidefitError, ImportError) as exc:
        error = str(exc)
    text = render_html(result, explanation, error)
    with open(out_path, "w", encoding="utf-8") as handle:
        handle.write(text)
