"""Hashes of every corpus image baked to every pre-existing format, so that a
refactor of the pipeline can show it changed no byte.

    python tests/golden_bakes.py --write   # record (only on purpose)
    python tests/golden_bakes.py           # check, list what differs
"""

import hashlib
import json
import pathlib
import sys

ROOT = pathlib.Path(__file__).resolve().parent.parent
HASHES = ROOT / "tests" / "data" / "bake_hashes.json"
FORMATS = ("rgba8", "rg8", "r8", "rgba16f", "rgba32f", "bc1", "bc1a", "bc3", "bc4", "bc5", "etc1")


def corpus_images():
    return sorted(p for p in (ROOT / "corpus").rglob("*") if p.suffix in (".png", ".hdr"))


def bake_hash(image_path, fmt, container="ktx2"):
    from texcook.image import read_image
    from texcook.pipeline import bake, container_bytes
    from texcook.recipe import Recipe

    recipe = Recipe.of(format=fmt, preset="fast")
    data = container_bytes(bake(read_image(image_path), recipe, container), container, recipe)
    return hashlib.sha256(data).hexdigest()


def compute(images=None, formats=FORMATS):
    out = {}
    for img in images or corpus_images():
        for fmt in formats:
            key = f"{img.relative_to(ROOT / 'corpus')}:{fmt}"
            try:
                out[key] = bake_hash(img, fmt)
            except Exception as exc:  # a refusal is part of the behaviour too
                out[key] = f"error: {type(exc).__name__}"
    return out


if __name__ == "__main__":
    got = compute()
    if "--write" in sys.argv:
        HASHES.write_text(json.dumps(got, indent=1, sort_keys=True) + "\n")
        print(f"wrote {len(got)} hashes")
        sys.exit(0)
    want = json.loads(HASHES.read_text())
    bad = [k for k in want if got.get(k) != want[k]]
    for k in bad:
        print("differs:", k)
    print(f"{len(want) - len(bad)}/{len(want)} identical")
    sys.exit(1 if bad else 0)
