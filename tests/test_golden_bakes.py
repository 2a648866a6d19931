"""Bytes pinned before the pipeline refactor stay the same: one image of each
corpus folder in every format (tests/golden_bakes.py checks all of them)."""

import json

import pytest

from golden_bakes import FORMATS, HASHES, ROOT, bake_hash

PINNED = json.loads(HASHES.read_text())
IMAGES = ["rgb/ldr-rgb-10.png", "rgba/ldr-rgba-01.png", "normal/ldr-xy-00.png", "hdr/hdr-rgb-00.hdr"]


@pytest.mark.parametrize("image", IMAGES)
def test_bakes_are_byte_identical(image):
    changed = [fmt for fmt in FORMATS if bake_hash(ROOT / "corpus" / image, fmt) != PINNED[f"{image}:{fmt}"]]
    assert changed == []
