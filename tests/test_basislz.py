"""BasisLZ supercompression of ETC1S blocks (texcook.container.basislz) in KTX2:
lossless round trips, the Basis Universal transcoder on our files, our reader
on KTX-Software's files, `ktx validate`, ktx-parse, and corrupt input."""

import base64
import json
import os
import shutil
import struct
import subprocess
from pathlib import Path

import numpy as np
import pytest

from texcook import codecs
from texcook.container import basislz, ktx2
from texcook.errors import InputError, UsageError

from conftest import JS_DIR, ROOT

DATA = Path(__file__).parent / "data" / "basislz"
TRANSCODER = ROOT / "texcook" / "view" / "node_modules" / "three" / "examples" / "jsm" / "libs" / "basis"


def etc1s_blocks(rng, n, n_ep, n_sel, alpha):
    """n random ETC1S blocks (two per texel block with alpha) drawn from n_ep
    endpoints and n_sel selector patterns."""
    eps = rng.integers(0, 1 << 18, n_ep)
    sels = rng.integers(0, 1 << 32, n_sel)

    def draw():
        e = eps[rng.integers(0, n_ep, n)]
        s = sels[rng.integers(0, n_sel, n)]
        b = np.zeros((n, 8), np.uint8)
        for c in range(3):
            b[:, c] = ((e >> (13 - 5 * c)) & 31) << 3
        t = e & 7
        b[:, 3] = (t << 5) | (t << 2) | 2
        for j in range(4):
            b[:, 4 + j] = (s >> (24 - 8 * j)) & 255
        return b

    return np.concatenate([draw()] + ([draw()] if alpha else []), axis=1).tobytes()


def chain(rng, w, h, levels, alpha, n_ep, n_sel):
    out = []
    for i in range(levels):
        lw, lh = max(1, w >> i), max(1, h >> i)
        out.append(etc1s_blocks(rng, -(-lw // 4) * -(-lh // 4), n_ep, n_sel, alpha))
    return out


# (width, height, levels, alpha, distinct endpoints, distinct selectors)
CASES = [
    (1, 1, 1, False, 1, 1),
    (5, 3, 3, True, 2, 3),
    (7, 9, 4, False, 40, 3),
    (13, 6, 1, True, 3, 40),
    (64, 48, 7, True, 300, 200),
    (130, 66, 2, False, 2000, 1500),
]


def write(blocks, w, h, alpha, srgb=True):
    fmt = ktx2.etc1s_format("etc1s-rgba" if alpha else "etc1s", srgb)
    return ktx2.write_ktx2(fmt, w, h, blocks)


@pytest.mark.parametrize("case", CASES, ids=lambda c: f"{c[0]}x{c[1]}-{c[2]}lv-{'rgba' if c[3] else 'rgb'}-{c[4]}e{c[5]}s")
def test_round_trip(case):
    w, h, levels, alpha, n_ep, n_sel = case
    blocks = chain(np.random.default_rng(w * 31 + h), w, h, levels, alpha, n_ep, n_sel)
    for srgb in (False, True):
        data = write(blocks, w, h, alpha, srgb)
        back = ktx2.read_ktx2(data, "t.ktx2")
        assert back.levels == blocks
        assert (back.vk_format, back.supercompression, back.srgb) == (0, ktx2.SUPERCOMPRESSION_BASISLZ, srgb)
        assert ktx2.read_texture(data).format == ("etc1s-rgba" if alpha else "etc1s")
        assert all(entry[2] == 0 for entry in back.level_index)  # uncompressedByteLength is 0 for BasisLZ
        (sgd_off,) = struct.unpack_from("<Q", data, 64)
        assert sgd_off % 8 == 0


def test_few_distinct_blocks_cost_few_bytes():
    """A flat level: every block predicted and run-length coded."""
    blocks = [etc1s_blocks(np.random.default_rng(0), 64 * 64, 1, 1, False)]
    gd, payloads = basislz.pack(blocks, 256, 256, False)
    assert len(payloads[0]) < 16 and len(gd) < 200
    assert basislz.unpack(gd, payloads, 256, 256, False, "x") == blocks


def test_writer_refuses_what_basislz_cannot_hold():
    good = etc1s_blocks(np.random.default_rng(1), 4, 2, 2, False)
    bad = bytearray(good)
    bad[8 + 3] ^= 1  # flip bit set in block 1
    with pytest.raises(UsageError, match="level 0 block 1 .*not an ETC1S block"):
        basislz.pack([bytes(bad)], 8, 8, False)
    bad = bytearray(good)
    bad[0] |= 2  # a non-zero red delta
    with pytest.raises(UsageError, match="block 0"):
        basislz.pack([bytes(bad)], 8, 8, False)
    many = etc1s_blocks(np.random.default_rng(2), 128 * 128, 1, 1 << 20, False)  # ~16300 distinct
    with pytest.raises(UsageError, match="at most 16128"):
        basislz.pack([many], 512, 512, False)
    with pytest.raises(UsageError, match="Zstandard"):
        ktx2.write_ktx2(ktx2.etc1s_format("etc1s", False), 8, 8, [good], zstd_level=3)


# --------------------------------------------------------------------------- independent decoders


def decode_rgba(blocks, w, h, alpha):
    """texcook's ETC1 decoder on ETC1S blocks: RGBA, alpha from the alpha block's G."""
    etc1 = codecs.get("etc1")
    if not alpha:
        out = np.array(etc1.decode(blocks, w, h))
        out[..., 3] = 255
        return out
    arr = np.frombuffer(blocks, np.uint8).reshape(-1, 16)
    out = np.array(etc1.decode(arr[:, :8].tobytes(), w, h))
    out[..., 3] = etc1.decode(arr[:, 8:].tobytes(), w, h)[..., 1]
    return out


def transcoder():
    if shutil.which("node") is None:
        pytest.skip("node is not installed")
    if not (TRANSCODER / "basis_transcoder.wasm").is_file():
        pytest.skip("three.js's Basis transcoder is missing (npm ci --prefix texcook/view)")

    def run(paths):
        proc = subprocess.run(["node", str(JS_DIR / "basis_decode.mjs"), str(TRANSCODER), *map(str, paths)],
                              capture_output=True, text=True, check=True, timeout=300)
        return [json.loads(line) for line in proc.stdout.splitlines()]

    return run


def test_basis_transcoder_decodes_our_files(tmp_path):
    run = transcoder()
    files = []
    for i, (w, h, levels, alpha, n_ep, n_sel) in enumerate(CASES):
        blocks = chain(np.random.default_rng(i), w, h, levels, alpha, n_ep, n_sel)
        path = tmp_path / f"{i}.ktx2"
        path.write_bytes(write(blocks, w, h, alpha))
        files.append((path, blocks, w, h, alpha))
    records = run([f[0] for f in files])
    for (path, blocks, w, h, alpha), rec in zip(files, records):
        assert "error" not in rec, rec
        assert (rec["width"], rec["height"], rec["hasAlpha"], len(rec["levels"])) == (w, h, alpha, len(blocks))
        for i, lv in enumerate(rec["levels"]):
            lw, lh = max(1, w >> i), max(1, h >> i)
            theirs = np.frombuffer(base64.b64decode(lv["rgba"]), np.uint8).reshape(lh, lw, 4)
            assert np.array_equal(theirs, decode_rgba(blocks[i], lw, lh, alpha)), (path.name, i)


def test_our_reader_on_ktx_software_files():
    """KTX-Software's BasisLZ files read to blocks that decode to what the transcoder gave."""
    want = np.load(DATA / "transcoded.npz")
    for stem, alpha in (("crop_rgb", False), ("crop_rgba", True)):
        ktx = ktx2.read_ktx2((DATA / f"{stem}.ktx2").read_bytes(), stem)
        assert (ktx.width, ktx.height, len(ktx.levels), ktx.srgb) == (64, 48, 7, True)
        for i, blocks in enumerate(ktx.levels):
            w, h = ktx.level_dims(i)
            assert np.array_equal(decode_rgba(blocks, w, h, alpha), want[f"{stem}_{i}"]), (stem, i)


def test_fixture_matches_the_live_transcoder():
    records = transcoder()([DATA / "crop_rgb.ktx2", DATA / "crop_rgba.ktx2"])
    want = np.load(DATA / "transcoded.npz")
    for stem, rec in zip(("crop_rgb", "crop_rgba"), records):
        for i, lv in enumerate(rec["levels"]):
            got = np.frombuffer(base64.b64decode(lv["rgba"]), np.uint8)
            assert np.array_equal(got, want[f"{stem}_{i}"].ravel())


def test_repacked_ktx_software_files_are_no_larger():
    """Our writer on the blocks of KTX-Software's files: global data and slices
    within 5% of its bytes (measured smaller: docs/pipeline.md)."""
    for stem, alpha in (("crop_rgb", False), ("crop_rgba", True)):
        data = (DATA / f"{stem}.ktx2").read_bytes()
        ktx = ktx2.read_ktx2(data, stem)
        (theirs,) = struct.unpack_from("<Q", data, 72)
        theirs += sum(entry[1] for entry in ktx.level_index)
        gd, payloads = basislz.pack(ktx.levels, 64, 48, alpha)
        assert len(gd) + sum(map(len, payloads)) <= 1.05 * theirs
        assert basislz.unpack(gd, payloads, 64, 48, alpha, stem) == ktx.levels


def test_ktx_validate_accepts_our_files(tmp_path):
    if shutil.which("ktx") is None:
        pytest.skip("KTX-Software's `ktx` is not on PATH")
    for i, (w, h, levels, alpha, n_ep, n_sel) in enumerate(CASES):
        path = tmp_path / f"{i}.ktx2"
        path.write_bytes(write(chain(np.random.default_rng(i), w, h, levels, alpha, n_ep, n_sel), w, h, alpha,
                               srgb=bool(i % 2)))
        proc = subprocess.run(["ktx", "validate", "--format", "mini-json", str(path)], capture_output=True,
                              text=True, timeout=60)
        report = json.loads(proc.stdout)
        assert report["valid"], report
        assert [m for m in report["messages"] if m["type"] != "warning" or m["id"] != 7010] == [], report


def test_ktx_parse_reads_our_files(tmp_path, ktx_parse):
    blocks = chain(np.random.default_rng(3), 20, 12, 3, True, 30, 30)
    path = tmp_path / "a.ktx2"
    data = write(blocks, 20, 12, True)
    path.write_bytes(data)
    (rec,) = ktx_parse([path])
    assert "error" not in rec, rec
    assert (rec["vkFormat"], rec["supercompressionScheme"], rec["colorModel"]) == (0, 1, 163)
    assert [s["channelType"] for s in rec["samples"]] == [0, 15]
    assert rec["bytesPlane"][:2] == [8, 8]
    ktx = ktx2.read_ktx2(data)
    for lv, (off, length, _u) in zip(rec["levels"], ktx.level_index):
        assert base64.b64decode(lv["data"]) == data[off:off + length]


# --------------------------------------------------------------------------- corrupt input


def _sample():
    blocks = chain(np.random.default_rng(9), 24, 20, 3, True, 25, 25)
    return write(blocks, 24, 20, True)


def _patch(data, offset, fmt, value):
    out = bytearray(data)
    struct.pack_into(fmt, out, offset, value)
    return bytes(out)


def _read(data):
    return ktx2.read_ktx2(data, "bad.ktx2")


def test_targeted_corruptions_are_one_line_errors():
    data = _sample()
    (sgd_off, sgd_len) = struct.unpack_from("<2Q", data, 64)
    level0 = struct.unpack_from("<3Q", data, 80)
    cases = {
        "truncated": (data[:-5], "truncated"),
        "endpointCount 0": (_patch(data, sgd_off, "<H", 0), "endpointCount 0"),
        "endpointCount larger": (_patch(data, sgd_off, "<H", 1000), "endpoint codebook"),
        "selectorCount larger": (_patch(data, sgd_off + 2, "<H", 3000), "selector codebook"),
        "lengths": (_patch(data, sgd_off + 4, "<I", 9999), "global data is"),
        "extended": (_patch(data, sgd_off + 16, "<I", 4), "global data is"),
        "flags": (_patch(data, sgd_off + 20, "<I", 2), "imageFlags"),
        "slice past level": (_patch(data, sgd_off + 20 + 4, "<I", 10 ** 6), "overruns"),
        "empty slice": (_patch(data, sgd_off + 20 + 8, "<I", 0), "slice is empty"),
        "uncompressedByteLength": (_patch(data, 80 + 16, "<Q", 5), "must be 0 with BasisLZ"),
        "sgd offset": (_patch(data, 64, "<Q", sgd_off + 8), "sgdByteOffset"),
        "sgd missing": (_patch(data, 72, "<Q", 0), "sgdByteLength is 0"),
        "zstd scheme": (_patch(data, 44, "<I", 2), "must be BasisLZ"),
        "slice bytes": (_patch(data, level0[0], "<I", 0xFFFFFFFF), "level 0"),
    }
    for label, (bad, message) in cases.items():
        with pytest.raises(InputError, match=message) as err:
            _read(bad)
        assert "bad.ktx2" in str(err.value) and "\n" not in str(err.value), label


def test_fuzzed_files_fail_cleanly():
    """Random byte changes in the global data and levels: the file reads or is
    an InputError, never another exception or a hang."""
    data = _sample()
    (sgd_off,) = struct.unpack_from("<Q", data, 64)
    rng = np.random.default_rng(4)
    rounds = 3000 if os.environ.get("TEXCOOK_LONG") else 300
    for _ in range(rounds):
        bad = bytearray(data)
        for _ in range(int(rng.integers(1, 4))):
            bad[int(rng.integers(sgd_off, len(bad)))] = int(rng.integers(0, 256))
        try:
            _read(bytes(bad))
        except InputError:
            pass
    for cut in range(sgd_off, len(data), 7):
        with pytest.raises(InputError):
            _read(data[:cut])
