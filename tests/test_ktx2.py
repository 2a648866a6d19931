"""KTX2 container: golden bytes, layout rules, the reader's validation, fuzzing, and an
independent cross-check of every supported format with npm's ktx-parse."""

import base64
import json
import struct
import subprocess

import numpy as np
import pytest
import zstandard

from texcook.container.ktx2 import (
    FORMATS,
    FORMATS_BY_NAME,
    describe,
    level_dims,
    max_levels,
    read_ktx2,
    write_ktx2,
)
from texcook.errors import ContainerError, UsageError

from conftest import JS_DIR
from reference import ktx2_layout

SIZES = [(1, 1), (3, 5), (127, 128)]


@pytest.fixture
def rng():
    return np.random.default_rng(20240611)


def random_levels(rng, vk, width, height, count):
    fmt = FORMATS[vk]
    return [
        rng.integers(0, 256, fmt.level_size(*level_dims(width, height, i)), dtype=np.uint8).tobytes()
        for i in range(count)
    ]


# ----------------------------------------------------------------------------- golden bytes


def test_golden_rgba8_srgb_1x1():
    """Every byte of a 1x1 R8G8B8A8_SRGB file, worked out by hand from the KTX 2.0 and
    Khronos Data Format specifications (see the comments)."""
    data = write_ktx2(43, 1, 1, [b"\x10\x20\x30\x40"], kv={"KTXwriter": "texcook test"})
    expected = bytes.fromhex(
        "ab4b5458203230bb0d0a1a0a"  # identifier «KTX 20»\r\n\x1a\n
        "2b000000"  # vkFormat 43 = R8G8B8A8_SRGB
        "01000000"  # typeSize 1
        "01000000" "01000000"  # pixelWidth 1, pixelHeight 1
        "00000000" "00000000"  # pixelDepth 0, layerCount 0
        "01000000" "01000000"  # faceCount 1, levelCount 1
        "00000000"  # supercompressionScheme 0
        "68000000" "5c000000"  # dfdByteOffset 104 = 80 + 24, dfdByteLength 92 (4 samples)
        "c4000000" "34000000"  # kvdByteOffset 196 = 104 + 92, kvdByteLength 52 = 24 + 28
        "0000000000000000" "0000000000000000"  # no supercompression global data
        "f800000000000000"  # level 0 byteOffset 248 = 196 + 52 (4-aligned already)
        "0400000000000000" "0400000000000000"  # byteLength 4, uncompressedByteLength 4
        # DFD
        "5c000000"  # dfdTotalSize 92
        "00000000"  # vendorId 0, descriptorType 0
        "02005800"  # versionNumber 2, descriptorBlockSize 88 = 24 + 4 * 16
        "01010200"  # colorModel RGBSDA 1, primaries BT709 1, transfer sRGB 2, flags 0
        "00000000"  # texel block 1x1x1x1 (stored minus one)
        "04000000" "00000000"  # bytesPlane0 4, the other planes 0
        "00000700" "00000000" "00000000" "ff000000"  # R: offset 0, length 8, channel 0, 0..255
        "08000701" "00000000" "00000000" "ff000000"  # G: offset 8, channel 1
        "10000702" "00000000" "00000000" "ff000000"  # B: offset 16, channel 2
        "1800071f" "00000000" "00000000" "ff000000"  # A: offset 24, channel 15 | LINEAR (0x10)
        # key/value data, sorted by key
        "12000000" "4b54586f7269656e746174696f6e00" "726400" "0000"  # 18: KTXorientation\0 rd\0, 2 pad
        "17000000" "4b5458777269746572" "00" "746578636f6f6b207465737400" "00"  # 23: KTXwriter\0 texcook test\0, 1 pad
        "10203040"  # the level's texels
    )
    assert len(expected) == 252
    assert data == expected
    ktx = read_ktx2(data)
    assert ktx.levels == [b"\x10\x20\x30\x40"] and ktx.srgb and ktx.text("KTXwriter") == "texcook test"


def test_default_metadata_and_kv_values():
    data = write_ktx2(9, 4, 4, [bytes(16)], kv={"b-custom": b"\x00\x01", "a-note": "héllo"})
    ktx = read_ktx2(data)
    assert ktx.kv["KTXorientation"] == b"rd\0"
    assert ktx.kv["KTXwriter"].startswith(b"texcook ") and ktx.kv["KTXwriter"].endswith(b"\0")
    assert ktx.kv["a-note"] == "héllo".encode() + b"\0"
    assert ktx.kv["b-custom"] == b"\x00\x01"  # bytes are stored verbatim
    assert list(ktx.kv) == sorted(ktx.kv, key=lambda k: k.encode())
    info = describe(ktx)
    assert info["key_values"]["a-note"] == "héllo"
    assert info["key_values"]["KTXorientation"] == "rd"
    assert (info["format"], info["vkFormat"], info["colour_space"], info["transfer"]) == ("R8_UNORM", 9, "linear", 1)
    assert info["mips"] == [{"level": 0, "width": 4, "height": 4, "bytes": 16, "uncompressed_bytes": 16}]
    assert (info["supercompression"], info["color_model"], info["levels"]) == ("none", "RGBSDA", 1)
    json.dumps(info)  # JSON-able


# ----------------------------------------------------------------------------- format table


def test_format_table_against_spec_notes():
    """vkFormat numbers, block sizes and DFD shapes from the Vulkan and KDF specifications."""
    expect = {
        9: ("R8_UNORM", 1, 1, 1, 1), 15: ("R8_SRGB", 1, 1, 1, 1),
        16: ("R8G8_UNORM", 1, 1, 2, 1), 22: ("R8G8_SRGB", 1, 1, 2, 1),
        37: ("R8G8B8A8_UNORM", 1, 1, 4, 1), 43: ("R8G8B8A8_SRGB", 1, 1, 4, 1),
        97: ("R16G16B16A16_SFLOAT", 1, 1, 8, 2),
        98: ("R32_UINT", 1, 1, 4, 4), 100: ("R32_SFLOAT", 1, 1, 4, 4),
        101: ("R32G32_UINT", 1, 1, 8, 4), 103: ("R32G32_SFLOAT", 1, 1, 8, 4),
        104: ("R32G32B32_UINT", 1, 1, 12, 4), 106: ("R32G32B32_SFLOAT", 1, 1, 12, 4),
        107: ("R32G32B32A32_UINT", 1, 1, 16, 4), 109: ("R32G32B32A32_SFLOAT", 1, 1, 16, 4),
        131: ("BC1_RGB_UNORM_BLOCK", 4, 4, 8, 1), 132: ("BC1_RGB_SRGB_BLOCK", 4, 4, 8, 1),
        133: ("BC1_RGBA_UNORM_BLOCK", 4, 4, 8, 1), 134: ("BC1_RGBA_SRGB_BLOCK", 4, 4, 8, 1),
        137: ("BC3_UNORM_BLOCK", 4, 4, 16, 1), 138: ("BC3_SRGB_BLOCK", 4, 4, 16, 1),
        139: ("BC4_UNORM_BLOCK", 4, 4, 8, 1), 140: ("BC4_SNORM_BLOCK", 4, 4, 8, 1),
        141: ("BC5_UNORM_BLOCK", 4, 4, 16, 1), 142: ("BC5_SNORM_BLOCK", 4, 4, 16, 1),
        147: ("ETC2_R8G8B8_UNORM_BLOCK", 4, 4, 8, 1), 148: ("ETC2_R8G8B8_SRGB_BLOCK", 4, 4, 8, 1),
        157: ("ASTC_4x4_UNORM_BLOCK", 4, 4, 16, 1), 162: ("ASTC_5x5_SRGB_BLOCK", 5, 5, 16, 1),
        171: ("ASTC_8x8_UNORM_BLOCK", 8, 8, 16, 1), 178: ("ASTC_10x8_SRGB_BLOCK", 10, 8, 16, 1),
        184: ("ASTC_12x12_SRGB_BLOCK", 12, 12, 16, 1),
    }
    for vk, (name, bw, bh, nbytes, type_size) in expect.items():
        f = FORMATS[vk]
        assert (f.name, f.block_w, f.block_h, f.bytes_per_block, f.type_size) == (name, bw, bh, nbytes, type_size)
        assert f.srgb == ("SRGB" in name)
    assert sorted(v for v in FORMATS if v >= 157) == list(range(157, 185))
    assert FORMATS[43].alignment == 4 and FORMATS[97].alignment == 8 and FORMATS[104].alignment == 12
    assert FORMATS[131].alignment == 8 and FORMATS[137].alignment == 16
    # Sample layout details that validators compare field by field.
    bc3 = FORMATS[138].samples
    assert [(s.bit_offset, s.bit_length, s.channel, s.qualifiers) for s in bc3] == [(0, 64, 15, 1), (64, 64, 0, 0)]
    assert [s.channel for s in FORMATS[134].samples] == [1]  # BC1 alpha-present: no LINEAR flag
    assert [(s.channel, s.qualifiers) for s in FORMATS[148].samples] == [(2, 0)]
    bc4s = FORMATS[140].samples[0]
    assert (bc4s.qualifiers, bc4s.lower, bc4s.upper) == (4, 0x80000000, 0x7FFFFFFF)
    half = FORMATS[97].samples
    assert [(s.bit_offset, s.bit_length, s.channel, s.qualifiers) for s in half] == [
        (0, 16, 0, 12), (16, 16, 1, 12), (32, 16, 2, 12), (48, 16, 15, 12)]
    assert (half[0].lower, half[0].upper) == (0xBF800000, 0x3F800000)
    u32 = FORMATS[104].samples
    assert [(s.bit_offset, s.channel, s.qualifiers, s.lower, s.upper) for s in u32] == [
        (0, 0, 0, 0, 1), (32, 1, 0, 0, 1), (64, 2, 0, 0, 1)]
    astc = FORMATS[180].samples  # 10x10 sRGB: one 128-bit data sample, no LINEAR
    assert [(s.bit_offset, s.bit_length, s.channel, s.qualifiers) for s in astc] == [(0, 128, 0, 0)]


# ----------------------------------------------------------------------------- layout rules


@pytest.mark.parametrize("vk", [9, 22, 43, 97, 104, 109, 131, 138, 142, 147, 157, 179])
@pytest.mark.parametrize("zstd_level", [None, 5])
def test_layout_matches_validator_rules(rng, vk, zstd_level):
    w, h = 37, 23
    n = max_levels(w, h)
    levels = random_levels(rng, vk, w, h, n)
    data = write_ktx2(vk, w, h, levels, zstd_level=zstd_level)
    hdr = struct.unpack_from("<13I2Q", data, 12)
    assert hdr[:9] == (vk, FORMATS[vk].type_size, w, h, 0, 0, 1, n, 0 if zstd_level is None else 2)
    index = [struct.unpack_from("<3Q", data, 80 + 24 * i) for i in range(n)]
    lengths = [e[1] for e in index]
    dfd_off, dfd_len, kvd_off, offsets = ktx2_layout(len(FORMATS[vk].samples), FORMATS[vk].bytes_per_block, hdr[12],
                                                     zstd_level is not None, lengths)
    assert hdr[9:12] == (dfd_off, dfd_len, kvd_off)
    assert hdr[13:] == (0, 0)
    for i, (off, length, ulen) in enumerate(index):
        assert off == offsets[i], f"level {i}"
        assert ulen == len(levels[i])
        if zstd_level is None:
            assert length == ulen
            assert data[off:off + length] == levels[i]
        else:
            assert zstandard.ZstdDecompressor().decompress(data[off:off + length]) == levels[i]
    # Sizes never grow down the index and data never moves forward: base level last in file.
    assert all(index[i][2] >= index[i + 1][2] and index[i][0] > index[i + 1][0] for i in range(n - 1))
    assert index[0][0] + index[0][1] == len(data)
    # Padding between sections is zero.
    ends = sorted((off, off + length) for off, length, _ in index)
    for (_, e), (s, _) in zip(ends, ends[1:]):
        assert data[e:s] == bytes(s - e)
    assert read_ktx2(data).levels == levels


def test_partial_chain_and_single_level(rng):
    levels = random_levels(rng, 133, 64, 16, 3)
    ktx = read_ktx2(write_ktx2(133, 64, 16, levels))
    assert ktx.levels == levels and [ktx.level_dims(i) for i in range(3)] == [(64, 16), (32, 8), (16, 4)]


# ----------------------------------------------------------------------------- writer errors


def test_writer_rejects_bad_arguments(rng):
    with pytest.raises(UsageError, match="vkFormat 12345"):
        write_ktx2(12345, 4, 4, [bytes(4)])
    with pytest.raises(UsageError, match="expected 8"):
        write_ktx2(131, 4, 4, [bytes(16)])
    with pytest.raises(UsageError, match="mip levels"):
        write_ktx2(37, 4, 4, random_levels(rng, 37, 4, 4, 3) + [bytes(4)])
    with pytest.raises(UsageError, match="size"):
        write_ktx2(37, 0, 4, [b""])
    with pytest.raises(UsageError, match="reserved"):
        write_ktx2(37, 1, 1, [bytes(4)], kv={"KTXmine": "x"})
    with pytest.raises(UsageError, match="non-empty"):
        write_ktx2(37, 1, 1, [bytes(4)], kv={"": "x"})
    with pytest.raises(UsageError, match="NUL-terminated"):
        write_ktx2(37, 1, 1, [bytes(4)], kv={"KTXwriter": b"me"})
    with pytest.raises(UsageError, match="KTXorientation"):
        write_ktx2(37, 1, 1, [bytes(4)], kv={"KTXorientation": "up"})
    with pytest.raises(UsageError, match="zstd level"):
        write_ktx2(37, 1, 1, [bytes(4)], zstd_level=99)


# ----------------------------------------------------------------------------- reader errors


def _patch(data, offset, fmt, *values):
    out = bytearray(data)
    struct.pack_into(fmt, out, offset, *values)
    return bytes(out)


def _error(data, name="bad.ktx2"):
    with pytest.raises(ContainerError) as info:
        read_ktx2(data, name)
    msg = str(info.value)
    assert msg.startswith(name + ": ") and "\n" not in msg
    return msg


def test_reader_messages(rng):
    base = write_ktx2(43, 1, 1, [b"\x10\x20\x30\x40"], kv={"KTXwriter": "texcook test"})
    assert "not a KTX2 file (bad identifier)" in _error(b"PNG\r\n" + base[5:])
    assert "not a KTX2 file" in _error(b"")
    assert _error(base[:-1]).endswith("truncated: level 0 ends at byte 252 but file has 251")
    assert "truncated: header" in _error(base[:40])
    assert "typeSize 2" in _error(_patch(base, 16, "<I", 2))
    assert "unsupported vkFormat 0" in _error(_patch(base, 12, "<I", 0))
    assert "cube maps" in _error(_patch(base, 36, "<I", 6))
    assert "array" in _error(_patch(base, 32, "<I", 2))
    assert "unknown supercompressionScheme 9" in _error(_patch(base, 44, "<I", 9))
    assert "dfdByteOffset" in _error(_patch(base, 48, "<I", 108))
    assert "bad DFD: dfdTotalSize 96" in _error(_patch(base, 104, "<I", 96))
    assert "colorPrimaries 12" in _error(_patch(base, 104 + 13, "<B", 12))
    assert "bad DFD: colorModel 2" in _error(_patch(base, 104 + 12, "<B", 2))
    assert "bad DFD: transferFunction 1 but R8G8B8A8_SRGB needs sRGB" in _error(_patch(base, 104 + 14, "<B", 1))
    assert "LINEAR" in _error(_patch(base, 104 + 28 + 48 + 3, "<B", 0x0F))
    assert "bad DFD: sample 1" in _error(_patch(base, 104 + 28 + 16 + 2, "<B", 15))  # G 16 bits
    assert "bytesPlane" in _error(_patch(base, 104 + 20, "<B", 3))
    assert "range" in _error(_patch(base, 104 + 28 + 12, "<I", 0xFFFF))
    assert "bad key/value data" in _error(_patch(base, 196, "<I", 200))
    # levelCount 20 for a 256x256 texture
    big = write_ktx2(37, 256, 256, random_levels(rng, 37, 256, 256, 1))
    assert _error(_patch(big, 40, "<I", 20)).endswith("levelCount 20 too large for 256x256 (at most 9)")
    # UNORM file claiming sRGB transfer
    unorm = write_ktx2(37, 1, 1, [bytes(4)])
    assert "has an _SRGB twin" in _error(_patch(unorm, 80 + 24 + 14, "<B", 2))
    # level offset misaligned / overlapping / out of order
    two = write_ktx2(131, 8, 8, random_levels(rng, 131, 8, 8, 2))
    off0 = struct.unpack_from("<Q", two, 80)[0]
    assert "not aligned" in _error(_patch(two, 80, "<Q", off0 + 4))
    assert "smallest first" in _error(_patch(two, 80 + 24, "<Q", off0))
    assert "byteLength 8, expected 32" in _error(_patch(two, 88, "<Q", 8))


def test_level_count_zero(rng):
    """levelCount 0 ("make the mips at load time") holds one level; block formats may not use it."""
    rgba = write_ktx2(37, 8, 4, random_levels(rng, 37, 8, 4, 1))
    ktx = read_ktx2(_patch(rgba, 40, "<I", 0))
    assert len(ktx.levels) == 1 and ktx.level_count_field == 0
    bc1 = write_ktx2(131, 8, 4, random_levels(rng, 131, 8, 4, 1))
    assert "levelCount 0 is not allowed" in _error(_patch(bc1, 40, "<I", 0))


def test_writer_accepts_buffers(rng):
    arr = np.arange(64, dtype=np.uint8).reshape(4, 4, 4)
    assert read_ktx2(write_ktx2(37, 4, 4, [arr])).levels == [arr.tobytes()]
    assert read_ktx2(write_ktx2(37, 4, 4, [bytearray(arr.tobytes())])).levels == [arr.tobytes()]


def _kv_file(kv):
    return write_ktx2(37, 1, 1, [bytes(4)], kv=kv)


def test_reader_kvd_rules():
    data = _kv_file({"aa": b"v", "ab": b"w"})
    kvd_off = struct.unpack_from("<I", data, 56)[0]
    assert data.count(b"aa\0") == 1
    swapped = data.replace(b"aa\0v", b"zz\0v")
    assert "out of order" in _error(swapped)
    dup = data.replace(b"ab\0w", b"aa\0w")
    assert "repeats" in _error(dup)
    no_nul = data.replace(b"aa\0v", b"aaxv")
    assert "not NUL-terminated" in _error(no_nul)
    empty = data.replace(b"aa\0v", b"\0aav")
    assert "empty key" in _error(empty)
    pad = _kv_file({"abc": b"vw"})  # 4 + 6 bytes, 2 padding bytes follow
    pos = pad.index(b"abc\0vw") + 6
    assert pad[pos:pos + 2] == b"\0\0"
    assert "non-zero padding" in _error(pad[:pos] + b"\x01" + pad[pos + 1:])
    assert kvd_off > 0


def test_reader_zstd_errors(rng):
    levels = random_levels(rng, 43, 16, 16, 2)
    data = write_ktx2(43, 16, 16, levels, zstd_level=3)
    off, length, ulen = struct.unpack_from("<3Q", data, 80)
    assert read_ktx2(data).levels == levels
    corrupt = bytearray(data)
    corrupt[off + length // 2] ^= 0xFF
    msg = _error(bytes(corrupt))
    assert "level 0" in msg
    assert "uncompressedByteLength 1000" in _error(_patch(data, 96, "<Q", 1000))
    # a valid stream of the wrong size: recompress level 0 with a byte missing
    short = zstandard.ZstdCompressor().compress(levels[0][:-1])
    rebuilt = bytearray(data[:off]) + short
    struct.pack_into("<Q", rebuilt, 88, len(short))
    assert "expands to 1023 bytes, expected 1024" in _error(bytes(rebuilt))
    # trailing garbage after the frame
    tail = bytearray(data) + b"junk"
    struct.pack_into("<Q", tail, 88, length + 4)
    assert "after the end" in _error(bytes(tail))


def test_zlib_supercompression_is_read(rng):
    """Scheme 3 is not written but is read, so files from other tools load."""
    import zlib

    levels = random_levels(rng, 43, 4, 4, 3)
    comp = [zlib.compress(lv) for lv in levels]
    plain = write_ktx2(43, 4, 4, levels)
    meta_end = struct.unpack_from("<I", plain, 56)[0] + struct.unpack_from("<I", plain, 60)[0]
    out = bytearray(plain[:meta_end])
    struct.pack_into("<I", out, 44, 3)
    offsets = {}
    for i in reversed(range(3)):
        offsets[i] = len(out)
        out += comp[i]
    for i in range(3):
        struct.pack_into("<3Q", out, 80 + 24 * i, offsets[i], len(comp[i]), len(levels[i]))
    ktx = read_ktx2(bytes(out))
    assert ktx.levels == levels and describe(ktx)["supercompression"] == "zlib"


# ----------------------------------------------------------------------------- fuzzing


def _only_container_errors(data):
    try:
        read_ktx2(data, "fuzz.ktx2")
    except ContainerError as exc:
        assert "\n" not in str(exc) and str(exc).startswith("fuzz.ktx2: ")
    # any other exception type fails the test


@pytest.mark.parametrize("zstd_level", [None, 3])
def test_fuzz_truncation_and_byte_flips(rng, zstd_level):
    levels = random_levels(rng, 138, 9, 6, 3)
    data = write_ktx2(138, 9, 6, levels, kv={"note": "fuzz"}, zstd_level=zstd_level)
    for cut in range(len(data)):
        with pytest.raises(ContainerError):
            read_ktx2(data[:cut], "fuzz.ktx2")
    for _ in range(3000):
        mutated = bytearray(data)
        for _ in range(int(rng.integers(1, 4))):
            pos = int(rng.integers(0, len(data)))
            mutated[pos] = int(rng.integers(0, 256))
        _only_container_errors(bytes(mutated))
    # Every byte before the level data, set to a few values that break fields differently.
    meta_end = struct.unpack_from("<I", data, 56)[0] + struct.unpack_from("<I", data, 60)[0]
    for pos in range(12, meta_end):
        for value in {0, 0xFF, data[pos] ^ 1, data[pos] ^ 0x80}:
            mutated = bytearray(data)
            mutated[pos] = value
            _only_container_errors(bytes(mutated))
    # Targeted: every 32-bit header and index word set to hostile values.
    for offset in range(12, 80 + 24 * 3, 4):
        for value in (0, 1, 2, 3, 0xFF, 0x7FFFFFFF, 0xFFFFFFFF):
            _only_container_errors(_patch(data, offset, "<I", value))


# ----------------------------------------------------------------------------- ktx-parse


def _int32(v):
    return v - (1 << 32) if v >= 1 << 31 else v


def test_vk_format_numbers_match_ktx_parse(ktx_parse):
    proc = subprocess.run(["node", str(JS_DIR / "ktxparse.mjs"), "--constants"],
                          capture_output=True, text=True, check=True, timeout=60)
    constants = json.loads(proc.stdout)
    for vk, fmt in FORMATS.items():
        assert constants["VK_FORMAT_" + fmt.name] == vk, fmt.name
    assert FORMATS_BY_NAME["BC5_SNORM_BLOCK"].vk_format == 142


def test_every_format_against_ktx_parse(ktx_parse, tmp_path, rng):
    cases = []
    for vk in sorted(FORMATS):
        for w, h in SIZES:
            for full in (False, True):
                for zstd_level in (None, 4):
                    n = max_levels(w, h) if full else 1
                    levels = random_levels(rng, vk, w, h, n)
                    kv = {"texcook.source": f"case {len(cases)}", "texcook.bin": bytes([1, 2, 3])}
                    data = write_ktx2(vk, w, h, levels, kv=kv, zstd_level=zstd_level)
                    path = tmp_path / f"{len(cases):04d}.ktx2"
                    path.write_bytes(data)
                    cases.append((path, vk, w, h, levels, zstd_level))
    records = ktx_parse([c[0] for c in cases])
    assert len(records) == len(cases)
    dctx = zstandard.ZstdDecompressor()
    for (path, vk, w, h, levels, zstd_level), rec in zip(cases, records):
        where = f"{FORMATS[vk].name} {w}x{h} levels={len(levels)} zstd={zstd_level}"
        assert "error" not in rec, (where, rec)
        ours = read_ktx2(path.read_bytes(), str(path))
        fmt = FORMATS[vk]
        # ktx-parse against the writer's inputs and against our reader
        assert rec["vkFormat"] == vk == ours.vk_format, where
        assert (rec["pixelWidth"], rec["pixelHeight"]) == (w, h) == (ours.width, ours.height), where
        assert (rec["pixelDepth"], rec["layerCount"], rec["faceCount"]) == (0, 0, 1), where
        assert rec["typeSize"] == fmt.type_size, where
        assert rec["levelCount"] == len(levels) == len(ours.levels), where
        assert rec["supercompressionScheme"] == (0 if zstd_level is None else 2) == ours.supercompression, where
        assert rec["transferFunction"] == (2 if fmt.srgb else 1) == ours.transfer, where
        assert rec["colorModel"] == fmt.color_model == ours.color_model, where
        assert rec["colorPrimaries"] == 1 and rec["flags"] == 0, where
        assert rec["texelBlockDimension"] == [fmt.block_w - 1, fmt.block_h - 1, 0, 0], where
        assert rec["bytesPlane"] == [fmt.bytes_per_block, 0, 0, 0, 0, 0, 0, 0], where
        want_samples = [
            {
                "bitOffset": s.bit_offset,
                "bitLength": s.bit_length - 1,
                "channelType": s.channel | (s.qualifiers << 4),
                # ktx-parse reads the range as signed when the SIGNED qualifier is set
                "sampleLower": _int32(s.lower) if s.qualifiers & 4 else s.lower,
                "sampleUpper": _int32(s.upper) if s.qualifiers & 4 else s.upper,
            }
            for s in fmt.samples
        ]
        assert rec["samples"] == want_samples, where
        kv_text = describe(ours)["key_values"]
        assert rec["keyValue"] == {
            "KTXorientation": "rd", "KTXwriter": kv_text["KTXwriter"],
            "texcook.bin": "\x01\x02\x03", "texcook.source": kv_text["texcook.source"],
        }, where
        assert kv_text["KTXwriter"].startswith("texcook ")
        for i, (lv, entry) in enumerate(zip(levels, rec["levels"])):
            stored = base64.b64decode(entry["data"])
            assert entry["uncompressedByteLength"] == len(lv), (where, i)
            got = stored if zstd_level is None else dctx.decompress(stored)
            assert got == lv == ours.levels[i], (where, i)


def test_ktx_parse_rejects_what_we_reject(ktx_parse, tmp_path):
    """Sanity check that the harness reports ktx-parse failures instead of hiding them."""
    bad = tmp_path / "bad.ktx2"
    bad.write_bytes(b"\x00" * 100)
    (rec,) = ktx_parse([bad])
    assert "identifier" in rec["error"]
    with pytest.raises(ContainerError, match="bad identifier"):
        read_ktx2(bad.read_bytes(), str(bad))


# --------------------------------------------------------------------------- the registry of texcook's keys


def _references(func, key):
    """True when `func`'s code names `key` (its name, or the registry's Key)
    through a global of its module: a constant bound to the name, or a
    module's attribute (`keys.SAT.name`, `transforms.KV_KEY`)."""
    import types

    names, stack = set(), [func.__code__]
    while stack:
        code = stack.pop()
        names |= set(code.co_names)
        stack += [c for c in code.co_consts if isinstance(c, types.CodeType)]
    for name in names:
        value = func.__globals__.get(name)
        if value == key.name or value is key:
            return True
        if isinstance(value, types.ModuleType):
            if any(getattr(value, n, None) in (key, key.name) for n in names):
                return True
    return False


def _function(where):
    import importlib

    module, name = where.split(":")
    obj = importlib.import_module(module)
    for part in name.split("."):
        obj = getattr(obj, part)
    return obj


def test_every_registered_key_is_named_by_the_rule_and_read_where_the_registry_says():
    from texcook.container import ktx2_keys

    for key in ktx2_keys.KEYS.values():
        assert ktx2_keys.check_name(key) == key.name
        assert key.writers and (key.readers or key.spec), key.name  # texcook reads every key of its own
        for where in key.writers + key.readers:
            assert _references(_function(where), key), f"{where} does not name {key.name}"
    # the rule refuses what it should
    bad = [ktx2_keys.Key("texcook.colourSpace", "text", {}, (), (), ""),
           ktx2_keys.Key("texcook.alpha_cutoff", "text", {}, (), (), "", gltf="alphaCutoff"),
           ktx2_keys.Key("texcook_content", "text", {}, (), (), "")]
    for key in bad:
        with pytest.raises(ValueError):
            ktx2_keys.check_name(key)


def test_every_key_a_bake_writes_is_registered(tmp_path):
    from pathlib import Path

    from texcook.container import ktx2_keys
    from texcook.image import write_image
    from texcook.pipeline import bake_file
    from texcook.recipe import Recipe

    rng = np.random.default_rng(5)
    grey_alpha, rgba = tmp_path / "ga.png", tmp_path / "rgba.png"
    write_image(str(grey_alpha), rng.integers(0, 256, (8, 8, 2), dtype=np.uint8))
    write_image(str(rgba), rng.integers(0, 256, (8, 8, 4), dtype=np.uint8))
    seen = {}
    recipes = [(grey_alpha, Recipe.of(sat=True, colour_space="linear")),  # rg8 with KTXswizzle rrrg
               (rgba, Recipe.of(colour_space="auto", alpha_cutoff=0.5)),
               (rgba, Recipe.of(normal_map=True, format="rg8", renormalize="texture")),
               (rgba, Recipe.of(format="bc3-ycocg", swizzle="bgra"))]
    for i, (src, recipe) in enumerate(recipes):
        out = tmp_path / f"o{i}.ktx2"
        summary = bake_file(str(src), str(out), recipe)
        for path in [out] + ([summary["sat"]] if "sat" in summary else []):
            ktx = read_ktx2(Path(path).read_bytes(), str(path))
            seen.update({k: ktx.text(k) for k in ktx.kv})
    assert set(seen) <= set(ktx2_keys.KEYS), set(seen) - set(ktx2_keys.KEYS)
    # between them the bakes write every registered key, each as its schema says
    assert set(seen) == set(ktx2_keys.KEYS)
    for name, text in seen.items():
        key = ktx2_keys.KEYS[name]
        assert ktx2_keys.conforms(json.loads(text) if key.value == "json" else text, key.schema), (name, text)
    assert not ktx2_keys.conforms({"chosen": "srgb"}, ktx2_keys.COLOUR_SPACE.schema)  # the check can fail


# --------------------------------------------------------------------------- KTX-Software's validator


def _validator_bakes(tmp_path):
    """One bake of every format texcook writes to KTX2, in each colour encoding it has, and of every
    option that changes what goes into the file: zstd, no mips, normal maps (KTXswizzle on ASTC and
    rg8), cut-outs, transforms, the colour-space choice and a summed-area table: [(label, path)]."""
    from texcook import formats
    from texcook.image import write_image
    from texcook.pipeline import bake_file
    from texcook.recipe import Recipe

    rng = np.random.default_rng(29)
    # 22x18: partial blocks for every block size, and a chain down to 1x1
    rgba = rng.integers(0, 256, (18, 22, 4), dtype=np.uint8)
    rgba[..., 3] = np.where(rng.random((18, 22)) < 0.4, 0, 255)
    normal = np.zeros((18, 22, 3), np.float32)
    normal[..., :2] = rng.uniform(-0.6, 0.6, (18, 22, 2))
    normal[..., 2] = np.sqrt(1 - (normal[..., :2] ** 2).sum(-1))
    sources = {"rgba": tmp_path / "rgba.png", "hdr": tmp_path / "hdr.exr", "normal": tmp_path / "normal.png",
               "grey_alpha": tmp_path / "ga.png"}
    write_image(str(sources["rgba"]), rgba)
    write_image(str(sources["hdr"]), rng.uniform(0, 8, (18, 22, 4)).astype(np.float32))
    write_image(str(sources["normal"]), np.round((normal * 0.5 + 0.5) * 255).astype(np.uint8))
    write_image(str(sources["grey_alpha"]), rgba[..., 2:])

    cases = []
    for name in formats.encodable():
        fmt = formats.get(name)
        source = "hdr" if fmt.sample.startswith("float") else "rgba"
        spaces = ["linear"] + (["srgb"] if fmt.vk_srgb else [])
        for space in spaces:
            cases.append((f"{name} {space}", source, dict(format=name, colour_space=space)))
    cases += [
        ("bc1 srgb zstd", "rgba", dict(format="bc1", colour_space="srgb", zstd=9)),
        ("bc7 linear zstd", "rgba", dict(format="bc7", colour_space="linear", zstd=3)),
        ("astc-6x6 srgb zstd", "rgba", dict(format="astc-6x6", colour_space="srgb", zstd=19)),
        ("bc6h zstd", "hdr", dict(format="bc6h", zstd=3)),
        ("rgba8 srgb zstd", "rgba", dict(format="rgba8", colour_space="srgb", zstd=1)),
        ("bc1 no mips", "rgba", dict(format="bc1", mips=False)),
        ("astc-5x4 no mips", "rgba", dict(format="astc-5x4", mips=False)),
        ("rgba8 no mips zstd", "rgba", dict(format="rgba8", mips=False, zstd=5)),
        ("astc-4x4 normal map (KTXswizzle ra01)", "normal", dict(format="astc-4x4", normal_map=True)),
        ("astc-8x8 normal map xyz", "normal", dict(format="astc-8x8", normal_map=True, normal_layout="xyz")),
        ("bc5 normal map", "normal", dict(format="bc5", normal_map=True)),
        ("eac-rg11 normal map zstd", "normal", dict(format="eac-rg11", normal_map=True, zstd=3)),
        ("rg8 normal map renormalized", "normal", dict(format="rg8", normal_map=True, renormalize="texture")),
        ("bc1a cut-out", "rgba", dict(format="bc1a", alpha_cutoff=0.5)),
        ("etc2a1 cut-out", "rgba", dict(format="etc2a1", alpha_cutoff=0.5)),
        ("rgba8 cut-out", "rgba", dict(format="rgba8", alpha_cutoff=0.3)),
        ("colour space auto", "rgba", dict(format="bc3", colour_space="auto")),
        ("swizzle bgra", "rgba", dict(format="bc3", swizzle="bgra")),
        ("renormalize per level", "rgba", dict(format="bc7", renormalize="level")),
        ("bc3-ycocg", "rgba", dict(format="bc3-ycocg")),
        ("grey+alpha rg8 (KTXswizzle rrrg) and a summed-area table", "grey_alpha",
         dict(colour_space="linear", sat=True)),
    ]
    out = []
    for i, (label, source, settings) in enumerate(cases):
        path = tmp_path / f"{i:02d}.ktx2"
        summary = bake_file(str(sources[source]), str(path), Recipe.of(preset="fastest", **settings))
        out.append((label, path))
        if "sat" in summary:
            out.append((label + ": the table", summary["sat"]))
    return out


def _ktx_validate(path):
    """`ktx validate`'s verdict on one file: (valid, [(id, type, details)])."""
    proc = subprocess.run(["ktx", "validate", "--format", "mini-json", str(path)], capture_output=True,
                          text=True, timeout=60)
    report = json.loads(proc.stdout)
    return report["valid"], [(m["id"], m["type"], m["details"]) for m in report["messages"]]


# KTX-Software warns about every key outside the KTX 2.0 specification's own
# ("Custom key in Key/Value Data"); texcook's registered keys are meant to be there.
CUSTOM_KEY_WARNING = 7010


def test_ktx_software_validates_every_format_and_option(tmp_path):
    """KTX-Software's `ktx validate` (built from source: docs/engines.md) finds no error in any
    file texcook writes, and no warning but the one it gives every key outside the specification,
    here only texcook's registered keys."""
    import re
    import shutil

    from texcook.container import ktx2_keys

    if shutil.which("ktx") is None:
        pytest.skip("KTX-Software's `ktx` is not on PATH (docs/engines.md says how to build it)")
    bakes = _validator_bakes(tmp_path)
    problems, custom = {}, set()
    for label, path in bakes:
        valid, messages = _ktx_validate(path)
        for id_, kind, details in messages:
            key = re.fullmatch(r'Custom key "(.*)" found in Key/Value Data\.', details)
            if id_ == CUSTOM_KEY_WARNING and key and key.group(1) in ktx2_keys.KEYS:
                custom.add(key.group(1))
            else:
                problems.setdefault(label, []).append((id_, kind, details))
        if not valid:
            problems.setdefault(label, []).append("not valid")
    assert not problems, problems
    assert custom == {k for k in ktx2_keys.KEYS if k.startswith(ktx2_keys.PREFIX)}  # every key was written
    # the run can fail: a file whose base level's index entry points past its end is refused
    broken = tmp_path / "broken.ktx2"
    data = bytearray(bakes[0][1].read_bytes())
    struct.pack_into("<Q", data, 80, len(data))
    broken.write_bytes(bytes(data))
    assert not _ktx_validate(broken)[0]
