"""--normal-metric angular: BC5 searched by the angle of the rebuilt normal."""

import numpy as np
import pytest

from texcook import codecs
from texcook.errors import UsageError
from texcook.image import read_image
from texcook.metrics import angular_summary, normal_angular_error, normal_angular_errors
from texcook.recipe import Recipe

from decoders import astcenc_decode
from reference import bc4_palette, percentile
from reference import normal_angles as ref_angles


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
    ref = ref_angles(a, b)
    s = angular_summary(a, b)
    assert (s["mean"], s["p99"], s["max"]) == pytest.approx((ref.mean(), percentile(ref, 99), ref.max()))
    assert normal_angular_error(a, b) == pytest.approx((ref.mean(), percentile(ref, 99)))
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


def test_indices_are_jointly_best_for_the_endpoints(rng):
    c = codecs.get("bc5")
    img = _normals(rng, 8)
    data = np.frombuffer(c.encode(img, "fast", angular=True), np.uint8).reshape(-1, 16)
    dec = c.decode(data.tobytes(), 8, 8)
    src = img[:4, :4].reshape(16, 4)
    blk = data[0]
    px, py = bc4_palette(int(blk[0]), int(blk[1])), bc4_palette(int(blk[8]), int(blk[9]))
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


# --- ASTC: the angular objective (texcook.codecs.astc.angular) ------------------------------

ASTC = "astc-6x6"  # the size the other ASTC tests compile and run


def _corpus_normals(corpus, size=96):
    """A crop of the corpus normal map with the most texels near the rim."""
    px = np.rint(read_image(corpus / "normal" / "ldr-xy-01.png").pixels * 255).astype(np.uint8)
    return np.ascontiguousarray(px[:size, :size])


def _astc_xy(c, data, w, h):
    from texcook.codecs.astc import normal_xy

    return normal_xy(c.decode(data, w, h))


def test_astc_angular_lowers_the_angle_on_a_corpus_normal_map(corpus):
    from texcook.codecs.astc import normal_xy

    c = codecs.get(ASTC)
    img = _corpus_normals(corpus)
    plain = c.encode(img, "medium", normal_map=True)
    angular = c.encode(img, "medium", normal_map=True, angular=True)
    assert angular != plain
    dec_p, dec_a = _astc_xy(c, plain, 96, 96), _astc_xy(c, angular, 96, 96)
    assert _cost(img, dec_a) < _cost(img, dec_p)
    (am, ap), (pm, pp) = normal_angular_error(img, dec_a), normal_angular_error(img, dec_p)
    assert am < pm * 0.97 and ap < pp
    # astcenc's decompressor reads the refined blocks as ours does
    assert np.array_equal(normal_xy(astcenc_decode(angular, 6, 6, 96, 96)), dec_a)


def test_astc_refinement_never_raises_a_blocks_cost(rng):
    """The refinement alone, on the X/Y search's blocks: every block's angular
    cost (measured on the decoded texture) is the same or lower, and the
    refined blocks pack."""
    from texcook.codecs._base import image_to_blocks
    from texcook.codecs.astc import angular as ang
    from texcook.codecs.astc import pack, to_rrrg

    c = codecs.get(ASTC)
    img = _normals(rng, 36)
    _, sym = c.encode_symbolic(img, "fast", normal_map=True)
    refined = sym.copy()
    blocks = np.ascontiguousarray(to_rrrg(image_to_blocks(img, 6, 6)))
    args = ang.kernel_args(6, 6, False)
    ang.refine_kernel(blocks, refined, np.int64(2), np.int64(ang.WEIGHT_STEPS), *args, np.zeros(len(sym)))
    costs = []
    for s in (sym, refined):
        out = np.zeros((s.shape[0], 16), np.uint8)
        assert pack.encode_symbolic_blocks(s, out) < 0
        dec = _astc_xy(c, out.tobytes(), 36, 36)
        per_texel = 1 - np.cos(np.radians(ref_angles(img, dec)))
        costs.append(per_texel.reshape(6, 6, 6, 6).sum(axis=(1, 3)).ravel())
        # the kernel's costs (0 rounds: measured only) are what the decoded texture shows
        mine = np.zeros(s.shape[0])
        ang.refine_kernel(blocks, s.copy(), np.int64(0), np.int64(ang.WEIGHT_STEPS), *args, mine)
        np.testing.assert_allclose(mine, costs[-1], atol=1e-9)
    assert (costs[1] <= costs[0] + 1e-12).all() and costs[1].sum() < costs[0].sum()


def _rim(rng, h, w):
    """Unit vectors on (and a little past) the rim: z near 0, where the angle
    is steepest in X and Y."""
    phi = np.linspace(0, 2 * np.pi, h * w).reshape(h, w) + rng.normal(0, 0.05, (h, w))
    r = np.clip(1.0 + rng.normal(0, 0.01, (h, w)), 0.97, 1.02)
    out = np.zeros((h, w, 4), np.uint8)
    out[..., 0] = np.clip(np.rint((r * np.cos(phi) * 0.5 + 0.5) * 255), 0, 255)
    out[..., 1] = np.clip(np.rint((r * np.sin(phi) * 0.5 + 0.5) * 255), 0, 255)
    out[..., 3] = 255
    return out


def test_astc_angular_hard_cases(rng):
    c = codecs.get(ASTC)
    flat = np.zeros((5, 7, 4), np.uint8)  # (0, 0, 1) everywhere: void-extent blocks, exact
    flat[..., :2] = 128
    flat[..., 2:] = 255
    dec = _astc_xy(c, c.encode(flat, "medium", normal_map=True, angular=True), 7, 5)
    assert (dec[..., :2] == 128).all()
    one = np.array([[[250, 3, 0, 255]]], np.uint8)  # past the rim: z rebuilt as 0
    dec = _astc_xy(c, c.encode(one, "medium", normal_map=True, angular=True), 1, 1)
    assert normal_angular_error(one, dec)[0] < 0.5
    for img in (_rim(rng, 13, 7), _normals(rng, 19)[:11]):  # odd sizes, partial blocks
        h, w = img.shape[:2]
        plain = _astc_xy(c, c.encode(img, "fast", normal_map=True), w, h)
        angular = _astc_xy(c, c.encode(img, "fast", normal_map=True, angular=True), w, h)
        assert normal_angular_error(img, angular)[0] < normal_angular_error(img, plain)[0]


def test_astc_angular_bytes_do_not_depend_on_threads(corpus):
    c = codecs.get(ASTC)
    img = _corpus_normals(corpus, 60)  # 100 blocks: several runs on several threads
    assert (c.encode(img, "fast", threads=1, normal_map=True, angular=True)
            == c.encode(img, "fast", threads=3, normal_map=True, angular=True))


def test_astc_angular_every_preset(rng):
    c = codecs.get(ASTC)
    img = _normals(rng, 12)
    for preset in c.presets:
        plain = _astc_xy(c, c.encode(img, preset, normal_map=True), 12, 12)
        angular = _astc_xy(c, c.encode(img, preset, normal_map=True, angular=True), 12, 12)
        assert _cost(img, angular) <= _cost(img, plain), preset


def test_astc_angular_needs_a_normal_map(rng):
    with pytest.raises(UsageError, match="normal_map"):
        codecs.get(ASTC).encode(_normals(rng, 8), "fast", angular=True)


def test_astc_recipe_bake_and_cli(tmp_path, cli_run, rng):
    import json

    from texcook.image import write_image
    from texcook.pipeline import bake_file, compare, load_texture

    r = Recipe.of(format=ASTC, normal_map=True, normal_metric="angular")
    assert dict(r.codec.options) == {"angular": True}
    with pytest.raises(UsageError, match="--normal-map"):
        Recipe.of(format=ASTC, normal_metric="angular")
    src = tmp_path / "n.png"
    write_image(src, _normals(rng, 40)[..., :3])
    outs = {}
    for metric in ("psnr", "angular"):
        outs[metric] = tmp_path / f"{metric}.ktx2"
        bake_file(src, outs[metric], Recipe.of(format=ASTC, normal_map=True, normal_metric=metric, mips=False))
    assert load_texture(outs["angular"]).normal_map
    got = {m: compare(src, p)["angular"] for m, p in outs.items()}
    assert got["angular"]["mean"] < got["psnr"]["mean"]
    out = tmp_path / "cli.ktx2"
    code, _, _ = cli_run("bake", src, "-o", out, "--format", ASTC, "--normal-map", "--normal-metric", "angular",
                         "--no-mips")
    assert code == 0 and out.read_bytes() == outs["angular"].read_bytes()
    code, stdout, _ = cli_run("compare", src, out, "--json")
    assert code == 0 and json.loads(stdout)["angular"] == pytest.approx(got["angular"])
    code, _, stderr = cli_run("bake", src, "-o", out, "--format", ASTC, "--normal-metric", "angular")
    assert code == 2 and "--normal-map" in stderr


# --- texcook compare: angles for normal maps -----------------------------------------------


def test_compare_reports_angles_for_a_normal_map_bake(tmp_path, cli_run, rng):
    import json

    from texcook.image import write_image
    from texcook.pipeline import load_texture

    src = tmp_path / "n.png"
    img = _normals(rng, 24)
    write_image(src, img[..., :3])
    out = tmp_path / "n.ktx2"
    assert cli_run("bake", src, "-o", out, "-f", "bc5", "--normal-map")[0] == 0
    code, stdout, _ = cli_run("compare", src, out, "--json")
    result = json.loads(stdout)
    dec = load_texture(out).levels[0]
    want = ref_angles(img, dec)
    assert result["normal_map"] and result["angular"]["mean"] == pytest.approx(want.mean())
    assert result["angular"]["p99"] == pytest.approx(percentile(want, 99))
    assert result["levels"][0]["angular"] == result["angular"]  # one level shared by both
    code, stdout, _ = cli_run("compare", src, out)
    assert code == 0 and "angle mean" in stdout.splitlines()[-1]
    # mip levels of two bakes: per level, and pooled over the levels
    other = tmp_path / "o.ktx2"
    assert cli_run("bake", src, "-o", other, "-f", "bc5", "--normal-map", "--normal-metric", "angular")[0] == 0
    result = json.loads(cli_run("compare", out, other, "--json")[1])
    assert len(result["levels"]) == 5 and all("angular" in row for row in result["levels"])


def test_compare_angles_of_plain_images_on_request(tmp_path, cli_run, rng):
    import json

    from texcook.image import write_image

    a = _normals(rng, 16)
    b = np.clip(a.astype(int) + rng.integers(-5, 6, a.shape), 0, 255).astype(np.uint8)
    pa, pb = tmp_path / "a.png", tmp_path / "b.png"
    write_image(pa, a)
    write_image(pb, b)
    assert "angular" not in json.loads(cli_run("compare", pa, pb, "--json")[1])
    result = json.loads(cli_run("compare", pa, pb, "--json", "--normal-map")[1])
    assert result["angular"]["mean"] == pytest.approx(ref_angles(a, b).mean())
    assert result["angular"]["max"] == pytest.approx(ref_angles(a, b).max())
    grey = tmp_path / "g.ktx2"  # BC4: one channel
    assert cli_run("bake", pa, "-o", grey, "-f", "bc4", "--no-mips")[0] == 0
    code, _, stderr = cli_run("compare", grey, grey, "--normal-map")
    assert code == 2 and "X and Y" in stderr and "g.ktx2" in stderr
