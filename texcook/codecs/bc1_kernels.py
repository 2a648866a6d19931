"""BC1 kernels: the decoder and the colour block search (see texcook.codecs.bc1
for the decoding convention and the search)."""

import numpy as np

from .._jit import borrow, jit, jit_inner
from ._kernels import byte
from .bc1_tables import Q5, Q6, SINGLE, W3, W4

# --------------------------------------------------------------------------
# bit-level helpers and the decoder

# Constant arguments to jitted callees are NumPy scalars, never Python literals:
# numba types a literal by its value and compiles the callee again for each one.
ZERO = np.int64(0)
NO = np.bool_(False)
YES = np.bool_(True)


@jit_inner
def exp5(c):
    return (c << 3) | (c >> 2)


@jit_inner
def exp6(c):
    return (c << 2) | (c >> 4)


@jit_inner
def _palette(c0, c1, pal):
    """pal (4, 3) int64: the colours the documented decoding gives (c0, c1) as u16."""
    r0 = exp5((c0 >> 11) & 31)
    g0 = exp6((c0 >> 5) & 63)
    b0 = exp5(c0 & 31)
    r1 = exp5((c1 >> 11) & 31)
    g1 = exp6((c1 >> 5) & 63)
    b1 = exp5(c1 & 31)
    pal[0, 0] = r0
    pal[0, 1] = g0
    pal[0, 2] = b0
    pal[1, 0] = r1
    pal[1, 1] = g1
    pal[1, 2] = b1
    if c0 > c1:
        pal[2, 0] = (2 * r0 + r1) // 3
        pal[2, 1] = (2 * g0 + g1) // 3
        pal[2, 2] = (2 * b0 + b1) // 3
        pal[3, 0] = (r0 + 2 * r1) // 3
        pal[3, 1] = (g0 + 2 * g1) // 3
        pal[3, 2] = (b0 + 2 * b1) // 3
    else:
        pal[2, 0] = (r0 + r1) // 2
        pal[2, 1] = (g0 + g1) // 2
        pal[2, 2] = (b0 + b1) // 2
        pal[3, 0] = 0
        pal[3, 1] = 0
        pal[3, 2] = 0


@jit_inner
def decode_colour_block(d, o, out, punch, pal):
    """Decode the 8 colour bytes d[o:o+8] into out (16, 4) uint8. punch: index 3 of
    the 3-colour mode is transparent black (BC1A) instead of opaque black.
    pal: (4, 3) int64 scratch."""
    c0 = np.int64(d[o]) | (np.int64(d[o + 1]) << 8)
    c1 = np.int64(d[o + 2]) | (np.int64(d[o + 3]) << 8)
    bits = (
        np.int64(d[o + 4])
        | (np.int64(d[o + 5]) << 8)
        | (np.int64(d[o + 6]) << 16)
        | (np.int64(d[o + 7]) << 24)
    )
    _palette(c0, c1, pal)
    for i in range(16):
        s = (bits >> (2 * i)) & 3
        out[i, 0] = pal[s, 0]
        out[i, 1] = pal[s, 1]
        out[i, 2] = pal[s, 2]
        out[i, 3] = 0 if (punch and s == 3 and c0 <= c1) else 255


@jit
def decode_run(data, out, punch):
    pal = np.empty((4, 3), np.int64)
    for b in range(data.shape[0]):
        decode_colour_block(data[b], ZERO, out[b], punch, pal)


# --------------------------------------------------------------------------
# encoder pieces
#
# A block's working data is two small arrays, F (float64) and I (int64), with
# the named rows below (NumPy integers: a Python int passed to a jitted
# function is a literal, and numba compiles the callee once per value); everything else travels as scalars and tuples. Numba
# reference-counts every array a function takes or unpacks, which costs more
# than the arithmetic of a fast block, so the pieces pass these two around and
# return (error, c0, c1) instead of writing the best so far into arrays.
# Texel values are integers, so with unit weights every sum and error is exact.
#
# The search's pieces take three tuples (scalars and arrays to numba, with no
# cost over passing their items one by one):
#   ws     (F, I): one thread's working arrays (colour_scratch);
#   block  (n, w, xx, black): the block's opaque texel count, the channel
#          weights (r, g, b), the weighted sum of its texels' |x|^2, and
#          whether the 3-colour black entry may stand for a colour;
#   best   (error, c0, c1): the best endpoints so far, whose indices are in
#          I[_I_B]; a piece returns the new best.
# Per-preset settings come from the preset record prm (SEARCH.record()[0]).

_F_PX = np.int64(0)  # rows 0-2: the block's opaque texels, one channel per row
_F_PROJ = np.int64(3)  # projection of each texel on the axis
_F_PRE = np.int64(4)  # rows 4-6: prefix sums of the texels in axis order (17 columns)
_F_TOP = np.int64(7)  # errors of the best distinct candidates of the exact cluster fit
_F_ERR = np.int64(8)  # each texel's error in _eval
_F_ROWS = np.int64(9)
_I_T = np.int64(0)  # indices of the candidate just measured
_I_L = np.int64(1)  # indices of the current refinement point
_I_B = np.int64(2)  # indices of the best candidate so far
_I_POS = np.int64(3)  # position in the block of each opaque texel
_I_ORD = np.int64(4)  # texels in axis order
_I_TOP = np.int64(5)  # their endpoint pairs, c0 << 16 | c1
_I_SAVE = np.int64(6)  # the best indices while a climb starts elsewhere
_I_ROWS = np.int64(7)


@jit_inner
def quant565(r, g, b):
    return (Q5[byte(r)] << 11) | (Q6[byte(g)] << 5) | Q5[byte(b)]


@jit
def _eval(F, I, row, n, w, xx, c0, c1, nsel):
    """Weighted squared error of the block decoded from (c0, c1), each texel
    taking the nearest of the first nsel palette entries (the first on ties);
    indices into I[row]. Exact for the documented decoding: |x - q|^2 is
    |x|^2 + (|q|^2 - 2 x.q) and the block's sum of |x|^2 is xx, so a texel
    costs one dot product per entry."""
    r0 = exp5((c0 >> 11) & 31)
    g0 = exp6((c0 >> 5) & 63)
    b0 = exp5(c0 & 31)
    r1 = exp5((c1 >> 11) & 31)
    g1 = exp6((c1 >> 5) & 63)
    b1 = exp5(c1 & 31)
    if c0 > c1:
        r2, g2, b2 = (2 * r0 + r1) // 3, (2 * g0 + g1) // 3, (2 * b0 + b1) // 3
        r3, g3, b3 = (r0 + 2 * r1) // 3, (g0 + 2 * g1) // 3, (b0 + 2 * b1) // 3
    else:
        r2, g2, b2 = (r0 + r1) // 2, (g0 + g1) // 2, (b0 + b1) // 2
        r3, g3, b3 = 0, 0, 0
    w0 = 2.0 * w[0]
    w1 = 2.0 * w[1]
    w2 = 2.0 * w[2]
    # entry j scores h_j - x . a_j
    a00, a01, a02 = w0 * r0, w1 * g0, w2 * b0
    a10, a11, a12 = w0 * r1, w1 * g1, w2 * b1
    a20, a21, a22 = w0 * r2, w1 * g2, w2 * b2
    a30, a31, a32 = w0 * r3, w1 * g3, w2 * b3
    h0 = 0.5 * (a00 * r0 + a01 * g0 + a02 * b0)
    h1 = 0.5 * (a10 * r1 + a11 * g1 + a12 * b1)
    h2 = 0.5 * (a20 * r2 + a21 * g2 + a22 * b2)
    h3 = 0.5 * (a30 * r3 + a31 * g3 + a32 * b3)
    if nsel < 4:
        h3 = 1e300
    # branch-free selects and the texel errors stored, then summed in order:
    # a loop without a floating-point reduction can be vectorised
    for i in range(n):
        x0 = F[0, i]
        x1 = F[1, i]
        x2 = F[2, i]
        e0 = h0 - (x0 * a00 + x1 * a01 + x2 * a02)
        e1 = h1 - (x0 * a10 + x1 * a11 + x2 * a12)
        e2 = h2 - (x0 * a20 + x1 * a21 + x2 * a22)
        e3 = h3 - (x0 * a30 + x1 * a31 + x2 * a32)
        m1 = e1 < e0
        e01 = e1 if m1 else e0
        i01 = 1 if m1 else 0
        m3 = e3 < e2
        e23 = e3 if m3 else e2
        i23 = 3 if m3 else 2
        m = e23 < e01
        F[_F_ERR, i] = e23 if m else e01
        I[row, i] = i23 if m else i01
    err = xx
    for i in range(n):
        err += F[_F_ERR, i]
    return err


@jit_inner
def _order(a, b, three):
    """(c0, c1, nsel) for endpoints a, b in the wanted mode."""
    if three:
        if a <= b:
            return a, b, 3
        return b, a, 3
    if a == b:
        # equal endpoints decode as 3-colour; entries 0-2 are all that colour
        return a, b, 3
    if a > b:
        return a, b, 4
    return b, a, 4


@jit_inner
def _keep(I, n, row):
    for i in range(n):
        I[_I_B, i] = I[row, i]


@jit_inner
def _measure(ws, block, a, b, three):
    """(error, c0, c1) of endpoints (a, b) in a mode, indices in I[_I_T]."""
    F, I = ws
    n, w, xx, black = block
    c0, c1, nsel = _order(a, b, three)
    if three and black:
        nsel = 4
    return _eval(F, I, _I_T, n, w, xx, c0, c1, nsel), c0, c1


@jit_inner
def _try(ws, block, a, b, three, best):
    """Measure endpoints (a, b) in a mode; the better of them and the best so far."""
    err, c0, c1 = _measure(ws, block, a, b, three)
    if err < best[0]:
        _keep(ws[1], block[0], _I_T)
        return err, c0, c1
    return best


@jit
def _ls_endpoints(F, I, row, n, three):
    """Least-squares endpoints for the indices in I[row]: (ok, c0 rgb, c1 rgb),
    ok False when the system is singular. Black texels (3-colour index 3) are
    left out. Weights are small integers (c0 gets a/d, c1 (d-a)/d), so only a,
    a^2, a*x and x are summed per texel; the rest follows from the counts."""
    d = 2.0 if three else 3.0
    cnt = 0.0
    sa = 0.0
    saa = 0.0
    ax0 = ax1 = ax2 = 0.0
    sx0 = sx1 = sx2 = 0.0
    for i in range(n):
        s = I[row, i]
        if three:
            if s == 3:
                continue
            a = W3[s]
        else:
            a = W4[s]
        x0 = F[0, i]
        x1 = F[1, i]
        x2 = F[2, i]
        cnt += 1.0
        sa += a
        saa += a * a
        ax0 += a * x0
        ax1 += a * x1
        ax2 += a * x2
        sx0 += x0
        sx1 += x1
        sx2 += x2
    # with b = d - a: sums of b^2, a*b and b*x
    aa = saa
    bb = cnt * d * d - 2.0 * d * sa + saa
    abx = d * sa - saa
    det = aa * bb - abx * abx
    if abs(det) < 1e-9:
        return False, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    bx0 = d * sx0 - ax0
    bx1 = d * sx1 - ax1
    bx2 = d * sx2 - ax2
    # solving with the integer weights scales the solution by 1/d
    f = d / det
    return (True,
            (ax0 * bb - bx0 * abx) * f, (ax1 * bb - bx1 * abx) * f, (ax2 * bb - bx2 * abx) * f,
            (bx0 * aa - ax0 * abx) * f, (bx1 * aa - ax1 * abx) * f, (bx2 * aa - ax2 * abx) * f)


@jit_inner
def _refine(ws, block, a, b, three, iters, best):
    """Measure (a, b), then re-solve the endpoints from the indices by least
    squares while that keeps lowering the error. Returns the best (error, c0, c1)."""
    F, I = ws
    n, w, xx, black = block
    berr, bc0, bc1 = best
    c0, c1, nsel = _order(a, b, three)
    if three and black:
        nsel = 4
    err = _eval(F, I, _I_L, n, w, xx, c0, c1, nsel)
    if err < berr:
        berr, bc0, bc1 = err, c0, c1
        _keep(I, n, _I_L)
    for _ in range(iters):
        if err <= 0.0:
            break
        ok, a0, a1, a2, b0, b1, b2 = _ls_endpoints(F, I, _I_L, n, three and c0 <= c1)
        if not ok:
            break
        d0, d1, ns = _order(quant565(a0, a1, a2), quant565(b0, b1, b2), three)
        if d0 == c0 and d1 == c1:
            # same pair again: same indices, nothing more to gain
            break
        if three and black:
            ns = 4
        e2 = _eval(F, I, _I_T, n, w, xx, d0, d1, ns)
        if e2 < berr:
            berr, bc0, bc1 = e2, d0, d1
            _keep(I, n, _I_T)
        if e2 >= err:
            break
        err = e2
        c0 = d0
        c1 = d1
        for i in range(n):
            I[_I_L, i] = I[_I_T, i]
    return berr, bc0, bc1


@jit_inner
def _principal_axis(mom, n, sw, iters):
    """(ok, mean, axis) of the weighted texels (q = x * sw) from the block's
    moments mom (sums of r, g, b, rr, rg, rb, gg, gb, bb); ok False if the
    texels are all one colour."""
    s0, s1, s2, m00, m01, m02, m11, m12, m22 = mom
    inv = 1.0 / n
    mean = (s0 * inv * sw[0], s1 * inv * sw[1], s2 * inv * sw[2])
    c00 = (m00 - s0 * s0 * inv) * sw[0] * sw[0]
    c01 = (m01 - s0 * s1 * inv) * sw[0] * sw[1]
    c02 = (m02 - s0 * s2 * inv) * sw[0] * sw[2]
    c11 = (m11 - s1 * s1 * inv) * sw[1] * sw[1]
    c12 = (m12 - s1 * s2 * inv) * sw[1] * sw[2]
    c22 = (m22 - s2 * s2 * inv) * sw[2] * sw[2]
    if c00 + c11 + c22 < 1e-9:
        return False, mean, (0.0, 0.0, 0.0)
    # start from the covariance row with the largest diagonal: never orthogonal
    # to the principal axis unless the spread is isotropic
    if c00 >= c11 and c00 >= c22:
        v0, v1, v2 = c00, c01, c02
    elif c11 >= c22:
        v0, v1, v2 = c01, c11, c12
    else:
        v0, v1, v2 = c02, c12, c22
    for _ in range(iters):
        t0 = c00 * v0 + c01 * v1 + c02 * v2
        t1 = c01 * v0 + c11 * v1 + c12 * v2
        t2 = c02 * v0 + c12 * v1 + c22 * v2
        m = max(abs(t0), abs(t1), abs(t2))
        if m < 1e-30:
            break
        m = 1.0 / m
        v0, v1, v2 = t0 * m, t1 * m, t2 * m
    nrm = np.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    if nrm < 1e-30:
        return False, mean, (0.0, 0.0, 0.0)
    nrm = 1.0 / nrm
    return True, mean, (v0 * nrm, v1 * nrm, v2 * nrm)


@jit_inner
def _range_fit(F, n, sw, mean, axis):
    """Endpoints (c0 rgb, c1 rgb) at the extreme projections of the texels on
    the axis through the mean, c0 at the high end. Only min and max: no sort."""
    k0 = sw[0] * axis[0]
    k1 = sw[1] * axis[1]
    k2 = sw[2] * axis[2]
    lo = 1e300
    hi = -1e300
    for i in range(n):
        p = F[0, i] * k0 + F[1, i] * k1 + F[2, i] * k2
        lo = min(lo, p)
        hi = max(hi, p)
    pm = mean[0] * axis[0] + mean[1] * axis[1] + mean[2] * axis[2]
    hi -= pm
    lo -= pm
    return ((mean[0] + hi * axis[0]) / sw[0], (mean[1] + hi * axis[1]) / sw[1], (mean[2] + hi * axis[2]) / sw[2],
            (mean[0] + lo * axis[0]) / sw[0], (mean[1] + lo * axis[1]) / sw[1], (mean[2] + lo * axis[2]) / sw[2])


@jit_inner
def _sort_along(F, I, n, sw, mean, axis):
    """Texel order along the axis into I[_I_ORD] (for the cluster fit)."""
    for i in range(n):
        F[_F_PROJ, i] = (
            (F[0, i] * sw[0] - mean[0]) * axis[0]
            + (F[1, i] * sw[1] - mean[1]) * axis[1]
            + (F[2, i] * sw[2] - mean[2]) * axis[2]
        )
        I[_I_ORD, i] = i
    # insertion sort: n <= 16
    for i in range(1, n):
        k = I[_I_ORD, i]
        v = F[_F_PROJ, k]
        j = i - 1
        while j >= 0 and F[_F_PROJ, I[_I_ORD, j]] > v:
            I[_I_ORD, j + 1] = I[_I_ORD, j]
            j -= 1
        I[_I_ORD, j + 1] = k


@jit_inner
def _cluster_fit(ws, block, m, three, exact, best, ntop, ktop):
    """Cluster fit over the first m texels in axis order (I[_I_ORD]; the rest
    are left to the 3-colour black) and measured on all n. Every ordered
    split into 4 groups (weights 1, 2/3, 1/3, 0) or 3 groups (1, 1/2, 0) gets
    least-squares endpoints. exact: quantise and measure every split (each
    kept in the top list of ktop pairs, ntop long); else find the split with
    the smallest estimated error. Returns (found, its (c0 rgb, c1 rgb), the
    best, the top list's length)."""
    F, I = ws
    n, w = block[0], block[1]
    berr, bc0, bc1 = best
    # prefix sums of sorted texels
    for c in range(3):
        F[_F_PRE + c, 0] = 0.0
    for i in range(m):
        k = I[_I_ORD, i]
        for c in range(3):
            F[_F_PRE + c, i + 1] = F[_F_PRE + c, i] + F[c, k]
    best_est = 1e300
    found = False
    if three:
        g1 = 0.5
        g2 = 0.5
    else:
        g1 = 2.0 / 3.0
        g2 = 1.0 / 3.0
    la = -1
    lb = -1
    e0 = e1 = e2 = e3 = e4 = e5 = 0.0
    for s1 in range(m + 1):
        for s2 in range(s1, m + 1):
            lo3 = s2 if not three else m
            for s3 in range(lo3, m + 1):
                # groups [0,s1) w=1, [s1,s2) g1, [s2,s3) g2, [s3,m) 0; in
                # 3-colour mode s3 == m and groups 2 and 3 merge into weight 1/2
                if three:
                    n1 = s1
                    n2 = s2 - s1
                    n3 = 0
                    n4 = m - s2
                else:
                    n1 = s1
                    n2 = s2 - s1
                    n3 = s3 - s2
                    n4 = m - s3
                aa = n1 + n2 * g1 * g1 + n3 * g2 * g2
                bb = n4 + n2 * (1 - g1) * (1 - g1) + n3 * (1 - g2) * (1 - g2)
                abx = n2 * g1 * (1 - g1) + n3 * g2 * (1 - g2)
                det = aa * bb - abx * abx
                if abs(det) < 1e-9:
                    continue
                f = 1.0 / det
                est = 0.0
                ca0 = ca1 = ca2 = cb0 = cb1 = cb2 = 0.0
                for c in range(3):
                    p1 = F[_F_PRE + c, s1]
                    p2 = F[_F_PRE + c, s2] - p1
                    if three:
                        p3 = 0.0
                    else:
                        p3 = F[_F_PRE + c, s3] - F[_F_PRE + c, s2]
                    tot = F[_F_PRE + c, m]
                    ax = p1 + g1 * p2 + g2 * p3
                    bx = tot - ax
                    a = (ax * bb - bx * abx) * f
                    b = (bx * aa - ax * abx) * f
                    if c == 0:
                        ca0, cb0 = a, b
                    elif c == 1:
                        ca1, cb1 = a, b
                    else:
                        ca2, cb2 = a, b
                    est += w[c] * (a * a * aa + b * b * bb + 2.0 * a * b * abx - 2.0 * a * ax - 2.0 * b * bx)
                if exact:
                    qa = quant565(ca0, ca1, ca2)
                    qb = quant565(cb0, cb1, cb2)
                    # neighbouring splits often quantise to the same pair
                    if qa != la or qb != lb:
                        la = qa
                        lb = qb
                        err, c0, c1 = _measure(ws, block, qa, qb, three)
                        if err < berr:
                            berr, bc0, bc1 = err, c0, c1
                            _keep(I, n, _I_T)
                        ntop = _top_insert(F, I, ntop, ktop, err, c0, c1)
                elif est < best_est:
                    best_est = est
                    found = True
                    e0, e1, e2, e3, e4, e5 = ca0, ca1, ca2, cb0, cb1, cb2
    return found, (e0, e1, e2, e3, e4, e5), (berr, bc0, bc1), ntop


@jit
def _top_insert(F, I, ntop, ktop, err, c0, c1):
    """Keep the ktop lowest-error distinct pairs, sorted; returns the count."""
    if ktop == 0:
        return 0
    key = (c0 << 16) | c1
    for j in range(ntop):
        if I[_I_TOP, j] == key:
            return ntop
    if ntop == ktop and err >= F[_F_TOP, ntop - 1]:
        return ntop
    j = min(ntop, ktop - 1)
    while j > 0 and F[_F_TOP, j - 1] > err:
        F[_F_TOP, j] = F[_F_TOP, j - 1]
        I[_I_TOP, j] = I[_I_TOP, j - 1]
        j -= 1
    F[_F_TOP, j] = err
    I[_I_TOP, j] = key
    return min(ntop + 1, ktop)


@jit_inner
def _climb(ws, block, passes, wide, three_ok, best):
    """Hill-climb over the quantised endpoints: move one channel of one endpoint
    (or of both the same way; wide: also opposite ways) by one level, keep any
    move that lowers the measured error."""
    berr, bc0, bc1 = best
    for _ in range(passes):
        if berr <= 0.0:
            break
        improved = False
        c0 = bc0
        c1 = bc1
        three = c0 <= c1 and c0 != c1
        if three and not three_ok:
            three = False
        for e in range(4 if wide else 3):  # move 0: c0, 1: c1, 2: both the same way, 3: apart
            for ch in range(3):
                if ch == 1:
                    sh, mx = 5, 63
                elif ch == 0:
                    sh, mx = 11, 31
                else:
                    sh, mx = 0, 31
                for dlt in (-1, 1):
                    a = c0
                    b = c1
                    ok = True
                    if e != 1:
                        v = ((a >> sh) & mx) + dlt
                        if v < 0 or v > mx:
                            ok = False
                        a = (a & ~(mx << sh)) | (v << sh)
                    if e >= 1:
                        v = ((b >> sh) & mx) + (-dlt if e == 3 else dlt)
                        if v < 0 or v > mx:
                            ok = False
                        b = (b & ~(mx << sh)) | (v << sh)
                    if not ok:
                        continue
                    before = berr
                    berr, bc0, bc1 = _try(ws, block, a, b, three, (berr, bc0, bc1))
                    if berr < before:
                        improved = True
        if not improved:
            break
    return berr, bc0, bc1


@jit_inner
def _single_colour(ws, block, rgb, three, best):
    """Endpoints from the single-colour tables for one colour (r, g, b)."""
    m = 1 if three else 0
    ri = byte(rgb[0])
    gi = byte(rgb[1])
    bi = byte(rgb[2])
    hi = (SINGLE[m, 0, ri, 0] << 11) | (SINGLE[m, 1, gi, 0] << 5) | SINGLE[m, 0, bi, 0]
    lo = (SINGLE[m, 0, ri, 1] << 11) | (SINGLE[m, 1, gi, 1] << 5) | SINGLE[m, 0, bi, 1]
    return _try(ws, block, hi, lo, three, best)


@jit_inner
def _cluster_search(ws, block, sw, line, prm, only_three, use_three, best):
    """Cluster fits over the texels sorted along the axis line (mean, axis):
    in each allowed mode, each result refined; then, when exact (prm.cluster
    2) and the black entry is usable, 3-colour fits with the darkest
    1..prm.dark texels left to black, which the plain fit never does: dark
    texels then stop pulling the two endpoints down. Returns the best
    (error, c0, c1) and the top-list count.

    One function for both rounds: numba compiles each callee into every
    caller, so two would each carry their own copy of the cluster fit."""
    F, I = ws
    n, w, black = block[0], block[1], block[3]
    berr, bc0, bc1 = best
    exact = prm.cluster > 1
    ls = prm.ls_iters
    ktop = min(16, prm.starts)
    _sort_along(F, I, n, sw, line[0], line[1])
    ntop = ZERO
    for mi in range(2 if use_three else 1):
        three = mi == 1 or only_three
        if mi == 0 and only_three:
            continue
        found, ends, (berr, bc0, bc1), ntop = _cluster_fit(ws, block, n, three, exact, (berr, bc0, bc1), ntop, ktop)
        if found:
            a0, a1, a2, b0, b1, b2 = ends
            berr, bc0, bc1 = _refine(ws, block, quant565(a0, a1, a2), quant565(b0, b1, b2), three, ls,
                                     (berr, bc0, bc1))
        elif exact:
            berr, bc0, bc1 = _refine(ws, block, bc0, bc1, three, ls, (berr, bc0, bc1))
    if not (use_three and black and exact):
        return berr, bc0, bc1, ntop
    # the dark rounds (the fits above read the axis order, never change it)
    m = n
    for _ in range(prm.dark):
        # drop the darkest texel still in the order
        dk = 0
        dv = 1e300
        for j in range(m):
            t = I[_I_ORD, j]
            v = w[0] * F[0, t] * F[0, t] + w[1] * F[1, t] * F[1, t] + w[2] * F[2, t] * F[2, t]
            if v < dv:
                dv = v
                dk = j
        if m < 3 or dv > 3.0 * 64.0 * 64.0:
            break
        for j in range(dk, m - 1):
            I[_I_ORD, j] = I[_I_ORD, j + 1]
        m -= 1
        # exact: every split is measured, nothing to refine afterwards
        res = _cluster_fit(ws, block, m, YES, YES, (berr, bc0, bc1), ntop, ktop)
        berr, bc0, bc1 = res[2]
        ntop = res[3]
    return berr, bc0, bc1, ntop


@jit_inner
def _flat(ws, block, only_three, three_ok):
    """(c0, c1) for a block of one colour: its nearest 565 pair, then the
    single-colour tables (indices in I[_I_B])."""
    F = ws[0]
    berr = 1e300
    bc0 = np.int64(0)
    bc1 = np.int64(0)
    # mode flags as typed booleans rather than literals: numba compiles a
    # callee once per literal argument value, which costs compile time
    no = block[0] < 0
    yes = not no
    rgb = (F[0, 0], F[1, 0], F[2, 0])
    q = quant565(rgb[0], rgb[1], rgb[2])
    berr, bc0, bc1 = _try(ws, block, q, q, only_three, (berr, bc0, bc1))
    if not only_three:
        berr, bc0, bc1 = _single_colour(ws, block, rgb, no, (berr, bc0, bc1))
    if three_ok:
        # cheap here, and some flat colours are only reachable as a 3-colour midpoint
        berr, bc0, bc1 = _single_colour(ws, block, rgb, yes, (berr, bc0, bc1))
    return bc0, bc1


@jit_inner
def _climbs(ws, block, ntop, prm, use_three, best):
    """Climb (prm.climb passes, prm.wide moves) from the best pair, then again
    from each of the ntop next-best cluster-fit pairs in the top list: they
    reach optima the first climb cannot reach one step at a time."""
    F, I = ws
    n = block[0]
    passes = prm.climb
    wide = prm.wide != 0
    berr, bc0, bc1 = _climb(ws, block, passes, wide, use_three, best)
    for k in range(ntop):
        if berr <= 0.0:
            break
        a = I[_I_TOP, k] >> 16
        b = I[_I_TOP, k] & 0xFFFF
        if a == bc0 and b == bc1:
            continue
        for i in range(n):
            I[_I_SAVE, i] = I[_I_B, i]
        lerr, l0, l1 = _climb(ws, block, passes, wide, use_three, (F[_F_TOP, k], a, b))
        if lerr < berr:
            berr, bc0, bc1 = lerr, l0, l1
        else:
            for i in range(n):
                I[_I_B, i] = I[_I_SAVE, i]
    return berr, bc0, bc1


@jit_inner
def _gather(blk, thr, F, I):
    """One pass over a block (16, 4): its opaque texels into F (positions in
    I[_I_POS]), their count, whether they are all one colour, and their
    moments (sums of r, g, b, rr, rg, rb, gg, gb, bb)."""
    n = np.int64(0)
    s0 = s1 = s2 = m00 = m01 = m02 = m11 = m12 = m22 = 0
    r0 = np.int64(blk[0, 0])
    g0 = np.int64(blk[0, 1])
    b0 = np.int64(blk[0, 2])
    uniform = n == 0  # True, typed as a boolean rather than a literal (see _flat)
    for i in range(16):
        if thr > 0 and blk[i, 3] < thr:
            continue
        r = np.int64(blk[i, 0])
        g = np.int64(blk[i, 1])
        b = np.int64(blk[i, 2])
        if n == 0:
            r0, g0, b0 = r, g, b
        elif r != r0 or g != g0 or b != b0:
            uniform = False
        F[0, n] = r
        F[1, n] = g
        F[2, n] = b
        I[_I_POS, n] = i
        s0 += r
        s1 += g
        s2 += b
        m00 += r * r
        m01 += r * g
        m02 += r * b
        m11 += g * g
        m12 += g * b
        m22 += b * b
        n += 1
    mom = (np.float64(s0), np.float64(s1), np.float64(s2), np.float64(m00), np.float64(m01),
           np.float64(m02), np.float64(m11), np.float64(m12), np.float64(m22))
    return n, uniform, mom


def colour_scratch():
    """The (F, I) working arrays of encode_colour_run, made by the caller:
    numba's own array allocation compiles several library routines, about
    half a second of every cold start."""
    return np.zeros((_F_ROWS, 17)), np.zeros((_I_ROWS, 16), np.int64)


def _colour_run_kernel(cluster):
    """encode_colour_run for the presets with the cluster fit (cluster=True)
    or for those without. Two kernels from one source: numba drops the branch
    on the constant, so a bake whose preset has no cluster fit (the default
    one included) never compiles it, about a third of the encoder's cold
    compile. numba caches the two apart (its key hashes the closure's
    constants)."""

    @jit
    def encode_colour_run(blocks, out, o, w, sw, rec, thr, three_ok, black_ok, F, I):
        """Encode the colour of each block (blocks (n, 16, 4) uint8) into
        out[b, o:o+8]; BC1 writes at 0, BC3 at 8. thr > 0: BC1A, texels with
        alpha < thr are transparent (3-colour index 3). three_ok: the 3-colour
        mode may be used; black_ok: its black entry may be used as a colour.
        F, I: working arrays from colour_scratch(), one pair per thread; rec:
        SEARCH.record(preset).

        A whole run is one kernel rather than a per-block function called from
        one: numba compiles every callee into each caller, so a per-block layer
        between the run and the search would compile the search twice."""
        # weights and settings as tuples: scalars to numba, no reference counting
        wt = (w[0], w[1], w[2])
        swt = (sw[0], sw[1], sw[2])
        prm = rec[0]
        ls = prm.ls_iters
        # borrowed views: the pieces pass them on without reference counting
        # (F and I, the arguments, outlive them)
        ws = borrow((F, I))
        for blk_i in range(blocks.shape[0]):
            blk = blocks[blk_i]
            n, uniform, mom = _gather(blk, thr, F, I)
            holes = n < 16
            c0 = np.int64(0)
            c1 = np.int64(0)
            bits = np.int64(0)
            if n > 0:
                # blocks with transparent texels must use the 3-colour mode
                use_three = three_ok and (holes or prm.three_colour != 0)
                black = black_ok and not holes
                xx = wt[0] * mom[3] + wt[1] * mom[6] + wt[2] * mom[8]
                block = (n, wt, xx, black)
                if uniform:
                    c0, c1 = _flat(ws, block, holes, three_ok)
                else:
                    # the search: fits along the principal axis, then climbing
                    berr = 1e300
                    c0 = ZERO
                    c1 = ZERO
                    ntop = ZERO
                    have_axis, mean, axis = _principal_axis(mom, n, swt, prm.power_iters)
                    if have_axis:
                        a0, a1, a2, b0, b1, b2 = _range_fit(F, n, swt, mean, axis)
                        qa = quant565(a0, a1, a2)
                        qb = quant565(b0, b1, b2)
                        if not holes:
                            berr, c0, c1 = _refine(ws, block, qa, qb, NO, ls, (berr, c0, c1))
                        if use_three and berr > 0.0:
                            berr, c0, c1 = _refine(ws, block, qa, qb, YES, ls, (berr, c0, c1))
                        if cluster and prm.cluster > 0 and berr > 0.0:
                            berr, c0, c1, ntop = _cluster_search(ws, block, swt, (mean, axis), prm, holes,
                                                                 use_three, (berr, c0, c1))
                    if (prm.mean_colour != 0 or not have_axis) and berr > 0.0:
                        mean_rgb = (mom[0] / n, mom[1] / n, mom[2] / n)
                        if not holes:
                            berr, c0, c1 = _single_colour(ws, block, mean_rgb, NO, (berr, c0, c1))
                        if use_three:
                            berr, c0, c1 = _single_colour(ws, block, mean_rgb, YES, (berr, c0, c1))
                    if prm.climb > 0:
                        berr, c0, c1 = _climbs(ws, block, ntop, prm, use_three, (berr, c0, c1))
                    if holes and c0 > c1:
                        # cannot happen (every candidate was ordered for 3-colour) but a
                        # transparent texel must never decode opaque
                        c0, c1 = c1, c0
                for k in range(n):
                    bits |= I[_I_B, k] << (2 * I[_I_POS, k])
            if holes:
                for i in range(16):
                    if blk[i, 3] < thr:
                        bits |= np.int64(3) << (2 * i)
            d = out[blk_i]
            d[o] = c0 & 255
            d[o + 1] = (c0 >> 8) & 255
            d[o + 2] = c1 & 255
            d[o + 3] = (c1 >> 8) & 255
            d[o + 4] = bits & 255
            d[o + 5] = (bits >> 8) & 255
            d[o + 6] = (bits >> 16) & 255
            d[o + 7] = (bits >> 24) & 255

    return encode_colour_run


_RUN_PLAIN = _colour_run_kernel(False)
_RUN_CLUSTER = _colour_run_kernel(True)


def encode_colour_run(blocks, out, o, w, sw, rec, thr, three_ok, black_ok, F, I):
    """The colour kernel the preset record rec needs (see _colour_run_kernel)."""
    run = _RUN_CLUSTER if rec["cluster"][0] > 0 else _RUN_PLAIN
    run(blocks, out, o, w, sw, rec, thr, three_ok, black_ok, F, I)


def colour_run(blocks, out, o, w, sw, rec, thr, three_ok, black_ok):
    """encode_colour_run with working arrays of its own: run_chunked calls this
    from several threads at once. A quick preset goes to bc1_quick instead."""
    prm = rec[0]
    if prm.quick:
        from .bc1_quick import quick_blocks  # here: bc1_quick imports this module

        quick_blocks(blocks, out, o, w, sw, np.int64(prm.power_iters), np.int64(prm.ls_iters), thr, three_ok)
        return
    encode_colour_run(blocks, out, o, w, sw, rec, thr, three_ok, black_ok, *colour_scratch())
