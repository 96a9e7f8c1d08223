r"""Machine-level model updating of guidefit joints: ``guidefit update DECK MEASURED --param ...``.

The deck (:mod:`guidefit.machine.ccx_deck`) ``*INCLUDE``\ s joints exported by
guidefit; the measured modes are read as ``correlate`` reads them
(:func:`guidefit.machine.correlate.read_test`: guidefit JSON, UFF-55, CSV). The
parameters are factors on exported joint stiffnesses, p = f * (exported
value), fitted as theta = ln f within bounds.

Parameters (``--param SEL:NAME[=LO..HI]``)
-------------------------------------------
``NAME`` a direction of the joint (model frame): ``K_H`` (x, lateral),
``K_V`` (y, vertical), ``K_pitch`` (rx), ``K_yaw`` (ry), ``K_roll`` (rz),
or ``K`` (every direction: the whole matrix). The factor scales the joint as
K' = D K D, D = diag(sqrt f) over the named directions
(:mod:`guidefit.machine.ccx_deck`). ``SEL`` which joints: ``joint2`` (one),
``joint1,joint3`` (one factor shared by the two), ``all`` (one factor
shared by every joint) or ``each`` (one factor per joint). ``LO..HI`` the
factor's bounds (default 0.1..10; they must hold 1, the exported value).
Damping does not move undamped natural frequencies and cannot be updated
from them; ``c_*`` names are refused.

Residuals and solver
--------------------
Per paired test mode r_j = (f_FE,j - f_test,j) / f_test,j / sigma (Eq. 34 as
a fraction, over the relative measurement std sigma); pairing as
:func:`guidefit.machine.correlate.correlate` (MAC where shapes share points, else
order with a warning), redone at every solver run. The Jacobian
dr/dtheta is forward differences (step :data:`FD_STEP` in ln f; backward at an
upper bound), one ccx run per parameter, run in parallel (``jobs``);
scipy's ``least_squares`` (trust-region reflective, bounds) iterates.

Identifiability and uncertainty
-------------------------------
At the exported values the sensitivity matrix J (relative frequency per
unit ln f) is examined first: a parameter whose column is below
:data:`SENS_FLOOR` moves no paired frequency; singular values below
SENS_FLOOR x sqrt(m) name the parameters of the null direction (only a
combination of them is seen). Those are held at their exported value (a
warning names them) and the rest are fitted. At the solution
cov(theta) = s^2 (J^T J)^-1 with s the given measurement std
(``freq_std_pct``) or, when none is given, the residual's
(s^2 = sum r^2 / (m - n), m modes, n parameters); a factor's std is
f std(theta). A parameter whose std(theta) reaches
:data:`IDENTIFIABLE_LOG_STD` (a factor 1.65, as ``explain``) is "not
identifiable from these modes".
"""

from __future__ import annotations

import math
import re
import tempfile
import threading
import time
import warnings
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from guidefit.machine.ccx_deck import Deck, DeckError, find_ccx, load_deck, render_joint_file, run_ccx, stage
from guidefit.machine.correlate import CorrelateError, Correlation, correlate

#: model directions scaled by each parameter name (indices into x, y, z, rx, ry, rz)
NAMES = {"K_H": (0,), "K_V": (1,), "K_pitch": (3,), "K_yaw": (4,), "K_roll": (5,), "K": (0, 1, 2, 3, 4, 5)}
DEFAULT_BOUNDS = (0.1, 10.0)
#: forward-difference step in ln f (2 %): ccx prints 7 digits, so the difference is good to ~1e-5
FD_STEP = 0.02
#: sensitivity (relative frequency per unit ln f) below which a parameter moves nothing measurable
SENS_FLOOR = 1e-4
IDENTIFIABLE_LOG_STD = 0.5
#: median FE/test frequency ratio beyond which the model and the measurement cannot be the same machine
UNIT_RATIO = 2.0


class UpdateError(DeckError):
    """Bad input to update (exit 2, one line)."""


@dataclass(frozen=True)
class Param:
    """One fitted factor: its display name, the joints it scales, the directions, and bounds."""

    name: str
    joints: tuple  # indices into deck.joints
    directions: tuple  # model DOF indices
    kind: str  # K_V, ...
    lower: float
    upper: float


def _bounds(text: str | None, where: str) -> tuple[float, float]:
    if not text:
        return DEFAULT_BOUNDS
    m = re.fullmatch(r"\s*([^.\s][^\s]*?)\s*\.\.\s*(\S+)\s*", text)
    try:
        lo, hi = (float(m.group(1)), float(m.group(2))) if m else (math.nan, math.nan)
    except ValueError:
        lo = hi = math.nan
    if not (math.isfinite(lo) and math.isfinite(hi) and 0 < lo <= 1.0 <= hi and lo < hi):
        raise UpdateError(f"--param '{where}': bounds '{text}' must be LO..HI factors with 0 < LO <= 1 <= HI "
                          "(e.g. 0.5..2; 1 is the exported value)")
    return lo, hi


def _joint_index(token: str, n: int, where: str) -> int:
    m = re.fullmatch(r"joint(\d+)", token.strip())
    if not m or not 1 <= int(m.group(1)) <= n:
        raise UpdateError(f"--param '{where}': '{token.strip()}' is not a joint of the deck (joint1..joint{n}, "
                          "all or each)")
    return int(m.group(1)) - 1


def parse_params(texts, n_joints: int) -> list[Param]:
    """``SEL:NAME[=LO..HI]`` texts -> :class:`Param` s (see the module docstring); overlaps refused."""
    out: list[Param] = []
    for text in texts:
        sel, colon, rest = text.partition(":")
        name, _, bounds = rest.partition("=")
        name = name.strip()
        if not colon or not sel.strip():
            raise UpdateError(f"--param '{text}': expected SEL:NAME[=LO..HI], e.g. each:K_V=0.5..2 or joint1:K_H")
        if name.startswith("c"):
            raise UpdateError(f"--param '{text}': damping does not change undamped natural frequencies, so "
                              f"update cannot fit '{name}'; use {', '.join(NAMES)}")
        if name not in NAMES:
            raise UpdateError(f"--param '{text}': '{name}' unknown; use {', '.join(NAMES)}")
        lo, hi = _bounds(bounds, text)
        sel = sel.strip()
        if sel == "each":
            groups = [((j,), f"joint{j + 1}:{name}") for j in range(n_joints)]
        elif sel == "all":
            groups = [(tuple(range(n_joints)), f"all:{name}")]
        else:
            idx = tuple(sorted({_joint_index(t, n_joints, text) for t in sel.split(",")}))
            groups = [(idx, "+".join(f"joint{j + 1}" for j in idx) + f":{name}")]
        for joints, label in groups:
            out.append(Param(label, joints, NAMES[name], name, lo, hi))
    if not out:
        raise UpdateError("no --param given: say which joint parameters may change, e.g. --param each:K_V=0.5..2")
    seen: dict = {}
    for p in out:
        for j in p.joints:
            for d in p.directions:
                if (j, d) in seen:
                    raise UpdateError(f"--param: {p.name} and {seen[j, d]} both scale joint{j + 1} "
                                      f"direction {'x y z rx ry rz'.split()[d]}; give each direction once")
                seen[j, d] = p.name
    return out


def joint_factors(deck: Deck, params: list[Param], f: np.ndarray) -> list[np.ndarray]:
    """Per joint file, (n_carriages, 6) model-direction factors for parameter factors ``f``."""
    per_joint = np.ones((len(deck.joints), 6))
    for p, value in zip(params, f):
        for j in p.joints:
            per_joint[j, list(p.directions)] *= value
    out = [np.ones((len(jf.carriages), 6)) for jf in deck.joint_files]
    for j, (k, c) in enumerate(deck.joints):
        out[k][c] = per_joint[j]
    return out


# --------------------------------------------------------------------------- solver runs


@dataclass
class Runner:
    """Runs ccx on the deck for factor vectors, in parallel; counts runs and solver time."""

    deck: Deck
    params: list
    test: object
    ccx: str
    folder: Path
    point_map: dict | None = None
    jobs: int = 1
    progress: object = None
    timeout_s: float = 600.0
    runs: int = 0
    ccx_seconds: float = 0.0
    notes: list = field(default_factory=list)
    cache: dict = field(default_factory=dict)
    lock: object = field(default_factory=threading.Lock)

    def _one(self, f: np.ndarray) -> Correlation:
        with self.lock:
            n = self.runs
            self.runs += 1
        folder = self.folder / f"run{n}"
        folder.mkdir()
        stage(self.deck, folder, joint_factors(self.deck, self.params, f))
        fe, seconds = run_ccx(self.ccx, folder, self.timeout_s)
        with self.lock:
            self.ccx_seconds += seconds
        for p in folder.iterdir():
            p.unlink()
        folder.rmdir()
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                result = correlate(fe, self.test, self.point_map)
        except CorrelateError as exc:
            raise UpdateError(str(exc)) from None
        for note in result.warnings:
            if note not in self.notes:
                self.notes.append(note)
        if self.progress is not None:
            with self.lock:
                self.progress()
        return result

    def many(self, fs: list[np.ndarray]) -> list[Correlation]:
        """Correlations of the factor vectors (cached by value), ``jobs`` ccx runs at a time."""
        keys = [tuple(np.round(np.log(f), 12)) for f in fs]
        todo = [(k, f) for k, f in {k: f for k, f in zip(keys, fs)}.items() if k not in self.cache]
        if self.jobs > 1 and len(todo) > 1:
            with ThreadPoolExecutor(self.jobs) as pool:
                results = list(pool.map(self._one, [f for _, f in todo]))
        else:
            results = [self._one(f) for _, f in todo]
        self.cache.update({k: r for (k, _), r in zip(todo, results)})
        return [self.cache[k] for k in keys]


def residuals(result: Correlation, sigma: float) -> np.ndarray:
    """Eq. (34) errors as fractions over sigma, one per test mode (ascending test frequency)."""
    return np.array([r["error_pct"] / 100.0 for r in result.rows]) / sigma


def jacobian(runner: Runner, theta: np.ndarray, free: list, upper: np.ndarray, sigma: float) -> np.ndarray:
    """Forward differences dr/dtheta of the free parameters (backward at an upper bound); parallel runs."""
    base = residuals(runner.many([np.exp(theta)])[0], sigma)
    steps, fs = [], []
    for k in free:
        h = FD_STEP if theta[k] + FD_STEP <= upper[k] else -FD_STEP
        t = theta.copy()
        t[k] += h
        steps.append(h)
        fs.append(np.exp(t))
    out = runner.many(fs)
    return np.column_stack([(residuals(r, sigma) - base) / h for r, h in zip(out, steps)]) if free else \
        np.zeros((base.size, 0))


def unidentifiable(jac: np.ndarray, names: list, sigma: float) -> list[tuple[list, str]]:
    """Groups of parameter names the sensitivities cannot separate, with the reason (see module docstring)."""
    j = jac * sigma  # relative frequency per unit ln f
    out, dead = [], []
    for k, name in enumerate(names):
        if np.linalg.norm(j[:, k]) < SENS_FLOOR:
            out.append(([name], "it moves no paired frequency (sensitivity below 1e-4 per unit ln f)"))
            dead.append(k)
    alive = [k for k in range(len(names)) if k not in dead]
    if alive:
        _, s, vt = np.linalg.svd(j[:, alive], full_matrices=True)
        s = np.concatenate([s, np.zeros(len(alive) - s.size)])
        for i in np.flatnonzero(s < SENS_FLOOR * math.sqrt(j.shape[0])):
            v = vt[i]
            group = [names[alive[k]] for k in np.flatnonzero(np.abs(v) > 0.3)]
            named = {g for o in out for g in o[0]}
            if group and not named.intersection(group):
                out.append((group, f"only a combination of {', '.join(group)} moves the paired frequencies "
                                   f"(sensitivity matrix rank {int(np.sum(s >= SENS_FLOOR * math.sqrt(j.shape[0])))}"
                                   f" of {len(alive)})"))
    return out


# --------------------------------------------------------------------------- the update


@dataclass
class UpdateResult:
    """Before/after correlation, fitted factors with their std, identifiability, and run counts."""

    deck: Deck
    params: list
    factors: np.ndarray
    std_log: np.ndarray  # std of ln f (nan where not fitted)
    fitted: list  # bool per parameter
    problems: list  # [(names, reason)]
    before: Correlation
    after: Correlation
    sigma: float
    sigma_from: str
    condition: float
    runs: int
    ccx_seconds: float
    total_seconds: float
    notes: list
    written: list = field(default_factory=list)

    def exported(self, p: Param) -> list:
        """The exported diagonal value of the parameter's first direction, per joint (file units)."""
        d = p.directions[0] if len(p.directions) == 1 else 1
        return [float(self.deck.joint_files[self.deck.joints[j][0]].model_diagonal(self.deck.joints[j][1])[d])
                for j in p.joints]

    def to_dict(self) -> dict:
        rows = []
        for k, p in enumerate(self.params):
            f, s = float(self.factors[k]), float(self.std_log[k])
            rows.append({"name": p.name, "kind": p.kind, "joints": [f"joint{j + 1}" for j in p.joints],
                         "factor": f, "factor_std": f * s if math.isfinite(s) else None,
                         "log_std": s if math.isfinite(s) else None, "lower": p.lower, "upper": p.upper,
                         "exported": self.exported(p), "updated": [v * f for v in self.exported(p)],
                         "fitted": self.fitted[k], "identifiable": self.identifiable(k),
                         "at_bound": self.at_bound(k)})
        return {"deck": str(self.deck.path), "units": self.deck.units,
                "joints": [{"name": f"joint{i + 1}", "file": str(self.deck.joint_files[k].path), "carriage": c + 1,
                            "source": self.deck.joint_files[k].sources[c]} for i, (k, c) in enumerate(self.deck.joints)],
                "parameters": rows, "not_identifiable": [{"parameters": g, "reason": r} for g, r in self.problems],
                "sigma_pct": self.sigma * 100 if math.isfinite(self.sigma) else None, "sigma_from": self.sigma_from,
                "condition": self.condition if math.isfinite(self.condition) else None,
                "before": self.before.to_dict(), "after": self.after.to_dict(), "runs": self.runs,
                "ccx_seconds": self.ccx_seconds, "total_seconds": self.total_seconds, "warnings": self.notes,
                "written": [str(w) for w in self.written]}

    def identifiable(self, k: int) -> bool:
        s = self.std_log[k]
        return bool(self.fitted[k] and math.isfinite(s) and s < IDENTIFIABLE_LOG_STD)

    def at_bound(self, k: int) -> bool:
        p, f = self.params[k], self.factors[k]
        return bool(self.fitted[k] and (abs(math.log(f / p.lower)) < 1e-3 or abs(math.log(p.upper / f)) < 1e-3))


def _check_units(result: Correlation, deck: Deck) -> None:
    ratio = float(np.median([r["fe_hz"] / r["test_hz"] for r in result.rows]))
    if not 1 / UNIT_RATIO <= ratio <= UNIT_RATIO:
        raise UpdateError(f"{deck.path}: the model's frequencies are {ratio:.3g} x the measured ones (median): "
                          f"units that disagree? (the joints are in {deck.units}; the deck's mass, length and "
                          "stiffness must be in the same system) - a joint update cannot bridge that")


def _covariance(jac: np.ndarray, r: np.ndarray, freq_std_pct: float | None, sigma: float):
    """(std of theta per fitted column, sigma used, where it came from)."""
    m, n = jac.shape
    if freq_std_pct is not None:
        s, source = 1.0, f"given --freq-std {freq_std_pct:g} %"
    elif m > n:
        s, source = math.sqrt(float(r @ r) / (m - n)), "residual (sum r^2 / (m - n))"
    else:
        return np.full(n, np.nan), math.nan, "none: as many parameters as modes; give --freq-std"
    cov = np.linalg.pinv(jac.T @ jac) * s**2
    return np.sqrt(np.clip(np.diag(cov), 0, None)), s * sigma, source


def update(deck_path, measured_path, param_texts, *, point_map_path=None, freq_std_pct: float | None = None,
           jobs: int = 1, ccx: str | None = None, progress=None, max_iterations: int = 20,
           timeout_s: float = 600.0) -> UpdateResult:
    """Fit the joint factors to the measured modes (see the module docstring); nothing is written here.

    ``progress()`` (no argument) is called after each ccx run, from the worker threads (the
    command passes :meth:`guidefit.progress.Bar.advance`, the one progress protocol).
    """
    from scipy.optimize import least_squares

    from guidefit.machine.correlate import read_point_map, read_test

    t0 = time.perf_counter()
    deck = load_deck(deck_path)
    params = parse_params(param_texts, len(deck.joints))
    test = read_test(measured_path)
    point_map = read_point_map(point_map_path) if point_map_path else None
    if freq_std_pct is not None and not (math.isfinite(freq_std_pct) and freq_std_pct > 0):
        raise UpdateError(f"--freq-std {freq_std_pct}: must be a positive percentage")
    sigma = (freq_std_pct or 1.0) / 100.0
    program = find_ccx(ccx)
    n = len(params)
    lower = np.log([p.lower for p in params])
    upper = np.log([p.upper for p in params])
    with tempfile.TemporaryDirectory(prefix="guidefit-update-") as tmp:
        runner = Runner(deck, params, test, program, Path(tmp), point_map, jobs, progress, timeout_s)
        theta0 = np.zeros(n)
        before = runner.many([np.ones(n)])[0]
        _check_units(before, deck)
        if len(before.rows) < 1:
            raise UpdateError(f"{measured_path}: no measured mode to fit")
        j0 = jacobian(runner, theta0, list(range(n)), upper, sigma)
        problems = unidentifiable(j0, [p.name for p in params], sigma)
        held = {name for group, _ in problems for name in group}
        free = [k for k, p in enumerate(params) if p.name not in held]
        theta = theta0.copy()
        jac_free = j0[:, free]
        if free:
            def fun(x):
                t = theta0.copy()
                t[free] = x
                return residuals(runner.many([np.exp(t)])[0], sigma)

            def jac(x):
                t = theta0.copy()
                t[free] = x
                return jacobian(runner, t, free, upper, sigma)

            lo, hi = lower[free], upper[free]
            x0 = np.clip(np.zeros(len(free)), lo + 1e-9, hi - 1e-9)
            sol = least_squares(fun, x0, jac=jac, bounds=(lo, hi), method="trf", x_scale=1.0,
                                xtol=1e-6, ftol=1e-10, gtol=1e-10, max_nfev=max_iterations)
            theta[free] = sol.x
            jac_free = jacobian(runner, theta, free, upper, sigma)
        after = runner.many([np.exp(theta)])[0]
        r = residuals(after, sigma)
        std_free, sigma_used, source = _covariance(jac_free, r, freq_std_pct, sigma)
        std = np.full(n, np.nan)
        std[free] = std_free
        cond = float(np.linalg.cond(jac_free)) if free else math.nan
        final = unidentifiable(jac_free, [params[k].name for k in free], sigma) if free else []
        problems += final
        result = UpdateResult(deck, params, np.exp(theta), std, [k in free for k in range(n)], problems, before,
                              after, sigma_used, source, cond, runner.runs, runner.ccx_seconds,
                              time.perf_counter() - t0, runner.notes)
    for k in free:
        if not result.identifiable(k) and math.isfinite(std[k]):
            result.problems.append(([params[k].name], f"std of ln f {std[k]:.3g} >= {IDENTIFIABLE_LOG_STD} "
                                                      "(a factor 1.65): not identifiable from these modes"))
    return result


def updated_texts(result: UpdateResult, sources: tuple = ()) -> dict:
    """{joint file path: updated text}, a comment block naming the update in each."""
    from guidefit import __version__
    from guidefit.export.core import _comment_lines

    factors = joint_factors(result.deck, result.params, result.factors)
    out = {}
    for k, jf in enumerate(result.deck.joint_files):
        mine = [(i, p) for i, p in enumerate(result.params)
                if any(result.deck.joints[j][0] == k for j in p.joints)]
        text = f"updated by guidefit {__version__} update from {' and '.join(str(s) for s in sources)}: "
        text += "; ".join(f"{p.name} x {result.factors[i]:.6g}" + (
            f" (std {result.factors[i] * result.std_log[i]:.2g})" if math.isfinite(result.std_log[i]) else "")
            + ("" if result.identifiable(i) else " NOT IDENTIFIED, kept") for i, p in mine) if mine else "no change"
        out[jf.path] = render_joint_file(jf, factors[k], header=_comment_lines("**", text))
    return out


def render(result: UpdateResult) -> str:
    """Parameters (exported -> updated, factor and std) and Table 3 before and after."""
    lines = [f"{'parameter':<24} {'exported':>12} {'updated':>12} {'factor':>8} {'std':>8}  note"]
    for k, p in enumerate(result.params):
        ex = result.exported(p)
        f, s = result.factors[k], result.std_log[k]
        note = "held (not identifiable)" if not result.fitted[k] else (
            "at a bound" if result.at_bound(k) else "" if result.identifiable(k) else "not identifiable")
        std = f"{f * s:.3g}" if math.isfinite(s) else "-"
        lines.append(f"{p.name:<24} {ex[0]:>12.5g} {ex[0] * f:>12.5g} {f:>8.4f} {std:>8}  {note}".rstrip())
    lines.append(f"stiffness in the joints' units ({result.deck.units}); std from {result.sigma_from}"
                 + (f", sigma {result.sigma * 100:.3g} %" if math.isfinite(result.sigma) else "")
                 + (f"; condition of the sensitivities {result.condition:.3g}" if math.isfinite(result.condition)
                    else ""))
    for group, reason in result.problems:
        lines.append(f"not identifiable: {', '.join(group)}: {reason}")
    lines.append("")
    head = f"{'test':>4} {'FE':>4} {'test f (Hz)':>12} {'before f':>12} {'error %':>8} {'after f':>12} " \
           f"{'error %':>8} {'MAC':>6}"
    lines.append(head)
    for b, a in zip(result.before.rows, result.after.rows):
        m = "" if a["mac"] is None else f"{a['mac']:.3f}"
        lines.append(f"{a['test_mode']:>4} {a['fe_mode']:>4} {a['test_hz']:>12.6g} {b['fe_hz']:>12.6g} "
                     f"{b['error_pct']:>+8.2f} {a['fe_hz']:>12.6g} {a['error_pct']:>+8.2f} {m:>6}")
    worst_b = max(abs(r["error_pct"]) for r in result.before.rows)
    worst_a = max(abs(r["error_pct"]) for r in result.after.rows)
    lines.append(f"paired by {result.after.paired_by}; Eq. (34) error = (f_FE - f_test) / f_test x 100 %; "
                 f"largest |error| {worst_b:.3g} % before, {worst_a:.3g} % after")
    lines.append(f"{result.runs} ccx runs: {result.ccx_seconds:.2f} s of solver time (summed over the parallel "
                 f"runs), {result.total_seconds:.2f} s in all")
    return "\n".join(lines) + "\n"
