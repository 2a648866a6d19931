"""The second image set (bench/outside_set.py) and the table of every preset
against its peers (bench/bench_front.py)."""

import hashlib
import pathlib
import sys

from texcook import bench

BENCH = pathlib.Path(__file__).resolve().parent.parent / "bench"
sys.path.insert(0, str(BENCH))

import bench_front  # noqa: E402
import outside_set  # noqa: E402


def test_outside_set_same_files_every_run_and_read_like_the_corpus(tmp_path):
    first = outside_set.write(tmp_path / "a")
    again = outside_set.write(tmp_path / "b")
    assert [pathlib.Path(p).relative_to(tmp_path / "a") for p in first] == \
        [pathlib.Path(p).relative_to(tmp_path / "b") for p in again]
    for p, q in zip(first, again):
        assert pathlib.Path(p).read_bytes() == pathlib.Path(q).read_bytes(), p
    pictures = bench.load_images([tmp_path / "a"])
    # each scoring takes its own folders, as on the bundled corpus
    names = {s: sorted(p.name for p in bench.images_for(s, pictures)) for s in bench.CORPUS_FOLDERS}
    assert names["normal"] == ["normal-dem.png", "normal-tiles.png"]
    assert names["hdr"] == ["grace-exposure.hdr", "sky.hdr"]
    assert names["alpha"] == ["cutout-blobs.png", "cutout-leaves.png", "grace-cutout.png", "logo.png", "present.png"]
    assert len(names["rgb"]) == 9 and "sky.hdr" not in names["rgb"]
    hdr = [p for p in pictures if p.folder == "hdr"]
    assert all(p.hdr is not None and p.hdr.max() > 1.0 for p in hdr)
    assert all(p.has_alpha for p in pictures if p.folder == "rgba")
    assert not any(p.has_alpha for p in pictures if p.folder in ("rgb", "normal"))


# the pixels the figures of docs/performance.md ("Every preset against its peers")
# were measured on; the generators are shared with bench/bench_astc_outside.py,
# so a change there changes this set and the published figures go stale
OUTSIDE_SHA256 = "d1ae78f122db9dea08d2048017993fa5632f638590c306618d900c85391aa5ee"


def test_outside_set_pixels_are_the_published_ones():
    h = hashlib.sha256()
    for folder, name, px in outside_set.images():
        h.update(f"{folder}/{name}{px.shape}{px.dtype}".encode())
        h.update(px.tobytes())
    assert h.hexdigest() == OUTSIDE_SHA256, "the outside set changed: measure docs/performance.md's table again"


def _row(fmt, encoder, preset, psnr, speed, pooled=None):
    return {"format": fmt, "encoder": encoder, "preset": preset, "psnr": psnr, "psnr_mean": psnr if pooled is None
            else None, "psnr_pooled": pooled if pooled is not None else psnr, "mpix_per_s": speed}


def test_table_flags_the_presets_bench_calls_dominated():
    rows = [_row("bc1", "texcook", "fastest", 30.0, 10.0),  # beaten by peer a: equal PSNR, faster
            _row("bc1", "texcook", "fast", 31.0, 5.0),
            _row("bc1", "peer a", None, 30.003, 20.0),
            _row("bc1", "peer b", None, 31.5, 1.0),
            # pooled (an image came back exactly): compared on the pooled PSNR
            _row("bc4", "texcook", "fastest", 41.0, 2.0, pooled=40.0),
            _row("bc4", "peer c", None, 40.5, 8.0)]
    result = {"rows": rows}
    table = bench_front.rows_of("corpus", result)
    flagged = {(r["format"], r["preset"]): r["dominated_by"] for r in table if r["dominated_by"]}
    expected = {(d["format"], d["preset"]): [p["encoder"] for p in d["by"]] for d in bench.dominated(rows)}
    assert flagged == expected == {("bc1", "fastest"): ["peer a"], ("bc4", "fastest"): ["peer c"]}
    speed = {(r["format"], r["encoder"], r["preset"]): r["speed_vs_fastest_peer"] for r in table}
    assert speed["bc1", "texcook", "fastest"] == 0.5 and speed["bc4", "texcook", "fastest"] == 0.25
    text = bench_front.table({"corpus": result})
    assert "| bc1 | corpus | texcook | fastest | 30.00 | 10 | 0.5 | peer a |" in text
    assert "| bc1 | corpus | texcook | fast | 31.00 | 5 | 0.25 | no |" in text
