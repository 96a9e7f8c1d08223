r"""One modal model for the whole test: shared poles over every run and channel.

The per-run curve fit of :func:`guidefit.modes.auto_fit` grows poles inside
each peak's band of one run. When an asymmetry couples the carriage modes, a
10 %-damped mode swallows a coupled neighbour that its run hardly excites,
and the neighbour's frequency and damping come out biased by much more than
their standard deviation. This module fits all runs and all response
channels of a recording together, in a band that holds every carriage mode:

1. :func:`lscf_stabilisation` -- the least-squares complex-frequency (LSCF)
   estimator in its common-denominator form (Guillaume et al. 2003; Peeters
   et al. 2004 for the poly-reference variant PolyMAX): every FRF of every run
   (``O`` outputs) is ``H_o(w) = B_o(z) / A(z)`` with one scalar denominator
   ``A`` of order ``n`` and ``z = exp(j w T_s)``, ``T_s = 1 / (2 f_hi)``. The
   numerators are eliminated from the normal equations (reduced normal
   matrix ``M = sum_o (T_o - S_o^T R^-1 S_o)``), so a whole sweep of model
   orders costs a few small solves. The poly-reference (matrix-fraction)
   form needs every output measured for every input; guidefit's runs may
   have different channel sets (y sensors only in the vertical run), so
   every run-channel FRF is its own output row of one shared denominator --
   the runs are still all references of one model with shared poles.
   For each order the residues of every FRF are then fitted by linear least
   squares (LSFD) to give each pole a *participation* vector.
2. :func:`select_poles` -- a pole is *stable* at order ``n`` when a pole of
   order ``n - 2`` lies within 1 % in frequency, 5 % in damping and has a
   participation vector with MAC >= 0.9. Stable poles are clustered in
   (ln f, ln zeta); a cluster that holds stable poles at enough orders and
   whose participation is not negligible is a physical mode. No model
   frequency enters the selection.
3. :func:`global_fit` -- the selected poles start a variable-projection
   least-squares fit of poles and residues on all FRFs together
   (:mod:`guidefit.modes.globalvp`, exact normal equations), with lower and upper
   residual terms per FRF for the modes outside the band. Its uncertainty
   combines the fit's own standard error, the delete-a-group jackknife over
   hits of the whole global fit, and the spread over pole selection (the fit
   repeated from the poles of other model orders and with the strongest
   rejected cluster added).

Examples
--------
>>> import numpy as np
>>> f = np.arange(500.0, 4000.0, 10.0)
>>> s = 2j * np.pi * f
>>> def mode(fn, z, c):
...     p = 2 * np.pi * fn * (-z + 1j * np.sqrt(1 - z * z))
...     A = c / (2j * p.imag)
...     return s**2 * (A / (s - p) + np.conj(A) / (s - np.conj(p)))
>>> H = np.stack([mode(1500, 0.02, 0.5) + mode(2500, 0.1, 0.3),
...               mode(1500, 0.02, -0.4) + mode(2500, 0.1, 0.6)], axis=1)
>>> diagram = lscf_stabilisation(f, H, orders=range(4, 21, 2))
>>> sel = select_poles(diagram)
>>> [(round(c.frequency_hz), round(c.damping_ratio, 3)) for c in sel.chosen]
[(1500, 0.02), (2500, 0.1)]
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from guidefit.errors import IdentificationError
from guidefit.modes import fitcore
from guidefit.modes.globalvp import Fit, SharedProblem, gauss_newton, solve

#: stability limits between consecutive orders: frequency, damping (relative), participation MAC
STABLE_FREQUENCY = 0.01
STABLE_DAMPING = 0.05
STABLE_MAC = 0.9
#: clustering scales in ln f and ln zeta (a distance of 1 joins two poles)
CLUSTER_LN_F = 0.004
CLUSTER_LN_ZETA = 0.25
#: a cluster is a physical mode when it holds stable poles at this share of the orders (and at least 3)
MIN_ORDER_SHARE = 0.2
#: ... and its participation is at least this share of the strongest cluster's
MIN_PARTICIPATION = 5e-3
MAX_DAMPING = 0.4


@dataclass(frozen=True)
class Stabilisation:
    """A stabilisation diagram: poles of every model order with their stability flags.

    Attributes
    ----------
    orders : numpy.ndarray
        ``(P,)`` model order of each pole.
    frequency_hz, damping_ratio : numpy.ndarray
        ``(P,)`` undamped natural frequency and damping ratio.
    participation : numpy.ndarray
        ``(P, O)`` complex modal constants of the (normalised) FRFs.
    stable_f, stable_z, stable_v : numpy.ndarray
        ``(P,)`` bool: frequency, damping and participation stable against
        the previous order.
    band_hz : (float, float)
    """

    orders: np.ndarray
    frequency_hz: np.ndarray
    damping_ratio: np.ndarray
    participation: np.ndarray
    stable_f: np.ndarray
    stable_z: np.ndarray
    stable_v: np.ndarray
    band_hz: tuple

    @property
    def stable(self) -> np.ndarray:
        """Poles stable in frequency, damping and participation."""
        return self.stable_f & self.stable_z & self.stable_v


@dataclass(frozen=True)
class PoleCluster:
    """Stable poles of one physical mode across model orders."""

    frequency_hz: float  # median over the cluster
    damping_ratio: float
    n_orders: int
    participation: float  # median norm of the participation vector, relative to the strongest cluster
    frequency_spread_hz: float  # std over the cluster's orders
    damping_spread: float
    members: np.ndarray = field(repr=False)  # indices into the diagram


@dataclass(frozen=True)
class PoleSelection:
    """Clusters kept as physical modes, and the strongest rejected ones."""

    chosen: list
    rejected: list


def one_blas_thread():
    """Context manager limiting BLAS to one thread (threadpoolctl; a no-op without it).

    Every matrix of the modal stage is small (a few thousand rows, tens of
    columns): a second BLAS thread cannot speed it up, and on a loaded
    machine each call waits for that thread to be scheduled. On the 20-hit,
    0.5 s benchmark recording (bench_identify_e2e.py) this made the global
    fit 7x slower (1.9 s against 0.26 s); the results are the same.

    The controller is built once per process (:func:`_blas_controller`):
    ``threadpoolctl.threadpool_limits`` scans every loaded library on each
    call, 1-10 ms, more than some of the fits it guards.
    """
    controller = _blas_controller()
    if controller is None:  # pragma: no cover - threadpoolctl is a dependency
        return contextlib.nullcontext()
    return controller.limit(limits=1, user_api="blas")


_CONTROLLER: dict = {}  # the loaded BLAS libraries (as far as the modules that load them tell) -> controller


def _blas_controller():
    """The threadpoolctl controller of the BLAS libraries loaded now (None without threadpoolctl).

    The fit's linear algebra is numpy's (numpy.linalg and matrix products), so
    numpy's BLAS is the one that matters; scipy.linalg is not imported for it.
    A controller knows the libraries loaded when it was made, so another is
    made (once) after scipy.linalg has loaded scipy's own BLAS (a second
    OpenBLAS in the wheels): every BLAS is limited, whatever the import order.
    """
    import sys

    key = "scipy.linalg" in sys.modules
    if key not in _CONTROLLER:
        try:
            from threadpoolctl import ThreadpoolController
        except ImportError:  # pragma: no cover - threadpoolctl is a dependency
            _CONTROLLER[key] = None
        else:
            _CONTROLLER[key] = ThreadpoolController()
    return _CONTROLLER[key]


def _mac(a: np.ndarray, b: np.ndarray) -> float:
    den = float(np.real(np.vdot(a, a) * np.vdot(b, b)))
    return float(abs(np.vdot(a, b)) ** 2 / den) if den > 0 else 0.0


def _reduced_matrices(f: np.ndarray, H3: np.ndarray, n_max: int, ts: float):
    """R (n+1, n+1), M-parts of the poly-reference LSCF normal equations at the largest order.

    ``H3`` is ``(F, O, m)``: O outputs, m references. Columns of ``S`` and
    ``T`` are ordered (order j, reference i) -> ``j m + i``.
    """
    F, n_out, m = H3.shape
    X = np.exp(1j * 2 * np.pi * f[:, None] * ts * np.arange(n_max + 1)[None, :])  # (F, n+1)
    R = np.real(X.conj().T @ X)
    Y = (X[:, None, :, None] * H3[:, :, None, :]).reshape(F, n_out, (n_max + 1) * m)  # z^j H_oi
    c = (n_max + 1) * m
    S = np.real(X.conj().T @ Y.reshape(F, n_out * c)).reshape(n_max + 1, n_out, c).transpose(1, 0, 2)
    Yf = Y.reshape(F * n_out, c)
    T = np.real(Yf.conj().T @ Yf)  # summed over outputs
    return R, S, T


def _lscf_poles(R, S, T, n: int, m: int, ts: float) -> np.ndarray:
    """Poles (rad/s) of the right matrix-fraction denominator of order n (highest coefficient I_m)."""
    k = n + 1
    c = k * m
    Rn, Sn, Tn = R[:k, :k], S[:, :k, :c], T[:c, :c]
    # Rn^-1 S through the inverse Cholesky factor of Rn: two matrix products (numpy.linalg, see fitcore.ls_solver)
    factor_inverse = fitcore.cholesky_inverse(Rn)
    if factor_inverse is None:
        raise np.linalg.LinAlgError(f"LSCF: the order-{n} basis Gram matrix is not positive definite")
    RinvS = factor_inverse.T @ (factor_inverse @ Sn.transpose(1, 0, 2).reshape(k, -1))
    RinvS = RinvS.reshape(k, S.shape[0], c).transpose(1, 0, 2)
    M = Tn - np.einsum("oji,ojk->ik", Sn, RinvS)
    if not np.all(np.isfinite(M)):
        return np.zeros(0, complex)
    low = n * m
    try:
        alpha = np.linalg.solve(M[:low, :low], -M[:low, low:])  # (n m, m): alpha_0 .. alpha_{n-1}
    except np.linalg.LinAlgError:
        alpha = np.linalg.lstsq(M[:low, :low], -M[:low, low:], rcond=None)[0]
    if m == 1:
        z = np.roots(np.concatenate([alpha[:, 0], [1.0]])[::-1])
    else:
        # block companion of A(z) v = sum_j z^j alpha_j^T v (rows of alpha_j multiply H's references)
        C = np.zeros((low, low))
        if n > 1:
            C[: low - m, m:] = np.eye(low - m)
        C[low - m:, :] = -np.concatenate([alpha[j * m:(j + 1) * m].T for j in range(n)], axis=1)
        z = np.linalg.eigvals(C)
    z = z[np.isfinite(z) & (np.abs(z) > 0)]
    return np.log(z) / ts


def _participation(f: np.ndarray, H: np.ndarray, poles: np.ndarray, problem: SharedProblem | None = None) -> np.ndarray:
    """(n, O) complex modal constants of each pole in every FRF by linear least squares (LSFD).

    ``problem``: a :class:`guidefit.modes.globalvp.SharedProblem` of ``(f, H)`` (unit scale, one group, no
    shift) when the caller has one: its design (the same numbers as ``fitcore.basis``, residual-term
    columns made once) and stacked ``H`` serve every order of a diagram.
    """
    prob = problem or SharedProblem(f, H, [slice(None)], [0.0], scale=np.ones(np.shape(H)[1]))
    A, norm = prob._design(np.asarray(poles), 0.0)
    Y = prob.Y
    solve = fitcore.ls_solver(A)
    if solve is not None:  # fitcore.ls_fit's coefficients (its residual is not needed here)
        B = solve(A.T @ Y)
        B += solve(A.T @ (Y - A @ B))
    if solve is None or not np.all(np.isfinite(B)):
        B = fitcore.ls_fit(A, Y)[1]
    B = B / norm[:, None]
    res = B[0 : 2 * poles.size : 2] + 1j * B[1 : 2 * poles.size : 2]  # (n, O)
    return 2j * poles.imag[:, None] * res


def lscf_stabilisation(frequency_hz, H, orders: Sequence[int] = range(4, 49, 2), band_hz=None,
                       references=None) -> Stabilisation:
    """LSCF poles over a range of model orders, with stability flags (the stabilisation diagram).

    With ``references`` (``(F, O_c, m)``: the outputs measured in all of m
    runs with different hit points), the poles come from the poly-reference
    (PolyMAX) matrix-fraction model ``H(z) = B(z) A(z)^-1``, A an m x m matrix
    polynomial of order n (n m poles): two close modes that the references
    excite differently then separate at low order. Without it, from the
    common-denominator model of all columns of ``H``. Participation is
    always fitted to every column of ``H``.

    Parameters
    ----------
    frequency_hz : array_like
        ``(F,)`` increasing frequencies (Hz).
    H : array_like
        ``(F, O)`` complex FRFs sharing the poles (all runs and channels).
    orders : sequence of int
        Denominator orders, increasing; stability is judged against the
        previous entry.
    band_hz : (float, float), optional
        Band used (default: all of ``frequency_hz``).

    Returns
    -------
    Stabilisation
    """
    f = np.asarray(frequency_hz, dtype=float)
    Hf = np.asarray(H, dtype=complex)
    if Hf.ndim == 1:
        Hf = Hf[:, None]
    lo, hi = (float(f[0]), float(f[-1])) if band_hz is None else (float(band_hz[0]), float(band_hz[1]))
    sel = (f >= lo) & (f <= hi)
    f, Hf = f[sel], Hf[sel]
    H3 = Hf[:, :, None] if references is None else np.asarray(references, dtype=complex)[sel]
    m = H3.shape[2]
    orders = sorted(int(n) for n in orders)
    if f.size < 2 * orders[0] + 4:
        raise IdentificationError(f"LSCF: {f.size} bins in {lo:.0f}-{hi:.0f} Hz; too few for model order {orders[0]}")
    if m > 1:
        orders = sorted({max(1, n // m) for n in orders})  # n m poles per order: the same pole counts
    orders = [n for n in orders if 2 * n * m + 4 <= f.size] or orders[:1]
    rms = np.sqrt(np.mean(np.abs(Hf) ** 2, axis=0))
    Hn = Hf / np.where(rms > 0, rms, 1.0)
    lsfd = SharedProblem(f, Hn, [slice(None)], [0.0], scale=np.ones(Hn.shape[1]))  # the participation's design
    rms3 = np.sqrt(np.mean(np.abs(H3) ** 2, axis=(0, 2)))
    H3n = H3 / np.where(rms3 > 0, rms3, 1.0)[None, :, None]
    ts = 1.0 / (2.0 * hi * 1.05)
    R, S, T = _reduced_matrices(f, H3n, orders[-1], ts)
    rows = []
    prev = None
    for n in orders:
        try:
            p = _lscf_poles(R, S, T, n, m, ts)
        except np.linalg.LinAlgError:  # a narrow band: the basis of this and every higher order is singular
            if not rows:
                raise IdentificationError(f"LSCF: the band {lo:.0f}-{hi:.0f} Hz holds too little for model order "
                                          f"{n} (its basis is numerically singular); widen the band") from None
            break  # the diagram ends at the last order the band supports
        wn = np.abs(p)
        zeta = -p.real / np.where(wn > 0, wn, 1.0)
        fn = wn / (2 * np.pi)
        keep = (p.imag > 0) & (zeta > 0) & (zeta < MAX_DAMPING) & (fn > lo) & (fn < hi)
        p, fn, zeta = p[keep], fn[keep], zeta[keep]
        part = _participation(f, Hn, p, lsfd) if p.size else np.zeros((0, Hn.shape[1]), complex)
        sf = np.zeros(p.size, bool)
        sz = np.zeros(p.size, bool)
        sv = np.zeros(p.size, bool)
        if prev is not None and prev[0].size and p.size:
            pf, pz, pv = prev
            j = np.argmin(np.abs(np.log(pf[None, :] / fn[:, None])), axis=1)  # nearest pole of the previous order
            sf = np.abs(pf[j] / fn - 1) < STABLE_FREQUENCY
            sz = sf & (np.abs(pz[j] / zeta - 1) < STABLE_DAMPING)
            for i in np.flatnonzero(sf):
                sv[i] = _mac(part[i], pv[j[i]]) >= STABLE_MAC
        prev = (fn, zeta, part)
        rows.append((np.full(p.size, n * m), fn, zeta, part, sf, sz, sv))
    cat = [np.concatenate([r[k] for r in rows]) for k in range(7)]
    return Stabilisation(cat[0], cat[1], cat[2], cat[3], cat[4], cat[5], cat[6], (lo, hi))


def _clusters(d: Stabilisation, idx: np.ndarray) -> list[np.ndarray]:
    """Average-linkage clusters of the poles ``idx`` in (ln f / CLUSTER_LN_F, ln zeta / CLUSTER_LN_ZETA)."""
    if idx.size == 0:
        return []
    if idx.size == 1:
        return [idx]
    x = np.stack([np.log(d.frequency_hz[idx]) / CLUSTER_LN_F, np.log(d.damping_ratio[idx]) / CLUSTER_LN_ZETA], 1)
    labels = average_linkage_labels(x, 1.0)
    return [idx[labels == k] for k in np.unique(labels)]


def average_linkage_labels(x: np.ndarray, t: float) -> np.ndarray:
    """Flat clusters of the points ``x`` (N, D): average-linkage (UPGMA) merges up to distance ``t``.

    The partition of ``scipy.cluster.hierarchy.fcluster(linkage(x, "average"), t,
    criterion="distance")`` (Euclidean distances; the Lance-Williams update
    ``(n_a d_ak + n_b d_bk) / (n_a + n_b)``), written with numpy because
    importing scipy.cluster costs about 20 ms, more than the clustering of a
    diagram. Points whose first coordinates are more than ``t`` apart are
    never joined (every distance across such a gap exceeds ``t``, and so does
    any average of them), so the points are split at those gaps first and
    each part is clustered on its own. Labels are 0, 1, ... in order of each
    cluster's lowest first coordinate.

    Examples
    --------
    >>> import numpy as np
    >>> average_linkage_labels(np.array([[0.0, 0.0], [0.5, 0.0], [5.0, 0.0], [0.2, 0.3]]), 1.0).tolist()
    [0, 0, 1, 0]
    """
    x = np.asarray(x, dtype=float)
    labels = np.empty(x.shape[0], dtype=int)
    order = np.argsort(x[:, 0], kind="stable")
    n_labels = 0
    for part in np.split(order, np.flatnonzero(np.diff(x[order, 0]) > t) + 1):
        for members in _agglomerate(x[part], t):
            labels[part[members]] = n_labels
            n_labels += 1
    return labels


def _agglomerate(x: np.ndarray, t: float) -> list[np.ndarray]:
    """Average-linkage clusters of a few points (index arrays into ``x``): merge the closest pair while
    its distance is at most ``t`` (average linkage is monotone, so this is the dendrogram cut at t)."""
    n = x.shape[0]
    if n == 1:
        return [np.zeros(1, dtype=int)]
    diff = x[:, None, :] - x[None, :, :]
    dist = np.sqrt(np.sum(diff * diff, axis=2))  # as scipy's pdist: sum of squared differences, then sqrt
    np.fill_diagonal(dist, np.inf)
    size = np.ones(n)
    members = [[i] for i in range(n)]
    while True:
        k = int(np.argmin(dist))
        a, b = divmod(k, n)
        if not dist[a, b] <= t:
            break
        merged = (size[a] * dist[a] + size[b] * dist[b]) / (size[a] + size[b])
        dist[a, :] = merged
        dist[:, a] = merged
        dist[a, a] = np.inf
        dist[b, :] = np.inf
        dist[:, b] = np.inf
        size[a] += size[b]
        members[a] += members[b]
        members[b] = []
    return [np.array(sorted(m)) for m in sorted((m for m in members if m), key=lambda m: x[m, 0].min())]


def select_poles(d: Stabilisation, min_order_share: float = MIN_ORDER_SHARE,
                 min_participation: float = MIN_PARTICIPATION) -> PoleSelection:
    """Physical poles of a stabilisation diagram, from stability alone (no model frequencies).

    Stable poles (frequency, damping and participation) are clustered; a
    cluster is chosen when it holds stable poles at ``min_order_share`` of
    the orders of the sweep (at least 3) and its median participation is at
    least ``min_participation`` of the strongest cluster's. Each cluster's
    frequency and damping are the medians over its orders (one pole per
    order, the one nearest the cluster's median).
    """
    n_orders = np.unique(d.orders).size
    clusters = []
    for members in _clusters(d, np.flatnonzero(d.stable)):
        # one pole per order
        fm, zm = np.median(d.frequency_hz[members]), np.median(d.damping_ratio[members])
        best: dict[int, int] = {}
        for i in members:
            dist = abs(math.log(d.frequency_hz[i] / fm)) / CLUSTER_LN_F + abs(math.log(d.damping_ratio[i] / zm))
            o = int(d.orders[i])
            if o not in best or dist < best[o][0]:
                best[o] = (dist, i)
        m = np.array(sorted(i for _, i in best.values()))
        amp = float(np.median(np.linalg.norm(d.participation[m], axis=1)))
        clusters.append((m, amp))
    if not clusters:
        return PoleSelection([], [])
    top = max(a for _, a in clusters) or 1.0
    need = max(3, int(math.ceil(min_order_share * n_orders)))
    chosen, rejected = [], []
    for m, amp in clusters:
        c = PoleCluster(float(np.median(d.frequency_hz[m])), float(np.median(d.damping_ratio[m])), int(m.size),
                        amp / top, float(np.std(d.frequency_hz[m])), float(np.std(d.damping_ratio[m])), m)
        (chosen if (m.size >= need and amp / top >= min_participation) else rejected).append(c)
    chosen.sort(key=lambda c: c.frequency_hz)
    rejected.sort(key=lambda c: (-c.n_orders, -c.participation))
    return PoleSelection(chosen, rejected)


# --------------------------------------------------------------------------- the global least-squares fit


@dataclass(frozen=True)
class GlobalFit:
    """Shared poles and residues of every FRF of every run, with their uncertainty.

    Attributes
    ----------
    modes : list of guidefit.modes.Mode
        Sorted by frequency; ``residues`` hold every FRF column (all runs, in
        the order of ``columns``); ``frequency_std_hz`` and ``damping_std``
        combine the fit's standard error, the jackknife over hits and the
        spread over pole selection (before any window correction).
    columns : list of (run, channel)
        The FRF behind each residue.
    runs : dict
        Run name -> slice of its columns.
    band_hz : (float, float)
    frequency_hz : numpy.ndarray
        The fitted bins.
    residuals : dict
        Residual-term coefficients per column (:attr:`guidefit.modes.BandFit.residuals`).
    diagram : Stabilisation
    selection : PoleSelection
    std_parts : list of dict
        Per mode: ``fit``, ``jackknife`` and ``selection`` std of ``f`` (Hz)
        and ``zeta``.
    excluded_runs : tuple of str
        Runs on another grid than most FRF columns: not fitted (identify warns). Identify's FRF stage
        puts runs of other record lengths or sample rates on one grid first (:func:`guidefit.frf.common_grid`,
        zero padding); only FRF files on several grids and non-integer sample rates end here.
    nrmse : float
        Normalised RMS misfit of the fit.
    """

    modes: list
    columns: list
    runs: dict
    band_hz: tuple
    frequency_hz: np.ndarray
    residuals: dict
    diagram: Stabilisation
    selection: PoleSelection
    std_parts: list
    excluded_runs: tuple = ()
    nrmse: float = math.nan

    def run_mode(self, k: int, run: str):
        """Mode ``k`` with the residues of one run's channels only (a :class:`guidefit.modes.Mode`)."""
        from dataclasses import replace

        return replace(self.modes[k], residues=np.asarray(self.modes[k].residues)[self.runs[run]])

    def synthesize(self, run: str, window_tau_s: float | None = None) -> np.ndarray:
        """The fitted model of one run's FRFs on :attr:`frequency_hz`, ``(F, R_run)``; with the run's
        ``window_tau_s`` as its windowed FRFs were measured (the model at ``s + 1/tau``), else the
        system's own FRFs."""
        from guidefit.modes import base as modal_base

        sl = self.runs[run]
        res = {k: np.asarray(v)[sl] for k, v in self.residuals.items()}
        return modal_base.synthesize(self.frequency_hz, [self.run_mode(k, run) for k in range(len(self.modes))], res,
                                     window_tau_s)


def _grid_key(frf) -> tuple:
    f = np.asarray(frf.frequency_hz)
    return (f.size, round(float(f[0]), 6), round(float(f[1] - f[0]), 9) if f.size > 1 else 0.0)


# the variable-projection problem and its solvers (guidefit.modes.globalvp)
_Shared = SharedProblem
_Fit = Fit
_solve_shared = solve
_gauss_newton = gauss_newton


def _refine(prob: _Shared, band, init, *, uncertainty=True, max_nfev=200, tol=1e-10):
    """Variable-projection fit from ``init`` [(f, zeta)]; modes that leave the band or hit a bound are
    dropped and the rest refitted. None when nothing is left."""
    init = list(init)
    while init:
        if prob.Y.shape[0] < 2 * (3 * len(init) + 5):
            init = init[:-1]
            continue
        try:
            fit = _solve_shared(prob, init, band, uncertainty=uncertainty, max_nfev=max_nfev, tol=tol)
        except (ValueError, np.linalg.LinAlgError):
            init = init[:-1]
            continue
        good = [(m.frequency_hz, m.damping_ratio) for m in fit.modes if not fitcore.suspicious(m, *band)]
        if len(good) == len(fit.modes):
            return fit
        init = good
    return None


def _significant(fit, f, rel_amplitude=MIN_PARTICIPATION, max_rel_std=3e-2) -> list:
    """Indices of the fit's modes that are not computational: modal constants of at least
    ``rel_amplitude`` of the strongest mode's (per FRF, relative to that FRF's largest) and a
    frequency std below ``max_rel_std``."""
    mc = np.array([np.abs(m.modal_constants) for m in fit.modes])  # (n, O)
    top = np.max(mc, axis=0)
    rel = np.max(mc / np.where(top > 0, top, 1.0), axis=1)
    keep = []
    for k, m in enumerate(fit.modes):
        sf = m.frequency_std_hz
        ok_std = sf is None or not math.isfinite(sf) or sf / m.frequency_hz <= max_rel_std
        if rel[k] >= rel_amplitude and ok_std:
            keep.append(k)
    return keep


def _match(modes, reference) -> list:
    """For each reference mode the index of the nearest mode (in ln f, ln zeta), or None."""
    out = []
    for r in reference:
        if not modes:
            out.append(None)
            continue
        d = [abs(math.log(m.frequency_hz / r.frequency_hz)) / CLUSTER_LN_F
             + abs(math.log(m.damping_ratio / r.damping_ratio)) / CLUSTER_LN_ZETA for m in modes]
        j = int(np.argmin(d))
        out.append(j if d[j] < 1.0 else None)
    return out


def _jackknife(frfs: list, band, modes, prob: _Shared, poles=None) -> list:
    """Delete-a-group jackknife std (f, zeta) of every mode over the hits of all runs together.

    Replicate g leaves group g out of every run (runs with fewer groups keep
    all their hits in the replicates beyond their count). Each replicate's
    global fit is one Gauss-Newton step of the whole variable-projection
    problem from the final poles, ``dx = -J^+ (r_g - r_0)`` (J the projected
    Jacobian of the full data, r the projected residuals): removing one group
    of hits moves the optimum little, and the linearised step reproduced the
    full refits of the replicates to about 1 % of their scatter on the
    simulated test matrix, at 1/8 of their cost. The residual change is
    linear in the data, ``r_g - r_0 = (I - P)(Y_g - Y_0)``, so every
    replicate's step comes from one product with the projected derivatives
    (:meth:`guidefit.modes.globalvp.SharedProblem.gradient_of`).
    """
    n_groups = max((getattr(x, "n_groups", 0) for x in frfs), default=0)
    if n_groups < 3 or not modes:
        return [(None, None)] * len(modes)
    wn, z = poles if poles is not None else _mode_poles(modes)
    try:
        JtJ = prob.normal(wn, z)[0]
        pinv = np.linalg.pinv(JtJ)
    except np.linalg.LinAlgError:
        return [(None, None)] * len(modes)
    # replicate FRFs of every run, (G, F_band, R): runs with fewer groups keep all hits beyond their count
    reps = np.concatenate([_replicates(x, band, n_groups) for x in frfs], axis=2)
    dY = np.concatenate([reps.real, reps.imag], axis=1) * prob.scale - prob.Y[None]  # (G, 2F, O)
    dY = dY.transpose(1, 2, 0)  # (2F, O, G)
    dx = -pinv @ prob.gradient_of(wn, z, [dY[:, g] for g in prob.groups])  # (2n, G)
    n = len(modes)
    out = []
    for k in range(n):
        a = modes[k].frequency_hz * np.exp(dx[k])
        b = modes[k].damping_ratio * np.exp(dx[n + k])
        out.append((math.sqrt((n_groups - 1) / n_groups * np.sum((a - a.mean()) ** 2)),
                    math.sqrt((n_groups - 1) / n_groups * np.sum((b - b.mean()) ** 2))))
    return out


def _replicates(frf, band, n_groups: int) -> np.ndarray:
    """(n_groups, F_band, R) FRFs of ``frf`` in the band without each hit group in turn (the FrfSet's
    ``leave_one_group_out`` on the band's bins, all groups at once); the FRF of all hits for the
    replicates beyond the run's own groups (or all of them when it has fewer than 2)."""
    from guidefit.frf import estimate_frf

    sel = (frf.frequency_hz >= band[0]) & (frf.frequency_hz <= band[1])
    H = np.asarray(frf.H)[sel]
    G = getattr(frf, "n_groups", 0) or 0
    out = np.broadcast_to(H, (n_groups,) + H.shape).copy()
    if G >= 2:
        gs = {k: np.asarray(frf.group_sums[k])[:, sel] for k in ("Sff", "Sxx", "Sfx")}
        sub = {k: np.sum(v, axis=0)[None] - v for k, v in gs.items()}
        out[:G] = estimate_frf(sub["Sff"], sub["Sxx"], sub["Sfx"], frf.estimator)
    return out


def _selection_spread(prob: _Shared, band, modes, sel: PoleSelection, diagram: Stabilisation) -> list:
    """Largest change of each mode's (f, zeta) when the fit restarts from the poles of the lowest and
    the highest stable order of each cluster, and with the strongest rejected cluster added."""
    alternatives = []
    for pick in (min, max):
        init = []
        for c in sel.chosen:
            i = pick(c.members, key=lambda i: diagram.orders[i])
            init.append((float(diagram.frequency_hz[i]), float(diagram.damping_ratio[i])))
        alternatives.append(init)
    base = [(m.frequency_hz, m.damping_ratio) for m in modes]
    extra = [c for c in sel.rejected if c.n_orders >= 2 and band[0] < c.frequency_hz < band[1]]
    if extra:
        alternatives.append(base + [(extra[0].frequency_hz, extra[0].damping_ratio)])
    df = np.zeros(len(modes))
    dz = np.zeros(len(modes))
    for init in alternatives:
        try:
            fit = _gauss_newton(prob, band, sorted(init), iterations=3)
        except (ValueError, np.linalg.LinAlgError):
            fit = None
        if fit is None:
            continue
        for k, j in enumerate(_match(fit.modes, modes)):
            if j is not None:
                df[k] = max(df[k], abs(fit.modes[j].frequency_hz - modes[k].frequency_hz))
                dz[k] = max(dz[k], abs(fit.modes[j].damping_ratio - modes[k].damping_ratio))
    return list(zip(df, dz))


#: the estimator's own error, relative, as a part of every std: what the layout x effect matrix of
#: benchmarks/layout_matrix.py shows beyond the fit and jackknife std of 8-hit recordings (a mass at one corner:
#: zeta of the vertical mode 1.5e-4 low on every seed; the roll_low frequency off by 4e-5 rms over 12 seeds
#: against a reported 2.6e-5, up to 3.2 std)
ESTIMATOR_BIAS_FREQUENCY = 2e-5
ESTIMATOR_BIAS_DAMPING = 5e-4


def _rss(*values) -> float | None:
    vals = [float(v) for v in values if v is not None and math.isfinite(v)]
    return math.sqrt(sum(v * v for v in vals)) if vals else None


def _mode_poles(modes: list, fit=None) -> tuple[np.ndarray, np.ndarray]:
    """(w_n rad/s, zeta) of ``modes``: the fit's own arrays when it has them for these modes (its problem
    keeps its design and products there), else from the modes' frequencies and damping ratios."""
    if fit is not None and getattr(fit, "wn", None) is not None and len(fit.modes) == len(modes):
        return fit.wn, fit.zeta
    return 2 * np.pi * np.array([m.frequency_hz for m in modes]), np.array([m.damping_ratio for m in modes])


def _conservative_std(prob: _Shared, modes: list, poles=None) -> list:
    """``modes`` with each f and zeta std the larger of its own and that of ``prob`` at the same poles
    (``poles``: their (w_n, zeta) arrays, default from the modes)."""
    from dataclasses import replace

    wn, z = poles if poles is not None else _mode_poles(modes)
    try:
        JtJ, _, cost = prob.normal(wn, z)
    except np.linalg.LinAlgError:
        return modes
    n = len(modes)
    dof = prob.Y.size - 2 * n - (2 * n + len(prob.terms)) * prob.Y.shape[1]
    if dof <= 0:
        return modes
    sd = np.sqrt(np.maximum(np.diag(np.linalg.pinv(JtJ)) * cost / dof, 0.0))
    out = []
    for k, m in enumerate(modes):
        sf, sz = sd[k] * m.frequency_hz, sd[n + k] * m.damping_ratio
        out.append(replace(m, frequency_std_hz=max(_nz(m.frequency_std_hz), sf), damping_std=max(_nz(m.damping_std), sz)))
    return out


#: the equally weighted problem of the conservative std lifts no column above 1 / (this x the strongest's RMS)
EQUAL_WEIGHT_FLOOR = 1e-2


def _equal_scale(H: np.ndarray) -> np.ndarray:
    """Column weights 1 / RMS (each FRF counts alike), but a column more than 100x weaker than the strongest
    is lifted only to that level: a sensor that reads noise alone (a z sensor in a run that drives no z
    motion) would otherwise weigh as much as a real one and its misfit (all of it) set the std of every
    mode (triaxial layout: f_V std 2.9 Hz against a scatter of 0.002 Hz)."""
    rms = np.sqrt(np.mean(np.abs(H) ** 2, axis=0))
    floor = EQUAL_WEIGHT_FLOOR * float(rms.max()) if rms.size else 0.0
    return 1.0 / np.where(rms > floor, rms, floor if floor > 0 else 1.0)


def _nz(v) -> float:
    return float(v) if v is not None and math.isfinite(v) else 0.0


def _noise_scale(frfs: list, sel: np.ndarray):
    """Per FRF column 1 / (RMS noise of H in the band) from the coherence, var H = |H|^2 (1 - g^2) / (g^2 n);
    None (RMS scaling) when a column has no coherence or no noise."""
    out = []
    for x in frfs:
        coh = getattr(x, "coherence", None)
        n = getattr(x, "n_averages", 0) or 0
        if coh is None or n < 2:
            return None
        g = np.clip(np.asarray(coh)[sel], 1e-6, 1.0)
        H = np.asarray(x.H)[sel]
        noise = np.sqrt(np.mean(np.abs(H) ** 2 * (1.0 - g) / (g * n), axis=0))
        rms = np.sqrt(np.mean(np.abs(H) ** 2, axis=0))
        if not np.all(noise > 1e-9 * np.maximum(rms, 1e-300)):
            return None
        out.append(1.0 / noise)
    return np.concatenate(out)


#: bins of the stabilisation diagram (long records are thinned to about this many; the refinement uses all)
MAX_DIAGRAM_BINS = 800


#: two runs whose FRFs at the common channels correlate this much have the same hit (one reference)
SAME_REFERENCE = 0.98


def _references(frfs: list, sel: np.ndarray):
    """``(F, O_c, m)`` FRFs of the channels every run measured, one reference per distinct hit, or None
    (one run, no common channel or one distinct hit: the common-denominator LSCF is used)."""
    common = [c for c in frfs[0].channels if all(c in x.channels for x in frfs[1:])]
    if len(frfs) < 2 or not common:
        return None
    cols = []
    for x in frfs:
        h = np.asarray(x.H)[sel][:, [list(x.channels).index(c) for c in common]]
        v = h.ravel()
        same = False
        for other in cols:
            w = other.ravel()
            den = float(np.real(np.vdot(v, v) * np.vdot(w, w)))
            if den > 0 and abs(np.vdot(v, w)) ** 2 / den > SAME_REFERENCE:
                same = True
                break
        if not same:
            cols.append(h)
    if len(cols) < 2:
        return None
    return np.stack(cols, axis=2)


#: a column whose median coherence in the band is below this is noise to the stabilisation diagram
DIAGRAM_MIN_COHERENCE = 0.5


def _diagram_columns(frfs: list, sel: np.ndarray, groups: list) -> np.ndarray:
    """Indices of the FRF columns the stabilisation diagram uses: all but those whose median coherence in the
    band is below :data:`DIAGRAM_MIN_COHERENCE` (a z sensor that nothing in its run drives reads noise, and the
    diagram normalises every column to unit RMS: two such columns of six left a 100 N run with no stable
    pole). A run keeps all its columns when none passes; the refinement always fits every column."""
    good = []
    for x in frfs:
        coh = getattr(x, "coherence", None)
        n = len(x.channels)
        if coh is None:
            good.append(np.ones(n, bool))
        else:
            good.append(np.median(np.asarray(coh)[sel], axis=0) >= DIAGRAM_MIN_COHERENCE)
    flags = np.concatenate(good) if good else np.zeros(0, bool)
    for sl in groups:
        if not np.any(flags[sl]):
            flags[sl] = True
    return np.flatnonzero(flags)


def _regroup(groups: list, keep: np.ndarray) -> list:
    """The run slices of the kept columns."""
    out, start = [], 0
    for sl in groups:
        n = int(np.count_nonzero((keep >= sl.start) & (keep < sl.stop)))
        out.append(slice(start, start + n))
        start += n
    return out


def _padded(d: Stabilisation, keep: np.ndarray, n_cols: int) -> Stabilisation:
    """A diagram of the kept columns with its participation on every column (zero on the others)."""
    if keep.size == n_cols:
        return d
    full = np.zeros((d.participation.shape[0], n_cols), complex)
    full[:, keep] = d.participation
    return replace(d, participation=full)


#: a run's own diagram (runs that share no channel) goes to this many poles: one run sees at most the five
#: carriage modes and a few of the rig's (36 poles hold 18 modes); the orders above cost 40 % of the diagram
PER_RUN_MAX_ORDER = 36


def _diagram(f, H, orders, refs, groups: list) -> Stabilisation:
    """The stabilisation diagram of all runs: poly-reference when the runs share channels and differ in
    hit (``refs``); else, with several runs, each run's own common-denominator diagram, the poles of all
    of them in one diagram (each pole's participation on its own run's columns, zero on the others).

    Runs that share no channel (one axis per run: y sensors in the vertical run, x in the lateral) see
    different modes: in one common-denominator fit of all columns a mode that only the lateral run shows
    (a damped roll_low beside the vertical run's pitch, a weakly hit yaw) stabilises at few orders or not
    at all, while each run's own diagram holds it at most orders (validation file v2_side: roll_low at
    3 of 23 orders together, 16 of 23 alone). :func:`select_poles` then clusters the poles of all runs:
    a mode that several runs show is one cluster.
    """
    if refs is not None or len(groups) < 2:
        return lscf_stabilisation(f, H, orders, references=refs)
    run_orders = [n for n in orders if n <= PER_RUN_MAX_ORDER] or list(orders)

    def one(sl):
        try:
            return sl, lscf_stabilisation(f, H[:, sl], run_orders)
        except IdentificationError:
            return None

    # each run's diagram is independent: two threads (the solves and eigenvalues release the GIL)
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(max_workers=2) as pool:
        parts = [p for p in pool.map(one, groups) if p is not None]
    if not parts:
        return lscf_stabilisation(f, H, orders)
    n_cols = H.shape[1]
    pad = []
    for sl, d in parts:
        full = np.zeros((d.participation.shape[0], n_cols), complex)
        full[:, sl] = d.participation
        pad.append(full)
    cat = [np.concatenate([getattr(d, k) for _, d in parts]) for k in
           ("orders", "frequency_hz", "damping_ratio")]
    flags = [np.concatenate([getattr(d, k) for _, d in parts]) for k in ("stable_f", "stable_z", "stable_v")]
    return Stabilisation(cat[0], cat[1], cat[2], np.concatenate(pad), *flags, parts[0][1].band_hz)


def global_fit(frf_by_run: dict, band_hz: tuple, *, orders: Sequence[int] = range(4, 49, 2),
               jackknife: bool = True, selection_spread: bool = True, weighting: str = "noise") -> GlobalFit:
    """Identify the modes of all runs together: LSCF diagram, pole selection, global refinement.

    Parameters
    ----------
    frf_by_run : dict of str to guidefit.frf.FrfSet
        Each run's FRFs (all response channels), on one frequency grid
        (:func:`guidefit.identify.run_frfs` makes one for runs of other record
        lengths or sample rates). Runs off the grid of most FRF columns are
        listed in ``excluded_runs``, not fitted.
    band_hz : (float, float)
        Band holding every mode of interest; the modes outside it are left to
        the residual terms.
    orders : sequence of int
        LSCF denominator orders of the stabilisation diagram.
    jackknife, selection_spread : bool
        Include the hit-group jackknife and the pole-selection spread in the std.

    Returns
    -------
    GlobalFit

    Raises
    ------
    guidefit.errors.IdentificationError
        When the band holds too few bins or no stable pole.
    """
    with one_blas_thread():
        return _global_fit(frf_by_run, band_hz, orders, jackknife, selection_spread, weighting)


def _global_fit(frf_by_run, band_hz, orders, jackknife, selection_spread, weighting) -> GlobalFit:
    if not frf_by_run:
        raise IdentificationError("global fit: no run gave an FRF")
    groups: dict[tuple, list] = {}
    for name, frf in frf_by_run.items():
        groups.setdefault(_grid_key(frf), []).append(name)
    main = max(groups.values(), key=lambda names: sum(len(frf_by_run[n].channels) for n in names))
    excluded = tuple(n for n in frf_by_run if n not in main)
    frfs = [frf_by_run[n] for n in main]
    f_all = np.asarray(frfs[0].frequency_hz, dtype=float)
    lo, hi = float(band_hz[0]), float(band_hz[1])
    sel_bins = (f_all >= lo) & (f_all <= hi)
    f = f_all[sel_bins]
    if f.size < 16:
        raise IdentificationError(f"global fit: {f.size} FRF bins between {lo:.0f} and {hi:.0f} Hz; too few")
    band = (float(f[0]), float(f[-1]))
    H = np.hstack([np.asarray(x.H)[sel_bins] for x in frfs])
    columns, runs, start = [], {}, 0
    for name, x in zip(main, frfs):
        columns += [(name, ch) for ch in x.channels]
        runs[name] = slice(start, start + len(x.channels))
        start += len(x.channels)
    # the diagram only seeds the refinement: at most ~MAX_DIAGRAM_BINS bins (long records: every k-th)
    step = max(1, int(math.ceil(f.size / MAX_DIAGRAM_BINS)))
    refs = _references(frfs, sel_bins)
    keep = _diagram_columns(frfs, sel_bins, list(runs.values()))
    diagram = _padded(_diagram(f[::step], H[::step][:, keep], orders, None if refs is None else refs[::step],
                               _regroup(list(runs.values()), keep)), keep, H.shape[1])
    selection = select_poles(diagram)
    if not selection.chosen:
        raise IdentificationError(f"global fit: no stable pole between {band[0]:.0f} and {band[1]:.0f} Hz")
    shifts = [1.0 / x.exp_window_tau_s if getattr(x, 'exp_window_tau_s', None) else 0.0 for x in frfs]
    groups = list(runs.values())
    prob = _Shared(f, H, groups, shifts, scale=_noise_scale(frfs, sel_bins) if weighting == "noise" else None)
    fit = _refine(prob, band, [(c.frequency_hz, c.damping_ratio) for c in selection.chosen])
    if fit is None:
        raise IdentificationError("global fit: the least-squares refinement of the selected poles failed")
    keep = _significant(fit, f)
    if len(keep) < len(fit.modes) and keep:
        fit = _refine(prob, band, [(fit.modes[k].frequency_hz, fit.modes[k].damping_ratio) for k in keep]) or fit
    modes = list(fit.modes)
    poles = _mode_poles(modes, fit)  # where prob keeps its design and products
    if prob.scale is not None and weighting == "noise":
        # the noise-weighted fit is the efficient estimate; its std assumes the model exact and the noise
        # known. The same poles' std in the equally weighted problem also carries the misfit of the weak
        # channels: the larger of the two is reported
        plain = _Shared(f, H, groups, shifts, scale=_equal_scale(H))
        plain.share = prob  # the same design at the same poles
        modes = _conservative_std(plain, modes, poles)
    jk = _jackknife(frfs, band, modes, prob, poles) if jackknife else [(None, None)] * len(modes)
    thin = _Shared(f[::step], H[::step], groups, shifts) if step > 1 else prob  # a spread, not an estimate
    sp = _selection_spread(thin, band, modes, selection, diagram) if selection_spread else [(None, None)] * len(modes)
    from dataclasses import replace

    parts, out = [], []
    for m, (jf, jz), (sf, sz) in zip(modes, jk, sp):
        ef, ez = ESTIMATOR_BIAS_FREQUENCY * m.frequency_hz, ESTIMATOR_BIAS_DAMPING * m.damping_ratio
        parts.append({"fit": (m.frequency_std_hz, m.damping_std), "jackknife": (jf, jz), "selection": (sf, sz),
                      "estimator": (ef, ez)})
        out.append(replace(m, frequency_std_hz=_rss(m.frequency_std_hz, jf, sf, ef),
                           damping_std=_rss(m.damping_std, jz, sz, ez)))
    return GlobalFit(out, columns, runs, band, f, fit.residuals, diagram, selection, parts, excluded, fit.nrmse)


def run_estimates(gf: GlobalFit, frf_by_run: dict, min_share: float = 0.01) -> dict:
    """Each run's own (f, zeta) of every global mode: the run's FRFs refitted alone from the global poles.

    A diagnostic beside the shared-pole fit, and what keeps runs that differ
    only in hit force apart (an amplitude-dependent joint gives each its own
    frequency). Returns ``{run: [Mode or None per global mode]}``; None where
    the run shows less than ``min_share`` of the mode's largest modal
    constant over the runs or where its refit drifts from the global pole
    (by more than ``zeta f`` in frequency).
    """
    with one_blas_thread():
        return _run_estimates(gf, frf_by_run, min_share)


def _run_estimates(gf: GlobalFit, frf_by_run: dict, min_share: float) -> dict:
    out: dict = {}
    lo, hi = gf.band_hz
    amps = {run: np.array([np.linalg.norm(np.asarray(m.modal_constants)[sl]) for m in gf.modes])
            for run, sl in gf.runs.items()}
    top = np.max(np.array(list(amps.values())), axis=0) if amps else np.zeros(len(gf.modes))
    for run in gf.runs:
        frf = frf_by_run[run]
        sel = np.flatnonzero((frf.frequency_hz >= lo) & (frf.frequency_hz <= hi))
        sel = sel[::max(1, int(math.ceil(sel.size / MAX_DIAGRAM_BINS)))]  # long records: every k-th bin
        tau = getattr(frf, "exp_window_tau_s", None)
        prob = _Shared(frf.frequency_hz[sel], np.asarray(frf.H)[sel], [slice(None)], [1.0 / tau if tau else 0.0])
        try:
            fit = _gauss_newton(prob, gf.band_hz, [(m.frequency_hz, m.damping_ratio) for m in gf.modes])
        except (ValueError, np.linalg.LinAlgError):
            fit = None
        row = [None] * len(gf.modes)
        if fit is not None:
            for k, j in enumerate(_match(fit.modes, gf.modes)):
                m = gf.modes[k]
                if j is None or amps[run][k] < min_share * max(top[k], 1e-300):
                    continue
                r = fit.modes[j]
                if abs(r.frequency_hz - m.frequency_hz) <= m.damping_ratio * m.frequency_hz:
                    row[k] = r
        out[run] = row
    return out
