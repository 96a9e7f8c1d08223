r"""Test-analysis correlation: the paper's Table 3 for any structure (``guidefit correlate FE TEST``).

FE side: :func:`guidefit.io.fe_results.read_fe` (CalculiX ``.dat``/``.frd``,
Nastran ``.f06``/``.op2``, CSV). Test side: UFF-55 mode shapes
(``.uff``/``.unv``), measured FRFs (UFF-58 function type 4, any number of
references, or guidefit's ``frf.h5``) fitted by guidefit's global estimator
(:func:`read_test_frfs`), guidefit JSON results (``identify --json``: modes
with ``frequency_hz`` and ``shape``), or a CSV of measured frequencies (and
shapes).

Pairing: where both sides have shapes at common points (names equal, or
mapped by a point-map file: lines ``test_point = fe_point``), each test mode
is paired with the FE mode of largest MAC (one FE mode per test mode, the
assignment of largest total MAC); else by order (lowest test mode with lowest
FE mode; with more FE modes, those skipped keep the pairs nearest in
frequency: :func:`order_pairing`), with a warning. The error is the paper's Eq. (34),
e = (f_FE - f_test) / f_test x 100 %, signed (positive: the model is stiff);
``--check max_error_pct`` bounds its magnitude.

MAC(a, b) = |a^H b|^2 / ((a^H a)(b^H b)) over the common DOFs (Allemang).

Examples
--------
>>> mac(np.array([1.0, 2.0]), np.array([2.0, 4.0]))
1.0
>>> round(eq34_error_pct(1014.0, 1000.0), 6)
1.4
"""

from __future__ import annotations

import math
import re
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from guidefit.errors import GuidefitError
from guidefit.io.fe_results import FEModes, FEResultError, read_fe, read_modes_csv

CHECKS = ("max_error_pct", "min_mac")
#: weight of |ln(f_FE / f_test)| against MAC in the pairing: a tie-break between FE modes of equal MAC
FREQUENCY_TIE_BREAK = 0.01
#: another FE mode's MAC this close to the pair's: the shapes cannot tell them apart (a warning)
MAC_ALIKE = 0.01


class CorrelateError(GuidefitError, ValueError):
    """Bad input to correlate (exit 2, one line)."""


def mac(a: np.ndarray, b: np.ndarray) -> float:
    """Modal assurance criterion of two shape vectors (complex allowed)."""
    a, b = np.asarray(a).ravel(), np.asarray(b).ravel()
    den = float(np.real(np.vdot(a, a)) * np.real(np.vdot(b, b)))
    return float(abs(np.vdot(a, b)) ** 2 / den) if den > 0 else 0.0


def eq34_error_pct(f_fe: float, f_test: float) -> float:
    """The paper's Eq. (34): relative error of the FE frequency, % of the measured one."""
    return (f_fe - f_test) / f_test * 100.0


# --------------------------------------------------------------------------- test side


def _split_channel(name: str) -> tuple[str, int] | None:
    """``acc_A_x`` or ``A:x`` -> (``A``, 0); None when the name carries no direction."""
    m = re.match(r"^(?:acc_)?(.+?)[_:]([xyzXYZ])$", name.strip())
    return (m.group(1), "xyz".index(m.group(2).lower())) if m else None


def _sensor_axes(docs) -> dict:
    """Channel -> (axis index, sign) from the results' ``sensors`` directions; None for an oblique sensor.

    A modal constant is read along the sensor's direction: a side-face sensor ``acc_G_x`` declared along
    -x reads -x motion, and was put on +x (a per-DOF sign error, so a wrong MAC); an oblique sensor
    reads no single axis and is left out.
    """
    out = {}
    for d in docs:
        for s in (d.get("sensors") or []) if isinstance(d, dict) else []:
            if not isinstance(s, dict) or "name" not in s or not isinstance(s.get("direction"), list):
                continue
            try:
                v = np.asarray(s["direction"], float)
            except (TypeError, ValueError):
                continue
            if v.shape != (3,) or not np.all(np.isfinite(v)) or not np.linalg.norm(v) > 0:
                continue
            v = v / np.linalg.norm(v)
            k = int(np.argmax(np.abs(v)))
            out.setdefault(str(s["name"]), (k, float(np.sign(v[k]))) if abs(v[k]) > 1 - 1e-6 else None)
    return out


def read_test_json(path) -> FEModes:
    """Modes of guidefit results (``identify --json``): frequencies and real shapes at the sensors."""
    from guidefit.jsonio import read_json_documents

    docs = []
    for d in read_json_documents(path):
        docs.extend(d if isinstance(d, list) else [d])
    modes = [m for d in docs if isinstance(d, dict) for m in (d.get("modes") or [])
             if isinstance(m, dict) and m.get("level") is None and m.get("frequency_hz") is not None]
    if not modes:
        raise CorrelateError(f"{path}: no modes with a frequency_hz (is it identify --json output?)")
    freqs = np.array([float(m["frequency_hz"]) for m in modes])
    if not np.all(np.isfinite(freqs)) or np.any(freqs <= 0):
        raise CorrelateError(f"{path}: a mode's frequency_hz is not a positive number")
    axes = _sensor_axes(docs)
    shapes: dict = {}
    for k, m in enumerate(modes):
        for channel, value in (m.get("shape") or {}).items():
            split = _split_channel(str(channel))
            if split is None or value is None or axes.get(str(channel), 1) is None:
                continue
            point, axis = split
            sign = 1.0
            if str(channel) in axes:  # the sensor's own direction, not its name's axis letter
                axis, sign = axes[str(channel)]
            shapes.setdefault(point, np.full((len(modes), 3), np.nan))[k, axis] = sign * float(value)
    labels = tuple(str(m.get("label") or "") for m in modes)
    return FEModes(freqs, shapes, str(path), labels)


def read_test_uff(path) -> FEModes:
    """UFF-55 normal-mode sets (pyuff): frequency and the three translations at each node."""
    try:
        import pyuff
    except ImportError:  # pragma: no cover - pyuff is a dependency
        raise CorrelateError(f"{path}: reading UFF needs pyuff") from None
    try:
        sets = [s for s in pyuff.UFF(str(path)).read_sets() if isinstance(s, dict)]
    except Exception as exc:  # noqa: BLE001 - pyuff raises many types for a bad file
        raise CorrelateError(f"{path}: not a readable UFF file ({type(exc).__name__})") from None
    sets = [s for s in sets if s.get("type") == 55 and s.get("freq") is not None]
    if not sets:
        raise CorrelateError(f"{path}: no UFF-55 mode shapes with a frequency (normal modes, analysis type 2)")
    freqs = np.array([float(s["freq"]) for s in sets])
    shapes: dict = {}
    for k, s in enumerate(sets):
        for i, node in enumerate(np.asarray(s["node_nums"]).astype(int)):
            row = shapes.setdefault(str(node), np.full((len(sets), 3), np.nan))
            row[k] = [np.real(s[f"r{j}"][i]) for j in (1, 2, 3)]
    return FEModes(freqs, shapes, str(path))


def fit_band(fe: FEModes, frequency_hz: np.ndarray) -> tuple[float, float]:
    """The band an FRF fit covers by default: the FE modes' range, 0.5x below and 1.5x above, in the data."""
    f = np.asarray(frequency_hz, float)
    lo = max(0.5 * float(np.min(fe.frequencies_hz)), float(f[f > 0][0]) if np.any(f > 0) else 0.0)
    return lo, min(1.5 * float(np.max(fe.frequencies_hz)), 0.8 * float(f[-1]))


def _dof(channel: str, direction) -> tuple[str, int, float] | None:
    """(point, axis, sign) of a response channel ``acc_<point>_<axis>`` along a global axis; ``N101`` is ``101``."""
    split = _split_channel(channel)
    d = np.asarray(direction, float)
    if split is None or not np.all(np.isfinite(d)) or not np.any(d):
        return None
    axis = int(np.argmax(np.abs(d)))
    point = split[0][1:] if re.fullmatch(r"N\d+", split[0]) else split[0]
    return point, axis, float(np.sign(d[axis]))


def _rank_one(R: np.ndarray, start: int, iterations: int = 50) -> np.ndarray:
    """psi of R ~ psi L^T over R's finite entries (DOFs x references), from column ``start``; NaN where unlinked."""
    seen = np.isfinite(R)
    linked, cols = seen[:, start].copy(), {start}
    while True:  # the references that share a response DOF with those taken, and their DOFs
        more = {j for j in range(R.shape[1]) if j not in cols and np.any(seen[:, j] & linked)}
        if not more:
            break
        cols |= more
        linked |= np.any(seen[:, sorted(more)], axis=1)
    cols = sorted(cols)
    A, W = np.where(seen, R, 0.0)[np.ix_(linked, cols)], seen[np.ix_(linked, cols)]
    psi, L = A[:, cols.index(start)].copy(), np.zeros(len(cols), complex)
    for _ in range(iterations):  # alternating least squares on the observed entries
        L = (np.conj(psi) @ A) / np.maximum((np.abs(psi) ** 2) @ W, 1e-300)
        psi = (A @ np.conj(L)) / np.maximum(W @ (np.abs(L) ** 2), 1e-300)
    out = np.full(R.shape[0], np.nan, complex)
    out[linked] = psi
    return out


def read_test_frfs(path, fe: FEModes, band_hz: tuple | None = None) -> FEModes:
    """Modes of measured FRFs (UFF-58 type 4 or guidefit's frf.h5) by guidefit's global estimator.

    All runs (one per reference) are fitted together
    (:func:`guidefit.modes.globalfit.global_fit`: LSCF stabilisation diagram, pole
    selection, shared-pole least squares) in ``band_hz`` (default
    :func:`fit_band` of the FE modes). Each mode's shape at the response DOFs
    is the rank-one fit psi L^T of its residues (DOFs x references) over the
    references linked to the one that shows the mode most by a common
    response DOF; DOFs only other references measure are NaN for that mode
    (their scale relative to it is unknown), made real by the best phase.
    """
    from guidefit.errors import GuidefitError as _Error
    from guidefit.io.frf_files import read_frf_file
    from guidefit.modes.globalfit import global_fit
    from guidefit.modes.shapes import real_shape

    try:
        frfs = read_frf_file(path)
    except _Error as exc:
        raise CorrelateError(str(exc)) from None
    runs = {run.name: (run, s) for run, s in zip(frfs.recording.runs, frfs.frfsets)}
    f = np.asarray(frfs.frfsets[0].frequency_hz, float)
    band = tuple(band_hz) if band_hz else fit_band(fe, f)
    if not band[0] < band[1]:
        raise CorrelateError(f"{path}: the FRFs end at {f[-1]:g} Hz, below the FE modes (from "
                             f"{np.min(fe.frequencies_hz):g} Hz): give --band LO,HI")
    try:
        gf = global_fit({n: s for n, (_, s) in runs.items()}, band, jackknife=False, selection_spread=False)
    except _Error as exc:
        raise CorrelateError(f"{path}: {exc}") from None
    dofs, rows = [], []  # rows: (DOF index, reference index, sign) per fitted column
    refs = list(gf.runs)
    for run_name, channel in gf.columns:
        run = runs[run_name][0]
        ch = next(c for c in run.channels if c.name == channel)
        dof = _dof(channel, ch.direction)
        if dof is None:
            rows.append(None)
            continue
        if dof[:2] not in dofs:
            dofs.append(dof[:2])
        rows.append((dofs.index(dof[:2]), refs.index(run_name), dof[2]))
    if not dofs:
        raise CorrelateError(f"{path}: no response channel named acc_<point>_<axis>: no shapes")
    shapes = {p: np.full((len(gf.modes), 3), np.nan) for p, _ in dofs}
    for k, mode in enumerate(gf.modes):
        R = np.full((len(dofs), len(refs)), np.nan, complex)
        for row, value in zip(rows, np.asarray(mode.residues)):
            if row is not None:
                R[row[0], row[1]] = row[2] * value
        strength = [np.sum(np.abs(np.nan_to_num(R[:, j])) ** 2) for j in range(len(refs))]
        psi = _rank_one(R, int(np.argmax(strength)))
        seen = np.isfinite(psi)
        values = np.full(len(dofs), np.nan)
        values[seen] = real_shape(psi[seen])
        for (point, axis), v in zip(dofs, values):
            shapes[point][k, axis] = v
    freqs = np.array([m.frequency_hz for m in gf.modes])
    return FEModes(freqs, shapes, str(path))


def _has_uff55(path) -> bool:
    """A UFF file with datasets 55 (mode shapes): they are the test modes, its FRFs are not refitted."""
    if Path(path).suffix.lower() not in (".uff", ".unv"):
        return False
    from guidefit.errors import RecordingError
    from guidefit.io.uff import open_uff

    try:
        return 55 in open_uff(str(path))[1]
    except RecordingError:
        return False


def read_test(path, fe: FEModes | None = None, band_hz: tuple | None = None) -> FEModes:
    """The test side of ``correlate``, by suffix; FRFs (UFF-58, frf.h5) are fitted in the FE modes' band."""
    from guidefit.io.frf_files import holds_frfs

    suffix = Path(path).suffix.lower()
    if suffix in (".json", ".jsonl"):
        return read_test_json(path)
    if suffix in (".uff", ".unv", ".h5", ".hdf5") and holds_frfs(path) and not _has_uff55(path):
        if fe is None:
            raise CorrelateError(f"{path}: holds FRFs, fitted in the FE modes' band, which is not known here: give "
                                 "the measured modes (UFF-55, guidefit JSON or CSV)")
        return read_test_frfs(path, fe, band_hz)
    if suffix in (".uff", ".unv"):
        return read_test_uff(path)
    if suffix == ".csv":
        return read_modes_csv(path, "test")
    raise CorrelateError(f"{path}: test modes are read from .uff/.unv (UFF-55 shapes or UFF-58 FRFs), guidefit's "
                         f"frf.h5, .json/.jsonl (guidefit results) or .csv; not '{suffix or 'no suffix'}'")


def read_point_map(path) -> dict[str, str]:
    """``test_point = fe_point`` (or ``test_point,fe_point``) per line; ``#`` comments."""
    out = {}
    try:
        lines = Path(path).read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise CorrelateError(f"{path}: cannot read the point map: {exc}") from None
    for n, line in enumerate(lines, 1):
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        parts = [p.strip() for p in re.split(r"[=,]", line)]
        if len(parts) != 2 or not all(parts):
            raise CorrelateError(f"{path}:{n}: expected 'test_point = fe_point', got '{line[:40]}'")
        out[parts[0]] = parts[1]
    return out


# --------------------------------------------------------------------------- pairing


@dataclass
class Correlation:
    """The Table 3 rows (one per test mode) and the MAC matrix (FE x test), None without shapes."""

    rows: list
    mac: np.ndarray | None
    points: tuple
    paired_by: str  # "mac" or "order"
    warnings: tuple = ()

    def to_dict(self) -> dict:
        return {"paired_by": self.paired_by, "common_points": list(self.points), "modes": self.rows,
                "mac_matrix": None if self.mac is None else self.mac.tolist(), "warnings": list(self.warnings),
                "max_abs_error_pct": max(abs(r["error_pct"]) for r in self.rows),
                "min_mac": None if self.mac is None else min(r["mac"] for r in self.rows)}


def _stack(modes: FEModes, points) -> np.ndarray:
    """(n_modes, 3 n_points) shapes at ``points``; NaN where a side has no value."""
    return np.hstack([modes.shapes[p] for p in points])


def mac_matrix(fe: FEModes, test: FEModes, point_map: dict | None = None) -> tuple[np.ndarray | None, tuple]:
    """MAC of every FE mode with every test mode over the DOFs both have; (None, ()) without common points.

    A DOF counts where every FE mode has it and the test measured it (not
    all zero); each test mode uses those of them it has (finite), at least 2.
    """
    point_map = point_map or {}
    pairs = [(tp, point_map.get(tp, tp)) for tp in test.shapes if point_map.get(tp, tp) in fe.shapes]
    if not pairs:
        return None, ()
    a = _stack(fe, [f for _, f in pairs])
    b = _stack(test, [t for t, _ in pairs])
    common = np.all(np.isfinite(a), axis=0) & np.any(np.nan_to_num(b) != 0, axis=0)  # never measured: not common
    use = common & np.isfinite(b)  # per test mode: the DOFs it has (FRFs of other references: NaN)
    if np.any(use.sum(axis=1) < 2):
        return None, ()
    out = np.empty((len(fe), len(test)))
    for j in range(len(test)):
        aj, bj = a[:, use[j]], b[j, use[j]]
        num = np.abs(aj.conj() @ bj) ** 2
        den = np.real(np.sum(aj.conj() * aj, axis=1)) * np.real(np.vdot(bj, bj))
        out[:, j] = np.divide(num, den, out=np.zeros_like(num), where=den > 0)
    return out, tuple(t for t, _ in pairs)


def order_pairing(fe_hz, test_hz) -> dict:
    """Test mode index -> FE mode index, in order (lowest with lowest), skipping FE modes where there are more.

    With as many FE as test modes this is lowest with lowest. With more FE
    modes the FE modes to skip are chosen so that the ordered pairs are
    nearest in frequency (least total |ln(f_FE / f_test)|, dynamic
    programming): a test that missed a mode pairs the modes after it with
    their own FE modes, not each with the FE mode below (before: a test
    without pitch paired roll_low 2497 Hz with the FE pitch 2276 Hz, -8.8 %).

    >>> order_pairing([1879.0, 2276.0, 2496.0, 3529.0], [1879.0, 2497.0, 3530.0])
    {0: 0, 1: 2, 2: 3}
    """
    fe_i, test_j = np.argsort(fe_hz), np.argsort(test_hz)
    a, b = np.log(np.asarray(fe_hz, float)[fe_i]), np.log(np.asarray(test_hz, float)[test_j])
    n, m = len(a), len(b)
    cost = np.full((n + 1, m + 1), np.inf)
    cost[:, 0] = 0.0
    for i in range(1, n + 1):
        for j in range(1, min(i, m) + 1):
            cost[i, j] = min(cost[i - 1, j], cost[i - 1, j - 1] + abs(a[i - 1] - b[j - 1]))
    pairing, i, j = {}, n, m
    while j > 0:
        if cost[i, j] == cost[i - 1, j - 1] + abs(a[i - 1] - b[j - 1]):
            pairing[int(test_j[j - 1])] = int(fe_i[i - 1])
            j -= 1
        i -= 1
    return dict(sorted(pairing.items()))


def correlate(fe: FEModes, test: FEModes, point_map: dict | None = None) -> Correlation:
    """Pair the modes (MAC where shapes allow, else order) and give Eq. (34) and MAC per pair."""
    notes = []
    matrix, points = mac_matrix(fe, test, point_map)
    if matrix is not None:
        from scipy.optimize import linear_sum_assignment

        if len(fe) < len(test):
            raise CorrelateError(f"{len(test)} test modes but only {len(fe)} FE modes: compute more FE modes")
        # MAC first; among FE modes the measured DOFs cannot tell apart (MAC within ~0.01), the nearest frequency
        gap = np.abs(np.log(fe.frequencies_hz[:, None] / test.frequencies_hz[None, :]))
        rows_i, cols_j = linear_sum_assignment(-matrix + FREQUENCY_TIE_BREAK * gap)
        pairing = dict(zip(cols_j, rows_i))
        paired_by = "mac"
        for j, i in sorted(pairing.items()):
            alike = [int(k) + 1 for k in np.flatnonzero(matrix[:, j] >= matrix[i, j] - MAC_ALIKE) if k != i]
            if alike:
                notes.append(f"test mode {j + 1}: its shape at the common DOFs is alike FE mode(s) "
                             f"{', '.join(map(str, alike))} and {i + 1} (MAC within {MAC_ALIKE:g}): paired with "
                             f"FE mode {i + 1} by frequency; measure more DOFs to tell them apart")
    else:
        if fe.shapes and test.shapes:
            notes.append("no common points with shapes on both sides (give --point-map): modes paired by order")
        else:
            notes.append("no shapes on " + ("either side" if not fe.shapes and not test.shapes
                                            else "the FE side" if not fe.shapes else "the test side")
                         + ": modes paired by order (lowest with lowest)")
        if len(fe) < len(test):
            raise CorrelateError(f"{len(test)} test modes but only {len(fe)} FE modes: compute more FE modes")
        pairing = order_pairing(fe.frequencies_hz, test.frequencies_hz)
        if len(fe) > len(test):
            notes.append(f"{len(fe)} FE modes for {len(test)} test modes: the FE modes skipped are those that "
                         "keep the ordered pairs nearest in frequency")
        paired_by = "order"
    rows = []
    for j in np.argsort(test.frequencies_hz):
        i = int(pairing[j])
        f_fe, f_test = float(fe.frequencies_hz[i]), float(test.frequencies_hz[j])
        rows.append({"test_mode": int(j) + 1, "label": test.labels[j] if test.labels else "",
                     "fe_mode": i + 1, "fe_hz": f_fe, "test_hz": f_test, "error_pct": eq34_error_pct(f_fe, f_test),
                     "mac": None if matrix is None else float(matrix[i, j])})
    return Correlation(rows, matrix, points, paired_by, tuple(notes))


def parse_checks(text: str | None) -> dict:
    """``max_error_pct=5,min_mac=0.8`` -> dict; bad text is a CorrelateError."""
    out = {}
    for item in (text or "").split(","):
        if not item.strip():
            continue
        key, eq, value = (s.strip() for s in item.partition("="))
        try:
            number = float(value)
        except ValueError:
            number = math.nan
        if not eq or key not in CHECKS or not math.isfinite(number):
            raise CorrelateError(f"--check '{item.strip()[:40]}': use {'=N, '.join(CHECKS)}=N "
                                 "(e.g. max_error_pct=5,min_mac=0.8)")
        out[key] = number
    return out


def parse_band(text: str | None) -> tuple[float, float] | None:
    """``LO,HI`` in Hz (0 <= LO < HI) -> tuple; None when not given; bad text is a CorrelateError."""
    if not text:
        return None
    try:
        lo, hi = (float(v) for v in text.split(","))
    except ValueError:
        lo = hi = math.nan
    if not (math.isfinite(lo) and math.isfinite(hi) and 0 <= lo < hi):
        raise CorrelateError(f"--band '{text[:40]}': use LO,HI in Hz with 0 <= LO < HI (e.g. 500,8000)")
    return lo, hi


def failed_checks(result: Correlation, checks: dict) -> list[str]:
    """One message per violated tolerance."""
    bad = []
    if "max_error_pct" in checks:
        for r in result.rows:
            if abs(r["error_pct"]) > checks["max_error_pct"]:
                bad.append(f"test mode {r['test_mode']}: |error| {abs(r['error_pct']):.3g} % > "
                           f"{checks['max_error_pct']:g} %")
    if "min_mac" in checks:
        if result.mac is None:
            bad.append("min_mac: no shapes to compute a MAC from")
        else:
            for r in result.rows:
                if r["mac"] < checks["min_mac"]:
                    bad.append(f"test mode {r['test_mode']}: MAC {r['mac']:.3f} < {checks['min_mac']:g}")
    return bad


def render_table(result: Correlation) -> str:
    """Table 3: test mode, FE mode, frequencies, Eq. (34) error, MAC."""
    lines = [f"{'test':>4} {'label':<10} {'FE':>4} {'FE f (Hz)':>12} {'test f (Hz)':>12} {'error %':>9} {'MAC':>6}"]
    for r in result.rows:
        m = "" if r["mac"] is None else f"{r['mac']:.3f}"
        lines.append(f"{r['test_mode']:>4} {r['label'][:10]:<10} {r['fe_mode']:>4} {r['fe_hz']:>12.6g} "
                     f"{r['test_hz']:>12.6g} {r['error_pct']:>+9.2f} {m:>6}")
    lines.append(f"paired by {result.paired_by}; error = (f_FE - f_test) / f_test x 100 % (Eq. 34)")
    return "\n".join(lines) + "\n"


def plot_mac(result: Correlation, path) -> None:
    """The MAC matrix (FE modes down, test modes across) as an image; the pairs outlined."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if result.mac is None:
        raise CorrelateError("--plot: no shapes on both sides at common points, so no MAC matrix to plot")
    fig, ax = plt.subplots(figsize=(1.5 + 0.5 * result.mac.shape[1], 1.5 + 0.4 * result.mac.shape[0]))
    image = ax.imshow(result.mac, vmin=0, vmax=1, cmap="viridis", aspect="auto")
    for r in result.rows:
        ax.add_patch(plt.Rectangle((r["test_mode"] - 1.5, r["fe_mode"] - 1.5), 1, 1, fill=False, color="red"))
    ax.set_xlabel("test mode")
    ax.set_ylabel("FE mode")
    ax.set_xticks(range(result.mac.shape[1]), [str(k + 1) for k in range(result.mac.shape[1])])
    ax.set_yticks(range(result.mac.shape[0]), [str(k + 1) for k in range(result.mac.shape[0])])
    fig.colorbar(image, ax=ax, label="MAC")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def run(fe_path, test_path, point_map_path=None, band_hz=None) -> Correlation:
    """Read both sides and correlate them; unreadable input is a one-line error (exit 2).

    ``band_hz`` (LO, HI): where measured FRFs are fitted (default :func:`fit_band`).
    """
    try:
        fe = read_fe(fe_path)
    except FEResultError as exc:
        raise CorrelateError(str(exc)) from None
    test = read_test(test_path, fe, band_hz)
    result = correlate(fe, test, read_point_map(point_map_path) if point_map_path else None)
    for note in result.warnings:
        warnings.warn(note, stacklevel=2)
    return result
