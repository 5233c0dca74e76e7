"""Robust statistics of long series without full-length temporaries: median and median absolute
deviation by exact O(n) histogram selection, of a series or of its first differences.

``np.median`` partitions a copy of its input, and a MAD of first differences written with numpy
makes three more; on a 24 h / 1 kHz record (86.4 M samples, 691 MB a copy) those copies would
dominate the memory of an analysis.  Here the order statistics are selected by repeated
histogramming of the values in a shrinking range: each pass reads the series once, forms each
value on the fly (x_i, or x_{i+1} − x_i, optionally as |v − centre|) and allocates only
:data:`SELECT_BINS` bins.  A series of at most :data:`NUMPY_MAX` values is ranked by numpy
itself: its copies are small there, and the selection's kernels then never compile on a first
run.  The results equal numpy's bit for bit either way (tests/stats/test_robust.py).
"""

from __future__ import annotations

import numba
import numpy as np

from imupipe.jit import kernel_input, on_parts, part_bounds, parts, spread

SELECT_BINS = 1 << 16
"""Histogram bins of each selection pass."""
NUMPY_MAX = 1 << 20
"""Longest series whose order statistics numpy computes (its temporaries: ≤ 8 MB each) rather
than the histogram selection: the 5-min sample's, a real 2.8 h / 100 Hz unit's (10⁶ samples) and
a 1 h / 100 Hz fleet unit's.  The selection's kernels cost ~1.4 s of compiling on a first run
(session 34, cold numba cache)."""
MAD_TO_SIGMA = 1.4826
"""1 / Φ⁻¹(3/4): the MAD of a Gaussian sample times this estimates its standard deviation."""


@numba.njit(cache=True, nogil=True, inline="always")
def _value(x: np.ndarray, i: int, center: float, absolute: bool, diff: bool) -> float:
    """Value i: x_i, or x_{i+1} − x_i (``diff``), or its |· − center| (``absolute``)."""
    v = float(x[i + 1]) - float(x[i]) if diff else float(x[i])
    return abs(v - center) if absolute else v


@numba.njit(cache=True, nogil=True)
def _extent_parts(
    x: np.ndarray, center: float, absolute: bool, diff: bool, positive: bool,
    count: np.ndarray, lo: np.ndarray, hi: np.ndarray, finite: np.ndarray, start: int, step: int,
) -> None:  # pragma: no cover (JIT)  # fmt: skip
    """Parts ``start, start + step, …`` of :func:`_extent`: each part's count, min and max of
    the values (only those > 0 if ``positive``) and whether all of them are finite."""
    for p in range(start, count.size, step):
        c, low, high, fin = 0, np.inf, -np.inf, True
        first, stop = part_bounds(len(x) - diff, count.size, p)
        for i in range(first, stop):
            v = _value(x, i, center, absolute, diff)
            if not np.isfinite(v):
                fin = False
            elif v > 0 or not positive:
                c += 1
                low = min(low, v)
                high = max(high, v)
        count[p], lo[p], hi[p], finite[p] = c, low, high, fin


def _extent(
    x: np.ndarray, center: float, absolute: bool, diff: bool, positive: bool
) -> tuple[int, float, float, bool]:
    """(count, min, max) of the values (only those > 0 if ``positive``) and whether all values
    are finite; the record's parts on the usable cores."""
    n_parts = parts(len(x) - diff)
    count, finite = np.zeros(n_parts, np.int64), np.ones(n_parts, np.bool_)
    lo, hi = np.full(n_parts, np.inf), np.full(n_parts, -np.inf)
    on_parts(_extent_parts, n_parts, x, center, absolute, diff, positive, count, lo, hi, finite)
    return int(count.sum()), float(lo.min()), float(hi.max()), bool(finite.all())


@numba.njit(cache=True, nogil=True)
def _histogram_parts(
    x: np.ndarray, lo: float, hi: float, scale: float, center: float, absolute: bool,
    diff: bool, hist: np.ndarray, bin_lo: np.ndarray, bin_hi: np.ndarray, start: int, step: int,
) -> None:  # pragma: no cover (JIT)  # fmt: skip
    """Rows ``start, start + step, …`` of the (parts, :data:`SELECT_BINS`) histograms: part p's
    values in [lo, hi] binned at ``scale`` bins per unit, with each bin's least and greatest
    member."""
    for p in range(start, hist.shape[0], step):
        first, stop = part_bounds(len(x) - diff, hist.shape[0], p)
        for i in range(first, stop):
            v = _value(x, i, center, absolute, diff)
            if lo <= v <= hi:
                c = min(int((v - lo) * scale), SELECT_BINS - 1)
                hist[p, c] += 1
                bin_lo[p, c] = min(bin_lo[p, c], v)
                bin_hi[p, c] = max(bin_hi[p, c], v)


@numba.njit(cache=True, nogil=True)
def _gather_parts(
    x: np.ndarray, lo: float, hi: float, center: float, absolute: bool, diff: bool,
    out: np.ndarray, count: np.ndarray, start: int, step: int,
) -> None:  # pragma: no cover (JIT)  # fmt: skip
    """Rows ``start, start + step, …`` of ``out``: part p's values in [lo, hi] in their order
    (``count[p]`` of them; a branch-free gather, so a row holds one more than it keeps)."""
    for p in range(start, out.shape[0], step):
        first, stop = part_bounds(len(x) - diff, out.shape[0], p)
        j = 0
        for t in range(first, stop):
            v = _value(x, t, center, absolute, diff)
            out[p, j] = v
            j += (v >= lo) & (v <= hi)
        count[p] = j


@numba.njit(cache=True, nogil=True)
def _rank_bin(hist: np.ndarray, k: int, below: int) -> tuple[int, int, int]:
    """(b, the values below bin b, the next non-empty bin after b or :data:`SELECT_BINS`): the
    bin of ``hist`` that holds rank k, ``below`` values lying under the histogram's range."""
    b = 0
    while below + hist[b] <= k:
        below += hist[b]
        b += 1
    nxt = b + 1
    while nxt < SELECT_BINS and hist[nxt] == 0:
        nxt += 1
    return b, below, nxt


def _select(
    x: np.ndarray, k: int, lo: float, hi: float, center: float, absolute: bool, diff: bool
) -> tuple[float, float, np.ndarray, int]:
    """Order statistics k and k + 1 (0-based) of the values in [lo, hi] (see :func:`_value`),
    by histogram selection, O(n); rank k + 1 is +inf when it does not exist.  Returns them, an
    empty array and 0, or (NaN, the least value above the bin, the bin's values unsorted, rank k's
    index among them) for :func:`_order_statistics` to sort.

    Each pass bins the values in [lo, hi] into :data:`SELECT_BINS` bins, with each bin's
    smallest and largest member (the bin index is monotone in the value, so a bin's members are
    exactly the values between those two), and keeps the bin holding rank k; rank k + 1 is in
    that bin or is the smallest member of the next non-empty one.  A bin of equal values
    (quantised data) ends the search; a bin of few values is returned to be sorted (by numpy:
    numba's sort would cost ~1.5 s of compiling on a first run).  Values outside [lo, hi]
    are not ranked.  Each pass reads the record's contiguous parts on the usable cores
    (:func:`imupipe.jit.parts`) and adds up their histograms: counts, least and greatest
    members are the same whatever the parts, and the gathered values come in the record's
    order.
    """
    n_parts = parts(len(x) - diff)
    below, above = 0, np.inf  # values below lo; the least value above hi
    while True:
        scale = SELECT_BINS / (hi - lo) if hi > lo else 0.0
        if not np.isfinite(scale):  # a range of subnormal width: one bin
            scale = 0.0
        hist = np.zeros((n_parts, SELECT_BINS), np.int64)
        bin_lo = np.full((n_parts, SELECT_BINS), np.inf)
        bin_hi = np.full((n_parts, SELECT_BINS), -np.inf)
        bins = (hist, bin_lo, bin_hi)
        on_parts(_histogram_parts, n_parts, x, lo, hi, scale, center, absolute, diff, *bins)
        hist, low, high = hist.sum(axis=0), bin_lo.min(axis=0), bin_hi.max(axis=0)
        b, below, nxt = _rank_bin(hist, k, below)
        if nxt < SELECT_BINS:
            above = float(low[nxt])
        lo, hi = float(low[b]), float(high[b])
        i = k - below
        if lo == hi:
            return lo, lo if i + 1 < hist[b] else above, np.empty(0), 0
        if hist[b] <= 4096 or scale == 0.0:
            rows = n_parts if hist[b] <= 4096 else 1  # a row of the bin's size per part
            rest = np.empty((rows, hist[b] + 1))
            kept = np.zeros(rows, np.int64)
            on_parts(_gather_parts, rows, x, lo, hi, center, absolute, diff, rest, kept)
            return (
                np.nan,
                above,
                np.concatenate([r[:j] for r, j in zip(rest, kept, strict=True)]),
                i,
            )


def _order_statistics(
    x: np.ndarray, k: int, lo: float, hi: float, center: float, absolute: bool, diff: bool
) -> tuple[float, float]:
    """Order statistics k and k + 1 of :func:`_select` (rank k + 1 is +inf when it does not
    exist)."""
    first, second, rest, i = _select(x, k, lo, hi, center, absolute, diff)
    if rest.size == 0:
        return first, second
    rest.sort()
    return rest[i], rest[i + 1] if i + 1 < rest.size else second


def _numpy_values(
    x: np.ndarray, center: float, absolute: bool, diff: bool, positive: bool
) -> np.ndarray | None:
    """The values of :func:`_value` as one float64 array (only those > 0 if ``positive``), or
    ``None`` when one of them is not finite: what the selection ranks, for numpy to rank."""
    v = np.asarray(x, dtype=np.float64)
    if diff:
        v = v[1:] - v[:-1]
    if absolute:
        v = np.abs(v - center)
    if not np.isfinite(v).all():
        return None
    return v[v > 0] if positive else v


def _median(
    x: np.ndarray, center: float = 0.0, absolute: bool = False, diff: bool = False,
    positive: bool = False,
) -> float:  # fmt: skip
    """Median of the values of :func:`_value` (NaN if there are none or one is not finite)."""
    if len(x) <= NUMPY_MAX:
        v = _numpy_values(x, center, absolute, diff, positive)
        return float("nan") if v is None or v.size == 0 else float(np.median(v))
    return _selected_median(x, center, absolute, diff, positive)


def _selected_median(
    x: np.ndarray, center: float, absolute: bool, diff: bool, positive: bool
) -> float:
    """:func:`_median` by histogram selection (no copy of ``x``)."""
    x = kernel_input(x)
    count, lo, hi, finite = _extent(x, center, absolute, diff, positive)
    if count == 0 or not finite:
        return float("nan")
    first, second = _order_statistics(x, (count - 1) // 2, lo, hi, center, absolute, diff)
    return float(first if count % 2 else (first + second) / 2)


def compile_long_record_kernels() -> None:
    """Compile the kernels of a long record's statistics (or load them from numba's disk cache)
    with the types the analysis passes them: the histogram selection on float64 and float32
    series, a bin of many equal values gathered, and the running median with a gap
    (:func:`imupipe.analysis.analyze.compile_kernels`; a series as short as these is ranked by
    numpy)."""
    white = np.random.default_rng(0).standard_normal(4096)
    walk = np.append(np.cumsum(white), 1e12)  # its values but one in one bin: gathered
    for x in (walk, walk.astype(np.float32)):
        _selected_median(x, 0.0, True, True, True)
        _selected_median(x, 0.0, False, False, False)
    _kernel_running_median(kernel_input(white.reshape(-1, 2), np.float64), 16, 2)


def median(x: np.ndarray, differences: bool = False) -> float:
    """``np.median(x)``, or of ``np.diff(x)``, without copying (module docstring); NaN and inf
    in ``x`` follow numpy's rules."""
    if not differences and len(x) and not np.isfinite(np.max(x) + np.min(x)):
        return float(np.median(x))
    return _median(x, diff=differences)


def median_positive(x: np.ndarray, differences: bool = False) -> float:
    """``np.median(v[v > 0])`` of the finite values v = x (or ``np.diff(x)``), without the
    copies; NaN if none is > 0."""
    return _median(x, diff=differences, positive=True)


def mad(x: np.ndarray, center: float | None = None, differences: bool = False) -> float:
    """Median absolute deviation ``np.median(np.abs(v - center))`` of the finite values v = x
    (or ``np.diff(x)``) about ``center`` (default: their median), without temporaries."""
    center = median(x, differences) if center is None else center
    return _median(x, center, absolute=True, diff=differences)


def row_medians(rows: np.ndarray) -> np.ndarray:
    """``np.median(rows, axis=1)`` bit for bit, NaN rows included, from a sorted copy: numpy's
    vectorised sort of short rows (tens to hundreds of values) is 4-5x faster than the
    partitions ``np.median`` makes (measured: 4.32 M values in rows of 25, 0.018 s against
    0.082 s); the mean of the two middle values of an even row is numpy's (a + b) / 2."""
    ordered = np.sort(rows, axis=1)
    half = rows.shape[1] // 2
    middle = (
        ordered[:, half] if rows.shape[1] % 2 else (ordered[:, half - 1] + ordered[:, half]) / 2
    )
    return np.where(np.isnan(ordered[:, -1]), np.nan, middle)  # NaN sorts last


QUANTUM_PROBE = 1 << 16
"""Samples examined by :func:`quantum`."""


def quantum(x: np.ndarray, probe: int = QUANTUM_PROBE) -> float:
    """The quantisation step (LSB) of ``x``, or 0.0 if it does not look quantised.

    From the first ``probe`` finite samples: quantised when they take at most ``probe // 8``
    distinct values; the step is then the least difference between two of them (float64
    values of integer counts times an LSB: exact to rounding)."""
    head = np.asarray(x[:probe], dtype=np.float64)
    values = np.unique(head[np.isfinite(head)])
    if values.size < 2 or values.size > max(2, head.size // 8):
        return 0.0
    return float(np.min(np.diff(values)))


def abs_quantile(x: np.ndarray, p: float) -> float:
    """``np.quantile(np.abs(v), p, method="higher")`` of the finite values v = x, without
    copies: order statistic ceil(p (n - 1)) of |x| by histogram selection (by numpy for at
    most :data:`NUMPY_MAX` values)."""
    if len(x) <= NUMPY_MAX:
        v = _numpy_values(x, 0.0, True, False, False)
        return (
            float("nan") if v is None or v.size == 0 else float(np.quantile(v, p, method="higher"))
        )
    x = kernel_input(x)
    count, lo, hi, finite = _extent(x, 0.0, True, False, False)
    if count == 0 or not finite:
        return float("nan")
    k = int(np.ceil(p * (count - 1)))
    return float(_order_statistics(x, k, lo, hi, 0.0, True, False)[0])


@numba.njit(cache=True, nogil=True)
def _running_median(
    x: np.ndarray, half: int, gap: int, width: int, out: np.ndarray, start: int, step: int
) -> None:  # pragma: no cover (JIT)
    """Columns ``start, start + step, …`` of :func:`running_median` into ``out`` (one
    :func:`imupipe.jit.spread` job a column): a sorted window of the rows at offsets
    ``gap`` ≤ |o| ≤ ``half`` (every |o| ≤ half when ``gap`` is 0), slid row by row: one entry
    replaced on each side (one in all when ``gap`` is 0) by a binary search for the old value
    and a shift of the entries between it and the new value's place.  The first window is
    built by insertion, and binary searches are written out (numba's ``sort`` and
    ``np.searchsorted`` would add ~3 s of compiling to a first run)."""
    rows, cols = x.shape
    window = np.empty(width)
    for c in range(start, cols, step):
        j = 0
        for o in range(-half, half + 1):  # the first row's window, clamped to the edges
            if gap > 0 and abs(o) < gap:
                continue
            v = x[min(max(o, 0), rows - 1), c]
            k = j
            while k > 0 and window[k - 1] > v:  # inserted in order
                window[k] = window[k - 1]
                k -= 1
            window[k] = v
            j += 1
        out[0, c] = 0.5 * (window[(width - 1) // 2] + window[width // 2])
        for i in range(1, rows):
            for side in range(1 if gap == 0 else 2):
                if gap == 0:  # row i − 1 − half leaves, row i + half enters
                    old, new = x[max(i - 1 - half, 0), c], x[min(i + half, rows - 1), c]
                elif side == 0:  # the left side gains row i − gap
                    old, new = x[max(i - 1 - half, 0), c], x[max(i - gap, 0), c]
                else:  # the right side loses row i − 1 + gap
                    old, new = x[min(i - 1 + gap, rows - 1), c], x[min(i + half, rows - 1), c]
                lo, hi = 0, width  # the left end of old's run of equal entries
                while lo < hi:
                    mid = (lo + hi) // 2
                    if window[mid] < old:
                        lo = mid + 1
                    else:
                        hi = mid
                k = lo
                if new >= old:  # shift the entries between up to new's place down by one
                    while k + 1 < width and window[k + 1] < new:
                        window[k] = window[k + 1]
                        k += 1
                else:  # shift those between new's place and old up by one
                    while k > 0 and window[k - 1] > new:
                        window[k] = window[k - 1]
                        k -= 1
                window[k] = new
            out[i, c] = 0.5 * (window[(width - 1) // 2] + window[width // 2])


def running_median(x: np.ndarray, half: int, gap: int = 0) -> np.ndarray:
    """Median of rows i − ``half`` … i + ``half`` of each column of ``x`` (rows, cols), the
    edge rows repeated beyond the ends: ``scipy.ndimage.median_filter(x, size=(2 half + 1, 1),
    mode="nearest")`` bit for bit (an odd window's median is one of its values) for finite
    ``x``, in O(rows · half) with small constants instead of a selection per row.

    ``gap`` > 0 leaves out the rows within ``gap`` − 1 of row i (row i itself at least): the
    median of the 2 (half − gap + 1) rows at gap ≤ |i − k| ≤ half, the mean of the two middle
    values.  The event detector scales its z by the residual against it: a level that shares
    no row with the window it is compared with (:mod:`imupipe.analysis.events`)."""
    x = kernel_input(x, np.float64)
    if x.ndim != 2 or not np.isfinite(x).all():
        raise ValueError("running_median: a finite 2-D array")
    if not 0 <= gap <= half:
        raise ValueError("running_median: 0 <= gap <= half")
    if x.shape[0] == 0:
        return np.empty(x.shape)
    if x.size * _window_width(half, gap) <= NUMPY_MAX:  # a short record's: no kernel to compile
        return _numpy_running_median(x, half, gap)
    return _kernel_running_median(x, half, gap)


def _window_width(half: int, gap: int) -> int:
    """Rows in :func:`running_median`'s window: 2 ``half`` + 1, or without the 2 ``gap`` − 1
    about the centre."""
    return 2 * half + 1 if gap == 0 else 2 * (half - gap + 1)


def _kernel_running_median(x: np.ndarray, half: int, gap: int) -> np.ndarray:
    """:func:`running_median` of at least one row by :func:`_running_median`, a column a job on
    the usable cores."""
    out = np.empty(x.shape)
    width = _window_width(half, gap)
    spread(lambda start, step: _running_median(x, half, gap, width, out, start, step), x.shape[1])
    return out


def _numpy_running_median(x: np.ndarray, half: int, gap: int) -> np.ndarray:
    """:func:`running_median` of at least one row by numpy's median of every window at once
    (x.size × the window's width values): the edge rows repeated, the rows within ``gap`` − 1
    of the centre left out."""
    padded = np.pad(x, ((half, half), (0, 0)), mode="edge")
    windows = np.lib.stride_tricks.sliding_window_view(padded, 2 * half + 1, axis=0)
    if gap > 0:  # offsets −half … −gap and gap … half of each row's window
        windows = np.concatenate([windows[..., : half - gap + 1], windows[..., half + gap :]], -1)
    return np.median(windows, axis=-1)
