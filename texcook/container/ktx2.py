"""KTX2 container: write and read 2D textures with a mip chain.

Layout written (KTX 2.0 specification, little-endian throughout):

    header (80 bytes) | level index (24 bytes per level, base level first)
    | DFD (one Basic block) | key/value data (4-byte aligned entries)
    | level data, smallest level first, each aligned to lcm(texel block bytes, 4)

With Zstandard supercompression (scheme 2) each level is compressed on its own,
stored without alignment padding, and its index entry records both the stored
and the uncompressed length; vkFormat and DFD describe the uncompressed data.

ETC1S (Basis Universal) is written with BasisLZ supercompression (scheme 1):
vkFormat 0, a DFD of colour model ETC1S with one sample (RGB) or two (RGB,
alpha), the BasisLZ global data 8-byte aligned after the key/value data, each
level its slices (texcook.container.basislz) with uncompressedByteLength 0.
ETC1S formats are keyed by the DFD's sample count and transfer function, not
by vkFormat; reading gives back the ETC1S blocks.

The DFD for each format is the one KTX-Software's vk2dfd produces, so files
pass `ktx validate`. The reader is a validator too: every header field, the
level index, the DFD and the key/value data are checked, and any problem is a
ContainerError naming the file.
"""

from __future__ import annotations

import math
import re
import struct
import zlib
from dataclasses import dataclass, field

from .. import __version__
from ..choices import ZSTD_LEVELS
from ..errors import ContainerError, UsageError
from ..fileio import check_memory, texel_bytes
from . import ktx2_keys as keys
from .levels import check_levels
from .table import CONTAINERS, Stored

IDENTIFIER = CONTAINERS["ktx2"].magic
HEADER_SIZE = 80
HEADER_BYTES = HEADER_SIZE  # what describe_head needs first
LEVEL_ENTRY_SIZE = 24

SUPERCOMPRESSION_NONE = 0
SUPERCOMPRESSION_BASISLZ = 1
SUPERCOMPRESSION_ZSTD = 2
SUPERCOMPRESSION_ZLIB = 3
SUPERCOMPRESSION_NAMES = {0: "none", 1: "basislz", 2: "zstd", 3: "zlib"}

from .. import formats as _formats
from ..formats import (  # noqa: F401 - re-exported for readers of this module
    CHANNEL_ALPHA, MODEL_ASTC, MODEL_BC1A, MODEL_BC3, MODEL_BC4, MODEL_BC5, MODEL_ETC1S, MODEL_ETC2, MODEL_NAMES,
    MODEL_RGBSDA,
    level_dims, max_levels,
)

PRIMARIES_BT709 = 1
TRANSFER_LINEAR = 1
TRANSFER_SRGB = 2
# Sample qualifiers (the top 4 bits of the channel byte).
Q_LINEAR = 1
Q_EXPONENT = 2
Q_SIGNED = 4
Q_FLOAT = 8

_F32_ONE = 0x3F800000
_F32_MINUS_ONE = 0xBF800000

# Keys with a KTX/ktx prefix are reserved; these are the ones the specification defines.
KNOWN_KTX_KEYS = frozenset({
    "KTXcubemapIncomplete", "KTXorientation", "KTXglFormat", "KTXdxgiFormat__",
    "KTXmetalPixelFormat", "KTXswizzle", "KTXwriter", "KTXwriterScParams",
    "KTXastcDecodeMode", "KTXanimData",
})


# Reserved keys whose values the specification defines as NUL-terminated UTF-8.
_TEXT_KEYS = frozenset({"KTXorientation", "KTXswizzle", "KTXwriter", "KTXwriterScParams", "KTXastcDecodeMode"})
_ORIENTATIONS_2D = frozenset({b"rd", b"ru", b"ld", b"lu"})


@dataclass(frozen=True)
class Sample:
    """One DFD sample: which bits of the texel block hold which channel."""

    bit_offset: int
    bit_length: int  # in bits (the DFD stores length - 1)
    channel: int
    qualifiers: int  # Q_* bits
    lower: int
    upper: int


@dataclass(frozen=True)
class FormatInfo:
    """What the container needs to know about one vkFormat."""

    name: str  # Vulkan name without the VK_FORMAT_ prefix
    block_w: int
    block_h: int
    bytes_per_block: int
    type_size: int
    srgb: bool
    vk_format: int = 0
    color_model: int = MODEL_RGBSDA
    samples: tuple = ()
    twin: int | None = None  # the sRGB/UNORM counterpart, when the format has one

    @property
    def block_compressed(self) -> bool:
        return self.color_model != MODEL_RGBSDA

    @property
    def etc1s(self) -> bool:
        return self.color_model == MODEL_ETC1S

    @property
    def planes(self) -> list:
        """bytesPlane0..7: ETC1S has one 8-byte plane per slice."""
        if self.etc1s:
            return [8] * len(self.samples) + [0] * (8 - len(self.samples))
        return [self.bytes_per_block] + [0] * 7

    @property
    def alignment(self) -> int:
        """Level alignment in an uncompressed file: lcm(texel block bytes, 4)."""
        return math.lcm(self.bytes_per_block, 4)

    def level_size(self, width: int, height: int) -> int:
        return _formats.level_size(width, height, self.block_w, self.block_h, self.bytes_per_block)


def _unpacked(vk, name, channels, channel_bytes, suffix, twin=None):
    """An uncompressed little-endian format, one sample per channel (createDFDUnpacked)."""
    bits = 8 * channel_bytes
    samples = []
    for i in range(channels):
        ch = CHANNEL_ALPHA if i == 3 else i
        if suffix in ("UNORM", "SRGB"):
            quals, lower, upper = 0, 0, min((1 << bits) - 1, 0xFFFFFFFF)
            if suffix == "SRGB" and ch == CHANNEL_ALPHA:
                quals = Q_LINEAR  # alpha is never sRGB-encoded
        elif suffix == "UINT":
            quals, lower, upper = 0, 0, 1
        elif suffix == "SFLOAT":
            quals, lower, upper = Q_FLOAT | Q_SIGNED, _F32_MINUS_ONE, _F32_ONE
        else:  # pragma: no cover - table below uses only the suffixes above
            raise AssertionError(suffix)
        samples.append(Sample(bits * i, bits, ch, quals, lower, upper))
    return FormatInfo(
        f"{name}_{suffix}", 1, 1, channels * channel_bytes, channel_bytes, suffix == "SRGB",
        vk, MODEL_RGBSDA, tuple(samples), twin,
    )


def _compressed(vk, name, bw, bh, nbytes, model, channels, suffix, twin=None):
    """A block format (createDFDCompressed): one sample per 64 or 128 bits of the block."""
    bits = 64 if len(channels) == 2 or nbytes == 8 else 128
    if suffix == "SNORM":
        quals, lower, upper = Q_SIGNED, 0x80000000, 0x7FFFFFFF
    elif suffix in ("SFLOAT", "UFLOAT"):
        # float blocks (BC6H): FLOAT (and SIGNED), bounds -1.0 or 0.0 to 1.0 as float32 bits (createDFDCompressed)
        signed = suffix == "SFLOAT"
        quals = Q_FLOAT | (Q_SIGNED if signed else 0)
        lower, upper = (_F32_MINUS_ONE if signed else 0), _F32_ONE
    else:
        quals, lower, upper = 0, 0, 0xFFFFFFFF
    samples = []
    for i, ch in enumerate(channels):
        q = quals
        if suffix == "SRGB" and ch == CHANNEL_ALPHA:
            q |= Q_LINEAR
        # a second sample of an 8-byte block (ETC2 punch-through: colour, then
        # alpha) covers the same 64 bits
        samples.append(Sample(i * bits % (8 * nbytes), bits, ch, q, lower, upper))
    return FormatInfo(
        f"{name}_{suffix}_BLOCK", bw, bh, nbytes, 1, suffix == "SRGB",
        vk, model, tuple(samples), twin,
    )


def _build_formats():
    """Container facts for every vkFormat of the format table and its twins."""
    out = {}
    for f in _formats.FORMATS.values():
        if f.stored_as or f.dfd_model == _formats.MODEL_ETC1S:
            continue  # written with the vkFormat of the format it is stored as; ETC1S: vkFormat 0, by its DFD
        variants = [(f.vk_unorm, f.linear_suffix, f.vk_srgb or None)]
        if f.vk_srgb:
            variants.append((f.vk_srgb, "SRGB", f.vk_unorm))
        if f.vk_snorm:
            variants.append((f.vk_snorm, "SNORM", None))
        for vk, suffix, twin in variants:
            if f.is_block_compressed:
                info = _compressed(vk, f.vk_name, f.block_w, f.block_h, f.bytes_per_block, f.dfd_model,
                                   f.dfd_channels, suffix, twin)
            else:
                info = _unpacked(vk, f.vk_name, f.channels, f.bytes_per_block // f.channels, suffix, twin)
            out[vk] = info
    return out


FORMATS: dict[int, FormatInfo] = _build_formats()
FORMATS_BY_NAME: dict[str, FormatInfo] = {f.name: f for f in FORMATS.values()}


def _etc1s_info(alpha: bool, srgb: bool) -> FormatInfo:
    """ETC1S (vkFormat 0): one 64-bit sample per slice, ETC1S_RGB (0) then ETC1S_AAA (15)."""
    channels = (0, CHANNEL_ALPHA) if alpha else (0,)
    samples = tuple(Sample(64 * i, 64, ch, 0, 0, 0xFFFFFFFF) for i, ch in enumerate(channels))
    return FormatInfo("ETC1S_RGBA" if alpha else "ETC1S_RGB", 4, 4, 8 * len(channels), 1, srgb, 0, MODEL_ETC1S,
                      samples)


# (alpha, srgb) -> the ETC1S format: told apart by the DFD's samples and transfer function
ETC1S_FORMATS: dict[tuple, FormatInfo] = {(a, s): _etc1s_info(a, s) for a in (False, True) for s in (False, True)}


def etc1s_format(name: str, srgb: bool) -> FormatInfo:
    """The KTX2 format of texcook's `etc1s` or `etc1s-rgba`."""
    return ETC1S_FORMATS[(_formats.get(name).channels == 4, bool(srgb))]


def _align(n: int, a: int) -> int:
    return -(-n // a) * a


# --------------------------------------------------------------------------- DFD


def dfd_bytes(fmt: FormatInfo, transfer: int | None = None) -> bytes:
    """The DFD (total size word plus one Basic block) for a format."""
    if transfer is None:
        transfer = TRANSFER_SRGB if fmt.srgb else TRANSFER_LINEAR
    block_size = 24 + 16 * len(fmt.samples)
    words = [
        4 + block_size,
        0,  # vendorId 0 (Khronos), descriptorType 0 (Basic)
        2 | (block_size << 16),  # versionNumber 2 = KDF 1.3
        fmt.color_model | (PRIMARIES_BT709 << 8) | (transfer << 16),  # flags 0: straight alpha
        (fmt.block_w - 1) | ((fmt.block_h - 1) << 8),
        sum(b << (8 * k) for k, b in enumerate(fmt.planes[:4])),
        sum(b << (8 * k) for k, b in enumerate(fmt.planes[4:])),
    ]
    for s in fmt.samples:
        words += [
            s.bit_offset | ((s.bit_length - 1) << 16) | (s.channel << 24) | (s.qualifiers << 28),
            0,  # sample position 0,0,0,0
            s.lower,
            s.upper,
        ]
    return struct.pack(f"<{len(words)}I", *words)


def parse_dfd(dfd: bytes) -> dict:
    """Decode the first Basic block of a DFD into a dict (no validation beyond sizes)."""
    (total,) = struct.unpack_from("<I", dfd, 0)
    w1, w2, w3, w4, w5, w6 = struct.unpack_from("<6I", dfd, 4)
    block_size = w2 >> 16
    # Only whole samples inside both the block and the buffer are decoded.
    nsamples = max(0, min(block_size - 24, len(dfd) - 28) // 16)
    samples = []
    for i in range(nsamples):
        a, pos, lower, upper = struct.unpack_from("<4I", dfd, 28 + 16 * i)
        samples.append({
            "bit_offset": a & 0xFFFF,
            "bit_length": ((a >> 16) & 0xFF) + 1,
            "channel": (a >> 24) & 0xF,
            "qualifiers": a >> 28,
            "position": [(pos >> (8 * k)) & 0xFF for k in range(4)],
            "lower": lower,
            "upper": upper,
        })
    return {
        "total_size": total,
        "vendor_id": w1 & 0x1FFFF,
        "descriptor_type": w1 >> 17,
        "version": w2 & 0xFFFF,
        "block_size": block_size,
        "color_model": w3 & 0xFF,
        "primaries": (w3 >> 8) & 0xFF,
        "transfer": (w3 >> 16) & 0xFF,
        "flags": w3 >> 24,
        "texel_block_dimension": [((w4 >> (8 * k)) & 0xFF) + 1 for k in range(4)],
        "bytes_plane": [(w5 >> (8 * k)) & 0xFF for k in range(4)] + [(w6 >> (8 * k)) & 0xFF for k in range(4)],
        "samples": samples,
    }


# --------------------------------------------------------------------------- KVD


def _check_key(key: str) -> bytes:
    if not isinstance(key, str) or not key:
        raise UsageError(f"KTX2 key {key!r} must be a non-empty string")
    if "\0" in key or key.startswith("\ufeff"):
        raise UsageError(f"KTX2 key {key!r} must not contain NUL or start with a byte-order mark")
    if key[:3] in ("KTX", "ktx") and key not in KNOWN_KTX_KEYS:
        raise UsageError(f"KTX2 key {key!r} uses the reserved KTX/ktx prefix")
    return key.encode("utf-8")


def kvd_bytes(kv: dict) -> bytes:
    """Key/value data: entries sorted by key, each padded to 4 bytes."""
    entries = []
    for key, value in kv.items():
        kb = _check_key(key)
        if isinstance(value, str):
            vb = value.encode("utf-8") + b"\0"
        elif isinstance(value, (bytes, bytearray, memoryview)):
            vb = bytes(value)
        else:
            raise UsageError(f"KTX2 value for {key!r} must be str or bytes, not {type(value).__name__}")
        if key in _TEXT_KEYS and not vb.endswith(b"\0"):
            raise UsageError(f"KTX2 value for {key} must be NUL-terminated text")
        if key == "KTXorientation" and vb[:-1] not in _ORIENTATIONS_2D:
            raise UsageError(f"KTXorientation {vb[:-1]!r} is not one of rd, ru, ld, lu")
        entries.append((kb, vb))
    # UTF-8 byte order is code point order, which the specification asks for.
    entries.sort(key=lambda e: e[0])
    out = bytearray()
    for kb, vb in entries:
        body = kb + b"\0" + vb
        out += struct.pack("<I", len(body)) + body
        out += b"\0" * (_align(len(out), 4) - len(out))
    return bytes(out)


# --------------------------------------------------------------------------- writer


def _zstd_compressor(level):
    import zstandard

    # A checksum per level lets readers detect corrupted payloads, which raw blocks cannot.
    return zstandard.ZstdCompressor(level=level, write_content_size=True, write_checksum=True)


def write_ktx2(vk_format, width: int, height: int, levels: list, *,
               kv: dict | None = None, zstd_level: int | None = None) -> bytes:
    """Serialise a 2D texture. `levels[0]` is the base level; each item holds the exact
    bytes of that level as the codec produced them. `vk_format` is a vkFormat, or
    a FormatInfo (an ETC1S one of ETC1S_FORMATS, which vkFormat 0 cannot name)."""
    fmt = vk_format if isinstance(vk_format, FormatInfo) else FORMATS.get(vk_format)
    if fmt is None:
        raise UsageError(f"vkFormat {vk_format} is not supported by the KTX2 writer"
                         + (" (ETC1S: pass its ktx2.ETC1S_FORMATS entry)" if vk_format == 0 else ""))
    vk_format = fmt.vk_format
    raw = check_levels("KTX2", width, height, levels, fmt.level_size, fmt.name)
    n = len(raw)

    meta = {keys.ORIENTATION.name: "rd", keys.WRITER.name: f"texcook {__version__}"}
    meta.update(kv or {})
    kvd = kvd_bytes(meta)

    sgd = b""
    ulens = [len(d) for d in raw]
    if fmt.etc1s:
        if zstd_level is not None:
            raise UsageError("Zstandard does not combine with ETC1S: its levels are BasisLZ-supercompressed already")
        from . import basislz

        scheme = SUPERCOMPRESSION_BASISLZ
        sgd, stored = basislz.pack(raw, width, height, len(fmt.samples) == 2)
        ulens = [0] * n  # the specification's value for BasisLZ
        align = 1
    elif zstd_level is None:
        scheme = SUPERCOMPRESSION_NONE
        stored = raw
        align = fmt.alignment
    else:
        lo, hi = ZSTD_LEVELS
        if not isinstance(zstd_level, int) or not lo <= zstd_level <= hi:
            raise UsageError(f"zstd level {zstd_level!r} must be an integer in {lo}..{hi}")
        scheme = SUPERCOMPRESSION_ZSTD
        cctx = _zstd_compressor(zstd_level)
        stored = [cctx.compress(d) for d in raw]
        align = 1  # supercompressed levels are packed without padding

    dfd = dfd_bytes(fmt)
    dfd_off = _align(HEADER_SIZE + LEVEL_ENTRY_SIZE * n, 4)
    kvd_off = dfd_off + len(dfd)  # the DFD is a whole number of words
    pos = kvd_off + len(kvd)
    sgd_off = _align(pos, 8) if sgd else 0  # global data starts on the next 8-byte boundary
    if sgd:
        pos = sgd_off + len(sgd)

    # Level data runs smallest first, so a streaming loader sees the small mips early.
    offsets = [0] * n
    for i in reversed(range(n)):
        pos = _align(pos, align)
        offsets[i] = pos
        pos += len(stored[i])
    total = pos

    head = bytearray(sgd_off + len(sgd) if sgd else kvd_off + len(kvd))
    head[0:12] = IDENTIFIER
    struct.pack_into(
        "<13I2Q", head, 12,
        vk_format, fmt.type_size, width, height, 0, 0, 1, n, scheme,
        dfd_off, len(dfd), kvd_off if kvd else 0, len(kvd),
        sgd_off, len(sgd),  # global data: BasisLZ only
    )
    for i in range(n):
        struct.pack_into("<3Q", head, HEADER_SIZE + LEVEL_ENTRY_SIZE * i, offsets[i], len(stored[i]), ulens[i])
    head[dfd_off:dfd_off + len(dfd)] = dfd
    head[kvd_off:kvd_off + len(kvd)] = kvd
    head[sgd_off:sgd_off + len(sgd)] = sgd
    # One join copies the level data once, however large the chain.
    parts = [bytes(head)]
    pos = len(head)
    for i in reversed(range(n)):
        parts.append(bytes(offsets[i] - pos))
        parts.append(stored[i])
        pos = offsets[i] + len(stored[i])
    out = b"".join(parts)
    assert len(out) == total
    return out


# --------------------------------------------------------------------------- reader


@dataclass
class Ktx2File:
    name: str
    vk_format: int
    format: FormatInfo
    width: int
    height: int
    levels: list  # decompressed level bytes, base level first (empty when read with load_levels=False)
    supercompression: int
    kv: dict  # key -> raw value bytes (NUL terminators kept)
    transfer: int
    color_model: int
    primaries: int
    dfd: dict
    level_index: list = field(default_factory=list)  # (byteOffset, byteLength, uncompressedByteLength)
    level_count_field: int = 0  # levelCount as stored (0 = "generate at load")

    @property
    def srgb(self) -> bool:
        return self.transfer == TRANSFER_SRGB

    @property
    def premultiplied(self) -> bool:
        return bool(self.dfd.get("flags", 0) & 1)

    def level_dims(self, level: int) -> tuple[int, int]:
        return level_dims(self.width, self.height, level)

    def text(self, key: str) -> str | None:
        """A key's value as text (NUL terminator stripped), or None when absent."""
        value = self.kv.get(key)
        return None if value is None else _value_text(value)


def _value_text(value: bytes) -> str:
    body = value[:-1] if value.endswith(b"\0") else value
    try:
        text = body.decode("utf-8")
    except UnicodeDecodeError:
        return "0x" + value.hex()
    if "\0" in text:
        return "0x" + value.hex()
    return text


class _Reader:
    """Bounds-checked little-endian access; every failure is a ContainerError."""

    def __init__(self, data: bytes, name: str, size: int | None = None):
        self.data = data  # the file, or (for describing) its first bytes up to the metadata's end
        self.name = name
        self.size = len(data) if size is None else size  # the file's length

    def fail(self, message):
        raise ContainerError(message, path=self.name)

    def need(self, end: int, what: str):
        if end > len(self.data):
            self.fail(f"truncated: {what} ends at byte {end} but file has {self.size}")

    def unpack(self, fmt: str, offset: int, what: str):
        self.need(offset + struct.calcsize(fmt), what)
        return struct.unpack_from(fmt, self.data, offset)


def metadata_end(head: bytes, file_size: int) -> int:
    """How many leading bytes of a KTX2 file hold the header, level index, DFD
    and key/value data, from its first 80 bytes; at most file_size."""
    if len(head) < HEADER_SIZE or head[:12] != IDENTIFIER:
        return min(HEADER_SIZE, file_size)
    level_count, = struct.unpack_from("<I", head, 40)
    dfd_off, dfd_len, kvd_off, kvd_len = struct.unpack_from("<4I", head, 48)
    end = max(HEADER_SIZE + LEVEL_ENTRY_SIZE * max(1, level_count), dfd_off + dfd_len, kvd_off + kvd_len)
    return min(end, file_size)


def read_ktx2(data, name: str = "<bytes>", *, load_levels: bool = True, file_size: int | None = None) -> Ktx2File:
    """Parse and validate a KTX2 file holding a 2D texture; levels come back
    decompressed. With load_levels=False the header, index, DFD and metadata are
    checked but no level is copied or decompressed (what `texcook info` needs);
    then `data` may be just the first metadata_end() bytes of a file of
    `file_size` bytes.
    Before any level is decompressed, the texture's decoded size is checked
    against the memory budget (texcook.fileio)."""
    try:
        data = bytes(data)
    except TypeError:
        raise ContainerError("not a KTX2 file (data is not bytes)", path=name) from None
    try:
        if load_levels and file_size is not None and file_size != len(data):
            raise ValueError("levels can only be loaded from the whole file")
        return _read_ktx2(data, name, load_levels, file_size)
    except MemoryError:
        raise ContainerError("out of memory reading the texture", path=name) from None


def _read_ktx2(data, name, load_levels, file_size=None):
    r = _Reader(data, str(name), file_size)
    if len(data) < 12 or data[:12] != IDENTIFIER:
        r.fail("not a KTX2 file (bad identifier)")
    (vk, type_size, width, height, depth, layers, faces, level_count, scheme,
     dfd_off, dfd_len, kvd_off, kvd_len, sgd_off, sgd_len) = r.unpack("<13I2Q", 12, "header")

    fmt = FORMATS.get(vk) if vk else _etc1s_of(r, dfd_off, dfd_len)
    if fmt is None:
        r.fail(f"unsupported vkFormat {vk}")
    if type_size != fmt.type_size:
        r.fail(f"typeSize {type_size} is wrong for {fmt.name} (expected {fmt.type_size})")
    if width == 0:
        r.fail("pixelWidth is 0")
    if height == 0:
        r.fail("pixelHeight is 0: 1D textures are not supported")
    if depth != 0:
        r.fail(f"pixelDepth {depth}: 3D textures are not supported")
    if layers != 0:
        r.fail(f"layerCount {layers}: array textures are not supported")
    if faces != 1:
        r.fail(f"faceCount {faces}: " + ("cube maps are not supported" if faces == 6 else "must be 1 or 6"))
    if level_count == 0 and fmt.block_compressed:
        r.fail(f"levelCount 0 is not allowed for block-compressed {fmt.name}")
    n = max(1, level_count)
    if n > max_levels(width, height):
        r.fail(f"levelCount {level_count} too large for {width}x{height} (at most {max_levels(width, height)})")
    if scheme == SUPERCOMPRESSION_BASISLZ and not fmt.etc1s:
        r.fail(f"BasisLZ supercompression holds only ETC1S data (vkFormat 0, DFD colour model 163), not {fmt.name}")
    if fmt.etc1s and scheme != SUPERCOMPRESSION_BASISLZ:
        r.fail(f"ETC1S data must be BasisLZ-supercompressed (supercompressionScheme 1), not scheme {scheme}")
    if scheme not in SUPERCOMPRESSION_NAMES:
        r.fail(f"unknown supercompressionScheme {scheme}")

    # Index of the metadata blocks: DFD right after the level index, KVD right after the DFD.
    index_end = HEADER_SIZE + LEVEL_ENTRY_SIZE * n
    r.need(index_end, "level index")
    if dfd_off != _align(index_end, 4):
        r.fail(f"dfdByteOffset {dfd_off} must be {_align(index_end, 4)} (right after the level index)")
    if dfd_len < 4:
        r.fail(f"dfdByteLength {dfd_len} is too small")
    r.need(dfd_off + dfd_len, "DFD")
    if kvd_len:
        if kvd_off != _align(dfd_off + dfd_len, 4):
            r.fail(f"kvdByteOffset {kvd_off} must be {_align(dfd_off + dfd_len, 4)} (right after the DFD)")
        r.need(kvd_off + kvd_len, "key/value data")
        meta_end = kvd_off + kvd_len
    else:
        if kvd_off:
            r.fail(f"kvdByteOffset {kvd_off} must be 0 when kvdByteLength is 0")
        meta_end = dfd_off + dfd_len
    if scheme == SUPERCOMPRESSION_BASISLZ:
        if sgd_len == 0:
            r.fail("sgdByteLength is 0 but BasisLZ needs its supercompression global data")
        if sgd_off != _align(meta_end, 8):
            r.fail(f"sgdByteOffset {sgd_off} must be {_align(meta_end, 8)} (the next 8-byte boundary after the "
                   "key/value data)")
        if sgd_off + sgd_len > r.size:
            r.fail(f"truncated: supercompression global data ends at byte {sgd_off + sgd_len} but file has {r.size}")
        meta_end = sgd_off + sgd_len
    elif sgd_len or sgd_off:
        r.fail(f"supercompression global data ({sgd_len} bytes at {sgd_off}) is not used by scheme {scheme}")

    dfd = _check_dfd(r, data[dfd_off:dfd_off + dfd_len], fmt, scheme)
    kv = _parse_kvd(r, data[kvd_off:kvd_off + kvd_len]) if kvd_len else {}
    index = [r.unpack("<3Q", HEADER_SIZE + LEVEL_ENTRY_SIZE * i, "level index") for i in range(n)]
    sgd = data[sgd_off:sgd_off + sgd_len] if load_levels and scheme == SUPERCOMPRESSION_BASISLZ else b""
    levels = _read_levels(r, index, fmt, width, height, scheme, meta_end, load_levels, sgd)

    return Ktx2File(
        name=str(name), vk_format=vk, format=fmt, width=width, height=height, levels=levels,
        supercompression=scheme, kv=kv, transfer=dfd["transfer"], color_model=dfd["color_model"],
        primaries=dfd["primaries"], dfd=dfd, level_index=[tuple(e) for e in index],
        level_count_field=level_count,
    )


def _etc1s_of(r: _Reader, dfd_off: int, dfd_len: int) -> FormatInfo:
    """vkFormat 0: the ETC1S format the DFD names (by its sample count and transfer)."""
    if dfd_len < 4 + 24 or dfd_off + 4 + 24 > len(r.data):
        r.fail("vkFormat 0 (VK_FORMAT_UNDEFINED) with no DFD to say what the data is")
    w2, w3 = struct.unpack_from("<2I", r.data, dfd_off + 8)
    model = w3 & 0xFF
    if model != MODEL_ETC1S:
        r.fail(f"unsupported vkFormat 0 with DFD colour model {MODEL_NAMES.get(model, model)} "
               "(texcook reads ETC1S, model 163)")
    block_size = w2 >> 16
    nsamples = (block_size - 24) // 16 if block_size >= 24 else 0
    if nsamples not in (1, 2):
        r.fail(f"bad DFD: ETC1S with {nsamples} samples (1: RGB; 2: RGB and alpha)")
    return ETC1S_FORMATS[(nsamples == 2, (w3 >> 16) & 0xFF == TRANSFER_SRGB)]


def _check_dfd(r: _Reader, dfd: bytes, fmt: FormatInfo, scheme: int) -> dict:
    (total,) = struct.unpack_from("<I", dfd, 0)
    if total != len(dfd):
        r.fail(f"bad DFD: dfdTotalSize {total} does not match dfdByteLength {len(dfd)}")
    if len(dfd) < 4 + 24:
        r.fail(f"bad DFD: {len(dfd)} bytes is too small for a Basic descriptor block")
    d = parse_dfd(dfd[: 4 + 24])  # header words first; samples checked below
    if d["vendor_id"] != 0 or d["descriptor_type"] != 0:
        r.fail(f"bad DFD: first block is vendor {d['vendor_id']} type {d['descriptor_type']}, not a Basic block")
    if d["version"] != 2:
        r.fail(f"bad DFD: versionNumber {d['version']} (expected 2)")
    size = d["block_size"]
    if size < 24 or (size - 24) % 16:
        r.fail(f"bad DFD: descriptorBlockSize {size} is not 24 + 16 * samples")
    if 4 + size > len(dfd):
        r.fail(f"bad DFD: descriptorBlockSize {size} overruns the {len(dfd)}-byte DFD")
    d = parse_dfd(dfd[: 4 + size])
    d["total_size"] = total
    if d["color_model"] != fmt.color_model:
        r.fail(f"bad DFD: colorModel {d['color_model']} does not match {fmt.name} "
               f"(expected {fmt.color_model})")
    if d["primaries"] > 11:  # KHR_DF_PRIMARIES_ADOBERGB is the last defined value
        r.fail(f"bad DFD: colorPrimaries {d['primaries']} is not a defined value")
    transfer = d["transfer"]
    if transfer not in (TRANSFER_LINEAR, TRANSFER_SRGB):
        r.fail(f"bad DFD: transferFunction {transfer} is not supported (linear 1 or sRGB 2)")
    if fmt.srgb and transfer != TRANSFER_SRGB:
        r.fail(f"bad DFD: transferFunction {transfer} but {fmt.name} needs sRGB (2)")
    if not fmt.srgb and fmt.twin is not None and transfer == TRANSFER_SRGB:
        r.fail(f"bad DFD: transferFunction sRGB on {fmt.name}, which has an _SRGB twin")
    if d["flags"] & ~1:
        r.fail(f"bad DFD: unknown flags 0x{d['flags']:02x}")
    dims = d["texel_block_dimension"]
    if dims != [fmt.block_w, fmt.block_h, 1, 1]:
        r.fail(f"bad DFD: texel block {dims[0]}x{dims[1]}x{dims[2]}x{dims[3]} does not match "
               f"{fmt.name} ({fmt.block_w}x{fmt.block_h}x1x1)")
    planes = d["bytes_plane"]
    # Writers before specification 2.0.4 left the bytesPlanes at 0 for supercompressed files.
    if planes != fmt.planes and not (scheme != SUPERCOMPRESSION_NONE and not any(planes)):
        r.fail(f"bad DFD: bytesPlane {planes} does not match {fmt.name} (expected {fmt.planes})")
    samples = d["samples"]
    if len(samples) != len(fmt.samples):
        r.fail(f"bad DFD: {len(samples)} samples but {fmt.name} has {len(fmt.samples)}")
    for i, (got, want) in enumerate(zip(samples, fmt.samples)):
        quals = got["qualifiers"]
        # With a non-linear transfer, alpha must be flagged LINEAR; with a linear one the flag is moot.
        alpha = got["channel"] == CHANNEL_ALPHA and fmt.color_model in (MODEL_RGBSDA, MODEL_BC3)
        if transfer == TRANSFER_SRGB and alpha and not quals & Q_LINEAR:
            r.fail(f"bad DFD: sample {i} (alpha) lacks the LINEAR qualifier in an sRGB format")
        if (got["bit_offset"], got["bit_length"], got["channel"], quals & ~Q_LINEAR) != (
                want.bit_offset, want.bit_length, want.channel, want.qualifiers & ~Q_LINEAR):
            r.fail(f"bad DFD: sample {i} is channel {got['channel']} bits {got['bit_offset']}+{got['bit_length']} "
                   f"qualifiers {quals:#x}, expected channel {want.channel} bits {want.bit_offset}+"
                   f"{want.bit_length} qualifiers {want.qualifiers:#x} for {fmt.name}")
        if any(got["position"]):
            r.fail(f"bad DFD: sample {i} has a non-zero sample position")
        if (got["lower"], got["upper"]) != (want.lower, want.upper):
            r.fail(f"bad DFD: sample {i} range {got['lower']:#x}..{got['upper']:#x}, expected "
                   f"{want.lower:#x}..{want.upper:#x} for {fmt.name}")
    return d


def _parse_kvd(r: _Reader, kvd: bytes) -> dict:
    out = {}
    pos = 0
    prev = None
    while pos < len(kvd):
        if pos + 4 > len(kvd):
            r.fail(f"bad key/value data: {len(kvd) - pos} stray bytes at the end")
        (length,) = struct.unpack_from("<I", kvd, pos)
        start = pos + 4
        end = start + length
        if length < 2:
            r.fail(f"bad key/value data: entry at byte {pos} has keyAndValueByteLength {length}")
        if end > len(kvd):
            r.fail(f"bad key/value data: entry at byte {pos} ({length} bytes) overruns kvdByteLength {len(kvd)}")
        body = kvd[start:end]
        nul = body.find(b"\0")
        if nul < 0:
            r.fail(f"bad key/value data: key at byte {pos} is not NUL-terminated")
        if nul == 0:
            r.fail(f"bad key/value data: empty key at byte {pos}")
        kb = body[:nul]
        try:
            key = kb.decode("utf-8")
        except UnicodeDecodeError:
            r.fail(f"bad key/value data: key at byte {pos} is not UTF-8")
        if key.startswith("\ufeff"):
            r.fail(f"bad key/value data: key {key[1:]!r} starts with a byte-order mark")
        if prev is not None and kb <= prev:
            r.fail(f"bad key/value data: key {key!r} " + ("repeats" if kb == prev else "is out of order"))
        prev = kb
        out[key] = body[nul + 1:]
        pad_end = _align(end, 4)
        if pad_end > len(kvd):
            r.fail(f"bad key/value data: padding after {key!r} overruns kvdByteLength {len(kvd)}")
        if any(kvd[end:pad_end]):
            r.fail(f"bad key/value data: non-zero padding after {key!r}")
        pos = pad_end
    return out


def _read_levels(r: _Reader, index, fmt: FormatInfo, width: int, height: int, scheme: int, meta_end: int,
                 load: bool = True, sgd: bytes = b""):
    n = len(index)
    align = fmt.alignment if scheme == SUPERCOMPRESSION_NONE else 1
    prev_end = None
    stored = []
    for i in reversed(range(n)):  # smallest level first, as laid out in the file
        off, length, ulen = index[i]
        w, h = level_dims(width, height, i)
        want = fmt.level_size(w, h)
        if scheme == SUPERCOMPRESSION_BASISLZ:
            if ulen != 0:
                r.fail(f"level {i} uncompressedByteLength {ulen} must be 0 with BasisLZ")
        elif ulen != want:
            r.fail(f"level {i} uncompressedByteLength {ulen}, expected {want} for {w}x{h} {fmt.name}")
        if scheme == SUPERCOMPRESSION_NONE and length != want:
            r.fail(f"level {i} byteLength {length}, expected {want} for {w}x{h} {fmt.name}")
        if length == 0:
            r.fail(f"level {i} byteLength is 0")
        if off % align:
            r.fail(f"level {i} byteOffset {off} is not aligned to {align} bytes")
        if off < meta_end:
            r.fail(f"level {i} byteOffset {off} overlaps the header and metadata (which end at {meta_end})")
        if prev_end is not None and off < prev_end:
            r.fail(f"level {i} at byte {off} comes before or overlaps level {i + 1}: "
                   "levels must be stored smallest first")
        if off + length > r.size:
            r.fail(f"truncated: level {i} ends at byte {off + length} but file has {r.size}")
        prev_end = off + length
        stored.append((off, length))
    if not load:
        return []
    # the index is sound: before copying or decompressing, the decoded size against the budget
    decoded = sum(texel_bytes(*level_dims(width, height, i)) for i in range(n))
    check_memory(decoded, f"decoding this {width}x{height} {fmt.name} texture ({n} level(s))", r.name,
                 error=ContainerError)
    stored = [r.data[off:off + length] for off, length in reversed(stored)]
    if scheme == SUPERCOMPRESSION_NONE:
        return stored
    if scheme == SUPERCOMPRESSION_BASISLZ:
        from . import basislz

        return basislz.unpack(sgd, stored, width, height, len(fmt.samples) == 2, r.name)
    return [_inflate(r, i, scheme, blob, index[i][2]) for i, blob in enumerate(stored)]


def _inflate(r: _Reader, level: int, scheme: int, blob: bytes, size: int) -> bytes:
    """Decompress one level into exactly `size` bytes: the output buffer is never
    larger than the level index declares, whatever the stream or its frame
    header claims, and a stream that would produce more is refused."""
    what = SUPERCOMPRESSION_NAMES[scheme]
    try:
        if scheme == SUPERCOMPRESSION_ZSTD:
            out = _unzstd(r, level, blob, size)
        else:
            out = _unzlib(r, level, blob, size)
    except ContainerError:
        raise
    except MemoryError:
        r.fail(f"level {level}: out of memory decompressing {size} bytes of {what} data")
    except Exception as exc:  # zstd and zlib raise their own error types
        detail = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        r.fail(f"level {level}: corrupt {what} data ({detail})")
    if len(out) != size:
        r.fail(f"level {level}: {what} data expands to {len(out)} bytes, expected {size}")
    return out


def _unzstd(r, level, blob, size):
    import zstandard

    try:
        params = zstandard.get_frame_parameters(blob)
    except zstandard.ZstdError as exc:
        r.fail(f"level {level}: corrupt zstd data ({exc})")
    declared = params.content_size
    if declared != zstandard.CONTENTSIZE_UNKNOWN and declared != size:
        # a frame that names its size is decompressed into a buffer of that size
        r.fail(f"level {level}: zstd data expands to {declared} bytes, expected {size} (by its frame header)")
    # one frame, nothing after it, never more than `size` bytes of output
    try:
        return zstandard.ZstdDecompressor().decompress(blob, max_output_size=size, read_across_frames=False,
                                                      allow_extra_data=False)
    except zstandard.ZstdError as exc:
        extra = re.search(r"contains (\d+) bytes of unused data", str(exc))
        if extra:
            r.fail(f"level {level}: {extra.group(1)} bytes after the end of the zstd data")
        raise


def _unzlib(r, level, blob, size):
    dobj = zlib.decompressobj()
    out = dobj.decompress(blob, size + 1)  # one byte past the size shows an overrun
    if len(out) > size:
        r.fail(f"level {level}: zlib data expands to more than the expected {size} bytes")
    if not dobj.eof:
        r.fail(f"level {level}: zlib data is truncated")
    if dobj.unused_data:
        r.fail(f"level {level}: {len(dobj.unused_data)} bytes after the end of the zlib data")
    return out


# --------------------------------------------------------------------------- summary


def describe(ktx: Ktx2File) -> dict:
    """A JSON-able summary of a file, for `texcook info`; the levels need not be
    loaded (sizes come from the level index)."""
    per_level = []
    for i, (_off, stored, uncompressed) in enumerate(ktx.level_index):
        w, h = ktx.level_dims(i)
        per_level.append({"level": i, "width": w, "height": h, "bytes": stored, "uncompressed_bytes": uncompressed})
    return {
        "file": ktx.name,
        "container": "ktx2",
        "format": ktx.format.name,
        "vkFormat": ktx.vk_format,
        "width": ktx.width,
        "height": ktx.height,
        "levels": len(ktx.level_index),
        "block": [ktx.format.block_w, ktx.format.block_h],
        "color_model": MODEL_NAMES.get(ktx.color_model, str(ktx.color_model)),
        "mips": per_level,
        "colour_space": "srgb" if ktx.srgb else "linear",
        "transfer": ktx.transfer,
        "primaries": ktx.primaries,
        "premultiplied_alpha": ktx.premultiplied,
        "supercompression": SUPERCOMPRESSION_NAMES.get(ktx.supercompression, str(ktx.supercompression)),
        "key_values": {k: _value_text(v) for k, v in ktx.kv.items()},
    }


# --------------------------------------------------------------------------- the container table's interface


def write_texture(texture, output) -> bytes:
    """The KTX2 file of a texture (container.table.Stored), with the output's zstd level."""
    fmt = _formats.get(texture.format)
    vk = etc1s_format(fmt.name, texture.srgb) if fmt.dfd_model == MODEL_ETC1S else fmt.vk_format(texture.srgb)
    return write_ktx2(vk, texture.width, texture.height, texture.levels, kv=texture.kv, zstd_level=output.zstd)


def read_texture(data, path=None):
    """A KTX2 file as a container.table.Stored: levels decompressed, key/values as text."""
    ktx = read_ktx2(data, path)
    if ktx.format.etc1s:  # vkFormat 0: the DFD names it
        name, srgb = ("etc1s-rgba" if len(ktx.format.samples) == 2 else "etc1s"), ktx.srgb
    else:
        fmt, kind = _formats.by_vk_format(ktx.vk_format)
        name, srgb = (fmt.name if fmt is not None and kind != "snorm" else None), kind == "srgb"
    return Stored(name, srgb, ktx.width, ktx.height, ktx.levels, {k: ktx.text(k) for k in ktx.kv},
                  f"vkFormat {ktx.vk_format}")


def describe_head(head, file_size, path) -> dict:
    """`texcook info`: the summary from the header and metadata alone."""
    from ..fileio import read_prefix

    need = metadata_end(head, file_size)
    data = head[:need] if need <= len(head) else read_prefix(path, need, "texture")[0]
    return describe(read_ktx2(data, path, load_levels=False, file_size=file_size))
