"""texcook preview: rasteriser, filters, reference, sampler choice and the CLI.

Golden frames live in tests/data/preview/; regenerate them on purpose with
TEXCOOK_REGEN_GOLDEN=1 (and look at them before committing)."""

import json
import math
import os
from pathlib import Path

import numpy as np
import pytest

from texcook.errors import InputError, UsageError
from texcook.image import read_image, write_image
from texcook.preview import FILTERS, render, save, scenes
from texcook.preview.raster import projection, rasterise, to_screen, triangle_setup
from texcook.preview.sample import Chain, lod_frame, padded_sat, parse_filter, sample_frame, wrap_texel
from texcook.preview.reference import blur_alias

GOLDEN = Path(__file__).parent / "data" / "preview"
REGEN = os.environ.get("TEXCOOK_REGEN_GOLDEN") == "1"


def checker(path, n=64, square=2):
    y, x = np.mgrid[0:n, 0:n]
    c = (((x // square) + (y // square)) % 2 * 255).astype(np.uint8)
    write_image(path, np.stack([c, c, c], axis=-1))
    return path


@pytest.fixture(scope="module")
def grazing(tmp_path_factory):
    """Every filter and the reference on a 2-texel checkerboard, plane scene."""
    path = checker(tmp_path_factory.mktemp("preview") / "checker.png")
    return render(path, scene="plane", filter="all", size=(96, 72))


# --- the acceptance ordering and goldens ---------------------------------------------------


def test_error_order_on_a_grazing_checkerboard(grazing):
    p = {row["filter"]: row["psnr"] for row in grazing.rows}
    assert p["nearest"] < p["bilinear"] < p["trilinear"] < p["aniso16"]
    assert p["trilinear"] < p["ewa"]
    assert p["trilinear"] + 2.0 < min(p["aniso16"], p["ewa"])  # clearly better, not by noise


def test_frames_are_finite_and_in_range(grazing):
    for frame in grazing.frames + [grazing.reference]:
        assert np.isfinite(frame.rgb).all(), frame.name
        assert frame.rgb.min() >= 0.0 and frame.rgb.max() <= 1.0
    for row in grazing.rows:
        assert all(math.isfinite(row[k]) for k in ("psnr", "blur_db", "alias_db", "seconds")), row
    assert grazing.valid.sum() > 0.4 * grazing.valid.size  # the plane fills much of the frame


def test_blur_and_aliasing_add_up_to_the_error(grazing):
    ref = grazing.reference.rgb
    for frame in grazing.frames:
        blur, alias = blur_alias(frame.rgb, ref, grazing.valid)
        mse = float(np.mean((frame.rgb[grazing.valid].astype(np.float64) - ref[grazing.valid]) ** 2))
        assert blur >= 0 and alias >= 0
        assert blur + alias == pytest.approx(mse, rel=1e-6)
    rows = {row["filter"]: row for row in grazing.rows}
    # nearest aliases more than trilinear, trilinear blurs more than aniso16
    assert rows["nearest"]["alias_db"] < rows["trilinear"]["alias_db"]
    assert rows["trilinear"]["blur_db"] < rows["aniso16"]["blur_db"]


@pytest.mark.parametrize("name", list(FILTERS) + ["reference"])
def test_golden_frames(grazing, name):
    frame = grazing.reference if name == "reference" else next(f for f in grazing.frames if f.name == name)
    got = np.clip(np.rint(frame.rgb * 255.0), 0, 255).astype(np.uint8)
    path = GOLDEN / f"{name}.png"
    if REGEN:
        GOLDEN.mkdir(parents=True, exist_ok=True)
        write_image(path, got)
    want = read_image(path).integer_values()
    assert want.shape == got.shape
    diff = np.abs(want.astype(int) - got.astype(int))
    # bit-exact on one machine; a little slack for another CPU's libm
    assert diff.max() <= 8 and np.mean(diff > 1) < 0.002, (name, diff.max())


def test_labelled_side_by_side(grazing, tmp_path):
    img = grazing.image
    # 6 filters + reference + level-of-detail map in a 4 x 2 grid, each under a label strip
    assert img.shape[1] == 4 * 96 + 3 * 2
    assert img.shape[0] > 2 * 72
    out = save(grazing, tmp_path / "all.png")
    assert read_image(out).integer_values().shape == img.shape


# --- rasteriser -----------------------------------------------------------------------------


def ray_cast_uv(sc, width, height, sx, sy):
    """u, v where the ray through pixel point (sx, sy) meets the quad scene's square."""
    fx, fy = projection(sc.fov_y, width, height)
    d = np.stack([(2.0 * sx / width - 1.0) / fx, (1.0 - 2.0 * sy / height) / fy, np.ones_like(sx)], axis=-1)
    c0, c1, c2 = sc.positions[0]  # corners 0, 1, 2 of the square; uv (0,0), (1,0), (1,1)
    eu, ev = c1 - c0, c2 - c1
    n = np.cross(eu, ev)
    t = np.dot(c0, n) / (d @ n)
    p = d * t[..., None] - c0
    return p @ eu / np.dot(eu, eu), p @ ev / np.dot(ev, ev)


def test_perspective_correct_interpolation_matches_ray_casting():
    sc = scenes.quad()
    w, h = 80, 60
    setup, boxes = triangle_setup(sc.positions, sc.uvs, sc.fov_y, w, h)
    gbuf, tri = rasterise(setup, boxes, w, h)
    ys, xs = np.nonzero(tri >= 0)
    assert len(xs) > 0.25 * w * h
    u, v = ray_cast_uv(sc, w, h, xs + 0.5, ys + 0.5)
    assert np.max(np.abs(gbuf[ys, xs, 0] - u)) < 1e-5
    assert np.max(np.abs(gbuf[ys, xs, 1] - v)) < 1e-5
    # analytic derivatives against central differences of the ray cast
    e = 1e-4
    for col, (dx, dy) in ((2, (e, 0)), (4, (0, e))):
        up, vp = ray_cast_uv(sc, w, h, xs + 0.5 + dx, ys + 0.5 + dy)
        um, vm = ray_cast_uv(sc, w, h, xs + 0.5 - dx, ys + 0.5 - dy)
        assert np.allclose(gbuf[ys, xs, col], (up - um) / (2 * e), rtol=1e-5, atol=1e-8)
        assert np.allclose(gbuf[ys, xs, col + 1], (vp - vm) / (2 * e), rtol=1e-5, atol=1e-8)


def test_affine_interpolation_would_be_wrong():
    """The tilted quad is really in perspective: screen-linear u differs."""
    sc = scenes.quad()
    w, h = 80, 60
    screen, _ = to_screen(sc.positions[0], sc.fov_y, w, h)
    centroid = screen.mean(axis=0)
    u, _ = ray_cast_uv(sc, w, h, centroid[:1], centroid[1:])
    assert abs(u[0] - sc.uvs[0][:, 0].mean()) > 0.02


@pytest.mark.parametrize("size", [(256, 192), (101, 77)])
def test_no_cracks_where_triangles_meet(size):
    """Pixel centres on the tunnel's corner edges (shared by two walls) are covered."""
    sc = scenes.tunnel()
    setup, boxes = triangle_setup(sc.positions, sc.uvs, sc.fov_y, *size)
    _, tri = rasterise(setup, boxes, *size)
    c = tri >= 0
    hole = ~c[1:-1, 1:-1] & c[:-2, 1:-1] & c[2:, 1:-1] & c[1:-1, :-2] & c[1:-1, 2:]
    assert not hole.any()
    assert (~c).sum() < 0.05 * c.size  # only the tunnel's far opening is empty


def test_nearest_surface_wins_and_background_stays_empty():
    # two overlapping fronto-parallel squares; the nearer one (z=2) must win
    sq = lambda z, u: ([(-1, 1, z), (1, 1, z), (1, -1, z)], [(u, 0), (u, 0), (u, 0)])
    (p0, t0), (p1, t1) = sq(4.0, 0.25), sq(2.0, 0.75)
    setup, boxes = triangle_setup([p0, p1], [t0, t1], math.radians(60), 40, 40)
    gbuf, tri = rasterise(setup, boxes, 40, 40)
    near = tri == 1
    assert near.any() and np.allclose(gbuf[near, 0], 0.75)
    assert (tri[0, :] == -1).all()  # the top row is outside both
    with pytest.raises(UsageError):
        triangle_setup([[(0, 0, -1), (1, 0, 1), (0, 1, 1)]], [[(0, 0)] * 3], 1.0, 8, 8)


# --- level of detail ------------------------------------------------------------------------


def front_quad(du_dx, dv_dx, du_dy, dv_dy, width=32, height=32, tex=64):
    """A fronto-parallel quad filling the frame whose texture coordinates have
    the given per-pixel derivatives (in level-0 texels of a tex x tex texture)."""
    sc_fov = math.radians(60)
    fx, fy = projection(sc_fov, width, height)
    z = 1.0
    # corners slightly outside the frame, with uv an affine function of the pixel position
    px = np.array([-2.0, width + 2.0, width + 2.0, -2.0])
    py = np.array([-2.0, -2.0, height + 2.0, height + 2.0])
    x = (2 * px / width - 1) / fx * z
    y = (1 - 2 * py / height) / fy * z
    u = (du_dx * px + du_dy * py) / tex
    v = (dv_dx * px + dv_dy * py) / tex
    c = np.stack([x, y, np.full(4, z)], axis=-1)
    t = np.stack([u, v], axis=-1)
    pos = np.stack([c[[0, 1, 2]], c[[0, 2, 3]]])
    uv = np.stack([t[[0, 1, 2]], t[[0, 2, 3]]])
    setup, boxes = triangle_setup(pos, uv, sc_fov, width, height)
    return rasterise(setup, boxes, width, height)


def constant_levels(tex=64):
    """A chain whose level i is the constant i / 16: a filter's output reads back its level."""
    levels, n = [], tex
    i = 0
    while True:
        levels.append(np.full((n, n, 4), i / 16.0, np.float32))
        if n == 1:
            return Chain(levels)
        n //= 2
        i += 1


@pytest.mark.parametrize(
    "derivs, want",
    [
        ((4, 0, 0, 4), 2.0),  # isotropic minification by 4
        ((8, 0, 0, 2), 3.0),  # anisotropic: the larger axis decides
        ((3, 3, -3, 3), math.log2(3 * math.sqrt(2))),  # rotated footprint
        ((0.5, 0, 0, 0.25), -1.0),  # magnification
        ((5, 1, 2, 7), math.log2(max(math.hypot(5, 1), math.hypot(2, 7)))),
    ],
)
def test_level_selection_is_the_opengl_formula(derivs, want):
    gbuf, tri = front_quad(*derivs)
    assert (tri >= 0).all()
    lam = lod_frame(gbuf, tri, 64, 64)
    assert np.allclose(lam, want, atol=1e-9)
    chain = constant_levels()
    tri_out = sample_frame("trilinear", gbuf, tri, chain)[..., 0]
    assert np.allclose(tri_out * 16, min(max(want, 0.0), 6.0), atol=1e-5)
    near = sample_frame("nearest_mipmap_nearest", gbuf, tri, chain)[..., 0]
    assert np.allclose(near * 16, min(max(math.ceil(want + 0.5) - 1, 0), 6) if want > 0 else 0.0)


def test_anisotropic_and_ewa_levels():
    gbuf, tri = front_quad(8, 0, 0, 2)  # Pmax 8, Pmin 2
    chain = constant_levels()
    # aniso16: 4 probes at log2(8 / 4) = 1; aniso2: 2 probes at log2(4) = 2
    assert np.allclose(sample_frame("aniso16", gbuf, tri, chain)[..., 0] * 16, 1.0, atol=1e-5)
    assert np.allclose(sample_frame("aniso2", gbuf, tri, chain)[..., 0] * 16, 2.0, atol=1e-5)
    # EWA: the minor axis (2 texels) picks level 1
    assert np.allclose(sample_frame("ewa", gbuf, tri, chain)[..., 0] * 16, 1.0, atol=1e-5)
    # EWA clamps eccentricity at 8: 64 x 2 becomes 64 x 8, level 3
    gbuf, tri = front_quad(64, 0, 0, 2)
    assert np.allclose(sample_frame("ewa", gbuf, tri, chain)[..., 0] * 16, 3.0, atol=1e-5)


# --- filters on their own ---------------------------------------------------------------------


@pytest.mark.parametrize("mode", ["clamp", "repeat", "mirror"])
def test_wrap_texel(mode):
    from texcook.preview.sample import WRAP_CODES

    n = 5
    idx = np.arange(-12, 13)
    got = np.array([wrap_texel(int(i), n, WRAP_CODES[mode]) for i in idx])
    want = {"clamp": np.clip(idx, 0, n - 1), "repeat": np.mod(idx, n),
            "mirror": np.where(np.mod(idx, 2 * n) >= n, 2 * n - 1 - np.mod(idx, 2 * n), np.mod(idx, 2 * n))}[mode]
    assert (got == want).all()


@pytest.mark.parametrize("name", list(FILTERS) + ["nearest_mipmap_linear", "aniso4"])
@pytest.mark.parametrize("wrap", [("repeat", "repeat"), ("clamp", "mirror")])
def test_constant_texture_stays_constant(name, wrap):
    colour = np.array([0.2, 0.5, 0.8, 0.6], np.float32)
    levels = [np.broadcast_to(colour, (n, m, 4)).copy() for n, m in ((12, 20), (6, 10), (3, 5), (1, 2), (1, 1))]
    sc = scenes.plane()
    setup, boxes = triangle_setup(sc.positions, sc.uvs * 3.0, sc.fov_y, 40, 30)
    gbuf, tri = rasterise(setup, boxes, 40, 30)
    tex = padded_sat(levels[0]) if name == "sat" else Chain(levels)
    out = sample_frame(name, gbuf, tri, tex, wrap)
    assert np.allclose(out[tri >= 0], colour, atol=1e-5)
    assert (out[tri < 0] == 0).all()


def _box_weights(lo, hi, n, mode):
    """Per texel of a wrapped axis, how much of [lo, hi] it covers (brute force)."""
    if mode == "clamp":  # the rectangle is clipped to the texture, or to the edge texel
        lo, hi = (0.0, 1.0) if hi <= 0 else (n - 1.0, float(n)) if lo >= n else (max(lo, 0.0), min(hi, n))
    j = np.arange(-4 * n, 5 * n)
    cover = np.clip(np.minimum(j + 1, hi) - np.maximum(j, lo), 0, None)
    k = np.mod(j, 2 * n)
    texel = {"repeat": np.mod(j, n), "mirror": np.where(k >= n, 2 * n - 1 - k, k), "clamp": np.clip(j, 0, n - 1)}[mode]
    return np.bincount(texel, cover, n)


@pytest.mark.parametrize("wrap", [("repeat", "repeat"), ("mirror", "clamp"), ("clamp", "mirror")])
def test_sat_is_the_box_mean_of_the_footprint(rng, wrap):
    texture = rng.random((8, 6, 4)).astype(np.float32)
    # footprint: 3 texels wide, 2 tall, reaching well past the texture's edges
    gbuf, tri = front_quad(3, 0, 0, 2, width=5, height=4, tex=1)
    gbuf[..., 0] = gbuf[..., 0] / 6 - 0.4  # u in units of the 6-texel width, some negative
    gbuf[..., 2] /= 6
    gbuf[..., 1] = gbuf[..., 1] / 8 - 0.3
    gbuf[..., 5] /= 8
    p, offset = padded_sat(texture)
    out = sample_frame("sat", gbuf, tri, (p, offset), wrap)
    for y in range(4):
        for x in range(5):
            s, t = gbuf[y, x, 0] * 6, gbuf[y, x, 1] * 8
            wx = _box_weights(s - 1.5, s + 1.5, 6, wrap[0])
            wy = _box_weights(t - 1.0, t + 1.0, 8, wrap[1])
            want = np.einsum("i,j,ijc->c", wy, wx, texture.astype(np.float64)) / (wx.sum() * wy.sum())
            assert np.allclose(out[y, x], want, atol=1e-5), (x, y)


def test_parse_filter(tmp_path):
    assert parse_filter("aniso") == ("aniso", 16)
    assert parse_filter("ANISO4") == ("aniso", 4)
    assert render(checker(tmp_path / "c.png", n=8), filter="SAT", size=(8, 8)).rows[0]["filter"] == "sat"
    for bad in ("bicubic", "aniso0", "aniso99", ""):
        with pytest.raises(UsageError):
            parse_filter(bad)


# --- textures, samplers, alpha ----------------------------------------------------------------


def test_one_texel_and_odd_sized_textures(tmp_path, corpus):
    one = tmp_path / "one.png"
    write_image(one, np.array([[[10, 200, 90]]], np.uint8))
    r = render(one, filter="all", size=(24, 16))
    assert all(np.isfinite(f.rgb).all() for f in r.frames)
    # a 1x1 frame of the tunnel sees only its open far end: nothing to measure, no NaN
    r = render(one, filter="all", scene="tunnel", size=(1, 1))
    assert not r.valid.any() and all(row["psnr"] is None for row in r.rows)
    r = render(corpus / "rgb" / "ldr-rgb-10.png", filter="all", scene="tunnel", size=(40, 30))
    assert all(np.isfinite(f.rgb).all() for f in r.frames)
    assert min(row["psnr"] for row in r.rows) > 10.0


def test_filters_without_mips_load_none_and_sat_only_for_sat(tmp_path, monkeypatch, corpus):
    import texcook.preview as preview

    src = corpus / "rgb" / "ldr-rgb-01.png"
    r = render(src, filter="bilinear", size=(16, 16))
    assert (r.levels_loaded, r.level_count) == (1, 9)
    assert render(src, filter="sat", size=(16, 16)).levels_loaded == 1
    assert render(src, filter="trilinear", size=(16, 16)).levels_loaded == 9

    def no_sat(*a, **k):
        raise AssertionError("SAT built for a filter that does not use it")

    monkeypatch.setattr(preview, "padded_sat", no_sat)
    render(src, filter="ewa", size=(16, 16))
    with pytest.raises(AssertionError):
        render(src, filter="sat", size=(16, 16))


def test_srgb_textures_are_filtered_in_linear_light(tmp_path):
    # a 1-texel black/white checker minified to grey: every level past 0 is 0.5 in
    # linear light, shown as sRGB 0.735, not the 0.5 filtering encoded values would give
    path = checker(tmp_path / "fine.png", n=64, square=1)
    r = render(path, filter="trilinear", size=(48, 36), scene="plane")
    far = (r.lod > 1.5) & r.valid
    assert far.any()
    assert np.allclose(r.frames[0].rgb[far], 0.735, atol=0.02)


def test_scene_json_sampler_and_flags(tmp_path, corpus):
    from texcook.pipeline import bake_file
    from texcook.recipe import Recipe

    tex = tmp_path / "wall.ktx2"
    bake_file(corpus / "rgb" / "ldr-rgb-01.png", tex, Recipe())
    r = render(tex, size=(16, 16))
    assert r.sampler == {"filter": "trilinear", "mag_linear": True, "wrap": ["repeat", "repeat"], "source": "default"}
    (tmp_path / "scene.json").write_text(json.dumps({"textures": [
        {"output": "other.ktx2", "sampler": {"minFilter": 9987}},
        {"output": "wall.ktx2", "sampler": {"minFilter": 9728, "magFilter": 9728, "wrapS": 33071, "wrapT": 33648}},
    ]}))
    r = render(tex, size=(16, 16))
    assert r.sampler == {"filter": "nearest", "mag_linear": False, "wrap": ["clamp", "mirror"], "source": "scene.json"}
    assert r.levels_loaded == 1
    r = render(tex, size=(16, 16), filter="ewa", wrap="repeat")
    assert r.sampler["filter"] == "ewa" and r.sampler["wrap"] == ["repeat", "repeat"]
    assert r.sampler["mag_linear"] is None  # as the named filter magnifies
    assert r.sampler["source"] == "scene.json+flags"
    # a cut-out material: the saved recipe carries the cutoff
    tex2 = tmp_path / "leaves.ktx2"
    bake_file(corpus / "rgba" / "ldr-rgba-01.png", tex2, Recipe.of(alpha_cutoff=0.4))
    (tmp_path / "scene.json").write_text(json.dumps({"textures": [
        {"output": "leaves.ktx2", "sampler": {}, "recipe": Recipe.of(alpha_cutoff=0.4).to_dict()}]}))
    r = render(tex2, size=(16, 16))
    assert (r.alpha_mode, r.alpha_cutoff, r.sampler["source"]) == ("mask", 0.4, "scene.json")
    (tmp_path / "scene.json").write_text("{not json")
    with pytest.raises(InputError):
        render(tex2, size=(16, 16))


def test_alpha_modes(corpus, tmp_path):
    src = corpus / "rgba" / "ldr-rgba-01.png"
    assert render(src, size=(16, 16)).alpha_mode == "blend"
    assert render(src, size=(16, 16), alpha_cutoff=0.5).alpha_mode == "mask"
    assert render(corpus / "rgb" / "ldr-rgb-01.png", size=(16, 16)).alpha_mode == "opaque"
    with pytest.raises(UsageError):
        render(corpus / "rgb" / "ldr-rgb-01.png", size=(16, 16), alpha_cutoff=0.5)


def test_alpha_cutoff_bake_keeps_coverage_in_far_mips(corpus, tmp_path):
    """A cut-out baked without --alpha-cutoff loses coverage in far mips; with it,
    coverage stays near the reference's (fraction of covered pixels)."""
    from texcook.pipeline import bake_file
    from texcook.recipe import Recipe

    src = corpus / "rgba" / "ldr-rgba-01.png"
    far = {}
    for cutoff in (None, 0.5):
        tex = tmp_path / f"cut{cutoff}.ktx2"
        bake_file(src, tex, Recipe.of(alpha_cutoff=cutoff))
        r = render(tex, scene="plane", filter="trilinear", reference=True, alpha_cutoff=0.5, size=(96, 96))
        summary = r.to_dict()
        far[cutoff] = (summary["filters"][0]["coverage_far"], summary["reference"]["coverage_far"])
    plain, kept = far[None], far[0.5]
    assert plain[1] == pytest.approx(kept[1])  # the same level 0, the same reference
    loss_plain = plain[1] - plain[0]
    loss_kept = abs(kept[1] - kept[0])
    assert loss_plain > 0.04
    assert loss_kept < loss_plain / 2


# --- CLI --------------------------------------------------------------------------------------


def test_cli_preview(cli_run, tmp_path, corpus):
    out = tmp_path / "view.png"
    code, stdout, _ = cli_run("preview", corpus / "rgb" / "ldr-rgb-02.png", "--filter", "all", "--size", "40x24",
                              "-o", out, "--json")
    assert code == 0
    data = json.loads(stdout)
    assert [row["filter"] for row in data["filters"]] == list(FILTERS)
    assert data["output"] == str(out)
    assert read_image(out).width == 4 * 40 + 3 * 2
    code, stdout, _ = cli_run("preview", corpus / "rgb" / "ldr-rgb-02.png", "--size", "32x32", "--reference",
                              "--scene", "quad")
    assert code == 0
    assert "trilinear" in stdout and "reference" in stdout


@pytest.mark.parametrize(
    "args, code",
    [
        (["--filter", "bicubic"], 2),
        (["--scene", "sphere"], 2),
        (["--size", "0x5"], 2),
        (["--size", "big"], 2),
        (["--wrap", "tile"], 2),
        (["--alpha-cutoff", "0.5"], 2),
        (["--alpha-cutoff", "1.5"], 2),
    ],
)
def test_cli_usage_errors(cli_run, corpus, args, code):
    rc, _, stderr = cli_run("preview", corpus / "rgb" / "ldr-rgb-02.png", "--size", "8x8", *args)
    assert rc == code
    assert stderr.count("\n") == 1


def test_cli_missing_and_broken_files(cli_run, tmp_path):
    rc, _, stderr = cli_run("preview", tmp_path / "none.ktx2")
    assert rc == 1 and "no such file" in stderr
    f = tmp_path / "x.astc"
    f.write_bytes(b"\x13\xab\xa1\x5c" + bytes(12))
    rc, _, stderr = cli_run("preview", f)
    assert rc == 1 and "x.astc" in stderr and stderr.count("\n") == 1


def test_astc_file(corpus, tmp_path):
    from texcook import codecs
    from texcook.container.astcfile import write_astc
    from texcook.pipeline import load_texture

    src = load_texture(corpus / "rgb" / "ldr-rgb-10.png").levels[0]  # 127x128: partial blocks
    h, w = src.shape[:2]
    data = codecs.get("astc-8x8").encode(np.ascontiguousarray(src), "fastest", 1)
    path = tmp_path / "t.astc"
    path.write_bytes(write_astc(8, 8, w, h, data))
    r = render(path, filter="bilinear", reference=True, size=(40, 30))
    assert not r.srgb and (r.levels_loaded, r.level_count) == (1, 1)
    assert r.rows[0]["psnr"] > 15.0


def test_cutoff_from_the_ktx2_key_value(corpus, tmp_path):
    from texcook.image import read_image as read
    from texcook.pipeline import bake, container_bytes
    from texcook.preview.source import ALPHA_CUTOFF_KEY
    from texcook.recipe import Recipe

    recipe = Recipe.of(alpha_cutoff=0.3)
    baked = bake(read(corpus / "rgba" / "ldr-rgba-01.png"), recipe)
    baked.kv[ALPHA_CUTOFF_KEY] = "0.3"
    path = tmp_path / "cut.ktx2"
    path.write_bytes(container_bytes(baked, "ktx2", recipe))
    r = render(path, size=(16, 16))
    assert (r.alpha_mode, r.alpha_cutoff) == ("mask", 0.3)
    assert render(path, size=(16, 16), alpha_cutoff=0.6).alpha_cutoff == 0.6  # the flag wins


def test_dds_input(corpus, tmp_path):
    from texcook.pipeline import bake_file
    from texcook.recipe import Recipe

    path = tmp_path / "t.dds"
    bake_file(corpus / "rgb" / "ldr-rgb-05.png", path, Recipe.of(format="bc1"))
    r = render(path, filter="trilinear", reference=True, size=(48, 32))
    assert r.srgb and r.levels_loaded == 9
    assert r.rows[0]["psnr"] > 15.0


def test_blended_constant_texture_matches_its_reference(tmp_path):
    """Alpha 0.5 over the checker: every filter and the reference agree with the
    blend computed by hand, in linear light."""
    from texcook.colour import linear_to_srgb, srgb_to_linear
    from texcook.preview.reference import background

    rgba = np.zeros((8, 8, 4), np.uint8)
    rgba[...] = (200, 100, 50, 128)
    path = tmp_path / "half.png"
    write_image(path, rgba)
    r = render(path, filter="all", size=(40, 30), scene="tunnel")
    assert r.alpha_mode == "blend"
    colour = srgb_to_linear(np.array([200, 100, 50], np.float64) / 255.0)
    a = 128 / 255.0
    want = linear_to_srgb(colour * a + background(40, 30) * (1.0 - a))
    for frame in r.frames + [r.reference]:
        got = frame.rgb[r.valid]
        assert np.allclose(got, want[r.valid], atol=1e-4), frame.name
    assert min(row["psnr"] for row in r.rows) > 60.0


def test_mag_filter_applies_where_magnified(rng):
    chain = Chain([rng.random((16, 16, 4)).astype(np.float32), rng.random((8, 8, 4)).astype(np.float32)])
    gbuf, tri = front_quad(0.3, 0.1, -0.1, 0.4, width=12, height=10, tex=16)  # lambda < 0 everywhere
    for mag_linear, same_as in ((False, "nearest"), (True, "bilinear")):
        got = sample_frame("trilinear", gbuf, tri, chain, mag_linear=mag_linear)
        assert np.array_equal(got, sample_frame(same_as, gbuf, tri, chain, mag_linear=mag_linear))
    # minified, the mag filter plays no part
    gbuf, tri = front_quad(3, 0, 0, 3, width=12, height=10, tex=16)
    assert np.array_equal(sample_frame("trilinear", gbuf, tri, chain, mag_linear=False),
                          sample_frame("trilinear", gbuf, tri, chain))


def test_extreme_float_values_stay_finite(tmp_path, rng):
    px = (rng.random((16, 12, 3)) * 1e4).astype(np.float32)
    px[0, 0] = 0.0
    px[1, 1] = 6.5e4
    path = tmp_path / "hot.exr"
    write_image(path, px)
    r = render(path, filter="all", size=(32, 24), scene="quad")
    assert not r.srgb
    for frame in r.frames + [r.reference]:
        assert np.isfinite(frame.rgb).all() and frame.rgb.max() <= 1.0


def test_preview_reads_the_sampler_texcook_scene_wrote(tmp_path, corpus):
    """End to end: a glTF cut-out material with a nearest/clamp sampler, baked by
    texcook scene; the preview of its output takes filter, wrap and cutoff from scene.json."""
    from texcook.scene import bake_scene

    model_dir = tmp_path / "model"
    model_dir.mkdir()
    pos = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32)
    uv = np.array([[0, 1], [1, 1], [1, 0], [0, 0]], np.float32)
    idx = np.array([0, 1, 2, 0, 2, 3], np.uint16)
    blob = pos.tobytes() + uv.tobytes() + idx.tobytes()
    (model_dir / "m.bin").write_bytes(blob)
    write_image(model_dir / "leaves.png", read_image(corpus / "rgba" / "ldr-rgba-01.png").integer_values())
    gltf = {
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "indices": 2, "material": 0}]}],
        "buffers": [{"uri": "m.bin", "byteLength": len(blob)}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 48, "target": 34962},
                        {"buffer": 0, "byteOffset": 48, "byteLength": 32, "target": 34962},
                        {"buffer": 0, "byteOffset": 80, "byteLength": 12, "target": 34963}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
                       "min": [0, 0, 0], "max": [1, 1, 0]},
                      {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC2"},
                      {"bufferView": 2, "componentType": 5123, "count": 6, "type": "SCALAR"}],
        "images": [{"uri": "leaves.png"}],
        "samplers": [{"minFilter": 9984, "magFilter": 9728, "wrapS": 33071, "wrapT": 33648}],
        "textures": [{"source": 0, "sampler": 0}],
        "materials": [{"name": "leaves", "alphaMode": "MASK", "alphaCutoff": 0.4,
                       "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}],
    }
    (model_dir / "m.gltf").write_text(json.dumps(gltf))
    out = tmp_path / "baked"
    report = bake_scene(model_dir / "m.gltf", out, preset="fastest")
    baked = out / os.path.basename(report["textures"][0]["output"])
    r = render(baked, size=(32, 24))
    assert r.sampler == {"filter": "nearest_mipmap_nearest", "mag_linear": False, "wrap": ["clamp", "mirror"],
                         "source": "scene.json"}
    assert (r.alpha_mode, r.alpha_cutoff) == ("mask", 0.4)


# --- limits and a scene.json from anywhere -------------------------------------------------


@pytest.fixture
def small_budget():
    from texcook.fileio import set_max_memory

    set_max_memory("64M")
    yield
    set_max_memory(None)


def test_frame_size_and_filters_are_held_to_the_memory_budget(tmp_path, small_budget, cli_run):
    tex = checker(tmp_path / "c.png", n=16)
    with pytest.raises(UsageError, match=r"1024x1024 preview with 1 filter\(s\) needs .* memory budget"):
        render(tex, filter="trilinear", size=(1024, 1024))
    render(tex, filter="trilinear", size=(64, 64))  # small frames still fit
    # the default budget: every filter and the reference at the largest size is refused before rendering
    from texcook.fileio import set_max_memory

    set_max_memory(None)
    code, _, stderr = cli_run("preview", tex, "--size", "4096x4096", "--filter", "all")
    assert code == 2 and "4096x4096 preview with 6 filter(s) and the reference" in stderr
    code, _, stderr = cli_run("--max-memory", "32M", "preview", tex, "--size", "512x512")
    assert code == 2 and "512x512 preview" in stderr and "32.0M memory budget" in stderr


def test_working_size_grows_with_filters_reference_and_texture():
    from texcook.preview import working_bytes

    one = working_bytes(512, 512, ["trilinear"], False)
    every = working_bytes(512, 512, list(FILTERS), True)
    assert 0 < one < every and working_bytes(1024, 1024, ["trilinear"], False) == 4 * one
    assert working_bytes(8, 8, ["sat"], False, (4096, 4096)) > working_bytes(8, 8, ["ewa"], False, (4096, 4096))


def _scene_json(folder, content):
    (folder / "scene.json").write_text(content if isinstance(content, str) else json.dumps(content))


@pytest.mark.parametrize("content, words", [
    ([{"output": "t.png"}], "expected an object"),  # a root that is a list
    ({"textures": {"output": "t.png"}}, "expected an object"),
    ({"textures": [{"output": 7}]}, "textures[0] is not an object with an \"output\""),
    ({"textures": [["t.png"]]}, "textures[0]"),
    ({"textures": [{"output": "t.png", "sampler": [9728]}]}, "sampler of t.png is not an object"),
    ({"textures": [{"output": "t.png", "sampler": {"minFilter": "9728"}}]}, "minFilter of t.png is '9728'"),
    ({"textures": [{"output": "t.png", "sampler": {"wrapS": True}}]}, "wrapS of t.png is True"),
    ({"textures": [{"output": "t.png", "sampler": {"minFilter": 1234}}]}, "not a glTF value"),
    ({"textures": [{"output": "t.png", "alphaCutoff": 2}]}, "within 0..1, not 2"),
    ('{"textures": [{"output": "t.png", "alphaCutoff": NaN}]}', "within 0..1, not nan"),
    ({"textures": [{"output": "t.png", "alphaCutoff": "half"}]}, "not 'half'"),
    ({"textures": [{"output": "t.png", "recipe": {"source": {"alpha_cutoff": -0.5}}}]}, "not -0.5"),
    ({"textures": [{"output": "t.png", "recipe": "fast"}]}, "recipe of t.png is not an object"),
    ("[" * 100000 + "]" * 100000, "nested too deeply"),
    ("{not json", "not readable JSON"),
])
def test_a_bad_scene_json_is_one_line_naming_it(tmp_path, content, words, cli_run):
    write_image(tmp_path / "t.png", np.full((8, 8, 4), 200, np.uint8))
    _scene_json(tmp_path, content)
    with pytest.raises(InputError, match="scene.json") as err:
        render(tmp_path / "t.png", size=(16, 16))
    assert words in str(err.value)
    code, _, stderr = cli_run("preview", tmp_path / "t.png", "--size", "16x16")
    assert code == 1 and len(stderr.strip().splitlines()) == 1 and "scene.json" in stderr


def test_entries_without_an_output_file_are_passed_over(tmp_path):
    # texcook scene writes no "output" for a texture that lives only inside the model (a GLB)
    write_image(tmp_path / "t.png", np.full((8, 8, 3), 200, np.uint8))
    _scene_json(tmp_path, {"textures": [{"texture": 0, "sampler": {"minFilter": 9728}},
                                        {"output": "t.png", "sampler": {"minFilter": 9729}}]})
    assert render(tmp_path / "t.png", size=(16, 16)).sampler["filter"] == "bilinear"


def test_a_scene_json_fifo_is_refused_at_once(tmp_path):
    write_image(tmp_path / "t.png", np.full((8, 8, 3), 200, np.uint8))
    os.mkfifo(tmp_path / "scene.json")
    with pytest.raises(InputError, match="pipe"):
        render(tmp_path / "t.png", size=(16, 16))  # opening it to read would block for ever


@pytest.mark.parametrize("min_filter, mag_filter, want, mag_linear", [
    (9728, 9728, "nearest", False), (9729, 9729, "bilinear", True),
    (9984, None, "nearest_mipmap_nearest", True), (9985, 9728, "linear_mipmap_nearest", False),
    (9986, None, "nearest_mipmap_linear", True), (9987.0, 9729.0, "trilinear", True),
    # a mipmap filter as magFilter (not allowed by glTF, written by exporters): magnifies by its first word
    (9987, 9987, "trilinear", True), (9728, 9984, "nearest", False),
])
def test_every_gltf_filter_value_maps_to_a_preview_filter(tmp_path, min_filter, mag_filter, want, mag_linear):
    write_image(tmp_path / "t.png", np.full((8, 8, 3), 200, np.uint8))
    _scene_json(tmp_path, {"textures": [{"output": "t.png",
                                         "sampler": {"minFilter": min_filter, "magFilter": mag_filter}}]})
    r = render(tmp_path / "t.png", size=(16, 16))
    assert (r.sampler["filter"], r.sampler["mag_linear"], r.sampler["source"]) == (want, mag_linear, "scene.json")


def test_a_cut_out_is_shown_where_its_edge_is_in_view(corpus, tmp_path):
    """An alpha-tested texture is shown on the quad: the whole texture once, so
    kept and cut-away texels (and the edge between them) share the view; the
    grazing plane shows mostly far repeats where the test is decided by mips."""
    from texcook.pipeline import bake_file
    from texcook.recipe import Recipe

    tex = tmp_path / "leaves.ktx2"
    bake_file(corpus / "rgba" / "ldr-rgba-00.png", tex, Recipe.of(alpha_cutoff=0.5))
    r = render(tex, size=(128, 96))
    assert (r.scene, r.alpha_mode) == ("quad", "mask")
    on = r.valid
    kept = float(r.frames[0].covered[on].mean())
    assert 0.2 < kept < 0.9  # both sides of the cutoff in view (0.80 here; the plane's frame: 0.93)
    # the edge: kept pixels next to cut ones, along many rows
    cov = np.where(on, r.frames[0].covered, np.nan)
    edge_rows = np.count_nonzero(np.nansum(np.abs(np.diff(cov, axis=1)), axis=1) > 0)
    assert edge_rows > 0.5 * np.count_nonzero(on.any(axis=1))
    assert render(tex, scene="plane", size=(32, 24)).scene == "plane"  # a named scene is kept
    opaque = tmp_path / "wall.ktx2"
    bake_file(corpus / "rgb" / "ldr-rgb-01.png", opaque, Recipe())
    assert render(opaque, size=(32, 24)).scene == "plane"
