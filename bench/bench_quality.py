"""Quality beyond the codecs' own search: YCoCg, renormalisation, angular BC5 and ASTC.

    python bench/bench_quality.py [--sections ycocg,renorm,normal] [--preset medium] [--corpus DIR]

ycocg:  bc3-ycocg against bc1 and bc3 on corpus rgb/: RGB PSNR per image and
        the mean. Blocks are decoded by texture2ddecoder (BC1, BC3); bc3-ycocg's
        BC3 texels then go through the shader's reconstruction.
renorm: each rgb/ image squeezed to a fifth of its range (v -> 0.4 + v / 5),
        stored as a 16-bit and an 8-bit PNG, baked (no mips; default colour
        space, sRGB for bc1, etc1 and astc-6x6, and bc1 --linear) plain, with
        --renormalize texture and with a 0.5% clip; PSNR in the source's units
        (0..1) between the source and the texture as `texcook compare` reads
        it, from the squared error pooled over the images. Beside it the
        unsqueezed 16-bit original ("full") and the most a stretch by 5 can
        give (full + 13.98 dB): a low-contrast image already codes with
        less error than the full one, so the gain is bounded by that gap.
normal: corpus normal/ in BC5 and in ASTC 4x4, 6x6 and 8x8 (--normal-map)
        with each objective (--normal-metric psnr, angular), quicktex's BC5
        and astcenc's -normal mode (same preset name): angular error mean and
        99th percentile in degrees, per image and mean, and the X/Y PSNR. BC5
        is decoded by texture2ddecoder, ASTC by astcenc.
Prints one table per section.
"""

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from texcook import codecs, transforms  # noqa: E402
from texcook.colour import quantize_unorm8  # noqa: E402
from texcook.image import read_image, write_image  # noqa: E402
from texcook.metrics import angular_summary, psnr  # noqa: E402


def load(folder):
    """Corpus images as RGBA uint8 (opaque for RGB), cropped to a multiple of 4."""
    from texcook.pipeline import _to_rgba

    out = []
    for p in sorted(folder.glob("*.png")):
        px = np.rint(_to_rgba(read_image(p).pixels, False) * 255.0).astype(np.uint8)
        h, w = px.shape[0] // 4 * 4, px.shape[1] // 4 * 4
        out.append((p.name, np.ascontiguousarray(px[:h, :w])))
    return out


def t2d_decode(fmt, data, w, h):
    import texture2ddecoder as t2d

    fn = {"bc1": t2d.decode_bc1, "bc3": t2d.decode_bc3, "bc5": t2d.decode_bc5}[fmt]
    bgra = np.frombuffer(fn(bytes(data), w, h), np.uint8).reshape(h, w, 4)
    return bgra[:, :, [2, 1, 0, 3]]


def table(header, rows):
    widths = [max(len(str(r[i])) for r in [header] + rows) for i in range(len(header))]
    for r in [header] + rows:
        print("  ".join(str(v).rjust(w) if i else str(v).ljust(w) for i, (v, w) in enumerate(zip(r, widths))))
    print()


def ycocg(args):
    images = load(args.corpus / "rgb")
    rows, sums = [], np.zeros(3)
    for name, img in images:
        h, w = img.shape[:2]
        got = []
        for fmt in ("bc1", "bc3", "bc3-ycocg"):
            data = codecs.get(fmt).encode(img, args.preset)
            if fmt == "bc3-ycocg":
                dec = quantize_unorm8(transforms.ycocg_rgb(t2d_decode("bc3", data, w, h) / 255.0))
            else:
                dec = t2d_decode(fmt, data, w, h)
            got.append(psnr(img, dec, 255.0, [0, 1, 2]))
        sums += got
        rows.append([name] + [f"{v:.2f}" for v in got] + [f"{got[2] - got[1]:+.2f}"])
    mean = sums / len(images)
    rows.append(["mean"] + [f"{v:.2f}" for v in mean] + [f"{mean[2] - mean[1]:+.2f}"])
    print(f"bc3-ycocg against bc1 and bc3: RGB PSNR (dB), corpus rgb/, preset {args.preset}")
    table(["image", "bc1", "bc3", "bc3-ycocg", "ycocg - bc3"], rows)


def _pooled(psnrs):
    """PSNR of the mean squared error over images (peak 1): an image that comes
    back exactly (inf) adds no error instead of making the mean infinite."""
    mses = [0.0 if np.isinf(p) else 10.0 ** (-p / 10.0) for p in psnrs]
    m = float(np.mean(mses))
    return float("inf") if m == 0 else -10.0 * np.log10(m)


RENORM_MODES = (("plain", {}), ("texture", {"renormalize": "texture"}),
                ("clip 0.5%", {"renormalize": "texture", "renormalize_clip": 0.5}))


def renorm(args):
    from texcook.pipeline import bake_file, compare
    from texcook.recipe import Recipe

    # (label, format, colour space): the default colour space (sRGB for bc1 and
    # etc1, whose stretch then runs in linear light) and bc1 stored linear
    setups = [("bc1", "bc1", None), ("bc1 --linear", "bc1", False), ("bc4", "bc4", None), ("etc1", "etc1", None)]
    setups.append(("astc-6x6", "astc-6x6", None))
    setups = [s for s in setups if s[1] in codecs.names()]
    paths = sorted((args.corpus / "rgb").glob("*.png"))
    results = {}  # (label, bits, mode) -> PSNR per image
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for p in paths:
            px = read_image(p).pixels[..., :3].astype(np.float64)
            full = tmp / "full16.png"
            write_image(full, np.rint(px * 65535).astype(np.uint16))
            low = 0.4 + px / 5.0
            sources = {16: tmp / "low16.png", 8: tmp / "low8.png"}
            write_image(sources[16], np.rint(low * 65535).astype(np.uint16))
            write_image(sources[8], np.rint(low * 255).astype(np.uint8))
            out = tmp / "t.ktx2"
            for label, fmt, srgb in setups:
                base = Recipe.of(format=fmt, preset=args.preset, mips=False, srgb=srgb)
                bake_file(full, out, base)
                results.setdefault((label, "full", "plain"), []).append(compare(full, out)["psnr"])
                for bits, src in sources.items():
                    for mode, flat in RENORM_MODES:
                        bake_file(src, out, base.replace(**flat))
                        results.setdefault((label, bits, mode), []).append(compare(src, out)["psnr"])
    rows = []
    for label, _, _ in setups:
        full = _pooled(results[(label, "full", "plain")])
        for bits in (16, 8):
            got = [_pooled(results[(label, bits, mode)]) for mode, _ in RENORM_MODES]
            rows.append([label, f"{bits}-bit", f"{full:.2f}"] + [f"{v:.2f}" for v in got]
                        + [f"{got[1] - got[0]:+.2f}", f"{full + 20 * np.log10(5) - got[0]:+.2f}"])
    print(f"renormalisation on low-contrast rgb/ (v -> 0.4 + v/5): PSNR (dB) of the pooled squared error in "
          f"source units, {len(paths)} images, preset {args.preset}; 'full': the 16-bit original, no squeeze; "
          f"'bound': full + 13.98 dB (a fifth of the error) less plain")
    table(["format", "source", "full", "plain", "--renormalize", "clip 0.5%", "gain", "bound"], rows)


ASTC_NORMAL_SIZES = ("astc-4x4", "astc-6x6", "astc-8x8")


def astcenc_ctx(bw, bh, preset, flags=0):
    import astc_encoder as A

    q = getattr(A.ASTCQualityPreset, preset.upper())
    return A.ASTCContext(A.ASTCConfig(A.ASTCProfile.LDR, bw, bh, 1, q, flags), 1)


def astcenc_decode(data, w, h, bw, bh):
    """astcenc's decompressor (texture2ddecoder's ASTC rounds some texels differently)."""
    import astc_encoder as A

    out = A.ASTCImage(A.ASTCType.U8, w, h, 1)
    astcenc_ctx(bw, bh, "fastest", A.ASTCConfigFlags.DECOMPRESS_ONLY).decompress(
        bytes(data), out, A.ASTCSwizzle.from_str("RGBA"))
    return np.frombuffer(out.data, np.uint8).reshape(h, w, 4)


def astcenc_normal(img, bw, bh, preset):
    """astcenc's own normal-map mode (-normal: X in RGB, Y in alpha, judged by angle)."""
    import astc_encoder as A

    h, w = img.shape[:2]
    ctx = astcenc_ctx(bw, bh, preset, A.ASTCConfigFlags.MAP_NORMAL)
    return ctx.compress(A.ASTCImage(A.ASTCType.U8, w, h, 1, img.tobytes()), A.ASTCSwizzle.from_str("RRRG"))


def normal(args):
    from texcook.codecs.astc import normal_xy

    images = load(args.corpus / "normal")
    bc5 = codecs.get("bc5")
    # (row name, bits per texel, encode(img) -> decoded X, Y in R, G)
    encoders = []
    for metric, opts in (("psnr", {}), ("angular", {"angular": True})):
        encoders.append((f"bc5 {metric}", 8.0, lambda img, o=opts: t2d_decode(
            "bc5", bc5.encode(img, args.preset, **o), img.shape[1], img.shape[0])))
    try:
        import quicktex
        import quicktex.s3tc.bc5 as qb5

        def qt(img):
            h, w = img.shape[:2]
            data = qb5.BC5Encoder(0, 1).encode(quicktex.RawTexture.frombytes(img.tobytes(), w, h)).tobytes()
            return t2d_decode("bc5", data, w, h)

        encoders.append(("quicktex bc5", 8.0, qt))
    except ImportError:
        print("(quicktex not installed: its row is left out)")
    for name in ASTC_NORMAL_SIZES:
        c = codecs.get(name)
        bw, bh = c.block_w, c.block_h
        for metric, opts in (("psnr", {}), ("angular", {"angular": True})):
            def astc(img, c=c, o=opts):
                h, w = img.shape[:2]
                data = c.encode(img, args.preset, normal_map=True, **o)
                return normal_xy(astcenc_decode(data, w, h, c.block_w, c.block_h))

            encoders.append((f"{name} {metric}", c.format.bits_per_texel, astc))
        try:
            import astc_encoder  # noqa: F401

            encoders.append((f"astcenc {name} -normal", c.format.bits_per_texel, lambda img, bw=bw, bh=bh: normal_xy(
                astcenc_decode(astcenc_normal(img, bw, bh, args.preset), img.shape[1], img.shape[0], bw, bh))))
        except ImportError:
            pass
    rows = []
    for label, bits, enc in encoders:
        row, sums, xy = [label, f"{bits:.2f}"], np.zeros(2), 0.0
        for _, img in images:
            dec = enc(img)
            s = angular_summary(img, dec)
            sums += (s["mean"], s["p99"])
            xy += psnr(img[..., :2], dec[..., :2]) / len(images)
            row.append(f"{s['mean']:.3f} / {s['p99']:.3f}")
        mean = sums / len(images)
        rows.append(row + [f"{mean[0]:.3f} / {mean[1]:.3f}", f"{xy:.2f}"])
        print(f"  {label}: {mean[0]:.3f} / {mean[1]:.3f}", file=sys.stderr, flush=True)
    print(f"Normal maps: angular error mean / p99 (degrees), corpus normal/, preset {args.preset}; "
          "BC5 decoded by texture2ddecoder, ASTC by astcenc; X/Y PSNR (dB) averaged over the images")
    table(["encoder", "bits/texel"] + [n.rsplit(".", 1)[0] for n, _ in images] + ["mean", "X/Y PSNR"], rows)


SECTIONS = {"ycocg": ycocg, "renorm": renorm, "normal": normal}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sections", default="ycocg,renorm,normal")
    ap.add_argument("--preset", default="medium")
    ap.add_argument("--corpus", type=Path, default=ROOT / "corpus")
    args = ap.parse_args()
    for name in args.sections.split(","):
        SECTIONS[name](args)


if __name__ == "__main__":
    main()
