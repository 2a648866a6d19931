"""Alpha-test coverage preservation.

Coverage is the fraction of texels whose alpha is above the cutoff T. Plain
filtering pulls alpha towards the mean at every level, so a cut-out whose
alpha sits mostly above T (foliage, fences) loses coverage and thins out with
distance. Each level's alpha is multiplied by the scale s that brings its
coverage back to level 0's (alpha = min(1, alpha * s)).

The count of texels with alpha * s > T only changes where T / s crosses one of
the level's alpha values, so the scale is found by a binary search over the
sorted alphas rather than by bisecting s blindly: the result is the count
closest to the target that the level can reach, and among the scales that
reach it the one closest to 1 (least change to the image).
"""

import numpy as np


def alpha_coverage(alpha, cutoff):
    """Fraction of texels with alpha > cutoff."""
    alpha = np.asarray(alpha)
    if alpha.size == 0:
        return 0.0
    return float(np.count_nonzero(alpha > cutoff)) / alpha.size


def _count_above(desc, threshold):
    """Number of values in descending `desc` strictly above `threshold`."""
    # desc is descending: negate to search an ascending array.
    return int(np.searchsorted(-desc, -threshold, side="left"))


def coverage_scale(alpha, cutoff, target):
    """The scale s for which min(1, alpha * s) has coverage closest to `target`
    at `cutoff`; ties go to the s closest to 1."""
    a = np.asarray(alpha, np.float64).ravel()
    n = a.size
    if n == 0 or cutoff <= 0.0 or cutoff >= 1.0:
        # T = 0: scaling never moves a texel across 0 (zeros stay zero);
        # T = 1: min(1, a * s) is never above 1. Coverage is what it is.
        return 1.0
    desc = np.sort(a)[::-1]
    # Texels with alpha 0 can never be lifted above T: the reachable counts are
    # 0 .. number of non-zero texels.
    reachable = int(np.count_nonzero(desc > 0.0))
    want = int(np.clip(round(target * n), 0, reachable))

    def interval(k):
        """(lo, hi) range of thresholds theta = T / s that give exactly k texels
        above, or None when ties make k unreachable. Count k needs
        desc[k] <= theta < desc[k-1]."""
        upper = desc[k - 1] if k > 0 else np.inf
        # a texel at or below 0 never crosses T (s > 0): it bounds nothing
        lower = max(desc[k], 0.0) if k < n else 0.0
        if not upper > lower:
            return None
        return lower, upper

    # Counts the level can reach: k works when the k-th and (k+1)-th largest
    # alphas differ (ties move together). Take the one closest to the target,
    # and of two equally close, the one nearer the current count.
    ks = np.flatnonzero(desc[:-1] > desc[1:]) + 1
    valid = np.concatenate([[0], ks, [n] if desc[-1] > 0.0 else []]).astype(np.int64)
    valid = valid[valid <= reachable]
    current = _count_above(desc, cutoff)
    order = np.lexsort((np.abs(valid - current), np.abs(valid - want)))
    best = int(valid[order[0]])
    lower, upper = interval(best)
    if lower <= cutoff < upper:
        return 1.0  # the level already has this count
    if np.isfinite(upper):
        # Any theta in [lower, upper) gives the count; the middle of the gap is
        # safest against float32 rounding of alpha * s.
        theta = 0.5 * (lower + upper)
    else:
        # k = 0: every texel must end at or below T; the smallest change does it.
        theta = lower * (1.0 + 1e-6)
    return float(cutoff / theta)


def scale_alpha_to_coverage(alpha, cutoff, target):
    """alpha (any shape, float32) scaled so that its coverage at `cutoff` is as
    close to `target` as the texels allow; returns a new float32 array."""
    alpha = np.asarray(alpha, np.float32)
    s = coverage_scale(alpha, cutoff, target)
    if s == 1.0:
        return alpha.copy()
    peak = float(np.abs(alpha).max()) if alpha.size else 0.0
    out = _scaled(alpha, s, peak)
    # float32 rounding of alpha * s can land exactly on the cutoff for texels
    # the float64 search put on the other side; nudge the scale until the
    # stored values give the count the search chose.
    a64 = alpha.astype(np.float64).ravel()
    want = int(np.count_nonzero(a64 * s > cutoff))
    for _ in range(8):
        got = int(np.count_nonzero(out > cutoff))
        if got == want:
            break
        s *= 1.0 + (1e-6 if got < want else -1e-6)
        out = _scaled(alpha, s, peak)
    return out


_FLOAT_MAX = float(np.finfo(np.float32).max)


def _scaled(alpha, s, peak):
    """min(1, alpha * s) as float32. Lifting tiny alphas (denormals) takes a
    scale beyond float32, and negative alphas times a huge scale go below its
    range: then the product is made in float64 and saturated."""
    if s * peak < 0.5 * _FLOAT_MAX and s < _FLOAT_MAX:  # a margin for float32(s) rounding up
        return np.minimum(alpha * np.float32(s), np.float32(1.0))
    return np.clip(alpha.astype(np.float64) * s, -_FLOAT_MAX, 1.0).astype(np.float32)
