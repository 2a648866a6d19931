"""Mip chains: sizes, the per-level filtering, alpha, normal maps.

Each level is filtered from the level above it (not from level 0): docs/mips.md
has the measurement (same quality within 0.1 dB on the corpus, and a chain
from level 0 costs one full-size pass per level instead of 4/3 of one).

The chain runs on internal working levels and derives the stored level from
each one, so that nothing lossy compounds down the chain:
- premultiplied colour is carried premultiplied and only divided for output;
- normal vectors are carried unnormalised (a shorter average is what the
  level above really contains) and only renormalised for output;
- alpha coverage scaling is applied to the output levels, never fed back.
Clamping (LDR to [0, 1], float to >= 0 where the source had no negatives) is
applied to the output levels only. Feeding clamped levels down the chain lets
each clamp's shift of the mean add up (measured: 1.8% at level 1 growing to
7.2% at the 1x1 level of ldr-rgb-09 with Lanczos-3); from the unclamped
working levels every level is within a clamp of the linear filter's result.
"""

from dataclasses import dataclass, replace

import numpy as np

from .._jit import jit
from .._threads import parallel_for
from ..colour import StoredRGBA
from ..errors import InputError, UsageError
from ..formats import level_dims, max_levels
from ..normals import z_from_xy
from .coverage import alpha_coverage, scale_alpha_to_coverage
from .filters import FILTERS, KAISER_ALPHA, KAISER_WIDTH, LANCZOS_A, make_filter
from .resample import WRAPS, clamped, resample, table_gain, tap_table

# A filtered normal shorter than this has no usable direction: it becomes +Z.
_MIN_NORMAL_LENGTH = 1e-6

# Finite float32 values near the maximum (3.4e38) overflow in a filter's sums
# (Lanczos and Kaiser weights add up to more than 1 before the negative lobes
# take it back), in a normal's 2x - 1 and in colour times alpha. The working
# level's channels are kept below this, times the filter's gain, by scaling
# them with a power of two (exact), and the output levels are scaled back,
# saturating at the float32 maximum. Ordinary images never come near it, so
# for them nothing is scaled and no byte changes.
_FLOAT_MAX = float(np.finfo(np.float32).max)
_ROOM = _FLOAT_MAX / 4.0  # a factor 4 above the bound covers float32 rounding of the sums


def _fit(bound, groups=()):
    """Per-channel powers of two (at most 1) that bring `bound` (float64, per
    channel) within _ROOM; the channels of each group in `groups` share one
    (a normal's X, Y and Z keep their direction)."""
    bound = np.asarray(bound, np.float64)
    if bound.max() <= _ROOM:
        return None
    need = bound / _ROOM
    exp = np.where(need > 1.0, np.frexp(np.maximum(need, 1.0))[1], 0)
    for group in groups:
        exp[group] = exp[group].max()
    return np.ldexp(1.0, -exp)


def _scaled(level, factor):
    """float32 level times per-channel powers of two (a new array)."""
    return (level * factor).astype(np.float32)


def _unscaled(level, factor):
    """float32 level times per-channel factors, saturated to the float32
    range (a new array; where every factor is 1, only saturated, in place)."""
    factor = np.asarray(factor, np.float64)
    if np.all(factor == 1.0):
        return np.clip(level, -_FLOAT_MAX, _FLOAT_MAX, out=level)
    return np.clip(level * factor, -_FLOAT_MAX, _FLOAT_MAX).astype(np.float32)


def _back(level, scale):
    """A working level's channels in the source's units: `level` itself when
    nothing was scaled (a finite working level needs no saturating)."""
    return level if np.all(scale == 1.0) else _unscaled(level, 1.0 / scale)


@jit
def _scan(flat, lo, hi):
    """One pass over (N, C) pixels: are all finite, and each channel's minimum
    and maximum (written into `lo` and `hi`)."""
    n, c = flat.shape
    for k in range(c):
        lo[k] = np.inf
        hi[k] = -np.inf
    finite = True
    for i in range(n):
        for k in range(c):
            v = flat[i, k]
            if not np.isfinite(v):
                finite = False
            if v < lo[k]:
                lo[k] = v
            if v > hi[k]:
                hi[k] = v
    return finite


@jit
def _flat_range(bits, out):
    """One pass over float32 values given as their int32 bit patterns (flat):
    out[0] and out[1] get the order keys of the smallest and largest value
    (the pattern with the magnitude bits flipped for negatives, so that keys
    order like the values), out[2] the largest exponent field, which is
    0x7F800000 when a value is NaN or infinite. Integer min and max only, so
    the loop vectorises; the float comparisons of _scan would not."""
    lo = np.int32(0x7FFFFFFF)
    hi = np.int32(-0x7FFFFFFF - 1)
    top = np.int32(0)
    for i in range(bits.shape[0]):
        b = bits[i]
        k = b ^ ((b >> np.int32(31)) & np.int32(0x7FFFFFFF))
        lo = min(lo, k)
        hi = max(hi, k)
        top = max(top, b & np.int32(0x7F800000))
    out[0] = lo
    out[1] = hi
    out[2] = top
    return out


def _key_value(key):
    """The float32 whose order key (see _flat_range) is `key`."""
    k = np.int32(key)
    return (k if k >= 0 else k ^ np.int32(0x7FFFFFFF)).view(np.float32)


def _bounds(level0, per_channel, threads):
    """(all finite, per-channel minimum, per-channel maximum) of (H, W, C)
    pixels in one threaded pass. Without `per_channel`, every channel gets the
    minimum and maximum over all of them (the integer pass, which is faster)."""
    h, w, n_ch = level0.shape
    parts = []
    if per_channel:
        def run(a, b):
            lo, hi = np.empty(n_ch, np.float32), np.empty(n_ch, np.float32)
            ok = _scan(level0[a:b].reshape(-1, n_ch), lo, hi)
            parts.append((ok, lo, hi))
    else:
        bits = level0.reshape(h, w * n_ch).view(np.int32)

        def run(a, b):
            keys = _flat_range(bits[a:b].reshape(-1), np.empty(3, np.int32))
            lo, hi = _key_value(keys[0]), _key_value(keys[1])
            parts.append((keys[2] != 0x7F800000, np.full(n_ch, lo), np.full(n_ch, hi)))
    parallel_for(run, h, threads, max(1, 262144 // (w * n_ch)))
    # min and max are exact in any order, so the chunking does not show
    finite = all(p[0] for p in parts)
    return finite, np.min([p[1] for p in parts], axis=0), np.max([p[2] for p in parts], axis=0)


def chain_sizes(width, height):
    """(w, h) of every level, level 0 first, down to 1x1 (texcook.formats.level_dims)."""
    width, height = int(width), int(height)
    if width < 1 or height < 1:
        raise UsageError(f"image size {width}x{height} has no texels")
    return [level_dims(width, height, i) for i in range(max_levels(width, height))]


def _normalise_wrap(wrap):
    if isinstance(wrap, str):
        wrap = (wrap, wrap)
    wrap = tuple(wrap)
    if len(wrap) != 2:
        raise UsageError(f"wrap must be one mode or an (x, y) pair, not {wrap!r}")
    for mode in wrap:
        if mode not in WRAPS:
            raise UsageError(f"unknown wrap mode {mode!r} (choose from {', '.join(WRAPS)})")
    return wrap


def _decode_normals(pixels, scale=1.0):
    """[0, 1]-encoded (H, W, 2 or more) -> float32 vectors (H, W, 3), times the
    power of two `scale` (which keeps huge values from overflowing). Two-channel
    maps get Z reconstructed on the positive hemisphere."""
    two, one = np.float32(2.0 * scale), np.float32(scale)
    x = pixels[..., 0] * two - one
    y = pixels[..., 1] * two - one
    if pixels.shape[2] >= 3:
        z = pixels[..., 2] * two - one
    else:
        # X or Y beyond +-1 leaves no room for Z either way: from values clipped
        # to [0, 1] Z is the same, and the squares cannot overflow
        cx, cy = (np.clip(pixels[..., k], 0.0, 1.0) * 2.0 - 1.0 for k in (0, 1))
        z = z_from_xy(cx, cy) * one
    return np.stack([x, y, z], axis=-1).astype(np.float32)


def _encode_normals(vectors, n_channels, scale=1.0):
    """Renormalise, send degenerate vectors to +Z, encode to [0, 1]. `scale`:
    the power of two the vectors carry (see _levels), so that the degenerate
    length is judged in the source's units."""
    length = np.sqrt(np.sum(vectors.astype(np.float64) ** 2, axis=-1, keepdims=True))
    ok = length > _MIN_NORMAL_LENGTH * scale
    unit = np.where(ok, vectors / np.where(ok, length, 1.0), np.array([0.0, 0.0, 1.0]))
    enc = np.clip(unit * 0.5 + 0.5, 0.0, 1.0).astype(np.float32)
    return enc[..., : min(3, n_channels)]


@dataclass(frozen=True)
class ChainSettings:
    """What a mip chain does (docs/mips.md has each setting), checked when
    made; the checks that need the pixels (their channel count) run in
    iter_chain. `wrap` is one mode or an (x, y) pair, kept as a pair.

    `clamp=False` leaves the overshoot of negative lobes in the output (for
    measuring what clamping costs; a texture should keep the default)."""

    filter: str = "box"
    wrap: tuple = ("clamp", "clamp")
    lanczos_a: float = LANCZOS_A
    kaiser_width: float = KAISER_WIDTH
    kaiser_alpha: float = KAISER_ALPHA
    premultiply: bool = False
    alpha_channel: int = None
    alpha_cutoff: float = None
    normal_map: bool = False
    ldr: bool = True
    max_levels: int = None
    clamp: bool = True

    def __post_init__(self):
        if self.filter not in FILTERS:
            raise UsageError(f"unknown mip filter {self.filter!r} (choose from {', '.join(FILTERS)})")
        make_filter(self.filter, **self.filter_options)  # validates the filter parameters
        object.__setattr__(self, "wrap", _normalise_wrap(self.wrap))
        if self.alpha_channel is not None:
            object.__setattr__(self, "alpha_channel", int(self.alpha_channel))
        if self.alpha_cutoff is not None:
            if self.alpha_channel is None:
                raise UsageError("--alpha-cutoff needs an image with an alpha channel")
            object.__setattr__(self, "alpha_cutoff", float(self.alpha_cutoff))
            if not (0.0 <= self.alpha_cutoff <= 1.0):
                raise UsageError(f"--alpha-cutoff must be between 0 and 1, not {self.alpha_cutoff}")
        if self.premultiply and self.alpha_channel is None:
            raise UsageError("--premultiply needs an image with an alpha channel")
        if self.normal_map and self.premultiply:
            raise UsageError("--premultiply does not apply to normal maps")
        if self.max_levels is not None:
            object.__setattr__(self, "max_levels", int(self.max_levels))
            if self.max_levels < 1:
                raise UsageError(f"max_levels must be at least 1, not {self.max_levels}")

    @property
    def filter_options(self):
        """The filter's parameters, as make_filter and tap_table take them."""
        return dict(lanczos_a=self.lanczos_a, kaiser_width=self.kaiser_width, kaiser_alpha=self.kaiser_alpha)

    def check_channels(self, n_ch):
        """UsageError unless the settings fit pixels of n_ch channels."""
        alpha = self.alpha_channel
        if alpha is not None and not 0 <= alpha < n_ch:
            raise UsageError(f"alpha channel {alpha} does not exist in a {n_ch}-channel image")
        if self.normal_map:
            if n_ch < 2:
                raise UsageError("--normal-map needs at least two channels (X, Y)")
            if alpha is not None and alpha < min(3, n_ch):
                raise UsageError("the alpha channel of a normal map must come after X, Y and Z")


def build_chain(pixels, **options):
    """The mip chain of linear-light float32 (H, W, C) pixels as a list, level 0
    first; the options are iter_chain's."""
    return list(iter_chain(pixels, **options))


def iter_chain(pixels, settings=None, *, threads=None, unit_range=False, **options):
    """The mip chain of linear-light float32 (H, W, C) pixels, level 0 first,
    one level at a time: each level is built from the one before when it is
    asked for, and nothing of a level is kept once the next one is built, so a
    caller that encodes each level as it comes holds two levels at most.
    The settings (a ChainSettings, or its fields by keyword) are checked
    before this returns. A level it yields is not to be modified by the
    caller (the next one may be filtered from it).

    Level 0 is the input (as float32, unchanged); every further level halves
    each axis (floor, at least 1) down to 1x1, or stops after `max_levels`
    levels. `threads`: threads for the filtering (chunks of rows; the same
    bytes for any count).

    `unit_range=True` promises that every value is finite and in [0, 1] (as
    the decode of stored integers makes them), which skips the pass over
    level 0 that checks for NaN and Inf and finds the range.

    `pixels` may be a colour.StoredRGBA (stored integers and their tables),
    yielded as level 0 as it is: level 1 is filtered from its rows as they are
    decoded, and no float copy of level 0 is made (unless premultiplied alpha
    or a normal map needs one to filter)."""
    if settings is None:
        settings = ChainSettings(**options)
    elif options:
        raise TypeError("iter_chain() takes a ChainSettings or its fields by keyword, not both")
    st = settings

    if isinstance(pixels, StoredRGBA):
        level0 = pixels
        unit_range = True
    else:
        src = np.asarray(pixels)
        if src.ndim == 2:
            src = src[:, :, None]
        if src.ndim != 3 or src.shape[0] < 1 or src.shape[1] < 1 or src.shape[2] < 1:
            raise UsageError(f"pixels must be (H, W, C), got shape {np.shape(pixels)}")
        level0 = np.ascontiguousarray(src, dtype=np.float32)
    h, w, n_ch = level0.shape
    # NaN or Inf, and the bounds: per channel only for float sources, whose
    # clamp bounds differ per channel
    if unit_range:
        finite, src_min, src_max = True, np.zeros(n_ch, np.float32), np.ones(n_ch, np.float32)
    else:
        finite, src_min, src_max = _bounds(level0, not st.ldr, threads)
    if not finite:
        raise InputError("pixels contain NaN or Inf; replace them before building mips")
    st.check_channels(n_ch)

    sizes = chain_sizes(w, h)
    if st.max_levels is not None:
        sizes = sizes[:st.max_levels]

    # Clamp bounds per channel of the working level.
    if st.ldr:
        lo = np.zeros(n_ch, np.float32)
        hi = np.ones(n_ch, np.float32)
    else:
        # Float sources: keep values above 1; forbid negatives only where the
        # source had none (negative lobes must not invent them).
        lo = np.where(src_min >= 0.0, 0.0, -np.inf).astype(np.float32)
        hi = np.full(n_ch, np.inf, np.float32)

    # Box and triangle weights are all positive: every output is a convex mix of
    # inputs, so a source already inside the bounds needs no clamping.
    if st.filter in ("box", "triangle") and np.all(src_min >= lo) and np.all(src_max <= hi):
        st = replace(st, clamp=False)

    target = None
    if st.alpha_cutoff is not None:
        a = st.alpha_channel
        alpha = level0.channel(a) if isinstance(level0, StoredRGBA) else level0[..., a]
        target = alpha_coverage(alpha, st.alpha_cutoff)
    peak = np.maximum(np.abs(src_min), np.abs(src_max)).astype(np.float64)  # largest magnitude per channel
    return _levels(level0, st, sizes, (lo, hi), target, peak, threads)


def _levels(level0, settings, sizes, bounds, target, peak, threads):
    """iter_chain's generator over the checked settings: `sizes` of the
    levels, the clamp `bounds` (lo, hi) per channel, the alpha coverage
    `target` (None without a cutoff) and the `peak` magnitude per channel of
    the source. Its references to a level end when the next one is built
    (`level0` is dropped after the first step).

    The working level holds each channel times scale[c], a power of two that
    is 1 unless the values come near the float32 maximum (_fit); `bound` is
    an upper bound of each channel's magnitude in the working level."""
    filter, wrap, options = settings.filter, settings.wrap, settings.filter_options
    premultiply, normal_map, ldr, clamp = settings.premultiply, settings.normal_map, settings.ldr, settings.clamp
    alpha_channel, alpha_cutoff = settings.alpha_channel, settings.alpha_cutoff
    lo, hi = bounds
    given = level0  # level 0 is yielded as it was given
    if isinstance(level0, StoredRGBA) and (premultiply or normal_map):
        level0 = level0.decode(threads)  # these filter a working copy of level 0
    n_ch = level0.shape[2]
    colour = [c for c in range(n_ch) if c != alpha_channel]
    n_vec = min(3, n_ch) if normal_map else 0  # channels that hold the vector
    groups = [[0, 1, 2]] if normal_map else []
    # Working level: what the next level is filtered from.
    if normal_map:
        # 2x - 1 of each vector channel; a rebuilt Z is at most 1
        vec = 2.0 * peak[:n_vec].max() + 1.0
        s = 1.0 if vec <= _ROOM else float(_fit([vec])[0])
        work = _decode_normals(level0, s)
        scale = np.concatenate([np.full(3, s), np.ones(n_ch - n_vec)])
        bound = np.concatenate([np.full(3, vec * s), peak[n_vec:]])
        if n_ch > n_vec:
            work = np.concatenate([work, level0[..., n_vec:]], axis=-1)
    else:
        scale, bound = np.ones(n_ch), peak.copy()
        # Read-only from here unless premultiplied below: no copy needed.
        work = level0.copy() if premultiply else level0
    straight = None
    if premultiply:
        straight = level0  # straight colour, only to fill fully transparent texels
        s_scale, s_bound = np.ones(n_ch), peak.copy()
        # colour times alpha must not overflow: alpha, then each colour, scaled first where needed
        a_fit = _fit(bound[alpha_channel: alpha_channel + 1])
        if a_fit is not None:
            scale[alpha_channel] = a_fit[0]
        bound[alpha_channel] *= scale[alpha_channel]
        c_fit = _fit(bound[colour] * bound[alpha_channel])
        if c_fit is not None:
            scale[colour] = c_fit
        if a_fit is not None or c_fit is not None:
            work = _scaled(level0, scale)
            scale[colour] *= scale[alpha_channel]
        bound[colour] *= bound[alpha_channel] * scale[colour] / scale[alpha_channel]
        work[..., colour] *= work[..., alpha_channel: alpha_channel + 1]

    yield given
    level0 = given = None

    def tables(n, m, mode):
        return tap_table(n, m, filter, mode, **options) if n != m else None

    def growth(n, m, mode):
        return table_gain(n, m, filter, mode, **options) if n != m else 1.0

    for (pw, ph), (nw, nh) in zip(sizes[:-1], sizes[1:]):
        tabs = (tables(pw, nw, wrap[0]), tables(ph, nh, wrap[1]))
        gain = growth(pw, nw, wrap[0]) * growth(ph, nh, wrap[1])
        factor = _fit(bound * gain, groups)
        if factor is not None:
            work, scale, bound = _scaled(work, factor), scale * factor, bound * factor
        bound = bound * gain
        # a plain clamped level is clipped from each chunk as it is filtered (still in cache)
        fused = clamp and not (premultiply or normal_map)
        filtered = resample(work, nw, nh, filter=filter, wrap=wrap, tables=tabs, threads=threads,
                            clamp=(lo, hi) if fused else None)
        work, out = filtered if fused else (filtered, None)
        if premultiply:
            factor = _fit(s_bound * gain)
            if factor is not None:
                straight, s_scale, s_bound = _scaled(straight, factor), s_scale * factor, s_bound * factor
            s_bound = s_bound * gain
            straight = resample(straight, nw, nh, filter=filter, wrap=wrap, tables=tabs, threads=threads)
            out = clamped(work, lo, hi, threads) if clamp else work.copy()
            a = out[..., alpha_channel: alpha_channel + 1]
            pre = out[..., colour]
            if clamp and ldr:
                # Premultiplied colour cannot exceed its alpha.
                pre = np.minimum(pre, a)
            safe = np.where(a > 0.0, a, 1.0)
            fill = np.clip(straight[..., colour], lo[colour], hi[colour]) if clamp else straight[..., colour]
            if ldr and np.all(scale == 1.0) and np.all(s_scale == 1.0):
                out[..., colour] = np.where(a > 0.0, pre / safe, fill)  # at most 1
            else:
                # a tiny alpha (a negative lobe, negative alphas) can divide a colour past the
                # float32 range: saturated, in the source's units
                with np.errstate(over="ignore"):
                    ratio = pre / safe
                ratio = _unscaled(ratio, scale[alpha_channel] / scale[colour])
                out[..., colour] = np.where(a > 0.0, ratio, _back(fill, s_scale[colour]))
                out[..., alpha_channel] = _back(out[..., alpha_channel], scale[alpha_channel])
            if clamp:
                np.clip(out, lo, hi, out=out)
        elif normal_map:
            out = np.empty((nh, nw, n_ch), np.float32)
            out[..., :n_vec] = _encode_normals(work[..., :3], n_ch, scale[0])
            out[..., n_vec:] = _back(work[..., 3:], scale[3:])
            if clamp:
                np.clip(out[..., n_vec:], lo[n_vec:], hi[n_vec:], out=out[..., n_vec:])
        else:
            if not clamp:
                # the working level itself, unless the coverage step below would change it
                out = work.copy() if alpha_cutoff is not None else work
            if not np.all(scale == 1.0):
                # clipped in the source's units: bounds of 0 and 1 (LDR) do not scale
                out = _back(work, scale)
                if clamp:
                    np.clip(out, lo, hi, out=out)
        out = np.ascontiguousarray(out, dtype=np.float32)
        if alpha_cutoff is not None:
            out[..., alpha_channel] = scale_alpha_to_coverage(out[..., alpha_channel], alpha_cutoff, target)
        yield out
        out = None  # the caller has it; the next level needs only `work`


def chain_level_count(width, height):
    """Number of levels in a full chain (texcook.formats.max_levels)."""
    return max_levels(width, height)
