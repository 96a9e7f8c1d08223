"""The result type of ``guidefit explain``, the Explanation (its input types, measured modes, sensors and force
levels, are :mod:`guidefit.model.measured`'s)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

# --------------------------------------------------------------------------- result


def clean_json(x):
    """JSON-safe: numpy scalars to Python, non-finite floats to None."""
    if isinstance(x, dict):
        return {k: clean_json(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [clean_json(v) for v in x]
    if isinstance(x, np.generic):
        x = x.item()
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


@dataclass(frozen=True)
class Explanation:
    """The result of :func:`explain_modes`.

    ``verdict`` is ``adequate``, ``explained`` or ``unexplained``;
    ``error_before`` and ``error_after`` hold the RMS relative frequency error
    (%) of the nominal and of the selected model (for ``unexplained``: of the
    best attempt, marked in ``model``); ``effects`` the selected effects with
    parameter values and standard deviations; ``candidates`` every fitted
    model ranked by BIC; ``modes`` one entry per measured mode.
    """

    verdict: str
    guide: str
    error_before: dict
    error_after: dict
    effects: tuple
    candidates: tuple
    modes: tuple
    notes: tuple
    source: str | None = None
    best_attempt: dict | None = None
    alternatives: tuple = ()
    n_data: int = 0
    settings: dict = field(default_factory=dict)
    fitted_effects: tuple = ()  # guidefit.model.effects.Effect of the "after" model

    def to_dict(self) -> dict:
        """The contract's ``explain --json`` object, with optional extra fields."""
        return clean_json({
            "file": self.source,
            "guide": self.guide,
            "verdict": self.verdict,
            "error_before": dict(self.error_before),
            "error_after": dict(self.error_after),
            "effects": list(self.effects),
            "modes": list(self.modes),
            "candidates": list(self.candidates),
            "alternatives": list(self.alternatives),
            "best_attempt": self.best_attempt,
            "notes": list(self.notes),
            "n_data": self.n_data,
            "settings": dict(self.settings),
        })

    def to_frame(self):
        """One row per measured mode: frequencies before/after, errors (%) and MAC."""
        import pandas as pd

        cols = ["label", "run", "measured_hz", "measured_std_hz", "sigma_hz", "model_before_hz",
                "model_after_hz", "error_before_pct", "error_after_pct", "mac_before", "mac_after"]
        return pd.DataFrame([{c: m.get(c) for c in cols} for m in self.modes], columns=cols)

    def candidates_frame(self):
        """One row per fitted candidate, best BIC first."""
        import pandas as pd

        cols = ["name", "variant", "n_params", "chi2", "dof", "p_value", "bic", "delta_bic",
                "rms_frequency_error_pct", "accepted", "note"]
        return pd.DataFrame([{c: m.get(c) for c in cols} for m in self.candidates], columns=cols)


