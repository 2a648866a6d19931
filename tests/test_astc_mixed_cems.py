"""ASTC blocks whose partitions take different kinds of endpoints (CEMs): one
partition direct, another base+scale, another luminance, as the multi-
partition CEM field allows. The mixed families the search estimates are the
least-missing kind per partition for each count of colour values saved, and
what is written decodes alike in astcenc and texcook."""

import numba
import numpy as np
import pytest
from decoders import astcenc_decode

from texcook import codecs
from texcook.codecs.astc import presets
from texcook.codecs.astc.search.endpoints import FAM_MIXED, N_FAMILIES, mixed_families
from texcook.codecs.astc.symbolic import KIND_NORMAL, S_CEM, S_KIND, S_PARTS
from texcook.metrics import psnr


@numba.njit
def _families(pgrey, psm, plm, luma):
    fam_list = np.zeros(16, np.int64)
    fam_extra = np.zeros(N_FAMILIES)
    n = mixed_families(pgrey.shape[0], pgrey, psm, plm, luma, fam_list, fam_extra, 0, np.zeros((2, 9)),
                       np.zeros((2, 9), np.int64))
    return fam_list[:n].copy(), fam_extra


def test_least_missing_kinds_per_count_of_values_saved():
    # partition 0 grey (its kind is fixed); 1 fits base+scale, 2 is nearly grey
    pgrey = np.array([1, 0, 0], np.int64)
    psm = np.array([0.0, 1.0, 50.0])
    plm = np.array([0.0, 100.0, 10.0])
    fams, extra = _families(pgrey, psm, plm, True)
    scale1, luma2 = 1 << 2, 2 << 4
    # saving 2 values: 1 base+scale; 4: 2 luminance (not both base+scale, 51);
    # 6: both; 8 is every partition luminance, a family of its own
    assert list(fams) == [FAM_MIXED + scale1, FAM_MIXED + luma2, FAM_MIXED + (scale1 | luma2)]
    assert [extra[f] for f in fams] == [1.0, 10.0, 11.0]
    # without luminance: one base+scale, the other direct (both base+scale is its own family)
    fams, extra = _families(pgrey, psm, plm, False)
    assert list(fams) == [FAM_MIXED + scale1] and extra[fams[0]] == 1.0
    # one colour partition: nothing to mix
    assert len(_families(np.array([1, 0], np.int64), psm[:2], plm[:2], True)[0]) == 0


def _three_kinds(n=36, seed=5):
    """Blocks of three regions: grey fading out, a hue-changing ramp (needs
    its own line: direct) and one hue's brightness ramp (base+scale is exact)."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:n, 0:n] % 6
    img = np.zeros((n, n, 4))
    u = x / 5.0
    grey = (x + y) < 4
    ramp = ~grey & (y < 3)
    scale = ~grey & ~ramp
    img[grey] = np.stack([130 + 10 * u, 130 + 10 * u, 130 + 10 * u, 60 + 150 * u], -1)[grey]
    img[ramp] = np.stack([220 - 180 * u, 40 + 170 * u, 40 + 0 * u, 255 + 0 * u], -1)[ramp]
    img[scale] = (np.array([40.0, 90.0, 180.0, 255.0]) * np.stack([0.5 + 0.5 * u] * 3 + [u * 0 + 1], -1))[scale]
    img[..., :3] += rng.normal(0, 1.0, (n, n, 3))
    return np.clip(img + 0.5, 0, 255).astype(np.uint8)


def _encode(img, preset, mixed, monkeypatch):
    real = presets.record

    def record(bw, bh, name):
        rec = real(bw, bh, name)
        rec["mixed_cems"] = mixed
        return rec

    monkeypatch.setattr(presets, "record", record)
    data, sym = codecs.get("astc-6x6").encode_symbolic(img, preset, threads=1)
    monkeypatch.setattr(presets, "record", real)
    return data, sym


def _kinds_apart(sym):
    """Blocks with a base+scale partition beside a direct one (no single
    family writes that)."""
    out = []
    for r in sym:
        cems = {int(c) for c in r[S_CEM:S_CEM + r[S_PARTS]]}
        if r[S_KIND] == KIND_NORMAL and cems & {6, 10} and cems & {8, 12}:
            out.append(r)
    return out


@pytest.mark.parametrize("preset", ["fast", "medium", "thorough"])
def test_partitions_take_their_own_kind_and_decode_alike(preset, monkeypatch):
    """Every block here is those three regions: `fast` (no luminance kind)
    gives the hue-changing ramp a direct pair beside base+scale for the
    other colour; `medium` and `thorough` may also give a nearly grey
    partition luminance. Each is at least as good as with one kind for the
    block (fast 23.69 -> 23.70 dB, medium 23.96 -> 25.57, thorough 26.13 ->
    26.69; `fast` gave 30 or more of the 36 blocks both kinds, 26 since its
    second plane goes to the component that leaves the line most, which
    here wins fewer blocks: docs/astc.md, "The plane for the component that
    leaves the line")."""
    img = _three_kinds()
    data, sym = _encode(img, preset, 1, monkeypatch)
    if preset == "fast":
        assert len(_kinds_apart(sym)) >= 24
    ours = codecs.get("astc-6x6").decode(data, 36, 36)
    assert np.array_equal(ours, astcenc_decode(data, 6, 6, 36, 36))
    before, sym_before = _encode(img, preset, 0, monkeypatch)
    assert not _kinds_apart(sym_before)
    # `fast` gains next to nothing here since its plane rule changed (above)
    gain = 0.0 if preset == "fast" else 0.2
    assert psnr(ours, img) >= psnr(codecs.get("astc-6x6").decode(before, 36, 36), img) + gain
