"""Image quality measures: PSNR (overall, per channel, per level), max error and
angular error of normal maps."""

import math

import numpy as np


def _as_float(a):
    return np.asarray(a, dtype=np.float64)


def mse(a, b, channels=None):
    a, b = _as_float(a), _as_float(b)
    if a.shape != b.shape:
        raise ValueError(f"shapes differ: {a.shape} vs {b.shape}")
    if channels is not None:
        a, b = a[..., list(channels)], b[..., list(channels)]
    return float(np.mean((a - b) ** 2))


def psnr(a, b, peak=255.0, channels=None):
    """PSNR in dB over the chosen channels (all when None); inf for identical."""
    return psnr_from_mse(mse(a, b, channels), peak)


def psnr_per_channel(a, b, peak=255.0):
    return [psnr(a, b, peak, [c]) for c in range(np.asarray(a).shape[-1])]


def max_error(a, b, channels=None):
    a, b = _as_float(a), _as_float(b)
    if channels is not None:
        a, b = a[..., list(channels)], b[..., list(channels)]
    return float(np.max(np.abs(a - b))) if a.size else 0.0


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
    z = np.sqrt(np.clip(1.0 - np.sum(xy * xy, axis=-1), 0.0, None))
    v = np.concatenate([xy, z[..., None]], axis=-1)
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n == 0, 1.0, n)


def psnr_from_mse(m, peak=255.0):
    return math.inf if m == 0.0 else 10.0 * math.log10(peak * peak / m)
