"""Colour transforms.

sRGB <-> linear uses the exact piecewise IEC 61966-2-1 transfer function. The
jitted scalar formulas below are the definition; `colour-science` is the
reference the tests hold them to (1e-6).

The pipeline does not evaluate the curve per texel:

- decoding stored 8- and 16-bit values is a table lookup (256 or 65536
  entries), each entry the formula applied to the value's float32 0..1 form,
  so the lookup is the formula's result bit for bit;
- quantising linear light to 8-bit sRGB codes is a search in a table of the
  255 thresholds between codes: the code of x is the number of thresholds at
  or below x. The thresholds are the smallest float32 inputs at which
  round(encode(x) * 255) reaches each code, found by bisection on the float32
  bit patterns; the mapping is monotonic (checked over every float32 in 0..1
  by tests/test_colour.py with TEXCOOK_EXHAUSTIVE=1), so the search returns
  exactly what the formula and rounding give. A table over the top 16 bits of
  the float32 pattern gives the code at the start of each bucket, and one or
  two comparisons finish it.

Both run over rows on the process's threads (`threads`), with the same bytes
for any count.
"""

import numpy as np

from . import _threads
from ._jit import cached, jit, jit_inner
from .normals import z_from_xy


def _srgb_to_linear_scalar(v):
    """The decode of one value in float64: the definition. Evaluated by
    Python for the tables (no kernel to compile or load for them) and jitted
    for float sources; both call the C library's pow, so they agree bit for
    bit (tests/test_colour.py checks every table entry)."""
    if v <= 0.04045:
        return v / 12.92
    return ((v + 0.055) / 1.055) ** 2.4


def _linear_to_srgb_scalar(v):
    """The encode of one value in float64 (see _srgb_to_linear_scalar)."""
    if v <= 0.0031308:
        return v * 12.92
    return 1.055 * v ** (1.0 / 2.4) - 0.055


_srgb_to_linear_1 = jit_inner(_srgb_to_linear_scalar)
_linear_to_srgb_1 = jit_inner(_linear_to_srgb_scalar)


@jit
def _srgb_to_linear_flat(x, out):
    for i in range(x.size):
        out[i] = _srgb_to_linear_1(np.float64(x[i]))
    return out


@jit
def _linear_to_srgb_flat(x, out):
    for i in range(x.size):
        out[i] = _linear_to_srgb_1(np.float64(x[i]))
    return out


def _apply(kernel, x):
    x = np.asarray(x)
    dtype = x.dtype if x.dtype in (np.float32, np.float64) else np.float32
    flat = np.ascontiguousarray(x, dtype=dtype).reshape(-1)
    out = np.empty_like(flat)
    kernel(flat, out)
    return out.reshape(x.shape)


def srgb_to_linear(x):
    """sRGB-encoded values (0..1; values beyond extend the curve) to linear light.
    Keeps float32/float64; other dtypes become float32."""
    return _apply(_srgb_to_linear_flat, x)


def linear_to_srgb(x):
    """Linear light to sRGB encoding; the inverse of srgb_to_linear."""
    return _apply(_linear_to_srgb_flat, x)


def encode_colour(pixels, srgb, alpha_channel):
    """Linear float pixels -> the encoding of the output (sRGB on colour channels
    only when `srgb`; alpha is always linear)."""
    return _on_colour_channels(linear_to_srgb, pixels, alpha_channel) if srgb else pixels


def decode_colour(pixels, srgb, alpha_channel):
    """The inverse of encode_colour."""
    return _on_colour_channels(srgb_to_linear, pixels, alpha_channel) if srgb else pixels


def _on_colour_channels(transfer, pixels, alpha_channel):
    out = pixels.copy()
    colour = [c for c in range(pixels.shape[2]) if c != alpha_channel]
    out[..., colour] = transfer(pixels[..., colour])
    return out


def quantize_unorm8(x):
    """Float 0..1 -> uint8 with round-to-nearest; out-of-range values clamp."""
    # clamp before scaling: a huge value times 255 would overflow float32 (a numpy warning)
    return np.rint(np.clip(np.asarray(x, np.float32), 0.0, 1.0) * 255.0).astype(np.uint8)


# --- YCoCg -------------------------------------------------------------------------
# Luma and two chroma differences (RTR4 6.2; Malvar and Sullivan). The lossy form
# keeps values in the same units as RGB (Y in 0..1, Co and Cg in -0.5..0.5 for
# RGB in 0..1). YCoCg-R is the lifting form: exactly reversible on integers, at
# the price of one more bit for Co and Cg (8-bit RGB: Co, Cg in -255..255).


@jit
def _rgb_to_ycocg_rows(x, out):
    for i in range(x.shape[0]):
        r = np.float64(x[i, 0])
        g = np.float64(x[i, 1])
        b = np.float64(x[i, 2])
        out[i, 0] = 0.25 * r + 0.5 * g + 0.25 * b
        out[i, 1] = 0.5 * r - 0.5 * b
        out[i, 2] = -0.25 * r + 0.5 * g - 0.25 * b
    return out


@jit
def _ycocg_to_rgb_rows(x, out):
    for i in range(x.shape[0]):
        y = np.float64(x[i, 0])
        co = np.float64(x[i, 1])
        cg = np.float64(x[i, 2])
        out[i, 0] = y + co - cg
        out[i, 1] = y + cg
        out[i, 2] = y - co - cg
    return out


@jit
def _rgb_to_ycocg_r_rows(x, out):
    for i in range(x.shape[0]):
        r = np.int32(x[i, 0])
        g = np.int32(x[i, 1])
        b = np.int32(x[i, 2])
        co = r - b
        t = b + (co >> 1)
        cg = g - t
        out[i, 0] = t + (cg >> 1)
        out[i, 1] = co
        out[i, 2] = cg
    return out


@jit
def _ycocg_r_to_rgb_rows(x, out):
    for i in range(x.shape[0]):
        y = np.int32(x[i, 0])
        co = np.int32(x[i, 1])
        cg = np.int32(x[i, 2])
        t = y - (cg >> 1)
        g = cg + t
        b = t - (co >> 1)
        out[i, 0] = b + co
        out[i, 1] = g
        out[i, 2] = b
    return out


def _rows(kernel, x, dtype):
    """Run a kernel over the last axis (3 values) of x, keeping x's shape."""
    x = np.asarray(x)
    if x.shape[-1:] != (3,):
        raise ValueError(f"expected (..., 3) values, got shape {x.shape}")
    flat = np.ascontiguousarray(x.reshape(-1, 3), dtype=dtype)
    out = np.empty_like(flat)
    kernel(flat, out)
    return out.reshape(x.shape)


def _float_dtype(x):
    return x.dtype if x.dtype in (np.float32, np.float64) else np.float32


def rgb_to_ycocg(rgb):
    """(..., 3) RGB -> (..., 3) Y, Co, Cg (the lossy transform). Float32/float64
    kept; other dtypes become float32."""
    rgb = np.asarray(rgb)
    return _rows(_rgb_to_ycocg_rows, rgb, _float_dtype(rgb))


def ycocg_to_rgb(ycocg):
    """The inverse of rgb_to_ycocg."""
    ycocg = np.asarray(ycocg)
    return _rows(_ycocg_to_rgb_rows, ycocg, _float_dtype(ycocg))


def rgb_to_ycocg_r(rgb):
    """(..., 3) integer RGB -> (..., 3) int32 Y, Co, Cg by lifting (YCoCg-R)."""
    return _rows(_rgb_to_ycocg_r_rows, rgb, np.int32)


def ycocg_r_to_rgb(ycocg):
    """The exact inverse of rgb_to_ycocg_r, as int32."""
    return _rows(_ycocg_r_to_rgb_rows, ycocg, np.int32)


# --- choosing sRGB or linear storage -------------------------------------------------
# Kaplanyan's rule (CryENGINE 3, 2010; RTR4 6.2): sRGB encoding spends its codes on
# dark values, so a texture whose values are mostly bright keeps more precision
# stored linear. Counted on each colour value in sRGB encoding.
AUTO_THRESHOLD = 116.0 / 255.0
AUTO_LINEAR_SHARE = 0.75


def bright_share(srgb_values):
    """The fraction of values (sRGB-encoded, 0..1) above 116/255."""
    v = np.asarray(srgb_values)
    return float(np.count_nonzero(v > AUTO_THRESHOLD)) / max(v.size, 1)


def auto_colour_space(srgb_values):
    """("linear" or "srgb", share): linear when at least 75% of the values are
    above 116/255."""
    share = bright_share(srgb_values)
    return ("linear" if share >= AUTO_LINEAR_SHARE else "srgb"), share


# --- tables ------------------------------------------------------------------------

_tables = {}


def unit_table(bits):
    """float32 0..1 value of every stored 8- or 16-bit integer (v / 255 or
    v / 65535, rounded once to float32): what an Image holds for it."""
    key = ("unit", bits)
    if key not in _tables:
        top = (1 << bits) - 1
        _tables[key] = (np.arange(top + 1, dtype=np.float64) / top).astype(np.float32)
    return _tables[key]


def _by_formula(scalar, x):
    """float32 values through a scalar formula in float64, rounded to float32
    as srgb_to_linear and linear_to_srgb round them."""
    return np.array([scalar(v) for v in np.asarray(x, np.float32).tolist()], np.float64).astype(np.float32)


def linear_table(bits):
    """Linear light (float32) of every stored 8- or 16-bit sRGB code:
    srgb_to_linear(unit_table(bits))."""
    key = ("linear", bits)
    if key not in _tables:
        _tables[key] = _by_formula(_srgb_to_linear_scalar, unit_table(bits))
    return _tables[key]


_ONE_BITS = 0x3F800000  # float32 1.0: every code from here up is 255
_BUCKET_SHIFT = 16  # buckets of the bucket table: the top 16 bits of the pattern


def srgb8_code(x):
    """The reference 8-bit sRGB code of float32 linear values: the formula, then
    round(y * 255) in float32, clamped; exactly quantize_unorm8(linear_to_srgb(x))."""
    return quantize_unorm8(linear_to_srgb(np.asarray(x, np.float32)))


def _srgb8_thresholds():
    """(255,) float32: for code k = 1..255 the smallest float32 >= 0 whose code
    is at least k, by bisection over the bit patterns of 0.0 .. 1.0 (ordered
    like the values), all codes at once."""
    k = np.arange(1, 256)
    lo = np.zeros(255, np.uint32)  # code(lo) < k
    hi = np.full(255, _ONE_BITS, np.uint32)  # code(1.0) == 255 >= k
    while np.any(hi - lo > 1):
        mid = lo + (hi - lo) // 2
        up = quantize_unorm8(_by_formula(_linear_to_srgb_scalar, mid.view(np.float32))) >= k  # srgb8_code
        hi = np.where(up, mid, hi)
        lo = np.where(up, lo, mid)
    return hi.view(np.float32)


def srgb8_tables():
    """(thresholds float32 (257,), bucket codes uint8): thresholds[k] is the
    smallest float32 with code >= k (thresholds[0] = -inf, thresholds[256] =
    +inf); bucket[b] is the code of the smallest non-negative float32 whose
    top 16 bits are b."""
    if "srgb8" not in _tables:
        t = np.empty(257, np.float32)
        t[0] = -np.inf
        t[256] = np.inf
        t[1:256] = _srgb8_thresholds()
        starts = (np.arange((_ONE_BITS >> _BUCKET_SHIFT) + 1, dtype=np.uint32) << _BUCKET_SHIFT).view(np.float32)
        bucket = (np.searchsorted(t[1:256], starts, side="right")).astype(np.uint8)
        _tables["srgb8"] = (t, bucket)
    return _tables["srgb8"]


# --- the pipeline's kernels ----------------------------------------------------------


@jit
def rgba_from_ints(src, tabs, one, out):
    """Stored integers (h, w, c) -> RGBA (h, w, 4) of the tables' type through
    the tables, channel k through tabs[k]. Grey fills R, G and B; a missing
    alpha is `one` (opaque). One loop per channel count, so the texel loop has
    no branch."""
    h, w, c = src.shape
    t0 = tabs[0]
    t1 = tabs[1]
    t2 = tabs[2]
    t3 = tabs[3]
    for y in range(h):
        s = src[y]
        o = out[y]
        if c == 4:
            for x in range(w):
                o[x, 0] = t0[s[x, 0]]
                o[x, 1] = t1[s[x, 1]]
                o[x, 2] = t2[s[x, 2]]
                o[x, 3] = t3[s[x, 3]]
        elif c == 3:
            for x in range(w):
                o[x, 0] = t0[s[x, 0]]
                o[x, 1] = t1[s[x, 1]]
                o[x, 2] = t2[s[x, 2]]
                o[x, 3] = one
        else:
            for x in range(w):
                v = t0[s[x, 0]]
                o[x, 0] = v
                o[x, 1] = v
                o[x, 2] = v
                o[x, 3] = t1[s[x, 1]] if c == 2 else one
    return out


_FLOAT32_MAX = float(np.finfo(np.float32).max)


@jit
def _rgba_from_floats(src, srgb, alpha, out):
    """float32 (h, w, c) -> float32 RGBA (h, w, 4), decoding sRGB on the colour
    channels when `srgb` (the formula: float sources have no table)."""
    h, w, c = src.shape
    for y in range(h):
        s = src[y]
        o = out[y]
        for x in range(w):
            for k in range(c):
                v = s[x, k]
                if srgb and k != alpha:
                    # the curve's power 2.4 takes values above about 1.6e16 past
                    # the float32 range: saturated, as a finite source stays finite
                    v = np.float32(min(_srgb_to_linear_1(np.float64(v)), _FLOAT32_MAX))
                if c <= 2 and k == 0:
                    o[x, 0] = v
                    o[x, 1] = v
                    o[x, 2] = v
                elif c == 2:
                    o[x, 3] = v
                else:
                    o[x, k] = v
            if c == 1 or c == 3:
                o[x, 3] = 1.0
    return out


@jit
def _quantize_rows(src, bits, srgb, thresholds, bucket, out):
    """float32 RGBA (h, w, 4) -> uint8: sRGB codes on channels 0-2 when `srgb`
    (threshold search), plain rounding elsewhere; both clamp to 0..255.
    bits: src viewed as uint32 by the caller (a view inside the kernel
    compiles numba's view routine, a tenth of a second of a cold start)."""
    h, w, c = src.shape
    for y in range(h):
        s = src[y]
        b = bits[y]
        o = out[y]
        for x in range(w):
            for k in range(c):
                v = s[x, k]
                if srgb and k < 3:
                    p = b[x, k]
                    if p >= 0x80000000:  # negative (or -0.0)
                        q = 0
                    elif p >= _ONE_BITS:  # 1.0 and above
                        q = 255
                    else:
                        q = np.int64(bucket[p >> _BUCKET_SHIFT])
                        while v >= thresholds[q + 1]:
                            q += 1
                    o[x, k] = q
                else:
                    y255 = v * np.float32(255.0)
                    if y255 <= 0.0:
                        o[x, k] = 0
                    elif y255 >= 255.0:
                        o[x, k] = 255
                    else:
                        o[x, k] = np.uint8(np.rint(y255))
    return out


def quantize_kernels_cached():
    """Whether quantize's kernels are in the kernel cache (texcook._jit.cached)."""
    return cached(_quantize_rows)


def to_rgba(px, normal_map):
    """(H, W, C) -> (H, W, 4) the way a sampler sees the source: grey replicates,
    missing alpha is opaque. A two-channel normal map is X, Y with Z rebuilt."""
    h, w, c = px.shape
    out = np.empty((h, w, 4), np.float32)
    out[..., 3] = 1.0
    if normal_map and c == 2:
        out[..., :2] = px
        # X or Y beyond +-1 leaves no room for Z either way; clipped first, the squares cannot overflow
        xy = np.clip(px, 0.0, 1.0) * 2.0 - 1.0
        out[..., 2] = z_from_xy(xy[..., 0], xy[..., 1]) * 0.5 + 0.5
    elif c <= 2:
        out[..., :3] = px[..., :1]
        if c == 2:
            out[..., 3] = px[..., 1]
    else:
        out[..., :c] = px
    return out


def _chunk_rows(h, w):
    """Chunk rows so each chunk has at least ~16K texels."""
    return max(1, 16384 // max(1, w))


class StoredRGBA:
    """Stored 8- or 16-bit integers (h, w, c), c in 1..4, read as float32 RGBA
    (h, w, 4) through a table per stored channel: sRGB-decoded on the colour
    channels when `srgb` (alpha, `alpha_channel`, never), otherwise v / max.
    Grey fills R, G, B; a missing alpha is 1.

    Nothing is decoded until asked: `decode` makes the whole image, and the
    mip chain decodes the rows it filters as it reaches them (a float copy of
    level 0 is four to sixteen times the stored size, and making it is a pass
    over memory that a second thread does not speed up)."""

    def __init__(self, values, srgb, alpha_channel):
        values = np.asarray(values)
        if values.ndim == 2:
            values = values[:, :, None]
        if values.dtype not in (np.uint8, np.uint16) or values.ndim != 3 or not 1 <= values.shape[2] <= 4:
            raise ValueError(f"stored values must be uint8 or uint16 (h, w, 1..4), not {values.dtype} {values.shape}")
        self.values = np.ascontiguousarray(values)
        bits = 8 if values.dtype == np.uint8 else 16
        unit = unit_table(bits)
        ctab = linear_table(bits) if srgb else unit
        alpha = -1 if alpha_channel is None else int(alpha_channel)
        # the table of each stored channel: alpha (and every channel when not sRGB) plain
        self.tables = np.stack([unit if k == alpha else ctab for k in range(4)])
        self.one = np.float32(1.0)
        self.shape = self.values.shape[:2] + (4,)

    def decode(self, threads=None):
        """The float32 RGBA image, on `threads` threads."""
        h, w, _ = self.shape
        out = np.empty(self.shape, np.float32)
        values, tables, one = self.values, self.tables, self.one
        _threads.parallel_for(lambda a, b: rgba_from_ints(values[a:b], tables, one, out[a:b]), h, threads,
                              _chunk_rows(h, w))
        return out

    def channel(self, k):
        """Channel k (0..3) of the RGBA image as float32 (h, w)."""
        c = self.values.shape[2]
        src = k if c >= 3 else (0 if k < 3 else 1)
        if src >= c:
            return np.ones(self.shape[:2], np.float32)  # a missing alpha
        return self.tables[src][self.values[..., src]]


def to_linear_rgba(values, srgb, alpha_channel, threads=None):
    """Source values (h, w, c), c in 1..4, as float32 RGBA (h, w, 4) in one
    pass: stored uint8/uint16 integers through the tables (StoredRGBA),
    float32 values through the formula. `srgb`: decode the sRGB curve on the
    colour channels (alpha, `alpha_channel`, never); otherwise integers become
    v / max. Grey fills R, G, B; a missing alpha is 1."""
    values = np.asarray(values)
    if values.dtype in (np.uint8, np.uint16):
        return StoredRGBA(values, srgb, alpha_channel).decode(threads)
    if values.ndim == 2:
        values = values[:, :, None]
    h, w, c = values.shape
    out = np.empty((h, w, 4), np.float32)
    alpha = -1 if alpha_channel is None else int(alpha_channel)
    values = np.ascontiguousarray(values, np.float32)
    flag = bool(srgb)
    _threads.parallel_for(lambda a, b: _rgba_from_floats(values[a:b], flag, alpha, out[a:b]), h, threads,
                          _chunk_rows(h, w))
    return out


def _quantize_tables(srgb):
    """_quantize_rows' tables: the sRGB ones only when the curve is wanted
    (empty ones keep the kernel's types)."""
    return srgb8_tables() if srgb else (np.zeros(257, np.float32), np.zeros(1, np.uint8))


def quantize(rgba, srgb, threads=None):
    """float32 linear-light RGBA (h, w, 4) -> uint8 RGBA: sRGB codes on R, G, B
    when `srgb`, else plain; alpha is always plain. Equal, byte for byte, to
    quantize_unorm8(encode_colour(rgba, srgb, 3))."""
    rgba = np.ascontiguousarray(rgba, np.float32)
    h, w, _ = rgba.shape
    out = np.empty(rgba.shape, np.uint8)
    bits = rgba.view(np.uint32)
    flag = bool(srgb)
    thresholds, bucket = _quantize_tables(flag)

    def run(a, b):
        _quantize_rows(rgba[a:b], bits[a:b], flag, thresholds, bucket, out[a:b])

    _threads.parallel_for(run, h, threads, _chunk_rows(h, w))
    return out


@jit
def _quantize_from_ints(src, tabs, one, srgb, thresholds, bucket, row, bits, out):
    """quantize of the RGBA that the tables make of stored integers (h, w, c),
    a row at a time through `row` (1, w, 4) float32 and `bits`, the same row
    viewed as uint32: no float image is made."""
    for y in range(src.shape[0]):
        rgba_from_ints(src[y: y + 1], tabs, one, row)
        _quantize_rows(row, bits, srgb, thresholds, bucket, out[y: y + 1])
    return out


# A cached kernel takes about 8 ms to load (0.3 s to compile); NumPy lays out
# RGB as RGBA in about 4.7 ns a texel on one thread (the kernel: 0.6 ns), so
# below about 2 Mpix NumPy is quicker, counting the load.
_LAYOUT_KERNEL_TEXELS = 1 << 20


def rgba8_from_stored(stored, srgb, alpha_channel, threads=None):
    """quantize(to_linear_rgba(stored, srgb, alpha_channel), srgb) for stored
    integers (h, w, c), without the float image between them. Every 8-bit
    code survives decoding to float32 and quantising back (tests/test_colour.py
    checks all 256), so for 8-bit values the result is the stored values laid
    out as RGBA (grey fills R, G, B; a missing alpha is 255), and an RGBA
    source is returned as it is, with no copy. That does not hold for 16-bit
    values, nor under `srgb` when the channel that lands in alpha is not the
    alpha channel (it was decoded as colour and is stored plain): those are
    decoded and quantised a row at a time."""
    stored = np.asarray(stored)
    if stored.ndim == 2:
        stored = stored[:, :, None]
    h, w, c = stored.shape
    stored = np.ascontiguousarray(stored)
    as_stored = stored.dtype == np.uint8 and not (srgb and alpha_channel != (c - 1 if c in (2, 4) else None))
    if as_stored and c == 4:
        return stored
    out = np.empty((h, w, 4), np.uint8)
    if as_stored:
        if h * w < _LAYOUT_KERNEL_TEXELS:
            # NumPy's copy: below this size the kernel costs more to load (or compile) than it saves
            out[..., :3] = stored[..., :1] if c <= 2 else stored
            out[..., 3] = stored[..., 1] if c == 2 else 255
            return out
        codes = np.tile(np.arange(256, dtype=np.uint8), (4, 1))  # each code as itself
        _threads.parallel_for(lambda a, b: rgba_from_ints(stored[a:b], codes, np.uint8(255), out[a:b]), h, threads,
                              _chunk_rows(h, w))
        return out
    level = StoredRGBA(stored, srgb, alpha_channel)
    flag = bool(srgb)
    thresholds, bucket = _quantize_tables(flag)

    def run(a, b):
        row = np.empty((1, w, 4), np.float32)
        _quantize_from_ints(stored[a:b], level.tables, level.one, flag, thresholds, bucket, row,
                            row.view(np.uint32), out[a:b])

    _threads.parallel_for(run, h, threads, _chunk_rows(h, w))
    return out
