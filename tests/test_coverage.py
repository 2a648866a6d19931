"""Alpha-test coverage kept down the mip chain."""

from pathlib import Path

import numpy as np
import pytest

from conftest import read_straight
from reference import best_reachable_coverage_error, coverage
from texcook.mips import alpha_coverage, build_chain, coverage_scale, scale_alpha_to_coverage

CORPUS = Path(__file__).resolve().parent.parent / "corpus"
RGBA = sorted((CORPUS / "rgba").glob("*.png"))



def test_alpha_coverage_counts_texels_above_the_cutoff(rng):
    a = rng.random((37, 29)).astype(np.float32)
    a[::3, ::4] = 0.5  # on the cutoff: not kept
    for cutoff in (0.0, 0.25, 0.5, 1.0):
        assert alpha_coverage(a, cutoff) == coverage(a, cutoff)


@pytest.mark.parametrize("path", RGBA, ids=lambda p: p.name)
@pytest.mark.parametrize("filter", ["box", "lanczos", "kaiser"])
def test_corpus_coverage_within_two_points(path, filter):
    img = read_straight(path)  # only alpha matters here, and alpha is linear in every format
    target = coverage(img[..., 3], 0.5)
    kept = build_chain(img, filter=filter, alpha_channel=3, alpha_cutoff=0.5)
    for k, lv in enumerate(kept[1:], 1):
        cov = coverage(lv[..., 3], 0.5)
        n = lv.shape[0] * lv.shape[1]
        if n >= 64:
            assert abs(cov - target) <= 0.02, (k, cov, target)
        else:
            # Below 8x8 a level's coverage comes in steps of 1/n texels: the best
            # reachable value is what can be asked for.
            assert abs(cov - target) <= best_reachable_coverage_error(
                build_chain(img, filter=filter, alpha_channel=3)[k][..., 3], 0.5, target
            ) + 1e-12


def test_plain_mips_lose_coverage_that_scaling_restores():
    worst_plain = 0.0
    worst_kept = 0.0
    for path in RGBA:
        img = read_straight(path)  # only alpha matters here, and alpha is linear in every format
        target = coverage(img[..., 3], 0.5)
        plain = build_chain(img, filter="box", alpha_channel=3)
        kept = build_chain(img, filter="box", alpha_channel=3, alpha_cutoff=0.5)
        for p, q in zip(plain[1:], kept[1:]):
            if p.shape[0] * p.shape[1] >= 64:
                worst_plain = max(worst_plain, abs(coverage(p[..., 3], 0.5) - target))
                worst_kept = max(worst_kept, abs(coverage(q[..., 3], 0.5) - target))
    assert worst_plain > 0.05  # measured 8.5 points (ldr-rgba-01, 16x16)
    assert worst_kept <= 0.02


def test_only_alpha_changes_and_scaling_does_not_compound(rng):
    img = rng.random((64, 48, 4), dtype=np.float32)
    img[..., 3] = (img[..., 3] > 0.7).astype(np.float32)  # sparse cut-out: filtering loses coverage
    plain = build_chain(img, filter="lanczos", alpha_channel=3)
    kept = build_chain(img, filter="lanczos", alpha_channel=3, alpha_cutoff=0.5)
    for k, (p, q) in enumerate(zip(plain, kept)):
        np.testing.assert_array_equal(p[..., :3], q[..., :3])
        # Each level is scaled from its own unscaled alpha: alpha_k = min(1, plain_k * s_k).
        if k:
            s = coverage_scale(p[..., 3], 0.5, alpha_coverage(img[..., 3], 0.5))
            np.testing.assert_allclose(q[..., 3], np.minimum(p[..., 3] * s, 1.0), rtol=1e-5, atol=1e-7)


@pytest.mark.parametrize("shape", [(1, 1), (1, 9), (3, 5), (128, 127)])
@pytest.mark.parametrize("cutoff", [0.0, 0.25, 0.5, 0.9, 1.0])
def test_every_size_and_cutoff(shape, cutoff, rng):
    img = rng.random(shape + (2,), dtype=np.float32)
    img[..., 1] = rng.random(shape) ** 3  # mostly low alpha
    target = coverage(img[..., 1], cutoff)
    plain = build_chain(img, filter="kaiser", alpha_channel=1)
    kept = build_chain(img, filter="kaiser", alpha_channel=1, alpha_cutoff=cutoff)
    for p, q in zip(plain[1:], kept[1:]):
        a = q[..., 1]
        assert np.isfinite(a).all() and a.min() >= 0.0 and a.max() <= 1.0
        best = best_reachable_coverage_error(p[..., 1], cutoff, target)
        assert abs(coverage(a, cutoff) - target) <= best + 1e-12
        if cutoff in (0.0, 1.0):
            # Scaling cannot move a texel across 0 or above 1: alpha is left alone.
            np.testing.assert_array_equal(a, p[..., 1])


@pytest.mark.parametrize("value", [0.0, 1.0, 0.5])
def test_uniform_alpha(value):
    img = np.full((16, 16, 4), value, np.float32)
    for lv in build_chain(img, filter="lanczos", alpha_channel=3, alpha_cutoff=0.5)[1:]:
        # Coverage is already right (0.5 is not above the cutoff): at most float noise changes.
        np.testing.assert_allclose(lv[..., 3], value, atol=1e-5)
        assert coverage(lv[..., 3], 0.5) == (1.0 if value == 1.0 else 0.0)


def test_scale_search_hits_exact_counts(rng):
    a = rng.random(1000)
    for target in (0.0, 0.001, 0.1, 0.37, 0.5, 0.999, 1.0):
        out = scale_alpha_to_coverage(a, 0.5, target)
        assert np.count_nonzero(out > 0.5) == round(target * 1000)
    # Ties: 10 texels at exactly 0.3 move together, the nearest count wins.
    b = np.array([0.3] * 10 + [0.1] * 10, np.float32)
    out = scale_alpha_to_coverage(b, 0.5, 0.3)  # 6 of 20 is unreachable: 10 of 20 (0.5) or 0
    assert coverage(out, 0.5) in (0.0, 0.5)
    assert coverage(scale_alpha_to_coverage(b, 0.5, 0.45), 0.5) == 0.5
    # Zeros can never be lifted above the cutoff.
    c = np.array([0.0, 0.0, 0.0, 0.2], np.float32)
    assert coverage(scale_alpha_to_coverage(c, 0.5, 1.0), 0.5) == 0.25


def test_scale_prefers_no_change():
    a = np.array([0.1, 0.4, 0.6, 0.9])
    assert coverage_scale(a, 0.5, 0.5) == 1.0
    assert coverage_scale(a, 0.5, 0.55) == 1.0  # 2 of 4 is already the closest count
