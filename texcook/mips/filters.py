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

from ..choices import MIP_FILTERS as FILTERS
from ..errors import UsageError

# Kaiser-windowed sinc: radius 3 destination texels (12 taps per axis at 2:1)
# with alpha 4. Radius 3 keeps the passband as flat as Lanczos-3; alpha 4 puts
# the first sidelobe of the window near -30 dB, which removes most of the
# aliasing that Lanczos-3 lets through while ringing less than a higher alpha
# with the same radius would (docs/mips.md has the frequency figures).
KAISER_WIDTH = 3.0
KAISER_ALPHA = 4.0
LANCZOS_A = 3


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
        if a != lanczos_a or not 1 <= a <= 8:
            raise UsageError(f"--lanczos-a must be an integer from 1 to 8, not {lanczos_a}")
        return (lambda x: lanczos(x, a)), float(a)
    if name == "kaiser":
        w = float(kaiser_width)
        al = float(kaiser_alpha)
        if not (math.isfinite(w) and 0.5 <= w <= 8.0):
            raise UsageError(f"Kaiser width must be between 0.5 and 8 destination texels, not {kaiser_width}")
        if not (math.isfinite(al) and 0.0 <= al <= 20.0):
            raise UsageError(f"Kaiser alpha must be between 0 and 20, not {kaiser_alpha}")
        return (lambda x: kaiser(x, w, al)), w
    raise UsageError(f"unknown mip filter {name!r} (choose from {', '.join(FILTERS)})")
