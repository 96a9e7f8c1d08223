"""The FRF engine: windowed records in, per-group spectral sums out (streamed, threaded).

Hits are pulled from an iterator a few at a time, windowed into block
buffers, transformed with :mod:`scipy.fft` on helper threads and their auto-
and cross-spectra added to per-group sums (the jackknife groups), block after
block in hit order so that the result does not depend on the threads. The
estimators, :class:`guidefit.frf.FrfSet` and the entrances
(:func:`guidefit.frf.compute_frf`, :func:`guidefit.frf.frf_from_records`) are
in :mod:`guidefit.frf`, whose module docstring explains speed, memory and
precision; every public name here is also importable from there.
"""

from __future__ import annotations

import threading
from collections.abc import Iterable, Iterator

import numpy as np

from guidefit.errors import IdentificationError, RecordingError
from guidefit.frf.windows import _force_offset

#: Default number of jackknife groups (fewer when there are fewer hits).
DEFAULT_GROUPS = 8

#: Default windows are chosen from the first (up to) this many records, at most
#: ``_WINDOW_BYTES`` of them (as float64), at least one.
_WINDOW_HITS = 4
_WINDOW_BYTES = 64 * 2**20
#: Hits per FFT call are limited so that one block of input stays below this size.
_BLOCK_BYTES = 16 * 2**20
_MAX_BLOCK_HITS = 2
#: Frequency bins per chunk of the spectral products (keeps temporaries in cache).
_CHUNK_BINS = 16384
#: FFT precisions: ``"auto"`` (that of the stored samples), ``"single"``, ``"double"``.
PRECISIONS = ("auto", "single", "double")


def fft_dtype(precision: str = "auto", sample_dtype=np.float64) -> type:
    """The real dtype the FFTs compute in: ``numpy.float32`` or ``numpy.float64``.

    ``"auto"``: single precision when the stored samples carry no more than
    float32's 24-bit significand (float16 and float32, integers of at most
    16 bits), else double. See "Precision" in the module docstring.

    Examples
    --------
    >>> import numpy as np
    >>> [fft_dtype("auto", d).__name__ for d in (np.float32, np.int16, np.int32, np.float64)]
    ['float32', 'float32', 'float64', 'float64']
    >>> fft_dtype("double", np.float32).__name__
    'float64'
    """
    if precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {', '.join(PRECISIONS)}; got {precision!r}")
    if precision == "auto":
        dt = np.dtype(sample_dtype)
        narrow = (dt.kind == "f" and dt.itemsize <= 4) or (dt.kind in "iub" and dt.itemsize <= 2)
        return np.float32 if narrow else np.float64
    return np.float32 if precision == "single" else np.float64


def _precision_name(dtype) -> str:
    return "single" if np.dtype(dtype) == np.float32 else "double"



def _group_runs(i0: int, n: int, n_groups: int, pair: int = 1):
    """Split hits i0..i0+n-1 into runs (j0, j1, g0): hit i goes to group
    ``(i // pair) % n_groups``; with ``pair=1`` a run is consecutive hits in
    consecutive, distinct groups, with ``pair=2`` one or two hits of one group."""
    j = 0
    while j < n:
        if pair == 1:
            g0 = (i0 + j) % n_groups
            m = min(n - j, n_groups - g0)
        else:
            g0 = ((i0 + j) // pair) % n_groups
            m = min(n - j, pair - (i0 + j) % pair)
        yield j, j + m, g0
        j += m


#: Runs of at least this many stored hits per jackknife group put two consecutive hits
#: in each group (``pair=2``): every group still gets hits, and the group sums, the
#: largest memory traffic of the engine, are read and written once per two hits.
PAIR_HITS_PER_GROUP = 4


def _response_index(force_index: int, n_channels: int):
    """Index of the response channels: a slice when they are contiguous."""
    if force_index == 0:
        return slice(1, n_channels)
    if force_index == n_channels - 1:
        return slice(0, n_channels - 1)
    return np.array([k for k in range(n_channels) if k != force_index])


class _Accumulator:
    """Per-group spectral sums; blocks of windowed records in, sums out.

    Internal layout is (G, R, F) (frequency contiguous, matching the FFT output);
    :meth:`group_sums` exposes (G, F, R) views.
    """

    def __init__(self, n_samples, n_channels, force_index, n_groups, workers, pair=1, n_bins=None, n_fft=None):
        self.n = n_samples
        self.n_fft = n_samples if n_fft is None else int(n_fft)  # > n_samples: zero-padded FFTs
        self.c = n_channels
        self.fi = force_index
        self.n_groups = n_groups
        self.pair = pair
        self.workers = workers
        every = self.n_fft // 2 + 1
        self.F = every if n_bins is None else min(every, n_bins)
        self.resp = _response_index(force_index, n_channels)
        r = n_channels - 1
        self.sff = np.zeros((n_groups, self.F))
        self.sxx = np.zeros((n_groups, r, self.F))
        self.sfx = np.zeros((n_groups, r, self.F), dtype=complex)
        self.counts = np.zeros(n_groups, dtype=np.int64)
        self.n_hits = 0
        self._bufs = None

    def add(self, Z: np.ndarray, i0: int) -> None:
        """Add the spectra ``Z`` (n, C, >= F) of hits i0..i0+n-1 (their first F bins)."""
        n = Z.shape[0]
        ch = min(_CHUNK_BINS, self.F)
        if self._bufs is None or self._bufs[0].shape[0] < n:
            r = self.c - 1
            self._bufs = (np.empty((n, self.c, ch)), np.empty((n, self.c, ch)),
                          np.empty((n, ch), dtype=complex), np.empty((n, r, ch), dtype=complex),
                          np.empty((n, self.c, ch), dtype=complex))
        sq, tmp, fcb, pcb, up = self._bufs
        single = Z.dtype != np.complex128  # complex64 spectra: products and sums in float64
        runs = list(_group_runs(i0, n, self.n_groups, self.pair))
        fi, resp = self.fi, self.resp
        for a in range(0, self.F, ch):
            b = min(a + ch, self.F)
            m = b - a
            z = Z[:, :, a:b]
            if single:
                z = np.copyto(up[:n, :, :m], z) or up[:n, :, :m]
            s, t = sq[:n, :, :m], tmp[:n, :, :m]
            np.multiply(z.real, z.real, out=s)
            np.multiply(z.imag, z.imag, out=t)
            s += t
            fc = fcb[:n, :m]
            np.conjugate(z[:, fi], out=fc)
            p = pcb[:n, :, :m]
            np.multiply(z[:, resp], fc[:, None, :], out=p)
            if self.pair == 1:
                for j0, j1, g0 in runs:
                    g1 = g0 + j1 - j0
                    self.sff[g0:g1, a:b] += s[j0:j1, fi]
                    self.sxx[g0:g1, :, a:b] += s[j0:j1, resp]
                    self.sfx[g0:g1, :, a:b] += p[j0:j1]
                continue
            for j0, j1, g0 in runs:  # one group per run: its hits summed here, then added once
                for j in range(j0 + 1, j1):
                    s[j0] += s[j]
                    p[j0] += p[j]
                self.sff[g0, a:b] += s[j0, fi]
                self.sxx[g0, :, a:b] += s[j0, resp]
                self.sfx[g0, :, a:b] += p[j0]
        for j0, j1, g0 in runs:
            if self.pair == 1:
                self.counts[g0:g0 + j1 - j0] += 1
            else:
                self.counts[g0] += j1 - j0

    def group_sums(self) -> dict:
        g = min(self.n_groups, -(-self.n_hits // self.pair))  # the groups that got a hit
        return {
            "Sff": _readonly(self.sff[:g]),
            "Sxx": _readonly(self.sxx[:g].transpose(0, 2, 1)),
            "Sfx": _readonly(self.sfx[:g].transpose(0, 2, 1)),
            "n_hits": _readonly(self.counts[:g].copy()),
        }


class _Buffers:
    """The memory of one :func:`_run_blocks` call: sums, block buffers, first records.

    ``touch``: write every page now (the first touch of fresh memory costs a
    page fault per 4 kB, about 60 MB here), so that a thread with nothing
    else to do can pay for it while another one reads the first pass over
    the force.
    """

    def __init__(self, n, c, dtype, force_index, n_groups, workers, pair=1, touch=False, n_bins=None, n_fft=None):
        self.key = (n, c, np.dtype(dtype), force_index, n_groups, workers, pair, n_bins, n_fft)
        self.n_first = max(1, min(_WINDOW_HITS, _WINDOW_BYTES // (8 * n * c)))
        self.block = _block_size(n, c)
        self.n_bufs = workers + 1 if workers > 1 else 1  # one being filled, one per helper, one queued
        if dtype == np.float64:  # the first records straight into the block buffers
            self.space = np.empty((max(self.n_bufs * self.block, self.n_first), c, n))
            self.first = self.space[:self.n_first]
        else:  # the windows are chosen from float64 copies, then rounded into the buffers
            self.first = np.empty((self.n_first, c, n))
            self.space = np.empty((self.n_bufs * self.block, c, n), dtype=dtype)
        self.acc = _Accumulator(n, c, force_index, n_groups, workers, pair, n_bins, n_fft)
        if touch:
            for a in (self.space, self.first, self.acc.sff, self.acc.sxx, self.acc.sfx):
                a.fill(0)


def _early_buffers(expect, precision, force_index, n_groups, workers, pair=1, n_bins=None, n_fft=None):
    """:class:`_Buffers` for records of shape ``expect`` (n_samples, n_channels), made and
    touched by a thread of their own while the caller goes on; ``None`` when there is
    nothing to expect or no second thread. ``.result()`` waits for them."""
    if expect is None or workers < 2:
        return None
    from concurrent.futures import ThreadPoolExecutor

    n, c = (int(v) for v in expect)
    pool = ThreadPoolExecutor(max_workers=1)
    length = _fft_length(n, n_fft)
    future = pool.submit(_Buffers, n, c, fft_dtype(precision), force_index, n_groups, workers, pair,
                         True, None if n_bins is None else n_bins(length), n_fft)
    pool.shutdown(wait=False)  # the thread ends with the job
    return future


def _run_blocks(items: Iterator[tuple[str, np.ndarray]], force_index: int, windows,
                n_groups: int, workers: int, force_offset: bool = False,
                precision: str = "auto", expect=None, pair: int = 1, n_bins=None,
                n_fft: int | None = None) -> _Accumulator | None:
    """Window, FFT and accumulate all records, a few hits per FFT call.

    ``windows(first)`` gets the first (up to ``_WINDOW_HITS``) raw records as
    (hits, C, n_samples) rows and returns ``(w_force, w_response)``. Every
    record is multiplied by them while being copied, transposed, into a block
    buffer (FFTs along contiguous rows are faster than along axis 0 of
    (n_samples, C) records; a record that is the transpose of contiguous rows,
    as hits from :func:`guidefit.hits.iter_hits` give, is multiplied row by row).

    ``workers`` threads in all: the calling thread pulls the records from
    ``items`` (for hits: reads and checks them) and windows them into a block
    buffer; ``workers - 1`` helper threads transform the blocks and add their
    spectra to the sums (``scipy.fft`` and numpy's ufuncs release the GIL, so
    this overlaps the reading and checking). When the helpers fall behind (a
    block waits for one), the calling thread transforms its next block
    itself, so that neither side idles while the other has work. With ``workers=1`` everything
    runs on the calling thread. The sums are added block after block in hit
    order, so the result does not depend on the number of threads or their
    timing. Returns ``None`` when there is no record. ``force_offset``:
    remove each record's force offset (its median where the force window is
    0, see :func:`_force_offset`). ``precision``: of the block buffers and
    FFTs (:func:`fft_dtype`; ``"auto"`` from the first record's dtype); the
    windows are chosen and multiplied in float64 either way, and the product
    rounded once into the block buffer. ``expect``: the (n_samples,
    n_channels) the records will have, if known: their memory is then made
    by another thread while the first record is pulled (for stored hits,
    while the first pass reads the force of the hits). ``pair``: hits per
    group turn (see :data:`PAIR_HITS_PER_GROUP`). ``n_bins``: None (every bin),
    or a function of the FFT length giving how many of the first bins to sum
    (the FFT is whole either way; the bins above are not summed). ``n_fft``:
    None (an FFT of the record's length), or a longer FFT: every windowed
    record zero-padded to ``n_fft`` samples (a finer bin spacing,
    ``fs / n_fft``; see "Common grid" in :mod:`guidefit.frf`).
    """
    source = iter(items)
    # the early buffers are passed on, not kept here: once the first records are in them, the future
    # holding them must go, or it keeps the first records' memory alive
    pulled = _pull_first(source, _early_buffers(expect, precision, force_index, n_groups, workers, pair, n_bins,
                                                n_fft),
                         precision, force_index, n_groups, workers, pair, n_bins, n_fft)
    if pulled is None:
        return None
    space, first, acc, n_bufs, block = pulled
    del pulled
    c, n = first.shape[1:]
    k = first.shape[0]
    window_rows, quiet = _window_first(first, windows, force_index, force_offset)
    if space.shape[0] > n_bufs * block:  # the first records did not fit in the buffers
        space = np.empty((n_bufs * block, c, n))
    elif first.base is space:  # already in place in the buffers
        first = None
    bufs = [space[i * block:(i + 1) * block] for i in range(n_bufs)]
    acc.precision = _precision_name(space.dtype)
    del space
    # the filler holds the only reference to the first records, and drops it once they are in a block
    fill = _block_filler(source, bufs, first, k, window_rows, quiet, force_index)
    del first
    return _transform_blocks(fill, bufs, acc, workers - 1)


def _pull_first(source, early, precision, force_index, n_groups, workers, pair, n_bins, n_fft=None):
    """The first (up to ``_WINDOW_HITS``) records of ``source``, copied transposed into the memory
    of a :class:`_Buffers` (``early``'s when it fits them, else new).

    Returns ``(space, first, acc, n_bufs, block)``: the block buffers' memory, the first records
    ``(hits, C, n)`` (a view into ``space`` when they fit in it), the accumulator and the buffers'
    count and size; ``None`` when ``source`` holds no record.
    """
    first = None  # the first records, (hits, C, n); in the block buffers when they fit
    k = 0
    for _, record in source:
        if first is None:
            n, c = record.shape
            dtype = fft_dtype(precision, record.dtype)
            length = _fft_length(n, n_fft)  # checked: no shorter than the records
            kept = None if n_bins is None else n_bins(length)
            key = (n, c, np.dtype(dtype), force_index, n_groups, workers, pair, kept, n_fft)
            mem = early.result() if early is not None else None
            if mem is None or mem.key != key:
                mem = _Buffers(n, c, dtype, force_index, n_groups, workers, pair, n_bins=kept, n_fft=n_fft)
            early = None
            n_first, block, n_bufs = mem.n_first, mem.block, mem.n_bufs
            space, first, acc = mem.space, mem.first, mem.acc
            del mem
        np.copyto(first[k], record.T)
        k += 1
        if k == n_first:
            break
    if first is None:
        return None
    return space, first[:k], acc, n_bufs, block


def _window_first(first, windows, fi, force_offset):
    """Choose the windows from the first records and apply them (and the force offset) in place.

    Returns ``(window_rows, quiet)``: the window row of each channel, ``(n,)`` views, and the
    quiet samples after the force window whose median is the force's offset (``None`` without
    ``force_offset`` or with fewer than 16 of them), see :func:`_force_offset`.
    """
    c = first.shape[1]
    w_force, w_resp = windows(first)
    w_pair = (np.array(w_force, dtype=float), np.array(w_resp, dtype=float))  # (n,) each
    window_rows = [w_pair[0] if ch == fi else w_pair[1] for ch in range(c)]  # views, per channel
    window_t = np.stack(window_rows)  # (C, n), for the first records only
    # a hammer pushes nothing after the force window: the force there is the sensor's offset
    quiet = np.flatnonzero(window_t[fi] == 0.0)[-512:] if force_offset else np.empty(0)
    quiet = quiet if quiet.size >= 16 else None  # the last <= 512 quiet samples: plenty, cheap
    if quiet is not None:
        for j in range(first.shape[0]):
            first[j, fi] -= _force_offset(first[j, fi, quiet], first[j, fi])
    first *= window_t
    return window_rows, quiet


def _window_span(window: np.ndarray) -> tuple[int, int, np.ndarray | None]:
    """``(a, b, w)``: the window ``window`` (n,) is 0 outside samples ``a:b``, and ``w`` is it there;
    ``w`` None when it is 1 at every sample (a = 0, b = n). See :func:`_windowed_into`."""
    n = window.size
    nonzero = np.flatnonzero(window)
    if nonzero.size == 0:
        return 0, 0, window[:0]
    a, b = int(nonzero[0]), int(nonzero[-1]) + 1
    if a == 0 and b == n and bool(np.all(window == 1.0)):
        return 0, n, None
    return a, b, window[a:b]


def _windowed_into(out: np.ndarray, row: np.ndarray, a: int, b: int, w: np.ndarray | None) -> None:
    """``out[:] = row * window`` for the window of :func:`_window_span` ``(a, b, w)``, the same
    values: a copy where it is 1 throughout, zeros where it is 0 (a force window is 0 past the
    pulse, most of the record), so that a float32 record is multiplied by the float64 window
    (the slow mixed-type loop) only where it must be."""
    if w is None:
        np.copyto(out, row)
        return
    np.multiply(row[a:b], w, out=out[a:b])
    out[:a] = 0.0
    out[b:] = 0.0


def _block_filler(source, bufs, first, ready, window_rows, quiet, fi):
    """``fill(turn)``: windowed records into ``bufs[turn]`` (block, C, n); returns how many.

    The ``ready`` windowed first records come first (copied from ``first``, or in place already
    when ``first`` is None), then the records still in ``source``, each multiplied row by row by
    its channel's window while being copied (and its force offset removed with ``quiet``).
    """
    block, c = bufs[0].shape[:2]
    plan = [_window_span(w) for w in window_rows]

    def fill(turn: int) -> int:
        """Windowed records into ``bufs[turn]`` (block, C, n); how many."""
        nonlocal ready, first
        buf = bufs[turn]
        k = 0
        if ready:  # the first records: in place already, or copied from ``first``
            k = min(block, ready)
            if first is not None:
                done = first.shape[0] - ready
                np.copyto(buf[:k], first[done:done + k])
            ready -= k
            if not ready:
                first = None
        if k < block:
            for _, record in source:
                rows = record.T
                for ch in range(c):  # row by row: the two window rows stay in cache
                    _windowed_into(buf[k, ch], rows[ch], *plan[ch])
                if quiet is not None:  # force offset (sensor bias): out of the windowed force
                    a, b, w = plan[fi]
                    pulse = buf[k, fi, a:b]  # the window is 0 outside: nothing to take off there
                    offset = _force_offset(record[quiet, fi], pulse) if b > a else 0.0
                    if offset:
                        pulse -= offset if w is None else offset * w
                del record, rows  # the hit's buffer may be reused (guidefit.hits._rows_buffer)
                k += 1
                if k == block:
                    break
        return k

    return fill


def _transform_blocks(fill, bufs, acc: _Accumulator, helpers: int) -> _Accumulator:
    """Fill, FFT and add the blocks in turn until ``fill`` runs dry; ``helpers`` threads besides
    the calling one transform (see :func:`_run_blocks`). The spectra are added in block order."""
    from concurrent.futures import ThreadPoolExecutor

    import scipy.fft

    n_bufs = len(bufs)
    block = bufs[0].shape[0]
    free = [threading.Event() for _ in range(n_bufs)]  # set: the buffer may be refilled
    for event in free:
        event.set()
    # spectra of transformed blocks wait here, by block number, to be added in order
    transformed: dict[int, tuple[np.ndarray, int]] = {}
    state = {"next": 0}  # the block to add next
    adding = threading.Lock()  # held while adding: one thread at a time, in order

    def add_ready(wait: bool) -> None:
        """Add the transformed blocks that are next in order (``wait``: for the lock)."""
        if not adding.acquire(blocking=wait):
            return  # another thread is adding; it takes the ready blocks too
        try:
            while state["next"] in transformed:
                acc.add(*transformed.pop(state["next"]))
                state["next"] += 1
        finally:
            adding.release()

    def transform(turn: int, k: int, i0: int, number: int) -> None:
        try:
            Z = scipy.fft.rfft(bufs[turn][:k], n=acc.n_fft, axis=-1, workers=1)
        finally:
            free[turn].set()
        transformed[number] = (Z, i0)
        add_ready(wait=False)

    with ThreadPoolExecutor(max_workers=helpers) if helpers else _NullExecutor() as pool:
        futures = []
        number = 0
        turn = 0
        while True:
            if not free[turn].is_set():
                add_ready(wait=False)  # rather than wait idle: add what a helper transformed
                free[turn].wait()
            if len(transformed) > n_bufs:  # bound the spectra waiting to be added
                add_ready(wait=True)
            k = fill(turn)
            if k == 0:
                break
            free[turn].clear()
            for future in [f for f in futures if f.done()]:
                future.result()  # re-raises a helper's error
                futures.remove(future)
            if any(not (f.running() or f.done()) for f in futures):
                transform(turn, k, acc.n_hits, number)  # the helpers are behind: this block here
            else:
                futures.append(pool.submit(transform, turn, k, acc.n_hits, number))
            number += 1
            acc.n_hits += k
            turn = (turn + 1) % n_bufs
            if k < block:
                break
        for future in futures:
            future.result()
        add_ready(wait=True)
    if state["next"] != number:  # cannot happen unless a block was lost
        raise RuntimeError(f"frf: {number - state['next']} transformed block(s) not added")
    return acc


class _NullExecutor:
    """Synchronous stand-in for a ThreadPoolExecutor (``workers=1``)."""

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def submit(self, fn, *args):
        class _Done:
            def __init__(self, value):
                self.value = value

            def result(self):
                return self.value

            def done(self):
                return True

        return _Done(fn(*args))


def _validated(items: Iterable[tuple[str, np.ndarray]], run: str,
               n_channels: int | None) -> Iterator[tuple[str, np.ndarray]]:
    """Yield (label, 2-D array) checking that every record has the first one's shape."""
    shape = None
    first_label = None
    for label, data in items:
        data = np.asarray(data)
        if data.ndim != 2:
            raise RecordingError(
                f"run '{run}': hit {label} data has shape {data.shape}, "
                "expected (n_samples, n_channels)"
            )
        if shape is None:
            shape, first_label = data.shape, label
            if n_channels is not None and data.shape[1] != n_channels:
                raise RecordingError(
                    f"run '{run}': hit {label} has {data.shape[1]} channels, "
                    f"the run declares {n_channels}"
                )
            if shape[0] < 2 or shape[1] < 2:
                raise RecordingError(
                    f"run '{run}': hit {label} has shape {shape}; need >= 2 samples "
                    "and a force plus >= 1 response channel"
                )
        elif data.shape != shape:
            raise RecordingError(
                f"run '{run}': hit {label} has {data.shape[0]} samples x {data.shape[1]} "
                f"channels, expected {shape[0]} x {shape[1]} as hit {first_label}"
            )
        yield label, data


def _fft_length(n_samples: int, n_fft: int | None) -> int:
    """The FFT length of records of ``n_samples``: ``n_fft`` (zero padding), or the record's own."""
    if n_fft is None:
        return n_samples
    if int(n_fft) < n_samples:
        raise ValueError(f"n_fft={n_fft} is shorter than the records ({n_samples} samples); "
                         "zero padding only lengthens them")
    return int(n_fft)


def _labelled(records) -> Iterator[tuple[str, np.ndarray]]:
    if isinstance(records, np.ndarray) and records.ndim == 3:
        records = iter(records)
    for i, data in enumerate(records):
        yield str(i), data


def _block_size(n_samples: int, n_channels: int) -> int:
    return max(1, min(_MAX_BLOCK_HITS, _BLOCK_BYTES // (8 * n_samples * n_channels)))


def spectral_sums(
    records,
    force_index: int,
    w_force,
    w_response,
    n_groups: int = DEFAULT_GROUPS,
    workers: int = 2,
    precision: str = "auto",
) -> dict:
    """Per-group spectral sums of windowed records (the core under every FRF here).

    Parameters
    ----------
    records : array_like (n_hits, n_samples, n_channels) or iterable of (n_samples, n_channels)
        Hit records; an iterable is consumed a few records at a time.
    force_index : int
        Column of the force channel; every other column is a response.
    w_force, w_response : array_like, shape (n_samples,)
        Windows multiplied onto the force and onto every response channel.
    n_groups : int
        Hit ``i`` goes to group ``i % n_groups``; groups that got no hit (fewer
        hits than groups) are dropped.
    workers : int
        Threads in all: with more than one, ``workers - 1`` helper threads
        transform the blocks and accumulate their spectra while the calling
        thread windows the next records (and, for hits, reads and checks
        them). The result is the same for any number.
    precision : {"auto", "single", "double"}
        Of the FFTs (:func:`fft_dtype`); ``"auto"``: single for float32
        records, else double. The sums are float64 either way.

    Returns
    -------
    dict
        ``Sff`` (G, F) float, ``Sxx`` (G, F, R) float, ``Sfx`` (G, F, R) complex,
        ``n_hits`` (G,) int: unscaled sums of :math:`|F|^2`, :math:`|X|^2`,
        :math:`\\overline{F} X` of the DFTs (``scipy.fft.rfft``) of the windowed
        records; F = n_samples // 2 + 1.

    Raises
    ------
    RecordingError
        A record whose shape differs from the first one's.

    Examples
    --------
    >>> import numpy as np
    >>> rec = np.zeros((3, 8, 2)); rec[:, 0, 0] = 1.0; rec[:, 1, 1] = 2.0
    >>> s = spectral_sums(rec, 0, np.ones(8), np.ones(8), n_groups=2)
    >>> s["Sff"].shape, s["Sfx"].shape, s["n_hits"].tolist()
    ((2, 5), (2, 5, 1), [2, 1])
    >>> bool(np.isclose(s["Sfx"][0, 2, 0], -4j))   # 2 hits * conj(1) * 2 exp(-2j pi 2/8)
    True
    """
    n_groups = _check_groups(n_groups)
    fft_dtype(precision)  # checked before any record is read
    items = _validated(_labelled(records), "records", None)
    acc = _run_blocks(_checked_force(items, force_index, "records"), force_index,
                      lambda block: (w_force, w_response), n_groups, max(1, int(workers)),
                      precision=precision)
    if acc is None:
        raise IdentificationError("records: no record to average")
    return acc.group_sums()


def _check_groups(n_groups) -> int:
    if int(n_groups) != n_groups or n_groups < 1:
        raise ValueError(f"n_groups must be an integer >= 1, got {n_groups!r}")
    return int(n_groups)


def _checked_force(items, force_index: int, run: str):
    """Pass records through, checking ``force_index`` against the first one."""
    for k, item in enumerate(items):
        if k == 0:
            c = item[1].shape[1]
            if not 0 <= force_index < c:
                raise RecordingError(
                    f"run '{run}': force_index {force_index} out of range for {c} channels"
                )
        yield item


def _readonly(a: np.ndarray) -> np.ndarray:
    a.flags.writeable = False
    return a
