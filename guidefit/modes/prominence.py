"""Local maxima and their topographic prominence: ``scipy.signal.find_peaks(y, prominence=p)`` in numpy.

Importing :mod:`scipy.signal` costs 0.4-0.7 s of start-up, more than the
whole identification of a small recording, and identify needs only the
peaks of a mode indicator with their prominence. :func:`prominent_peaks`
gives the same peaks (a plateau reduced to its middle sample) and the same
prominences (the same samples' minimum subtracted from the peak, so the same
numbers); tests compare the two on random walks, long curves with plateaus,
and NaN and infinite values.
"""

from __future__ import annotations

import numpy as np


def prominent_peaks(y, min_prominence: float) -> tuple[np.ndarray, np.ndarray]:
    """Local maxima of ``y`` with their topographic prominence, those >= ``min_prominence``.

    The same peaks and prominences as ``scipy.signal.find_peaks(y,
    prominence=min_prominence)`` (flat tops: the middle sample), written with
    numpy because importing :mod:`scipy.signal` costs 0.4-0.7 s of start-up,
    more than the whole identification of a small recording; a test compares
    the two on random data.

    >>> idx, prom = prominent_peaks(np.array([0, 3, 1, 2, 1, 5, 0.0]), 0.5)
    >>> idx.tolist(), prom.tolist()
    ([1, 3, 5], [2.0, 1.0, 5.0])
    """
    y = np.asarray(y, dtype=float)
    if y.size < 3:
        return np.zeros(0, dtype=int), np.zeros(0)
    if not np.all(np.isfinite(y)):
        idx, prom = _prominences_walk(y)  # NaN compares false: scipy's sample-by-sample rules
    else:
        idx = _local_maxima(y)
        prom = _prominences(y, idx)
    keep = prom >= min_prominence
    return idx[keep], prom[keep]


def _local_maxima(y: np.ndarray) -> np.ndarray:
    """Indices of the local maxima of finite ``y``, a plateau reduced to its middle sample (scipy's
    ``_local_maxima_1d``): runs of equal samples higher than the runs on both sides, neither run at an end."""
    starts = np.flatnonzero(np.concatenate(([True], y[1:] != y[:-1])))
    ends = np.append(starts[1:], y.size) - 1
    v = y[starts]
    k = np.flatnonzero((v[1:-1] > v[:-2]) & (v[1:-1] > v[2:])) + 1
    return (starts[k] + ends[k]) // 2


def _prominences(y: np.ndarray, peaks: np.ndarray) -> np.ndarray:
    """Topographic prominence of each peak of finite ``y`` (scipy's ``_peak_prominences``, no wlen).

    Each side extends to the nearest strictly higher sample (or the edge); the base on a side is the
    lowest sample of that stretch. The stretches are found for all peaks at once by binary lifting on
    a sparse table of range maxima (the walk sample by sample cost 13 ms on 2 x 2300 bins), and their
    minima read from a table of range minima: the same samples, so the same numbers.
    """
    n = y.size
    hi, lo = [y], [y]  # level k: max / min of y[i : i + 2**k]
    while 2 ** len(hi) <= n:
        h = 2 ** (len(hi) - 1)
        hi.append(np.maximum(hi[-1][:-h], hi[-1][h:]))
        lo.append(np.minimum(lo[-1][:-h], lo[-1][h:]))
    top = y[peaks]
    left = peaks.copy()  # y[left:peak] <= y[peak] (empty at first)
    right = peaks.copy()  # y[peak + 1:right + 1] <= y[peak]
    for k in range(len(hi) - 1, -1, -1):
        w = 2 ** k
        ok = left - w >= 0
        ok[ok] &= hi[k][left[ok] - w] <= top[ok]
        left[ok] -= w
        ok = right + w <= n - 1
        ok[ok] &= hi[k][right[ok] + 1] <= top[ok]
        right[ok] += w

    def range_min(a, b):  # min of y[a:b + 1], a <= b
        k = np.floor(np.log2(b - a + 1)).astype(int)
        out = np.empty(a.size)
        for level in np.unique(k):
            sel = k == level
            t = lo[level]
            out[sel] = np.minimum(t[a[sel]], t[b[sel] - 2 ** level + 1])
        return out

    return top - np.maximum(range_min(left, peaks), range_min(peaks, right))


def _prominences_walk(y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Local maxima and prominences by scipy's sample-by-sample walks (any input, NaN included)."""
    n = y.size
    y_arr, y = y, y.tolist()  # python floats for the walks below (one sample at a time)
    # candidate maxima, plateaus reduced to their middle sample (as scipy's _local_maxima_1d)
    peaks = []
    i = 1
    while i < n - 1:
        if y[i - 1] < y[i]:
            ahead = i + 1
            while ahead < n - 1 and y[ahead] == y[i]:
                ahead += 1
            if y[ahead] < y[i]:
                peaks.append((i + ahead - 1) // 2)
                i = ahead
        i += 1
    idx = np.array(peaks, dtype=int)
    prom = np.empty(idx.size)
    for k, p in enumerate(peaks):
        # walk out to the nearest strictly higher sample (or the edge); the base is the minimum on the way
        left = p
        while left > 0 and y[left - 1] <= y[p]:
            left -= 1
        right = p
        while right < n - 1 and y[right + 1] <= y[p]:
            right += 1
        prom[k] = y[p] - max(y_arr[left:p + 1].min(), y_arr[p:right + 1].min())
    return idx, prom
