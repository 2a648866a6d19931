"""ASTC search: endpoint quantisation. The CEM each partition gets for a
family, and the colour values of each CEM chosen for the texels: the refit's
sums (per partition and component: sum (1-u)^2, u(1-u), u^2, (1-u)x, ux over
its texels) give the squared error of any pair of decoded endpoints exactly
(up to the decoder's rounding), so candidate codes are compared by the error
they decode to, not by their distance from the fitted float endpoints.
Candidates are the codes on either side of the ideal value (through the
unquantisation table, never rounded to 8 bits first); base+scale fits its
constrained form (one colour and a scale) to the texels; blue-contraction
and base+offset stay legal (the decoder's swap rule holds for what is
written)."""

from collections import namedtuple

import numpy as np

from ...._jit import jit_inner
from ..endpoint_decode import _bit_transfer_signed, decode_endpoints
from ..quant import COLOUR_CEIL, COLOUR_FLOOR, COLOUR_ORDER, COLOUR_RANK, RANGE_LEVELS

# _nrt=False on the helpers called per fit or candidate: no reference
# counting of their array arguments (why: grid.py)

# CEM families: per partition the content (grey?, opaque?) picks the mode
FAM_DIRECT = 0  # 0 / 4 / 8 / 12
FAM_SCALE = 1  # 0 / 4 / 6 / 10
FAM_OFFSET = 2  # 0 / 4 / 9 / 13, only where the colour range keeps them exact
FAM_LUMA = 3  # 0 / 4 for every partition: two colour values buy the widest colour range
# FAM_MIXED + code: each colour partition p its own kind, (code >> 2p) & 3 of
# 0 direct, 1 base+scale, 2 luminance: the values one partition's colours
# need are not spent on another's that a cheaper kind holds
FAM_MIXED = 4
N_FAMILIES = FAM_MIXED + 256
OFFSET_MIN_RANGE = 17  # 128 levels: every bit base+offset uses survives

# what quant_endpoints reads and writes: float endpoints e0, e1 (4, 4), the
# ISE values (vals (32,)), the decoded 8-bit endpoints d0, d1 (4, 4), and alt
# (8,), altd (2, 4) scratch (candidate codes, unquantised values, offsets)
EndpointWork = namedtuple("EndpointWork", "e0 e1 vals d0 d1 alt altd")


@jit_inner(_nrt=False)
def _cem_for(fam, p, grey, opaque):
    if fam >= FAM_MIXED:
        fam = (FAM_DIRECT, FAM_SCALE, FAM_LUMA, FAM_DIRECT)[((fam - FAM_MIXED) >> (2 * p)) & 3]
    if grey or fam == FAM_LUMA:
        return 0 if opaque else 4
    if fam == FAM_SCALE:
        return 6 if opaque else 10
    if fam == FAM_OFFSET:
        return 9 if opaque else 13
    return 8 if opaque else 12


@jit_inner(_nrt=False)
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
        cems[p] = _cem_for(fam, p, pgrey[p], popaque[p])
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


@jit_inner(_nrt=False)
def mixed_families(nparts, pgrey, psm, plm, luma, fam_list, fam_extra, nfl, miss, code):
    """Append to fam_list (from nfl) the mixed families worth estimating: for
    each count of colour values saved (two per step), the kinds per colour
    partition (direct, base+scale missing psm[p], luminance missing plm[p]
    where `luma`) that miss least, unless that is every partition base+scale
    or every one luminance (families of their own); their misses go to
    fam_extra. miss, code (2, 9) are scratch. Returns the new nfl."""
    for k in range(9):
        miss[0, k] = np.inf
    miss[0, 0] = 0.0
    code[0, 0] = 0
    cur = 0
    allscale = 0
    allluma = 0
    top = 0
    for p in range(nparts):
        if pgrey[p]:
            continue
        allscale |= 1 << (2 * p)
        allluma |= 2 << (2 * p)
        nxt = 1 - cur
        for k in range(9):
            miss[nxt, k] = np.inf
        for k in range(top + 1):
            m = miss[cur, k]
            if m == np.inf:
                continue
            for opt in range(3 if luma else 2):
                v = m + (0.0 if opt == 0 else (psm[p] if opt == 1 else plm[p]))
                if v < miss[nxt, k + opt]:
                    miss[nxt, k + opt] = v
                    code[nxt, k + opt] = code[cur, k] | (opt << (2 * p))
        top += 2 if luma else 1
        cur = nxt
    for k in range(1, top + 1):
        c = code[cur, k]
        if miss[cur, k] < np.inf and c != allscale and c != allluma:
            fam_list[nfl] = FAM_MIXED + c
            fam_extra[FAM_MIXED + c] = miss[cur, k]
            nfl += 1
    return nfl


@jit_inner(inline="always")
def expand(e, srgb):
    if srgb:
        return (e << 8) | 0x80
    return e * 257


# _bracket, _q and _qmin are called from a dozen places each: compiled once
# and called (LLVM inlines them where it pays), not copied into every caller
# by numba, they cost the candidate encoding's first compile 1.2 s less, the
# same speed
@jit_inner(_nrt=False)
def _bracket(v, cq, cunq):
    """The codes of range cq whose values are next to float v on either side:
    (nearer, farther); both the same where v is a code's value or past an
    end of the range."""
    f = np.floor(v)
    i = min(max(int(f), 0), 255)
    j = min(max(int(f) + (1 if v > f else 0), 0), 255)
    lo = COLOUR_FLOOR[cq, i]
    hi = COLOUR_CEIL[cq, j]
    if cunq[cq, hi] - v < v - cunq[cq, lo]:
        return hi, lo
    return lo, hi


@jit_inner(_nrt=False)
def _q(acc, p, c, a, b):
    """Squared error of component c of partition p's texels decoded between
    a and b, less the constant sum of x^2 (acc: the refit's sums)."""
    return (acc[p, c, 0] * a * a + 2.0 * acc[p, c, 1] * a * b + acc[p, c, 2] * b * b
            - 2.0 * (acc[p, c, 3] * a + acc[p, c, 4] * b))


@jit_inner(inline="always")
def fit_err(acc, nparts, chw, e0, e1, sxx):
    """Weighted squared error of float endpoints e0, e1 (4, 4) at the weights
    the refit's sums acc were made for; sxx: the block's weighted sum of
    squared texel values (what _q leaves out)."""
    e = sxx
    for p in range(nparts):
        for c in range(4):
            e += chw[c] * _q(acc, p, c, e0[p, c], e1[p, c])
    return e


@jit_inner(_nrt=False)
def _pair(acc, p, c, v0, v1, cq, cunq):
    """The best codes (k0, k1) for one component's two endpoints near float
    v0, v1 by decoded error; returns (k0, k1, error)."""
    n0, f0 = _bracket(v0, cq, cunq)
    n1, f1 = _bracket(v1, cq, cunq)
    aa = acc[p, c, 0]
    ab2 = 2.0 * acc[p, c, 1]
    bb = acc[p, c, 2]
    xa2 = 2.0 * acc[p, c, 3]
    xb2 = 2.0 * acc[p, c, 4]
    best = np.inf
    b0 = n0
    b1 = n1
    for i in range(2 if f0 != n0 else 1):
        k0 = n0 if i == 0 else f0
        a = float(cunq[cq, k0])
        qa = aa * a * a - xa2 * a
        for j in range(2 if f1 != n1 else 1):
            k1 = n1 if j == 0 else f1
            b = float(cunq[cq, k1])
            e = qa + (ab2 * a + bb * b - xb2) * b
            if e < best:
                best = e
                b0 = k0
                b1 = k1
    return b0, b1, best


@jit_inner(_nrt=False)
def _mean(acc, p, c, fallback):
    """The one value that best stands for both endpoints of component c."""
    n = acc[p, c, 0] + 2.0 * acc[p, c, 1] + acc[p, c, 2]
    return (acc[p, c, 3] + acc[p, c, 4]) / n if n > 1e-9 else fallback


@jit_inner(_nrt=False)
def _luma(acc, p, chw, l0, l1, cq, cunq, vals, off):
    """CEM 0/4's two luminance codes near l0, l1 by the RGB decoded error."""
    n0, f0 = _bracket(l0, cq, cunq)
    n1, f1 = _bracket(l1, cq, cunq)
    best = np.inf
    for i in range(2):
        k0 = n0 if i == 0 else f0
        for j in range(2):
            k1 = n1 if j == 0 else f1
            e = 0.0
            for c in range(3):
                e += chw[c] * _q(acc, p, c, cunq[cq, k0], cunq[cq, k1])
            if e < best:
                best = e
                vals[off] = k0
                vals[off + 1] = k1


@jit_inner(_nrt=False)
def _direct(acc, p, chw, e0, e1, cq, cunq, vals, off):
    """CEM 8/12 in the plain order: the best codes per component; if the
    decoder would read them swapped (sum of the second below the first's),
    the best of the candidates' combinations it reads in order, or one colour
    for both endpoints if that is closer. Returns the RGB error."""
    err = 0.0
    s0 = 0
    s1 = 0
    for c in range(3):
        k0, k1, e = _pair(acc, p, c, e0[p, c], e1[p, c], cq, cunq)
        vals[off + 2 * c] = k0
        vals[off + 2 * c + 1] = k1
        err += chw[c] * e
        s0 += cunq[cq, k0]
        s1 += cunq[cq, k1]
    if s1 >= s0:
        return err
    # rare: every combination of the components' candidates (two codes each end)
    err = np.inf
    for m in range(64):
        e = 0.0
        sd = 0
        for c in range(3):
            n0, f0 = _bracket(e0[p, c], cq, cunq)
            n1, f1 = _bracket(e1[p, c], cq, cunq)
            u0 = cunq[cq, f0 if (m >> (2 * c)) & 1 else n0]
            u1 = cunq[cq, f1 if (m >> (2 * c)) & 2 else n1]
            e += chw[c] * _q(acc, p, c, u0, u1)
            sd += u1 - u0
        if sd >= 0 and e < err:
            err = e
            for c in range(3):
                n0, f0 = _bracket(e0[p, c], cq, cunq)
                n1, f1 = _bracket(e1[p, c], cq, cunq)
                vals[off + 2 * c] = f0 if (m >> (2 * c)) & 1 else n0
                vals[off + 2 * c + 1] = f1 if (m >> (2 * c)) & 2 else n1
    # one colour for both endpoints: always legal
    flat = 0.0
    for c in range(3):
        k = _bracket(_mean(acc, p, c, e0[p, c]), cq, cunq)[0]
        u = cunq[cq, k]
        flat += chw[c] * _q(acc, p, c, u, u)
    if err <= flat:
        return err
    for c in range(3):
        k = _bracket(_mean(acc, p, c, e0[p, c]), cq, cunq)[0]
        vals[off + 2 * c] = k
        vals[off + 2 * c + 1] = k
    return flat


@jit_inner(_nrt=False)
def _qmin(acc, p, c):
    """The least _q of component c over all real endpoint pairs: what no
    encoding can go below."""
    aa = acc[p, c, 0]
    ab = acc[p, c, 1]
    bb = acc[p, c, 2]
    xa = acc[p, c, 3]
    xb = acc[p, c, 4]
    det = aa * bb - ab * ab
    if det > 1e-6 * (aa + bb) * (aa + bb):
        return -(bb * xa * xa - 2.0 * ab * xa * xb + aa * xb * xb) / det
    n = aa + 2.0 * ab + bb
    return -(xa + xb) * (xa + xb) / n if n > 1e-9 else 0.0


@jit_inner(_nrt=False)
def _blue(acc, p, chw, e0, e1, cq, cunq, alt, bound):
    """CEM 8/12 blue-contracted into alt[0:6], if it decodes to less error
    than bound: the decoder swaps the pair and reads red and green as
    (v + blue) >> 1, so odd values hold the first endpoint, even ones the
    second, red and green at twice the precision. Each of blue's candidate
    pairs that can still win takes red's and green's best codes, or if those
    are not read as contracted (odd sum below the even sum), the best of
    their 16 combinations that is. Returns the RGB error (inf if nothing
    legal beat bound)."""
    c2 = np.int64(2)  # np.int64 values, not literals (see quant_endpoints)
    # red and green can do no better than their unquantised least error
    rg = chw[0] * _qmin(acc, p, 0) + chw[1] * _qmin(acc, p, 1)
    n4, f4 = _bracket(e1[p, 2], cq, cunq)
    n5, f5 = _bracket(e0[p, 2], cq, cunq)
    best = bound
    found = False
    bro = bre = bgo = bge = bk4 = bk5 = 0
    for i in range(2):
        k4 = n4 if i == 0 else f4
        b1 = cunq[cq, k4]
        for j in range(2):
            k5 = n5 if j == 0 else f5
            b0 = cunq[cq, k5]
            eb = chw[2] * _q(acc, p, c2, b0, b1)
            if eb + rg >= best:
                continue
            # red's and green's candidates: odd values read as (v + b0) >> 1,
            # aimed half a level up (the shift rounds down), even ones with b1
            for c in range(2):
                no, fo = _bracket(2.0 * e0[p, c] - b0 + 0.5, cq, cunq)
                ne, fe = _bracket(2.0 * e1[p, c] - b1 + 0.5, cq, cunq)
                alt[4 * c] = no
                alt[4 * c + 1] = fo
                alt[4 * c + 2] = ne
                alt[4 * c + 3] = fe
            # the 16 combinations, red's and green's own best first
            m0 = 0
            er = np.inf
            eg = np.inf
            for m in range(4):
                e = _q(acc, p, 0, (cunq[cq, alt[m & 1]] + b0) >> 1, (cunq[cq, alt[2 + (m >> 1)]] + b1) >> 1)
                if e < er:
                    er = e
                    m0 = (m0 & 12) | m
                e = _q(acc, p, 1, (cunq[cq, alt[4 + (m & 1)]] + b0) >> 1, (cunq[cq, alt[6 + (m >> 1)]] + b1) >> 1)
                if e < eg:
                    eg = e
                    m0 = (m0 & 3) | (m << 2)
            if eb + chw[0] * er + chw[1] * eg >= best:
                continue
            for t in range(17):
                m = m0 if t == 0 else t - 1
                if t > 0 and m == m0:
                    continue
                ro = alt[m & 1]
                re = alt[2 + ((m >> 1) & 1)]
                go = alt[4 + ((m >> 2) & 1)]
                ge = alt[6 + (m >> 3)]
                uro = (cunq[cq, ro] + b0) >> 1
                ure = (cunq[cq, re] + b1) >> 1
                ugo = (cunq[cq, go] + b0) >> 1
                uge = (cunq[cq, ge] + b1) >> 1
                err = eb + chw[0] * _q(acc, p, 0, uro, ure) + chw[1] * _q(acc, p, 1, ugo, uge)
                if err < best and cunq[cq, ro] + cunq[cq, go] + b0 < cunq[cq, re] + cunq[cq, ge] + b1:
                    best = err
                    found = True
                    bro, bre, bgo, bge, bk4, bk5 = ro, re, go, ge, k4, k5
                    if t == 0:
                        break  # the unconstrained best is legal
    if not found:
        return np.inf
    alt[0] = bre
    alt[1] = bro
    alt[2] = bge
    alt[3] = bgo
    alt[4] = bk4
    alt[5] = bk5
    return best


@jit_inner(_nrt=False)
def _scale_c(acc, p, c, s, fallback):
    """Base+scale: the colour value of component c that best fits the texels
    for scale s (endpoints s*C and C)."""
    d = acc[p, c, 0] * s * s + 2.0 * acc[p, c, 1] * s + acc[p, c, 2]
    if d <= 1e-9:
        return fallback
    return min(max((acc[p, c, 3] * s + acc[p, c, 4]) / d, 0.0), 255.0)


@jit_inner(_nrt=False)
def _scale(acc, p, chw, e0, e1, cq, cunq, vals, off, alt):
    """CEM 6/10: the colour C and scale s (endpoints C*s >> 8 and C) fitted
    to the texels (alternating least squares from the fitted endpoints'
    ratio), then the scale codes around the fit, each with its best colour
    codes, by the decoded error."""
    num = 0.0
    den = 0.0
    for c in range(3):
        num += chw[c] * e0[p, c] * e1[p, c]
        den += chw[c] * e1[p, c] * e1[p, c]
    s = min(max(num / den, 0.0), 1.0) if den > 0 else 1.0
    for _ in range(3):
        num = 0.0
        den = 0.0
        for c in range(3):
            cc = _scale_c(acc, p, c, s, e1[p, c])
            num += chw[c] * (acc[p, c, 3] * cc - acc[p, c, 1] * cc * cc)
            den += chw[c] * acc[p, c, 0] * cc * cc
        if den <= 1e-9:
            break
        s = min(max(num / den, 0.0), 1.0)
    k = _bracket(256.0 * s, cq, cunq)[0]
    r = COLOUR_RANK[cq, k]
    best = np.inf
    for rr in range(max(r - 1, 0), min(r + 2, RANGE_LEVELS[cq])):
        ks = COLOUR_ORDER[cq, rr]
        su = cunq[cq, ks]
        err = 0.0
        for c in range(3):
            n, f = _bracket(_scale_c(acc, p, c, su / 256.0, e1[p, c]), cq, cunq)
            cb = np.inf
            for i in range(2):
                kc = n if i == 0 else f
                u = cunq[cq, kc]
                e = _q(acc, p, c, (u * su) >> 8, u)
                if e < cb:
                    cb = e
                    alt[c] = kc
            err += chw[c] * cb
        if err < best:
            best = err
            for c in range(3):
                vals[off + c] = alt[c]
            vals[off + 3] = ks


@jit_inner(_nrt=False)
def _offset_c(acc, p, c, v0, v1, omin, cq, cunq, cquant, vals, off, offs):
    """Base+offset, one component: bases on either side of v0, offsets (at
    least omin, 6 bits signed) on either side of v1 - base, as the decoder
    reads their quantised values back; codes into vals[off + 2c], [+ 1],
    the decoded offset into offs[c]."""
    best = np.inf
    oc = min(max(v1 - v0, omin), 31.0)
    if oc != v1 - v0:
        # the offset at its bound: the base that fits best with it
        n = acc[p, c, 0] + 2.0 * acc[p, c, 1] + acc[p, c, 2]
        if n > 1e-9:
            v0 = (acc[p, c, 3] + acc[p, c, 4] - oc * (acc[p, c, 1] + acc[p, c, 2])) / n
        v1 = v0 + oc
    bl = min(max(int(np.floor(v0)), 0), 255)
    for i in range(2):
        b = min(bl + i, 255)
        ol = int(np.floor(v1)) - b
        for j in range(2):
            o = min(max(ol + j, omin, -32), 31)
            ka = cquant[cq, (b & 0x7F) << 1]
            kb = cquant[cq, (b & 0x80) | ((o & 0x3F) << 1)]
            do, db = _bit_transfer_signed(cunq[cq, kb], cunq[cq, ka])
            e = _q(acc, p, c, db, min(max(db + do, 0), 255))
            if e < best:
                best = e
                vals[off + 2 * c] = ka
                vals[off + 2 * c + 1] = kb
                offs[c] = do


@jit_inner(_nrt=False)
def quant_endpoints(cem, p, cq, chw, cunq, cquant, off, ep, acc):
    """Quantise partition p's endpoints for its CEM by the decoded error of
    its texels (acc (4, 4, 5): the refit's sums), starting from the fitted
    float endpoints e0[p], e1[p]: ISE values into vals[off:], decoded 8-bit
    endpoints into d0[p], d1[p] (what the decoder computes), all fields of
    ep (EndpointWork). Returns the number of values written."""
    e0, e1, vals, d0, d1, alt, altd = ep
    # np.int64 values, not literals: numba compiles a callee once more for
    # every literal value it is passed
    ca = np.int64(3)
    olo = np.int64(-32)
    ozero = np.int64(0)
    contracted = False
    if cem == 0 or cem == 4:
        wl = max(chw[0] + chw[1] + chw[2], 1e-9)
        l0 = (e0[p, 0] * chw[0] + e0[p, 1] * chw[1] + e0[p, 2] * chw[2]) / wl
        l1 = (e1[p, 0] * chw[0] + e1[p, 1] * chw[1] + e1[p, 2] * chw[2]) / wl
        _luma(acc, p, chw, l0, l1, cq, cunq, vals, off)
        n = 2
    elif cem == 6 or cem == 10:
        _scale(acc, p, chw, e0, e1, cq, cunq, vals, off, alt)
        n = 4
    elif cem == 9 or cem == 13:
        # base + signed 6-bit offset: v(2c) holds the base's low 7 bits, v(2c+1)
        # its top bit and the offset (bit_transfer_signed in reverse); offsets
        # summing below zero would be read swapped and blue-contracted, so
        # then every colour offset is kept at zero or above
        offs = altd[0]
        for c in range(3):
            _offset_c(acc, p, c, e0[p, c], e1[p, c], olo, cq, cunq, cquant, vals, off, offs)
        if offs[0] + offs[1] + offs[2] < 0:
            for c in range(3):
                _offset_c(acc, p, c, e0[p, c], e1[p, c], ozero, cq, cunq, cquant, vals, off, offs)
        n = 6
        if cem == 13:
            _offset_c(acc, p, ca, e0[p, 3], e1[p, 3], olo, cq, cunq, cquant, vals, off, offs)
            n = 8
    else:
        # RGB / RGBA direct (8 / 12): plain order, or swapped with blue-contraction
        err = _direct(acc, p, chw, e0, e1, cq, cunq, vals, off)
        if _blue(acc, p, chw, e0, e1, cq, cunq, alt, err) < err:
            for k in range(6):
                vals[off + k] = alt[k]
            contracted = True
        n = 6
    if cem == 4 or cem == 10 or cem == 12:
        # alpha's pair after the colour values, swapped with a contracted colour
        k0, k1, _ = _pair(acc, p, ca, e0[p, 3], e1[p, 3], cq, cunq)
        vals[off + n] = k1 if contracted else k0
        vals[off + n + 1] = k0 if contracted else k1
        n += 2
    # what the decoder makes of them
    for k in range(n):
        alt[k] = cunq[cq, vals[off + k]]
    decode_endpoints(cem, alt, d0[p], d1[p])
    return n
