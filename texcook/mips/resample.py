"""Separable polyphase resampling with wrap modes.

A reduction from n to m texels along one axis is described by a tap table:
for every output texel i, `idx[i, t]` (source texel, already wrapped) and
`wts[i, t]` (normalised weight). Output texel i sits at the true position
(i + 0.5) * n / m in source coordinates, so odd sizes lose no row or column:
3 -> 1 averages all three texels, 5 -> 2 splits the middle one. The tables
are small (m x taps) and built in NumPy; the jitted kernels only apply them.

Every phase of the table is computed in float64 and normalised to sum 1, so
constant images stay constant, and a kernel never divides by a tap sum.
"""

import math

import numpy as np

from .._jit import jit, jit_inner
from .._threads import parallel_for
from ..colour import StoredRGBA, rgba_from_ints
from ..choices import WRAPS
from ..errors import UsageError
from .filters import make_filter


def wrap_index(j, n, mode):
    """Map integer source indices (any range) into 0..n-1."""
    j = np.asarray(j, np.int64)
    if mode == "repeat":
        return np.mod(j, n)
    if mode in ("clamp", "mirror"):
        # Mirrored repeat with the edge texel repeated (..., 1, 0 | 0, 1, ...),
        # the GL_MIRRORED_REPEAT layout: period 2n. "clamp" (no wrap-around)
        # extends the image the same way for filtering: replicating the edge
        # texel instead gives it the weight of every tap past the border and
        # drifts the mean of small levels by several percent (docs/mips.md);
        # the symmetric extension keeps it exactly for even sizes. Taps at
        # most one texel past the border (box, triangle) read the edge texel
        # either way.
        k = np.mod(j, 2 * n)
        return np.where(k >= n, 2 * n - 1 - k, k)
    raise UsageError(f"unknown wrap mode {mode!r} (choose from {', '.join(WRAPS)})")


_tables = {}  # a chain, and every bake of the same size, asks for the same few tables


def tap_table(n, m, filter="box", wrap="clamp", **filter_options):
    """(idx int32 (m, T), wts float32 (m, T)) reducing n source texels to m,
    read-only (they are kept for the next call with the same arguments)."""
    key = (int(n), int(m), filter, wrap, tuple(sorted(filter_options.items())))
    tables = _tables.get(key)
    if tables is None:
        tables = _tap_table(n, m, filter, wrap, **filter_options)
        for a in tables:
            a.flags.writeable = False
        if len(_tables) >= 256:
            _tables.clear()
        _tables[key] = tables
    return tables


_gains = {}


def table_gain(n, m, filter="box", wrap="clamp", **filter_options):
    """The most one pass of tap_table(n, m, ...) can grow the largest
    magnitude: the largest sum of |weights| of an output texel. 1 for box and
    triangle, whose weights are positive (and sum to 1 up to float32
    rounding); above 1 where negative lobes are."""
    if filter in ("box", "triangle"):
        return 1.0
    key = (int(n), int(m), filter, wrap, tuple(sorted(filter_options.items())))
    gain = _gains.get(key)
    if gain is None:
        wts = tap_table(n, m, filter, wrap, **filter_options)[1]
        gain = float(np.abs(wts).sum(axis=1, dtype=np.float64).max())
        if len(_gains) >= 256:
            _gains.clear()
        _gains[key] = gain
    return gain


def _tap_table(n, m, filter, wrap, **filter_options):
    if not (1 <= m <= n):
        raise ValueError(f"cannot reduce {n} texels to {m}")
    kernel, radius = make_filter(filter, **filter_options)
    wrap_index(0, 1, wrap)  # validates the mode name early
    s = n / m
    centres = (np.arange(m, dtype=np.float64) + 0.5) * s
    half = radius * s  # support half-width in source texels
    first = np.floor(centres - half).astype(np.int64)
    taps = int(math.ceil(2.0 * half)) + 2
    j = first[:, None] + np.arange(taps, dtype=np.int64)[None, :]
    if filter == "box":
        # Exact area coverage of texel [j, j + 1] by the box [c - s/2, c + s/2]:
        # the boxes of neighbouring outputs tile the source, so the mean is kept
        # exactly for any size.
        lo = np.maximum(j, (centres - half)[:, None])
        hi = np.minimum(j + 1, (centres + half)[:, None])
        w = np.clip(hi - lo, 0.0, None)
    else:
        # the kernel once per distinct distance: at 2:1 every output has the same few
        x, where = np.unique((j + 0.5 - centres[:, None]) / s, return_inverse=True)
        w = kernel(x)[where].reshape(j.shape)
    w = np.where(np.abs(w) < 1e-12, 0.0, w)
    # Drop tap columns that are zero for every output (the table was sized
    # generously); fewer taps is less work in the kernels.
    used = np.flatnonzero(np.any(w != 0.0, axis=0))
    w = w[:, used[0]: used[-1] + 1]
    j = j[:, used[0]: used[-1] + 1]
    total = w.sum(axis=1, keepdims=True)
    w = w / total
    idx = wrap_index(j, n, wrap).astype(np.int32)
    return np.ascontiguousarray(idx), np.ascontiguousarray(w.astype(np.float32))


@jit_inner
def _vertical_row(src, idx, wts, i, row):
    """row = sum_t wts[i, t] * src[idx[i, t]] over whole rows of (H, W*C)
    values: the inner loop runs over contiguous memory and vectorises without
    reassociating anything. A zero weight after the first is skipped (adding
    0 * x would turn a -0.0 sum into +0.0)."""
    taps = idx.shape[1]
    n_cols = row.shape[0]
    w = wts[i, 0]
    s = src[idx[i, 0]]
    for x in range(n_cols):
        row[x] = w * s[x]
    for t in range(1, taps):
        w = wts[i, t]
        if w == 0.0:
            continue
        s = src[idx[i, t]]
        for x in range(n_cols):
            row[x] += w * s[x]


@jit_inner
def _horizontal_row4(srow, idx, wts, orow):
    """orow[i, c] = sum_t wts[i, t] * srow[idx[i, t], c] for four channels,
    the accumulators in registers (the same sums in the same order as
    _horizontal)."""
    m, taps = idx.shape
    for i in range(m):
        a0 = np.float32(0.0)
        a1 = np.float32(0.0)
        a2 = np.float32(0.0)
        a3 = np.float32(0.0)
        for t in range(taps):
            w = wts[i, t]
            j = idx[i, t]
            a0 += w * srow[j, 0]
            a1 += w * srow[j, 1]
            a2 += w * srow[j, 2]
            a3 += w * srow[j, 3]
        orow[i, 0] = a0
        orow[i, 1] = a1
        orow[i, 2] = a2
        orow[i, 3] = a3


@jit
def _vertical(src, idx, wts, out):
    """out[i] = sum_t wts[i, t] * src[idx[i, t]] with rows flattened to (H, W*C)."""
    for i in range(idx.shape[0]):
        _vertical_row(src, idx, wts, i, out[i])
    return out


@jit
def _horizontal(src, idx, wts, out):
    """out[y, i, c] = sum_t wts[i, t] * src[y, idx[i, t], c]."""
    h, _, n_ch = src.shape
    m, taps = idx.shape
    acc = np.empty(n_ch, np.float32)
    for y in range(h):
        srow = src[y]
        orow = out[y]
        for i in range(m):
            for c in range(n_ch):
                acc[c] = 0.0
            for t in range(taps):
                w = wts[i, t]
                j = idx[i, t]
                for c in range(n_ch):
                    acc[c] += w * srow[j, c]
            for c in range(n_ch):
                orow[i, c] = acc[c]
    return out


@jit
def _horizontal4(src, idx, wts, out):
    """_horizontal for four channels."""
    for y in range(src.shape[0]):
        _horizontal_row4(src[y], idx, wts, out[y])
    return out


@jit
def _separable(src, idy, wty, idx, wtx, out):
    """Both passes for four channels, one output row at a time: the vertical
    sum of source rows (src is (H, W*4)) into a row of scratch, then the
    horizontal taps from it into out (M, N, 4). The same arithmetic as
    _vertical then _horizontal4, without a full-size intermediate image: the
    scratch row stays in cache."""
    n_cols = src.shape[1]
    flat = np.empty(n_cols, np.float32)
    row = flat.reshape(n_cols // 4, 4)
    for i in range(idy.shape[0]):
        _vertical_row(src, idy, wty, i, flat)
        _horizontal_row4(row, idx, wtx, out[i])
    return out


@jit_inner
def _box_row(r0, r1, o):
    """One row of the even-size 2:1 box: o[j] is the mean of the 2x2 quad of
    rows r0, r1 (W, C) at columns 2j, 2j+1. The same arithmetic as the two
    separable passes (pairs averaged vertically, then horizontally). Four
    channels get a loop with the channel count fixed, which vectorises."""
    m_w, n_ch = o.shape
    half = np.float32(0.5)
    if n_ch == 4:
        for j in range(m_w):
            for c in range(4):
                a = half * r0[2 * j, c] + half * r1[2 * j, c]
                b = half * r0[2 * j + 1, c] + half * r1[2 * j + 1, c]
                o[j, c] = half * a + half * b
    else:
        for j in range(m_w):
            for c in range(n_ch):
                a = half * r0[2 * j, c] + half * r1[2 * j, c]
                b = half * r0[2 * j + 1, c] + half * r1[2 * j + 1, c]
                o[j, c] = half * a + half * b


@jit
def _box2x2(src, out):
    """Even-size 2:1 box in both axes in one pass, without the intermediate
    image of two separable passes."""
    for i in range(out.shape[0]):
        _box_row(src[2 * i], src[2 * i + 1], out[i])
    return out


@jit
def _box2x2_ints(ints, tables, one, out, pair):
    """_box2x2 of the RGBA that the tables make of stored integers (2M, W, c)
    (colour.StoredRGBA), decoding two rows at a time into `pair` (2, W, 4),
    which stays in cache: the next level straight from the stored values.
    (The caller makes `pair`: an array made in a kernel compiles numba's
    allocation routine, a tenth of a second of a cold start.)"""
    for i in range(out.shape[0]):
        rgba_from_ints(ints[2 * i: 2 * i + 2], tables, one, pair)
        _box_row(pair[0], pair[1], out[i])
    return out


@jit
def _separable_ints(ints, tables, one, idy, wty, idx, wtx, out, cache, tags, local, flat):
    """_separable of the RGBA that the tables make of stored integers (H, W, c)
    (colour.StoredRGBA): the source rows the taps read are decoded into a
    small cache as they are first needed, so each is decoded about once and
    no float image of the source is made. The same arithmetic as _separable
    on the decoded image. Any row order works (wrapped taps): a miss replaces
    the slot filled longest ago that this output row has not placed a tap in.
    Working arrays from the caller (no allocation routine to compile): cache
    float32 (taps + 1, W, 4), more slots than one output row's taps, so a
    victim always exists; tags int64 (taps + 1,) all -1; local (1, taps) of
    idy's type; flat float32 (W * 4,)."""
    w = ints.shape[1]
    taps = idy.shape[1]
    slots = cache.shape[0]
    rows = cache.reshape(slots, w * 4)
    scratch = flat.reshape(w, 4)
    victim = 0
    for i in range(idy.shape[0]):
        for t in range(taps):
            r = idy[i, t]
            s = -1
            for k in range(slots):
                if tags[k] == r:
                    s = k
                    break
            if s < 0:
                while True:
                    placed = False
                    for u in range(t):
                        placed |= local[0, u] == victim
                    if not placed:
                        break
                    victim = (victim + 1) % slots
                s = victim
                victim = (victim + 1) % slots
                tags[s] = r
                rgba_from_ints(ints[r: r + 1], tables, one, cache[s: s + 1])
            local[0, t] = s
        _vertical_row(rows, local, wty[i: i + 1], 0, flat)
        _horizontal_row4(scratch, idx, wtx, out[i])
    return out


@jit
def _clamp_rows(src, lo, hi, out):
    """out = src clipped to [lo[x], hi[x]] for every column x of (R, N) rows:
    per-column bounds (each channel's, repeated along the row) keep the loop
    free of index arithmetic, so it vectorises."""
    n = src.shape[1]
    for y in range(src.shape[0]):
        s = src[y]
        o = out[y]
        for x in range(n):
            v = s[x]
            if v < lo[x]:
                v = lo[x]
            elif v > hi[x]:
                v = hi[x]
            o[x] = v
    return out


def _column_bounds(lo, hi, width):
    """Per-channel bounds repeated for each texel of a row: _clamp_rows' form."""
    return (np.tile(np.asarray(lo, np.float32), width), np.tile(np.asarray(hi, np.float32), width))


def _is_plain_halving(tab, n):
    """True when a tap table is the even-size 2:1 box (taps j = 2i, 2i+1 at 1/2)."""
    if tab is None or tab[0].shape[1] != 2 or n % 2:
        return False
    idx, wts = tab
    m = idx.shape[0]
    return bool(np.all(wts == 0.5) and np.array_equal(idx[:, 0], 2 * np.arange(m)) and np.array_equal(idx[:, 1], idx[:, 0] + 1))


def resample(pixels, out_w, out_h, *, filter="box", wrap=("clamp", "clamp"), tables=None, threads=None,
             clamp=None, **filter_options):
    """Resize float32 (H, W, C) pixels down to (out_h, out_w, C), on `threads`
    threads (chunks of output rows; the same bytes for any count).

    Vertical pass first: it is the fast one (whole-row sums), and doing it first
    halves the rows the slower horizontal pass has to visit. When both axes
    shrink, both passes run per output row (no intermediate image).

    `clamp`, per-channel (lo, hi) bounds: also return a clipped copy, made from
    each chunk of rows while it is still in cache: (resized, clipped).

    `pixels` may be a colour.StoredRGBA: where both axes shrink, the rows are
    decoded as they are filtered (the same bytes as resampling its decode)."""
    stored = isinstance(pixels, StoredRGBA)
    if not stored:
        pixels = np.ascontiguousarray(pixels, dtype=np.float32)
        if pixels.ndim != 3:
            raise ValueError("resample expects (H, W, C) pixels")
    h, w, n_ch = pixels.shape
    wrap_x, wrap_y = wrap
    if tables is None:
        tables = (
            tap_table(w, out_w, filter, wrap_x, **filter_options) if out_w != w else None,
            tap_table(h, out_h, filter, wrap_y, **filter_options) if out_h != h else None,
        )
    tab_x, tab_y = tables
    rows = _rows_per_chunk(w, n_ch)
    out = np.empty((out_h, out_w, n_ch), np.float32)
    halving = _is_plain_halving(tab_x, w) and _is_plain_halving(tab_y, h)
    if stored and tab_x is not None and tab_y is not None:
        ints, tabs, one = pixels.values, pixels.tables, pixels.one
        if halving:
            def last(a, b):
                _box2x2_ints(ints[2 * a: 2 * b], tabs, one, out[a:b], np.empty((2, w, 4), np.float32))
        else:
            (idx, wtx), (idy, wty) = tab_x, tab_y
            # a chunk decodes the rows its taps overlap with the next chunk's again: larger chunks
            rows = max(rows, 4 * idy.shape[1])

            def last(a, b):
                taps = idy.shape[1]
                _separable_ints(ints, tabs, one, idy[a:b], wty[a:b], idx, wtx, out[a:b],
                                np.empty((taps + 1, w, 4), np.float32), np.full(taps + 1, -1, np.int64),
                                np.empty((1, taps), idy.dtype), np.empty(w * 4, np.float32))
        return _finish(last, out, out_h, out_w, rows, threads, clamp)
    # one axis keeps its size (a 1-texel-wide or -high source): small, decoded whole
    src = pixels.decode(threads) if stored else pixels
    if halving:
        def last(a, b):
            _box2x2(src[2 * a: 2 * b], out[a:b])
    elif tab_x is not None and tab_y is not None and n_ch == 4:
        # (other channel counts, which the pipeline does not make, take the two passes below)
        flat = src.reshape(h, w * n_ch)
        (idx, wtx), (idy, wty) = tab_x, tab_y

        def last(a, b):
            _separable(flat, idy[a:b], wty[a:b], idx, wtx, out[a:b])
    else:
        if tab_y is not None:
            flat = src.reshape(h, w * n_ch)
            mid = np.empty((out_h, w * n_ch), np.float32) if tab_x is not None else out.reshape(out_h, w * n_ch)
            idy, wty = tab_y
            parallel_for(lambda a, b: _vertical(flat, idy[a:b], wty[a:b], mid[a:b]), out_h, threads, rows)
            src = mid.reshape(out_h, w, n_ch)
        if tab_x is not None:
            kernel = _horizontal4 if n_ch == 4 else _horizontal
            idx, wtx = tab_x

            def last(a, b):
                kernel(src[a:b], idx, wtx, out[a:b])
        elif tab_y is not None:
            def last(a, b):
                pass  # the vertical pass wrote `out`
        else:
            def last(a, b):
                out[a:b] = src[a:b]
    return _finish(last, out, out_h, out_w, rows, threads, clamp)


def _finish(last, out, out_h, out_w, rows, threads, clamp):
    """Run `last` (which fills out[a:b]) over chunks of output rows, and clip
    each chunk to `clamp` as it is made: resample's result."""
    if clamp is None:
        parallel_for(last, out_h, threads, rows)
        return out
    clipped = np.empty_like(out)
    lo, hi = _column_bounds(clamp[0], clamp[1], out_w)
    flat_out, flat_clipped = out.reshape(out_h, -1), clipped.reshape(out_h, -1)

    def last_and_clip(a, b):
        last(a, b)
        _clamp_rows(flat_out[a:b], lo, hi, flat_clipped[a:b])

    parallel_for(last_and_clip, out_h, threads, rows)
    return out, clipped


def clamped(pixels, lo, hi, threads=None):
    """A copy of float32 (H, W, C) pixels clipped to per-channel [lo, hi]."""
    h, w, c = pixels.shape
    out = np.empty_like(pixels)
    clo, chi = _column_bounds(lo, hi, w)
    src2, out2 = pixels.reshape(h, w * c), out.reshape(h, w * c)
    parallel_for(lambda a, b: _clamp_rows(src2[a:b], clo, chi, out2[a:b]), h, threads, _rows_per_chunk(w, c))
    return out


def _rows_per_chunk(w, n_ch):
    """Rows per chunk: enough work (~64K values) to outweigh handing it out."""
    return max(1, 65536 // max(1, w * n_ch))
