"""What three.js, the viewer's renderer, loads: the one list of the vkFormats its
KTX2Loader accepts, the WebGL extension each block format needs, and where
npm installed it (texcook/view/package.json pins the version; its lock file
fixes the bytes)."""

import json
import os
import shlex

from .. import formats
from ..errors import UsageError
from ..fileio import read_bytes

HERE = os.path.dirname(os.path.abspath(__file__))
THREE_DIR = os.path.join(HERE, "node_modules", "three")
# npm installs next to this module, wherever pip put it (package.json and the lock
# file are package data): the source tree's texcook/view or site-packages/texcook/view
INSTALL = f"npm ci --prefix {shlex.quote(HERE)}"

# The container the page's loader (KTX2Loader) reads; other containers' blocks
# are rewrapped in it before the page sees them.
LOADS_CONTAINER = "ktx2"

# The keys of FORMAT_MAP in three.js r187's examples/jsm/loaders/KTX2Loader.js:
# a KTX2 file of any other vkFormat (not Basis) throws "Unsupported vkFormat".
# Note what is missing: ETC2 RGB and RGBA8 are taken in their sRGB variants only
# (147 and 151 are refused), and ASTC only in 4x4 and 6x6.
THREE_KTX2_VK_FORMATS = frozenset({
    9, 15,  # R8 UNORM, sRGB
    16, 22,  # R8G8 UNORM, sRGB
    37, 43,  # R8G8B8A8 UNORM, sRGB
    76, 83, 97,  # R16, R16G16, R16G16B16A16 SFLOAT
    91,  # R16G16B16A16_UNORM
    100, 103, 109,  # R32, R32G32, R32G32B32A32 SFLOAT
    122, 123,  # B10G11R11_UFLOAT_PACK32, E5B9G9R9_UFLOAT_PACK32
    131, 132, 133, 134,  # BC1 RGB, RGBA: UNORM, sRGB
    137, 138, 139, 140, 141, 142,  # BC3 UNORM/sRGB, BC4 and BC5 UNORM/SNORM
    145, 146,  # BC7 UNORM, sRGB
    148, 152,  # ETC2 R8G8B8 sRGB, R8G8B8A8 sRGB
    153, 154, 155, 156,  # EAC R11, R11G11: UNORM, SNORM
    157, 158, 165, 166,  # ASTC 4x4 and 6x6: UNORM, sRGB
    1000054000, 1000054001, 1000054004, 1000054005,  # PVRTC1 2 and 4 bpp, UNORM and sRGB
    1000066000, 1000066004,  # ASTC 4x4 and 6x6 SFLOAT
})

# The colour models of the vkFormat-0 (Basis Universal) payloads three.js's
# KTX2Loader transcodes with its Basis transcoder (examples/jsm/libs/basis, which
# the page serves) to whatever this GPU samples: ETC1S. (UASTC too, which
# texcook does not write.)
THREE_TRANSCODES = frozenset({formats.MODEL_ETC1S})


def three_takes(fmt: formats.Format, srgb: bool) -> bool:
    """three.js's KTX2Loader loads a KTX2 file of `fmt` stored so."""
    if srgb and not fmt.has_srgb:
        return False
    if fmt.dfd_model in THREE_TRANSCODES:
        return True
    return fmt.vk_format(srgb) in THREE_KTX2_VK_FORMATS


# vkFormats three.js takes but samples without the sRGB curve: it uploads them
# as R8 and RG8 (WebGL 2 has no one- or two-channel sRGB format), so a shader
# reads the encoded values as if they were linear.
THREE_IGNORES_SRGB = frozenset({15, 22})

# The WebGL 2 extension a block format needs, by the start of its Vulkan name.
_WEBGL_EXTENSIONS = (
    ("BC1", "WEBGL_compressed_texture_s3tc"), ("BC2", "WEBGL_compressed_texture_s3tc"),
    ("BC3", "WEBGL_compressed_texture_s3tc"),
    ("BC4", "EXT_texture_compression_rgtc"), ("BC5", "EXT_texture_compression_rgtc"),
    ("BC6", "EXT_texture_compression_bptc"), ("BC7", "EXT_texture_compression_bptc"),
    ("ETC2", "WEBGL_compressed_texture_etc"), ("EAC", "WEBGL_compressed_texture_etc"),
    ("ASTC", "WEBGL_compressed_texture_astc"),
)


def webgl_extensions(fmt: formats.Format, srgb: bool) -> list:
    """The WebGL 2 extensions a browser needs to upload `fmt` (none for uncompressed)."""
    for stem, name in _WEBGL_EXTENSIONS:
        if fmt.vk_name.startswith(stem):
            # sRGB S3TC is a separate extension; the others cover both
            return [name, name + "_srgb"] if srgb and name.endswith("_s3tc") else [name]
    return []


def vk_table() -> dict:
    """vkFormat -> what the page needs to know of it: texcook's name, sRGB, the
    WebGL extensions, and whether three.js's KTX2Loader takes it."""
    table = {}
    for fmt in formats.FORMATS.values():
        for vk in (fmt.vk_unorm, fmt.vk_srgb):
            named, kind = formats.by_vk_format(vk)
            if vk and named is not None:  # named as texcook's reader names it
                table[vk] = {"format": named.name, "srgb": kind == "srgb",
                             "webgl": webgl_extensions(named, kind == "srgb"), "three": vk in THREE_KTX2_VK_FORMATS,
                             "srgb_ignored": vk in THREE_IGNORES_SRGB}
    # vkFormat 0: a Basis Universal payload, which KTX2Loader transcodes to a
    # format this GPU samples (no extension of its own needed)
    basis = [f.name for f in formats.FORMATS.values() if f.dfd_model in THREE_TRANSCODES and f.codec_module]
    if basis:
        table[0] = {"format": " or ".join(basis), "srgb": False, "webgl": [], "three": True, "srgb_ignored": False,
                    "transcoded": True}
    return table


def written_variants():
    """(Format, srgb) of every vkFormat texcook can write to KTX2, and whether
    three.js takes it: what the browser conformance test walks."""
    out = []
    for name in formats.encodable():
        fmt = formats.get(name)
        if fmt.transform:
            continue  # a transform three.js knows nothing of: it would show the stored channels
        for vk, srgb in ((fmt.vk_unorm, False), (fmt.vk_srgb, True)):
            if vk:
                out.append((fmt, srgb, vk in THREE_KTX2_VK_FORMATS))
    return out


def three_version():
    """three.js's installed version, or None when `npm ci` has not installed it."""
    package = os.path.join(THREE_DIR, "package.json")
    if not os.path.isfile(package):
        return None
    return json.loads(read_bytes(package, "three.js package.json"))["version"]


def require_three():
    """UsageError with the install command when three.js is missing."""
    if three_version() is None:
        # an installed texcook may live where this user cannot write (a system site-packages)
        who = "" if os.access(HERE, os.W_OK) else " as a user who can write there"
        raise UsageError(f"three.js is not installed for texcook view; run `{INSTALL}`{who}")
