"""BC7 encoder search: fills a symbolic block (bc7_kernels) for each 4x4
block; the bits are packed afterwards. See texcook.codecs.bc7 for the search
and the preset table (`prm`) it reads.

Texels are float64 (16, 4); the error of a candidate is the weighted sum of
squared channel differences of the block as the decoder would return it
(every candidate is measured exactly: its indices are the nearest palette
entries). Ties keep the earlier candidate, so the result depends on nothing
but the block, the weights and the preset.
"""

import numpy as np

from .._jit import jit, jit_inner
from .bc7_kernels import (S_EP, S_IDX, S_ISEL, S_MODE, S_P, S_PART, S_ROT, SYM_LEN, decode_sym, index_sets,
                          normalise_anchors, pack)
from .bc7_tables import AB, CB, EPB, EXPAND, IB, IB2, MODES, NEAREST, NS, PB, SINGLE, SPB, SUBSET, WEIGHTS

# rows of the float scratch F (16 columns each)
F_X = 0  # rows 0-3: the subset's texels, one channel per row
F_E = 4  # rows 4-5: float endpoints (4 channels)
F_V = 6  # the axis (4 channels), then the mean in row 7
F_M = 7
F_PAL = 8  # rows 8-11: palette by channel (16 entries)
F_ROT = 12  # rows 12-15: the rotated block, one channel per row
F_ROWS = 16
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
def _byte(v):
    if v <= 0.0:
        return 0
    if v >= 255.0:
        return 255
    return np.int64(v + 0.5)


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
def _evaluate(F, I, n, c0, c1, w, mode, ib):
    """Error of the candidate in I[I_Q..], p-bits I[I_P, 0..1]; its indices
    (nearest entry, the first on ties) into I[I_IDX]."""
    nidx = np.int64(1) << ib
    for c in range(c0, c1):
        bits = _bits(mode, c)
        e0 = EXPAND[bits, I[I_P, 0], I[I_Q, c]]
        e1 = EXPAND[bits, I[I_P, 1], I[I_Q + 1, c]]
        for j in range(nidx):
            wt = WEIGHTS[ib, j]
            F[F_PAL + c, j] = ((64 - wt) * e0 + wt * e1 + 32) >> 6
    err = 0.0
    for k in range(n):
        best = 1e300
        bj = 0
        for j in range(nidx):
            e = 0.0
            for c in range(c0, c1):
                d = F[F_X + c, k] - F[F_PAL + c, j]
                e += w[c] * d * d
            if e < best:
                best = e
                bj = j
        I[I_IDX, k] = bj
        err += best
    return err


@jit_inner
def _quantise(F, I, c0, c1, mode, p0, p1):
    """Stored channels nearest the float endpoints F[F_E..] with p-bits p0, p1
    (2: the mode has none) into I[I_Q..]."""
    I[I_P, 0] = p0
    I[I_P, 1] = p1
    for c in range(c0, c1):
        bits = _bits(mode, c)
        I[I_Q, c] = NEAREST[bits, p0, _byte(F[F_E, c])]
        I[I_Q + 1, c] = NEAREST[bits, p1, _byte(F[F_E + 1, c])]


@jit_inner
def _quant_error(F, c0, c1, w, mode, e, p):
    """Weighted squared error of float endpoint e stored with p-bit p."""
    err = 0.0
    for c in range(c0, c1):
        bits = _bits(mode, c)
        v = _byte(F[F_E + e, c])
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
def _try(F, I, n, c0, c1, w, mode, ib, prm, best):
    """Quantise the float endpoints F[F_E..] (every p-bit choice the preset
    allows) and measure; the best kept in I's best rows. Returns the best error."""
    pmode = 2 if MODES[mode, EPB] else (1 if MODES[mode, SPB] else 0)
    if pmode == 0:
        _quantise(F, I, c0, c1, mode, 2, 2)
        e = _evaluate(F, I, n, c0, c1, w, mode, ib)
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
        e = _evaluate(F, I, n, c0, c1, w, mode, ib)
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
        e = _evaluate(F, I, n, c0, c1, w, mode, ib)
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
    cov = np.zeros((4, 4))
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
    for _ in range(iters):
        u0 = cov[0, 0] * v0 + cov[0, 1] * v1 + cov[0, 2] * v2 + cov[0, 3] * v3
        u1 = cov[1, 0] * v0 + cov[1, 1] * v1 + cov[1, 2] * v2 + cov[1, 3] * v3
        u2 = cov[2, 0] * v0 + cov[2, 1] * v1 + cov[2, 2] * v2 + cov[2, 3] * v3
        u3 = cov[3, 0] * v0 + cov[3, 1] * v1 + cov[3, 2] * v2 + cov[3, 3] * v3
        m = max(abs(u0), abs(u1), abs(u2), abs(u3))
        if m <= 0.0:
            break
        v0, v1, v2, v3 = u0 / m, u1 / m, u2 / m, u3 / m
    norm = np.sqrt(v0 * v0 + v1 * v1 + v2 * v2 + v3 * v3)
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
def fit_subset(px, w, sw, prm, sym, s, which, F, I):
    """Endpoints, p-bits and indices of subset s of the mode, partition and
    index selector in sym, for the channels `which` names (see _layout),
    written into sym. Returns their error. Principal axis and range fit, then
    least-squares refinement of the endpoints from the indices."""
    mode = sym[S_MODE]
    c0, c1, slot, ib = _layout(mode, which, sym[S_ISEL])
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
    best = _try(F, I, n, c0, c1, w, mode, ib, prm, 1e300)
    for _ in range(prm.ls_iters):
        if not _least_squares(F, I, n, c0, c1, ib):
            break
        e = _try(F, I, n, c0, c1, w, mode, ib, prm, best)
        if not e < best:
            break
        best = e
    for c in range(c0, c1):
        sym[S_EP + (s * 2) * 4 + c] = I[I_BQ, c]
        sym[S_EP + (s * 2 + 1) * 4 + c] = I[I_BQ + 1, c]
    if MODES[mode, EPB] or MODES[mode, SPB]:
        sym[S_P + s * 2] = I[I_P, 2]
        sym[S_P + s * 2 + 1] = I[I_P, 3]
    for k in range(n):
        sym[slot + I[I_MEM, k]] = I[I_BEST, k]
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
def _estimate(px, sw, mode, part, F, I):
    """Quick error estimate of a partition: per subset, the distance of the
    texels from their principal axis plus the rounding of their positions along
    it to the mode's index steps, endpoints unquantised."""
    ns = MODES[mode, NS]
    c1 = 4 if MODES[mode, AB] else 3
    levels = (np.int64(1) << MODES[mode, IB]) - 1
    total = 0.0
    for s in range(ns):
        n = 0
        for i in range(16):
            if SUBSET[ns - 1, part, i] == s:
                for c in range(c1):
                    F[F_X + c, n] = px[i, c]
                n += 1
        _axis(F, n, 0, c1, sw, 2)
        tmin = 1e300
        tmax = -1e300
        for k in range(n):
            t = 0.0
            for c in range(c1):
                t += (F[F_X + c, k] - F[F_M, c]) * sw[c] * F[F_V, c]
            F[F_E, k] = t
            tmin = min(tmin, t)
            tmax = max(tmax, t)
        step = (tmax - tmin) / levels
        for k in range(n):
            t = F[F_E, k]
            r = 0.0
            for c in range(c1):
                d = (F[F_X + c, k] - F[F_M, c]) * sw[c]
                r += d * d
            r -= t * t  # distance from the axis, squared
            if step > 0.0:
                u = (t - tmin) / step
                q = (u - np.floor(u + 0.5)) * step
                r += q * q
            total += max(r, 0.0)
    return total


@jit_inner
def _top_partitions(px, sw, mode, keep, F, I):
    """The `keep` partitions of the mode with the lowest estimates into I[I_TOP]
    (ties: the lower number first). Returns how many."""
    count = np.int64(1) << MODES[mode, PB]
    keep = min(keep, count)
    est = np.empty(64)
    for p in range(count):
        est[p] = _estimate(px, sw, mode, p, F, I)
    for j in range(keep):
        bp = -1
        for p in range(count):
            if est[p] < 1e300 and (bp < 0 or est[p] < est[bp]):
                bp = p
        I[I_TOP, j] = bp
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
    decode_sym(cand, out)
    for i in range(16):
        if out[i, 3] != flat_alpha:
            return False
    return True


@jit_inner
def search_block(px, w, sw, prm, best, cand, F, I, out):
    """The best symbolic block for texels px (16, 4) into `best` (out: (16, 4)
    uint8 scratch)."""
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
    for mode in range(8):
        if not (modes >> mode) & 1:
            continue
        ns = MODES[mode, NS]
        if mode == 4 or mode == 5:
            rw = F[F_ROT + 3]  # the rotated weights, kept beside the rotated texels
            rx = np.empty((16, 4))
            for rot in range(4 if prm.rotations else 1):
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
                for isel in range(2 if mode == 4 else 1):
                    _clear(cand, mode)
                    cand[S_ROT] = rot
                    cand[S_ISEL] = isel
                    e = fit_subset(rx, rw[:4], rw[4:8], prm, cand, 0, 0, F, I)
                    if e < best_err:
                        e += fit_subset(rx, rw[:4], rw[4:8], prm, cand, 0, 1, F, I)
                        if _accept(e, best_err, cand, flat_alpha, out):
                            best_err = e
                            _copy(cand, best)
            continue
        base = penalty if MODES[mode, AB] == 0 else 0.0
        if base >= best_err:
            continue
        if ns == 1:
            _clear(cand, mode)
            e = base + fit_subset(px, w, sw, prm, cand, 0, 0, F, I)
            if _accept(e, best_err, cand, flat_alpha, out):
                best_err = e
                _copy(cand, best)
            continue
        kept = _top_partitions(px, sw, mode, prm.partitions, F, I)
        for j in range(kept):
            part = I[I_TOP, j]
            _clear(cand, mode)
            cand[S_PART] = part
            e = base
            for s in range(ns):
                e += fit_subset(px, w, sw, prm, cand, s, 0, F, I)
                if e >= best_err:
                    break
            if _accept(e, best_err, cand, flat_alpha, out):
                best_err = e
                _copy(cand, best)
    return best_err


@jit
def encode_run(blocks, out, w, sw, rec):
    """Encode blocks (n, 16, 4) uint8 into out (n, 16) uint8."""
    prm = rec[0]
    px = np.empty((16, 4))
    best = np.zeros(SYM_LEN, np.int64)
    cand = np.zeros(SYM_LEN, np.int64)
    F = np.zeros((F_ROWS, 16))
    I = np.zeros((I_ROWS, 64), np.int64)
    tmp = np.zeros((16, 4), np.uint8)
    for b in range(blocks.shape[0]):
        for i in range(16):
            for c in range(4):
                px[i, c] = blocks[b, i, c]
        search_block(px, w, sw, prm, best, cand, F, I, tmp)
        normalise_anchors(best)
        pack(best, out[b])


@jit
def search_run(blocks, syms, errs, w, sw, rec):
    """The symbolic blocks and their errors, before the anchors are normalised (for tests)."""
    prm = rec[0]
    px = np.empty((16, 4))
    cand = np.zeros(SYM_LEN, np.int64)
    F = np.zeros((F_ROWS, 16))
    I = np.zeros((I_ROWS, 64), np.int64)
    tmp = np.zeros((16, 4), np.uint8)
    for b in range(blocks.shape[0]):
        for i in range(16):
            for c in range(4):
                px[i, c] = blocks[b, i, c]
        errs[b] = search_block(px, w, sw, prm, syms[b], cand, F, I, tmp)
