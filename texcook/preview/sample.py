"""Texture filters, each as a GPU (or PBRT) would run it, over a G-buffer.

Every filter reads, per covered pixel, the texture coordinates (u, v) and
their screen-space derivatives from the rasteriser, and writes linear-light
RGBA. Coordinates are normalised (1 = one repeat of the texture); a level of
w x h texels has texel i covering [i / w, (i + 1) / w). Derivatives are
measured in level-0 texels when a footprint is sized.

- nearest, bilinear: level 0 only (minFilter NEAREST / LINEAR, no mips).
- nearest_mipmap_nearest, linear_mipmap_nearest, nearest_mipmap_linear and
  trilinear (LINEAR_MIPMAP_LINEAR): the OpenGL level of detail
  lambda = log2(rho), rho = max(|d(u,v)/dx|, |d(u,v)/dy|) in level-0 texels;
  lambda <= 0 is magnification (the mag filter on level 0).
- anisoN: N at most probes along the footprint's major axis, each trilinear at
  lambda = log2(Pmax / probes), probes = min(ceil(Pmax / Pmin), N)
  (EXT_texture_filter_anisotropic).
- ewa: an elliptical Gaussian over the ellipse the two derivative vectors
  span, widened by one texel for reconstruction, with the eccentricity clamped
  to EWA_MAX_ANISOTROPY by lengthening the minor axis, at the level the minor
  axis picks and blended with the next (Heckbert 1989; PBRT's MIPMap::EWA).
- sat: the mean over the footprint's bounding rectangle (at least one texel)
  from a summed-area table of level 0, with fractional texel coverage.
"""

import math
import re

import numpy as np
from numba import prange

from .._jit import jit
from ..errors import UsageError
from ..mips.resample import WRAPS
from .raster import STRIPES

# GL-style filters: name -> (texel filter linear?, mip mode 0 none / 1 nearest / 2 linear)
GL_FILTERS = {
    "nearest": (False, 0),
    "bilinear": (True, 0),
    "nearest_mipmap_nearest": (False, 1),
    "linear_mipmap_nearest": (True, 1),
    "nearest_mipmap_linear": (False, 2),
    "trilinear": (True, 2),
}
FILTERS = ("nearest", "bilinear", "trilinear", "aniso16", "ewa", "sat")  # what `all` shows
DEFAULT_ANISO = 16
EWA_MAX_ANISOTROPY = 8.0  # PBRT's default
EWA_ALPHA = 2.0  # Gaussian falloff: weight exp(-alpha r^2) - exp(-alpha), r = 1 on the ellipse
_EWA_LUT = 128
WRAP_CODES = {name: i for i, name in enumerate(WRAPS)}  # clamp (to edge), repeat, mirror(ed repeat)
_CLAMP, _REPEAT, _MIRROR = WRAP_CODES["clamp"], WRAP_CODES["repeat"], WRAP_CODES["mirror"]


def parse_filter(name):
    """A filter name -> (kind, parameter): ('gl', name), ('aniso', N), ('ewa', 0),
    ('sat', 0). Raises UsageError for anything else."""
    name = str(name).lower()
    if name in GL_FILTERS:
        return "gl", name
    m = re.fullmatch(r"aniso(\d*)", name)
    if m:
        n = int(m.group(1)) if m.group(1) else DEFAULT_ANISO
        if not 1 <= n <= 64:
            raise UsageError(f"anisotropy must be within 1..64, not {n}")
        return "aniso", n
    if name in ("ewa", "sat"):
        return name, 0
    choices = ", ".join(list(GL_FILTERS) + ["aniso[N]", "ewa", "sat", "all"])
    raise UsageError(f"unknown filter {name!r}; choose one of {choices}")


def mag_linear_of(name):
    """How a filter named on its own magnifies: nearest texel filters nearest, the rest linear."""
    kind, param = parse_filter(name)
    return GL_FILTERS[param][0] if kind == "gl" else True


def uses_mips(name):
    kind, param = parse_filter(name)
    return kind in ("aniso", "ewa") or (kind == "gl" and GL_FILTERS[param][1] != 0)


class Chain:
    """Mip levels (linear-light float32 RGBA) packed into one texel array, so
    that kernels take one signature whatever the level count."""

    def __init__(self, levels):
        levels = [np.ascontiguousarray(lv, np.float32) for lv in levels]
        if not levels or any(lv.ndim != 3 or lv.shape[2] != 4 for lv in levels):
            raise ValueError("a chain needs (H, W, 4) levels")
        self.levels = levels
        self.widths = np.array([lv.shape[1] for lv in levels], np.int64)
        self.heights = np.array([lv.shape[0] for lv in levels], np.int64)
        sizes = self.widths * self.heights
        self.offsets = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
        self.texels = np.concatenate([lv.reshape(-1, 4) for lv in levels])

    def args(self):
        return self.texels, self.offsets, self.widths, self.heights


# --- texel access -------------------------------------------------------------------


@jit
def wrap_texel(i, n, mode):
    """Integer texel index -> 0..n-1 under a GL wrap mode."""
    if mode == _REPEAT:
        return i % n
    if mode == _MIRROR:
        k = i % (2 * n)
        return 2 * n - 1 - k if k >= n else k
    return min(max(i, 0), n - 1)


@jit
def _fetch(tex, off, w, h, x, y, ws, wt):
    return tex[off + wrap_texel(y, h, wt) * w + wrap_texel(x, w, ws)]


@jit
def _nearest(tex, off, w, h, u, v, ws, wt):
    p = _fetch(tex, off, w, h, int(math.floor(u * w)), int(math.floor(v * h)), ws, wt)
    return np.float64(p[0]), np.float64(p[1]), np.float64(p[2]), np.float64(p[3])


@jit
def bilinear(tex, off, w, h, u, v, ws, wt):
    x = u * w - 0.5
    y = v * h - 0.5
    fx0 = math.floor(x)
    fy0 = math.floor(y)
    fx = x - fx0
    fy = y - fy0
    x0 = int(fx0)
    y0 = int(fy0)
    a = _fetch(tex, off, w, h, x0, y0, ws, wt)
    b = _fetch(tex, off, w, h, x0 + 1, y0, ws, wt)
    c = _fetch(tex, off, w, h, x0, y0 + 1, ws, wt)
    d = _fetch(tex, off, w, h, x0 + 1, y0 + 1, ws, wt)
    w00 = (1.0 - fx) * (1.0 - fy)
    w10 = fx * (1.0 - fy)
    w01 = (1.0 - fx) * fy
    w11 = fx * fy
    return (
        a[0] * w00 + b[0] * w10 + c[0] * w01 + d[0] * w11,
        a[1] * w00 + b[1] * w10 + c[1] * w01 + d[1] * w11,
        a[2] * w00 + b[2] * w10 + c[2] * w01 + d[2] * w11,
        a[3] * w00 + b[3] * w10 + c[3] * w01 + d[3] * w11,
    )


@jit
def _level_sample(tex, offs, lw, lh, level, u, v, linear, wrap_s, wrap_t):
    if linear:
        return bilinear(tex, offs[level], lw[level], lh[level], u, v, wrap_s, wrap_t)
    return _nearest(tex, offs[level], lw[level], lh[level], u, v, wrap_s, wrap_t)


# --- level of detail -----------------------------------------------------------------


@jit
def level_of_detail(g, w0, h0):
    """OpenGL's lambda = log2(max(|dx|, |dy|)), footprint axes in level-0 texels.
    A zero footprint gives -inf (pure magnification)."""
    lx = math.hypot(g[2] * w0, g[3] * h0)
    ly = math.hypot(g[4] * w0, g[5] * h0)
    rho = max(lx, ly)
    if rho <= 0.0:
        return -math.inf
    return math.log2(rho)


@jit(parallel=True)
def _lod_frame(gbuf, tri, w0, h0, out):
    height, width = tri.shape
    for stripe in prange(STRIPES):
        for y in range(stripe, height, STRIPES):
            for x in range(width):
                out[y, x] = level_of_detail(gbuf[y, x], w0, h0) if tri[y, x] >= 0 else np.nan
    return out


def lod_frame(gbuf, tri, width0, height0):
    """Per-pixel lambda for a texture of width0 x height0 (NaN where empty)."""
    out = np.empty(tri.shape, np.float64)
    return _lod_frame(gbuf, tri, float(width0), float(height0), out)


@jit
def _mip_sample(tex, offs, lw, lh, u, v, lam, linear, mip_mode, wrap_s, wrap_t):
    """A GL min filter at level of detail lam (> 0) with mips."""
    top = lw.shape[0] - 1
    if mip_mode == 1:
        # the level nearest lambda: ceil(lambda + 1/2) - 1, within the chain
        d = min(max(int(math.ceil(lam + 0.5)) - 1, 0), top)
        return _level_sample(tex, offs, lw, lh, d, u, v, linear, wrap_s, wrap_t)
    lam = min(max(lam, 0.0), float(top))
    d = int(math.floor(lam))
    f = lam - d
    a = _level_sample(tex, offs, lw, lh, d, u, v, linear, wrap_s, wrap_t)
    if d >= top or f == 0.0:
        return a
    b = _level_sample(tex, offs, lw, lh, d + 1, u, v, linear, wrap_s, wrap_t)
    g = 1.0 - f
    return a[0] * g + b[0] * f, a[1] * g + b[1] * f, a[2] * g + b[2] * f, a[3] * g + b[3] * f


@jit
def _gl_sample(tex, offs, lw, lh, u, v, lam, min_linear, mip_mode, mag_linear, wrap_s, wrap_t):
    if lam <= 0.0:
        return _level_sample(tex, offs, lw, lh, 0, u, v, mag_linear, wrap_s, wrap_t)
    if mip_mode == 0:
        return _level_sample(tex, offs, lw, lh, 0, u, v, min_linear, wrap_s, wrap_t)
    return _mip_sample(tex, offs, lw, lh, u, v, lam, min_linear, mip_mode, wrap_s, wrap_t)


@jit(parallel=True)
def _frame_gl(gbuf, tri, tex, offs, lw, lh, min_linear, mip_mode, mag_linear, wrap_s, wrap_t, out):
    height, width = tri.shape
    w0 = float(lw[0])
    h0 = float(lh[0])
    for stripe in prange(STRIPES):
        for y in range(stripe, height, STRIPES):
            for x in range(width):
                if tri[y, x] < 0:
                    continue
                g = gbuf[y, x]
                lam = level_of_detail(g, w0, h0)
                r, gg, b, a = _gl_sample(tex, offs, lw, lh, g[0], g[1], lam, min_linear, mip_mode, mag_linear,
                                         wrap_s, wrap_t)
                out[y, x, 0] = r
                out[y, x, 1] = gg
                out[y, x, 2] = b
                out[y, x, 3] = a
    return out


@jit(parallel=True)
def _frame_aniso(gbuf, tri, tex, offs, lw, lh, max_aniso, mag_linear, wrap_s, wrap_t, out):
    height, width = tri.shape
    w0 = float(lw[0])
    h0 = float(lh[0])
    for stripe in prange(STRIPES):
        for y in range(stripe, height, STRIPES):
            for x in range(width):
                if tri[y, x] < 0:
                    continue
                g = gbuf[y, x]
                px = math.hypot(g[2] * w0, g[3] * h0)
                py = math.hypot(g[4] * w0, g[5] * h0)
                if px >= py:
                    pmax, pmin, du, dv = px, py, g[2], g[3]
                else:
                    pmax, pmin, du, dv = py, px, g[4], g[5]
                n = 1
                if pmin > 0.0:
                    # a ratio within rounding of an integer takes that integer
                    n = int(min(math.ceil(pmax / pmin - 1e-9), max_aniso))
                elif pmax > 0.0:
                    n = max_aniso
                lam = math.log2(pmax / n) if pmax > 0.0 else -math.inf
                r = gg = b = a = 0.0
                for i in range(n):
                    t = (i + 0.5) / n - 0.5
                    s = _gl_sample(tex, offs, lw, lh, g[0] + du * t, g[1] + dv * t, lam, True, 2, mag_linear,
                                   wrap_s, wrap_t)
                    r += s[0]
                    gg += s[1]
                    b += s[2]
                    a += s[3]
                out[y, x, 0] = r / n
                out[y, x, 1] = gg / n
                out[y, x, 2] = b / n
                out[y, x, 3] = a / n
    return out


# --- EWA -----------------------------------------------------------------------------


def ewa_weights(size=_EWA_LUT, alpha=EWA_ALPHA):
    """Gaussian weights by squared radius r^2 in [0, 1), zero at the ellipse."""
    r2 = (np.arange(size) + 0.5) / size
    return np.exp(-alpha * r2) - math.exp(-alpha)


@jit
def _ewa_level(level, u, v, ax, ay, bx, by, wrap, lut):
    """Gaussian-weighted texels of one level (tex, offset, width, height)
    inside the ellipse {a cos + b sin} (axes in this level's texels) widened
    by a unit reconstruction disc; wrap: (wrap_s, wrap_t)."""
    tex, off, w, h = level
    wrap_s, wrap_t = wrap
    s = u * w - 0.5
    t = v * h - 0.5
    # Covariance M = J J^T + I (J = [a b]); inside when p^T M^-1 p < 1.
    sxx = ax * ax + bx * bx + 1.0
    syy = ay * ay + by * by + 1.0
    sxy = ax * ay + bx * by
    det = sxx * syy - sxy * sxy
    ca = syy / det
    cb = -2.0 * sxy / det
    cc = sxx / det
    ex = math.sqrt(sxx)
    ey = math.sqrt(syy)
    x0 = int(math.ceil(s - ex))
    x1 = int(math.floor(s + ex))
    y0 = int(math.ceil(t - ey))
    y1 = int(math.floor(t + ey))
    n = lut.shape[0]
    r = g = b = a = 0.0
    wsum = 0.0
    for iy in range(y0, y1 + 1):
        dy = iy - t
        row = wrap_texel(iy, h, wrap_t) * w + off
        for ix in range(x0, x1 + 1):
            dx = ix - s
            r2 = ca * dx * dx + cb * dx * dy + cc * dy * dy
            if r2 >= 1.0:
                continue
            wt = lut[min(int(r2 * n), n - 1)]
            p = tex[row + wrap_texel(ix, w, wrap_s)]
            r += wt * p[0]
            g += wt * p[1]
            b += wt * p[2]
            a += wt * p[3]
            wsum += wt
    if wsum <= 0.0:
        return bilinear(tex, off, w, h, u, v, wrap_s, wrap_t)
    return r / wsum, g / wsum, b / wsum, a / wsum


@jit
def _ewa(chain, u, v, ax, ay, bx, by, max_aniso, wrap, lut):
    """One EWA lookup in chain (tex, offs, lw, lh: Chain.args()); (ax, ay),
    (bx, by) are the footprint axes in level-0 texels; wrap: (wrap_s, wrap_t)."""
    tex, offs, lw, lh = chain
    wrap_s, wrap_t = wrap
    la = math.hypot(ax, ay)
    lb = math.hypot(bx, by)
    if lb > la:
        ax, ay, bx, by, la, lb = bx, by, ax, ay, lb, la
    if lb <= 0.0:
        return bilinear(tex, offs[0], lw[0], lh[0], u, v, wrap_s, wrap_t)
    if lb * max_aniso < la:
        k = la / (lb * max_aniso)
        bx *= k
        by *= k
        lb *= k
    top = lw.shape[0] - 1
    lod = max(math.log2(lb), 0.0)
    if lod >= top:
        # the footprint covers the whole texture: its smallest level says it all (and an
        # ellipse larger than that level would loop over it many times)
        return bilinear(tex, offs[top], lw[top], lh[top], u, v, wrap_s, wrap_t)
    d = int(math.floor(lod))
    f = lod - d
    w0 = float(lw[0])
    h0 = float(lh[0])
    kx = lw[d] / w0
    ky = lh[d] / h0
    p = _ewa_level((tex, offs[d], lw[d], lh[d]), u, v, ax * kx, ay * ky, bx * kx, by * ky, wrap, lut)
    if d >= top or f == 0.0:
        return p
    kx = lw[d + 1] / w0
    ky = lh[d + 1] / h0
    q = _ewa_level((tex, offs[d + 1], lw[d + 1], lh[d + 1]), u, v, ax * kx, ay * ky, bx * kx, by * ky, wrap,
                   lut)
    g = 1.0 - f
    return p[0] * g + q[0] * f, p[1] * g + q[1] * f, p[2] * g + q[2] * f, p[3] * g + q[3] * f


@jit(parallel=True)
def _frame_ewa(gbuf, tri, tex, offs, lw, lh, max_aniso, wrap_s, wrap_t, lut, out):
    height, width = tri.shape
    w0 = float(lw[0])
    h0 = float(lh[0])
    chain = (tex, offs, lw, lh)
    wrap = (wrap_s, wrap_t)
    for stripe in prange(STRIPES):
        for y in range(stripe, height, STRIPES):
            for x in range(width):
                if tri[y, x] < 0:
                    continue
                g = gbuf[y, x]
                s = _ewa(chain, g[0], g[1], g[2] * w0, g[3] * h0, g[4] * w0, g[5] * h0, max_aniso, wrap, lut)
                out[y, x, 0] = s[0]
                out[y, x, 1] = s[1]
                out[y, x, 2] = s[2]
                out[y, x, 3] = s[3]
    return out


# --- summed-area table -----------------------------------------------------------------


@jit
def _sat_at(p, x, y, c):
    """Integral of channel c over [0, x] x [0, y] (texel units, within the
    texture): bilinear in the padded table, exact for box-shaped texels."""
    h = p.shape[0] - 1
    w = p.shape[1] - 1
    ix = min(int(x), w - 1)
    iy = min(int(y), h - 1)
    fx = x - ix
    fy = y - iy
    return ((p[iy, ix, c] * (1.0 - fx) + p[iy, ix + 1, c] * fx) * (1.0 - fy)
            + (p[iy + 1, ix, c] * (1.0 - fx) + p[iy + 1, ix + 1, c] * fx) * fy)


@jit
def _fold(x, n, mode):
    """Integral from 0 to x of a wrapped axis as (whole periods, sign, rest):
    whole * (integral over [0, n]) + sign * (integral over [0, rest])."""
    if mode == _REPEAT:
        q = np.floor(x / n)
        return q, 1.0, x - q * n
    if mode == _MIRROR:
        q = np.floor(x / (2.0 * n))
        rest = x - q * 2.0 * n
        if rest <= n:
            return 2.0 * q, 1.0, rest
        return 2.0 * q + 2.0, -1.0, 2.0 * n - rest
    return 0.0, 1.0, x  # clamp: rectangles are clipped to the texture first


@jit
def _sat_integral(p, x, y, wrap_s, wrap_t, c):
    w = p.shape[1] - 1
    h = p.shape[0] - 1
    ax, sx, rx = _fold(x, w, wrap_s)
    ay, sy, ry = _fold(y, h, wrap_t)
    total = 0.0
    if ax != 0.0 and ay != 0.0:
        total += ax * ay * p[h, w, c]
    if ax != 0.0:
        total += ax * sy * _sat_at(p, w, ry, c)
    if ay != 0.0:
        total += sx * ay * _sat_at(p, rx, h, c)
    return total + sx * sy * _sat_at(p, rx, ry, c)


@jit
def _clip(lo, hi, n, mode):
    if mode != _CLAMP:
        return lo, hi
    if hi <= 0.0:
        return 0.0, 1.0
    if lo >= n:
        return n - 1.0, float(n)
    return max(lo, 0.0), min(hi, float(n))


@jit(parallel=True)
def _frame_sat(gbuf, tri, p, offset, wrap_s, wrap_t, out):
    height, width = tri.shape
    w0 = p.shape[1] - 1
    h0 = p.shape[0] - 1
    channels = p.shape[2]
    for stripe in prange(STRIPES):
        for y in range(stripe, height, STRIPES):
            for x in range(width):
                if tri[y, x] < 0:
                    continue
                g = gbuf[y, x]
                s = g[0] * w0
                t = g[1] * h0
                ex = max(0.5 * (abs(g[2]) + abs(g[4])) * w0, 0.5)
                ey = max(0.5 * (abs(g[3]) + abs(g[5])) * h0, 0.5)
                x0, x1 = _clip(s - ex, s + ex, w0, wrap_s)
                y0, y1 = _clip(t - ey, t + ey, h0, wrap_t)
                area = (x1 - x0) * (y1 - y0)
                for c in range(channels):
                    total = (_sat_integral(p, x1, y1, wrap_s, wrap_t, c) - _sat_integral(p, x0, y1, wrap_s, wrap_t, c)
                             - _sat_integral(p, x1, y0, wrap_s, wrap_t, c) + _sat_integral(p, x0, y0, wrap_s, wrap_t, c))
                    out[y, x, c] = total / area + offset[c]
    return out


def padded_sat(level0):
    """A summed-area table of level 0 (texcook.sat, float64 with the mean taken
    out) with a zero row and column in front, so that P[y, x] is the sum over
    texels [0, x) x [0, y); and the per-channel offset to add back."""
    from ..sat import SummedAreaTable

    table = SummedAreaTable.build(np.ascontiguousarray(level0, np.float32))
    h, w, c = table.table.shape
    p = np.zeros((h + 1, w + 1, c), np.float64)
    p[1:, 1:] = table.table
    return p, np.ascontiguousarray(table.offset, np.float64)


# --- one entry point -------------------------------------------------------------------


def sample_frame(name, gbuf, tri, texture, wrap=("repeat", "repeat"), mag_linear=True):
    """Linear RGBA float32 (H, W, 4) of filter `name` over a rasterised frame.
    `texture` is a Chain (mip filters read its levels; the others only level 0)
    or, for `sat`, the (table, offset) pair from padded_sat."""
    kind, param = parse_filter(name)
    wrap_s, wrap_t = (WRAP_CODES[m] for m in wrap)
    out = np.zeros(tri.shape + (4,), np.float32)
    if kind == "sat":
        p, offset = texture
        return _frame_sat(gbuf, tri, p, offset, wrap_s, wrap_t, out)
    tex, offs, lw, lh = texture.args()
    if kind == "gl":
        min_linear, mip_mode = GL_FILTERS[param]
        if mip_mode and len(lw) == 1:
            mip_mode = 0
        return _frame_gl(gbuf, tri, tex, offs, lw, lh, min_linear, mip_mode, mag_linear, wrap_s, wrap_t, out)
    if kind == "aniso":
        return _frame_aniso(gbuf, tri, tex, offs, lw, lh, param, mag_linear, wrap_s, wrap_t, out)
    return _frame_ewa(gbuf, tri, tex, offs, lw, lh, EWA_MAX_ANISOTROPY, wrap_s, wrap_t, ewa_weights(), out)
