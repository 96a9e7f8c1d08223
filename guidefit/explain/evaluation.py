"""One model evaluation: effects applied, modes paired, prediction, residuals (:class:`Evaluation`).

Each measured mode ``i`` contributes

* a frequency residual ``(f_model - f_i) / sigma_i`` (``sigma_i`` with the
  forward model's own error in quadrature, if the candidate has one);
* if it has a shape at the sensors: the component of the measured unit shape
  vector perpendicular to the model's, ``(m - a (a . m)) sqrt(n_ch) / s``,
  whose squared norm is ``(1 - MAC) n_ch / s^2``;
* if the model has no mode to pair it with: a fixed residual of
  :data:`~guidefit.explain.settings.UNPAIRED_PENALTY` standard deviations.

Each force level adds ``(d - mean_w(d)) / sigma`` with
``d = f_model(F) - f_level``: the levels of one mode from one run are a trend
measured with one estimator, and only the trend is compared (one degree of
freedom per group). The prediction is the linear eigen-solution, or the
``forward`` of the candidate's effect that declares one (the registry of
:mod:`guidefit.model.effects`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from guidefit.errors import ModelError
from guidefit.explain.pairing import pair
from guidefit.explain.settings import BAD_RESIDUAL, UNPAIRED_PENALTY


@dataclass
class Context:
    """The nominal model of one explain call, its evaluation count and the forward models' cache."""

    guide: object
    spec: object
    n_eval: int = 0
    cache: dict = field(default_factory=dict)


@dataclass(frozen=True)
class Evaluation:
    """Residuals and prediction of one model.

    ``r``: the residual vector (frequencies, shape blocks, levels);
    ``pairing``: model mode per measured mode (-1 unpaired); ``f_pred``:
    predicted frequency per measured mode (nan unpaired); ``mac`` per
    measured mode (nan without shape); ``lv_pred`` per force level;
    ``sol``: the model's modes (None when it could not be evaluated).
    """

    r: np.ndarray
    pairing: np.ndarray
    f_pred: np.ndarray
    mac: np.ndarray
    lv_pred: np.ndarray
    sol: object
    ok: bool = True

    @property
    def chi2(self) -> float:
        return float(self.r @ self.r)


def _forward(ctx: Context, data, effects, spec, sol, pairing):
    """The prediction of a model: the linear one, or that of its effect with a ``forward``."""
    from guidefit.model.effects import EFFECTS, Forward, ForwardRequest, resolve_name

    fm = sol.frequencies_hz
    model, level_model = pairing.model, pairing.level_model
    nonlinear = [e for e in effects if EFFECTS[resolve_name(e.name)].forward is not None]
    if not nonlinear:
        f_pred = np.where(model >= 0, fm[np.maximum(model, 0)], np.nan)
        lv_pred = np.where(level_model >= 0, fm[np.maximum(level_model, 0)], np.nan)
        return Forward(f_pred, lv_pred, np.zeros(data.f.size), np.zeros(data.lv_f.size))
    if len(nonlinear) > 1:
        raise ModelError("explain: at most one effect with its own forward model per candidate")
    effect = nonlinear[0]
    zetas = np.full(fm.size, np.nan)  # damping of the model modes from their measured partners
    zetas[model[model >= 0]] = data.mode_zeta[model >= 0]
    request = ForwardRequest(
        guide=ctx.guide, spec=spec, solution=sol, parameters=dict(effect.parameters), effects=tuple(effects),
        mode_model=model, mode_label=tuple(data.labels), mode_run=tuple(data.mode_run),
        mode_levels=tuple(data.mode_levels), mode_measured_hz=data.f, model_damping=zetas,
        level_model=level_model, levels=data.levels, cache=ctx.cache)
    return EFFECTS[resolve_name(effect.name)].forward(request)


def _failed(data) -> Evaluation:
    n = data.f.size
    # as many residuals as a model that evaluates: frequencies, n_ch per shape, every level
    n_r = n + sum(int(s.unit.size) for s in data.shapes) + int(data.lv_f.size)
    return Evaluation(np.full(n_r, BAD_RESIDUAL), np.full(n, -1), np.full(n, np.nan), np.full(n, np.nan),
                      np.full(data.lv_f.size, np.nan), None, ok=False)


def _shape_residuals(data, pairing) -> tuple[list, np.ndarray]:
    blocks = []
    mac = np.full(data.f.size, np.nan)
    for s, a_set in zip(data.shapes, pairing.model_shapes):
        j = pairing.model[s.index]
        ok = j >= 0
        a = a_set[:, np.maximum(j, 0)].T
        block = (s.unit - a * np.sum(a * s.unit, axis=1, keepdims=True)) * s.scale[:, None]
        block[~ok] = 0.0
        blocks.append(block.ravel())
        mac[s.index[ok]] = pairing.mac[s.index[ok], j[ok]]
    return blocks, mac


def _level_residuals(data, lv_pred, lv_std) -> np.ndarray:
    """The trend within each group: its weighted mean removed (one dof per group)."""
    r_lv = np.full(data.lv_f.size, UNPAIRED_PENALTY)
    lv_sigma = np.hypot(data.lv_sigma, lv_std)
    for g in data.lv_groups:
        d, s = lv_pred[g] - data.lv_f[g], lv_sigma[g]
        w = s ** -2.0
        if np.all(np.isfinite(d)):
            r_lv[g] = (d - np.sum(w * d) / np.sum(w)) / s
    return r_lv


def evaluate(ctx: Context, data, effects) -> Evaluation:
    """Apply ``effects`` to the nominal model, solve, pair and form the residuals (module docstring)."""
    from guidefit.model import vibration as vib
    from guidefit.model.effects import apply_effects

    try:
        spec = apply_effects(ctx.spec, ctx.guide, effects) if effects else ctx.spec
        sol = vib.solve_modes(spec)
    except (ModelError, np.linalg.LinAlgError, ValueError):
        return _failed(data)
    pairing = pair(data, sol)
    pred = _forward(ctx, data, effects, spec, sol, pairing)
    sigma = np.hypot(data.sigma, pred.mode_std_hz)  # the forward model's own error, in quadrature
    r_f = np.where(pairing.model >= 0, (pred.mode_hz - data.f) / sigma, UNPAIRED_PENALTY)
    r_f = np.nan_to_num(r_f, nan=UNPAIRED_PENALTY)
    shape_blocks, mac = _shape_residuals(data, pairing)
    r_lv = _level_residuals(data, pred.level_hz, pred.level_std_hz)
    return Evaluation(np.concatenate([r_f, *shape_blocks, r_lv]), pairing.model, pred.mode_hz, mac,
                      pred.level_hz, sol)
