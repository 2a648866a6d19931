"""Mip chains: sizes, filters, wrap modes, gamma, ranges, premultiplied alpha, normal maps."""

import importlib
from pathlib import Path

import numpy as np
import pytest

import reference
from conftest import read_straight
from texcook.errors import InputError, UsageError
from texcook.mips import FILTERS, build_chain, chain_sizes, resample, tap_table

R = importlib.import_module("texcook.mips.resample")  # the module, not the re-exported function

CORPUS = Path(__file__).resolve().parent.parent / "corpus"
MEAN_FILTERS = ("box", "lanczos", "kaiser")



def load_linear(path):
    """Corpus image as linear float32: PNGs are sRGB on colour channels."""
    px = read_straight(path)
    if path.suffix == ".png":
        px[..., :3] = reference.srgb_to_linear(px[..., :3])
    return px


def corpus_paths():
    return sorted((CORPUS / "rgb").glob("*.png")) + sorted((CORPUS / "rgba").glob("*.png")) + sorted(
        (CORPUS / "hdr").glob("*.hdr")
    )


# ---------------------------------------------------------------- sizes


@pytest.mark.parametrize(
    "size, expected",
    [
        ((1, 1), [(1, 1)]),
        ((1, 6), [(1, 6), (1, 3), (1, 1)]),
        ((3, 5), [(3, 5), (1, 2), (1, 1)]),
        ((127, 128), [(127, 128), (63, 64), (31, 32), (15, 16), (7, 8), (3, 4), (1, 2), (1, 1)]),
    ],
)
def test_chain_sizes_follow_floor_rule(size, expected):
    assert chain_sizes(*size) == expected


def test_chain_length_4096():
    sizes = chain_sizes(4096, 4096)
    assert len(sizes) == 13 and sizes[-1] == (1, 1) and sizes[1] == (2048, 2048)


@pytest.mark.parametrize("shape", [(1, 1, 4), (1, 9, 3), (9, 1, 1), (3, 5, 4), (128, 127, 4)])
@pytest.mark.parametrize("filter", FILTERS)
def test_every_size_builds_down_to_one_texel(shape, filter, rng):
    img = rng.random(shape, dtype=np.float32)
    levels = build_chain(img, filter=filter)
    assert [lv.shape[1::-1] for lv in levels] == chain_sizes(shape[1], shape[0])
    assert np.array_equal(levels[0], img)
    for lv in levels:
        assert lv.dtype == np.float32 and lv.shape[2] == shape[2]
        assert np.isfinite(lv).all() and lv.min() >= 0.0 and lv.max() <= 1.0


def test_max_levels_stops_early(rng):
    levels = build_chain(rng.random((64, 64, 3), dtype=np.float32), max_levels=3)
    assert [lv.shape[:2] for lv in levels] == [(64, 64), (32, 32), (16, 16)]


# ---------------------------------------------------------------- the resampler


@pytest.mark.parametrize("filter", FILTERS)
@pytest.mark.parametrize("wrap", [("clamp", "clamp"), ("repeat", "mirror"), ("mirror", "repeat")])
@pytest.mark.parametrize("shape", [(8, 8, 4), (5, 3, 2), (7, 12, 1), (13, 11, 3)])
def test_resampler_matches_dense_reference(filter, wrap, shape, rng):
    img = rng.random(shape, dtype=np.float32)
    out_w, out_h = max(1, shape[1] // 2), max(1, shape[0] // 2)
    got = resample(img, out_w, out_h, filter=filter, wrap=wrap)
    ref = reference.resample(img, out_w, out_h, filter, wrap)
    np.testing.assert_allclose(got, ref, atol=2e-6)


def test_odd_sizes_use_true_positions():
    # 5 -> 2: the middle texel is shared; 3 -> 1 averages all three. No texel is dropped.
    idx, wts = tap_table(5, 2, "box")
    dense = np.zeros((2, 5))
    np.add.at(dense, (np.repeat(np.arange(2), idx.shape[1]), idx.ravel()), wts.ravel())
    np.testing.assert_allclose(dense, [[0.4, 0.4, 0.2, 0, 0], [0, 0, 0.2, 0.4, 0.4]], atol=1e-7)
    img = np.zeros((3, 5, 1), np.float32)
    img[2, 4] = 1.0  # the last row and column, which a 2x2 box would drop
    lv1 = build_chain(img, filter="box")[1]
    assert lv1.shape == (1, 2, 1)
    assert lv1[0, 1, 0] == pytest.approx(0.4 / 3)


def test_jitted_kernels_match_their_python(rng):
    # the passes call row helpers that only kernels can call: checked against the sums in NumPy
    img = rng.random((6, 7, 4), dtype=np.float32)
    idx, wts = tap_table(7, 3, "lanczos", "mirror")
    want = np.einsum("it,yitc->yic", wts.astype(np.float64), img[:, idx].astype(np.float64))
    a = R._horizontal4(img, idx, wts, np.empty((6, 3, 4), np.float32))
    c = R._horizontal(img, idx, wts, np.empty((6, 3, 4), np.float32))
    np.testing.assert_allclose(a, want, atol=1e-6)
    assert np.array_equal(a, c)  # the same sums in the same order
    idy, wty = tap_table(6, 3, "kaiser", "repeat")
    flat = img.reshape(6, 28)
    d = R._vertical(flat, idy, wty, np.empty((3, 28), np.float32))
    np.testing.assert_allclose(d, np.einsum("it,itx->ix", wty.astype(np.float64), flat[idy].astype(np.float64)),
                               atol=1e-6)


def test_fused_passes_equal_the_two_passes_bit_for_bit(rng):
    # _separable does both passes per output row; it must give what the passes give one after the other
    img = rng.uniform(-0.2, 1.2, (23, 19, 4)).astype(np.float32)
    img[3, 4] = -0.0
    for filter in ("triangle", "lanczos", "kaiser"):
        idx, wtx = tap_table(19, 9, filter, "repeat")
        idy, wty = tap_table(23, 11, filter, "mirror")
        flat = img.reshape(23, 19 * 4)
        mid = R._vertical(flat, idy, wty, np.empty((11, 19 * 4), np.float32)).reshape(11, 19, 4)
        want = R._horizontal4(mid, idx, wtx, np.empty((11, 9, 4), np.float32))
        got = R._separable(flat, idy, wty, idx, wtx, np.empty((11, 9, 4), np.float32))
        assert np.array_equal(got.view(np.uint32), want.view(np.uint32))


@pytest.mark.parametrize("filter", FILTERS)
@pytest.mark.parametrize("wrap", ["clamp", "repeat", "mirror"])
@pytest.mark.parametrize("shape", [(1, 1), (1, 7), (3, 5), (128, 127)])
def test_constant_images_stay_constant(filter, wrap, shape):
    img = np.full(shape + (2,), 0.3, np.float32)
    img[..., 1] = 7.5
    for lv in build_chain(img, filter=filter, wrap=wrap, ldr=False):
        np.testing.assert_allclose(lv[..., 0], 0.3, rtol=1e-5)
        np.testing.assert_allclose(lv[..., 1], 7.5, rtol=1e-5)


# ---------------------------------------------------------------- gamma


@pytest.mark.parametrize("filter, wrap", [("box", "clamp")] + [(f, "repeat") for f in FILTERS])
def test_srgb_checkerboard_filters_in_linear_light(filter, wrap):
    board = (np.indices((16, 16)).sum(axis=0) % 2).astype(np.float32)
    srgb = np.repeat(board[..., None], 3, axis=2)
    lv1 = build_chain(reference.srgb_to_linear(srgb).astype(np.float32), filter=filter, wrap=wrap)[1]
    np.testing.assert_allclose(lv1, 0.5, atol=1e-5)
    encoded = np.rint(reference.linear_to_srgb(lv1) * 255.0)
    assert (encoded == 188).all()


# ---------------------------------------------------------------- means


def _level_means(levels):
    return [lv.reshape(-1, lv.shape[2]).astype(np.float64).mean(axis=0) for lv in levels]


@pytest.mark.parametrize("path", corpus_paths(), ids=lambda p: p.name)
def test_mean_of_every_level_is_kept(path):
    img = load_linear(path)
    ldr = path.suffix == ".png"
    for filter in MEAN_FILTERS:
        m0, *rest = _level_means(build_chain(img, filter=filter, ldr=ldr, clamp=False))
        for k, m in enumerate(rest, 1):
            # Relative 0.5%; channels that are black throughout compare absolutely.
            assert np.all(np.abs(m - m0) <= 0.005 * np.maximum(m0, 1e-3)), (filter, k, m, m0)
        # Clamping the negative lobes' overshoot moves the mean: by at most 3%
        # of the level's mean on this corpus (docs/mips.md), never for box.
        m0, *rest = _level_means(build_chain(img, filter=filter, ldr=ldr))
        limit = 0.005 if filter == "box" else 0.03
        for k, m in enumerate(rest, 1):
            assert np.all(np.abs(m - m0) <= limit * np.maximum(m0, 1e-3)), (filter, k, m, m0)


# ---------------------------------------------------------------- ranges


@pytest.mark.parametrize("filter", ["lanczos", "kaiser"])
def test_negative_lobes_stay_in_ldr_range(filter, rng):
    img = (rng.random((67, 64, 3)) > 0.5).astype(np.float32)  # maximal contrast everywhere
    unclamped = build_chain(img, filter=filter, clamp=False)
    assert min(lv.min() for lv in unclamped) < 0.0 and max(lv.max() for lv in unclamped) > 1.0
    for lv in build_chain(img, filter=filter):
        assert np.isfinite(lv).all() and lv.min() >= 0.0 and lv.max() <= 1.0


@pytest.mark.parametrize("filter", FILTERS)
def test_float_inputs_keep_values_above_one(filter):
    img = np.zeros((16, 16, 3), np.float32)
    img[:, :8] = 1e6
    img[:, 8:] = 1e-6
    levels = build_chain(img, filter=filter, ldr=False)
    for lv in levels:
        assert np.isfinite(lv).all()
        assert lv.min() >= 0.0  # the source had no negatives
        assert lv.max() > 1.0
    np.testing.assert_allclose(levels[-1], 0.5e6 + 0.5e-6, rtol=1e-5)


def test_float_negatives_survive_where_the_source_has_them():
    img = np.zeros((8, 8, 2), np.float32)
    img[..., 0] = np.linspace(-2.0, 2.0, 8)[None, :]
    img[..., 1] = 3.0
    lv1 = build_chain(img, filter="lanczos", ldr=False)[1]
    assert lv1[..., 0].min() < -1.0


def test_non_finite_input_is_refused():
    img = np.zeros((4, 4, 3), np.float32)
    img[1, 2, 0] = np.nan
    with pytest.raises(InputError):
        build_chain(img)
    img[1, 2, 0] = np.inf
    with pytest.raises(InputError):
        build_chain(img)


# ---------------------------------------------------------------- wrap modes


@pytest.mark.parametrize("filter", FILTERS)
def test_repeat_mips_equal_centre_crop_of_tiled_mips(filter, rng):
    tile = rng.random((64, 64, 3), dtype=np.float32)
    tiled = np.tile(tile, (3, 3, 1))
    own = build_chain(tile, filter=filter, wrap="repeat", ldr=False)
    big = build_chain(tiled, filter=filter, wrap="clamp", ldr=False)
    radius = reference.filter_radius(filter)
    checked = 0
    for k in range(1, len(own)):
        # Cascaded support of level k in level-0 texels: radius * (2 + 4 + ... + 2^k).
        support = radius * (2 ** (k + 1) - 2)
        if support >= 64:
            break
        n = 64 >> k
        np.testing.assert_allclose(own[k], big[k][n: 2 * n, n: 2 * n], atol=1e-5)
        checked += 1
    assert checked >= 3


def test_repeat_levels_are_seamless(rng):
    # A smooth periodic tile: opposite edges of every level must continue each other
    # as well as neighbouring columns inside do.
    y, x = np.mgrid[0:128, 0:128] / 128.0
    tile = (0.5 + 0.4 * np.sin(2 * np.pi * (3 * x + 2 * y)))[..., None].astype(np.float32)
    for lv in build_chain(tile, filter="lanczos", wrap="repeat")[1:5]:
        inner = np.abs(np.diff(lv, axis=1)).max()
        seam = np.abs(lv[:, 0] - lv[:, -1]).max()
        assert seam <= inner * 1.01 + 1e-6


def test_wrap_per_axis():
    img = np.zeros((8, 8, 1), np.float32)
    img[:, 0] = 1.0  # a bright left column
    img[0, :] = 1.0  # and top row
    lv = build_chain(img, filter="triangle", wrap=("repeat", "clamp"))[1]
    # Repeat in x: the left column bleeds into the right edge; clamp in y: the top row does not reach the bottom.
    assert lv[2, -1, 0] > 0.1
    assert lv[-1, 2, 0] == pytest.approx(0.0, abs=1e-7)


# ---------------------------------------------------------------- alpha


def test_premultiply_removes_halos():
    img = np.zeros((32, 32, 4), np.float32)
    img[..., 1] = 1.0  # invisible texels are bright green
    img[7:23, 9:25] = [1.0, 0.0, 0.0, 1.0]  # an opaque red square, off the 2x2 grid
    for filter in FILTERS:
        plain = build_chain(img, filter=filter, alpha_channel=3)
        pre = build_chain(img, filter=filter, alpha_channel=3, premultiply=True)
        for p, q in zip(plain[1:4], pre[1:4]):
            visible = q[..., 3] > 0.0
            assert np.abs(q[..., 1][visible]).max() < 1e-5  # no green at visible texels
            assert q[..., 0][visible].min() > 1.0 - 1e-5  # full red kept
            assert p[..., 1][p[..., 3] > 0.0].max() > 0.1  # straight filtering bleeds green
            np.testing.assert_allclose(p[..., 3], q[..., 3], atol=1e-6)  # alpha itself is the same
            # Fully transparent texels keep a plausible colour, not black.
            if (~visible).any():
                assert q[..., 1][~visible].max() > 0.5


@pytest.mark.parametrize("alpha", [0.0, 1.0])
def test_premultiply_uniform_alpha(alpha, rng):
    img = rng.random((9, 14, 4), dtype=np.float32)
    img[..., 3] = alpha
    for lv, ref in zip(
        build_chain(img, filter="kaiser", alpha_channel=3, premultiply=True),
        build_chain(img, filter="kaiser", alpha_channel=3),
    ):
        assert np.isfinite(lv).all()
        np.testing.assert_allclose(lv, ref, atol=1e-5)


# ---------------------------------------------------------------- normal maps


def _decode(lv):
    return lv[..., :3] * 2.0 - 1.0


def test_normal_map_levels_are_unit_vectors():
    for path in sorted((CORPUS / "normal").glob("*.png")):
        px = read_straight(path)[..., :3]
        for lv in build_chain(px, filter="lanczos", normal_map=True)[1:]:
            length = np.linalg.norm(_decode(lv), axis=-1)
            np.testing.assert_allclose(length, 1.0, atol=2e-6)


def test_opposite_normals_cancel_to_plus_z():
    img = np.zeros((8, 8, 3), np.float32)
    img[:, 0::2] = [1.0, 0.5, 0.5]  # +X
    img[:, 1::2] = [0.0, 0.5, 0.5]  # -X
    lv1 = build_chain(img, filter="box", normal_map=True)[1]
    np.testing.assert_allclose(lv1, np.broadcast_to([0.5, 0.5, 1.0], lv1.shape), atol=1e-6)
    # Half and half in large blocks: the average of +X and +Z is their bisector.
    img = np.zeros((4, 4, 3), np.float32)
    img[:, :2] = [1.0, 0.5, 0.5]
    img[:, 2:] = [0.5, 0.5, 1.0]
    last = _decode(build_chain(img, filter="box", normal_map=True)[-1])[0, 0]
    np.testing.assert_allclose(last, [np.sqrt(0.5), 0.0, np.sqrt(0.5)], atol=1e-6)


def test_two_channel_normal_maps_reconstruct_z():
    path = sorted((CORPUS / "normal").glob("*.png"))[0]
    px = read_straight(path)
    xyz = px[..., :3].copy()
    v = xyz * 2.0 - 1.0
    v[..., 2] = np.abs(v[..., 2])  # reconstruction assumes the +Z hemisphere
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    xyz = (v * 0.5 + 0.5).astype(np.float32)
    three = build_chain(xyz, filter="kaiser", normal_map=True)
    two = build_chain(np.ascontiguousarray(xyz[..., :2]), filter="kaiser", normal_map=True)
    for a, b in zip(three[1:], two[1:]):
        assert b.shape[2] == 2
        # Z rebuilt from 8-bit X and Y differs from the stored Z by quantisation only.
        assert np.abs(a[..., :2] - b).max() < 0.01


def test_normal_map_keeps_extra_channels(rng):
    img = np.concatenate([np.full((8, 8, 3), 0.5, np.float32), rng.random((8, 8, 1), dtype=np.float32)], -1)
    img[..., 2] = 1.0
    levels = build_chain(img, filter="box", normal_map=True)
    assert levels[1].shape == (4, 4, 4)
    np.testing.assert_allclose(levels[1][..., 3], img[..., 3].reshape(4, 2, 4, 2).mean(axis=(1, 3)), atol=1e-6)


# ---------------------------------------------------------------- options


@pytest.mark.parametrize(
    "kwargs",
    [
        dict(filter="gauss"),
        dict(wrap="border"),
        dict(wrap=("clamp", "clamp", "clamp")),
        dict(alpha_cutoff=0.5),  # no alpha channel named
        dict(alpha_channel=3, alpha_cutoff=1.5),
        dict(alpha_channel=3, alpha_cutoff=-0.1),
        dict(alpha_channel=4),
        dict(premultiply=True),
        dict(filter="lanczos", lanczos_a=2.5),
        dict(filter="lanczos", lanczos_a=0),
        dict(filter="kaiser", kaiser_width=0.1),
        dict(filter="kaiser", kaiser_alpha=-1.0),
        dict(normal_map=True, premultiply=True, alpha_channel=3),
        dict(max_levels=0),
    ],
)
def test_bad_options_are_usage_errors(kwargs):
    with pytest.raises(UsageError):
        build_chain(np.zeros((4, 4, 4), np.float32), **kwargs)


def test_lanczos_a_and_kaiser_parameters_change_the_result(rng):
    img = rng.random((32, 32, 1), dtype=np.float32)
    a2 = build_chain(img, filter="lanczos", lanczos_a=2, ldr=False)[1]
    a3 = build_chain(img, filter="lanczos", ldr=False)[1]
    assert np.abs(a2 - a3).max() > 1e-3
    k1 = build_chain(img, filter="kaiser", kaiser_width=2.0, kaiser_alpha=6.0, ldr=False)[1]
    k0 = build_chain(img, filter="kaiser", ldr=False)[1]
    assert np.abs(k1 - k0).max() > 1e-3


def test_bounds_pass_finds_extremes_and_non_finite_values(rng):
    chain = importlib.import_module("texcook.mips.chain")
    img = rng.uniform(-3.0, 2.0, (37, 11, 4)).astype(np.float32)
    img[5, 6, 2] = -0.0
    for per_channel in (False, True):
        for threads in (1, 2, 3):
            finite, lo, hi = chain._bounds(img, per_channel, threads)
            assert finite
            want_lo = img.min(axis=(0, 1)) if per_channel else np.full(4, img.min())
            want_hi = img.max(axis=(0, 1)) if per_channel else np.full(4, img.max())
            np.testing.assert_array_equal(lo, want_lo)
            np.testing.assert_array_equal(hi, want_hi)
    keys = chain._flat_range(np.array([0.0, -0.0, 1e-45, -1e-45, 7.5, -np.inf], np.float32).view(np.int32),
                             np.empty(3, np.int32))
    assert chain._key_value(keys[0]) == -np.inf and chain._key_value(keys[1]) == 7.5
    assert keys[2] == 0x7F800000
    one = np.ones((3, 5, 4), np.float32)
    assert chain._bounds(one, False, 1)[1][0] == 1.0
    for bad in (np.nan, np.inf, -np.inf):
        for per_channel in (False, True):
            x = img.copy()
            x[36, 10, 3] = bad
            assert not chain._bounds(x, per_channel, 2)[0]


def test_chain_helper_kernels_match_their_python(rng):
    chain = importlib.import_module("texcook.mips.chain")
    img = (rng.random((6, 8, 3), dtype=np.float32) * 3.0 - 1.0).astype(np.float32)
    flat = img.reshape(-1, 3)
    lo_a, hi_a = np.empty(3, np.float32), np.empty(3, np.float32)
    lo_b, hi_b = np.empty(3, np.float32), np.empty(3, np.float32)
    assert chain._scan(flat, lo_a, hi_a) and chain._scan.py_func(flat, lo_b, hi_b)
    np.testing.assert_array_equal(lo_a, flat.min(axis=0))
    np.testing.assert_array_equal(hi_b, flat.max(axis=0))
    bad = flat.copy()
    bad[3, 1] = np.inf
    assert not chain._scan(bad, lo_a, hi_a)
    lo, hi = np.array([0.0, -0.5, -np.inf], np.float32), np.array([1.0, 0.5, np.inf], np.float32)
    rows = img.reshape(6, 24)
    clo, chi = R._column_bounds(lo, hi, 8)
    a = R._clamp_rows(rows, clo, chi, np.empty_like(rows))
    b = R._clamp_rows.py_func(rows, clo, chi, np.empty_like(rows))
    np.testing.assert_array_equal(a.reshape(img.shape), np.clip(img, lo, hi))
    np.testing.assert_array_equal(b, a)
    out = R._box2x2(img, np.empty((3, 4, 3), np.float32))
    np.testing.assert_allclose(out, img.reshape(3, 2, 4, 2, 3).mean(axis=(1, 3)), atol=1e-6)


# --- one level at a time, on several threads ------------------------------------------

from texcook._threads import parallel_for, split  # noqa: E402
from texcook.mips import iter_chain  # noqa: E402

CHAIN_CASES = [
    dict(filter="box"),
    dict(filter="lanczos", wrap=("repeat", "mirror")),
    dict(filter="kaiser"),
    dict(filter="triangle", premultiply=True, alpha_channel=3),
    dict(filter="lanczos", premultiply=True, alpha_channel=3),
    dict(filter="box", alpha_channel=3, alpha_cutoff=0.5),
    dict(filter="lanczos", normal_map=True),
    dict(filter="lanczos", ldr=False),
    dict(filter="triangle", channels=3),
    dict(filter="box", channels=1, ldr=False),
    dict(filter="kaiser", channels=2, wrap="repeat"),
]


@pytest.mark.parametrize("case", range(len(CHAIN_CASES)))
def test_chain_is_the_same_bytes_on_any_thread_count_and_one_level_at_a_time(case, many_chunks):
    options = dict(CHAIN_CASES[case])
    channels = options.pop("channels", 4)
    rng = np.random.default_rng(case)
    # odd sizes, several chunks per level for every stage (the bounds pass, both passes, the clip)
    px = rng.uniform(0, 1, (131, 67, channels)).astype(np.float32)
    if not options.get("ldr", True):
        px = px * 8.0 - 1.0
    if options.get("alpha_cutoff"):
        px[..., 3] = (rng.uniform(0, 1, px.shape[:2]) > 0.6).astype(np.float32)
    want = build_chain(px, threads=1, **options)
    for threads in (2, 3):
        got = list(iter_chain(px, threads=threads, **options))
        assert len(got) == len(want)
        for a, b in zip(got, want):
            assert a.dtype == np.float32 and a.flags.c_contiguous
            assert np.array_equal(a.view(np.uint32), b.view(np.uint32))
    assert np.array_equal(px, build_chain(px, **options)[0])  # the input is not touched


STORED_CASES = [
    # (shape, dtype, srgb, options): odd and even sizes, a single row and column, every wrap
    ((131, 67, 4), np.uint8, True, dict(filter="box", alpha_channel=3, alpha_cutoff=0.5)),
    ((64, 48, 3), np.uint8, True, dict(filter="box")),
    ((64, 48, 3), np.uint8, True, dict(filter="lanczos", wrap=("repeat", "mirror"))),
    ((37, 29, 2), np.uint8, False, dict(filter="kaiser", wrap="repeat", alpha_channel=3)),
    ((45, 33, 1), np.uint16, True, dict(filter="triangle", wrap="mirror")),
    ((50, 70, 3), np.uint16, False, dict(filter="lanczos", alpha_channel=3, alpha_cutoff=0.3)),
    ((1, 40, 4), np.uint8, True, dict(filter="lanczos")),
    ((33, 1, 3), np.uint8, True, dict(filter="box")),
    ((1, 1, 4), np.uint8, True, dict(filter="box")),
    ((16, 16, 4), np.uint8, True, dict(filter="lanczos", premultiply=True, alpha_channel=3)),
    ((16, 16, 3), np.uint8, False, dict(filter="box", normal_map=True)),
]


@pytest.mark.parametrize("case", range(len(STORED_CASES)))
def test_a_chain_from_stored_integers_is_the_chain_of_their_decode(case, many_chunks):
    """Level 1 filtered from the stored integers' rows as they are decoded
    (colour.StoredRGBA) is the level filtered from the decoded image, byte for
    byte, and every level after it too, on any thread count."""
    from texcook.colour import StoredRGBA, to_linear_rgba

    shape, dtype, srgb, options = STORED_CASES[case]
    rng = np.random.default_rng(case)
    stored = rng.integers(0, np.iinfo(dtype).max + 1, shape).astype(dtype)
    stored[: shape[0] // 3] = np.iinfo(dtype).max  # saturated rows: the negative lobes overshoot 1
    alpha = shape[2] - 1 if shape[2] in (2, 4) else None
    want = build_chain(to_linear_rgba(stored, srgb, alpha), unit_range=True, **options)
    for threads in (1, 2):
        got = list(iter_chain(StoredRGBA(stored, srgb, alpha), threads=threads, **options))
        assert isinstance(got[0], StoredRGBA) and len(got) == len(want)
        assert np.array_equal(got[0].decode(threads).view(np.uint32), want[0].view(np.uint32))
        for a, b in zip(got[1:], want[1:]):
            assert a.dtype == np.float32 and a.flags.c_contiguous
            assert np.array_equal(a.view(np.uint32), b.view(np.uint32))
    # what the coverage search reads: each RGBA channel as the decode has it
    for k in range(4):
        assert np.array_equal(StoredRGBA(stored, srgb, alpha).channel(k), want[0][..., k])


def test_iter_chain_checks_options_before_the_first_level():
    with pytest.raises(UsageError):
        iter_chain(np.zeros((4, 4, 4), np.float32), filter="nope")
    with pytest.raises(UsageError):
        iter_chain(np.zeros((4, 4, 3), np.float32), alpha_cutoff=0.5)


def test_iter_chain_keeps_no_level_it_has_handed_on():
    import gc
    import weakref

    px = np.random.default_rng(0).uniform(0, 1, (64, 64, 4)).astype(np.float32)
    chain = iter_chain(px.copy(), filter="box")
    refs = []
    for level in chain:
        refs.append(weakref.ref(level))
        level = None
        gc.collect()
        # only the level just yielded may still be referenced (the next one is filtered from it)
        assert all(r() is None for r in refs[:-1])


def test_parallel_for_covers_every_index_once():
    for n in (0, 1, 7, 100, 1001):
        for threads in (1, 2, 5):
            hits = np.zeros(n, np.int64)

            def fn(a, b):
                hits[a:b] += 1

            parallel_for(fn, n, threads, min_chunk=3)
            assert np.all(hits == 1)
            bounds = split(n, threads, 3)
            assert sum(b - a for a, b in bounds) == n


def test_parallel_for_passes_errors_on():
    calls = []

    def fn(a, b):
        calls.append(a)
        raise ValueError("boom")

    with pytest.raises(ValueError):
        parallel_for(fn, 1000, 2, min_chunk=10)
    assert len(calls) <= 2  # a failed chunk stops the others taking more (8 chunks on 2 threads)


def test_parallel_for_inside_a_worker_runs_inline():
    # a chunk that splits its own work again must not wait on the busy pool
    out = np.zeros((4, 100), np.int64)

    def inner(row):
        def fn(a, b):
            out[row, a:b] += 1
        parallel_for(fn, 100, 2, min_chunk=10)

    parallel_for(lambda a, b: [inner(r) for r in range(a, b)], 4, 2, min_chunk=1)
    assert np.all(out == 1)


@pytest.mark.parametrize("filter", FILTERS)
def test_unit_range_skips_the_check_and_changes_nothing(filter):
    from texcook.colour import to_linear_rgba

    rng = np.random.default_rng(3)
    stored = rng.integers(0, 256, (37, 29, 4)).astype(np.uint8)
    stored[:8] = 255  # saturated texels: the negative lobes overshoot 1
    px = to_linear_rgba(stored, True, 3)
    want = build_chain(px, filter=filter, alpha_channel=3)
    got = build_chain(px, filter=filter, alpha_channel=3, unit_range=True)
    assert all(np.array_equal(a.view(np.uint32), b.view(np.uint32)) for a, b in zip(got, want))
