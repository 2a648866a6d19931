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


@jit
def _q5(v):
    """Nearest 5-bit level (after bit replication) to an 8-bit float value."""
    if v <= 0.0:
        return np.int64(0)
    if v >= 255.0:
        return np.int64(31)
    q = np.int64(v * (31.0 / 255.0) + 0.5)
    best = q
    bd = abs(_exp5(q) - v)
    if q > 0 and abs(_exp5(q - 1) - v) < bd:
        best = q - 1
        bd = abs(_exp5(q - 1) - v)
    if q < 31 and abs(_exp5(q + 1) - v) < bd:
        best = q + 1
    return best


@jit
def _q6(v):
    if v <= 0.0:
        return np.int64(0)
    if v >= 255.0:
        return np.int64(63)
    q = np.int64(v * (63.0 / 255.0) + 0.5)
    best = q
    bd = abs(_exp6(q) - v)
    if q > 0 and abs(_exp6(q - 1) - v) < bd:
        best = q - 1
        bd = abs(_exp6(q - 1) - v)
    if q < 63 and abs(_exp6(q + 1) - v) < bd:
        best = q + 1
    return best


@jit
def _quant(r, g, b):
    return (_q5(r) << 11) | (_q6(g) << 5) | _q5(b)


@jit
def _eval(px, n, w, c0, c1, nsel, pal, idx):
    """Weighted squared error of the block decoded from (c0, c1), each texel
    taking the nearest of the first nsel palette entries; indices into idx."""
    _palette(c0, c1, pal)
    err = 0.0
    for i in range(n):
        best = 1e30
        bi = 0
        for j in range(nsel):
            d0 = px[i, 0] - pal[j, 0]
            d1 = px[i, 1] - pal[j, 1]
            d2 = px[i, 2] - pal[j, 2]
            e = w[0] * d0 * d0 + w[1] * d1 * d1 + w[2] * d2 * d2
            if e < best:
                best = e
                bi = j
        idx[i] = bi
        err += best
    return err


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
def _try(a, b, three, black, px, n, w, pal, tidx, best, berr, bidx):
    """Measure endpoints (a, b) in a mode; keep them if they beat the best.
    Returns the error and leaves the ordered pair in best only on improvement."""
    c0, c1, nsel = _order(a, b, three)
    if three and black:
        nsel = 4
    err = _eval(px, n, w, c0, c1, nsel, pal, tidx)
    if err < berr[0]:
        berr[0] = err
        best[0] = c0
        best[1] = c1
        for i in range(n):
            bidx[i] = tidx[i]
    return err


@jit
def _ls_endpoints(px, n, idx, three, ab):
    """Least-squares endpoints (ab[0] for c0, ab[1] for c1) given indices; False
    when the system is singular. Black texels (3-colour index 3) are left out."""
    aa = 0.0
    bb = 0.0
    abx = 0.0
    ax0 = 0.0
    ax1 = 0.0
    ax2 = 0.0
    bx0 = 0.0
    bx1 = 0.0
    bx2 = 0.0
    for i in range(n):
        s = idx[i]
        if three:
            if s == 3:
                continue
            al = 1.0 if s == 0 else (0.0 if s == 1 else 0.5)
        else:
            al = 1.0 if s == 0 else (0.0 if s == 1 else (2.0 / 3.0 if s == 2 else 1.0 / 3.0))
        be = 1.0 - al
        aa += al * al
        bb += be * be
        abx += al * be
        ax0 += al * px[i, 0]
        ax1 += al * px[i, 1]
        ax2 += al * px[i, 2]
        bx0 += be * px[i, 0]
        bx1 += be * px[i, 1]
        bx2 += be * px[i, 2]
    det = aa * bb - abx * abx
    if abs(det) < 1e-9:
        return False
    f = 1.0 / det
    ab[0, 0] = (ax0 * bb - bx0 * abx) * f
    ab[0, 1] = (ax1 * bb - bx1 * abx) * f
    ab[0, 2] = (ax2 * bb - bx2 * abx) * f
    ab[1, 0] = (bx0 * aa - ax0 * abx) * f
    ab[1, 1] = (bx1 * aa - ax1 * abx) * f
    ab[1, 2] = (bx2 * aa - ax2 * abx) * f
    return True


@jit
def _refine(a, b, three, black, iters, px, n, w, pal, tidx, lidx, ab, best, berr, bidx):
    """Measure (a, b), then re-solve the endpoints from the indices by least
    squares while that keeps lowering the error."""
    c0, c1, nsel = _order(a, b, three)
    if three and black:
        nsel = 4
    err = _eval(px, n, w, c0, c1, nsel, pal, lidx)
    if err < berr[0]:
        berr[0] = err
        best[0] = c0
        best[1] = c1
        for i in range(n):
            bidx[i] = lidx[i]
    for _ in range(iters):
        if not _ls_endpoints(px, n, lidx, three and c0 <= c1, ab):
            break
        qa = _quant(ab[0, 0], ab[0, 1], ab[0, 2])
        qb = _quant(ab[1, 0], ab[1, 1], ab[1, 2])
        d0, d1, ns = _order(qa, qb, three)
        if three and black:
            ns = 4
        e2 = _eval(px, n, w, d0, d1, ns, pal, tidx)
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
def _principal_axis(px, n, sw, iters, mean, axis):
    """Mean and principal axis of the weighted texels (q = px * sw). False if the
    texels are all one colour."""
    for c in range(3):
        s = 0.0
        for i in range(n):
            s += px[i, c] * sw[c]
        mean[c] = s / n
    c00 = c01 = c02 = c11 = c12 = c22 = 0.0
    for i in range(n):
        d0 = px[i, 0] * sw[0] - mean[0]
        d1 = px[i, 1] * sw[1] - mean[1]
        d2 = px[i, 2] * sw[2] - mean[2]
        c00 += d0 * d0
        c01 += d0 * d1
        c02 += d0 * d2
        c11 += d1 * d1
        c12 += d1 * d2
        c22 += d2 * d2
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
def _sort_along(px, n, sw, mean, axis, proj, order):
    for i in range(n):
        proj[i] = (
            (px[i, 0] * sw[0] - mean[0]) * axis[0]
            + (px[i, 1] * sw[1] - mean[1]) * axis[1]
            + (px[i, 2] * sw[2] - mean[2]) * axis[2]
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
def _cluster_fit(px, n, w, order, three, exact, black, pal, tidx, best, berr, bidx, cand, pre):
    """Cluster fit over texels sorted along the axis. Every ordered split into
    4 groups (weights 1, 2/3, 1/3, 0) or 3 groups (1, 1/2, 0) gets least-squares
    endpoints. exact: quantise and measure every split; otherwise keep the split
    with the smallest estimated error and return its endpoints in cand."""
    # prefix sums of sorted texels
    for i in range(n):
        k = order[i]
        for c in range(3):
            pre[0, c] = 0.0
            pre[i + 1, c] = pre[i, c] + px[k, c]
    tx0 = pre[n, 0]
    tx1 = pre[n, 1]
    tx2 = pre[n, 2]
    best_est = 1e300
    found = False
    if three:
        g1 = 0.5
        g2 = 0.5
    else:
        g1 = 2.0 / 3.0
        g2 = 1.0 / 3.0
    s3max = n if not three else 0
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
                    _try(qa, qb, three, black, px, n, w, pal, tidx, best, berr, bidx)
                elif est < best_est:
                    best_est = est
                    found = True
                    for c in range(3):
                        cand[0, c] = cand[2, c]
                        cand[1, c] = cand[3, c]
    return found


@jit
def _climb(passes, three_ok, black, px, n, w, pal, tidx, best, berr, bidx):
    """Hill-climb over the quantised endpoints: move one channel of one endpoint
    (or of both) by one level, keep any move that lowers the measured error."""
    for _ in range(passes):
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
                    _try(a, b, three, black, px, n, w, pal, tidx, best, berr, bidx)
                    if berr[0] < before:
                        improved = True
        if not improved:
            break


@jit
def _single_colour(r, g, b, three, black, px, n, w, pal, tidx, best, berr, bidx):
    """Endpoints from the single-colour tables for one colour."""
    m = 1 if three else 0
    ri = min(255, max(0, np.int64(r + 0.5)))
    gi = min(255, max(0, np.int64(g + 0.5)))
    bi = min(255, max(0, np.int64(b + 0.5)))
    hi = (_SINGLE[m, 0, ri, 0] << 11) | (_SINGLE[m, 1, gi, 0] << 5) | _SINGLE[m, 0, bi, 0]
    lo = (_SINGLE[m, 0, ri, 1] << 11) | (_SINGLE[m, 1, gi, 1] << 5) | _SINGLE[m, 0, bi, 1]
    _try(hi, lo, three, black, px, n, w, pal, tidx, best, berr, bidx)


@jit
def encode_colour_block(blk, w, sw, prm, thr, three_ok, black_ok, out, o, scr):
    """Encode one block's colour (blk (16, 4) uint8) into out[o:o+8].
    thr > 0: BC1A, texels with alpha < thr are transparent (3-colour index 3).
    three_ok: the 3-colour mode may be used; black_ok: its black entry may be
    used as a colour. scr: scratch arrays from colour_scratch()."""
    px, pos, pal, tidx, lidx, bidx, best, berr, ab, mean, axis, cand, proj, order, pre = scr
    n = 0
    for i in range(16):
        if thr > 0 and blk[i, 3] < thr:
            continue
        px[n, 0] = blk[i, 0]
        px[n, 1] = blk[i, 1]
        px[n, 2] = blk[i, 2]
        pos[n] = i
        n += 1
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
        uniform = True
        for i in range(1, n):
            if px[i, 0] != px[0, 0] or px[i, 1] != px[0, 1] or px[i, 2] != px[0, 2]:
                uniform = False
                break
        if uniform:
            q = _quant(px[0, 0], px[0, 1], px[0, 2])
            _try(q, q, only_three, black, px, n, w, pal, tidx, best, berr, bidx)
            if not only_three:
                _single_colour(px[0, 0], px[0, 1], px[0, 2], False, black, px, n, w, pal, tidx, best, berr, bidx)
            if three_ok:
                # cheap here, and some flat colours are only reachable as a 3-colour midpoint
                _single_colour(px[0, 0], px[0, 1], px[0, 2], True, black, px, n, w, pal, tidx, best, berr, bidx)
        else:
            have_axis = _principal_axis(px, n, sw, prm[_P_POWER], mean, axis)
            if have_axis:
                _sort_along(px, n, sw, mean, axis, proj, order)
                lo = proj[order[0]]
                hi = proj[order[n - 1]]
                for c in range(3):
                    ab[0, c] = (mean[c] + hi * axis[c]) / sw[c]
                    ab[1, c] = (mean[c] + lo * axis[c]) / sw[c]
                qa = _quant(ab[0, 0], ab[0, 1], ab[0, 2])
                qb = _quant(ab[1, 0], ab[1, 1], ab[1, 2])
                if not only_three:
                    _refine(qa, qb, False, black, prm[_P_LS], px, n, w, pal, tidx, lidx, ab, best, berr, bidx)
                if use_three:
                    _refine(qa, qb, True, black, prm[_P_LS], px, n, w, pal, tidx, lidx, ab, best, berr, bidx)
                if prm[_P_CLUSTER] > 0:
                    exact = prm[_P_CLUSTER] > 1
                    modes = 2 if use_three else 1
                    for mi in range(modes):
                        three = mi == 1 or only_three
                        if mi == 0 and only_three:
                            continue
                        if _cluster_fit(px, n, w, order, three, exact, black, pal, tidx, best, berr, bidx, cand, pre):
                            qa = _quant(cand[0, 0], cand[0, 1], cand[0, 2])
                            qb = _quant(cand[1, 0], cand[1, 1], cand[1, 2])
                            _refine(qa, qb, three, black, prm[_P_LS], px, n, w, pal, tidx, lidx, ab, best, berr, bidx)
                        elif exact:
                            _refine(best[0], best[1], three, black, prm[_P_LS], px, n, w, pal, tidx, lidx, ab, best,
                                    berr, bidx)
            if prm[_P_MEAN] != 0 or not have_axis:
                mr = mg = mb = 0.0
                for i in range(n):
                    mr += px[i, 0]
                    mg += px[i, 1]
                    mb += px[i, 2]
                if not only_three:
                    _single_colour(mr / n, mg / n, mb / n, False, black, px, n, w, pal, tidx, best, berr, bidx)
                if use_three:
                    _single_colour(mr / n, mg / n, mb / n, True, black, px, n, w, pal, tidx, best, berr, bidx)
            if prm[_P_CLIMB] > 0:
                _climb(prm[_P_CLIMB], use_three, black, px, n, w, pal, tidx, best, berr, bidx)
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
        np.empty((16, 3)), np.empty(16, np.int64), np.empty((4, 3), np.int64),
        np.zeros(16, np.int64), np.zeros(16, np.int64), np.zeros(16, np.int64),
        np.zeros(2, np.int64), np.full(1, 1e300), np.empty((2, 3)), np.empty(3), np.empty(3),
        np.empty((4, 3)), np.empty(16), np.empty(16, np.int64), np.zeros((17, 3)),
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
