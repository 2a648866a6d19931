"""The transform stage, between the mip chain and the encoder.

    forward(levels, transform) -> (levels, kv)   before encoding
    inverse(levels, kv)        -> levels         after decoding

Levels are float32 RGBA arrays in linear light: the values a shader sees after
the sampler has decoded the texture (and undone sRGB). `forward` records what
it did under one KTX2 key as JSON, a list of steps in the order they ran, so a
shader, an engine, `load_texture`, `texcook decode` and `texcook compare` can
undo them and judge a texture in its source's units.

Each transform is a pair of functions registered in STEPS by name.
"""

from __future__ import annotations

import json

import numpy as np

from .errors import ContainerError

KV_KEY = "texcook.transforms"
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


STEPS = {
    "swizzle": (_swizzle_forward, _swizzle_inverse),
}


def forward(levels, transform):
    """Run the recipe's transform steps; returns (levels, kv). kv is empty
    when no step ran, so untransformed files carry no extra key."""
    record = []
    for name, params in transform.steps:
        fwd, _ = STEPS[name]
        levels, meta = fwd(levels, params)
        record.append(dict(meta, name=name))
    kv = {KV_KEY: json.dumps(record, sort_keys=True)} if record else {}
    return levels, kv


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
