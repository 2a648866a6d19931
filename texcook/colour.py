"""Colour transforms.

sRGB <-> linear uses the exact piecewise IEC 61966-2-1 transfer function. The
jitted path is what the pipeline runs; `colour-science` is the reference the
tests hold it to (1e-6).
"""

import numpy as np

from ._jit import jit


@jit
def _srgb_to_linear_flat(x, out):
    for i in range(x.size):
        v = np.float64(x[i])
        if v <= 0.04045:
            out[i] = v / 12.92
        else:
            out[i] = ((v + 0.055) / 1.055) ** 2.4
    return out


@jit
def _linear_to_srgb_flat(x, out):
    for i in range(x.size):
        v = np.float64(x[i])
        if v <= 0.0031308:
            out[i] = v * 12.92
        else:
            out[i] = 1.055 * v ** (1.0 / 2.4) - 0.055
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
