"""astcenc's .astc files: one 2D ASTC image, no mip levels, no colour space.

Layout: a 16-byte header, then the blocks in row-major order.

    0   magic 0x5CA1AB13, little-endian (bytes 13 AB A1 5C)
    4   block width, height, depth in texels (one byte each; depth 1 for 2D)
    7   image width, height, depth in texels, each a 24-bit little-endian integer

The file does not say whether the data is sRGB: that is the reader's choice
(astcenc's decompressor takes it as an option too).
"""

from typing import NamedTuple

from .. import formats
from ..errors import ContainerError, UsageError
from ..fileio import check_memory, texel_bytes
from ..formats import ASTC_BLOCK_SIZES, level_size
from .table import CONTAINERS, Stored

MAGIC = CONTAINERS["astc"].magic  # 0x5CA1AB13, little-endian
HEADER_BYTES = 16
BLOCK_SIZES = ASTC_BLOCK_SIZES
_MAX_DIM = (1 << 24) - 1


class AstcFile(NamedTuple):
    block_w: int
    block_h: int
    width: int
    height: int
    data: bytes  # the blocks, 16 bytes each, row-major

    @property
    def format_name(self):
        return f"astc-{self.block_w}x{self.block_h}"


def data_size(block_w, block_h, width, height):
    """Bytes of blocks a width x height image takes."""
    return level_size(width, height, block_w, block_h, 16)


def write_astc(block_w: int, block_h: int, width: int, height: int, data: bytes) -> bytes:
    """The bytes of a .astc file holding one image's blocks."""
    if (block_w, block_h) not in BLOCK_SIZES:
        raise UsageError(f"{block_w}x{block_h} is not a 2D ASTC block size")
    if not (1 <= width <= _MAX_DIM and 1 <= height <= _MAX_DIM):
        raise UsageError(f".astc image size {width}x{height} is out of range (1..{_MAX_DIM})")
    data = bytes(data)
    need = data_size(block_w, block_h, width, height)
    if len(data) != need:
        raise UsageError(f"{width}x{height} in {block_w}x{block_h} blocks needs {need} bytes, got {len(data)}")
    header = (MAGIC + bytes((block_w, block_h, 1)) + width.to_bytes(3, "little")
              + height.to_bytes(3, "little") + (1).to_bytes(3, "little"))
    return header + data


def read_astc(data, name: str = None, file_size: int = None) -> AstcFile:
    """Parse and validate a .astc file's bytes; name is the file name, used in
    error messages. With `file_size`, `data` may be the header alone (for
    `texcook info`): the sizes are checked against the file's size instead."""
    def fail(msg):
        return ContainerError(msg, path=name)

    try:
        data = bytes(data)
    except TypeError:
        raise fail("not an .astc file (data is not bytes)") from None
    if len(data) < 4 or data[:4] != MAGIC:
        raise fail("not an .astc file (bad magic)")
    if len(data) < HEADER_BYTES:
        raise fail(f"truncated .astc header ({len(data)} bytes)")
    bw, bh, bd = data[4], data[5], data[6]
    width = int.from_bytes(data[7:10], "little")
    height = int.from_bytes(data[10:13], "little")
    depth = int.from_bytes(data[13:16], "little")
    if bd != 1 or depth != 1:
        raise fail(f"3D ASTC ({bw}x{bh}x{bd} blocks, depth {depth}) is not supported")
    if (bw, bh) not in BLOCK_SIZES:
        raise fail(f"block size {bw}x{bh} is not a 2D ASTC block size")
    if width < 1 or height < 1:
        raise fail(f"image size {width}x{height} is invalid")
    need = data_size(bw, bh, width, height)
    have = (len(data) if file_size is None else file_size) - HEADER_BYTES
    if have < need:
        raise fail(f"truncated: {width}x{height} in {bw}x{bh} blocks needs {need} bytes of blocks, file has {have}")
    if have > need:
        raise fail(f"{have - need} bytes after the last block")
    if file_size is None:
        # decoding makes RGBA texels of the whole image: up to 36x the file at 12x12
        check_memory(texel_bytes(width, height), f"decoding this {width}x{height} ASTC image", name,
                     ContainerError)
    return AstcFile(bw, bh, width, height, data[HEADER_BYTES:] if file_size is None else b"")


def describe_astc(astc: AstcFile, name: str) -> dict:
    """A JSON-able summary, like the KTX2 and DDS ones, for `texcook info`."""
    size = data_size(astc.block_w, astc.block_h, astc.width, astc.height)
    return {
        "file": name,
        "container": "astc",
        "format": astc.format_name,
        "width": astc.width,
        "height": astc.height,
        "levels": 1,
        "block": [astc.block_w, astc.block_h],
        "mips": [{"level": 0, "width": astc.width, "height": astc.height, "bytes": size}],
        "colour_space": "not recorded (.astc files do not say; read as linear)",
    }


# --------------------------------------------------------------------------- the container table's interface


def write_texture(texture, output) -> bytes:
    """The .astc file of a texture's level 0 (container.table.Stored)."""
    fmt = formats.get(texture.format)
    return write_astc(fmt.block_w, fmt.block_h, texture.width, texture.height, texture.levels[0])


def read_texture(data, path=None):
    astc = read_astc(data, path)
    # the file says nothing of colour space: read as UNORM, as astcenc does by default
    return Stored(astc.format_name, False, astc.width, astc.height, [astc.data], label=astc.format_name)


def describe_head(head, file_size, path) -> dict:
    return describe_astc(read_astc(head[:HEADER_BYTES], path, file_size=file_size), path)
