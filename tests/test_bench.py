"""The accuracy-against-time harness: structure of its figures, PSNR against
an independent computation, the plot, and the stage timings."""

import json
import math
import os
import sys

import numpy as np
import pytest

from texcook import bench, codecs
from texcook.image import write_image

from decoders import t2d


@pytest.fixture
def two_images(tmp_path, rng):
    paths = []
    for i, (h, w) in enumerate([(16, 20), (13, 9)]):  # the second is cropped to 12x8
        px = rng.integers(0, 256, (h, w, 4)).astype(np.uint8)
        px[..., :3] = np.clip(px[..., :3] // 4 + 100 + i * 20, 0, 255)  # smooth-ish, so PSNR is finite
        p = tmp_path / f"img{i}.png"
        write_image(p, px)
        paths.append(p)
    return paths


def _independent_psnr(fmt, paths, preset, channels, alpha_in_red=False):
    from texcook.image import read_image

    values = []
    for p in paths:
        px = read_image(p).integer_values().astype(np.uint8)
        h, w = px.shape[0] // 4 * 4, px.shape[1] // 4 * 4
        px = np.ascontiguousarray(px[:h, :w])
        if alpha_in_red:
            px = np.ascontiguousarray(np.repeat(px[..., 3:4], 4, axis=2))
        data = codecs.get(fmt).encode(px, preset, threads=1)
        dec = t2d(fmt, data, w, h)
        mse = np.mean((px[..., channels].astype(float) - dec[..., channels]) ** 2)
        values.append(10 * math.log10(255**2 / mse))
    return float(np.mean(values))


def test_run_structure_and_quality(two_images, tmp_path, cli_run):
    out = tmp_path / "b.json"
    plot = tmp_path / "b.png"
    code, stdout, stderr = cli_run("bench", *two_images, "--formats", "bc1,bc4", "--presets", "fastest,fast",
                                   "--no-peers", "--repeat", "1", "--json", out, "--plot", plot,
                                   "--plot-preset", "fast")
    assert code == 0, stderr
    assert "| bc1 | rgb | texcook | fastest |" in stdout
    result = json.loads(out.read_text())
    assert set(result) >= {"command", "machine", "threads", "images", "rows", "scorings", "missing_peers"}
    assert result["machine"]["cpus"] >= 1 and result["machine"]["texcook"]
    assert [(r["format"], r["preset"]) for r in result["rows"]] == [
        ("bc1", "fastest"), ("bc1", "fast"), ("bc4", "fastest"), ("bc4", "fast")]
    for r in result["rows"]:
        assert r["judge"] == "texture2ddecoder" and r["images"] == 2 and r["bits_per_texel"] == 4.0
        assert r["mpix_per_s"] > 0 and r["mpix_per_s_all_cores"] > 0 and r["first_call_s"] >= 0
        assert r["megapixels"] == pytest.approx((16 * 20 + 12 * 8) / 1e6)
    bc1 = result["rows"][1]
    assert bc1["psnr"] == pytest.approx(_independent_psnr("bc1", two_images, "fast", [0, 1, 2]), abs=1e-9)
    bc4 = result["rows"][2]
    assert bc4["psnr"] == pytest.approx(_independent_psnr("bc4", two_images, "fastest", [0], True), abs=1e-9)
    # the plot: a valid PNG with a panel per format and the size panel
    data = plot.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    import OpenImageIO as oiio

    spec = oiio.ImageInput.open(str(plot)).spec()
    assert spec.width > 2 * spec.height  # three panels side by side


def test_peers_are_measured_or_listed(two_images):
    result = bench.run(two_images, ["bc5"], ["fastest"], with_peers=True, repeat=1)
    names = [r["encoder"] for r in result["rows"]]
    assert names[0] == "texcook" and "quicktex" in names and "etcpak" in names
    bc5 = result["rows"][0]
    assert bc5["angle_mean_deg"] >= 0 and bc5["angle_p99_deg"] >= bc5["angle_mean_deg"]


def test_pareto_front():
    pts = [(1.0, 30.0), (2.0, 31.0), (3.0, 30.5), (0.5, 29.0), (2.0, 29.0)]
    assert bench.pareto(pts) == [3, 0, 1]


def test_unknown_format_or_preset_is_refused(cli_run):
    code, _, stderr = cli_run("bench", "--formats", "bc9")
    assert code == 2 and "unknown format" in stderr
    code, _, stderr = cli_run("bench", "--presets", "ludicrous")
    assert code == 2 and "ludicrous" in stderr


def test_stages_of_a_whole_bake(two_images, cli_run, tmp_path):
    out = tmp_path / "s.json"
    code, stdout, stderr = cli_run("bench", "--stages", two_images[0], "--formats", "bc1", "--presets", "fast",
                                   "--repeat", "1", "--json", out)
    assert code == 0, stderr
    row = json.loads(out.read_text())["rows"][0]
    assert list(row["seconds"]) == ["read", "colour", "mips", "transform", "encode", "container", "write"]
    assert row["total_s"] == pytest.approx(sum(row["seconds"].values()))
    assert row["seconds"]["encode"] > 0


@pytest.mark.parametrize("option, where", [("--json", "missing/b.json"), ("--plot", "missing/b.png"),
                                           ("--json", "afile/b.json"),
                                           ("--plot", "/proc/self/b.png")])  # a folder nobody may write
def test_an_unwritable_output_fails_before_the_benchmark(two_images, tmp_path, cli_run, monkeypatch, option,
                                                         where):
    (tmp_path / "afile").write_text("")
    ran = []
    monkeypatch.setattr(bench, "run", lambda *a, **k: ran.append(1))
    monkeypatch.setattr(bench, "stages", lambda *a, **k: ran.append(1))
    code, _, stderr = cli_run("bench", *two_images, "--no-peers", option, tmp_path / where)
    assert code != 0 and not ran
    assert str(tmp_path / where) in stderr and len(stderr.strip().splitlines()) == 1
    code, _, _ = cli_run("bench", "--stages", two_images[0], option, tmp_path / where)
    assert code != 0 and not ran
    assert not any(".texcook-" in n for n in os.listdir(tmp_path))  # the probe leaves nothing behind


def test_progress_starts_before_the_first_row(two_images):
    """The bar shows from the start (the first rows compile kernels), then a
    step per row as it finishes, naming the row under way."""
    calls = []
    bench.run(two_images, ["bc1"], ["fastest", "fast"], with_peers=False, repeat=1,
              progress=lambda done, total, label: calls.append((done, total, label)))
    assert calls == [(0, 2, "bc1 texcook fastest"), (1, 2, "bc1 texcook fast"), (2, 2, None)]


def test_cli_bar_on_a_terminal_only(two_images, monkeypatch):
    from texcook import cli

    shown = []
    monkeypatch.setattr(cli._BenchBar, "__call__", lambda self, *a: shown.append(a))
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True, raising=False)
    cli.cli.main(["bench", *map(str, two_images), "--formats", "bc1", "--presets", "fastest", "--no-peers",
                  "--repeat", "1"], standalone_mode=False)
    assert shown[0] == (0, 1, "bc1 texcook fastest") and shown[-1] == (1, 1, None)


def _row(fmt, encoder, mpix, mean, pooled=None, preset=None):
    """A made-up row: `mean` None when an image came back exactly (the
    column then holds the pooled PSNR)."""
    pooled = mean if pooled is None else pooled
    return {"format": fmt, "encoder": encoder, "preset": preset, "mpix_per_s": mpix, "psnr_mean": mean,
            "psnr_pooled": pooled, "psnr": pooled if mean is None else mean}


def test_a_peer_better_or_equal_and_faster_dominates_a_preset():
    rows = [_row("bc4", "texcook", 10.0, 40.0, preset="fastest"),
            _row("bc4", "texcook", 2.0, 42.0, preset="fast"),
            _row("bc4", "peerA", 50.0, 40.2),    # better and faster than fastest; lower than fast
            _row("bc4", "peerB", 20.0, 40.0),    # equal and faster than fastest
            _row("bc4", "peerC", 1.0, 43.0),     # better than both, slower than both
            _row("bc1", "peerD", 99.0, 60.0)]    # another panel
    found = bench.dominated(rows)
    assert [(d["format"], d["preset"]) for d in found] == [("bc4", "fastest")]
    assert [(p["encoder"], p["statistic"], p["psnr"], p["preset_psnr"]) for p in found[0]["by"]] == [
        ("peerA", "mean", 40.2, 40.0), ("peerB", "mean", 40.0, 40.0)]
    # equal as the table shows it (two decimals) counts as equal; a visible step below does not
    assert bench.dominated([rows[0], _row("bc4", "p", 50.0, 39.996)])
    assert not bench.dominated([rows[0], _row("bc4", "p", 50.0, 39.99)])
    assert not bench.dominated([rows[0], _row("bc4", "p", 10.0, 41.0)])  # as fast is not faster


def test_a_faster_preset_as_good_outranks_a_slower_one():
    """A texcook preset another texcook preset of its format beats (better or
    equal PSNR, faster) is outranked, listed apart from the peers' dominance
    and warned of in its own words; a preset is never its own rival."""
    rows = [_row("astc-4x4", "texcook", 10.0, 59.2, preset="medium"),
            _row("astc-4x4", "texcook", 5.0, 59.196, preset="thorough"),  # equal as shown, slower: outranked
            _row("astc-4x4", "texcook", 20.0, 56.0, preset="fast"),
            _row("astc-6x6", "texcook", 30.0, 70.0, preset="fast"),      # another panel
            _row("astc-4x4", "peer", 100.0, 70.0)]                       # beats them all: dominance, not rank
    found = bench.outranked(rows)
    assert [(d["preset"], [(p["encoder"], p["psnr"]) for p in d["by"]]) for d in found] == [
        ("thorough", [("texcook medium", 59.2)])]
    assert {d["preset"] for d in bench.dominated(rows)} == {"medium", "thorough", "fast"}
    assert bench.dominated_warnings({"outranked": found}) == [
        "texcook: warning: astc-4x4 thorough (5 Mpix/s on one thread) is outranked by texcook medium (59.20 dB "
        "against 59.20, mean PSNR; 10 Mpix/s)"]


def test_dominance_compares_one_statistic_for_both_rows():
    """The PSNR column is a mean of per-image PSNRs unless an image came back
    exactly (then pooled): where either row has no mean, both are compared
    pooled, not one's mean against the other's pooled figure."""
    exact_preset = _row("bc4", "texcook", 5.0, None, pooled=42.0, preset="fast")
    peer = _row("bc4", "peer", 50.0, 42.5, pooled=41.5)  # its column is above the preset's, its pooled below
    assert peer["psnr"] >= exact_preset["psnr"] and not bench.dominated([exact_preset, peer])
    preset = _row("bc4", "texcook", 5.0, 43.0, pooled=40.0, preset="fast")
    exact_peer = _row("bc4", "peer", 50.0, None, pooled=41.0)  # its column is below, its pooled above
    found = bench.dominated([preset, exact_peer])
    assert exact_peer["psnr"] < preset["psnr"] and [d["preset"] for d in found] == ["fast"]
    assert [(p["statistic"], p["psnr"], p["preset_psnr"]) for p in found[0]["by"]] == [("pooled", 41.0, 40.0)]


def test_bench_warns_of_dominated_presets_and_lists_them_in_the_json(two_images, tmp_path, cli_run, monkeypatch):
    """Real runs of bc4 with its peers, made-up figures: one warning line on
    stderr per dominated preset, and the same in the JSON."""
    measure = bench.measure
    figures = iter([(3.0, 40.0), (1.0, 41.0), (200.0, 40.5), (300.0, 40.0)])  # fastest, fast, quicktex, etcpak

    def made_up(*args, **kwargs):
        row = measure(*args, **kwargs)
        row["mpix_per_s"], row["psnr_mean"] = next(figures)
        row["psnr"] = row["psnr_mean"]
        return row

    monkeypatch.setattr(bench, "measure", made_up)
    out = tmp_path / "b.json"
    code, _, stderr = cli_run("bench", *two_images, "--formats", "bc4", "--presets", "fastest,fast",
                              "--repeat", "1", "--json", out)
    assert code == 0, stderr
    result = json.loads(out.read_text())
    assert [r["encoder"] for r in result["rows"]] == ["texcook", "texcook", "quicktex", "etcpak"]
    assert [(d["preset"], [p["encoder"] for p in d["by"]]) for d in result["dominated"]] == [
        ("fastest", ["etcpak", "quicktex"])]
    warnings = [line for line in stderr.splitlines() if "warning" in line]
    assert warnings == [("texcook: warning: bc4 fastest (3 Mpix/s on one thread) is dominated by etcpak (40.00 dB "
                         "against 40.00, mean PSNR; 300 Mpix/s), quicktex (40.50 dB against 40.00, mean PSNR; "
                         "200 Mpix/s)")]


def test_a_transformed_format_is_scored_on_what_a_reader_rebuilds(rng):
    """bc3-ycocg's blocks are BC3 holding the YCoCg layout: the independent
    decoder reads them as BC3, then undoes the step as a reader does, so the
    bench scores RGB (it scored the layout, about 9 dB)."""
    y, x = np.mgrid[0:32, 0:24]
    img = np.stack([x * 8, y * 6, 255 - x * 4, np.full_like(x, 255)], axis=2)
    img = np.clip(img + rng.integers(-4, 5, img.shape), 0, 255).astype(np.uint8)
    codec = codecs.get("bc3-ycocg")
    data = codec.encode(img, "fast", threads=1)
    ours = codec.decode(data, 24, 32)
    theirs = bench.independent_decoder("bc3-ycocg")(data, 24, 32)
    assert np.array_equal(theirs[..., :3], ours[..., :3])
    assert bench.psnr_of(*bench.score("rgb", img, theirs)[:2]) > 35


def test_astc_is_judged_by_the_specified_8_bit_output(tmp_path, rng):
    """ASTC's 8-bit texel is the top byte of the 16-bit result; the bench
    scores texcook and astcenc through astcenc's decoder, which gives it
    (texture2ddecoder rounds to nearest and scored texcook's blocks low)."""
    from decoders import astcenc_decode

    y, x = np.mgrid[0:32, 0:32]
    img = np.stack([x * 7, y * 5 + 20, 200 - x * 3 - y * 2], axis=2)
    img = np.clip(img + rng.integers(-6, 7, img.shape), 0, 255).astype(np.uint8)
    path = tmp_path / "ramp.png"
    write_image(path, img)
    result = bench.run([path], ["astc-4x4"], ["fast"], with_peers=True, repeat=1)
    assert {r["judge"] for r in result["rows"]} == {"astcenc"}
    assert {r["encoder"] for r in result["rows"]} >= {"texcook", "astcenc fastest", "astcenc medium"}
    rgba = np.ascontiguousarray(np.concatenate([img, np.full((32, 32, 1), 255, np.uint8)], axis=2))
    data = codecs.get("astc-4x4").encode(rgba, "fast", threads=1)
    spec = astcenc_decode(data, 4, 4, 32, 32)
    assert np.array_equal(spec, codecs.get("astc-4x4").decode(data, 32, 32))
    ours = [r for r in result["rows"] if r["encoder"] == "texcook"][0]
    assert ours["psnr"] == pytest.approx(bench.psnr_of(*bench.score("rgb", img, spec)[:2]), abs=1e-9)
    rounded = t2d("astc-4x4", data, 32, 32)
    assert np.count_nonzero(rounded[..., :3] != spec[..., :3]) > 0  # the judges differ on these blocks


def test_a_set_without_a_format_s_folder_is_noted_not_a_crash(tmp_path, rng, cli_run):
    """A folder laid out like the corpus with no normal/ folder: bc5 (scored
    on normal maps) and its peers have nothing to measure, and the run says
    so in one line and goes on with the other formats (it raised IndexError
    on the peers' warm-up)."""
    from texcook.image import write_image

    (tmp_path / "set" / "rgb").mkdir(parents=True)
    write_image(str(tmp_path / "set" / "rgb" / "a.png"), rng.integers(0, 256, (16, 16, 3), dtype=np.uint8))
    out = tmp_path / "b.json"
    code, _, stderr = cli_run("bench", tmp_path / "set", "--formats", "bc5,bc1", "--presets", "fastest",
                              "--repeat", "1", "--json", out)
    assert code == 0, stderr
    result = json.loads(out.read_text())
    assert result["unscored"] == {"bc5": ["normal"]}
    assert {r["format"] for r in result["rows"]} == {"bc1"}
    assert "texcook: note: no image to measure bc5 on: the set has no normal folder" in stderr.splitlines()


def _thorough_after_medium(fmt):
    """astcenc `thorough` preceded, on every image, by a `medium` compress in
    the same process (what one process running the levels in turn does)."""
    medium = bench._astcenc_peer(fmt, "medium")[0]
    thorough = bench._astcenc_peer(fmt, "thorough")[0]
    return (lambda img: (medium(img), thorough(img))[1],)


def test_astcenc_levels_are_measured_each_in_a_process_of_its_own(tmp_path):
    """astcenc writes other blocks at `thorough` after a `medium` compress in
    the same process (this grey crop shows it); the bench's `thorough` row is
    astcenc's own, run alone."""
    pytest.importorskip("astc_encoder")
    from texcook.image import read_image

    px = read_image(bench.CORPUS / "rgb" / "ldr-rgb-01.png").integer_values()[:10, :10, :3].astype(float)
    grey = np.rint(px @ [0.2126, 0.7152, 0.0722]).astype(np.uint8)
    path = tmp_path / "grey.png"
    write_image(path, np.repeat(grey[..., None], 3, axis=2))
    result = bench.run([path], ["astc-5x5"], ["fastest"], with_peers=True, repeat=1)
    row = [r for r in result["rows"] if r["encoder"] == "astcenc thorough"][0]
    pics = bench.load_images([path])
    alone = bench.in_spawned_process(bench._measure_made_peer, "astc-5x5", "alone", bench._astcenc_peer,
                                     ("astc-5x5", "thorough"), pics, 1)
    shared = bench.in_spawned_process(bench._measure_made_peer, "astc-5x5", "shared", _thorough_after_medium,
                                      ("astc-5x5",), pics, 1)
    assert row["psnr"] == alone["psnr"]
    assert shared["psnr"] != alone["psnr"]  # the state this guards against, still there
