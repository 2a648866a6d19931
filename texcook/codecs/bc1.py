"""BC1 (DXT1): 4x4 blocks of 8 bytes, two RGB565 endpoints and 2-bit indices.

Decoding convention
-------------------
Endpoints expand to 8 bits by bit replication; the interpolated colours are
computed on the 8-bit values with truncating integer division:

    c0 > c1 (as u16):  c2 = (2*c0 + c1) // 3,  c3 = (c0 + 2*c1) // 3
    c0 <= c1:          c2 = (c0 + c1) // 2,    c3 = black (transparent in BC1A)

This is the exact KDF formula rounded down, the rule texture2ddecoder
implements (checked bit for bit in the tests). It is no single GPU vendor's:
NVIDIA hardware interpolates from the 5/6-bit values and AMD uses
(43*a + 21*b + 32) >> 6, so on those GPUs a texel can differ by one or two
levels. The encoder measures every candidate with this decoding, so it is
the one the encoder optimises for.

Encoder
-------
A block is searched for a pair of 565 endpoints and a mode; the search grows
with the preset (see ``PRESET_TABLE``):

- constant colours use tables of the best endpoint pair for each 8-bit value
  and channel width (per mode), so a flat colour comes back as close as BC1
  allows;
- principal axis by power iteration, range fit along it;
- least-squares refinement of the endpoints from the chosen indices
  (repeated while it helps);
- cluster fit: every ordered split of the texels sorted along the axis into
  4 (or 3) groups, endpoints solved by least squares for each;
- hill climbing over the quantised endpoints (one 565 step at a time), each
  candidate measured with the exact decoding above.

The 3-colour mode (c0 <= c1) is tried per block when the preset allows and
kept when it lowers the error; in plain BC1 its black entry is usable as a
fourth colour, in BC1A it marks transparent texels (alpha < threshold).

Error is a weighted sum of squared channel differences; ``weights=(r, g, b)``
changes it. The default is (1, 1, 1), which maximises RGB PSNR.
"""

from dataclasses import dataclass

import numpy as np

from .._jit import jit
from ..errors import UsageError
from ._base import Codec, run_chunked

# --------------------------------------------------------------------------
# bit-level helpers and the decoder


@jit
def _exp5(c):
    return (c << 3) | (c >> 2)


@jit
def _exp6(c):
    return (c << 2) | (c >> 4)


@jit
def _palette(c0, c1, pal):
    """pal (4, 3) int64: the colours the documented decoding gives (c0, c1) as u16."""
    r0 = _exp5((c0 >> 11) & 31)
    g0 = _exp6((c0 >> 5) & 63)
    b0 = _exp5(c0 & 31)
    r1 = _exp5((c1 >> 11) & 31)
    g1 = _exp6((c1 >> 5) & 63)
    b1 = _exp5(c1 & 31)
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


@jit
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
def _decode_kernel(data, out, punch):
    pal = np.empty((4, 3), np.int64)
    for b in range(data.shape[0]):
        decode_colour_block(data[b], 0, out[b], punch, pal)


# --------------------------------------------------------------------------
# optimal single-colour tables


def _single_tables():
    """For each 8-bit value: the (hi, lo) endpoint levels whose interpolant
    (2*hi + lo) // 3 (4-colour) or (hi + lo) // 2 (3-colour) is nearest.
    Shape (2 modes, 2 widths [5-bit, 6-bit], 256, 2)."""
    tab = np.zeros((2, 2, 256, 2), np.int64)
    v = np.arange(256)[:, None, None]
    for wi, bits in enumerate((5, 6)):
        lv = np.arange(1 << bits)
        e = (lv << (8 - bits)) | (lv >> (2 * bits - 8))
        for mi, val in enumerate(((2 * e[:, None] + e[None, :]) // 3, (e[:, None] + e[None, :]) // 2)):
            # ties go to the pair with the smallest spread: the most robust to
            # other decoders' rounding
            cost = np.abs(val[None] - v) * 1024 + np.abs(e[:, None] - e[None, :])[None]
            flat = cost.reshape(256, -1).argmin(axis=1)
            tab[mi, wi, :, 0] = flat // lv.size
            tab[mi, wi, :, 1] = flat % lv.size
    return tab


_SINGLE = _single_tables()

# --------------------------------------------------------------------------
# presets


@dataclass(frozen=True)
class BC1Preset:
    power_iters: int  # power-iteration steps for the principal axis
    ls_iters: int  # least-squares refinement rounds after a fit
    three_colour: bool  # try the 3-colour mode
    cluster: int  # 0 none, 1 cluster fit (best estimate), 2 measure every split exactly
    climb: int  # 0 none, else maximum hill-climbing passes over the endpoints
    mean_colour: bool  # try the block's mean through the single-colour tables

    def as_array(self):
        return np.array(
            [self.power_iters, self.ls_iters, int(self.three_colour), self.cluster, self.climb,
             int(self.mean_colour)],
            np.int64,
        )


PRESET_TABLE = {
    "fastest": BC1Preset(power_iters=3, ls_iters=0, three_colour=False, cluster=0, climb=0, mean_colour=False),
    "fast": BC1Preset(power_iters=2, ls_iters=2, three_colour=False, cluster=0, climb=0, mean_colour=False),
    "medium": BC1Preset(power_iters=6, ls_iters=4, three_colour=True, cluster=0, climb=2, mean_colour=True),
    "thorough": BC1Preset(power_iters=8, ls_iters=4, three_colour=True, cluster=1, climb=4, mean_colour=True),
    "exhaustive": BC1Preset(power_iters=8, ls_iters=8, three_colour=True, cluster=2, climb=32, mean_colour=True),
}

# indices into the preset array
_P_POWER, _P_LS, _P_THREE, _P_CLUSTER, _P_CLIMB, _P_MEAN = range(6)

# --------------------------------------------------------------------------
# encoder pieces
#
# Texels live channel-major in px (3, 16) float64 (integer values, so sums and
# errors with unit weights are exact), the first n columns used. xx is the
# block's sum of weighted |x|^2, carried so that _eval only needs dot products.


def _level_tables():
    """Nearest 5- and 6-bit level (after bit replication) for every 8-bit value."""
    v = np.arange(256)
    out = []
    for bits in (5, 6):
        lv = np.arange(1 << bits)
        e = (lv << (8 - bits)) | (lv >> (2 * bits - 8))
        out.append(np.abs(e[None, :] - v[:, None]).argmin(axis=1).astype(np.int64))
    return out[0], out[1]


_Q5, _Q6 = _level_tables()


@jit
def _byte(v):
    """Float colour value rounded and clamped to 0..255."""
    if v <= 0.0:
        return 0
    if v >= 255.0:
        return 255
    return np.int64(v + 0.5)


@jit
def _quant(r, g, b):
    return (_Q5[_byte(r)] << 11) | (_Q6[_byte(g)] << 5) | _Q5[_byte(b)]


@jit
def _eval(px, n, w, xx, c0, c1, nsel, pal, idx):
    """Weighted squared error of the block decoded from (c0, c1), each texel
    taking the nearest of the first nsel palette entries (the first on ties);
    indices into idx. Exact for the documented decoding: |x - q|^2 is
    |x|^2 + (|q|^2 - 2 x.q), and the block's sum of |x|^2 is xx, so a texel
    costs one dot product per entry."""
    _palette(c0, c1, pal)
    w0 = w[0]
    w1 = w[1]
    w2 = w[2]
    # entry j scores h_j - x . a_j; locals keep the loop free of array loads
    a00 = 2.0 * w0 * pal[0, 0]
    a01 = 2.0 * w1 * pal[0, 1]
    a02 = 2.0 * w2 * pal[0, 2]
    a10 = 2.0 * w0 * pal[1, 0]
    a11 = 2.0 * w1 * pal[1, 1]
    a12 = 2.0 * w2 * pal[1, 2]
    a20 = 2.0 * w0 * pal[2, 0]
    a21 = 2.0 * w1 * pal[2, 1]
    a22 = 2.0 * w2 * pal[2, 2]
    a30 = 2.0 * w0 * pal[3, 0]
    a31 = 2.0 * w1 * pal[3, 1]
    a32 = 2.0 * w2 * pal[3, 2]
    h0 = 0.5 * (a00 * pal[0, 0] + a01 * pal[0, 1] + a02 * pal[0, 2])
    h1 = 0.5 * (a10 * pal[1, 0] + a11 * pal[1, 1] + a12 * pal[1, 2])
    h2 = 0.5 * (a20 * pal[2, 0] + a21 * pal[2, 1] + a22 * pal[2, 2])
    h3 = 0.5 * (a30 * pal[3, 0] + a31 * pal[3, 1] + a32 * pal[3, 2])
    if nsel < 4:
        h3 = 1e300
    err = 0.0
    for i in range(n):
        x0 = px[0, i]
        x1 = px[1, i]
        x2 = px[2, i]
        best = h0 - (x0 * a00 + x1 * a01 + x2 * a02)
        bi = 0
        e = h1 - (x0 * a10 + x1 * a11 + x2 * a12)
        if e < best:
            best = e
            bi = 1
        e = h2 - (x0 * a20 + x1 * a21 + x2 * a22)
        if e < best:
            best = e
            bi = 2
        e = h3 - (x0 * a30 + x1 * a31 + x2 * a32)
        if e < best:
            best = e
            bi = 3
        idx[i] = bi
        err += best
    return err + xx


@jit
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


@jit
def _try(a, b, three, black, px, n, w, xx, pal, tidx, best, berr, bidx):
    """Measure endpoints (a, b) in a mode; keep them if they beat the best.
    Returns the error and leaves the ordered pair in best only on improvement."""
    c0, c1, nsel = _order(a, b, three)
    if three and black:
        nsel = 4
    err = _eval(px, n, w, xx, c0, c1, nsel, pal, tidx)
    if err < berr[0]:
        berr[0] = err
        best[0] = c0
        best[1] = c1
        for i in range(n):
            bidx[i] = tidx[i]
    return err


# index -> weight of c0, in thirds (4-colour) and halves (3-colour; 3 is black)
_W4 = np.array([3.0, 0.0, 2.0, 1.0])
_W3 = np.array([2.0, 0.0, 1.0, 0.0])


@jit
def _ls_endpoints(px, n, idx, three, ab):
    """Least-squares endpoints (ab[0] for c0, ab[1] for c1) given indices; False
    when the system is singular. Black texels (3-colour index 3) are left out.
    Weights are small integers (c0 gets a/d, c1 (d-a)/d), so only a, a^2, a*x
    and x are summed per texel; the rest follows from the counts."""
    d = 2.0 if three else 3.0
    cnt = 0.0
    sa = 0.0
    saa = 0.0
    ax0 = ax1 = ax2 = 0.0
    sx0 = sx1 = sx2 = 0.0
    for i in range(n):
        s = idx[i]
        if three:
            if s == 3:
                continue
            a = _W3[s]
        else:
            a = _W4[s]
        x0 = px[0, i]
        x1 = px[1, i]
        x2 = px[2, i]
        cnt += 1.0
        sa += a
        saa += a * a
        ax0 += a * x0
        ax1 += a * x1
        ax2 += a * x2
        sx0 += x0
        sx1 += x1
        sx2 += x2
    # with b = d - a: sum b^2, sum a*b, sum b*x
    aa = saa
    bb = cnt * d * d - 2.0 * d * sa + saa
    abx = d * sa - saa
    det = aa * bb - abx * abx
    if abs(det) < 1e-9:
        return False
    bx0 = d * sx0 - ax0
    bx1 = d * sx1 - ax1
    bx2 = d * sx2 - ax2
    # solving with the integer weights scales the solution by 1/d
    f = d / det
    ab[0, 0] = (ax0 * bb - bx0 * abx) * f
    ab[0, 1] = (ax1 * bb - bx1 * abx) * f
    ab[0, 2] = (ax2 * bb - bx2 * abx) * f
    ab[1, 0] = (bx0 * aa - ax0 * abx) * f
    ab[1, 1] = (bx1 * aa - ax1 * abx) * f
    ab[1, 2] = (bx2 * aa - ax2 * abx) * f
    return True


@jit
def _refine(a, b, three, black, iters, px, n, w, xx, pal, tidx, lidx, ab, best, berr, bidx):
    """Measure (a, b), then re-solve the endpoints from the indices by least
    squares while that keeps lowering the error."""
    c0, c1, nsel = _order(a, b, three)
    if three and black:
        nsel = 4
    err = _eval(px, n, w, xx, c0, c1, nsel, pal, lidx)
    if err < berr[0]:
        berr[0] = err
        best[0] = c0
        best[1] = c1
        for i in range(n):
            bidx[i] = lidx[i]
    for _ in range(iters):
        if err <= 0.0:
            break
        if not _ls_endpoints(px, n, lidx, three and c0 <= c1, ab):
            break
        qa = _quant(ab[0, 0], ab[0, 1], ab[0, 2])
        qb = _quant(ab[1, 0], ab[1, 1], ab[1, 2])
        d0, d1, ns = _order(qa, qb, three)
        if d0 == c0 and d1 == c1:
            # same pair again: same indices, nothing more to gain
            break
        if three and black:
            ns = 4
        e2 = _eval(px, n, w, xx, d0, d1, ns, pal, tidx)
        if e2 < berr[0]:
            berr[0] = e2
            best[0] = d0
            best[1] = d1
            for i in range(n):
                bidx[i] = tidx[i]
        if e2 >= err:
            break
        err = e2
        c0 = d0
        c1 = d1
        for i in range(n):
            lidx[i] = tidx[i]
    return err


@jit
def _principal_axis(mom, n, sw, iters, mean, axis):
    """Mean and principal axis of the weighted texels (q = px * sw) from the
    block's moments mom (sums of x_c, then of x_r x_r, x_r x_g, x_r x_b,
    x_g x_g, x_g x_b, x_b x_b). False if the texels are all one colour."""
    s0 = mom[0]
    s1 = mom[1]
    s2 = mom[2]
    inv = 1.0 / n
    mean[0] = s0 * inv * sw[0]
    mean[1] = s1 * inv * sw[1]
    mean[2] = s2 * inv * sw[2]
    c00 = (mom[3] - s0 * s0 * inv) * sw[0] * sw[0]
    c01 = (mom[4] - s0 * s1 * inv) * sw[0] * sw[1]
    c02 = (mom[5] - s0 * s2 * inv) * sw[0] * sw[2]
    c11 = (mom[6] - s1 * s1 * inv) * sw[1] * sw[1]
    c12 = (mom[7] - s1 * s2 * inv) * sw[1] * sw[2]
    c22 = (mom[8] - s2 * s2 * inv) * sw[2] * sw[2]
    if c00 + c11 + c22 < 1e-9:
        return False
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
        v0, v1, v2 = t0 / m, t1 / m, t2 / m
    nrm = np.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    if nrm < 1e-30:
        return False
    axis[0] = v0 / nrm
    axis[1] = v1 / nrm
    axis[2] = v2 / nrm
    return True


@jit
def _range_fit(px, n, sw, mean, axis, ab):
    """Endpoints at the extreme projections of the texels on the axis through
    the mean (ab[0] the high end, for c0). Only min and max: no sort."""
    k0 = sw[0] * axis[0]
    k1 = sw[1] * axis[1]
    k2 = sw[2] * axis[2]
    lo = 1e300
    hi = -1e300
    for i in range(n):
        p = px[0, i] * k0 + px[1, i] * k1 + px[2, i] * k2
        lo = min(lo, p)
        hi = max(hi, p)
    pm = mean[0] * axis[0] + mean[1] * axis[1] + mean[2] * axis[2]
    for c in range(3):
        ab[0, c] = (mean[c] + (hi - pm) * axis[c]) / sw[c]
        ab[1, c] = (mean[c] + (lo - pm) * axis[c]) / sw[c]


@jit
def _sort_along(px, n, sw, mean, axis, proj, order):
    """Texel order along the axis (for the cluster fit)."""
    for i in range(n):
        proj[i] = (
            (px[0, i] * sw[0] - mean[0]) * axis[0]
            + (px[1, i] * sw[1] - mean[1]) * axis[1]
            + (px[2, i] * sw[2] - mean[2]) * axis[2]
        )
        order[i] = i
    # insertion sort: n <= 16
    for i in range(1, n):
        k = order[i]
        v = proj[k]
        j = i - 1
        while j >= 0 and proj[order[j]] > v:
            order[j + 1] = order[j]
            j -= 1
        order[j + 1] = k


@jit
def _cluster_fit(px, n, w, xx, order, three, exact, black, pal, tidx, best, berr, bidx, cand, pre):
    """Cluster fit over texels sorted along the axis. Every ordered split into
    4 groups (weights 1, 2/3, 1/3, 0) or 3 groups (1, 1/2, 0) gets least-squares
    endpoints. exact: quantise and measure every split; otherwise keep the split
    with the smallest estimated error and return its endpoints in cand."""
    # prefix sums of sorted texels
    for c in range(3):
        pre[0, c] = 0.0
    for i in range(n):
        k = order[i]
        for c in range(3):
            pre[i + 1, c] = pre[i, c] + px[c, k]
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
    for s1 in range(n + 1):
        for s2 in range(s1, n + 1):
            lo3 = s2 if not three else n
            for s3 in range(lo3, n + 1):
                # groups [0,s1) w=1, [s1,s2) g1, [s2,s3) g2, [s3,n) 0; in
                # 3-colour mode s3 == n and groups 2 and 3 merge into weight 1/2
                if three:
                    n1 = s1
                    n2 = s2 - s1
                    n3 = 0
                    n4 = n - s2
                else:
                    n1 = s1
                    n2 = s2 - s1
                    n3 = s3 - s2
                    n4 = n - s3
                aa = n1 + n2 * g1 * g1 + n3 * g2 * g2
                bb = n4 + n2 * (1 - g1) * (1 - g1) + n3 * (1 - g2) * (1 - g2)
                abx = n2 * g1 * (1 - g1) + n3 * g2 * (1 - g2)
                det = aa * bb - abx * abx
                if abs(det) < 1e-9:
                    continue
                f = 1.0 / det
                est = 0.0
                for c in range(3):
                    p1 = pre[s1, c]
                    p2 = pre[s2, c] - pre[s1, c]
                    if three:
                        p3 = 0.0
                    else:
                        p3 = pre[s3, c] - pre[s2, c]
                    tot = pre[n, c]
                    ax = p1 + g1 * p2 + g2 * p3
                    bx = tot - ax
                    a = (ax * bb - bx * abx) * f
                    b = (bx * aa - ax * abx) * f
                    cand[2, c] = a
                    cand[3, c] = b
                    est += w[c] * (a * a * aa + b * b * bb + 2.0 * a * b * abx - 2.0 * a * ax - 2.0 * b * bx)
                if exact:
                    qa = _quant(cand[2, 0], cand[2, 1], cand[2, 2])
                    qb = _quant(cand[3, 0], cand[3, 1], cand[3, 2])
                    # neighbouring splits often quantise to the same pair
                    if qa != la or qb != lb:
                        la = qa
                        lb = qb
                        _try(qa, qb, three, black, px, n, w, xx, pal, tidx, best, berr, bidx)
                elif est < best_est:
                    best_est = est
                    found = True
                    for c in range(3):
                        cand[0, c] = cand[2, c]
                        cand[1, c] = cand[3, c]
    return found


@jit
def _climb(passes, three_ok, black, px, n, w, xx, pal, tidx, best, berr, bidx):
    """Hill-climb over the quantised endpoints: move one channel of one endpoint
    (or of both) by one level, keep any move that lowers the measured error."""
    for _ in range(passes):
        if berr[0] <= 0.0:
            break
        improved = False
        c0 = best[0]
        c1 = best[1]
        three = c0 <= c1 and c0 != c1
        if three and not three_ok:
            three = False
        for e in range(3):  # 0: move c0, 1: move c1, 2: move both the same way
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
                    if e == 0 or e == 2:
                        v = ((a >> sh) & mx) + dlt
                        if v < 0 or v > mx:
                            ok = False
                        a = (a & ~(mx << sh)) | (v << sh)
                    if e == 1 or e == 2:
                        v = ((b >> sh) & mx) + dlt
                        if v < 0 or v > mx:
                            ok = False
                        b = (b & ~(mx << sh)) | (v << sh)
                    if not ok:
                        continue
                    before = berr[0]
                    _try(a, b, three, black, px, n, w, xx, pal, tidx, best, berr, bidx)
                    if berr[0] < before:
                        improved = True
        if not improved:
            break


@jit
def _single_colour(r, g, b, three, black, px, n, w, xx, pal, tidx, best, berr, bidx):
    """Endpoints from the single-colour tables for one colour."""
    m = 1 if three else 0
    ri = _byte(r)
    gi = _byte(g)
    bi = _byte(b)
    hi = (_SINGLE[m, 0, ri, 0] << 11) | (_SINGLE[m, 1, gi, 0] << 5) | _SINGLE[m, 0, bi, 0]
    lo = (_SINGLE[m, 0, ri, 1] << 11) | (_SINGLE[m, 1, gi, 1] << 5) | _SINGLE[m, 0, bi, 1]
    _try(hi, lo, three, black, px, n, w, xx, pal, tidx, best, berr, bidx)


@jit
def encode_colour_block(blk, w, sw, prm, thr, three_ok, black_ok, out, o, scr):
    """Encode one block's colour (blk (16, 4) uint8) into out[o:o+8].
    thr > 0: BC1A, texels with alpha < thr are transparent (3-colour index 3).
    three_ok: the 3-colour mode may be used; black_ok: its black entry may be
    used as a colour. scr: scratch arrays from colour_scratch()."""
    px, pos, pal, tidx, lidx, bidx, best, berr, ab, mean, axis, cand, proj, order, pre, mom = scr
    # one pass: gather the opaque texels, their moments and whether they differ
    n = 0
    for k in range(9):
        mom[k] = 0.0
    xx = 0.0
    uniform = True
    for i in range(16):
        if thr > 0 and blk[i, 3] < thr:
            continue
        r = np.float64(blk[i, 0])
        g = np.float64(blk[i, 1])
        b = np.float64(blk[i, 2])
        px[0, n] = r
        px[1, n] = g
        px[2, n] = b
        pos[n] = i
        if r != px[0, 0] or g != px[1, 0] or b != px[2, 0]:
            uniform = False
        mom[0] += r
        mom[1] += g
        mom[2] += b
        mom[3] += r * r
        mom[4] += r * g
        mom[5] += r * b
        mom[6] += g * g
        mom[7] += g * b
        mom[8] += b * b
        n += 1
    xx = w[0] * mom[3] + w[1] * mom[6] + w[2] * mom[8]
    berr[0] = 1e300
    best[0] = 0
    best[1] = 0

    holes = n < 16
    if n == 0:
        best[0] = 0
        best[1] = 0
    else:
        # blocks with transparent texels must use the 3-colour mode
        only_three = holes
        use_three = three_ok and (holes or prm[_P_THREE] != 0)
        black = black_ok and not holes
        if uniform:
            q = _quant(px[0, 0], px[1, 0], px[2, 0])
            _try(q, q, only_three, black, px, n, w, xx, pal, tidx, best, berr, bidx)
            if not only_three:
                _single_colour(px[0, 0], px[1, 0], px[2, 0], False, black, px, n, w, xx, pal, tidx, best, berr,
                               bidx)
            if three_ok:
                # cheap here, and some flat colours are only reachable as a 3-colour midpoint
                _single_colour(px[0, 0], px[1, 0], px[2, 0], True, black, px, n, w, xx, pal, tidx, best, berr,
                               bidx)
        else:
            have_axis = _principal_axis(mom, n, sw, prm[_P_POWER], mean, axis)
            if have_axis:
                _range_fit(px, n, sw, mean, axis, ab)
                qa = _quant(ab[0, 0], ab[0, 1], ab[0, 2])
                qb = _quant(ab[1, 0], ab[1, 1], ab[1, 2])
                if not only_three:
                    _refine(qa, qb, False, black, prm[_P_LS], px, n, w, xx, pal, tidx, lidx, ab, best, berr, bidx)
                if use_three and berr[0] > 0.0:
                    _refine(qa, qb, True, black, prm[_P_LS], px, n, w, xx, pal, tidx, lidx, ab, best, berr, bidx)
                if prm[_P_CLUSTER] > 0 and berr[0] > 0.0:
                    _sort_along(px, n, sw, mean, axis, proj, order)
                    exact = prm[_P_CLUSTER] > 1
                    modes = 2 if use_three else 1
                    for mi in range(modes):
                        three = mi == 1 or only_three
                        if mi == 0 and only_three:
                            continue
                        if _cluster_fit(px, n, w, xx, order, three, exact, black, pal, tidx, best, berr, bidx, cand,
                                        pre):
                            qa = _quant(cand[0, 0], cand[0, 1], cand[0, 2])
                            qb = _quant(cand[1, 0], cand[1, 1], cand[1, 2])
                            _refine(qa, qb, three, black, prm[_P_LS], px, n, w, xx, pal, tidx, lidx, ab, best, berr,
                                    bidx)
                        elif exact:
                            _refine(best[0], best[1], three, black, prm[_P_LS], px, n, w, xx, pal, tidx, lidx, ab,
                                    best, berr, bidx)
            if (prm[_P_MEAN] != 0 or not have_axis) and berr[0] > 0.0:
                mr = mom[0] / n
                mg = mom[1] / n
                mb = mom[2] / n
                if not only_three:
                    _single_colour(mr, mg, mb, False, black, px, n, w, xx, pal, tidx, best, berr, bidx)
                if use_three:
                    _single_colour(mr, mg, mb, True, black, px, n, w, xx, pal, tidx, best, berr, bidx)
            if prm[_P_CLIMB] > 0:
                _climb(prm[_P_CLIMB], use_three, black, px, n, w, xx, pal, tidx, best, berr, bidx)
            if only_three and best[0] > best[1]:
                # cannot happen (every candidate was ordered for 3-colour) but a
                # transparent texel must never decode opaque
                t = best[0]
                best[0] = best[1]
                best[1] = t
    c0 = best[0]
    c1 = best[1]
    bits = np.int64(0)
    for k in range(n):
        bits |= bidx[k] << (2 * pos[k])
    if holes:
        for i in range(16):
            if blk[i, 3] < thr:
                bits |= np.int64(3) << (2 * i)
    out[o] = c0 & 255
    out[o + 1] = (c0 >> 8) & 255
    out[o + 2] = c1 & 255
    out[o + 3] = (c1 >> 8) & 255
    out[o + 4] = bits & 255
    out[o + 5] = (bits >> 8) & 255
    out[o + 6] = (bits >> 16) & 255
    out[o + 7] = (bits >> 24) & 255


@jit
def colour_scratch():
    """Working arrays for encode_colour_block, allocated once per run of blocks."""
    return (
        np.zeros((3, 16)), np.empty(16, np.int64), np.empty((4, 3), np.int64),
        np.zeros(16, np.int64), np.zeros(16, np.int64), np.zeros(16, np.int64),
        np.zeros(2, np.int64), np.full(1, 1e300), np.empty((2, 3)), np.empty(3), np.empty(3),
        np.empty((4, 3)), np.empty(16), np.empty(16, np.int64), np.zeros((17, 3)), np.zeros(9),
    )


@jit
def _encode_kernel(blocks, out, w, sw, prm, thr, three_ok, black_ok):
    scr = colour_scratch()
    for b in range(blocks.shape[0]):
        encode_colour_block(blocks[b], w, sw, prm, thr, three_ok, black_ok, out[b], 0, scr)


# --------------------------------------------------------------------------
# Python side


def colour_weights(weights):
    """(w, sqrt(w)) float64 arrays from the weights option; default (1, 1, 1)."""
    if weights is None:
        weights = (1.0, 1.0, 1.0)
    try:
        w = np.array([float(x) for x in weights], np.float64)
    except (TypeError, ValueError):
        raise UsageError(f"weights must be three numbers r,g,b, not {weights!r}") from None
    if w.shape != (3,) or not np.all(np.isfinite(w)) or np.any(w < 0) or w.max() <= 0:
        raise UsageError(f"weights must be three non-negative numbers r,g,b, not all zero, not {weights!r}")
    # a zero weight becomes 1/1000 of the largest: the search still needs a
    # direction in that channel (it divides by the square root of the weight)
    w = np.maximum(w / w.max(), 1e-3)
    return w, np.sqrt(w)


def preset_array(preset):
    return PRESET_TABLE[preset].as_array()


@dataclass(frozen=True)
class BC1Codec(Codec):
    punch_through: bool = False

    def _encode_blocks(self, blocks, out, preset, threads, weights=None, alpha_threshold=128, **options):
        w, sw = colour_weights(weights)
        thr = 0
        if self.punch_through:
            thr = int(alpha_threshold)
            if not 0 <= thr <= 256:
                raise UsageError(f"alpha_threshold must be in 0..256, not {alpha_threshold}")
        prm = preset_array(preset)
        black = not self.punch_through
        run_chunked(_encode_kernel, blocks, out, threads, w, sw, prm, np.int64(thr), True, black)

    def _decode_blocks(self, data, out):
        _decode_kernel(data, out, self.punch_through)


BC1 = BC1Codec(
    "bc1", 4, 4, 8, 3, vk_unorm=131, vk_srgb=132,
    description="BC1 (DXT1) RGB, 4 bits per texel",
)
BC1A = BC1Codec(
    "bc1a", 4, 4, 8, 4, vk_unorm=133, vk_srgb=134, punch_through=True,
    description="BC1 (DXT1) RGB with 1-bit alpha, 4 bits per texel",
)
