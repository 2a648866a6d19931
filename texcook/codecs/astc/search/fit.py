"""ASTC search: ideal endpoints and weights. Per-texel moments summed per
partition, a principal-axis fit per partition (ideal endpoints, weights and
their importance), least-squares endpoints for fixed weights, weights for
decoded endpoints, and the components worth a weight plane of their own."""

from collections import namedtuple

import numpy as np

from ...._jit import jit_inner
from .lanes import O_E0, O_E1, O_RES, O_SP, O_SS, O_TOT
from .partitioning import _popcount

# one thread's scratch for the fits of a block: per-texel moments (prod (T, 16)) and their sums (tot),
# per-partition sums (mom (4, 16)), ideal endpoints (e0f, e1f (4, 4)), ideal weights and their
# importance per plane (w1, w2, s1, s2 (T,)), and fsc (24, 4) for fit_partitions's own use (it leaves the
# sums of s1 and s2 in fsc[20, 0:2]); runs: the run's first fits (lanes.Lanes.out, an array: a call
# passes each array of a record, and this one is called many times a block)
FitWork = namedtuple("FitWork", "prod tot mom e0f e1f w1 w2 s1 s2 fsc runs")


@jit_inner(inline="always")
def _principal_axis(cov, a, b):
    """Unit principal axis of a 4x4 covariance into a (zero when there is no
    variance): four steps of power iteration from the row of the largest
    variance, on the covariance divided by its trace (its largest eigenvalue
    is then between 1/4 and 1, so the steps need no normalising). b (4,) is
    scratch."""
    best = 0
    for c in range(1, 4):
        if cov[c, c] > cov[best, best]:
            best = c
    tr = cov[0, 0] + cov[1, 1] + cov[2, 2] + cov[3, 3]
    if tr <= 1e-12:
        for c in range(4):
            a[c] = 0.0
        return
    f = 1.0 / tr
    for c in range(4):
        a[c] = cov[best, c] * f
    for _ in range(2):
        for c in range(4):
            b[c] = (cov[c, 0] * a[0] + cov[c, 1] * a[1] + cov[c, 2] * a[2] + cov[c, 3] * a[3]) * f
        for c in range(4):
            a[c] = (cov[c, 0] * b[0] + cov[c, 1] * b[1] + cov[c, 2] * b[2] + cov[c, 3] * b[3]) * f
    nrm = np.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2] + a[3] * a[3])
    if nrm <= 1e-30:
        for c in range(4):
            a[c] = 0.0
    else:
        for c in range(4):
            a[c] /= nrm


# the search takes these sums from its run's first fits (lanes.first_fits,
# the same bits); this is their definition per block, which the tests hold
# the runs' to
@jit_inner(inline="always")
def texel_moments(x, chw, nt, tot):
    """The sums over the block's texels of the 15 moments a line fit needs
    (1, the four weighted components, their ten products; texel_products)
    into tot (16,): all a fit of one partition reads."""
    s0 = np.sqrt(chw[0])
    s1 = np.sqrt(chw[1])
    s2 = np.sqrt(chw[2])
    s3 = np.sqrt(chw[3])
    # in registers, added in texel order as texel_products's rows would be
    a1 = a2 = a3 = a4 = a5 = a6 = a7 = a8 = a9 = a10 = a11 = a12 = a13 = a14 = 0.0
    for t in range(nt):
        v0 = x[t, 0] * s0
        v1 = x[t, 1] * s1
        v2 = x[t, 2] * s2
        v3 = x[t, 3] * s3
        a1 += v0
        a2 += v1
        a3 += v2
        a4 += v3
        a5 += v0 * v0
        a6 += v0 * v1
        a7 += v0 * v2
        a8 += v0 * v3
        a9 += v1 * v1
        a10 += v1 * v2
        a11 += v1 * v3
        a12 += v2 * v2
        a13 += v2 * v3
        a14 += v3 * v3
    tot[0] = float(nt)
    tot[1] = a1
    tot[2] = a2
    tot[3] = a3
    tot[4] = a4
    tot[5] = a5
    tot[6] = a6
    tot[7] = a7
    tot[8] = a8
    tot[9] = a9
    tot[10] = a10
    tot[11] = a11
    tot[12] = a12
    tot[13] = a13
    tot[14] = a14
    tot[15] = 0.0


@jit_inner
def texel_products(x, chw, nt, prod):
    """Per texel the moments texel_moments sums, into prod (nt, 16): made
    only for blocks that go on to more partitions, which are ranked and fitted
    by adding rows."""
    s0 = np.sqrt(chw[0])
    s1 = np.sqrt(chw[1])
    s2 = np.sqrt(chw[2])
    s3 = np.sqrt(chw[3])
    for t in range(nt):
        v0 = x[t, 0] * s0
        v1 = x[t, 1] * s1
        v2 = x[t, 2] * s2
        v3 = x[t, 3] * s3
        prod[t, 0] = 1.0
        prod[t, 1] = v0
        prod[t, 2] = v1
        prod[t, 3] = v2
        prod[t, 4] = v3
        prod[t, 5] = v0 * v0
        prod[t, 6] = v0 * v1
        prod[t, 7] = v0 * v2
        prod[t, 8] = v0 * v3
        prod[t, 9] = v1 * v1
        prod[t, 10] = v1 * v2
        prod[t, 11] = v1 * v3
        prod[t, 12] = v2 * v2
        prod[t, 13] = v2 * v3
        prod[t, 14] = v3 * v3
        prod[t, 15] = 0.0


@jit_inner(inline="always")
def _set_sums(mom, p, sums):
    """Row p of mom (4, 16) from a partition's 15 moment sums (the 16th is 0)."""
    for k in range(15):
        mom[p, k] = sums[k]
    mom[p, 15] = 0.0


@jit_inner(inline="always")
def _last_sums(tot, mom, last):
    """Partition last's moment sums: the block's (tot) less the others'."""
    for k in range(16):
        acc = tot[k]
        for p in range(last):
            acc -= mom[p, k]
        mom[last, k] = acc


@jit_inner(inline="always")
def _partition_moments(labels, nparts, nt, prod, tot, mom):
    """Per partition the sums of the texels' moments (texel_moments) into
    mom (4, 16): the last partition's are the total less the others'."""
    last = nparts - 1
    # each other partition in registers over every texel, one of another
    # partition adding zeros: the same sums in the same order as adding its
    # own texels' rows, without a branch or a store per texel
    for p in range(last):
        a0 = a1 = a2 = a3 = a4 = a5 = a6 = a7 = a8 = a9 = a10 = a11 = a12 = a13 = a14 = 0.0
        for t in range(nt):
            w = 1.0 if labels[t] == p else 0.0
            a0 += w
            a1 += prod[t, 1] * w
            a2 += prod[t, 2] * w
            a3 += prod[t, 3] * w
            a4 += prod[t, 4] * w
            a5 += prod[t, 5] * w
            a6 += prod[t, 6] * w
            a7 += prod[t, 7] * w
            a8 += prod[t, 8] * w
            a9 += prod[t, 9] * w
            a10 += prod[t, 10] * w
            a11 += prod[t, 11] * w
            a12 += prod[t, 12] * w
            a13 += prod[t, 13] * w
            a14 += prod[t, 14] * w
        _set_sums(mom, p, (a0, a1, a2, a3, a4, a5, a6, a7, a8, a9, a10, a11, a12, a13, a14))
    _last_sums(tot, mom, last)


@jit_inner(inline="always")
def _moment_cov(mo, skip, m, cov):
    """Mean m (4,) and covariance cov (4, 4) of weighted texels from their
    moment sums mo (16,) (texel_moments); component skip (-1: none) left out
    as zero, and so is a component whose spread is only rounding. Returns the
    texel count."""
    n = mo[0]
    k = 5
    for c in range(4):
        m[c] = mo[1 + c] / n if n > 0 else 0.0
        for j in range(c, 4):
            cov[c, j] = mo[k] - mo[1 + c] * mo[1 + j] / n if n > 0 else 0.0
            cov[j, c] = cov[c, j]
            k += 1
    for c in range(4):
        if c == skip or cov[c, c] <= 1e-6:
            for j in range(4):
                cov[c, j] = 0.0
                cov[j, c] = 0.0
    if skip >= 0:
        m[skip] = 0.0
    return n


@jit_inner
def line_resid(pmask, nparts, nt, prod, tot, mom, fsc, bound):
    """Weighted squared distance of the texels from their partition's
    principal line (what fit_partitions returns), from the texels' moments
    (texel_moments, texel_products). pmask (4, 3): each partition's texels as
    bits, 48 a word (PartTables.pmask's row of the pattern); mom (4, 16) and
    fsc (24, 4) are scratch. Where a lower bound of it is above bound (a
    candidate that cannot be kept), that lower bound is returned instead."""
    last = nparts - 1
    # each partition but the last summed over its own texels, found from the
    # set bits in texel order: the sums _partition_moments makes, in its order
    for p in range(last):
        a0 = a1 = a2 = a3 = a4 = a5 = a6 = a7 = a8 = a9 = a10 = a11 = a12 = a13 = a14 = 0.0
        for w in range((nt + 47) // 48):
            bits = pmask[p, w]
            while bits != 0:
                low = bits & -bits
                bits ^= low
                t = w * 48 + _popcount(low - 1)
                a0 += 1.0
                a1 += prod[t, 1]
                a2 += prod[t, 2]
                a3 += prod[t, 3]
                a4 += prod[t, 4]
                a5 += prod[t, 5]
                a6 += prod[t, 6]
                a7 += prod[t, 7]
                a8 += prod[t, 8]
                a9 += prod[t, 9]
                a10 += prod[t, 10]
                a11 += prod[t, 11]
                a12 += prod[t, 12]
                a13 += prod[t, 13]
                a14 += prod[t, 14]
        _set_sums(mom, p, (a0, a1, a2, a3, a4, a5, a6, a7, a8, a9, a10, a11, a12, a13, a14))
    _last_sums(tot, mom, last)
    n = fsc[0]
    m = fsc[1]
    a = fsc[2]
    b = fsc[3]
    # no unit axis keeps more of a partition's spread than its largest
    # eigenvalue, at most the covariance's Frobenius norm and at most the
    # fourth root of the trace of its fourth power (the squared Frobenius
    # norm of its square: closer where two eigenvalues are alike): the trace
    # less the smaller bounds what the axis leaves (with a margin far above
    # the rounding). Made only where there is a bound to compare with.
    low = 0.0
    spread = 0.0
    for p in range(nparts):
        cov = fsc[8 + 4 * p:12 + 4 * p]
        n[p] = _moment_cov(mom[p], -1, m, cov)
        if n[p] < 0.5 or bound == np.inf:
            continue
        tr = cov[0, 0] + cov[1, 1] + cov[2, 2] + cov[3, 3]
        f2 = 0.0
        for c in range(4):
            for j in range(4):
                f2 += cov[c, j] * cov[c, j]
        q4 = 0.0
        for c in range(4):
            for j in range(c, 4):
                sq = cov[c, 0] * cov[0, j] + cov[c, 1] * cov[1, j] + cov[c, 2] * cov[2, j] + cov[c, 3] * cov[3, j]
                q4 += sq * sq if j == c else 2.0 * sq * sq
        low += tr - min(tr, np.sqrt(f2), np.sqrt(np.sqrt(q4)))
        spread += tr
    if low - 1e-9 * spread > bound:
        return low
    resid = 0.0
    for p in range(nparts):
        if n[p] < 0.5:
            continue
        cov = fsc[8 + 4 * p:12 + 4 * p]
        _principal_axis(cov, a, b)
        for c in range(4):
            resid += cov[c, c]
            for j in range(4):
                resid -= a[c] * cov[c, j] * a[j]
    return resid


# without reference counting (it allocates nothing): a call otherwise counts
# its 13 arrays in and out; inlined into the kernel instead it was as fast,
# but took a cold compile 3-4 s longer
@jit_inner(_nrt=False)
def fit_partitions(x, chw, labels, nparts, nt, dual, ccs, fw, given=0):
    """Principal-axis fit per partition: ideal endpoints (float, 0..255) and
    ideal weights (0..1) with their importance (squared weighted endpoint
    distance, the error per unit of weight error). With two planes, component
    ccs is fitted on its own and the axis ignores it. Returns the weighted
    squared distance of the texels from their partition's line. Means and
    covariances come from the texels' moments (texel_moments in fw.tot, and
    for more than one partition texel_products in fw.prod); the fit goes into fw (FitWork),
    the sums of s1 and s2 into fw.fsc[20, 0:2].
    given 1: fw.mom already holds the partitions' moment sums (line_resid
    made them for the pattern; the same sums in the same order); given < 0
    with one plane: the block's first fit, made for its run (lanes.first_tile)
    in row -1 - given of fw.runs, is copied."""
    prod, tot, mom, e0f, e1f, w1, w2, s1, s2, fsc, runs = fw
    if given < 0 and not dual:
        o = runs[-1 - given]
        span = o[nt + O_SP]
        for t in range(nt):
            w1[t] = o[t]
            s1[t] = span * span
        for j in range(16):
            mom[0, j] = o[nt + O_TOT + j]
        for c in range(4):
            e0f[0, c] = o[nt + O_E0 + c]
            e1f[0, c] = o[nt + O_E1 + c]
        fsc[20, 0] = o[nt + O_SS]
        fsc[20, 1] = 0.0
        return o[nt + O_RES]
    sq = fsc[0]
    b = fsc[3]
    cov = fsc[4:8]
    mp = fsc[8:12]  # per partition: mean, axis, [lo, hi, lo2, hi2]
    ap = fsc[12:16]
    rng = fsc[16:20]
    for c in range(4):
        sq[c] = np.sqrt(chw[c])
    if dual:
        sq[ccs] = 0.0
    skip = ccs if dual else -1
    if given != 1:
        _partition_moments(labels, nparts, nt, prod, tot, mom)
    resid = 0.0
    for p in range(nparts):
        _moment_cov(mom[p], skip, mp[p], cov)
        a = ap[p]
        _principal_axis(cov, a, b)
        # what the line leaves unexplained: trace minus the variance along it
        for c in range(4):
            resid += cov[c, c]
            for k in range(4):
                resid -= a[c] * cov[c, k] * a[k]
        # orient so that the second endpoint is the brighter one (the plain
        # CEM 8/12 order needs sum(e1) >= sum(e0))
        rgb = 0.0
        for c in range(3):
            if sq[c] > 0:
                rgb += a[c] / sq[c]
        if rgb < 0:
            for c in range(4):
                a[c] = -a[c]
        rng[p, 0] = 1e18
        rng[p, 1] = -1e18
        rng[p, 2] = 1e9
        rng[p, 3] = -1e9
    # one pass: each texel's position along its partition's axis
    if nparts == 1:
        # the ranges in registers: in memory each texel's min and max waits
        # on the store of the one before
        lo, hi, lo2, hi2 = rng[0, 0], rng[0, 1], rng[0, 2], rng[0, 3]
        for t in range(nt):
            pr = 0.0
            for c in range(4):
                pr += (x[t, c] * sq[c] - mp[0, c]) * ap[0, c]
            w1[t] = pr
            lo = min(lo, pr)
            hi = max(hi, pr)
            if dual:
                v = x[t, ccs]
                lo2 = min(lo2, v)
                hi2 = max(hi2, v)
        rng[0, 0], rng[0, 1], rng[0, 2], rng[0, 3] = lo, hi, lo2, hi2
    for t in range(nt if nparts > 1 else 0):
        p = labels[t]
        pr = 0.0
        for c in range(4):
            pr += (x[t, c] * sq[c] - mp[p, c]) * ap[p, c]
        w1[t] = pr
        rng[p, 0] = min(rng[p, 0], pr)
        rng[p, 1] = max(rng[p, 1], pr)
        if dual:
            v = x[t, ccs]
            rng[p, 2] = min(rng[p, 2], v)
            rng[p, 3] = max(rng[p, 3], v)
    for p in range(nparts):
        if mom[p, 0] < 0.5:
            for c in range(4):
                e0f[p, c] = 0.0
                e1f[p, c] = 0.0
            continue
        tlo = rng[p, 0]
        thi = rng[p, 1]
        for c in range(4):
            if sq[c] > 0:
                e0f[p, c] = min(max((mp[p, c] + tlo * ap[p, c]) / sq[c], 0.0), 255.0)
                e1f[p, c] = min(max((mp[p, c] + thi * ap[p, c]) / sq[c], 0.0), 255.0)
            else:
                e0f[p, c] = 0.0
                e1f[p, c] = 0.0
        if dual:
            e0f[p, ccs] = rng[p, 2]
            e1f[p, ccs] = rng[p, 3]
        # channels without weight still decode: give them their mean
        for c in range(4):
            if sq[c] == 0 and not (dual and c == ccs):
                mc = 0.0
                for t in range(nt):
                    if labels[t] == p:
                        mc += x[t, c]
                e0f[p, c] = mc / mom[p, 0]
                e1f[p, c] = mc / mom[p, 0]
    # the importances' sums (in texel order) for the mode estimate, added
    # here beside the divisions, where they do not wait alone
    ss1 = 0.0
    ss2 = 0.0
    for t in range(nt):
        p = labels[t]
        span = rng[p, 1] - rng[p, 0]
        w1[t] = (w1[t] - rng[p, 0]) / span if span > 1e-9 else 0.0
        s1[t] = span * span
        ss1 += s1[t]
        if dual:
            lo2 = rng[p, 2]
            d2 = rng[p, 3] - lo2
            w2[t] = (x[t, ccs] - lo2) / d2 if d2 > 1e-9 else 0.0
            s2[t] = chw[ccs] * d2 * d2
            ss2 += s2[t]
    fsc[20, 0] = ss1
    fsc[20, 1] = ss2
    return resid


@jit_inner
def refit(x, labels, nparts, nt, wt1, wt2, dual, ccs, e0f, e1f, acc):
    """Least-squares endpoints per partition and component for fixed weights,
    from one pass of sums. acc (4, 4, 5) is scratch: per partition and
    component the sums of (1-u)^2, u(1-u), u^2, (1-u)x and ux."""
    if nparts == 1:
        _refit_sums1(x, nt, wt1, wt2, dual, ccs, acc)
    else:
        _refit_sums(x, labels, nparts, nt, wt1, wt2, dual, ccs, acc)
    for p in range(nparts):
        for c in range(4):
            aa = acc[p, c, 0]
            ab = acc[p, c, 1]
            bb = acc[p, c, 2]
            xa = acc[p, c, 3]
            xb = acc[p, c, 4]
            n = aa + 2.0 * ab + bb  # (1-u) + u = 1 per texel
            if n < 0.5:
                continue
            det = aa * bb - ab * ab
            if det > 1e-6 * (aa + bb) * (aa + bb):
                e0 = (xa * bb - xb * ab) / det
                e1 = (xb * aa - xa * ab) / det
            else:
                e0 = (xa + xb) / n
                e1 = e0
            e0f[p, c] = min(max(e0, 0.0), 255.0)
            e1f[p, c] = min(max(e1, 0.0), 255.0)


@jit_inner(inline="always")
def _refit_sums1(x, nt, wt1, wt2, dual, ccs, acc):
    """refit's sums for one partition, in registers (each the same additions
    in the same order as _refit_sums makes them in memory): the weights'
    three sums are shared by the components of a plane."""
    a0 = 0.0
    a1 = 0.0
    a2 = 0.0
    b0 = 0.0
    b1 = 0.0
    b2 = 0.0
    xa0 = 0.0
    xa1 = 0.0
    xa2 = 0.0
    xa3 = 0.0
    xb0 = 0.0
    xb1 = 0.0
    xb2 = 0.0
    xb3 = 0.0
    c2 = ccs if dual else -1
    for t in range(nt):
        u = wt1[t] / 64.0
        v = 1.0 - u
        a0 += v * v
        a1 += u * v
        a2 += u * u
        u2 = u
        v2 = v
        if dual:
            u2 = wt2[t] / 64.0
            v2 = 1.0 - u2
            b0 += v2 * v2
            b1 += u2 * v2
            b2 += u2 * u2
        uc = u2 if c2 == 0 else u
        vc = v2 if c2 == 0 else v
        xa0 += vc * x[t, 0]
        xb0 += uc * x[t, 0]
        uc = u2 if c2 == 1 else u
        vc = v2 if c2 == 1 else v
        xa1 += vc * x[t, 1]
        xb1 += uc * x[t, 1]
        uc = u2 if c2 == 2 else u
        vc = v2 if c2 == 2 else v
        xa2 += vc * x[t, 2]
        xb2 += uc * x[t, 2]
        uc = u2 if c2 == 3 else u
        vc = v2 if c2 == 3 else v
        xa3 += vc * x[t, 3]
        xb3 += uc * x[t, 3]
    for c in range(4):
        on2 = c == c2
        acc[0, c, 0] = b0 if on2 else a0
        acc[0, c, 1] = b1 if on2 else a1
        acc[0, c, 2] = b2 if on2 else a2
    acc[0, 0, 3] = xa0
    acc[0, 0, 4] = xb0
    acc[0, 1, 3] = xa1
    acc[0, 1, 4] = xb1
    acc[0, 2, 3] = xa2
    acc[0, 2, 4] = xb2
    acc[0, 3, 3] = xa3
    acc[0, 3, 4] = xb3


@jit_inner(inline="always")
def _refit_sums(x, labels, nparts, nt, wt1, wt2, dual, ccs, acc):
    """refit's sums per partition and component, into acc. The weights'
    three sums are the same for every component of a plane: each plane's
    are made once per texel (in component c1's row, and ccs's for the
    second plane) and copied to the plane's other components after."""
    c2 = ccs if dual else -1
    c1 = 1 if c2 == 0 else 0
    for p in range(nparts):
        for c in range(4):
            for k in range(5):
                acc[p, c, k] = 0.0
    for t in range(nt):
        p = labels[t]
        u = wt1[t] / 64.0
        v = 1.0 - u
        acc[p, c1, 0] += v * v
        acc[p, c1, 1] += u * v
        acc[p, c1, 2] += u * u
        u2 = u
        v2 = v
        if dual:
            u2 = wt2[t] / 64.0
            v2 = 1.0 - u2
            acc[p, c2, 0] += v2 * v2
            acc[p, c2, 1] += u2 * v2
            acc[p, c2, 2] += u2 * u2
        for c in range(4):
            uc = u2 if c == c2 else u
            vc = v2 if c == c2 else v
            acc[p, c, 3] += vc * x[t, c]
            acc[p, c, 4] += uc * x[t, c]
    for p in range(nparts):
        for c in range(4):
            if c != c1 and c != c2:
                for k in range(3):
                    acc[p, c, k] = acc[p, c1, k]


@jit_inner
def weights_from(x, chw, labels, nt, d0, d1, dual, ccs, w1, w2, s1, s2):
    """Ideal weights for decoded endpoints: projection onto each partition's
    decoded segment."""
    for t in range(nt):
        p = labels[t]
        num = 0.0
        den = 0.0
        for c in range(4):
            if dual and c == ccs:
                continue
            d = d1[p, c] - d0[p, c]
            num += chw[c] * (x[t, c] - d0[p, c]) * d
            den += chw[c] * d * d
        w1[t] = min(max(num / den, 0.0), 1.0) if den > 0 else 0.0
        s1[t] = den
        if dual:
            d = d1[p, ccs] - d0[p, ccs]
            w2[t] = min(max((x[t, ccs] - d0[p, ccs]) / d, 0.0), 1.0) if d != 0 else 0.0
            s2[t] = chw[ccs] * d * d


@jit_inner(inline="always")
def _max_corr(cov, c):
    """Component c's largest correlation with another that varies."""
    worst = 0.0
    for k in range(4):
        if k != c and cov[k, k] > 0:
            worst = max(worst, abs(cov[c, k]) / np.sqrt(cov[c, c] * cov[k, k]))
    return worst


@jit_inner(inline="always")
def _resid_without(cov, c):
    """The weighted squared distance of the texels from their principal line
    with component c left out: the trace of the other three's covariance less
    its largest eigenvalue (the closed form of a symmetric 3x3's). What stays
    off one line once c has a plane of its own."""
    i = 1 if c == 0 else 0
    j = 2 if c <= 1 else 1
    k = 2 if c == 3 else 3
    a = cov[i, i]
    d = cov[j, j]
    f = cov[k, k]
    b = cov[i, j]
    e = cov[i, k]
    g = cov[j, k]
    tr = a + d + f
    off = b * b + e * e + g * g
    if off <= 1e-12 * tr * tr:
        return tr - max(a, d, f)
    q = tr / 3.0
    p = np.sqrt(((a - q) ** 2 + (d - q) ** 2 + (f - q) ** 2 + 2.0 * off) / 6.0)
    # det((A - qI) / p) / 2, in [-1, 1] but for rounding
    r = ((a - q) * ((d - q) * (f - q) - g * g) - b * (b * (f - q) - g * e) + e * (b * g - (d - q) * e)) / (2.0 * p ** 3)
    top = q + 2.0 * p * np.cos(np.arccos(min(max(r, -1.0), 1.0)) / 3.0)
    return max(tr - top, 0.0)


@jit_inner
def dual_channels(tot, opaque, mode, max_corr, out, fsc):
    """Components worth a plane of their own: all that vary (mode 2), or the
    one whose leaving leaves the others closest to one line (_resid_without:
    the most of the block's distance from its line a plane of its own takes
    off; the least correlated component can be a faint noise) when its
    correlation with every other is below max_corr (mode 1), and with mode 3
    the next best after it (a second plane for each of the two: most of what
    trying every component gains, for half the fits), from the block's moment
    sums tot (texel_moments; a component without weight does not vary
    there). Returns the count. fsc (8, 4) is scratch."""
    cov = fsc[4:8]
    _moment_cov(tot, -1, fsc[0], cov)
    n = 0
    best = -1
    bscore = np.inf
    second = -1
    sscore = np.inf
    for c in range(4):
        if cov[c, c] <= 0 or (c == 3 and opaque):
            continue
        if mode == 2:
            out[n] = c
            n += 1
            continue
        left = _resid_without(cov, c)
        if left < bscore:
            second = best
            sscore = bscore
            bscore = left
            best = c
        elif left < sscore:
            second = c
            sscore = left
    if mode != 2 and best >= 0 and _max_corr(cov, best) < max_corr:
        out[0] = best
        n = 1
        if mode == 3 and second >= 0 and _max_corr(cov, second) < max_corr:
            out[1] = second
            n = 2
    return n
