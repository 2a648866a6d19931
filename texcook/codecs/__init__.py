"""Codec registry: every output format, uncompressed or block-compressed, is
reached by name through `get(name)`.

Modules load lazily so that a BC1 bake does not compile the ETC1 kernels.
"""

import importlib
import importlib.util

from ..errors import UsageError
from ._base import PRESETS, Codec  # noqa: F401
from .astc import BLOCK_SIZES as _ASTC_SIZES


def _astc_names():
    return [f"astc-{w}x{h}" for w, h in _ASTC_SIZES]


# name -> (module, attribute holding the Codec instance)
_REGISTRY = {
    "rgba8": ("texcook.codecs.uncompressed", "RGBA8"),
    "rg8": ("texcook.codecs.uncompressed", "RG8"),
    "r8": ("texcook.codecs.uncompressed", "R8"),
    "rgba16f": ("texcook.codecs.uncompressed", "RGBA16F"),
    "rgba32f": ("texcook.codecs.uncompressed", "RGBA32F"),
    "bc1": ("texcook.codecs.bc1", "BC1"),
    "bc1a": ("texcook.codecs.bc1", "BC1A"),
    "bc3": ("texcook.codecs.bc4", "BC3"),
    "bc4": ("texcook.codecs.bc4", "BC4"),
    "bc5": ("texcook.codecs.bc4", "BC5"),
    "etc1": ("texcook.codecs.etc1", "ETC1"),
}
# ASTC: one codec per 2D block size, held in the package's CODECS dict (the
# package's __init__ imports no kernels)
_REGISTRY.update({name: ("texcook.codecs.astc", name) for name in _astc_names()})


def names():
    """Names whose module is present in this installation."""
    out = []
    for name, (module, _) in _REGISTRY.items():
        if importlib.util.find_spec(module) is not None:
            out.append(name)
    return out


def get(name) -> Codec:
    key = str(name).lower()
    entry = _REGISTRY.get(key)
    if entry is None:
        raise UsageError(f"unknown format {name!r}; known: {', '.join(names())}")
    module, attr = entry
    try:
        mod = importlib.import_module(module)
    except ModuleNotFoundError as exc:
        if exc.name == module:
            raise UsageError(f"format {name!r} is not available in this build") from None
        raise
    if hasattr(mod, "CODECS"):
        return mod.CODECS[attr]
    return getattr(mod, attr)


def by_vk_format(vk_format):
    """(codec, is_srgb) for a vkFormat, for readers of KTX2/DDS files."""
    for name in names():
        codec = get(name)
        if codec.vk_unorm == vk_format:
            return codec, False
        if codec.vk_srgb and codec.vk_srgb == vk_format:
            return codec, True
    return None, False
