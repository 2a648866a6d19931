"""Reconstruction filters for mip reduction.

Each filter is a function of distance measured in *destination* texels (so a
2:1 reduction stretches it over twice as many source texels) and a support
radius in the same units. The resampler samples the filter at the true source
texel centres and normalises the taps, so a filter only has to be the right
shape, not exactly unit-area.

Defaults and the measurements behind them are in docs/mips.md.
"""

import math

import numpy as np

# the defaults and limits live with the other settings' words (the recipe
# checks a value against the same limits when it is made)
from ..choices import KAISER_ALPHA, KAISER_ALPHA_RANGE, KAISER_WIDTH, KAISER_WIDTH_RANGE, LANCZOS_A, LANCZOS_A_RANGE
from ..choices import MIP_FILTERS as FILTERS
from ..errors import UsageError


def _sinc(x):
    # np.sinc is sin(pi x) / (pi x) with sinc(0) = 1.
    return np.sinc(x)


def box(x):
    return (np.abs(x) <= 0.5).astype(np.float64)


def triangle(x):
    return np.maximum(0.0, 1.0 - np.abs(x))


def lanczos(x, a=LANCZOS_A):
    x = np.asarray(x, np.float64)
    return np.where(np.abs(x) < a, _sinc(x) * _sinc(x / a), 0.0)


def kaiser(x, width=KAISER_WIDTH, alpha=KAISER_ALPHA):
    x = np.asarray(x, np.float64)
    t = np.clip(1.0 - (x / width) ** 2, 0.0, None)
    window = np.i0(alpha * np.sqrt(t)) / np.i0(alpha)
    return np.where(np.abs(x) < width, _sinc(x) * window, 0.0)


def make_filter(name, *, lanczos_a=LANCZOS_A, kaiser_width=KAISER_WIDTH, kaiser_alpha=KAISER_ALPHA):
    """(kernel function, radius in destination texels) for a filter name.

    Box is handled by the resampler as exact area coverage (it never samples
    the kernel), which is what makes odd sizes mean-preserving; its radius is
    still reported as 0.5."""
    if name == "box":
        return box, 0.5
    if name == "triangle":
        return triangle, 1.0
    if name == "lanczos":
        a = int(lanczos_a)
        lo, hi = LANCZOS_A_RANGE
        if a != lanczos_a or not lo <= a <= hi:
            raise UsageError(f"--lanczos-a must be an integer from {lo} to {hi}, not {lanczos_a}")
        return (lambda x: lanczos(x, a)), float(a)
    if name == "kaiser":
        w = float(kaiser_width)
        al = float(kaiser_alpha)
        if not (math.isfinite(w) and KAISER_WIDTH_RANGE[0] <= w <= KAISER_WIDTH_RANGE[1]):
            raise UsageError("Kaiser width must be between {:g} and {:g} destination texels, not {}".format(
                *KAISER_WIDTH_RANGE, kaiser_width))
        if not (math.isfinite(al) and KAISER_ALPHA_RANGE[0] <= al <= KAISER_ALPHA_RANGE[1]):
            raise UsageError("Kaiser alpha must be between {:g} and {:g}, not {}".format(*KAISER_ALPHA_RANGE,
                                                                                        kaiser_alpha))
        return (lambda x: kaiser(x, w, al)), w
    raise UsageError(f"unknown mip filter {name!r} (choose from {', '.join(FILTERS)})")
