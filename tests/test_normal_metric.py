"""--normal-metric angular: BC5 searched by the angle of the rebuilt normal."""

import numpy as np
import pytest

from texcook import codecs
from texcook.errors import UsageError
from texcook.image import read_image
from texcook.metrics import angular_summary, normal_angular_error, normal_angular_errors
from texcook.recipe import Recipe


def ref_angles(a, b):
    """Readable reference: unit normals from X, Y with Z rebuilt, angle by arccos."""
    def unit(px):
        x = px[..., 0] / 255.0 * 2 - 1
        y = px[..., 1] / 255.0 * 2 - 1
        z = np.sqrt(np.maximum(0.0, 1 - x * x - y * y))
        v = np.stack([x, y, z], axis=-1)
        return v / np.linalg.norm(v, axis=-1, keepdims=True)

    return np.degrees(np.arccos(np.clip((unit(a) * unit(b)).sum(-1), -1, 1)))


def _normals(rng, n=32):
    """A bumpy normal map as unorm8 X, Y, Z."""
    y, x = np.mgrid[0:n, 0:n] / n
    h = np.sin(7 * x + 3 * y) * 0.6 + np.cos(11 * y) * 0.4 + rng.normal(0, 0.02, (n, n))
    gx, gy = np.gradient(h * 4)
    v = np.stack([-gx, -gy, np.ones_like(gx)], axis=-1)
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    out = np.full((n, n, 4), 255, np.uint8)
    out[..., :3] = np.clip(np.rint((v * 0.5 + 0.5) * 255), 0, 255)
    return out


def test_metrics_match_reference(rng):
    a = _normals(rng)
    b = np.clip(a.astype(int) + rng.integers(-6, 7, a.shape), 0, 255).astype(np.uint8)
    np.testing.assert_allclose(normal_angular_errors(a, b), ref_angles(a, b).ravel(), atol=1e-6)
    s = angular_summary(a, b)
    assert (s["mean"], s["p99"]) == pytest.approx(normal_angular_error(a, b))
    assert s["max"] == pytest.approx(ref_angles(a, b).max())
    assert angular_summary(a, a) == {"mean": 0.0, "p99": 0.0, "max": 0.0}


def _cost(src, dec):
    return float((1 - np.cos(np.radians(normal_angular_errors(src, dec)))).sum())


@pytest.mark.parametrize("preset", ["fastest", "medium"])
def test_angular_search_lowers_the_angle(rng, preset):
    c = codecs.get("bc5")
    img = _normals(rng)
    psnr_dec = c.decode(c.encode(img, preset), 32, 32)
    ang_dec = c.decode(c.encode(img, preset, angular=True), 32, 32)
    # it starts from the X/Y result and keeps only what lowers the angular cost
    assert _cost(img, ang_dec) < _cost(img, psnr_dec)
    a, p = normal_angular_error(img, ang_dec), normal_angular_error(img, psnr_dec)
    assert a[0] < p[0] and a[1] <= p[1] + 1e-9


def _palette(r0, r1, pal):
    """BC4's eight values from its two endpoints (readable reference)."""
    pal[:2] = r0, r1
    if r0 > r1:
        pal[2:] = [((7 - i) * r0 + i * r1) // 7 for i in range(1, 7)]
    else:
        pal[2:6] = [((5 - i) * r0 + i * r1) // 5 for i in range(1, 5)]
        pal[6:] = 0, 255


def test_indices_are_jointly_best_for_the_endpoints(rng):
    c = codecs.get("bc5")
    img = _normals(rng, 8)
    data = np.frombuffer(c.encode(img, "fast", angular=True), np.uint8).reshape(-1, 16)
    dec = c.decode(data.tobytes(), 8, 8)
    px, py = np.empty(8, np.int64), np.empty(8, np.int64)
    src = img[:4, :4].reshape(16, 4)
    blk = data[0]
    _palette(int(blk[0]), int(blk[1]), px)
    _palette(int(blk[8]), int(blk[9]), py)
    # every (X, Y) pair of palette values for every texel of the first block
    grid = np.stack(np.meshgrid(px, py, indexing="ij"), axis=-1).reshape(-1, 2)
    for t in range(16):
        cand = np.zeros((64, 4), np.uint8)
        cand[:, :2] = grid
        costs = 1 - np.cos(np.radians(ref_angles(np.repeat(src[t:t + 1], 64, 0), cand)))
        got = dec[t // 4, t % 4]
        mine = 1 - np.cos(np.radians(ref_angles(src[t:t + 1], got[None])))[0]
        assert mine <= costs.min() + 1e-12


def test_flat_and_small_images():
    c = codecs.get("bc5")
    flat = np.zeros((5, 7, 4), np.uint8)
    flat[..., :2] = 128
    flat[..., 2:] = 255
    dec = c.decode(c.encode(flat, "medium", angular=True), 7, 5)
    assert (dec[..., :2] == 128).all()
    one = np.array([[[250, 3, 0, 255]]], np.uint8)  # past the rim: z rebuilt as 0
    dec = c.decode(c.encode(one, "medium", angular=True), 1, 1)
    assert normal_angular_error(one, dec)[0] < 0.5


def test_corpus_normal_map_p99_improves(corpus):
    c = codecs.get("bc5")
    img = np.rint(read_image(corpus / "normal" / "ldr-xy-00.png").pixels * 255).astype(np.uint8)[:64, :64].copy()
    plain = normal_angular_error(img, c.decode(c.encode(img, "medium"), 64, 64))
    angular = normal_angular_error(img, c.decode(c.encode(img, "medium", angular=True), 64, 64))
    assert angular[0] < plain[0] and angular[1] < plain[1]


def test_recipe_and_cli(tmp_path, cli_run, rng):
    r = Recipe.of(format="bc5", normal_map=True, normal_metric="angular")
    assert dict(r.codec.options) == {"angular": True}
    assert Recipe.from_dict(r.to_dict()) == r
    assert r.replace(normal_metric="psnr") == Recipe.of(format="bc5", normal_map=True)
    for bad in ({"format": "bc5", "normal_metric": "angular"},  # not a normal map
                {"format": "bc1", "normal_map": True, "normal_metric": "angular"},
                {"format": "bc5", "normal_map": True, "normal_metric": "cosine"}):
        with pytest.raises(UsageError):
            Recipe.of(**bad)
    from texcook.image import write_image

    src = tmp_path / "n.png"
    write_image(src, _normals(rng)[..., :3])
    out = tmp_path / "n.ktx2"
    code, _, _ = cli_run("bake", src, "-o", out, "-f", "bc5", "--normal-map", "--normal-metric", "angular")
    assert code == 0
    code, _, stderr = cli_run("bake", src, "-o", out, "-f", "bc5", "--normal-metric", "angular")
    assert code == 2 and "--normal-map" in stderr
