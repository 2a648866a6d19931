"""ASTC search: endpoint quantisation. The CEM each partition gets for a
family, and float endpoints quantised to a colour range the way the decoder
reads them back (blue-contraction, base+scale, base+offset)."""

from collections import namedtuple

import numpy as np

from ...._jit import jit_inner
from ..endpoint_decode import decode_endpoints


# CEM families: per partition the content (grey?, opaque?) picks the mode
FAM_DIRECT = 0  # 0 / 4 / 8 / 12
FAM_SCALE = 1  # 0 / 4 / 6 / 10
FAM_OFFSET = 2  # 0 / 4 / 9 / 13, only where the colour range keeps them exact
FAM_LUMA = 3  # 0 / 4 for every partition: two colour values buy the widest colour range
OFFSET_MIN_RANGE = 17  # 128 levels: every bit base+offset uses survives

# what quant_endpoints reads and writes: float endpoints e0, e1 (4, 4), the
# ISE values (vals (32,)), the decoded 8-bit endpoints d0, d1 (4, 4), and alt
# (8,), altd (2, 4) scratch
EndpointWork = namedtuple("EndpointWork", "e0 e1 vals d0 d1 alt altd")


@jit_inner
def _cem_for(fam, grey, opaque):
    if grey or fam == FAM_LUMA:
        return 0 if opaque else 4
    if fam == FAM_SCALE:
        return 6 if opaque else 10
    if fam == FAM_OFFSET:
        return 9 if opaque else 13
    return 8 if opaque else 12


@jit_inner
def _promote(cem, minclass):
    """A CEM of at least class minclass that stores the same content."""
    while (cem >> 2) < minclass:
        if cem == 0:
            cem = 4 if minclass == 1 else 8
        elif cem == 6:
            cem = 10 if minclass == 2 else 12
        elif cem == 4:
            cem = 12
        elif cem == 8 or cem == 10:
            cem = 12
        elif cem == 9:
            cem = 13
        else:
            cem = 12
    return cem


@jit_inner(inline="always")
def choose_cems(fam, nparts, pgrey, popaque, cems):
    """CEM per partition for a family; classes kept within one step of each other
    (what the multi-partition CEM field can say). Returns (colour value count,
    1 if all partitions share one CEM)."""
    maxc = 0
    for p in range(nparts):
        cems[p] = _cem_for(fam, pgrey[p], popaque[p])
        if (cems[p] >> 2) > maxc:
            maxc = cems[p] >> 2
    nv = 0
    same = 1
    for p in range(nparts):
        if (cems[p] >> 2) < maxc - 1:
            cems[p] = _promote(cems[p], maxc - 1)
        nv += 2 * ((cems[p] >> 2) + 1)
        if cems[p] != cems[0]:
            same = 0
    return nv, same


@jit_inner(inline="always")
def expand(e, srgb):
    if srgb:
        return (e << 8) | 0x80
    return e * 257


@jit_inner(inline="always")
def _q8(v):
    """Float -> nearest 0..255 integer."""
    i = int(np.floor(v + 0.5))
    if i < 0:
        return 0
    if i > 255:
        return 255
    return i


@jit_inner(inline="always")
def _cq(v, cq, cquant):
    return cquant[cq, _q8(v)]


@jit_inner
def _ep_err(chw, e0, e1, p, a0, a1, q, nc):
    """Weighted squared distance of endpoints (a0[q], a1[q]) from (e0[p], e1[p])."""
    s = 0.0
    for c in range(nc):
        u = a0[q, c] - e0[p, c]
        v = a1[q, c] - e1[p, c]
        s += chw[c] * (u * u + v * v)
    return s


@jit_inner
def _decode_direct(vals, off, cq, cunq, alpha, d0, d1, p):
    """The decoder's CEM 8/12 on vals[off:]: swap and blue-contract when the
    sum says so; endpoints into d0[p], d1[p]."""
    r0 = cunq[cq, vals[off]]
    r1 = cunq[cq, vals[off + 1]]
    g0 = cunq[cq, vals[off + 2]]
    g1 = cunq[cq, vals[off + 3]]
    b0 = cunq[cq, vals[off + 4]]
    b1 = cunq[cq, vals[off + 5]]
    a0 = cunq[cq, vals[off + 6]] if alpha else 255
    a1 = cunq[cq, vals[off + 7]] if alpha else 255
    if r1 + g1 + b1 >= r0 + g0 + b0:
        d0[p, 0] = r0
        d0[p, 1] = g0
        d0[p, 2] = b0
        d0[p, 3] = a0
        d1[p, 0] = r1
        d1[p, 1] = g1
        d1[p, 2] = b1
        d1[p, 3] = a1
    else:
        d0[p, 0] = (r1 + b1) >> 1
        d0[p, 1] = (g1 + b1) >> 1
        d0[p, 2] = b1
        d0[p, 3] = a1
        d1[p, 0] = (r0 + b0) >> 1
        d1[p, 1] = (g0 + b0) >> 1
        d1[p, 2] = b0
        d1[p, 3] = a0


@jit_inner
def quant_endpoints(cem, p, cq, chw, cunq, cquant, off, ep):
    """Quantise partition p's float endpoints e0[p], e1[p] for its CEM: ISE
    values into vals[off:], decoded 8-bit endpoints into d0[p], d1[p] (what
    the decoder computes), all fields of ep (EndpointWork). Returns the
    number of values written."""
    e0, e1, vals, d0, d1, alt, altd = ep
    if cem == 0 or cem == 4:
        wl = max(chw[0] + chw[1] + chw[2], 1e-9)
        l0 = (e0[p, 0] * chw[0] + e0[p, 1] * chw[1] + e0[p, 2] * chw[2]) / wl
        l1 = (e1[p, 0] * chw[0] + e1[p, 1] * chw[1] + e1[p, 2] * chw[2]) / wl
        vals[off] = _cq(l0, cq, cquant)
        vals[off + 1] = _cq(l1, cq, cquant)
        a = cunq[cq, vals[off]]
        b = cunq[cq, vals[off + 1]]
        for c in range(3):
            d0[p, c] = a
            d1[p, c] = b
        if cem == 0:
            d0[p, 3] = 255
            d1[p, 3] = 255
            return 2
        vals[off + 2] = _cq(e0[p, 3], cq, cquant)
        vals[off + 3] = _cq(e1[p, 3], cq, cquant)
        d0[p, 3] = cunq[cq, vals[off + 2]]
        d1[p, 3] = cunq[cq, vals[off + 3]]
        return 4
    if cem == 6 or cem == 10:
        for c in range(3):
            vals[off + c] = _cq(e1[p, c], cq, cquant)
            d1[p, c] = cunq[cq, vals[off + c]]
        num = 0.0
        den = 0.0
        for c in range(3):
            num += chw[c] * e0[p, c] * d1[p, c]
            den += chw[c] * d1[p, c] * d1[p, c]
        sv = 256.0 * num / den if den > 0 else 255.0
        # the nearest scale code and its neighbours a quarter-step away
        best = -1.0
        bcode = 0
        for k in range(3):
            cand = _cq(sv + (k - 1) * 4.0, cq, cquant)
            su = cunq[cq, cand]
            err = 0.0
            for c in range(3):
                dd = ((d1[p, c] * su) >> 8) - e0[p, c]
                err += chw[c] * dd * dd
            if best < 0 or err < best:
                best = err
                bcode = cand
        vals[off + 3] = bcode
        su = cunq[cq, bcode]
        for c in range(3):
            d0[p, c] = (d1[p, c] * su) >> 8
        if cem == 6:
            d0[p, 3] = 255
            d1[p, 3] = 255
            return 4
        vals[off + 4] = _cq(e0[p, 3], cq, cquant)
        vals[off + 5] = _cq(e1[p, 3], cq, cquant)
        d0[p, 3] = cunq[cq, vals[off + 4]]
        d1[p, 3] = cunq[cq, vals[off + 5]]
        return 6
    if cem == 9 or cem == 13:
        # base + signed 6-bit offset: v(2c) holds the base's low 7 bits, v(2c+1)
        # its top bit and the offset (bit_transfer_signed in reverse)
        nc = 4 if cem == 13 else 3
        for c in range(nc):
            b = _q8(e0[p, c])
            o = min(max(_q8(e1[p, c]) - b, -32), 31)
            vals[off + 2 * c] = cquant[cq, (b & 0x7F) << 1]
            vals[off + 2 * c + 1] = cquant[cq, (b & 0x80) | ((o & 0x3F) << 1)]
        for k in range(2 * nc):
            alt[k] = cunq[cq, vals[off + k]]
        decode_endpoints(cem, alt, d0[p], d1[p])
        return 2 * nc
    # RGB / RGBA direct (8 / 12): plain order, or swapped with blue-contraction
    alpha = cem == 12
    n = 8 if alpha else 6
    nc = 4 if alpha else 3
    for c in range(nc):
        vals[off + 2 * c] = _cq(e0[p, c], cq, cquant)
        vals[off + 2 * c + 1] = _cq(e1[p, c], cq, cquant)
    _decode_direct(vals, off, cq, cunq, alpha, d0, d1, p)
    err_plain = _ep_err(chw, e0, e1, p, d0, d1, p, nc)
    # blue-contracted: odd values hold e0 and even values e1, red and green
    # stored as 2x - b so the decoder's (x + b) >> 1 gives them back at
    # twice the precision
    for c in range(2):
        r0 = 2.0 * e0[p, c] - e0[p, 2]
        r1 = 2.0 * e1[p, c] - e1[p, 2]
        if r0 < -0.5 or r0 > 255.5 or r1 < -0.5 or r1 > 255.5:
            return n
    for c in range(nc):
        if c < 2:
            alt[2 * c] = _cq(2.0 * e1[p, c] - e1[p, 2], cq, cquant)
            alt[2 * c + 1] = _cq(2.0 * e0[p, c] - e0[p, 2], cq, cquant)
        else:
            alt[2 * c] = _cq(e1[p, c], cq, cquant)
            alt[2 * c + 1] = _cq(e0[p, c], cq, cquant)
    s0 = cunq[cq, alt[0]] + cunq[cq, alt[2]] + cunq[cq, alt[4]]
    s1 = cunq[cq, alt[1]] + cunq[cq, alt[3]] + cunq[cq, alt[5]]
    if s1 >= s0:
        return n  # would decode unswapped: not a blue-contracted pair
    # np.int64(0), not 0: a literal argument makes numba compile the callee
    # again for that value
    zero = np.int64(0)
    _decode_direct(alt, zero, cq, cunq, alpha, altd, altd[1:], zero)
    if _ep_err(chw, e0, e1, p, altd, altd[1:], zero, nc) < err_plain:
        for k in range(n):
            vals[off + k] = alt[k]
        for c in range(4):
            d0[p, c] = altd[0, c]
            d1[p, c] = altd[1, c]
    return n
