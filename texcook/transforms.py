"""The transform stage, between the mip chain and the encoder.

    forward(levels, transform) -> (levels, kv)   before encoding
    inverse(levels, kv)        -> levels         after decoding

Levels are float32 RGBA arrays in linear light: the values a shader sees after
the sampler has decoded the texture (and undone sRGB). `forward` records what
it did under one KTX2 key as JSON, a list of steps in the order they ran, so a
shader, an engine, `load_texture`, `texcook decode` and `texcook compare` can
undo them and judge a texture in its source's units.

Each transform is a pair of functions registered in STEPS by name; a forward
function returns (levels, meta), or (levels, meta, notes) with what a user
should be told.

Renormalisation (Kaplanyan, after RTR4 6.2) maps the range each channel uses
onto 0..1 before encoding, so the codec spends its precision on that range. It
records, per channel r, g, b, a (and per level in "level" mode), a scale and a
bias with which a shader restores the value it would have sampled:

    value = stored * scale + bias

where `stored` is what the sampler returns (after it decodes sRGB), so the map
is affine in linear light, where this stage runs.
"""

from __future__ import annotations

import json

import numpy as np

from .colour import rgb_to_ycocg, ycocg_to_rgb
from .container import ktx2_keys as keys
from . import formats
from .errors import ContainerError

KV_KEY = keys.TRANSFORMS.name
_CHANNELS = "rgba"
_FILL = (0.0, 0.0, 0.0, 1.0)  # what a channel no stored channel carries reads as


def swizzle(levels, mapping):
    """Output channel i takes source channel mapping[i], or the constant 0 or 1
    (255 for 8-bit levels). Also how KTXswizzle is applied on reading."""
    out = []
    for px in levels:
        one = 255 if px.dtype == np.uint8 else 1.0
        res = np.empty_like(px)
        for i, c in enumerate(mapping):
            if c in "01":
                res[..., i] = one if c == "1" else 0
            else:
                res[..., i] = px[..., _CHANNELS.index(c)]
        out.append(res)
    return out


def _swizzle_forward(levels, mapping):
    return swizzle(levels, mapping), {"map": mapping}


def _swizzle_inverse(levels, params):
    mapping = params.get("map")
    if not isinstance(mapping, str) or len(mapping) != 4 or any(c not in "rgba01" for c in mapping):
        raise ValueError(f"bad swizzle map {mapping!r}")
    out = []
    for px in levels:
        res = np.empty_like(px)
        for c, name in enumerate(_CHANNELS):
            i = mapping.find(name)
            # a source channel no output channel kept cannot come back
            res[..., c] = px[..., i] if i >= 0 else _FILL[c]
        out.append(res)
    return out


def _channel_range(values, clip):
    """(lo, hi, below, above) of a (n, 4) array per channel: min/max, or the
    `clip` and 100 - `clip` percentiles, with the fraction of values outside."""
    if clip:
        with np.errstate(over="ignore", invalid="ignore"):
            lo = np.percentile(values, clip, axis=0)
            hi = np.percentile(values, 100.0 - clip, axis=0)
        if not (np.isfinite(lo).all() and np.isfinite(hi).all()):
            # between values of opposite sign near the float32 maximum the
            # interpolation overflows float32: again in float64
            lo = np.percentile(values.astype(np.float64), clip, axis=0)
            hi = np.percentile(values.astype(np.float64), 100.0 - clip, axis=0)
    else:
        lo, hi = values.min(axis=0), values.max(axis=0)
    below = (values < lo).mean(axis=0)
    above = (values > hi).mean(axis=0)
    return lo.astype(np.float64), hi.astype(np.float64), below, above


def _scale_bias(lo, hi):
    """Per-channel (scale, bias) as float32-exact Python floats. A constant
    channel keeps scale 1 and bias 0: there is no range to stretch, and an
    opaque alpha stays exactly 1."""
    scale, bias = [], []
    for a, b in zip(lo, hi):
        if not b - a > 1e-7:
            scale.append(1.0)
            bias.append(0.0)
        else:
            if b - a > _FLOAT_MAX:
                # wider than float32 can scale (values of both signs near its
                # maximum): the widest range it can, centred on this one
                a, b = 0.5 * (a + b) - 0.5 * _FLOAT_MAX, 0.5 * (a + b) + 0.5 * _FLOAT_MAX
            scale.append(float(np.float32(b - a)))
            bias.append(float(np.float32(a)))
    return scale, bias


_FLOAT_MAX = float(np.finfo(np.float32).max)


def _remap(px, scale, bias):
    s = np.asarray(scale, np.float32)
    b = np.asarray(bias, np.float32)
    # values a percentile clip cut off land on the ends of the range (and a
    # difference that overflows float32 is far beyond them: it clips the same)
    with np.errstate(over="ignore"):
        return np.clip((px - b) / s, 0.0, 1.0).astype(np.float32)


def _renormalize_forward(levels, params):
    mode, clip = params["mode"], params.get("clip")
    groups = [levels] if mode == "texture" else [[px] for px in levels]
    scales, biases, clipped = [], [], []
    for group in groups:
        values = np.concatenate([px.reshape(-1, px.shape[-1]) for px in group])
        lo, hi, below, above = _channel_range(values, clip)
        scale, bias = _scale_bias(lo, hi)
        scales.append(scale)
        biases.append(bias)
        clipped.append((below, above))
    if mode == "texture":
        out = [_remap(px, scales[0], biases[0]) for px in levels]
        meta = {"mode": mode, "scale": scales[0], "bias": biases[0]}
    else:
        out = [_remap(px, s, b) for px, s, b in zip(levels, scales, biases)]
        meta = {"mode": mode, "scale": scales, "bias": biases}
    notes = []
    if clip:
        below = np.mean([c[0] for c in clipped], axis=0)
        above = np.mean([c[1] for c in clipped], axis=0)
        per = ", ".join(f"{ch} {100 * lo_:.2f}%/{100 * hi_:.2f}%" for ch, lo_, hi_ in zip(_CHANNELS, below, above))
        notes.append(f"renormalize clipped {clip}% at each end: values below/above the kept range: {per}")
        meta["clip"] = clip
    return out, meta, notes


def _number_list(x, n, what):
    if not isinstance(x, list) or len(x) != n or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v) for v in x):
        raise ValueError(f"renormalize {what} must be {n} numbers")
    return np.asarray(x, np.float32)


def _renormalize_inverse(levels, params):
    mode = params.get("mode")
    scale, bias = params.get("scale"), params.get("bias")
    if mode == "texture":
        per_level = [(scale, bias)] * len(levels)
    elif mode == "level":
        if not isinstance(scale, list) or not isinstance(bias, list) or len(scale) < len(levels) \
                or len(bias) < len(levels):
            raise ValueError("renormalize needs a scale and bias for every level")
        per_level = list(zip(scale, bias))
    else:
        raise ValueError(f"renormalize mode must be texture or level, not {mode!r}")
    out = []
    for px, (s, b) in zip(levels, per_level):
        n = px.shape[-1]
        out.append((px * _number_list(s, n, "scale") + _number_list(b, n, "bias")).astype(np.float32))
    return out


# Scaled YCoCg (van Waveren and Castano 2007), the layout of format bc3-ycocg:
# per 4x4 block, R = Co * s + 128/255, G = Cg * s + 128/255, B = (s - 1) * 8/255
# (s - 1 in the top bits of a 5-bit BC1 blue, so it survives the endpoints
# exactly) and A = Y. s in {1, 2, 4} is the largest that keeps the block's
# scaled Co and Cg within 8 bits. The shader's reconstruction:
YCOCG_SHADER = ("s = B * 255/8 + 1; Co = (R - 128/255) / s; Cg = (G - 128/255) / s; Y = A; "
                "RGB = (Y + Co - Cg, Y + Cg, Y - Co - Cg)")
YCOCG_BLOCK = formats.get("bc3-ycocg").block_w  # each block of the codec has its own scale
YCOCG_OFFSET = 128.0 / 255.0
YCOCG_SCALES = (4, 2, 1)


def ycocg_layout(px):
    """(H, W, 4) float RGB (0..1) -> the scaled YCoCg layout; alpha is not kept."""
    h, w = px.shape[:2]
    ycc = rgb_to_ycocg(np.asarray(px[..., :3], np.float32))
    n = YCOCG_BLOCK
    nby, nbx = formats.block_count(h, n), formats.block_count(w, n)
    # edge-replicated like the codec's blocks, so each block's range is its texels'
    pad = np.pad(ycc[..., 1:], ((0, nby * n - h), (0, nbx * n - w), (0, 0)), mode="edge")
    blocks = pad.reshape(nby, n, nbx, n, 2)
    hi = blocks.max(axis=(1, 3, 4))
    lo = blocks.min(axis=(1, 3, 4))
    scale = np.ones((nby, nbx), np.float32)
    for s in YCOCG_SCALES[::-1]:
        # scaled chroma must land within -128/255 .. 127/255 (half a code of slack)
        fits = (hi * s <= 127.5 / 255) & (lo * s >= -128.5 / 255)
        scale = np.where(fits, np.float32(s), scale)
    full = np.repeat(np.repeat(scale, n, axis=0), n, axis=1)[:h, :w]
    out = np.empty((h, w, 4), np.float32)
    out[..., 0] = ycc[..., 1] * full + YCOCG_OFFSET
    out[..., 1] = ycc[..., 2] * full + YCOCG_OFFSET
    out[..., 2] = (full - 1.0) * (8.0 / 255.0)
    out[..., 3] = ycc[..., 0]
    return out


def ycocg_rgb(px):
    """The shader's reconstruction (YCOCG_SHADER): layout -> (H, W, 4) RGB, alpha 1."""
    px = np.asarray(px, np.float32)
    s = px[..., 2] * np.float32(255.0 / 8.0) + 1.0
    ycc = np.stack([px[..., 3], (px[..., 0] - YCOCG_OFFSET) / s, (px[..., 1] - YCOCG_OFFSET) / s], axis=-1)
    out = np.ones(px.shape[:2] + (4,), np.float32)
    out[..., :3] = ycocg_to_rgb(ycc)
    return out


def _ycocg_forward(levels, params):
    return [ycocg_layout(px) for px in levels], ycocg_record()


def _ycocg_inverse(levels, params):
    return [ycocg_rgb(px) for px in levels]


def ycocg_record():
    """What the ycocg step records: the reconstruction, for a shader's author.
    The pipeline adds "rgb": the encoding of the rebuilt RGB (the source's:
    "srgb" means a shader applies the sRGB decode after rebuilding)."""
    return {"layout": "scaled YCoCg-DXT5", "shader": YCOCG_SHADER}


STEPS = {
    "swizzle": (_swizzle_forward, _swizzle_inverse),
    "renormalize": (_renormalize_forward, _renormalize_inverse),
    "ycocg": (_ycocg_forward, _ycocg_inverse),
}

# What a format that records a transform (formats.Format.transform) adds to the record.
FORMAT_STEPS = {"ycocg": ycocg_record}
# Channels that carry data once a step is undone, where the step decides it.
_CHANNELS_AFTER = {"ycocg": 3}

# Steps whose inverse yields values between 8-bit codes: a reader keeps them as float.
FRACTIONAL = frozenset({"renormalize"})


def forward(levels, transform, notes=None):
    """Run the recipe's transform steps; returns (levels, kv). kv is empty
    when no step ran, so untransformed files carry no extra key. What a user
    should know (a percentile clip's cut) is appended to `notes`."""
    record = []
    for name, params in transform.steps:
        fwd, _ = STEPS[name]
        result = fwd(levels, params)
        levels, meta = result[:2]
        if notes is not None and len(result) > 2:
            notes.extend(result[2])
        record.append(dict(meta, name=name))
    kv = {KV_KEY: json.dumps(record, sort_keys=True)} if record else {}
    return levels, kv


def record_format_step(kv, name, **extra):
    """kv with the format's own step (done by its codec) appended to the record."""
    record = json.loads(kv[KV_KEY]) if KV_KEY in kv else []
    record.append(dict(FORMAT_STEPS[name](), name=name, **extra))
    return dict(kv, **{KV_KEY: json.dumps(record, sort_keys=True)})


def rgb_encoding(kv_text, path=None):
    """"srgb" when a recorded step says the RGB it rebuilds is sRGB-encoded
    (a shader decodes it after the reconstruction), else None."""
    for step in recorded(kv_text, path):
        if step.get("rgb") == "srgb":
            return "srgb"
    return None


def channels_after(kv_text, channels, path=None):
    """How many channels carry data after the recorded steps are undone."""
    for step in recorded(kv_text, path):
        channels = _CHANNELS_AFTER.get(step["name"], channels)
    return channels


def fractional(kv_text, path=None):
    """True when undoing the recorded steps gives values between 8-bit codes."""
    return any(step["name"] in FRACTIONAL for step in recorded(kv_text, path))


def recorded(kv_text, path=None):
    """The steps recorded in a file's key/value text, validated."""
    try:
        steps = json.loads(kv_text)
        if not isinstance(steps, list) or not all(isinstance(s, dict) and s.get("name") in STEPS for s in steps):
            raise ValueError("not a list of known steps")
    except ValueError as exc:
        raise ContainerError(f"bad {KV_KEY} value: {exc}", path) from None
    return steps


def inverse(levels, kv_text, path=None):
    """Undo the recorded steps, last first."""
    for step in reversed(recorded(kv_text, path)):
        _, inv = STEPS[step["name"]]
        try:
            levels = inv(levels, step)
        except ValueError as exc:
            raise ContainerError(f"bad {KV_KEY} value: {exc}", path) from None
    return levels
