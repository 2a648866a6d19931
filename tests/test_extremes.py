"""Extreme finite values: nothing NaN or Inf is ever written where the source
had none (docs/reliability.md, Float hygiene).

Tiny odd-sized float images holding denormals, 1e-38, the half-float limit
and the value just past it, 1e30 and 3.4e38 (each with its negative, alone,
as a +-checker, mixed in one image, and a ramp over the whole float32 range)
are baked through every format, mip filter, wrap mode and option set, and
every level is read back with texcook's own readers: the stored values
(read_ktx2 and the codec's decoder) and the values a reader gets
(load_texture, which undoes the recorded transforms). Float formats must hold
finite values within their range; 8-bit and block formats clamp. Every
option meets every extreme at least once; the full product runs with
TEXCOOK_LONG=1.
"""

import itertools
import json
import os

import numpy as np
import pytest

from texcook import codecs, formats
from texcook.container.ktx2 import read_ktx2, read_texture
from texcook.container.levels import level_dims
from texcook.errors import InputError
from texcook.image import Image, write_image
from texcook.mips import scale_alpha_to_coverage
from texcook.pipeline import bake, container_bytes, load_texture
from texcook.recipe import Recipe

pytestmark = pytest.mark.filterwarnings("error::RuntimeWarning")  # a numpy overflow warning fails a test

LONG = os.environ.get("TEXCOOK_LONG") == "1"
F32_MAX = float(np.finfo(np.float32).max)
EXTREMES = (1e-45, 1e-38, 65504.0, 65520.0, 1e30, 3.4e38)
FILTERS = ("box", "triangle", "lanczos", "kaiser")
WRAPS = ("clamp", "repeat", "mirror", "clamp,repeat")
# (name, recipe settings, colour space of the source)
OPTIONS = (
    ("plain", {}, "linear"),
    ("normal-map", {"normal_map": True}, "linear"),
    ("premultiply", {"premultiply": True}, "linear"),
    ("alpha-coverage", {"alpha_cutoff": 0.5}, "linear"),
    ("renormalize-texture", {"renormalize": "texture"}, "linear"),
    ("renormalize-level-clip", {"renormalize": "level", "renormalize_clip": 2.0}, "linear"),
    ("srgb-source", {}, "srgb"),
    ("auto-colour-space", {"colour_space": "auto"}, "srgb"),
)


def _image(kind, shape):
    """float32 RGBA of one kind of extreme value; alpha varies so that
    premultiplication and coverage have something to work on."""
    h, w = shape
    rng = np.random.default_rng(abs(hash((kind, shape))) % 2**32)
    if kind == "mixed":
        values = np.array(EXTREMES + tuple(-v for v in EXTREMES) + (0.0, 0.5, 1.0), np.float32)
        px = rng.choice(values, size=(h, w, 4)).astype(np.float32)
        px[:3, :3] = EXTREMES[-1]  # a block of the largest: a filter's sums over it overflow
    elif kind == "ramp":
        px = np.linspace(-F32_MAX, F32_MAX, h * w * 4).astype(np.float32).reshape(h, w, 4)
    else:
        v = np.float32(kind)
        px = np.full((h, w, 4), v, np.float32)
        checker = (np.indices((h, w)).sum(axis=0) % 2) == 1
        checker[:, : w // 2] = False
        px[checker] = -v  # v on the left, a checker of +-v on the right
        px[::3, ::2, 3] = 0.25
    px[h // 2, :, 3] = rng.random(w).astype(np.float32)  # some ordinary alphas as well
    assert np.isfinite(px).all()
    return px


KINDS = EXTREMES + tuple(-v for v in EXTREMES) + ("mixed", "ramp")


def _check(baked, recipe, tmp_path):
    """Every level of the texture, as stored and as read back: finite, and
    within the format's range."""
    data = container_bytes(baked, "ktx2", recipe)
    ktx = read_ktx2(data)
    codec = codecs.get(read_texture(data).format)  # by vkFormat, or by the DFD for vkFormat 0 (ETC1S)
    fmt = formats.get(codec.name)
    top = float(np.finfo(np.dtype(fmt.sample)).max) if fmt.is_float else 255
    for text in (ktx.text("texcook.transforms"),):
        if text is not None:
            json.loads(text, parse_constant=lambda c: pytest.fail(f"{c} in the recorded transforms"))
    assert len(ktx.levels) == len(baked.levels)
    for i, raw in enumerate(ktx.levels):
        px = codec.decode(raw, *level_dims(ktx.width, ktx.height, i))
        assert np.isfinite(px).all(), f"level {i} stores NaN or Inf"
        assert np.abs(px.astype(np.float64)).max() <= top, f"level {i} beyond the {codec.name} range"
    path = tmp_path / "t.ktx2"
    path.write_bytes(data)
    for i, px in enumerate(load_texture(path).levels):
        assert np.isfinite(px).all(), f"level {i} reads back as NaN or Inf"


def _bake(px, source_space, fmt, filter="box", wrap="clamp", **settings):
    recipe = Recipe.of(format=fmt, clamp=True, mip_filter=filter, wrap=wrap, preset="fastest", **settings)
    return bake(Image.from_array(px, colour_space=source_space), recipe), recipe


@pytest.mark.parametrize("fmt", formats.encodable())
def test_every_format(fmt, tmp_path):
    """Each format, each extreme (mixed in one image and a ramp): 8-bit and
    block formats clamp, float formats stay finite."""
    for kind, shape in (("mixed", (9, 7)), ("ramp", (5, 5))):
        baked, recipe = _bake(_image(kind, shape), "linear", fmt, "lanczos")
        _check(baked, recipe, tmp_path)


def _cases():
    """(option, filter, wrap) for every option with every filter; the wrap
    modes rotate through them."""
    for i, ((name, settings, space), filter) in enumerate(itertools.product(OPTIONS, FILTERS)):
        yield pytest.param(settings, space, filter, WRAPS[i % len(WRAPS)], id=f"{name}-{filter}")


@pytest.mark.parametrize("settings, space, filter, wrap", list(_cases()))
def test_every_option_filter_and_extreme(settings, space, filter, wrap, tmp_path):
    """Every extreme through this option set and filter, to both float
    formats and an 8-bit one, on odd sizes."""
    fmts = ("rgba16f", "rgba32f") if space == "linear" else ("rgba8", "rgba16f", "rgba32f")
    for j, kind in enumerate(KINDS):
        shape = ((9, 7), (5, 5), (1, 6))[j % 3]
        for fmt in fmts:
            if fmt != "rgba8" and settings.get("colour_space") == "auto":
                continue  # auto chooses between sRGB and linear 8-bit storage
            baked, recipe = _bake(_image(kind, shape), space, fmt, filter, wrap, **settings)
            _check(baked, recipe, tmp_path)


@pytest.mark.skipif(not LONG, reason="set TEXCOOK_LONG=1 (the full product takes minutes)")
@pytest.mark.parametrize("fmt", ["rgba8", "rgba16f", "rgba32f", "bc1", "bc5", "bc3-ycocg", "etc1", "astc-6x5"])
def test_full_product(fmt, tmp_path):
    for (name, settings, space), filter, wrap, kind, shape in itertools.product(
            OPTIONS, FILTERS, WRAPS, KINDS, ((9, 7), (5, 5), (1, 6))):
        if settings.get("colour_space") == "auto" and formats.get(fmt).is_float:
            continue
        baked, recipe = _bake(_image(kind, shape), space, fmt, filter, wrap, **settings)
        _check(baked, recipe, tmp_path)


def test_huge_normal_map_to_half_float(tmp_path, cli_run):
    """Was: an EXR of 3.4e38 baked to rgba16f with --normal-map --clamp had
    level 0 at 65504 and NaN in levels 1-3, exit 0. The mips of a constant
    normal keep its direction."""
    px = np.full((8, 8, 4), 3.4e38, np.float32)
    px[..., 3] = 1.0
    src, out = tmp_path / "big.exr", tmp_path / "big.ktx2"
    write_image(src, px)
    code, _, stderr = cli_run("bake", src, "-o", out, "-f", "rgba16f", "--normal-map", "--clamp")
    assert (code, stderr) == (0, "")
    levels = load_texture(out).levels
    assert len(levels) == 4 and levels[0][0, 0, 0] == 65504
    for level in levels[1:]:
        assert np.isfinite(level).all()
        np.testing.assert_allclose(level[..., :3], 0.5 + 0.5 / np.sqrt(3), atol=1e-3)


@pytest.mark.parametrize("filter", FILTERS)
def test_largest_values_keep_their_mean(filter, tmp_path):
    """A constant image at the float32 maximum mips to itself in rgba32f
    (scaled down to filter it, back up saturating), not to Inf."""
    px = np.full((9, 7, 4), F32_MAX, np.float32)
    baked, recipe = _bake(px, "linear", "rgba32f", filter)
    _check(baked, recipe, tmp_path)
    for raw in baked.levels[1:]:
        np.testing.assert_allclose(np.frombuffer(raw, "<f4"), F32_MAX, rtol=1e-5)


def test_coverage_of_denormal_alphas():
    """Was: lifting alphas of 1e-45 to a cutoff took a scale beyond float32
    (alpha * inf: NaN), and negative alphas a negative threshold."""
    alpha = np.array([[1e-45, 2e-45, 0.0, 3e-45], [-1e-38, 1e-45, -3.4e38, 0.0]], np.float32)
    out = scale_alpha_to_coverage(alpha, 0.5, 0.5)
    assert np.isfinite(out).all() and out.max() <= 1.0
    assert np.count_nonzero(out > 0.5) == 4 and out[1, 2] == -F32_MAX


def test_renormalize_records_finite_scales(tmp_path):
    """Was: a range of +-3.4e38 recorded a scale of Infinity (not JSON) and
    stored NaN."""
    px = _image(3.4e38, (9, 7))
    for mode in ("texture", "level"):
        baked, recipe = _bake(px, "linear", "rgba32f", renormalize=mode)
        _check(baked, recipe, tmp_path)
        record = json.loads(baked.kv["texcook.transforms"])[0]
        scales = np.ravel(record["scale"])
        assert np.isfinite(scales).all() and scales.max() == np.float32(F32_MAX)


def test_nan_and_inf_sources_are_treated_as_documented(tmp_path):
    """NaN and Inf in the source keep their behaviour: refused, or replaced
    with 0 under --nan-to-zero."""
    px = _image("mixed", (5, 5))
    px[1, 1, 0], px[2, 2, 1] = np.nan, -np.inf
    with pytest.raises(InputError, match="2 NaN or Inf value"):
        _bake(px, "linear", "rgba16f", "lanczos")
    baked, recipe = _bake(px, "linear", "rgba16f", "lanczos", nan_to_zero=True)
    _check(baked, recipe, tmp_path)


def test_summed_area_table_beyond_float32_is_refused(tmp_path, cli_run):
    """A table whose sums leave the float32 range would store Inf: the bake
    is refused in one line and nothing is written; sums within it are kept."""
    px = np.full((8, 8, 4), 3.4e38, np.float32)
    px[:, 4:] = -3.4e38
    src, out = tmp_path / "sat.exr", tmp_path / "t.ktx2"
    write_image(src, px)
    code, _, stderr = cli_run("bake", src, "-o", out, "-f", "rgba16f", "--clamp", "--sat", tmp_path / "t.sat.ktx2")
    assert code == 1 and stderr.count("\n") == 1 and "sat.exr" in stderr and "float32 range" in stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sat.exr"]
    write_image(src, _image(1e30, (9, 7)))
    code, _, stderr = cli_run("bake", src, "-o", out, "-f", "rgba32f", "--sat", tmp_path / "t.sat.ktx2")
    assert (code, stderr) == (0, "")
    table = np.frombuffer(read_ktx2((tmp_path / "t.sat.ktx2").read_bytes()).levels[0], "<f4")
    assert np.isfinite(table).all()


def test_two_channel_normal_map_rebuilds_z_quietly(tmp_path):
    """Was: X and Y of 3.4e38 overflowed (numpy warnings) rebuilding Z."""
    for v in (1e30, -3.4e38):
        px = np.full((9, 7, 2), v, np.float32)
        for fmt in ("rg8", "rgba16f", "bc5"):
            baked, recipe = _bake(px, "linear", fmt, "lanczos", normal_map=True)
            _check(baked, recipe, tmp_path)


@pytest.mark.parametrize("filter", FILTERS)
@pytest.mark.parametrize("options", [{}, {"premultiply": True, "alpha_channel": 3}, {"normal_map": True},
                                     {"alpha_channel": 3, "alpha_cutoff": 0.5}], ids=["plain", "premultiply",
                                                                                      "normal-map", "coverage"])
def test_chain_of_largest_values(filter, options):
    """build_chain straight from the library: float levels finite, LDR levels
    (which clamp to 0..1 in the source's units, however it was scaled to be
    filtered) within 0..1."""
    from texcook.mips import build_chain

    px = _image(3.4e38, (9, 7))
    px[..., 3] = np.abs(px[..., 3])
    for ldr in (False, True):
        for level in build_chain(px, filter=filter, ldr=ldr, **options)[1:]:
            assert np.isfinite(level).all()
            if ldr:
                assert level.min() >= 0.0 and level.max() <= 1.0


def test_half_float_encoder_saturates():
    """The rgba16f encoder called directly (the pipeline refuses or clamps
    first): finite values past 65504 become 65504, not Inf; Inf stays Inf."""
    codec = codecs.get("rgba16f")
    px = np.array([[[65519.0, 65520.0, -1e30, 3.4e38], [np.inf, -np.inf, 1e-45, 1.0]]], np.float32)
    back = codec.decode(codec.encode(px, "medium"), 2, 1)
    assert back[0, 0].tolist() == [65504.0, 65504.0, -65504.0, 65504.0]
    assert back[0, 1].tolist() == [np.inf, -np.inf, 0.0, 1.0]
