"""Rank ASTC block modes by how often they win, per block size, and write
texcook/codecs/astc/mode_ranks.py (the fast presets search only the modes that
cover a given share of the wins).

    python bench/astc_mode_ranks.py [--preset medium] [--sizes 4x4,6x6] [--out PATH]
    python bench/astc_mode_ranks.py --keep-ranks   # same ranks, trimmed and fingerprinted again

Training images are NOT the benchmark corpus (corpus/rgb, corpus/rgba): the
photograph and the RGBA drawing that ship in matplotlib's sample data, the
corpus HDR image tone-mapped to 8 bits, and the corpus normal maps read as
plain RGB textures. Every image is encoded with the given preset (all block
modes searched) and each block with one or two partitions counts one win for
its (grid width, grid height, weight range, planes). Each size's list stops
where the presets stop reading it (presets.rows_read at the largest share
below 1000 any preset gives the size).

The header records a fingerprint of what the ranking depends on: the
settings, the training images and the symbolic blocks the search makes of a
small crop at every block size. tests/test_astc_mode_ranks.py recomputes it
in a few seconds: when the search or the images change, it fails until the
file is written again: measured again (which changes what the fast presets
try, and so their output), or with --keep-ranks, which keeps the ranks and
records today's fingerprint (for a search change meant to keep the tuning).
"""

import argparse
import hashlib
import os

import numpy as np
import OpenImageIO as oiio

from texcook import codecs
from texcook.codecs.astc import BLOCK_SIZES, presets
from texcook.codecs.astc.symbolic import KIND_NORMAL, S_DUAL, S_GRID_H, S_GRID_W, S_KIND, S_PARTS
from texcook.codecs.astc.symbolic import S_WQUANT

HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "..", "texcook", "codecs", "astc", "mode_ranks.py")
KEEP = 0.999  # the ranking counts modes until this share of the wins (then trimmed to what presets read)
PROBE = 40  # side of the fingerprint's crop (cut to whole blocks): seconds, not minutes


def _rgba(px):
    out = np.full(px.shape[:2] + (4,), 255, np.uint8)
    out[:, :, :min(4, px.shape[2])] = px[:, :, :4]
    return out


def training_images():
    import matplotlib

    sample = os.path.join(os.path.dirname(matplotlib.__file__), "mpl-data", "sample_data")
    corpus = os.path.join(HERE, "..", "corpus")
    spec = oiio.ImageSpec()
    spec.attribute("oiio:UnassociatedAlpha", 1)
    images = []
    for name in ("grace_hopper.jpg", "Minduka_Present_Blue_Pack.png"):
        images.append(_rgba(oiio.ImageBuf(os.path.join(sample, name), 0, 0, spec)
                            .get_pixels(oiio.UINT8)))
    for sub, ext in (("hdr", ".hdr"), ("normal", ".png")):
        for name in sorted(os.listdir(os.path.join(corpus, sub))):
            if not name.endswith(ext):
                continue
            px = oiio.ImageBuf(os.path.join(corpus, sub, name)).get_pixels(oiio.FLOAT)
            if ext == ".hdr":
                # Reinhard, then the sRGB curve: an ordinary 8-bit photograph
                px = px / (1.0 + px)
                px = np.where(px <= 0.0031308, 12.92 * px, 1.055 * np.power(px, 1 / 2.4) - 0.055)
            images.append(_rgba(np.clip(px * 255.0 + 0.5, 0, 255).astype(np.uint8)))
    return images


def rank(bw, bh, preset, images):
    codec = codecs.get(f"astc-{bw}x{bh}")
    counts = {}
    for img in images:
        h, w = img.shape[0] // bh * bh, img.shape[1] // bw * bw
        _, sym = codec.encode_symbolic(np.ascontiguousarray(img[:h, :w]), preset, threads=1)
        sel = (sym[:, S_KIND] == KIND_NORMAL) & (sym[:, S_PARTS] <= 2)
        for r in sym[sel]:
            key = (int(r[S_GRID_W]), int(r[S_GRID_H]), int(r[S_WQUANT]), int(r[S_DUAL]))
            counts[key] = counts.get(key, 0) + 1
    total = sum(counts.values())
    ranked = sorted(counts.items(), key=lambda kv: (-kv[1], kv[0]))
    rows, acc = [], 0
    for key, n in ranked:
        acc += n
        rows.append(key + (round(1000 * acc / total),))
        if acc >= KEEP * total:
            break
    return trim(bw, bh, rows), total


def fingerprint(images, preset):
    """sha256 of what a ranking depends on, cheap to recompute: the settings,
    the training images, and the symbolic blocks the search makes of a crop of
    the first image at every block size (a changed search shows there)."""
    h = hashlib.sha256(f"{preset} {KEEP} {PROBE}".encode())
    for img in images:
        h.update(np.ascontiguousarray(img).tobytes())
    for bw, bh in BLOCK_SIZES:
        probe = np.ascontiguousarray(images[0][:PROBE // bh * bh, :PROBE // bw * bw])
        _, sym = codecs.get(f"astc-{bw}x{bh}").encode_symbolic(probe, preset, threads=1)
        h.update(sym.tobytes())
    return h.hexdigest()


def kept_ranks(path):
    """(preset, [(bw, bh, rows, blocks counted)]) of an existing mode_ranks.py,
    its rows trimmed to what the presets read now."""
    import re

    with open(path) as f:
        text = f.read()
    space = {}
    exec(compile(text, path, "exec"), space)
    totals = {(int(w), int(h)): int(n) for w, h, n in re.findall(r"\((\d+), (\d+)\): \(  # (\d+) blocks", text)}
    return space.get("PRESET", "medium"), [(bw, bh, trim(bw, bh, list(rows)), totals[(bw, bh)])
                                           for (bw, bh), rows in space["RANKS"].items()]


def trim(bw, bh, rows):
    """The rows some preset reads at this size (presets.rows_read at the largest share below 1000)."""
    shares = presets.shares_read(bw, bh)
    return rows[:presets.rows_read(rows, shares[-1])] if shares else []


def render(preset, fp, ranked, kept=False):
    """The text of mode_ranks.py: ranked is (bw, bh, rows, blocks counted) per size;
    kept: the ranks come from an earlier measurement (--keep-ranks)."""
    lines = [
        '"""GENERATED by bench/astc_mode_ranks.py; do not edit. Regenerate with',
        f"    python bench/astc_mode_ranks.py --preset {preset}",
        "(every block size, on one core; tests/test_astc_mode_ranks.py says when).",
        "",
        "Block modes ranked by how often they win, per block size, measured on",
        "images outside the benchmark corpus (see the script): every block with one",
        f"or two partitions of the `{preset}` search counts one win for its mode.",
        "Per size: (grid w, grid h, weight range, dual plane, cumulative share of",
        "the wins in 1/1000), most frequent first, as far as the presets read.",
    ] + ([
        "",
        "The ranks come from an earlier measurement, kept (--keep-ranks) so that",
        "what the fast presets try stays as tuned; the fingerprint is of the",
        "inputs when they were kept.",
    ] if kept else []) + [
        '"""',
        "",
        f'PRESET = "{preset}"',
        f'FINGERPRINT = "{fp}"  # of the inputs (bench/astc_mode_ranks.py fingerprint)',
        "",
        "RANKS = {",
    ]
    for bw, bh, rows, total in ranked:
        lines.append(f"    ({bw}, {bh}): (  # {total} blocks")
        for r in rows:
            lines.append(f"        {r},")
        lines.append("    ),")
    lines.append("}")
    return "\n".join(lines) + "\n"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--preset", default="medium")
    ap.add_argument("--sizes", default=",".join(f"{w}x{h}" for w, h in BLOCK_SIZES))
    ap.add_argument("--out", default=OUT)
    ap.add_argument("--keep-ranks", action="store_true",
                    help="keep the ranks of the existing --out file; trim them and record today's fingerprint")
    args = ap.parse_args()
    images = training_images()
    if args.keep_ranks:
        preset, ranked = kept_ranks(args.out)
        with open(args.out, "w") as f:
            f.write(render(preset, fingerprint(images, preset), ranked, kept=True))
        return
    ranked = []
    for size in args.sizes.split(","):
        bw, bh = (int(v) for v in size.split("x"))
        rows, total = rank(bw, bh, args.preset, images)
        print(f"{size}: {total} blocks, {len(rows)} modes", flush=True)
        ranked.append((bw, bh, rows, total))
    with open(args.out, "w") as f:
        f.write(render(args.preset, fingerprint(images, args.preset), ranked))


if __name__ == "__main__":
    main()
