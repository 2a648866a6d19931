"""A wider hash matrix than tests/golden_bakes.py, for refactors of the codecs
and the pipeline: every corpus image in every non-ASTC format and preset, every
ASTC block size at the three quick presets on one image of each kind, the slow
ASTC presets at four block sizes, and recipe variants (normal maps, linear
output, filters, wrap, premultiplied and alpha-tested mips, DDS).

    python tests/golden_matrix.py --write   # record (only on purpose)
    python tests/golden_matrix.py           # check, list what differs
    python tests/golden_matrix.py -j 2      # on two processes
    python tests/golden_matrix.py --only bc4,bc5   # the cases of these formats
    python tests/golden_matrix.py --only bc4 --write   # record these, keep the others

The normal run takes several minutes; it is not part of the test suite.
"""

import hashlib
import json
import pathlib
import sys

ROOT = pathlib.Path(__file__).resolve().parent.parent
HASHES = ROOT / "tests" / "data" / "bake_hashes_wide.json"
PRESETS = ("fastest", "fast", "medium", "thorough", "exhaustive")
PLAIN = ("rgba8", "rg8", "r8", "rgba16f", "rgba32f", "bc1", "bc1a", "bc3", "bc4", "bc5", "etc1", "bc3-ycocg")
ASTC = ("astc-4x4", "astc-5x4", "astc-5x5", "astc-6x5", "astc-6x6", "astc-8x5", "astc-8x6", "astc-8x8",
        "astc-10x5", "astc-10x6", "astc-10x8", "astc-10x10", "astc-12x10", "astc-12x12")
KINDS = ("rgb/ldr-rgb-03.png", "rgba/ldr-rgba-00.png", "normal/ldr-xy-01.png")
VARIANTS = {
    "normal": dict(normal_map=True),
    "linear": dict(srgb=False),
    "lanczos-clamp": dict(mip_filter="lanczos", wrap=("clamp", "clamp")),
    "kaiser-mirror": dict(mip_filter="kaiser", wrap=("mirror", "repeat")),
    "premultiply": dict(premultiply=True),
    "cutoff": dict(alpha_cutoff=0.5),
    "nomips": dict(mips=False),
}


def cases():
    """(key, image, flat recipe, container) for every case of the matrix."""
    images = sorted(p.relative_to(ROOT / "corpus").as_posix()
                    for p in (ROOT / "corpus").rglob("*") if p.suffix in (".png", ".hdr"))
    out = []
    for img in images:
        for fmt in PLAIN:
            for preset in PRESETS if fmt.startswith(("bc", "etc")) else ("medium",):
                out.append((f"{img}:{fmt}:{preset}", img, dict(format=fmt, preset=preset), "ktx2"))
    for img in KINDS:
        for fmt in ASTC:
            for preset in ("fastest", "fast", "medium"):
                out.append((f"{img}:{fmt}:{preset}", img, dict(format=fmt, preset=preset), "ktx2"))
    for fmt in ("astc-4x4", "astc-6x6", "astc-8x8", "astc-12x12"):
        for preset in ("thorough", "exhaustive"):
            out.append((f"{KINDS[0]}:{fmt}:{preset}", KINDS[0], dict(format=fmt, preset=preset), "ktx2"))
    for img in KINDS:
        for fmt in ("bc1", "bc3", "bc5", "etc1", "astc-4x4", "astc-6x6", "rgba8"):
            for name, flat in VARIANTS.items():
                out.append((f"{img}:{fmt}:fast:{name}", img, dict(format=fmt, preset="fast", **flat), "ktx2"))
        for fmt in ("bc1", "bc1a", "bc3", "bc4", "bc5", "rgba8"):
            out.append((f"{img}:{fmt}:fast:dds", img, dict(format=fmt, preset="fast"), "dds"))
    return out


def bake_hash(case):
    from texcook.image import read_image
    from texcook.pipeline import bake, container_bytes
    from texcook.recipe import Recipe

    key, img, flat, container = case
    try:
        recipe = Recipe.of(**flat)
        data = container_bytes(bake(read_image(ROOT / "corpus" / img), recipe, container, threads=1), container,
                               recipe)
        return key, hashlib.sha256(data).hexdigest()
    except Exception as exc:  # a refusal is part of the behaviour too
        return key, f"error: {type(exc).__name__}"


def compute(jobs=1, only=None):
    todo = [c for c in cases() if only is None or c[2]["format"] in only]
    if jobs > 1:
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(jobs) as pool:
            return dict(pool.map(bake_hash, todo, chunksize=4))
    return dict(map(bake_hash, todo))


if __name__ == "__main__":
    jobs = int(sys.argv[sys.argv.index("-j") + 1]) if "-j" in sys.argv else 1
    only = set(sys.argv[sys.argv.index("--only") + 1].split(",")) if "--only" in sys.argv else None
    got = compute(jobs, only)
    if "--write" in sys.argv:
        # with --only, the other formats' pins are kept as they are
        pinned = dict(json.loads(HASHES.read_text()), **got) if only is not None else got
        HASHES.write_text(json.dumps(pinned, indent=1, sort_keys=True) + "\n")
        print(f"wrote {len(got)} hashes")
        sys.exit(0)
    want = json.loads(HASHES.read_text())
    if only is not None:
        want = {k: v for k, v in want.items() if k.split(":")[1] in only}
    bad = sorted(k for k in set(want) | set(got) if got.get(k) != want.get(k))
    for k in bad:
        print("differs:", k, want.get(k, "-")[:16], got.get(k, "-")[:16])
    print(f"{len(want) - len(bad)}/{len(want)} identical")
    sys.exit(1 if bad else 0)
