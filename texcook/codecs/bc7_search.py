"""BC7 encoder search: fills a symbolic block (bc7_kernels) for each 4x4
block; the bits are packed afterwards. See texcook.codecs.bc7 for the search
and the preset table (`prm`) it reads.

Texels are float64 (16, 4); the error of a candidate is the weighted sum of
squared channel differences of the block as the decoder would return it
(every candidate is measured exactly on its decoded palette). Ties keep the
earlier candidate, so the result depends on nothing but the block, the
weights and the preset.

The working data of a block lives in two scratch arrays, F (float) and I
(int), with the named rows below; helpers pass them on instead of making
arrays of their own (an allocation costs more than a small fit).
"""

import numpy as np

from .._jit import borrow, jit, jit_inner
from ._kernels import byte
from .bc7_kernels import (S_EP, S_IDX, S_ISEL, S_MODE, S_P, S_PART, S_ROT, SYM_LEN, decode_sym, index_sets,
                          normalise_anchors, pack)
from .bc7_tables import (AB, CB, EPB, EXPAND, IB, IB2, COUNT, MODES, NEAREST, NIBBLE, NS, PB, SINGLE, SPB, SUBSET,
                         WEIGHTS)

# rows of the float scratch F (64 columns; most rows use 16)
F_X = 0  # rows 0-3: the subset's texels, one channel per row
F_E = 4  # rows 4-5: float endpoints (4 channels)
F_V = 6  # the axis (4 channels), then the mean in row 7
F_M = 7
F_PAL = 8  # rows 8-11: 2 w q of each palette entry q, by channel (16 entries)
F_W = 12  # the weights (0-3) and their roots (4-7) as the fits read them (rotated in modes 4, 5)
F_MOM = 13  # rows 13-26: each texel's weighted channels and their products (_moments)
F_EST = 27  # the estimate of each partition (64 columns)
F_GEO = 28  # rows 28-33: _geometry of 2 and 3 subsets of RGB, 2 subsets of RGBA
F_NIB = 34  # rows 34-97: _row_sums
F_TOPE = 98  # the estimates of the partitions in I[I_TOP]
F_H = 99  # |q|^2 of each palette entry (weighted), in _evaluate
F_ROWS = 100
# rows of the int scratch I (64 columns: a row holds up to 64 partitions)
I_MEM = 0  # texels of the subset being fitted
I_IDX = 1  # indices of the candidate measured last (member order)
I_BEST = 2  # indices of the best candidate (member order)
I_Q = 3  # rows 3-4: stored endpoint channels of the candidate
I_BQ = 5  # rows 5-6: those of the best
I_P = 7  # p-bits: candidate [0, 1], best [2, 3]
I_TOP = 8  # partitions kept after the estimate
I_ROWS = 9


@jit_inner
def _layout(mode, which, isel):
    """(first channel, end channel, index slot, index bits) of one fit:
    which 0 is the colour (all channels of modes without a second index set),
    which 1 the alpha of modes 4 and 5."""
    has_alpha = MODES[mode, AB] > 0
    if MODES[mode, IB2] == 0:
        return 0, (4 if has_alpha else 3), S_IDX, MODES[mode, IB]
    cslot, aslot, cbits, abits = index_sets(mode, isel)
    if which == 0:
        return 0, 3, cslot, cbits
    return 3, 4, aslot, abits


@jit_inner
def _bits(mode, c):
    return MODES[mode, AB] if c == 3 else MODES[mode, CB]


@jit_inner
def _evaluate(F, I, n, c0, c1, w, mode, ib, every):
    """Error of the candidate in I[I_Q..], p-bits I[I_P, 0..1]; its indices
    into I[I_IDX]: the nearest palette entry (the first on ties) among all
    (`every`) or among the three around the texel's projection on the line
    through the end entries (the palette is that line, rounded).

    A texel x costs |x|^2 + (|q|^2 - 2 x.q) against entry q (weighted): one
    dot product per entry, with 2q and |q|^2 made once per candidate; the
    channels outside c0..c1 weigh 0."""
    nidx = np.int64(1) << ib
    w0 = w[0] if c0 <= 0 < c1 else 0.0
    w1 = w[1] if c0 <= 1 < c1 else 0.0
    w2 = w[2] if c0 <= 2 < c1 else 0.0
    w3 = w[3] if c0 <= 3 < c1 else 0.0
    for j in range(nidx):
        F[F_H, j] = 0.0
    for c in range(4):
        if c < c0 or c >= c1:
            for j in range(nidx):
                F[F_PAL + c, j] = 0.0
            continue
        bits = _bits(mode, c)
        e0 = EXPAND[bits, I[I_P, 0], I[I_Q, c]]
        e1 = EXPAND[bits, I[I_P, 1], I[I_Q + 1, c]]
        for j in range(nidx):
            wt = WEIGHTS[ib, j]
            q = np.float64(((64 - wt) * e0 + wt * e1 + 32) >> 6)
            F[F_PAL + c, j] = 2.0 * w[c] * q
            F[F_H, j] += w[c] * q * q
    # the line through the end entries, for the projection (the end entries
    # are the endpoints themselves: weights 0 and 64)
    d0 = (F[F_PAL, nidx - 1] - F[F_PAL, 0]) * 0.5
    d1 = (F[F_PAL + 1, nidx - 1] - F[F_PAL + 1, 0]) * 0.5
    d2 = (F[F_PAL + 2, nidx - 1] - F[F_PAL + 2, 0]) * 0.5
    d3 = (F[F_PAL + 3, nidx - 1] - F[F_PAL + 3, 0]) * 0.5
    dd = 0.0
    if w0 > 0.0:
        dd += d0 * d0 / w0
    if w1 > 0.0:
        dd += d1 * d1 / w1
    if w2 > 0.0:
        dd += d2 * d2 / w2
    if w3 > 0.0:
        dd += d3 * d3 / w3
    scale = (nidx - 1) / dd if dd > 0.0 else 0.0
    # e0 . d, so that a texel's projection is x . d less this
    t0 = 0.0
    if w0 > 0.0:
        t0 += F[F_PAL, 0] * d0 / (2.0 * w0)
    if w1 > 0.0:
        t0 += F[F_PAL + 1, 0] * d1 / (2.0 * w1)
    if w2 > 0.0:
        t0 += F[F_PAL + 2, 0] * d2 / (2.0 * w2)
    if w3 > 0.0:
        t0 += F[F_PAL + 3, 0] * d3 / (2.0 * w3)
    err = 0.0
    for k in range(n):
        x0 = F[F_X, k] if w0 > 0.0 else 0.0
        x1 = F[F_X + 1, k] if w1 > 0.0 else 0.0
        x2 = F[F_X + 2, k] if w2 > 0.0 else 0.0
        x3 = F[F_X + 3, k] if w3 > 0.0 else 0.0
        lo = 0
        hi = nidx
        if not every:
            # (x - e0) . (e1 - e0), weighted: d holds w (e1 - e0)
            t = x0 * d0 + x1 * d1 + x2 * d2 + x3 * d3 - t0
            j = np.int64(np.floor(t * scale + 0.5))
            lo = min(max(j - 1, 0), nidx - 1)
            hi = min(max(j + 2, 1), nidx)
        best = 1e300
        bj = 0
        for j in range(lo, hi):
            e = F[F_H, j] - (x0 * F[F_PAL, j] + x1 * F[F_PAL + 1, j] + x2 * F[F_PAL + 2, j]
                             + x3 * F[F_PAL + 3, j])
            if e < best:
                best = e
                bj = j
        I[I_IDX, k] = bj
        err += best + (w0 * x0 * x0 + w1 * x1 * x1 + w2 * x2 * x2 + w3 * x3 * x3)
    return err


@jit_inner
def _quantise(F, I, c0, c1, mode, p0, p1):
    """Stored channels nearest the float endpoints F[F_E..] with p-bits p0, p1
    (2: the mode has none) into I[I_Q..]."""
    I[I_P, 0] = p0
    I[I_P, 1] = p1
    for c in range(c0, c1):
        bits = _bits(mode, c)
        I[I_Q, c] = NEAREST[bits, p0, byte(F[F_E, c])]
        I[I_Q + 1, c] = NEAREST[bits, p1, byte(F[F_E + 1, c])]


@jit_inner
def _quant_error(F, c0, c1, w, mode, e, p):
    """Weighted squared error of float endpoint e stored with p-bit p."""
    err = 0.0
    for c in range(c0, c1):
        bits = _bits(mode, c)
        v = byte(F[F_E + e, c])
        d = EXPAND[bits, p, NEAREST[bits, p, v]] - F[F_E + e, c]
        err += w[c] * d * d
    return err


@jit_inner
def _keep(I, c0, c1, n):
    for c in range(c0, c1):
        I[I_BQ, c] = I[I_Q, c]
        I[I_BQ + 1, c] = I[I_Q + 1, c]
    I[I_P, 2] = I[I_P, 0]
    I[I_P, 3] = I[I_P, 1]
    for k in range(n):
        I[I_BEST, k] = I[I_IDX, k]


@jit_inner
def _try(F, I, n, c0, c1, w, mode, ib, prm, best, force_p):
    """Quantise the float endpoints F[F_E..] (every p-bit choice the preset
    allows, or both p-bits force_p when that is >= 0) and measure; the best
    kept in I's best rows. Returns the best error."""
    pmode = 2 if MODES[mode, EPB] else (1 if MODES[mode, SPB] else 0)
    if pmode == 0 or force_p >= 0:
        p = 2 if pmode == 0 else force_p
        _quantise(F, I, c0, c1, mode, p, p)
        e = _evaluate(F, I, n, c0, c1, w, mode, ib, prm.every_index)
        if e < best:
            best = e
            _keep(I, c0, c1, n)
        return best
    if prm.pbits == 0:
        # p-bits by the endpoints' own quantisation error, one measurement
        if pmode == 1:
            p = 0 if (_quant_error(F, c0, c1, w, mode, 0, 0) + _quant_error(F, c0, c1, w, mode, 1, 0)
                      <= _quant_error(F, c0, c1, w, mode, 0, 1) + _quant_error(F, c0, c1, w, mode, 1, 1)) else 1
            p0 = p
            p1 = p
        else:
            p0 = 0 if _quant_error(F, c0, c1, w, mode, 0, 0) <= _quant_error(F, c0, c1, w, mode, 0, 1) else 1
            p1 = 0 if _quant_error(F, c0, c1, w, mode, 1, 0) <= _quant_error(F, c0, c1, w, mode, 1, 1) else 1
        _quantise(F, I, c0, c1, mode, p0, p1)
        e = _evaluate(F, I, n, c0, c1, w, mode, ib, prm.every_index)
        if e < best:
            best = e
            _keep(I, c0, c1, n)
        return best
    for combo in range(4):
        p0 = combo >> 1
        p1 = combo & 1
        if pmode == 1 and p0 != p1:
            continue
        _quantise(F, I, c0, c1, mode, p0, p1)
        e = _evaluate(F, I, n, c0, c1, w, mode, ib, prm.every_index)
        if e < best:
            best = e
            _keep(I, c0, c1, n)
    return best


@jit_inner
def _axis(F, n, c0, c1, sw, iters):
    """Mean into F[F_M], principal axis of the weighted texels into F[F_V]
    (unit length; zero when the texels are all equal)."""
    for c in range(c0, c1):
        s = 0.0
        for k in range(n):
            s += F[F_X + c, k]
        F[F_M, c] = s / n
    cov = F[F_PAL:F_PAL + 4]  # rows of the covariance (the palette is not in use)
    for a in range(4):
        for b in range(4):
            cov[a, b] = 0.0
    for a in range(c0, c1):
        for b in range(a, c1):
            s = 0.0
            for k in range(n):
                s += (F[F_X + a, k] - F[F_M, a]) * (F[F_X + b, k] - F[F_M, b])
            s *= sw[a] * sw[b]
            cov[a, b] = s
            cov[b, a] = s
    # start from the channel of largest variance: never orthogonal to the axis
    # unless that channel is flat, and then all are
    big = c0
    for c in range(c0, c1):
        if cov[c, c] > cov[big, big]:
            big = c
    for c in range(4):
        F[F_V, c] = 0.0
    if cov[big, big] <= 1e-12:
        return
    v0, v1, v2, v3 = cov[big, 0], cov[big, 1], cov[big, 2], cov[big, 3]
    for it in range(iters):
        u0 = cov[0, 0] * v0 + cov[0, 1] * v1 + cov[0, 2] * v2 + cov[0, 3] * v3
        u1 = cov[1, 0] * v0 + cov[1, 1] * v1 + cov[1, 2] * v2 + cov[1, 3] * v3
        u2 = cov[2, 0] * v0 + cov[2, 1] * v1 + cov[2, 2] * v2 + cov[2, 3] * v3
        u3 = cov[3, 0] * v0 + cov[3, 1] * v1 + cov[3, 2] * v2 + cov[3, 3] * v3
        if it & 3 == 3:
            # rescaled now and then (a division is slow): entries are below
            # 16 * 255^2, so four unscaled steps stay far from overflow
            m = 1.0 / max(abs(u0), abs(u1), abs(u2), abs(u3))
            u0, u1, u2, u3 = u0 * m, u1 * m, u2 * m, u3 * m
        v0, v1, v2, v3 = u0, u1, u2, u3
    norm = np.sqrt(v0 * v0 + v1 * v1 + v2 * v2 + v3 * v3)
    if not norm > 0.0:
        return
    F[F_V, 0] = v0 / norm
    F[F_V, 1] = v1 / norm
    F[F_V, 2] = v2 / norm
    F[F_V, 3] = v3 / norm


@jit_inner
def _gather(px, sym, s, c0, c1, F, I):
    """The texels of subset s into F's rows (channels c0..c1-1); their positions
    into I[I_MEM]. Returns how many."""
    mode = sym[S_MODE]
    ns = MODES[mode, NS]
    part = sym[S_PART]
    n = 0
    for i in range(16):
        if SUBSET[ns - 1, part, i] == s:
            I[I_MEM, n] = i
            for c in range(c0, c1):
                F[F_X + c, n] = px[i, c]
            n += 1
    return n


@jit_inner
def fit_subset(px, w, sw, prm, sym, s, which, F, I, flat_alpha):
    """Endpoints, p-bits and indices of subset s of the mode, partition and
    index selector in sym, for the channels `which` names (see _layout),
    written into sym. Returns their error. Principal axis and range fit, then
    least-squares refinement of the endpoints from the indices. A block whose
    alpha is flat_alpha throughout (-1: it is not flat) keeps it exactly in
    modes 6 and 7: both p-bits are its low bit."""
    mode = sym[S_MODE]
    c0, c1, slot, ib = _layout(mode, which, sym[S_ISEL])
    force_p = flat_alpha & 1 if flat_alpha >= 0 and c1 == 4 and c0 == 0 else -1
    n = _gather(px, sym, s, c0, c1, F, I)
    _axis(F, n, c0, c1, sw, prm.power_iters)
    tmin = 1e300
    tmax = -1e300
    for k in range(n):
        t = 0.0
        for c in range(c0, c1):
            t += (F[F_X + c, k] - F[F_M, c]) * sw[c] * F[F_V, c]
        tmin = min(tmin, t)
        tmax = max(tmax, t)
    for c in range(c0, c1):
        F[F_E, c] = F[F_M, c] + tmin * F[F_V, c] / sw[c]
        F[F_E + 1, c] = F[F_M, c] + tmax * F[F_V, c] / sw[c]
    best = _try(F, I, n, c0, c1, w, mode, ib, prm, 1e300, force_p)
    for _ in range(prm.ls_iters):
        if not _least_squares(F, I, n, c0, c1, ib):
            break
        e = _try(F, I, n, c0, c1, w, mode, ib, prm, best, force_p)
        if not e < best:
            break
        best = e
    _store(sym, I, s, c0, c1, slot, n)
    return best


@jit_inner
def _store(sym, I, s, c0, c1, slot, n):
    """The best candidate of subset s (I's best rows) into sym."""
    mode = sym[S_MODE]
    for c in range(c0, c1):
        sym[S_EP + (s * 2) * 4 + c] = I[I_BQ, c]
        sym[S_EP + (s * 2 + 1) * 4 + c] = I[I_BQ + 1, c]
    if MODES[mode, EPB] or MODES[mode, SPB]:
        sym[S_P + s * 2] = I[I_P, 2]
        sym[S_P + s * 2 + 1] = I[I_P, 3]
    for k in range(n):
        sym[slot + I[I_MEM, k]] = I[I_BEST, k]


@jit_inner
def bounding_box_fit(px, w, sym, F, I, flat_alpha):
    """The trivial fit, always a candidate so that no block ends worse: mode 6
    with the per-channel minimum and maximum as endpoints, p-bits by their
    rounding error (a flat alpha's low bit when alpha is flat), each texel
    its nearest entry of all 16. Written into sym; returns its error."""
    _clear(sym, 6)
    n = _gather(px, sym, 0, 0, 4, F, I)
    for c in range(4):
        lo = 255.0
        hi = 0.0
        for k in range(n):
            lo = min(lo, F[F_X + c, k])
            hi = max(hi, F[F_X + c, k])
        F[F_E, c] = lo
        F[F_E + 1, c] = hi
    if flat_alpha >= 0:
        p0 = flat_alpha & 1
        p1 = p0
    else:
        p0 = 0 if _quant_error(F, 0, 4, w, 6, 0, 0) <= _quant_error(F, 0, 4, w, 6, 0, 1) else 1
        p1 = 0 if _quant_error(F, 0, 4, w, 6, 1, 0) <= _quant_error(F, 0, 4, w, 6, 1, 1) else 1
    _quantise(F, I, 0, 4, 6, p0, p1)
    e = _evaluate(F, I, n, 0, 4, w, 6, 4, True)
    _keep(I, 0, 4, n)
    _store(sym, I, 0, 0, 4, S_IDX, n)
    return e


@jit_inner
def _from_best(I, c0, c1):
    """The best candidate's endpoints and p-bits back into the candidate rows."""
    for c in range(c0, c1):
        I[I_Q, c] = I[I_BQ, c]
        I[I_Q + 1, c] = I[I_BQ + 1, c]
    I[I_P, 0] = I[I_P, 2]
    I[I_P, 1] = I[I_P, 3]


@jit_inner
def _climb(F, I, n, c0, c1, w, mode, ib, prm, best, force_p):
    """Hill climbing from the best candidate: each stored endpoint channel one
    step up or down and, with a p-bit per endpoint (not forced), each p-bit
    flipped, measured exactly; improvements kept, up to prm.climb passes."""
    flip = MODES[mode, EPB] and force_p < 0
    for _ in range(prm.climb):
        improved = False
        for e in range(2):
            moves = 2 * (c1 - c0) + (1 if flip else 0)
            for m in range(moves):
                _from_best(I, c0, c1)
                if m == 2 * (c1 - c0):
                    I[I_P, e] = 1 - I[I_P, e]
                else:
                    c = c0 + (m >> 1)
                    q = I[I_Q + e, c] + (1 if m & 1 else -1)
                    if q < 0 or q >= (np.int64(1) << _bits(mode, c)):
                        continue
                    I[I_Q + e, c] = q
                err = _evaluate(F, I, n, c0, c1, w, mode, ib, prm.every_index)
                if err < best:
                    best = err
                    _keep(I, c0, c1, n)
                    improved = True
        if not improved:
            break
    return best


@jit_inner
def _least_squares(F, I, n, c0, c1, ib):
    """Float endpoints minimising the squared error for the best indices so far
    into F[F_E..]; False when the indices do not determine them (all equal)."""
    a = 0.0
    b = 0.0
    d = 0.0
    for k in range(n):
        t = WEIGHTS[ib, I[I_BEST, k]] / 64.0
        a += (1.0 - t) * (1.0 - t)
        b += (1.0 - t) * t
        d += t * t
    det = a * d - b * b
    if det < 1e-9:
        return False
    for c in range(c0, c1):
        r0 = 0.0
        r1 = 0.0
        for k in range(n):
            t = WEIGHTS[ib, I[I_BEST, k]] / 64.0
            r0 += (1.0 - t) * F[F_X + c, k]
            r1 += t * F[F_X + c, k]
        F[F_E, c] = (d * r0 - b * r1) / det
        F[F_E + 1, c] = (a * r1 - b * r0) / det
    return True


@jit_inner
def _moments(px, sw, F):
    """Each texel's weighted channels y and their products, in rows
    F_MOM..F_MOM+13: y0 y1 y2, y0y0 y0y1 y0y2 y1y1 y1y2 y2y2, y3, y0y3 y1y3
    y2y3 y3y3. A subset's sums give its covariance."""
    for i in range(16):
        y0 = px[i, 0] * sw[0]
        y1 = px[i, 1] * sw[1]
        y2 = px[i, 2] * sw[2]
        y3 = px[i, 3] * sw[3]
        F[F_MOM, i] = y0
        F[F_MOM + 1, i] = y1
        F[F_MOM + 2, i] = y2
        F[F_MOM + 3, i] = y0 * y0
        F[F_MOM + 4, i] = y0 * y1
        F[F_MOM + 5, i] = y0 * y2
        F[F_MOM + 6, i] = y1 * y1
        F[F_MOM + 7, i] = y1 * y2
        F[F_MOM + 8, i] = y2 * y2
        F[F_MOM + 9, i] = y3
        F[F_MOM + 10, i] = y0 * y3
        F[F_MOM + 11, i] = y1 * y3
        F[F_MOM + 12, i] = y2 * y3
        F[F_MOM + 13, i] = y3 * y3


@jit_inner
def _spread(n, m, nch):
    """(distance from the axis, spread along it), as sums of squares, of texels
    whose moment sums (in _moments' order) are the 14-tuple m: the trace of
    their covariance less its largest eigenvalue (power iteration), and that
    eigenvalue."""
    c00 = m[3] - m[0] * m[0] / n
    c01 = m[4] - m[0] * m[1] / n
    c02 = m[5] - m[0] * m[2] / n
    c11 = m[6] - m[1] * m[1] / n
    c12 = m[7] - m[1] * m[2] / n
    c22 = m[8] - m[2] * m[2] / n
    c03 = c13 = c23 = c33 = 0.0
    if nch == 4:
        c03 = m[10] - m[0] * m[9] / n
        c13 = m[11] - m[1] * m[9] / n
        c23 = m[12] - m[2] * m[9] / n
        c33 = m[13] - m[9] * m[9] / n
    trace = c00 + c11 + c22 + c33
    # start from the row of the largest diagonal entry
    v0, v1, v2, v3 = c00, c01, c02, c03
    big = c00
    if c11 > big:
        v0, v1, v2, v3 = c01, c11, c12, c13
        big = c11
    if c22 > big:
        v0, v1, v2, v3 = c02, c12, c22, c23
        big = c22
    if c33 > big:
        v0, v1, v2, v3 = c03, c13, c23, c33
        big = c33
    if big <= 1e-9:
        return 0.0, 0.0
    # unnormalised: entries are below 16 * 255^2, so three steps stay far
    # from overflow, and the ratio below does not care about the length
    for _ in range(3):
        u0 = c00 * v0 + c01 * v1 + c02 * v2 + c03 * v3
        u1 = c01 * v0 + c11 * v1 + c12 * v2 + c13 * v3
        u2 = c02 * v0 + c12 * v1 + c22 * v2 + c23 * v3
        u3 = c03 * v0 + c13 * v1 + c23 * v2 + c33 * v3
        v0, v1, v2, v3 = u0, u1, u2, u3
    u0 = c00 * v0 + c01 * v1 + c02 * v2 + c03 * v3
    u1 = c01 * v0 + c11 * v1 + c12 * v2 + c13 * v3
    u2 = c02 * v0 + c12 * v1 + c22 * v2 + c23 * v3
    u3 = c03 * v0 + c13 * v1 + c23 * v2 + c33 * v3
    lam = (v0 * u0 + v1 * u1 + v2 * u2 + v3 * u3) / (v0 * v0 + v1 * v1 + v2 * v2 + v3 * v3)
    return max(trace - lam, 0.0), lam


@jit_inner
def _row_sums(F):
    """For each row y of the block and each 4-bit pattern of its texels, the
    sums of their 14 moments into F[F_NIB + 16 y + pattern, 0..13]: a
    subset's sums are then four lookups."""
    for y in range(4):
        base = F_NIB + 16 * y
        for r in range(14):
            F[base, r] = 0.0
        for pattern in range(1, 16):
            low = pattern & (pattern - 1)  # the pattern less its lowest texel
            x = 0
            while not (pattern >> x) & 1:
                x += 1
            for r in range(14):
                F[base + pattern, r] = F[base + low, r] + F[F_MOM + r, 4 * y + x]


@jit_inner
def _subset_sums(F, ns, part, s):
    """The 14 moment sums of subset s of the partition."""
    r0 = F_NIB + NIBBLE[ns - 1, part, s, 0]
    r1 = F_NIB + 16 + NIBBLE[ns - 1, part, s, 1]
    r2 = F_NIB + 32 + NIBBLE[ns - 1, part, s, 2]
    r3 = F_NIB + 48 + NIBBLE[ns - 1, part, s, 3]
    return (F[r0, 0] + F[r1, 0] + F[r2, 0] + F[r3, 0], F[r0, 1] + F[r1, 1] + F[r2, 1] + F[r3, 1],
            F[r0, 2] + F[r1, 2] + F[r2, 2] + F[r3, 2], F[r0, 3] + F[r1, 3] + F[r2, 3] + F[r3, 3],
            F[r0, 4] + F[r1, 4] + F[r2, 4] + F[r3, 4], F[r0, 5] + F[r1, 5] + F[r2, 5] + F[r3, 5],
            F[r0, 6] + F[r1, 6] + F[r2, 6] + F[r3, 6], F[r0, 7] + F[r1, 7] + F[r2, 7] + F[r3, 7],
            F[r0, 8] + F[r1, 8] + F[r2, 8] + F[r3, 8], F[r0, 9] + F[r1, 9] + F[r2, 9] + F[r3, 9],
            F[r0, 10] + F[r1, 10] + F[r2, 10] + F[r3, 10], F[r0, 11] + F[r1, 11] + F[r2, 11] + F[r3, 11],
            F[r0, 12] + F[r1, 12] + F[r2, 12] + F[r3, 12], F[r0, 13] + F[r1, 13] + F[r2, 13] + F[r3, 13])


@jit_inner
def _minus(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2], a[3] - b[3], a[4] - b[4], a[5] - b[5], a[6] - b[6],
            a[7] - b[7], a[8] - b[8], a[9] - b[9], a[10] - b[10], a[11] - b[11], a[12] - b[12], a[13] - b[13])


@jit_inner
def _geometry(F, ns, nch, row):
    """For every partition of ns subsets: the sum over subsets of the squared
    distances of the weighted texels from their principal axis into
    F[row], the sum of their squared spreads along it into F[row + 1].
    Subset 0's moments are the block's less the others'."""
    total = _subset_sums(F, 1, 0, 0)
    for part in range(64):
        m1 = _subset_sums(F, ns, part, 1)
        n1 = COUNT[ns - 1, part, 1]
        rest = _minus(total, m1)
        off, along = _spread(n1, m1, nch)
        if ns == 3:
            m2 = _subset_sums(F, ns, part, 2)
            n2 = COUNT[ns - 1, part, 2]
            rest = _minus(rest, m2)
            o, a = _spread(n2, m2, nch)
            off += o
            along += a
            o, a = _spread(16.0 - n1 - n2, rest, nch)
        else:
            o, a = _spread(16.0 - n1, rest, nch)
        F[row, part] = off + o
        F[row + 1, part] = along + a


@jit_inner
def _geometry_row(mode):
    """The rows of F holding _geometry for the mode's subsets and channels."""
    if MODES[mode, AB]:
        return F_GEO + 4
    return F_GEO + 2 * (MODES[mode, NS] - 2)


@jit_inner
def _top_partitions(mode, keep, F, I):
    """The `keep` partitions of the mode with the lowest estimates into I[I_TOP]
    (ties: the lower number first); returns how many. The estimate: distance
    from each subset's axis plus the rounding along it to the index steps, as
    if the texels were spread evenly (step^2 / 12 each; the endpoints'
    rounding ignored)."""
    count = np.int64(1) << MODES[mode, PB]
    keep = min(keep, count)
    levels = (np.int64(1) << MODES[mode, IB]) - 1
    rounding = 1.0 / (levels * levels)
    row = _geometry_row(mode)
    est = F[F_EST]
    for p in range(count):
        est[p] = F[row, p] + rounding * F[row + 1, p]
    for j in range(keep):
        bp = -1
        for p in range(count):
            if est[p] < 1e300 and (bp < 0 or est[p] < est[bp]):
                bp = p
        I[I_TOP, j] = bp
        F[F_TOPE, j] = est[bp]
        est[bp] = 1e300
    return keep


@jit_inner
def _copy(src, dst):
    for k in range(SYM_LEN):
        dst[k] = src[k]


@jit_inner
def _clear(sym, mode):
    for k in range(SYM_LEN):
        sym[k] = 0
    sym[S_MODE] = mode


@jit_inner
def _alpha_penalty(px, w):
    """Error of modes without alpha (they decode alpha as 255)."""
    e = 0.0
    for i in range(16):
        d = 255.0 - px[i, 3]
        e += w[3] * d * d
    return e


@jit_inner
def _single_colour(px, sym):
    """A constant block, exactly: mode 5, each colour channel at index 1 of an
    endpoint pair from the single-colour table, alpha in both 8-bit endpoints."""
    _clear(sym, 5)
    for c in range(3):
        v = np.int64(px[0, c])
        sym[S_EP + c] = SINGLE[v, 0]
        sym[S_EP + 4 + c] = SINGLE[v, 1]
    a = np.int64(px[0, 3])
    sym[S_EP + 3] = a
    sym[S_EP + 7] = a
    for i in range(16):
        sym[S_IDX + i] = 1


@jit_inner
def _accept(e, best_err, cand, flat_alpha, out):
    """True when candidate cand (error e) beats the best so far. A block whose
    alpha is one value throughout (all opaque, all transparent) keeps it
    exactly: a candidate decoding to any other alpha is refused, however small
    its error (mode 5 and modes 0-3 always have an exact candidate)."""
    if not e < best_err:
        return False
    if flat_alpha < 0:
        return True
    mode = cand[S_MODE]
    if MODES[mode, AB] == 0:
        return flat_alpha == 255
    if mode == 6 or mode == 7:
        return True  # fit_subset gave them flat_alpha's low bit as p-bits: exact
    decode_sym(cand, out)
    for i in range(16):
        if out[i, 3] != flat_alpha:
            return False
    return True


@jit_inner
def _rotate(px, w, sw, rot, rx, rw):
    """The texels and weights as modes 4 and 5 store them under rotation rot
    (alpha swapped with channel rot - 1): rx (16, 4); rw[0:4] weights, rw[4:8]
    their roots."""
    for i in range(16):
        for c in range(4):
            rx[i, c] = px[i, c]
        if rot:
            rx[i, rot - 1] = px[i, 3]
            rx[i, 3] = px[i, rot - 1]
    for c in range(4):
        rw[c] = w[c]
        rw[4 + c] = sw[c]
    if rot:
        rw[rot - 1], rw[3] = w[3], w[rot - 1]
        rw[4 + rot - 1], rw[7] = sw[3], sw[rot - 1]


@jit_inner
def _polish(px, w, prm, sym, F, I, flat_alpha):
    """Hill climbing (_climb) over the endpoints of every subset of the chosen
    block, in place; returns its error. Only the winner is climbed: the
    search's candidates are ranked without it."""
    mode = sym[S_MODE]
    ns = MODES[mode, NS]
    err = 0.0 if MODES[mode, AB] else _alpha_penalty(px, w)
    parts = 2 if MODES[mode, IB2] else 1
    pbits = MODES[mode, EPB] or MODES[mode, SPB]
    for s in range(ns):
        for which in range(parts):
            c0, c1, slot, ib = _layout(mode, which, sym[S_ISEL])
            n = _gather(px, sym, s, c0, c1, F, I)
            for c in range(c0, c1):
                I[I_BQ, c] = sym[S_EP + (s * 2) * 4 + c]
                I[I_BQ + 1, c] = sym[S_EP + (s * 2 + 1) * 4 + c]
            I[I_P, 2] = sym[S_P + s * 2] if pbits else 2
            I[I_P, 3] = sym[S_P + s * 2 + 1] if pbits else 2
            _from_best(I, c0, c1)
            best = _evaluate(F, I, n, c0, c1, w, mode, ib, prm.every_index)
            _keep(I, c0, c1, n)
            force_p = flat_alpha & 1 if flat_alpha >= 0 and c1 == 4 and c0 == 0 else -1
            if best > 0.0:
                best = _climb(F, I, n, c0, c1, w, mode, ib, prm, best, force_p)
            err += best
            _store(sym, I, s, c0, c1, slot, n)
    return err


# single-subset modes first: their error lets the estimates skip partitions
MODE_ORDER = (6, 5, 4, 1, 3, 7, 0, 2)


@jit_inner
def search_block(px, w, sw, prm, best, cand, F, I, out, rx):
    """The best symbolic block for texels px (16, 4) into `best` (out: (16, 4)
    uint8 and rx (16, 4) float scratch)."""
    constant = True
    opaque = True
    flat_alpha = np.int64(px[0, 3])
    for i in range(16):
        for c in range(4):
            if px[i, c] != px[0, c]:
                constant = False
        if px[i, 3] != 255.0:
            opaque = False
        if px[i, 3] != px[0, 3]:
            flat_alpha = -1
    if constant:
        _single_colour(px, best)
        return 0.0
    modes = prm.opaque_modes if opaque else prm.alpha_modes
    best_err = 1e300
    penalty = _alpha_penalty(px, w)
    geo_done = np.int64(0)  # rows of _geometry filled for this block
    # every fit reads the texels and weights from rx and rw (rotated for modes
    # 4 and 5), so that its helpers compile for one set of argument types
    rw = F[F_W]
    for mode in MODE_ORDER:
        if not (modes >> mode) & 1:
            continue
        ns = MODES[mode, NS]
        base = penalty if MODES[mode, AB] == 0 else 0.0
        if base >= best_err:
            continue
        rotating = mode == 4 or mode == 5
        if ns > 1:
            row = _geometry_row(mode)
            if not (geo_done >> row) & 1:
                if geo_done == 0:
                    _moments(px, sw, F)
                    _row_sums(F)
                _geometry(F, ns, 4 if MODES[mode, AB] else 3, row)
                geo_done |= np.int64(1) << row
            tries = _top_partitions(mode, prm.partitions, F, I)
        elif rotating:
            # rotation j >> 1 and index selector j & 1 (mode 4), rotation j (mode 5)
            tries = (4 if prm.rotations else 1) * (2 if mode == 4 else 1)
        else:
            tries = 1
        parts = 2 if rotating else 1
        for j in range(tries):
            _clear(cand, mode)
            rot = 0
            if ns > 1:
                if prm.prune and (base + F[F_TOPE, j]) * 100.0 >= best_err * prm.prune:
                    break  # the estimate (in percent of the best error) says the rest cannot win
                cand[S_PART] = I[I_TOP, j]
            elif rotating:
                rot = j >> 1 if mode == 4 else j
                cand[S_ROT] = rot
                cand[S_ISEL] = j & 1 if mode == 4 else 0
            _rotate(px, w, sw, rot, rx, rw)
            e = base
            for k in range(ns * parts):
                e += fit_subset(rx, rw[:4], rw[4:8], prm, cand, k // parts, k % parts, F, I, flat_alpha)
                if e >= best_err:
                    break
            if _accept(e, best_err, cand, flat_alpha, out):
                best_err = e
                _copy(cand, best)
        if mode == 6:
            e = bounding_box_fit(rx, rw[:4], cand, F, I, flat_alpha)  # rx, rw: rotation 0
            if _accept(e, best_err, cand, flat_alpha, out):
                best_err = e
                _copy(cand, best)
    if prm.climb and best_err > 0.0:
        _rotate(px, w, sw, best[S_ROT], rx, rw)
        best_err = _polish(rx, rw[:4], prm, best, F, I, flat_alpha)
    return best_err


@jit
def encode_run(blocks, out, w, sw, rec, syms, errs):
    """Encode blocks (n, 16, 4) uint8 into out (n, 16) uint8. syms (n, SYM_LEN)
    int64 and errs (n,) float64 receive each block's symbolic form before its
    anchors are normalised and its error, when they have n rows (the tests'
    view of the search); the codec passes them empty. One kernel serves both,
    so the search compiles once."""
    prm = rec[0]
    px = np.empty((16, 4))
    best = np.zeros(SYM_LEN, np.int64)
    cand = np.zeros(SYM_LEN, np.int64)
    F = np.zeros((F_ROWS, 64))
    I = np.zeros((I_ROWS, 64), np.int64)
    tmp = np.zeros((16, 4), np.uint8)
    rx = np.zeros((16, 4))
    keep = syms.shape[0] == blocks.shape[0] and errs.shape[0] == blocks.shape[0]
    # views without reference counts (_jit.borrow): the helpers take several
    # arrays and run many times a block; `own` keeps the arrays alive
    own = (px, best, cand, F, I, tmp, rx, w, sw, blocks, out)
    (px, best, cand, F, I, tmp, rx, w, sw, blocks, out) = borrow(own)
    for b in range(blocks.shape[0]):
        for i in range(16):
            for c in range(4):
                px[i, c] = blocks[b, i, c]
        err = search_block(px, w, sw, prm, best, cand, F, I, tmp, rx)
        if keep:
            errs[b] = err
            for k in range(SYM_LEN):
                syms[b, k] = best[k]
        normalise_anchors(best)
        pack(best, out[b])
    return len(own)
