"""Hits of a run: detection in continuous records and per-hit quality checks.

A run stores either one record per hit (layout ``hits``) or one continuous
record (layout ``signals``). :func:`iter_hits` turns both into a stream of
:class:`Hit` records of equal length, reading the file in bounded memory:

- ``hits`` layout: one Hit per stored record, in file order.
- ``signals`` layout: the force channel is streamed in chunks (never the
  whole signal) to find *triggers*: rising crossings of ``|f - mean(f)|``
  through the trigger level, at most one per hold-off time. Each hit's record
  starts ``pretrigger`` samples before its trigger; every record of a run has
  the same length (see :class:`HitSettings` for how it is chosen). Then each
  record is read.

The file stays open for the whole iteration
(:func:`guidefit.io.open_reader`). For ``hits``, the force of every
stored hit is read first (for the run's median peak, used by ``too_weak``) in
blocks of at most 8 MB, or the whole run is read once if it is that small.

Every record is checked; a hit that fails a check is yielded with
``accepted=False``, ``data=None`` and a reason, never dropped. The checks, in
order (the first two end the assessment; the others are all reported):

``non_finite``
    NaN or Inf in any channel.
``negative``
    The largest force excursion is negative: the hit pushed against
    ``excitation_direction`` (a wrong sign in the file, or a rebound).
``too_weak``
    Peak force below ``min_peak_force_n`` or below ``min_peak_fraction`` of the
    run's median peak.
``double_hit``
    A second impact: the force, after (or before) the main pulse, rises again
    above ``double_hit_ratio`` (10 %) of the peak, however soon after the main
    pulse ends (the pulse ends where the force falls below
    ``pulse_end_fraction``, 5 %, of the peak); or the main pulse has two humps
    separated by a dip deeper than ``double_hit_ratio`` of the peak. This is a
    time-domain test; spectral tests miss second impacts that come soon
    after the first.
``clipped``
    Overload of any channel: a run of at least ``clip_min_run`` consecutive
    samples exactly at the channel's extreme value (the side of its largest
    |value|) whose edges are steeper than a smooth quantised peak allows. A
    smooth peak of a quantised signal repeats its top code over m samples only
    if its curvature is small, and then the signal ``max(2, m // 4)`` samples
    beyond the run lies within a few LSB of the top; a clipped signal drops
    much faster. The limit is ``4 + 96 / (m - 2)^2`` LSB, the LSB being the
    smallest step between distinct values of the channel in the record (for
    unquantised data: tiny, so any exact flat top of m >= 3 samples with an
    edge counts). It was set from 40 000 simulated 12- to 16-bit decaying
    oscillations (3 to 20 000 samples per period, 0-5 LSB of noise): none of
    the unclipped ones exceeds it, and all but 4 of 37 848 clipped by 5 % or
    more (with a flat top of 3 or more samples) do; ``tests/test_hits.py``
    repeats a smaller version. A channel stuck at one non-zero value over the
    whole record counts as clipped too.
``dropout``
    Every channel holds its value exactly for ``dropout_min_s`` (0.1 ms, at
    least 8 samples) or longer, starting after the trigger and before the
    responses have decayed below 10 % of their peaks: the data acquisition
    lost a block of samples (they read as a constant, often 0). A live,
    noisy signal never stands still in all channels at once; before the
    trigger (e.g. noise-free simulated data) such blocks are normal.
``flat_end``
    A response channel ends in a run of samples exactly equal to its last
    value (zeros of a padded export, the held value of a DAQ that stopped),
    at least 2 % of the record (16 samples or more) long, while just before
    that run it still rang: above 4 quantisation steps (the channel's LSB:
    the smallest step between its distinct values; for unquantised data a
    tiny number), above 0.1 % of its peak, and, in RMS, above 3 times its
    pre-trigger noise (a response that had decayed into its noise, or 60 dB
    down, lost nothing that matters when the rest was cut). A real decaying response is never exactly constant:
    quantised, it becomes constant only once it has decayed below one LSB,
    and because it took the whole time since the trigger to decay from its
    peak to that level, its amplitude in the last 1/32 of that time (the
    window looked at) is at most (peak / LSB)^(1/32), about 1.4 LSB for a
    full-scale 16-bit peak, 1.7 for 24 bits: a quiet 16-bit tail passes.
    Truncated records would otherwise be fitted as if the response had died
    out (zeroing every record of the sample 3 ms after its hit gave f_V
    -1.9 % and zeta_V +14 %).
``not_decayed``
    A response channel has not died out by the end of the record: the RMS of
    its last ``decay_end_fraction`` (5 %) of samples, times sqrt(2), exceeds
    ``max_end_ratio`` (10 %) of its peak |value| (both after removing the
    pre-trigger baseline) and exceeds 3 times the pre-trigger noise RMS.
``incomplete``, ``overlap`` (``signals`` layout only)
    The record would start before or end after the signal, or it would
    overlap the previous hit's record (the previous impact is less than one
    record length before).

The reason string is ``"<code>: <detail>"``, several joined by ``"; "``;
:attr:`Hit.codes` holds the codes alone.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

import numpy as np

from guidefit.errors import GuidefitError
from guidefit.hit_checks import (
    _ABSURD_SAMPLE,
    _METRICS,
    _assess,
    _assess_rows,
    _median,
    _rows_from_raw,
    _signed_extreme,
)
from guidefit.io.records import Run, open_reader, read_block, read_hit  # noqa: F401

__all__ = [
    "CHUNK_SAMPLES",
    "REJECTION_CODES",
    "Hit",
    "HitSettings",
    "HitSettingsError",
    "check_hit",
    "iter_hits",
    "summarise_hits",
]

CHUNK_SAMPLES = 1_000_000
"""Samples of the force channel read per step when scanning a ``signals`` run."""

_READ_BYTES = 8 << 20
"""Bound on one read (all channels, as float64; at least one hit) when scanning the force of stored hits."""
_CACHE_BYTES = 8 << 20
"""Stored hits up to this size in float64 are read once and kept between the two passes."""

DEFAULT_PRETRIGGER_S = 1e-3

REJECTION_CODES = {
    "non_finite": "NaN or Inf samples in a channel",
    "negative": "the force points against excitation_direction",
    "too_weak": "peak force below the minimum",
    "double_hit": "a second impact in the record",
    "clipped": "a channel is flat at its extreme (overload)",
    "dropout": "every channel frozen for a block of samples while the response rings",
    "flat_end": "a response ends held exactly constant while it still rang (DAQ stopped, padded export)",
    "not_decayed": "a response has not died out by the end of the record",
    "incomplete": "the record would run outside the signal",
    "overlap": "the record overlaps the previous hit's record",
}
"""Codes of :attr:`Hit.codes` and what they mean."""


class HitSettingsError(GuidefitError, ValueError):
    """A :class:`HitSettings` value is out of range (exit status 2)."""


@dataclass(frozen=True)
class HitSettings:
    """How hits are found and checked. Times in s, forces in N, ratios as fractions.

    Parameters
    ----------
    trigger_level_n : float, optional
        Absolute trigger level on ``|force - mean(force)|``, N. Default: relative.
    trigger_fraction : float
        Relative trigger level: this fraction of the run's largest
        ``|force - mean(force)|``, found in a first streaming pass (default 0.05).
    pretrigger_s : float, optional
        Record start before the trigger (``signals`` layout; stored hits keep
        their own). Default: the file's
        ``pretrigger_samples`` if given, else 1 ms, shortened to the first
        trigger's position if that comes earlier in the signal.
    record_length_s : float, optional
        Length of every record (pretrigger included). Default for ``signals``:
        the shortest spacing between triggers (ignoring spacings below half the
        median, which are double hits), at most ``max_record_length_s``, and
        shortened to fit the last hit when at least half of it fits (a single
        hit: the rest of the signal after its pretrigger); for
        ``hits``: the stored length. A set value is never changed: records
        that do not fit are rejected.
    max_record_length_s : float
        Upper bound of the default record length (0.5 s).
    holdoff_s : float
        After a trigger, no new trigger for this long (5 ms); a second impact
        within it is judged by the double-hit check.
    min_peak_force_n : float, optional
        Absolute minimum peak force, N.
    min_peak_fraction : float
        Minimum peak force as a fraction of the run's median peak (0.05).
    double_hit_ratio : float
        A second impact counts from this fraction of the main peak (0.10).
    pulse_end_fraction : float
        The main pulse ends where the force falls below this fraction of
        its peak (0.05).
    clip_min_run : int
        Shortest flat run at a channel's extreme that can count as clipping (3).
    decay_end_fraction : float
        Share of the record at its end over which the decay is judged (0.05).
    max_end_ratio : float
        Largest allowed end amplitude, as a fraction of the channel's peak (0.10).
    dropout_min_s : float
        Shortest block, s (at least 8 samples), in which every channel holding
        its value exactly counts as a data dropout (0.1 ms).

    Examples
    --------
    >>> HitSettings(record_length_s=0.2).holdoff_s
    0.005
    >>> HitSettings(trigger_fraction=2.0)
    Traceback (most recent call last):
    ...
    guidefit.hits.HitSettingsError: HitSettings: trigger_fraction is 2.0; expected a number in (0, 1)
    """

    trigger_level_n: float | None = None
    trigger_fraction: float = 0.05
    pretrigger_s: float | None = None
    record_length_s: float | None = None
    max_record_length_s: float = 0.5
    holdoff_s: float = 0.005
    min_peak_force_n: float | None = None
    min_peak_fraction: float = 0.05
    double_hit_ratio: float = 0.10
    pulse_end_fraction: float = 0.05
    clip_min_run: int = 3
    decay_end_fraction: float = 0.05
    max_end_ratio: float = 0.10
    dropout_min_s: float = 1e-4

    def __post_init__(self):
        fractions = (
            "trigger_fraction",
            "double_hit_ratio",
            "pulse_end_fraction",
            "decay_end_fraction",
            "max_end_ratio",
        )
        for name in fractions:
            value = getattr(self, name)
            if not _is_number(value) or not 0 < value < 1:
                raise HitSettingsError(
                    f"HitSettings: {name} is {value!r}; expected a number in (0, 1)"
                )
        if not _is_number(self.min_peak_fraction) or not 0 <= self.min_peak_fraction < 1:
            raise HitSettingsError(
                f"HitSettings: min_peak_fraction is {self.min_peak_fraction!r}; expected a number in [0, 1)"
            )
        positive = (
            "trigger_level_n",
            "record_length_s",
            "max_record_length_s",
            "holdoff_s",
            "dropout_min_s",
        )
        for name in positive:
            value = getattr(self, name)
            if value is None and name in ("trigger_level_n", "record_length_s"):
                continue
            if not _is_number(value) or not value > 0:
                raise HitSettingsError(
                    f"HitSettings: {name} is {value!r}; expected a positive number"
                )
        for name in ("pretrigger_s", "min_peak_force_n"):
            value = getattr(self, name)
            if value is not None and (not _is_number(value) or value < 0):
                raise HitSettingsError(f"HitSettings: {name} is {value!r}; expected a number >= 0")
        if not isinstance(self.clip_min_run, (int, np.integer)) or self.clip_min_run < 3:
            raise HitSettingsError(
                f"HitSettings: clip_min_run is {self.clip_min_run!r}; expected an integer >= 3"
            )
        if self.pulse_end_fraction >= self.double_hit_ratio:
            raise HitSettingsError(
                f"HitSettings: pulse_end_fraction ({self.pulse_end_fraction}) must be below "
                f"double_hit_ratio ({self.double_hit_ratio})"
            )


def _is_number(value) -> bool:
    return (
        isinstance(value, (int, float, np.integer, np.floating))
        and not isinstance(value, bool)
        and math.isfinite(value)
    )


@dataclass(frozen=True, eq=False)
class Hit:
    """One hit of a run, accepted or rejected.

    Attributes
    ----------
    run : str
        Run name.
    index : int
        Hit number within the run: the stored record (``hits``) or the trigger
        in time order (``signals``), counting rejected hits too.
    start_sample : int
        First sample of the record in the run's continuous signal (``signals``);
        0 for stored records (``hits``).
    data : ndarray, shape (n_samples, n_channels), or None
        float64 SI samples of all channels in the run's column order
        (read-only); None if rejected. Raw: no baseline removed, no window.
    peak_force_n : float
        Signed extreme of the force after removing its pre-trigger baseline, N
        (negative for a ``negative`` hit; NaN if it cannot be told).
    accepted : bool
    reason : str or None
        Why it was rejected: ``"<code>: <detail>"``, several joined by ``"; "``.
    pretrigger_samples : int or None
        Samples before the trigger in the record (for stored hits without the
        attribute: where the force first reaches the trigger level).
    codes : tuple of str
        The rejection codes (keys of :data:`REJECTION_CODES`); empty if accepted.
    metrics : mapping of str to float
        ``pulse_width_s`` (main pulse above ``pulse_end_fraction`` of the peak),
        ``second_impact_ratio`` (largest other impact / peak), ``end_ratio``
        (worst response end amplitude / peak); NaN where not computed.
    """

    run: str
    index: int
    start_sample: int
    data: np.ndarray | None
    peak_force_n: float
    accepted: bool
    reason: str | None
    pretrigger_samples: int | None = None
    codes: tuple[str, ...] = ()
    metrics: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self):
        object.__setattr__(self, "metrics", MappingProxyType(dict(self.metrics)))
        object.__setattr__(self, "codes", tuple(self.codes))


class _RowsHit(Hit):
    """An accepted Hit that holds its samples as channel rows (C, n).

    ``data`` (n, C) is made from the rows on first access (the checks and the
    FFT work on rows; :func:`guidefit.frf.compute_frf` uses ``_rows`` and
    never needs ``data``). The values are the same either way.
    """

    @property
    def data(self):
        data = self.__dict__.get("_data")
        if data is None and self.__dict__.get("_rows") is not None:
            data = np.ascontiguousarray(self._rows.T, dtype=np.float64)  # rows may be float32 (exact values)
            data.setflags(write=False)
            object.__setattr__(self, "_data", data)
        return data

    @data.setter
    def data(self, value):  # the dataclass __init__ sets data; rows come after
        self.__dict__["_data"] = value


def _hit_with_rows(run: str, index: int, rows: np.ndarray, peak, trigger, metrics) -> Hit:
    """An accepted stored hit whose data are ``rows.T`` (``rows`` then owned by the Hit)."""
    rows.setflags(write=False)
    hit = _RowsHit(run, index, 0, None, peak, True, None, trigger, (), metrics)
    object.__setattr__(hit, "_rows", rows)
    return hit



def summarise_hits(hits: Iterable[Hit]):
    """One row per hit as a pandas DataFrame (for tables and reports).

    Columns: ``run, index, start_sample, pretrigger_samples, peak_force_n,
    accepted, codes, reason, pulse_width_s, second_impact_ratio, end_ratio``.

    Examples
    --------
    >>> hit = Hit("vertical", 0, 0, None, 12.5, False, "too_weak: peak 12.5 N", codes=("too_weak",))
    >>> summarise_hits([hit])[["index", "accepted", "codes"]].to_dict("records")
    [{'index': 0, 'accepted': False, 'codes': 'too_weak'}]
    """
    import pandas as pd

    columns = [
        "run",
        "index",
        "start_sample",
        "pretrigger_samples",
        "peak_force_n",
        "accepted",
        "codes",
        "reason",
    ]
    rows = []
    for hit in hits:
        row = {
            "run": hit.run,
            "index": hit.index,
            "start_sample": hit.start_sample,
            "pretrigger_samples": hit.pretrigger_samples,
            "peak_force_n": hit.peak_force_n,
            "accepted": hit.accepted,
            "codes": ",".join(hit.codes),
            "reason": hit.reason,
        }
        row.update({k: hit.metrics.get(k, math.nan) for k in _METRICS})
        rows.append(row)
    return pd.DataFrame(rows, columns=columns + list(_METRICS))


# ------------------------------------------------------------------ checks


def check_hit(
    run: Run,
    data: np.ndarray,
    settings: HitSettings | None = None,
    *,
    index: int = 0,
    start_sample: int = 0,
    pretrigger_samples: int | None = None,
    median_peak_n: float | None = None,
) -> Hit:
    """Run the quality checks on one record of ``run`` and return the Hit.

    Parameters
    ----------
    run : Run
        Gives the channel names, the force column and the sample rate.
    data : ndarray, shape (n_samples, n_channels)
        float64 SI samples, as from :func:`guidefit.io.read_hit`.
    settings : HitSettings, optional
    index, start_sample : int
        Copied into the Hit.
    pretrigger_samples : int, optional
        Samples before the trigger; with 16 or more, the baseline and noise
        are taken from them, else the baseline is the record's median.
    median_peak_n : float, optional
        The run's median peak force, for the ``too_weak`` check.

    Returns
    -------
    Hit
    """
    settings = HitSettings() if settings is None else settings
    data = np.array(data, dtype=np.float64)  # a copy: the Hit's data is read-only
    if data.ndim != 2 or data.shape[1] != run.n_channels:
        raise ValueError(
            f"data has shape {data.shape}; expected (n_samples, {run.n_channels}) for run '{run.name}'"
        )
    return _check(run, data, settings, index, start_sample, pretrigger_samples, median_peak_n)


def _check(
    run, data, settings, index, start_sample, pretrigger_samples, median_peak_n, force_base=None
) -> Hit:
    """Assess ``data`` (float64, owned by the caller's new Hit) and build the Hit."""
    codes, reasons, peak, trigger, metrics = _assess(
        data, run, settings, pretrigger_samples, median_peak_n, force_base
    )
    if codes:
        return Hit(
            run.name,
            index,
            start_sample,
            None,
            peak,
            False,
            "; ".join(reasons),
            trigger,
            codes,
            metrics,
        )
    data.setflags(write=False)
    return Hit(run.name, index, start_sample, data, peak, True, None, trigger, (), metrics)


def _check_raw(
    run, raw, rows, scale, settings, index, pretrigger_samples, median_peak_n, force_base
) -> Hit:
    """Assess a stored hit read as stored (``raw``: (n, C), file units and dtype).

    The samples are converted once, to SI channel rows in ``rows`` (C, n):
    the layout the checks and the FFT work on; float32 when the stored
    samples are float32 and need no scaling (the same values), else float64. An accepted hit keeps
    them (its ``data`` is their transpose, made if asked for). ``scale`` is
    ``run.scale_to_si``, or None when every factor is 1; the values are those
    of :func:`guidefit.io.read_hit`.
    """
    extremes = _rows_from_raw(rows, raw, scale)
    codes, reasons, peak, trigger, metrics = _assess_rows(
        rows, run, settings, pretrigger_samples, median_peak_n, force_base, extremes
    )
    if codes:
        return Hit(
            run.name, index, 0, None, peak, False, "; ".join(reasons), trigger, codes, metrics
        )
    return _hit_with_rows(run.name, index, rows, peak, trigger, metrics)


# -------------------------------------------------------------- iteration


def iter_hits(
    run: Run, settings: HitSettings | None = None, *, chunk_samples: int = CHUNK_SAMPLES
) -> Iterator[Hit]:
    """The hits of a run, accepted and rejected, in order (bounded memory).

    Parameters
    ----------
    run : Run
        From :func:`guidefit.io.read_recording`.
    settings : HitSettings, optional
    chunk_samples : int
        Force samples read per step when scanning a ``signals`` run.

    Yields
    ------
    Hit
        All records of a run have the same length. A ``signals`` run without
        any trigger yields nothing.

    Raises
    ------
    HitSettingsError
        A setting that does not fit the run (e.g. a record longer than the
        stored hits).

    Examples
    --------
    >>> import os, tempfile
    >>> import numpy as np
    >>> from guidefit.io import RunData, read_recording, write_recording
    >>> fs = 200_000.0
    >>> t = np.arange(4000) / fs
    >>> force = np.where(t < 1e-4, 100 * np.sin(np.pi * t / 1e-4), 0.0)
    >>> acc = np.exp(-t / 2e-3) * np.sin(2 * np.pi * 3450 * t)
    >>> signals = np.zeros((20_000, 2))
    >>> for start in (1_000, 9_000, 15_000):
    ...     signals[start:start + 4000] += np.column_stack([force, acc])
    >>> run = RunData("vertical", fs, [0, -1, 0], ["force", "acc_A_y"], ["N", "m/s^2"],
    ...               [[0, 0, 0], [0.03, 0, 0.045]], [[0, -1, 0], [0, 1, 0]], data=signals)
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     write_recording(os.path.join(folder, "rec.h5"), run)
    ...     hits = list(iter_hits(read_recording(os.path.join(folder, "rec.h5")).runs[0]))
    >>> [(h.index, h.accepted, h.start_sample, h.data.shape) for h in hits]
    [(0, True, 801, (5199, 2)), (1, True, 8801, (5199, 2)), (2, True, 14801, (5199, 2))]

    The triggers are at samples 1001, 9001 and 15001 (5 % of the 100 N peak);
    records start 1 ms (200 samples) earlier and are as long as fits before
    the end of the signal.
    """
    settings = HitSettings() if settings is None else settings
    if not isinstance(settings, HitSettings):
        raise TypeError(f"settings: expected HitSettings, got {type(settings).__name__}")
    if not isinstance(chunk_samples, (int, np.integer)) or chunk_samples < 2:
        raise ValueError(f"chunk_samples={chunk_samples!r}: expected an integer >= 2")
    fs = run.sample_rate_hz
    if run.layout == "hits":
        length = run.n_samples
        if settings.record_length_s is not None:
            length = round(settings.record_length_s * fs)
            if not 2 <= length <= run.n_samples:
                raise HitSettingsError(
                    f"run '{run.name}': record_length_s {settings.record_length_s:g} s is {length} samples; "
                    f"the stored hits have {run.n_samples}"
                )
        return _stored_hits(run, settings, length)
    if (
        settings.record_length_s is not None
        and settings.pretrigger_s is not None
        and settings.pretrigger_s >= settings.record_length_s
    ):
        raise HitSettingsError(
            f"HitSettings: pretrigger_s ({settings.pretrigger_s:g}) must be shorter than "
            f"record_length_s ({settings.record_length_s:g})"
        )
    return _signal_hits(run, settings, int(chunk_samples))


def _force_peak(force: np.ndarray, pre: int | None):
    """(peak, baseline) of one stored hit's force (float64 SI): the peak is
    max |force - baseline| (None when no finite baseline exists: the hit adds
    no peak to the run's median), the baseline the median of the pretrigger
    or of all the force (None unless every sample is finite)."""
    hi, lo = float(force.max()), float(force.min())  # NaN if a NaN, +-Inf if an Inf
    if math.isfinite(hi) and math.isfinite(lo):
        median = _median(force[: pre - 2] if pre is not None and pre >= 16 else force)
        # max |force - median| from the extremes: rounding is monotone
        hi, lo = hi - median, lo - median
        return abs(hi if hi >= -lo else lo), median
    finite = np.isfinite(force)
    quiet = finite[: pre - 2] if pre is not None and pre >= 16 else finite
    base = force[: quiet.size][quiet]
    if base.size:
        return abs(_signed_extreme(force[finite] - _median(base))), None
    return None, None


def _median_upper_bound(ordered, n_unknown: int) -> float | None:
    """The largest ``np.median`` of the sorted values ``ordered`` plus up to
    ``n_unknown`` more values (each absent or anything): the median with
    ``n_unknown`` values of +inf. ``inf`` when the unknown could decide it;
    None when there is no value at all."""
    n = len(ordered) + n_unknown
    if n == 0:
        return None

    def at(k):
        return ordered[k] if k < len(ordered) else math.inf

    return float(at(n // 2)) if n % 2 else (at(n // 2 - 1) + at(n // 2)) / 2


def _partial_start(n_hits: int) -> int:
    """First hit of the first pass over the force: the last ``n_hits // 2 + 2`` hits,
    enough to bound the run's median peak from above before the first hit is judged."""
    return max(0, n_hits - (n_hits // 2 + 2))


def _stored_hits(run: Run, s: HitSettings, length: int) -> Iterator[Hit]:
    """Stored hits, judged in order, with the file open once.

    The ``too_weak`` check needs the run's median peak. A first pass reads the
    force of the last ``n_hits // 2 + 2`` hits; with those, and the peaks of
    the hits judged so far, the median of all peaks is bounded from above
    (:func:`_median_upper_bound`). A hit that is not too weak against the bound
    is not too weak against the median either (the limit grows with the
    median) and is judged exactly as with the median; only a hit that is too
    weak against the bound (or the first hit, if the bound is not finite yet)
    makes the force of the hits not read yet be read, and from then on the
    median is exact. So each hit's force is read about 1.5 times, not twice,
    and every decision, reason and metric is that of the median of all peaks.

    A run of at most ``_CACHE_BYTES`` (as float64) is read only once and
    kept; a larger one has its hits read in blocks of at most ``_READ_BYTES``
    (as float64) for the force. Samples are read as stored and converted to
    float64 SI once, straight into the layout each pass works on (see
    :func:`_check_raw`)."""
    fi = run.force_index
    pre = run.pretrigger_samples
    n_hits = run.n_hits_stored
    if n_hits == 0:
        return
    scale = np.asarray(run.scale_to_si, dtype=np.float64)
    scale = scale if np.any(scale != 1.0) else None
    with open_reader(run) as reader:
        n_channels = run.n_channels
        # float32 samples that need no scaling stay float32 in the rows: the same values, half the memory
        # traffic of every check and of the windowing (a tenth of identify's time); else float64 SI
        rows_dtype = np.float32 if scale is None and np.dtype(reader.dtype) == np.float32 else np.float64
        cache = None
        if n_hits * length * n_channels * 8 <= _CACHE_BYTES:
            cache = reader.read_hits_raw(0, n_hits, length)
            per, block = n_hits, None
        else:
            per = min(n_hits, max(1, _READ_BYTES // (8 * length * n_channels)))
            block = np.empty((per, length, n_channels), dtype=reader.dtype)
        peaks: dict[int, float] = {}  # hit -> peak (a hit without a finite baseline has none)
        bases = [None] * n_hits  # force baseline of each all-finite force, reused below
        forces = np.empty((min(per, n_hits), length))

        def force_pass(h0: int, h1: int) -> None:
            """Peaks and baselines of hits h0..h1-1 from their forces."""
            for i0 in range(h0, h1, per):
                i1 = min(h1, i0 + per)
                raw = cache[i0:i1] if cache is not None else reader.read_hits_raw(
                    i0, i1, length, out=block[: i1 - i0])
                force_rows = forces[: i1 - i0]
                np.copyto(force_rows, raw[:, :, fi])
                if scale is not None:
                    force_rows *= scale[fi]
                for k, force in enumerate(force_rows):
                    peak, bases[i0 + k] = _force_peak(force, pre)
                    if peak is not None:
                        peaks[i0 + k] = peak

        def exact_median() -> float | None:
            return float(np.median(list(peaks.values()))) if peaks else None

        first_read = 0 if cache is not None else _partial_start(n_hits)
        force_pass(first_read, n_hits)
        exact = first_read == 0  # False: the median is only bounded so far
        median = exact_median() if exact else None
        ordered = sorted(peaks.values())  # the known peaks, for the bound
        own = np.empty((1, length))  # the force of the hit being judged
        one = None if cache is not None else np.empty((1, length, n_channels), dtype=reader.dtype)
        spare: list[np.ndarray] = []  # rows of earlier hits, reused once nothing else holds them
        for i in range(n_hits):
            raw = cache[i] if cache is not None else reader.read_hits_raw(i, i + 1, length, out=one)[0]
            if not exact:
                if i < first_read:  # this hit's own peak, as the first pass takes it
                    np.copyto(own[0], raw[:, fi])
                    if scale is not None:
                        own *= scale[fi]
                    peak, bases[i] = _force_peak(own[0], pre)
                    if peak is not None:
                        peaks[i] = peak
                        bisect.insort(ordered, peak)
                unknown = first_read - i - 1  # hits whose force has not been read
                bound = _median_upper_bound(ordered, unknown) if unknown > 0 else None
                if bound is not None and math.isfinite(bound):
                    hit = _check_raw(run, raw, _rows_buffer(spare, (n_channels, length), rows_dtype), scale, s,
                                     i, pre, bound, bases[i])
                    if "too_weak" not in hit.codes:
                        yield hit
                        continue
                    del hit
                force_pass(i + 1, first_read)  # the rest of the force (if any): the exact median
                median, exact = exact_median(), True
            yield _check_raw(run, raw, _rows_buffer(spare, (n_channels, length), rows_dtype), scale, s, i,
                             pre, median, bases[i])


def _rows_buffer(spare: list, shape: tuple[int, int], dtype=np.float64) -> np.ndarray:
    """An array of ``shape`` and ``dtype`` for a hit's rows: one of ``spare`` that only
    ``spare`` still references (its Hit and every view of it are gone), else a
    new one, kept in ``spare`` (at most 3). Reusing memory that is already
    mapped saves first-touch page faults: a new 4 MB array costs about 1000."""
    import sys

    for rows in spare:
        if sys.getrefcount(rows) == 3 and rows.dtype == dtype:  # ``spare``, ``rows`` and the argument
            rows.setflags(write=True)
            return rows
    rows = np.empty(shape, dtype=dtype)
    if len(spare) < 3:
        spare.append(rows)
    return rows


def _force_stats(run: Run, chunk: int, reader) -> tuple[float, float, float]:
    """(mean, max, min) of the finite force samples (not corrupt ones, beyond 1e100), streamed."""
    total, count = 0.0, 0
    hi, lo = -math.inf, math.inf
    for start in range(0, run.n_samples, chunk):
        f = reader.read_block(start, min(run.n_samples, start + chunk), [run.force_index])[:, 0]
        f = f[np.abs(f) < _ABSURD_SAMPLE]
        if f.size:
            total += float(np.sum(f))
            count += f.size
            hi, lo = max(hi, float(f.max())), min(lo, float(f.min()))
    if count == 0:
        return math.nan, math.nan, math.nan
    return total / count, hi, lo


def _find_triggers(run: Run, level: float, offset: float, holdoff: int, chunk: int, reader):
    """Trigger samples and the signed peak of ``f - offset`` in each hold-off window."""
    triggers: list[int] = []
    peaks: list[float] = []
    windows: list[list] = []  # [index into triggers, end sample, hi, lo]
    previous_above = False
    next_allowed = 0
    n = run.n_samples
    for start in range(0, n, chunk):
        stop = min(n, start + chunk)
        x = reader.read_block(start, stop, [run.force_index])[:, 0] - offset
        with np.errstate(invalid="ignore"):
            # a corrupt force sample (NaN, Inf, beyond 1e100) may hide an impact: it opens a window as one,
            # so the record around it is read and rejected as non_finite (else that hit vanished unnamed)
            above = ~(np.abs(x) < _ABSURD_SAMPLE) | (np.abs(x) >= level)
        before = np.empty_like(above)
        before[0] = previous_above
        before[1:] = above[:-1]
        previous_above = bool(above[-1])
        for r in np.flatnonzero(above & ~before) + start:
            if r >= next_allowed:
                triggers.append(int(r))
                peaks.append(math.nan)
                windows.append([len(triggers) - 1, int(r) + holdoff, -math.inf, math.inf])
                next_allowed = int(r) + holdoff
        still_open = []
        for w in windows:
            k, end = w[0], w[1]
            a = max(triggers[k], start) - start
            b = min(end, stop) - start
            if b > a:
                seg = x[a:b]
                seg = seg[np.isfinite(seg)]
                if seg.size:
                    w[2], w[3] = max(w[2], float(seg.max())), min(w[3], float(seg.min()))
            if end <= stop:
                peaks[k] = w[2] if w[2] >= -w[3] else w[3]
            else:
                still_open.append(w)
        windows = still_open
    for w in windows:
        peaks[w[0]] = w[2] if w[2] >= -w[3] else w[3]
    return triggers, [p if math.isfinite(p) else math.nan for p in peaks]


def _signal_hits(run: Run, s: HitSettings, chunk: int) -> Iterator[Hit]:
    with open_reader(run) as reader:  # one open file for all the reads
        yield from _signal_hits_read(run, s, chunk, reader)


def _signal_hits_read(run: Run, s: HitSettings, chunk: int, reader) -> Iterator[Hit]:
    fs = run.sample_rate_hz
    n = run.n_samples
    offset, hi, lo = _force_stats(run, chunk, reader)
    if not math.isfinite(offset):
        return
    level = (
        s.trigger_level_n
        if s.trigger_level_n is not None
        else s.trigger_fraction * max(hi - offset, offset - lo)
    )
    if not level > 0:
        return
    holdoff = max(1, round(s.holdoff_s * fs))
    triggers, peaks = _find_triggers(run, level, offset, holdoff, chunk, reader)
    if not triggers:
        return
    if s.pretrigger_s is not None:
        pre = round(s.pretrigger_s * fs)
    elif run.pretrigger_samples is not None:
        pre = run.pretrigger_samples
    else:
        pre = max(1, min(round(DEFAULT_PRETRIGGER_S * fs), triggers[0]))
    if s.record_length_s is not None:
        length = round(s.record_length_s * fs)
    else:
        length = round(s.max_record_length_s * fs)
        gaps = np.diff(triggers)
        if gaps.size:
            regular = gaps[gaps >= 0.5 * np.median(gaps)]
            length = min(length, int(regular.min()))
        available = n - (triggers[-1] - pre)
        if (length / 2 <= available or not gaps.size) and available < length:  # one hit: the rest of the signal
            length = available
    length = max(length, pre + 1)
    finite_peaks = [abs(p) for p in peaks if math.isfinite(p)]
    median_peak = float(np.median(finite_peaks)) if finite_peaks else None
    for k, trigger in enumerate(triggers):
        start = trigger - pre
        stop = start + length
        reason = code = None
        if start < 0:
            code = "incomplete"
            reason = f"incomplete: the record would start {-start} samples before the signal (pretrigger {pre})"
        elif stop > n:
            code = "incomplete"
            reason = f"incomplete: the record would end {stop - n} samples after the signal ({length} needed)"
        elif k > 0 and trigger - triggers[k - 1] < length:
            code = "overlap"
            gap_ms = (trigger - triggers[k - 1]) / fs * 1e3
            reason = (
                f"overlap: hit {k - 1} came only {gap_ms:.3g} ms earlier, inside this record "
                f"({length / fs * 1e3:.3g} ms)"
            )
        if code:
            yield Hit(
                run.name,
                k,
                start,
                None,
                peaks[k],
                False,
                reason,
                pre,
                (code,),
                dict.fromkeys(_METRICS, math.nan),
            )
            continue
        data = reader.read_block(start, stop)
        yield _check(run, data, s, k, start, pre, median_peak)
