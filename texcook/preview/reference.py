"""Shading (alpha test, blending over a background), the supersampled ground
truth, and each filter's error against it.

The reference integrates the level-0 texture over each pixel's square: a
jittered grid of sub-samples, each ray-cast into the scene (nearest triangle)
and sampled bilinearly from level 0, shaded exactly like a filtered pixel, and
averaged. The grid is sized from the pixel's footprint so that sub-samples are
at most half a texel apart along each screen axis (between REF_MIN and REF_MAX
per axis): the box-filtered texture, which is what every filter approximates.

Error is measured where both the pixel centre and every sub-sample hit
geometry (silhouette pixels measure geometric antialiasing, not texture
filtering), on display values (sRGB-encoded for sRGB textures) in 0..1.
"""

import math

import numpy as np
from numba import prange

from .._jit import jit
from .raster import STRIPES, hit
from .sample import WRAP_CODES, bilinear

ALPHA_MODES = ("opaque", "blend", "mask")  # glTF OPAQUE, BLEND, MASK
_BLEND, _MASK = 1, 2
REF_MIN, REF_MAX = 4, 48  # sub-samples per pixel axis
CHECKER = 16  # background checker squares, in pixels
_BG_DARK, _BG_LIGHT = 0.08, 0.30  # linear grey levels of the checker


@jit
def shade(r, g, b, a, bg_r, bg_g, bg_b, mode, cutoff):
    """(r, g, b, coverage) of one sample over the background: MASK keeps the
    sample where alpha >= cutoff (glTF's rule), BLEND mixes by alpha, OPAQUE
    ignores alpha."""
    if mode == _MASK:
        if a >= cutoff:
            return r, g, b, 1.0
        return bg_r, bg_g, bg_b, 0.0
    if mode == _BLEND:
        a = min(max(a, 0.0), 1.0)
        k = 1.0 - a
        return r * a + bg_r * k, g * a + bg_g * k, b * a + bg_b * k, a
    return r, g, b, 1.0


def background(width, height):
    """A grey checker in linear light, (H, W, 3) float64."""
    y, x = np.mgrid[0:height, 0:width]
    light = ((x // CHECKER + y // CHECKER) % 2).astype(bool)
    grey = np.where(light, _BG_LIGHT, _BG_DARK)
    return np.repeat(grey[:, :, None], 3, axis=2).astype(np.float64)


@jit(parallel=True)
def _composite(rgba, tri, bg, mode, cutoff, out, covered):
    height, width = tri.shape
    for stripe in prange(STRIPES):
        for y in range(stripe, height, STRIPES):
            for x in range(width):
                if tri[y, x] < 0:
                    out[y, x, 0] = bg[y, x, 0]
                    out[y, x, 1] = bg[y, x, 1]
                    out[y, x, 2] = bg[y, x, 2]
                    covered[y, x] = 0.0
                    continue
                p = rgba[y, x]
                r, g, b, c = shade(np.float64(p[0]), np.float64(p[1]), np.float64(p[2]), np.float64(p[3]),
                                   bg[y, x, 0], bg[y, x, 1], bg[y, x, 2], mode, cutoff)
                out[y, x, 0] = r
                out[y, x, 1] = g
                out[y, x, 2] = b
                covered[y, x] = c
    return out


def composite(rgba, tri, bg, mode, cutoff):
    """Shade a filtered frame: (linear RGB float32 (H, W, 3), coverage (H, W))."""
    out = np.empty(tri.shape + (3,), np.float32)
    covered = np.empty(tri.shape, np.float32)
    _composite(rgba, tri, bg, ALPHA_MODES.index(mode), float(cutoff), out, covered)
    return out, covered


@jit
def _hash01(a, b, c):
    """A deterministic number in [0, 1) from three small integers."""
    h = (a * 374761393 + b * 668265263 + c * 1442695041) & 0xFFFFFFFF
    h = ((h ^ (h >> 15)) * 2246822519) & 0xFFFFFFFF
    h = ((h ^ (h >> 13)) * 3266489917) & 0xFFFFFFFF
    h = h ^ (h >> 16)
    return h / 4294967296.0


@jit
def _grid(n_texels, lo, hi):
    return min(max(int(math.ceil(2.0 * n_texels)), lo), hi)


# reference_frame's per-call constants, one record for the kernel: level 0's
# size, its wrap modes (sample.WRAP_CODES), the alpha mode and cutoff, and the
# bounds of the sub-sample grid per pixel axis
_SETTINGS = np.dtype([("w0", np.int64), ("h0", np.int64), ("wrap_s", np.int64), ("wrap_t", np.int64),
                      ("mode", np.int64), ("cutoff", np.float64), ("lo", np.int64), ("hi", np.int64)])


@jit(parallel=True)
def _reference(setup, gbuf, tri, tex, bg, rec, out, geo, covered):
    """rec: a one-element _SETTINGS array."""
    prm = rec[0]
    w0, h0, wrap_s, wrap_t = prm.w0, prm.h0, prm.wrap_s, prm.wrap_t
    mode, cutoff, lo, hi = prm.mode, prm.cutoff, prm.lo, prm.hi
    height, width = tri.shape
    for stripe in prange(STRIPES):
        for y in range(stripe, height, STRIPES):
            for x in range(width):
                nx = ny = lo
                if tri[y, x] >= 0:
                    g = gbuf[y, x]
                    nx = _grid(math.hypot(g[2] * w0, g[3] * h0), lo, hi)
                    ny = _grid(math.hypot(g[4] * w0, g[5] * h0), lo, hi)
                br = bg[y, x, 0]
                bgg = bg[y, x, 1]
                bb = bg[y, x, 2]
                r = gg = b = hits = cov = 0.0
                pix = y * width + x
                for j in range(ny):
                    for i in range(nx):
                        k = j * nx + i
                        sx = x + (i + _hash01(pix, k, 1)) / nx
                        sy = y + (j + _hash01(pix, k, 2)) / ny
                        t, u, v = hit(setup, sx, sy)
                        if t < 0:
                            r += br
                            gg += bgg
                            b += bb
                            continue
                        p = bilinear(tex, 0, w0, h0, u, v, wrap_s, wrap_t)
                        sr, sg, sb, c = shade(p[0], p[1], p[2], p[3], br, bgg, bb, mode, cutoff)
                        r += sr
                        gg += sg
                        b += sb
                        cov += c
                        hits += 1.0
                n = nx * ny
                out[y, x, 0] = r / n
                out[y, x, 1] = gg / n
                out[y, x, 2] = b / n
                geo[y, x] = hits / n
                covered[y, x] = cov / n
    return out


def reference_frame(setup, gbuf, tri, level0, wrap, bg, mode, cutoff, lo=REF_MIN, hi=REF_MAX):
    """(linear RGB float32 (H, W, 3), geometric coverage (H, W), alpha
    coverage (H, W)) of the supersampled ground truth."""
    level0 = np.ascontiguousarray(level0, np.float32)
    h0, w0 = level0.shape[:2]
    out = np.empty(tri.shape + (3,), np.float32)
    geo = np.empty(tri.shape, np.float32)
    covered = np.empty(tri.shape, np.float32)
    rec = np.array([(w0, h0, WRAP_CODES[wrap[0]], WRAP_CODES[wrap[1]], ALPHA_MODES.index(mode), float(cutoff),
                     int(lo), int(hi))], _SETTINGS)
    _reference(setup, gbuf, tri, level0.reshape(-1, 4), bg, rec, out, geo, covered)
    return out, geo, covered


# --- error -----------------------------------------------------------------------------


def psnr(a, b, mask):
    """PSNR (dB) of display values in 0..1 over the masked pixels."""
    if not mask.any():
        return math.nan
    d = (a[mask].astype(np.float64) - b[mask].astype(np.float64))
    m = float(np.mean(d * d))
    return math.inf if m == 0.0 else 10.0 * math.log10(1.0 / m)


def blur_alias(a, ref, mask, tile=32, bands=8):
    """Split the squared error of `a` against `ref` (display values, masked) in
    two: blur, the part a gain per frequency band applied to the reference
    explains (detail lost, or its contrast changed), and aliasing, the rest
    (energy where the reference has none, or out of phase with it). The frame
    is cut into tiles, since the footprint changes across it; per tile and
    radial band of the tile's spectrum, g = Re<A, R> / <R, R>, and
    blur = |(g - 1) R|^2 and aliasing = |A - g R|^2 add up to |A - R|^2
    exactly. Returned as MSEs over the masked pixels (they sum to its MSE)."""
    n_masked = int(mask.sum())
    if not n_masked:
        return math.nan, math.nan
    h, w, c = ref.shape
    ph, pw = -h % tile, -w % tile
    ref = np.pad(ref.astype(np.float64), ((0, ph), (0, pw), (0, 0)), mode="edge")
    a = np.pad(a.astype(np.float64), ((0, ph), (0, pw), (0, 0)), mode="edge")
    m = np.pad(mask, ((0, ph), (0, pw)))
    a = np.where(m[..., None], a, ref)  # no error outside the mask

    def tiles(x):
        ty, tx = x.shape[0] // tile, x.shape[1] // tile
        return np.fft.fft2(x.reshape(ty, tile, tx, tile, c).transpose(0, 2, 1, 3, 4), axes=(2, 3))

    fa, fr = tiles(a), tiles(ref)
    f = np.fft.fftfreq(tile)
    radius = np.sqrt(f[:, None] ** 2 + f[None, :] ** 2) / math.sqrt(0.5)
    band = np.minimum((radius * bands).astype(np.int64), bands - 1)
    n_tiles = fa.shape[0] * fa.shape[1]
    index = (np.arange(n_tiles).reshape(fa.shape[:2])[:, :, None, None, None] * bands
             + band[None, None, :, :, None])
    index = np.broadcast_to(index, fa.shape).ravel()
    cross = np.bincount(index, (fa * np.conj(fr)).real.ravel(), n_tiles * bands)
    power = np.bincount(index, (np.abs(fr) ** 2).ravel(), n_tiles * bands)
    gain = np.divide(cross, power, out=np.ones_like(cross), where=power > 1e-12)
    g = gain[index].reshape(fa.shape)
    blur = float(np.sum(np.abs((g - 1.0) * fr) ** 2))
    alias = float(np.sum(np.abs(fa - g * fr) ** 2))
    scale = 1.0 / (tile * tile * n_masked * c)  # Parseval per tile, then the mean over masked samples
    return blur * scale, alias * scale


def db(mse):
    if mse is None or math.isnan(mse):
        return math.nan
    return math.inf if mse <= 0.0 else 10.0 * math.log10(1.0 / mse)
