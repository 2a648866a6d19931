"""ASTC quality and speed on the corpus, every 2D block size, against astcenc
(astc-encoder-py) in the same process.

    python bench/bench_astc.py [--sizes 4x4,6x6] [--presets fastest,fast] [--astcenc fastest,medium,thorough]
                               [--every N] [--repeat N]

PSNR: mean over corpus/rgb and corpus/rgba of each image's PSNR over the
image's channels (RGB for rgb/, RGBA for rgba/), images cropped to a multiple
of the block size, 8-bit values; our streams decoded by our decoder (the
tests check it against astcenc's). Throughput: single-threaded megapixels per
second over the whole set, kernels compiled beforehand, astcenc after an
untimed warm-up call.
"""

import argparse
import glob
import os
import time

import numpy as np
import OpenImageIO as oiio

from texcook import codecs
from texcook.codecs.astc import BLOCK_SIZES
from texcook.metrics import psnr

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "corpus")


def load_corpus(root=ROOT):
    """The PNGs of a folder laid out like the corpus (rgb/, rgba/) as
    [(name, channels scored, RGBA uint8)]."""
    images = []
    spec = oiio.ImageSpec()
    spec.attribute("oiio:UnassociatedAlpha", 1)
    for sub in ("rgb", "rgba"):
        for path in sorted(glob.glob(os.path.join(root, sub, "*.png"))):
            px = oiio.ImageBuf(path, 0, 0, spec).get_pixels(oiio.UINT8)
            rgba = np.full(px.shape[:2] + (4,), 255, np.uint8)
            rgba[:, :, : min(4, px.shape[2])] = px[:, :, :4]
            images.append((os.path.basename(path), 4 if sub == "rgba" else 3, rgba))
    return images


def crop(img, bw, bh):
    h, w = img.shape[0] // bh * bh, img.shape[1] // bw * bw
    return np.ascontiguousarray(img[:h, :w])


def astcenc_run(images, bw, bh, preset):
    import astc_encoder as A

    q = {"fastest": A.ASTCQualityPreset.FASTEST, "fast": A.ASTCQualityPreset.FAST,
         "medium": A.ASTCQualityPreset.MEDIUM, "thorough": A.ASTCQualityPreset.THOROUGH,
         "exhaustive": A.ASTCQualityPreset.EXHAUSTIVE}[preset]
    ctx = A.ASTCContext(A.ASTCConfig(A.ASTCProfile.LDR, bw, bh, 1, q), 1)
    sw = A.ASTCSwizzle.from_str("RGBA")
    warm = images[0][2][:bh * 2, :bw * 2].copy()
    ctx.compress(A.ASTCImage(A.ASTCType.U8, warm.shape[1], warm.shape[0], 1, warm.tobytes()), sw)
    total = 0.0
    scores = []
    for _, nch, img in images:
        h, w = img.shape[:2]
        im = A.ASTCImage(A.ASTCType.U8, w, h, 1, img.tobytes())
        t0 = time.perf_counter()
        comp = ctx.compress(im, sw)
        total += time.perf_counter() - t0
        out = A.ASTCImage(A.ASTCType.U8, w, h, 1)
        ctx.decompress(comp, out, sw)
        dec = np.frombuffer(out.data, np.uint8).reshape(h, w, 4)
        scores.append(psnr(dec[..., :nch], img[..., :nch]))
    return total, scores


def ours_run(images, codec, preset):
    codec.encode(images[0][2][:codec.block_h, :codec.block_w].copy(), preset, threads=1)
    total = 0.0
    scores = []
    for _, nch, img in images:
        t0 = time.perf_counter()
        data = codec.encode(img, preset, threads=1)
        total += time.perf_counter() - t0
        dec = codec.decode(data, img.shape[1], img.shape[0])
        scores.append(psnr(dec[..., :nch], img[..., :nch]))
    return total, scores


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default=",".join(f"{w}x{h}" for w, h in BLOCK_SIZES))
    ap.add_argument("--presets", default="fastest,fast,medium,thorough,exhaustive")
    ap.add_argument("--astcenc", default="fastest,medium,thorough")
    ap.add_argument("--every", type=int, default=1,
                    help="use every Nth corpus image (for the slow presets)")
    ap.add_argument("--repeat", type=int, default=1,
                    help="time every encoder N times, in turn, and keep each one's best "
                         "(a virtual machine's speed drifts between runs)")
    args = ap.parse_args()
    corpus = load_corpus()[::args.every]
    print("| block | bits/texel | encoder | preset | PSNR dB | Mpix/s |")
    print("|---|---|---|---|---|---|")
    for size in args.sizes.split(","):
        bw, bh = (int(v) for v in size.split("x"))
        images = [(n, c, crop(img, bw, bh)) for n, c, img in corpus]
        mpix = sum(img.shape[0] * img.shape[1] for _, _, img in images) / 1e6
        codec = codecs.get(f"astc-{bw}x{bh}")
        runs = [("texcook", preset, lambda p: ours_run(images, codec, p))
                for preset in filter(None, args.presets.split(","))]
        runs += [("astcenc", preset, lambda p: astcenc_run(images, bw, bh, p))
                 for preset in filter(None, args.astcenc.split(","))]
        best = {}
        scores = {}
        for _ in range(max(args.repeat, 1)):
            for enc, preset, run in runs:
                t, s = run(preset)
                best[enc, preset] = min(t, best.get((enc, preset), t))
                scores[enc, preset] = float(np.mean(s))
        for enc, preset, _ in runs:
            speed = mpix / best[enc, preset]
            print(f"| {size} | {128 / (bw * bh):.2f} | {enc} | {preset} | {scores[enc, preset]:.2f} "
                  f"| {speed:.3g} |", flush=True)


if __name__ == "__main__":
    main()
