""".astc files (astcenc's container): header layout, round trips at every block
size and awkward image sizes, validation errors naming the file, and astcenc's
command-line tool (Debian package `astcenc`, when installed) reading what we
write and writing what we read."""

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from texcook.codecs.astc.decode import decode_blocks
from texcook.container.astcfile import BLOCK_SIZES, data_size, read_astc, write_astc
from texcook.errors import ContainerError, UsageError

CORPUS = Path(__file__).resolve().parent.parent / "corpus"


@pytest.fixture
def rng():
    return np.random.default_rng(7)


def test_header_layout():
    data = bytes(range(16)) * (data_size(6, 5, 43, 37) // 16)
    f = write_astc(6, 5, 43, 37, data)
    assert f[:16] == bytes.fromhex("13aba15c" "060501" "2b0000" "250000" "010000")
    assert f[16:] == data
    # 24-bit sizes, little-endian
    big = write_astc(4, 4, 70000, 1, bytes(data_size(4, 4, 70000, 1)))
    assert big[7:10] == (70000).to_bytes(3, "little")


@pytest.mark.parametrize("bw,bh", BLOCK_SIZES)
def test_round_trip(rng, bw, bh):
    for w, h in ((1, 1), (13, 7), (127, 128), (bw, bh)):
        blocks = rng.integers(0, 256, data_size(bw, bh, w, h), dtype=np.uint8).tobytes()
        f = read_astc(write_astc(bw, bh, w, h, blocks), "x.astc")
        assert (f.block_w, f.block_h, f.width, f.height, f.data) == (bw, bh, w, h, blocks)
        assert f.format_name == f"astc-{bw}x{bh}"


def test_read_errors():
    good = write_astc(8, 8, 20, 9, bytes(data_size(8, 8, 20, 9)))
    cases = {
        "bad magic": b"DDS " + good[4:],
        "truncated .astc header": good[:10],
        "3D ASTC": good[:6] + b"\x02" + good[7:],
        "depth 4": good[:13] + (4).to_bytes(3, "little") + good[16:],
        "not a 2D ASTC block size": good[:4] + b"\x07\x07" + good[6:],
        "image size 0x9": good[:7] + b"\0\0\0" + good[10:],
        "truncated: 20x9": good[:-1],
        "1 bytes after the last block": good + b"\0",
    }
    for msg, data in cases.items():
        with pytest.raises(ContainerError, match=msg) as err:
            read_astc(data, "tex/broken.astc")
        assert str(err.value).startswith("tex/broken.astc: ")
    with pytest.raises(ContainerError, match="not bytes"):
        read_astc(None, "n.astc")


def test_write_errors():
    with pytest.raises(UsageError, match="block size"):
        write_astc(7, 7, 8, 8, bytes(32))
    with pytest.raises(UsageError, match="needs 64 bytes"):
        write_astc(4, 4, 8, 8, bytes(63))
    with pytest.raises(UsageError, match="out of range"):
        write_astc(4, 4, 0, 8, b"")


def _decode(f):
    nbx, nby = -(-f.width // f.block_w), -(-f.height // f.block_h)
    buf = np.frombuffer(f.data, np.uint8).reshape(-1, 16)
    out = np.zeros((buf.shape[0], f.block_w * f.block_h, 4), np.uint8)
    decode_blocks(buf, out, f.block_w, f.block_h, 0)
    img = out.reshape(nby, nbx, f.block_h, f.block_w, 4).transpose(0, 2, 1, 3, 4)
    return img.reshape(nby * f.block_h, nbx * f.block_w, 4)[:f.height, :f.width]


@pytest.mark.skipif(shutil.which("astcenc") is None, reason="astcenc command-line tool not installed")
@pytest.mark.parametrize("bw,bh", [(4, 4), (6, 5), (12, 10)])
def test_astcenc_cli(tmp_path, bw, bh):
    """astcenc writes a .astc we read; it decodes a .astc we wrote (its blocks
    re-framed by write_astc) to the very pixels it decodes from its own file.
    Debian's astcenc 4.2 writes 8-bit images through its float decode, which
    rounds where the spec's decode_unorm8 takes the top byte, so our pixels are
    within one step of its (test_astc_bitstream compares exactly through the
    library, with decode_unorm8)."""
    import OpenImageIO as oiio

    # PNG alpha is straight: keep OpenImageIO from premultiplying on read and write
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)

    def png(path):
        return oiio.ImageBuf(str(path), 0, 0, config).get_pixels(oiio.UINT8)

    crop = np.ascontiguousarray(png(CORPUS / "rgba/ldr-rgba-00.png")[100:137, 80:123, :4])  # partial blocks
    spec = oiio.ImageSpec(43, 37, 4, oiio.UINT8)
    spec.attribute("oiio:UnassociatedAlpha", 1)
    src = oiio.ImageBuf(spec)
    src.set_pixels(oiio.ROI(), crop)
    src.write(str(tmp_path / "in.png"))

    def run(*args):
        subprocess.run(["astcenc", *args], check=True, capture_output=True)

    run("-cl", str(tmp_path / "in.png"), str(tmp_path / "a.astc"), f"{bw}x{bh}", "-fast")
    f = read_astc((tmp_path / "a.astc").read_bytes(), "a.astc")
    assert (f.block_w, f.block_h, f.width, f.height) == (bw, bh, 43, 37)
    run("-dl", str(tmp_path / "a.astc"), str(tmp_path / "a.png"))
    theirs = png(tmp_path / "a.png")
    assert np.abs(theirs.astype(int) - _decode(f)).max() <= 1

    (tmp_path / "b.astc").write_bytes(write_astc(bw, bh, 43, 37, f.data))
    run("-dl", str(tmp_path / "b.astc"), str(tmp_path / "b.png"))
    assert (png(tmp_path / "b.png") == theirs).all()
