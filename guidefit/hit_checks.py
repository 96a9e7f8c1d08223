"""The per-hit quality checks of :mod:`guidefit.hits`: the numerics that judge one record.

:func:`_assess_rows` runs the checks (``non_finite``, ``negative``, ``too_weak``,
``double_hit``, ``clipped``, ``dropout``, ``flat_end``, ``not_decayed``; see
:mod:`guidefit.hits` for what each means) on the channel rows of one record,
one helper per check giving its reason (:func:`_non_finite`, :func:`_too_weak`,
:func:`_clipped`, :func:`_dropped_out`, :func:`_flat_ends`, :func:`_not_decayed`)
on top of the detectors (:func:`_double_hit`, :func:`_dropout`, :func:`_flat_end`,
:func:`_flat_top`, :func:`_median`...). They are kept apart from
:mod:`guidefit.hits`, which finds the hits and reads them from the file, because
they are pure functions of the samples (no file, no iteration state): they can
be read, tested and tuned without the streaming code, and the streaming code
without them. Nothing here imports :mod:`guidefit.hits` (the settings object
passed in is a :class:`guidefit.hits.HitSettings`).
"""

from __future__ import annotations

import math

import numpy as np

from guidefit.io.records import Run

_METRICS = ("pulse_width_s", "second_impact_ratio", "end_ratio")


_ABSURD_SAMPLE = 1e100  # |sample| at or beyond this is corrupt (non_finite); its square overflows

#: samples per step of :func:`_rows_from_raw`: a (C, 8192) float64 block stays in the core's cache
_CONVERT_BLOCK = 8192


def _rows_from_raw(rows: np.ndarray, raw: np.ndarray, scale) -> tuple[np.ndarray, np.ndarray]:
    """``rows[:] = float64(raw.T) * scale[:, None]``, and the max and min of each row.

    Block by block, so that the max and min are taken while the block is still
    in cache (one pass over the hit instead of three); the values are those of
    ``rows.max(axis=1)`` and ``rows.min(axis=1)`` (a NaN or an Inf propagates
    the same way).
    """
    n = rows.shape[1]
    steps = range(0, n, _CONVERT_BLOCK)
    tops = np.empty((len(steps), rows.shape[0]))
    bottoms = np.empty_like(tops)
    for j, a in enumerate(steps):
        block = rows[:, a:a + _CONVERT_BLOCK]
        np.copyto(block, raw[a:a + _CONVERT_BLOCK].T)
        if scale is not None:
            block *= scale[:, None]
        np.max(block, axis=1, out=tops[j])
        np.min(block, axis=1, out=bottoms[j])
    return tops.max(axis=0), bottoms.min(axis=0)


def _assess(data, run: Run, s, pre: int | None, median_peak, force_base=None):
    """(codes, reasons, signed peak, pretrigger, metrics) of one record ``data`` (n, C).

    ``force_base``, if given, is the force baseline already computed from the
    same samples (the median of the pre-trigger or of the whole force).
    """
    # one contiguous row per channel: cheaper passes
    return _assess_rows(np.ascontiguousarray(data.T), run, s, pre, median_peak, force_base)


def _assess_rows(columns, run: Run, s, pre: int | None, median_peak, force_base=None,
                 extremes=None):
    """:func:`_assess` of the channel rows ``columns`` (C, n), SI, float64 or float32 (``extremes``: their
    max and min per row, if known).

    The checks in turn: corrupt samples (:func:`_non_finite`, which ends the assessment), the
    force peak's sign, then ``too_weak``, ``double_hit``, ``clipped``, ``dropout``, ``flat_end``
    and ``not_decayed`` (each by a helper below that returns its reason or ``None``).
    """
    names = run.channel_names
    fs = run.sample_rate_hz
    fi = run.force_index
    metrics = dict.fromkeys(_METRICS, math.nan)
    # max and min of each channel: NaN if it holds a NaN, +-Inf if an Inf
    tops, bottoms = extremes if extremes is not None else (columns.max(axis=1), columns.min(axis=1))
    # a sample beyond +-1e100 (a corrupt one: no force or acceleration comes near) would overflow the spectra
    if not (np.all(np.abs(tops) < _ABSURD_SAMPLE) and np.all(np.abs(bottoms) < _ABSURD_SAMPLE)):
        # False for NaN too (every finite float32 is below 1e100)
        return (*_non_finite(columns, names, fi), pre, metrics)
    quiet = slice(0, pre - 2) if pre is not None and pre >= 16 else None
    force = columns[fi]
    if force_base is None:
        force_base = _median(force[quiet]) if quiet else _median(force)
    fc = force - force_base
    bases = {}

    def base(c):  # baseline of channel c, computed once
        if c not in bases:
            col = columns[c]
            bases[c] = _median(col[quiet]) if quiet else _median(col)
        return bases[c]

    p = _peak_index(fc, tops[fi] - force_base, bottoms[fi] - force_base)
    peak = float(fc[p])
    if peak <= 0:
        if peak == 0:
            return ["too_weak"], ["too_weak: the force is flat"], peak, pre, metrics
        return (
            ["negative"],
            [
                f"negative: force peak {peak:.4g} N points against excitation_direction (force sign or direction wrong?)"
            ],
            peak,
            pre,
            metrics,
        )
    if (
        pre is None
    ):  # stored hit without pretrigger_samples: where the force reaches the trigger level
        level = s.trigger_level_n if s.trigger_level_n is not None else s.trigger_fraction * peak
        pre = int(np.argmax(fc >= min(level, peak)))
    double = _double_hit(fc, p, peak, fs, s, metrics)
    found = {
        "too_weak": _too_weak(peak, median_peak, s),
        "double_hit": f"double_hit: {double}" if double else None,
        "clipped": _clipped(columns, run, s, tops, bottoms),
        "dropout": _dropped_out(columns, run, s, quiet, pre, base),
        "flat_end": _flat_ends(columns, run, quiet, pre, base, tops, bottoms),
    }
    metrics["end_ratio"], found["not_decayed"] = _not_decayed(columns, run, s, quiet, base, tops, bottoms)
    codes = [code for code, reason in found.items() if reason is not None]
    return codes, [found[code] for code in codes], peak, pre, metrics


def _non_finite(columns, names, fi) -> tuple[list, list, float]:
    """``(codes, reasons, signed peak)`` of a record holding a NaN, an Inf or a sample beyond
    +-1e100 (a corrupt one): ``non_finite``, with the count and the channels."""
    finite = np.isfinite(columns) if columns.dtype == np.float32 else np.abs(columns) < _ABSURD_SAMPLE
    bad = [names[c] for c in np.flatnonzero(~finite.all(axis=1))]
    force = columns[fi][finite[fi]].astype(np.float64, copy=False)  # a rare hit: float64 arithmetic
    peak = _signed_extreme(force - np.median(force)) if force.size else math.nan
    count = int((~finite).sum())
    return (
        ["non_finite"],
        [f"non_finite: {count} NaN/Inf{'' if count == (~np.isfinite(columns)).sum() else ' or corrupt (beyond 1e100)'} "
         f"sample(s) in {', '.join(bad)}"],
        peak,
    )


def _peak_index(fc, top, bottom) -> int:
    """``argmax |fc|`` (its first occurrence), given ``top`` and ``bottom``, the max and min of ``fc``.

    The max and min of fc come from those of the force (rounding is monotone), so only the
    winning side is searched.
    """
    if top > -bottom:
        return int(np.argmax(fc))
    if top < -bottom:
        return int(np.argmin(fc))
    return min(int(np.argmax(fc)), int(np.argmin(fc)))


def _too_weak(peak, median_peak, s) -> str | None:
    """The ``too_weak`` reason when the force peak is below the minimum or the run's median share."""
    limit, why = 0.0, ""
    if s.min_peak_force_n is not None:
        limit, why = s.min_peak_force_n, "the minimum"
    if (
        median_peak is not None
        and math.isfinite(median_peak)
        and s.min_peak_fraction * median_peak > limit
    ):
        limit = s.min_peak_fraction * median_peak
        why = f"{s.min_peak_fraction:.0%} of the run's median peak {median_peak:.4g} N"
    if peak < limit:
        return f"too_weak: peak {peak:.4g} N below {limit:.4g} N ({why})"
    return None


def _clipped(columns, run: Run, s, tops, bottoms) -> str | None:
    """The ``clipped`` reason: the channels with a flat top or bottom (:func:`_flat_top`)."""
    clipped = []
    for c in range(columns.shape[0]):
        flat = _flat_top(columns[c], s.clip_min_run, float(tops[c]), float(bottoms[c]))
        if flat is not None:
            m, value = flat
            unit = run.channels[c].unit_si
            clipped.append(f"{run.channel_names[c]} ({m} samples at {value:.6g} {unit})")
    return f"clipped: {', '.join(clipped)}" if clipped else None


def _dropped_out(columns, run: Run, s, quiet, pre, base) -> str | None:
    """The ``dropout`` reason: every channel frozen while the response rings (:func:`_dropout`)."""
    fs = run.sample_rate_hz
    dropout = _dropout(
        columns, run.response_indices, quiet, pre, max(8, round(s.dropout_min_s * fs)), base
    )
    if dropout is None:
        return None
    a, m = dropout
    return (
        f"dropout: every channel frozen for {m} samples ({m / fs * 1e3:.3g} ms) from sample {a}, "
        "while the response is still ringing"
    )


def _flat_ends(columns, run: Run, quiet, pre, base, tops, bottoms) -> str | None:
    """The ``flat_end`` reason: response channels held at one value to the end (:func:`_flat_end`)."""
    names, fs, n = run.channel_names, run.sample_rate_hz, columns.shape[1]
    flat = []
    for c in run.response_indices:
        noise = 0.0
        if quiet:
            start = columns[c][quiet] - base(c)
            noise = math.sqrt(np.add.reduce(np.square(start, out=start)) / start.size)
        peak_c = float(max(tops[c] - base(c), base(c) - bottoms[c]))
        tail = _flat_end(columns[c], pre, noise, peak_c)
        if tail is not None:
            k, value, lsbs = tail
            flat.append(
                f"{names[c]} held at {value:.6g} {run.channels[c].unit_si} for its last "
                f"{(n - k) / fs * 1e3:.3g} ms (from sample {k}), right after ringing at {lsbs:.3g} LSB"
            )
    return f"flat_end: {', '.join(flat)} (DAQ stopped or padded export?)" if flat else None


def _not_decayed(columns, run: Run, s, quiet, base, tops, bottoms) -> tuple[float, str | None]:
    """``(end_ratio, reason)``: the largest ratio of a response channel's end RMS (times sqrt 2) to
    its peak, and the ``not_decayed`` reason when one is above the limit and above the noise."""
    names, n = run.channel_names, columns.shape[1]
    n_end = max(8, math.ceil(s.decay_end_fraction * n))
    worst = 0.0
    slow = []
    for c in run.response_indices:
        col = columns[c]
        m = base(c)
        # max |x - m| without forming x: rounding is monotone, and min <= m <= max
        top = float(max(tops[c] - m, m - bottoms[c]))
        if top == 0 or n_end >= n:
            continue
        # RMS as sqrt(np.mean(x ** 2)): the same sum, divided by the count
        end = col[-n_end:] - m
        rms_end = math.sqrt(np.add.reduce(np.square(end, out=end)) / n_end)
        if quiet:
            start = col[quiet] - m
            noise = math.sqrt(np.add.reduce(np.square(start, out=start)) / start.size)
        else:
            noise = 0.0
        ratio = rms_end * math.sqrt(2) / top
        worst = max(worst, ratio)
        if ratio > s.max_end_ratio and rms_end > 3 * noise:
            slow.append(f"{names[c]} ends at {ratio:.0%} of its peak")
    if slow:
        return worst, f"not_decayed: {', '.join(slow)} (limit {s.max_end_ratio:.0%}, a longer record helps)"
    return worst, None


def _median(x: np.ndarray) -> np.float64:
    """``np.median(x)`` of a finite 1-D float array (float32 as float64 arithmetic gives it), usually faster.

    The middle order statistics are bracketed between two values of a strided
    sample; counting the samples below and within the bracket (cheap vectorised
    passes) confirms the bracket, and only the samples inside it are
    partitioned. Where the bracket misses (and for short arrays) the whole
    array is partitioned (:func:`_partition_median`).
    """
    n = x.size
    if n < 8192:
        return _partition_median(x)
    k = n // 2
    ranks = (k - 1, k) if n % 2 == 0 else (k,)
    sample = x[:: n // 4096]
    m = sample.size
    margin = 2 * math.isqrt(m)  # the sample median's rank varies by about isqrt(m) / 2
    edges = (max(0, m // 2 - margin), min(m - 1, m // 2 + margin))
    lo, hi = np.partition(sample, edges)[list(edges)]
    below = int(np.count_nonzero(x < lo))
    if below > ranks[0]:
        return _partition_median(x)
    band = x[(x >= lo) & (x <= hi)]
    if below + band.size <= ranks[-1] or band.size > n // 4:
        return _partition_median(x)
    kth = [r - below for r in ranks]
    part = np.partition(band, kth)
    return np.mean(part[kth[0] : kth[-1] + 1], dtype=np.float64)  # as np.median: the middle one or two


def _partition_median(x: np.ndarray) -> np.float64:
    """The median by one partition, as ``np.median`` computes it: the middle value, or the mean of the
    middle two in float64 (exact order statistics of float32 samples, no float64 copy); NaN if empty."""
    n = x.size
    if n == 0:
        return np.float64(np.nan)
    k = n // 2
    if n % 2:
        return np.float64(np.partition(x, k)[k])
    part = np.partition(x, (k - 1, k))
    return (np.float64(part[k - 1]) + np.float64(part[k])) / 2


def _signed_extreme(x: np.ndarray) -> float:
    if x.size == 0:
        return math.nan
    hi, lo = float(np.max(x)), float(np.min(x))
    return hi if hi >= -lo else lo


def _double_hit(
    fc: np.ndarray, p: int, peak: float, fs: float, s, metrics: dict
) -> str:
    """Describe a second impact in the (baseline-free, positive-peak) force, or ''."""
    # segments of consecutive samples above the pulse-end level: [starts, ends)
    above = np.flatnonzero(fc > s.pulse_end_fraction * peak)  # holds p: peak > 0
    gaps = np.flatnonzero(np.diff(above) > 1)
    starts = np.concatenate((above[:1], above[gaps + 1]))
    ends = np.concatenate((above[gaps], above[-1:])) + 1
    # between segments the force is below the pulse-end level, so a max from
    # one start to the next is the segment's own max
    seg_max = np.maximum.reduceat(fc, starts)
    main = int(np.searchsorted(starts, p, side="right") - 1)
    s0, e0 = int(starts[main]), int(ends[main])
    metrics["pulse_width_s"] = (e0 - s0) / fs
    impacts = np.flatnonzero(seg_max >= s.double_hit_ratio * peak)
    others = impacts[impacts != main]
    if others.size:
        k = int(others[np.argmax(seg_max[others])])
        q = int(starts[k]) + int(np.argmax(fc[starts[k] : ends[k]]))
        ratio = float(seg_max[k]) / peak
        metrics["second_impact_ratio"] = ratio
        gap_ms = ((starts[k] - e0) if k > main else (s0 - ends[k])) / fs * 1e3
        when = "after" if k > main else "before"
        return (
            f"second impact of {ratio:.0%} of the peak {abs(q - p) / fs * 1e3:.3g} ms {when} it "
            f"({gap_ms:.3g} ms {when} the main pulse {'ends' if k > main else 'starts'})"
        )
    seg = fc[s0:e0]
    left = np.maximum.accumulate(seg)
    right = np.maximum.accumulate(seg[::-1])[::-1]
    floor = np.minimum(left, right)
    depth = floor - seg
    j = int(np.argmax(depth))
    metrics["second_impact_ratio"] = (
        float(floor[j]) / peak if depth[j] >= s.double_hit_ratio * peak else 0.0
    )
    if depth[j] >= s.double_hit_ratio * peak:
        return (
            f"two peaks within one pulse, {depth[j] / peak:.0%} of the peak deep dip between them"
        )
    return ""


def _dropout(
    columns: np.ndarray, responses, quiet, trigger: int, min_len: int, base=None
) -> tuple[int, int] | None:
    """(first sample, length) of a block where every channel holds its value, or None.

    Only blocks that start at or after the trigger and before the responses
    have decayed below 10 % of their peaks count: there a live signal cannot
    stand still in every channel at once. ``columns[c]`` holds channel c;
    ``base(c)``, if given, returns its baseline (the median of its pre-trigger,
    or of all of it).
    """
    if not responses:
        return None
    # steps i where sample i + 1 equals sample i in every channel: narrowed
    # channel by channel (responses first: they are rarely still)
    order = list(responses) + [c for c in range(len(columns)) if c not in responses]
    col = columns[order[0]]
    same = col[1:] == col[:-1]  # step i: sample i + 1 equals sample i
    # quick exit: a block needs min_len - 1 equal steps from the trigger on in
    # this channel too; ``run[i]``: steps i .. i + width - 1 after the trigger all equal
    run, width, need = same[trigger:].copy(), 1, min_len - 1
    while width < need and run.size:
        shift = min(width, need - width)
        run[:-shift] &= run[shift:]
        run[-shift:] = False
        width += shift
    if not run.any():
        return None
    still = np.flatnonzero(same)
    for c in order[1:]:
        if not still.size:
            break
        col = columns[c]
        still = still[col[still + 1] == col[still]]
    if not still.size:
        return None
    breaks = np.flatnonzero(np.diff(still) > 1)
    starts = np.r_[still[0], still[breaks + 1]]
    ends = np.r_[still[breaks], still[-1]] + 1  # exclusive, in steps: samples starts .. ends are equal
    lengths = ends - starts + 1
    candidates = np.flatnonzero((lengths >= min_len) & (starts >= trigger))
    if not candidates.size:
        return None
    active_end = 0
    for c in responses:
        if base is None:
            m = np.median(columns[c][quiet]) if quiet else np.median(columns[c])
        else:
            m = base(c)
        x = columns[c] - m
        top = np.max(np.abs(x))
        if top > 0:
            active_end = max(active_end, int(np.flatnonzero(np.abs(x) >= 0.1 * top)[-1]))
    for k in candidates:
        a = int(starts[k])
        if a < active_end:
            return a, int(lengths[k])
    return None


FLAT_END_MIN_FRACTION = 0.02
"""Shortest constant end of a response, as a fraction of the record, that ``flat_end`` judges."""
FLAT_END_MAX_LSB = 4.0
"""Largest amplitude, in LSB, a response may have just before a constant end."""
FLAT_END_MIN_PEAK_FRACTION = 1e-3
"""A constant end after the response fell below this fraction of its peak cut nothing that matters."""


def _flat_end(
    x: np.ndarray, trigger: int, noise_rms: float = 0.0, peak: float = 0.0
) -> tuple[int, float, float] | None:
    """(first sample, value, amplitude before in LSB) of a constant end of ``x`` cut while ringing.

    The end counts when the last ``max(16, 2 %)`` samples or more equal the last
    one exactly, and in the window of ``max(8, (k - trigger) // 32)`` samples
    before it (k: where the constant run starts) the channel deviates from that
    value by more than :data:`FLAT_END_MAX_LSB` quantisation steps and by more
    than :data:`FLAT_END_MIN_PEAK_FRACTION` of ``peak`` (the channel's largest
    excursion from its baseline), and its RMS about it exceeds 3 times
    ``noise_rms`` (the pre-trigger noise): it still rang. See the module docstring for why a real quantised decay never does.
    """
    n = x.size
    need = max(16, math.ceil(FLAT_END_MIN_FRACTION * n))
    if need >= n:
        return None
    value = x[-1]
    if x[-need] != value or not np.all(x[-need:] == value):  # the usual, cheap way out
        return None
    moving = np.flatnonzero(x[: n - need] != value)
    if not moving.size:
        return None  # constant over the whole record: a dead channel, not a cut one
    k = int(moving[-1]) + 1
    width = max(8, (k - trigger) // 32)
    if k - width <= trigger:
        return None  # the response never rang before it froze
    window = x[k - width : k] - value
    amplitude = float(np.max(np.abs(window)))
    if amplitude <= FLAT_END_MIN_PEAK_FRACTION * peak:
        return None  # cut 60 dB down: less than 1e-6 of the response's energy was lost
    if math.sqrt(float(np.mean(np.square(window)))) <= 3.0 * noise_rms:
        return None  # it had decayed into its noise: nothing of the response was cut
    steps = np.diff(np.unique(x))
    lsb = float(np.min(steps)) if steps.size else math.inf
    if amplitude > FLAT_END_MAX_LSB * lsb:
        return k, float(value), amplitude / lsb
    return None


def _flat_top(
    x: np.ndarray, min_run: int, hi: float | None = None, lo: float | None = None
) -> tuple[int, float] | None:
    """(run length, value) of a clipped flat top of ``x``, or None.

    A run of m >= ``min_run`` equal samples at the channel's extreme (the side
    of its largest |value|) counts when, ``max(2, m // 4)`` samples beyond both
    of its ends, the signal lies more than ``4 + 96 / (m - 2)**2`` LSB below it.
    """
    n = x.size
    if hi is None or lo is None:  # max and min of x
        hi, lo = float(np.max(x)), float(np.min(x))
    biggest = max(hi, -lo)  # = max |x|
    if biggest == 0:
        return None
    lsb = None
    for value in {hi, lo}:
        if abs(value) < 0.9 * biggest:
            continue
        at = x == value
        if np.count_nonzero(at) < min_run:  # the usual way out: counting is cheaper than listing
            continue
        at = np.flatnonzero(at)
        breaks = np.flatnonzero(np.diff(at) > 1)
        run_starts = np.r_[at[0], at[breaks + 1]]
        run_ends = np.r_[at[breaks], at[-1]]
        for a, b in zip(run_starts, run_ends):
            m = int(b - a + 1)
            if m < min_run:
                continue
            k = max(2, m // 4)
            drops = []
            if a >= 2:
                drops.append(abs(value - x[a - min(k, a)]))
            if b + 2 < n:
                drops.append(abs(value - x[b + min(k, n - 1 - b)]))
            if not drops:  # stuck at a non-zero value over the whole record
                return m, value
            if lsb is None:  # smallest step between distinct values (as np.diff(np.unique(x)))
                steps = np.diff(np.sort(x))
                steps = steps[steps > 0]
                lsb = float(np.min(steps)) if steps.size else math.inf
            if min(drops) > (4 + 96 / (m - 2) ** 2) * lsb:
                return m, value
    return None
