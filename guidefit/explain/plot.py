"""Figure of an explanation: measured vs model frequencies before and after, optional FRF panel."""

from __future__ import annotations

import numpy as np

from guidefit.explain.inputs import Explanation


def plot_explanation(explanation: Explanation, path, frf=None) -> str:
    """Plot measured vs model frequencies before and after, and optional FRF overlays.

    Left: frequency per measured mode (measured with its 1-sigma bar, nominal
    model, fitted model). Right: relative error (%) before and after with the
    uncertainty band. ``frf``, if given, is a dict with ``frequency_hz`` and
    any of ``measured``, ``before``, ``after`` (complex or magnitude arrays of
    one FRF) and an optional ``title``: a third panel of magnitudes.

    Returns the path written.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    modes = list(explanation.modes)
    n_panels = 3 if frf else 2
    fig, axes = plt.subplots(1, n_panels, figsize=(5.2 * n_panels, 4.2))
    x = np.arange(len(modes))
    names = [f"{m['label']}" + (f"\n{m['run']}" if m.get("run") else "") for m in modes]

    def col(key):
        return np.array([np.nan if m.get(key) is None else m[key] for m in modes], dtype=float)

    ax = axes[0]
    ax.errorbar(x, col("measured_hz"), yerr=col("sigma_hz"), fmt="o", color="k", capsize=4, label="measured")
    ax.plot(x - 0.15, col("model_before_hz"), "x", color="tab:red", ms=9, label="model before")
    after_label = {"explained": "model after", "adequate": "model (nominal)"}.get(
        explanation.verdict, "best attempt (not accepted)")
    ax.plot(x + 0.15, col("model_after_hz"), "s", mfc="none", color="tab:blue", ms=8, label=after_label)
    ax.set_xticks(x, names, fontsize=8)
    ax.set_ylabel("frequency (Hz)")
    ax.set_title(f"verdict: {explanation.verdict}")
    ax.legend(fontsize=8)
    ax = axes[1]
    sig = 100 * col("sigma_hz") / col("measured_hz")
    ax.fill_between(np.r_[x - 0.4, x[-1:] + 0.4] if len(x) else x, 0, 0, color="none")
    ax.bar(x - 0.2, col("error_before_pct"), width=0.4, color="tab:red", alpha=0.7,
           label=f"before (RMS {explanation.error_before['rms_frequency_error_pct']:.2f} %)")
    ax.bar(x + 0.2, col("error_after_pct"), width=0.4, color="tab:blue", alpha=0.7,
           label=f"after (RMS {explanation.error_after['rms_frequency_error_pct']:.2f} %)")
    ax.errorbar(x + 0.2, np.zeros(len(x)), yerr=sig, fmt="none", color="k", capsize=4, label="1 sigma")
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set_xticks(x, names, fontsize=8)
    ax.set_ylabel("model - measured (%)")
    ax.set_yscale("symlog", linthresh=0.1)
    ax.legend(fontsize=8)
    if frf:
        ax = axes[2]
        f = np.asarray(frf["frequency_hz"], float)
        for key, style in (("measured", "k-"), ("before", "r--"), ("after", "b-")):
            if frf.get(key) is not None:
                ax.semilogy(f, np.abs(np.asarray(frf[key])), style, lw=1.0, label=key)
        ax.set_xlabel("frequency (Hz)")
        ax.set_ylabel("|H|")
        ax.set_title(frf.get("title", "FRF"))
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return str(path)


