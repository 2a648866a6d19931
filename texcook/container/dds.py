"""DDS files with a mip chain: BC1, BC1A, BC3, BC4, BC5, and the uncompressed
formats that have a DXGI format (rgba8, rg8, r8, rgba16f, rgba32f).

Two header styles:

- legacy: a FourCC in the pixel format (DXT1, DXT5, ATI1, ATI2), read by every
  DDS loader; it cannot say sRGB. BC1 with punch-through alpha sets the
  DDPF_ALPHAPIXELS flag so a reader can tell it from opaque BC1.
- DX10: FourCC "DX10" followed by a 20-byte extension naming a DXGI format,
  which can say sRGB (BC1/BC3). BC1A there is BC1 with alpha mode "straight".

An sRGB texture is always written with the DX10 header: a legacy header would
silently drop the colour space. Uncompressed formats always use it too (their
DXGI format says exactly what is stored), with a row pitch instead of a linear
size as the header asks of uncompressed data.

Layout: "DDS ", the 124-byte header, [the DX10 extension], then the levels
largest first, each level's blocks in row-major order, no padding.
"""

import struct
from dataclasses import dataclass

from .. import formats
from ..errors import ContainerError
from ..fileio import check_memory, texel_bytes
from ..formats import level_dims, max_levels
from .levels import check_levels
from .table import CONTAINERS, Stored

MAGIC = CONTAINERS["dds"].magic

# header flags
_CAPS, _HEIGHT, _WIDTH, _PITCH, _PIXELFORMAT, _MIPMAPCOUNT, _LINEARSIZE = (
    0x1, 0x2, 0x4, 0x8, 0x1000, 0x20000, 0x80000)
# pixel format flags
_PF_ALPHAPIXELS, _PF_FOURCC = 0x1, 0x4
# caps
_CAPS_COMPLEX, _CAPS_TEXTURE, _CAPS_MIPMAP = 0x8, 0x1000, 0x400000
_DIM_TEXTURE2D = 3
_ALPHA_UNKNOWN, _ALPHA_STRAIGHT = 0, 1

# Legacy FourCCs other writers use besides the table's own.
_LEGACY_ALIASES = {b"BC4U": "bc4", b"BC5U": "bc5"}

# A format that shares another's DXGI code and FourCC (bc1a: bc1's), by the
# name of that other one: the header's alpha flags say which was written.
_ALPHA_TWIN = {f.dds_alpha_of: f.name for f in formats.FORMATS.values() if f.dds_alpha_of}


def _legacy_read(fourcc):
    for fmt in formats.FORMATS.values():
        if fmt.fourcc and fmt.fourcc == fourcc and not fmt.dds_alpha_of:
            return fmt.name
    return _LEGACY_ALIASES.get(fourcc)


def _level_size(name, width, height, i):
    w, h = level_dims(width, height, i)
    return formats.get(name).level_size(w, h)


def check_format(name, srgb=False, path=None):
    """UsageError unless DDS can hold the format (and its sRGB variant)."""
    return CONTAINERS["dds"].check_format(name, srgb, path)


def write_dds(codec_name: str, width: int, height: int, levels: list, srgb: bool, dx10: bool = False) -> bytes:
    """The bytes of a DDS file; levels[0] is the base level."""
    fmt = check_format(codec_name, srgb)
    name = fmt.name
    levels = check_levels("DDS", width, height, levels, fmt.level_size, name)
    n = len(levels)
    # sRGB and formats without a FourCC need the DX10 header; a legacy header
    # would silently drop the colour space
    dx10 = bool(dx10 or srgb or not fmt.fourcc)

    flags = _CAPS | _HEIGHT | _WIDTH | _PIXELFORMAT
    if fmt.is_block_compressed:
        flags |= _LINEARSIZE
        pitch_or_size = len(levels[0])
    else:
        flags |= _PITCH
        pitch_or_size = width * fmt.bytes_per_block
    caps = _CAPS_TEXTURE
    if n > 1:
        flags |= _MIPMAPCOUNT
        caps |= _CAPS_COMPLEX | _CAPS_MIPMAP
    pf_flags = _PF_FOURCC
    if fmt.dds_alpha_of and not dx10:
        pf_flags |= _PF_ALPHAPIXELS
    pixel_format = struct.pack("<II4s5I", 32, pf_flags, b"DX10" if dx10 else fmt.fourcc, 0, 0, 0, 0, 0)
    header = struct.pack(
        "<7I44s32s5I",
        124, flags, height, width, pitch_or_size, 0, n,
        bytes(44), pixel_format, caps, 0, 0, 0, 0,
    )
    parts = [MAGIC, header]
    if dx10:
        alpha_mode = _ALPHA_STRAIGHT if fmt.dds_alpha_of else _ALPHA_UNKNOWN
        parts.append(struct.pack("<5I", fmt.dxgi_srgb if srgb else fmt.dxgi, _DIM_TEXTURE2D, 0, 1, alpha_mode))
    parts.extend(bytes(x) for x in levels)
    return b"".join(parts)


_CAPS2_CUBEMAP, _CAPS2_VOLUME = 0x200, 0x200000
_MISC_TEXTURECUBE = 0x4


@dataclass(frozen=True)
class DdsHeader:
    """What a DDS header declares, checked against the file's length."""

    name: str  # file name, for messages
    codec: str
    width: int
    height: int
    srgb: bool
    dx10: bool
    level_sizes: tuple  # bytes of each level, base first
    data_offset: int
    file_size: int


HEADER_BYTES = 148  # "DDS ", the header and the DX10 extension: all parse_dds reads


def parse_dds(data: bytes, name: str = None, file_size: int | None = None) -> DdsHeader:
    """Check a DDS file's header and that every level it declares is in the file,
    without copying any level. `data` may be just the first HEADER_BYTES of a
    file of `file_size` bytes."""
    size_of_file = len(data) if file_size is None else file_size

    def fail(msg):
        return ContainerError(msg, path=name)

    if len(data) < 4 or data[:4] != MAGIC:
        raise fail("not a DDS file (bad magic)")
    if len(data) < 128:
        raise fail(f"truncated DDS header ({len(data)} bytes)")
    (size, flags, height, width, _linear, _depth, mips) = struct.unpack_from("<7I", data, 4)
    if size != 124:
        raise fail(f"DDS header size {size}, expected 124")
    pf_size, pf_flags, fourcc = struct.unpack_from("<II4s", data, 76)
    if pf_size != 32:
        raise fail(f"DDS pixel format size {pf_size}, expected 32")
    if not pf_flags & _PF_FOURCC:
        raise fail("DDS pixel formats without a FourCC (legacy uncompressed) are not supported")
    if width < 1 or height < 1:
        raise fail(f"DDS size {width}x{height} is invalid")
    (caps2,) = struct.unpack_from("<I", data, 112)
    if caps2 & _CAPS2_CUBEMAP:
        raise fail("DDS cube maps are not supported")
    if caps2 & _CAPS2_VOLUME:
        raise fail("DDS volume textures are not supported")
    offset = 128
    srgb = False
    if fourcc == b"DX10":
        if len(data) < 148:
            raise fail("truncated DDS DX10 header")
        dxgi, dim, misc, array_size, alpha_mode = struct.unpack_from("<5I", data, 128)
        offset = 148
        fmt, srgb = formats.by_dxgi(dxgi)
        if fmt is None or not fmt.codec_module:
            raise fail(f"DXGI format {dxgi} is not supported")
        if dim != _DIM_TEXTURE2D:
            raise fail(f"DDS resource dimension {dim} is not a 2D texture")
        if misc & _MISC_TEXTURECUBE:
            raise fail("DDS cube maps are not supported")
        if array_size > 1:
            raise fail(f"DDS texture arrays ({array_size} layers) are not supported")
        codec = fmt.name
        if alpha_mode == _ALPHA_STRAIGHT:
            codec = _ALPHA_TWIN.get(codec, codec)
    else:
        codec = _legacy_read(fourcc)
        if codec is None:
            raise fail(f"DDS FourCC {printable_fourcc(fourcc)} is not supported (DXT1, DXT5, ATI1, ATI2 only)")
        if pf_flags & _PF_ALPHAPIXELS:
            codec = _ALPHA_TWIN.get(codec, codec)
    n = mips if (flags & _MIPMAPCOUNT and mips > 0) else 1
    if n > max_levels(width, height):
        raise fail(f"{n} mip levels for {width}x{height} is more than the size allows")
    sizes = []
    end = offset
    for i in range(n):
        sz = _level_size(codec, width, height, i)
        end += sz
        if end > size_of_file:
            raise fail(f"truncated DDS data in mip level {i} (needs {end} bytes, file has {size_of_file})")
        sizes.append(sz)
    return DdsHeader(name, codec, width, height, srgb, fourcc == b"DX10", tuple(sizes), offset, size_of_file)


def printable_fourcc(fourcc: bytes) -> str:
    return "".join(chr(b) if 32 <= b < 127 else f"\\x{b:02x}" for b in fourcc)


def read_dds(data: bytes, name: str = None) -> tuple:
    """(codec_name, width, height, levels, srgb) from a DDS file's bytes. name is
    the file name, used in error messages. The decoded size is checked against
    the memory budget (texcook.fileio) before any level is copied."""
    data = bytes(data)
    head = parse_dds(data, name)
    decoded = sum(texel_bytes(*level_dims(head.width, head.height, i)) for i in range(len(head.level_sizes)))
    check_memory(decoded, f"decoding this {head.width}x{head.height} {head.codec} texture "
                 f"({len(head.level_sizes)} level(s))", name, error=ContainerError)
    levels = []
    offset = head.data_offset
    for sz in head.level_sizes:
        levels.append(data[offset:offset + sz])
        offset += sz
    return head.codec, head.width, head.height, levels, head.srgb


def describe_dds(head: DdsHeader) -> dict:
    """A JSON-able summary of a DDS file for `texcook info`, with the keys a KTX2
    summary has where DDS has the fact."""
    mips = []
    for i, sz in enumerate(head.level_sizes):
        w, h = level_dims(head.width, head.height, i)
        mips.append({"level": i, "width": w, "height": h, "bytes": sz})
    return {
        "file": head.name,
        "container": "dds",
        "format": head.codec,
        "header": "DX10" if head.dx10 else "legacy",
        "width": head.width,
        "height": head.height,
        "levels": len(head.level_sizes),
        "block": [formats.get(head.codec).block_w, formats.get(head.codec).block_h],
        "mips": mips,
        "colour_space": "srgb" if head.srgb else "linear",
        "trailing_bytes": head.file_size - head.data_offset - sum(head.level_sizes),
    }


# --------------------------------------------------------------------------- the container table's interface


def write_texture(texture, output) -> bytes:
    """The DDS file of a texture (container.table.Stored), in the output's header style."""
    return write_dds(texture.format, texture.width, texture.height, texture.levels, texture.srgb,
                     dx10=output.dds_dx10)


def read_texture(data, path=None):
    name, width, height, levels, srgb = read_dds(data, path)
    return Stored(name, srgb, width, height, levels, label=name)


def describe_head(head, file_size, path) -> dict:
    return describe_dds(parse_dds(head, path, file_size=file_size))
