"""Codec registry: every format of texcook.formats that has an encoder is
reached by name through `get(name)`.

A format names the module holding its codec (`Format.codec_module`, whose
`CODECS` dict maps names to codecs). Modules load lazily so that a BC1 bake
does not compile the ETC1 kernels.
"""

import importlib
import importlib.util

from .. import formats
from ..errors import UsageError
from ._base import PRESETS, Codec, Option  # noqa: F401


def names():
    """Names of the formats whose codec module is present in this installation."""
    return [n for n in formats.encodable() if importlib.util.find_spec(formats.get(n).codec_module)]


def get(name) -> Codec:
    fmt = formats.get(name)
    if not fmt.codec_module:
        raise UsageError(f"format {fmt.name} is stored by texcook (summed-area tables) but has no encoder")
    try:
        mod = importlib.import_module(fmt.codec_module)
    except ModuleNotFoundError as exc:
        if exc.name == fmt.codec_module:
            raise UsageError(f"format {name!r} is not available in this build") from None
        raise
    return mod.CODECS[fmt.name]


def by_vk_format(vk_format):
    """(codec, is_srgb) for a vkFormat, for readers of KTX2/DDS files; (None,
    False) when no codec decodes it."""
    fmt, kind = formats.by_vk_format(vk_format)
    if fmt is None or kind == "snorm" or fmt.name not in names():
        return None, False
    return get(fmt.name), kind == "srgb"
