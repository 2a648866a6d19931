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
