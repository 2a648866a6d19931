"""ETC1S: PSNR against file size, texcook's `etc1s` / `etc1s-rgba` against
KTX-Software's BasisLZ encoder (`ktx encode --codec basis-lz`), one level.

    python bench/bench_etc1s.py [--rgba] [--preset P] [--quality 32,64,128,192] IMAGE ...

For each image: KTX-Software at --qlevel 16..255 (--clevel 1, its default),
the file size and the RGB (RGBA with --rgba) PSNR of `ktx extract --transcode
rgba8`; then texcook at each --quality, the size of its KTX2 file and the
PSNR of its decode (KTX-Software's transcoder decodes both alike), with
"vs basisu": our PSNR less KTX-Software's at our size (its curve
interpolated; blank outside its range). RGB images also print "re-packed":
the same against KTX-Software's blocks in texcook's KTX2 file (its writer),
which compares the choice of blocks alone (texcook's writer makes files
about 5% smaller than KTX-Software's from the same blocks, docs/pipeline.md).
Speed: Mpix/s of the encode (KTX-Software's includes its process start).
"""

import argparse
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

KTX = os.environ.get("KTX", "/usr/local/bin/ktx")
THEIR_Q = (16, 32, 64, 96, 128, 160, 192, 224, 255)


def load(path):
    import OpenImageIO as oiio

    spec = oiio.ImageSpec()
    spec.attribute("oiio:UnassociatedAlpha", 1)
    px = oiio.ImageBuf(str(path), 0, 0, spec).get_pixels(oiio.UINT8)
    if px.shape[2] == 1:
        px = np.repeat(px, 3, axis=2)
    if px.shape[2] == 3:
        px = np.concatenate([px, np.full(px.shape[:2] + (1,), 255, np.uint8)], axis=2)
    return np.ascontiguousarray(px[..., :4])


def psnr(a, b):
    mse = ((a.astype(np.float64) - b) ** 2).mean()
    return 10 * np.log10(255.0 ** 2 / mse) if mse else float("inf")


def basisu(img, quality, channels, work):
    """(PSNR, file bytes, re-packed bytes or None, seconds) of KTX-Software's encode."""
    import OpenImageIO as oiio

    from texcook.codecs import get
    from texcook.container.ktx2 import etc1s_format, write_ktx2

    h, w = img.shape[:2]
    src, raw, enc = (os.path.join(work, n) for n in ("in.png", "in.ktx2", "out.ktx2"))
    out = oiio.ImageOutput.create(src)
    spec = oiio.ImageSpec(w, h, channels, "uint8")
    spec.attribute("oiio:UnassociatedAlpha", 1)  # the texels as they are, not un-premultiplied
    out.open(src, spec)
    out.write_image(np.ascontiguousarray(img[..., :channels]))
    out.close()
    fmt = "R8G8B8A8_UNORM" if channels == 4 else "R8G8B8_UNORM"
    subprocess.run([KTX, "create", "--format", fmt, "--assign-tf", "linear", src, raw], check=True,
                   capture_output=True)
    t0 = time.perf_counter()
    subprocess.run([KTX, "encode", "--codec", "basis-lz", "--qlevel", str(quality), "--clevel", "1", raw, enc],
                   check=True, capture_output=True)
    seconds = time.perf_counter() - t0
    png = os.path.join(work, "out.png")
    subprocess.run([KTX, "extract", "--transcode", "rgba8", enc, png], check=True, capture_output=True)
    spec = oiio.ImageSpec()
    spec.attribute("oiio:UnassociatedAlpha", 1)
    dec = oiio.ImageBuf(png, 0, 0, spec).get_pixels(oiio.UINT8)
    repacked = None
    if channels == 3:
        blocks = os.path.join(work, "etc1.raw")
        subprocess.run([KTX, "extract", "--raw", "--transcode", "etc-rgb", enc, blocks], check=True,
                       capture_output=True)
        with open(blocks, "rb") as fh:
            data = fh.read()
        assert np.array_equal(get("etc1").decode(data, w, h)[..., :3], dec[..., :3])
        repacked = len(write_ktx2(etc1s_format("etc1s", False), w, h, [data]))
    return psnr(dec[..., :channels], img[..., :channels]), os.path.getsize(enc), repacked, seconds


def ours(img, quality, preset, channels):
    """(PSNR, KTX2 bytes, seconds) of texcook's encode."""
    from texcook.codecs import get
    from texcook.container.ktx2 import etc1s_format, write_ktx2

    name = "etc1s-rgba" if channels == 4 else "etc1s"
    codec = get(name)
    h, w = img.shape[:2]
    codec.encode(img[:8, :8].copy(), preset, quality=quality)  # kernels loaded
    t0 = time.perf_counter()
    data = codec.encode(img, preset, quality=quality)
    seconds = time.perf_counter() - t0
    size = len(write_ktx2(etc1s_format(name, False), w, h, [data]))
    return psnr(codec.decode(data, w, h)[..., :channels], img[..., :channels]), size, seconds


def at(curve, bits):
    """PSNR of a (bits, PSNR) curve at `bits` (nan outside it)."""
    c = np.array(sorted(curve))
    return float(np.interp(bits, c[:, 0], c[:, 1], left=np.nan, right=np.nan))


def _db(gain):
    return f"{gain:+.2f} dB" if np.isfinite(gain) else "(outside its sizes)"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("images", nargs="+")
    ap.add_argument("--rgba", action="store_true", help="etc1s-rgba against KTX-Software's RGBA, RGBA PSNR")
    ap.add_argument("--preset", default="medium")
    ap.add_argument("--quality", default="32,64,128,192")
    args = ap.parse_args()
    channels = 4 if args.rgba else 3
    gains, regains = [], []
    for path in args.images:
        img = load(path)
        texels = img.shape[0] * img.shape[1]
        bpt = 8.0 / texels
        name = os.path.basename(path)
        curve, recurve = [], []
        with tempfile.TemporaryDirectory() as work:
            for q in THEIR_Q:
                p, size, repacked, s = basisu(img, q, channels, work)
                curve.append((size * bpt, p))
                if repacked is not None:
                    recurve.append((repacked * bpt, p))
                if q in (32, 64, 128, 192):
                    print(f"{name} basisu q{q}: {p:.2f} dB {size * bpt:.3f} bpt "
                          f"{texels / s / 1e6:.2f} Mpix/s", flush=True)
        for q in (int(x) for x in args.quality.split(",")):
            p, size, s = ours(img, q, args.preset, channels)
            b = size * bpt
            gain = p - at(curve, b)
            line = f"{name} texcook q{q} {args.preset}: {p:.2f} dB {b:.3f} bpt {texels / s / 1e6:.2f} Mpix/s" \
                   f" vs basisu {_db(gain)}"
            if np.isfinite(gain):
                gains.append(gain)
            if recurve:
                regain = p - at(recurve, b)
                line += f", re-packed {_db(regain)}"
                if np.isfinite(regain):
                    regains.append(regain)
            print(line, flush=True)
    print(f"mean vs basisu {np.mean(gains):+.2f} dB (min {np.min(gains):+.2f}, {len(gains)} points)")
    if regains:
        print(f"mean vs basisu re-packed {np.mean(regains):+.2f} dB (min {np.min(regains):+.2f}, "
              f"{len(regains)} points)")


if __name__ == "__main__":
    sys.exit(main())
