"""Image quality measures: PSNR (overall, per channel, per level), max error and
angular error of normal maps.

Float textures may hold NaN and Inf. Errors are then defined texel by texel: two
equal values (Inf and Inf, or NaN and NaN) differ by 0; a non-finite value
against anything else differs by Inf. So PSNR is +inf (identical), a finite
number, or -inf (some non-finite value does not match): never NaN, and no numpy
warning is raised on the way."""

import math

import numpy as np

from .normals import z_from_xy


def _as_float(a):
    return np.asarray(a, dtype=np.float64)


def squared_errors(a, b):
    """(a - b)^2 in float64, with the non-finite rule of the module docstring."""
    a, b = _as_float(a), _as_float(b)
    if a.shape != b.shape:
        raise ValueError(f"shapes differ: {a.shape} vs {b.shape}")
    with np.errstate(invalid="ignore", over="ignore"):
        se = (a - b) ** 2
    bad = ~np.isfinite(se)
    if bad.any():
        same = (a == b) | (np.isnan(a) & np.isnan(b))
        se[bad] = np.where(same[bad], 0.0, np.inf)
    return se


def mse(a, b, channels=None):
    a, b = _as_float(a), _as_float(b)
    if channels is not None:
        a, b = a[..., list(channels)], b[..., list(channels)]
    se = squared_errors(a, b)
    return float(np.mean(se)) if se.size else 0.0


def psnr(a, b, peak=255.0, channels=None):
    """PSNR in dB over the chosen channels (all when None); inf for identical."""
    return psnr_from_mse(mse(a, b, channels), peak)


def psnr_per_channel(a, b, peak=255.0):
    return [psnr(a, b, peak, [c]) for c in range(np.asarray(a).shape[-1])]


def max_error(a, b, channels=None):
    a, b = _as_float(a), _as_float(b)
    if channels is not None:
        a, b = a[..., list(channels)], b[..., list(channels)]
    return math.sqrt(float(np.max(squared_errors(a, b)))) if a.size else 0.0


def compare_level(a, b, channels):
    """One row of `texcook compare`: PSNR over `channels` and per channel (peak
    1.0), max error, and how many values are NaN or Inf in either; plus the
    squared-error sum and count for an overall figure."""
    a, b = _as_float(a), _as_float(b)
    chans = list(channels)
    se = squared_errors(a[..., chans], b[..., chans])
    nonfinite = int(np.count_nonzero(~np.isfinite(a[..., chans]) | ~np.isfinite(b[..., chans])))
    row = {
        "psnr": psnr_from_mse(float(se.mean()) if se.size else 0.0, 1.0),
        "channels": {"RGBA"[c]: psnr_from_mse(float(se[..., i].mean()), 1.0) for i, c in enumerate(chans)},
        "max_error": math.sqrt(float(se.max())) if se.size else 0.0,
        "nonfinite": nonfinite,
    }
    return row, float(se.sum()), se.size


def psnr_levels(levels_a, levels_b, peak=255.0, channels=None):
    """PSNR of each mip level pair."""
    if len(levels_a) != len(levels_b):
        raise ValueError(f"level counts differ: {len(levels_a)} vs {len(levels_b)}")
    return [psnr(a, b, peak, channels) for a, b in zip(levels_a, levels_b)]


def normal_angular_error(a, b):
    """Angles in degrees between normals stored as unorm8 (or 0..1 float) in R and G,
    with Z reconstructed as sqrt(1 - x^2 - y^2). Returns (mean, 99th percentile)."""
    ang = normal_angular_errors(a, b)
    return float(ang.mean()), float(np.percentile(ang, 99))


def normal_angular_errors(a, b):
    """The angle in degrees at every texel (flattened), as normal_angular_error."""
    va, vb = _unpack_normals(a), _unpack_normals(b)
    cos = np.clip(np.sum(va * vb, axis=-1), -1.0, 1.0)
    return np.degrees(np.arccos(cos)).ravel()


def _unpack_normals(x):
    x = _as_float(x)
    if np.issubdtype(np.asarray(x).dtype, np.integer) or x.max() > 1.0:
        x = x / 255.0
    xy = x[..., :2] * 2.0 - 1.0
    z = z_from_xy(xy[..., 0], xy[..., 1])
    v = np.concatenate([xy, z[..., None]], axis=-1)
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n == 0, 1.0, n)


def psnr_from_mse(m, peak=255.0):
    """+inf for 0, -inf for an infinite error, NaN only for a NaN input."""
    if m != m:
        return math.nan
    if m <= 0.0:
        return math.inf
    if math.isinf(m):
        return -math.inf
    ratio = peak * peak / m
    return 10.0 * math.log10(ratio) if ratio > 0.0 else -math.inf


def angular_summary(a, b):
    """Mean, 99th percentile and largest angle (degrees) between normal maps."""
    return angle_summary(normal_angular_errors(a, b))


def angle_summary(angles):
    """Mean, 99th percentile and largest of angles in degrees (a flat array)."""
    return {"mean": float(angles.mean()), "p99": float(np.percentile(angles, 99)), "max": float(angles.max())}


# --- HDR measures: on linear float RGB, values clamped to the half float's range


LOG2_FLOOR = 2.0 ** -14  # the smallest normal half float: darker values count as this


def _hdr(a):
    """float64 copy of linear values clamped to 0..65504 (NaN to 0), as the
    half floats an HDR format stores them."""
    return np.clip(np.nan_to_num(_as_float(a), nan=0.0), 0.0, 65504.0)


def _log2(a, floor=LOG2_FLOOR):
    """log2 of the magnitude in stops above `floor` (0 at and below it), with
    the value's sign: log2 v up to a constant for positive values, and
    signed HDR (bc6h-sf) keeps its negative half."""
    x = np.clip(np.nan_to_num(_as_float(a), nan=0.0), -65504.0, 65504.0)
    return np.sign(x) * (np.log2(np.maximum(np.abs(x), floor)) - math.log2(floor))


def hdr_log2_errors(a, b, floor=LOG2_FLOOR):
    """Differences of log2 values (in stops), magnitudes below `floor` counted
    as floor, the sign kept (_log2)."""
    return _log2(a, floor) - _log2(b, floor)


def log2_peak(a, floor=LOG2_FLOOR):
    """The range of a reference in stops: log2 of its largest over its smallest
    value (below `floor` counted as floor; across 0, the stops of both
    signs), at least 1."""
    la = _log2(a, floor)
    return max(1.0, float(la.max() - la.min())) if la.size else 1.0


def log2_psnr(a, b, floor=LOG2_FLOOR):
    """PSNR of log2 values over all given channels: a the reference. Values
    below `floor` count as floor (negative values as the negated log2 of
    their magnitude, _log2); the peak is the reference's range in stops
    (log2_peak), so one stop of error everywhere scores 20 log10(range) dB."""
    d = hdr_log2_errors(a, b, floor)
    return psnr_from_mse(float(np.mean(d * d)) if d.size else 0.0, log2_peak(a, floor))


def mpsnr(a, b, fstop_lo=-10, fstop_hi=10):
    """Multi-exposure PSNR as astcenc reports it (its mPSNR (RGB)): each value
    exposed by 2^e for every whole stop e in fstop_lo..fstop_hi, mapped to
    255 * v^(1/2.2) clamped to 0..255, squared differences summed over the
    exposures and averaged; peak 255."""
    va, vb = _hdr(a), _hdr(b)
    total = 0.0
    for e in range(fstop_lo, fstop_hi + 1):
        ta = np.clip(255.0 * (va * 2.0 ** e) ** (1.0 / 2.2), 0.0, 255.0)
        tb = np.clip(255.0 * (vb * 2.0 ** e) ** (1.0 / 2.2), 0.0, 255.0)
        total += float(np.sum((ta - tb) ** 2))
    n = va.size * (fstop_hi - fstop_lo + 1)
    return psnr_from_mse(total / n if n else 0.0, 255.0)
