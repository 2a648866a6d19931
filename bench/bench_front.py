"""Every preset of every format against its peers, on the bundled corpus and on
the set outside it (bench/outside_set.py): one markdown table.

    python bench/bench_front.py [--formats bc1,bc5,...] [--presets all] [--repeat 3] [--sets corpus,outside]
                                [--crop N] [--json OUT] [--load SET=bench.json ...]

Each set is one `texcook.bench.run` (the harness of `texcook bench`), so speeds
compare as ratios within a set's run. Per row: PSNR as the format is scored
(the mean of per-image PSNRs, pooled where an image comes back exactly), Mpix/s
on one thread, that speed over the fastest peer's of the same format and set,
and whether a peer dominates the preset (texcook.bench.dominated: PSNR better
or equal and faster; the peers named). Default formats: every non-ASTC format
with a peer or a panel; ASTC when named (`--formats astc-4x4,astc-6x6,astc-8x8`).
Default presets: all of them; `exhaustive` alone takes hours on a 2-core
machine in some formats (bc5, etc2); `--presets fastest,fast,medium,thorough`
took 20 minutes a set for the default formats at load average 8.
`--crop N` measures the top-left NxN of every image (a quick check that the
command runs); `--load` prints the table of saved runs (`--json` of this
script, or `texcook bench --json`) instead of measuring.
"""

import argparse
import datetime
import json
import os
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

FORMATS = ("bc1", "bc1a", "bc3", "bc3-ycocg", "bc4", "bc5", "bc7", "bc6h", "etc1", "etc2", "etc2a1", "etc2a8",
           "eac-r11", "eac-rg11")
SETS = ("corpus", "outside")


def _cropped(src, dst, n):
    """Copy the images of folder `src` (its layout kept) cropped to their
    top-left n x n into `dst`."""
    from texcook.bench import IMAGE_EXTENSIONS
    from texcook.image import read_image, write_image

    for root, _, files in os.walk(src):
        for f in sorted(files):
            if os.path.splitext(f)[1].lower() not in IMAGE_EXTENSIONS:
                continue
            out = os.path.join(dst, os.path.relpath(os.path.join(root, f), src))
            os.makedirs(os.path.dirname(out), exist_ok=True)
            img = read_image(os.path.join(root, f))
            px = img.pixels[:n, :n]
            write_image(out, px if img.is_float else (px * 255.0 + 0.5).astype("uint8"))


def measure(sets, format_names, presets, repeat, crop, tmp):
    """{set name: texcook.bench.run's result}."""
    from texcook import bench
    import outside_set

    out = {}
    for name in sets:
        if name == "corpus":
            folder = str(bench.CORPUS)
        else:
            folder = os.path.join(tmp, "outside")
            outside_set.write(folder)
        if crop:
            small = os.path.join(tmp, f"{name}-{crop}")
            _cropped(folder, small, crop)
            folder = small
        load = os.getloadavg()
        result = bench.run([folder], format_names, presets, repeat=repeat)
        result["load_average"] = {"before": load, "after": os.getloadavg()}
        result["set"] = name
        out[name] = result
    return out


def rows_of(set_name, result):
    """The table's rows of one set's result: dicts of format, set, encoder,
    preset, psnr, mpix_per_s, speed_vs_fastest_peer (None without a peer) and
    dominated_by (the peers that dominate a preset, [] if none)."""
    from texcook.bench import dominated

    beaten = {(d["format"], d["preset"]): [p["encoder"] for p in d["by"]] for d in dominated(result["rows"])}
    fastest = {}
    for r in result["rows"]:
        if r["encoder"] != "texcook":
            fastest[r["format"]] = max(fastest.get(r["format"], 0.0), r["mpix_per_s"])
    out = []
    for r in result["rows"]:
        peer = fastest.get(r["format"])
        out.append({"format": r["format"], "set": set_name, "encoder": r["encoder"], "preset": r["preset"],
                    "psnr": r["psnr"], "mpix_per_s": r["mpix_per_s"],
                    "speed_vs_fastest_peer": r["mpix_per_s"] / peer if peer else None,
                    "dominated_by": beaten.get((r["format"], r["preset"]), []) if r["encoder"] == "texcook" else []})
    return out


def table(results):
    """Markdown: every format's rows, corpus then outside, texcook's presets
    then the peers."""
    rows = [r for name, res in results.items() for r in rows_of(name, res)]
    order = list(dict.fromkeys(r["format"] for r in rows))
    lines = ["| format | set | encoder | preset | PSNR dB | Mpix/s 1 thread | x fastest peer | dominated by |",
             "|---|---|---|---|---|---|---|---|"]
    for fmt in order:
        for name in results:
            for r in (r for r in rows if r["format"] == fmt and r["set"] == name):
                ratio = "" if r["speed_vs_fastest_peer"] is None else f"{r['speed_vs_fastest_peer']:.3g}"
                mark = ", ".join(r["dominated_by"]) if r["dominated_by"] else ("no" if r["encoder"] == "texcook" else "")
                lines.append(f"| {fmt} | {name} | {r['encoder']} | {r['preset'] or ''} | {r['psnr']:.2f} | "
                             f"{r['mpix_per_s']:.3g} | {ratio} | {mark} |")
    return "\n".join(lines)


def header(results):
    lines = []
    for name, res in results.items():
        load = res.get("load_average")
        where = f"load average {load['before'][0]:.1f} before, {load['after'][0]:.1f} after" if load else ""
        images = ", ".join(f"{i['folder']}/{i['name']}" if i["folder"] else i["name"] for i in res["images"])
        lines.append(f"- {name}: {len(res['images'])} images ({images}); repeat {res['repeat']}; {where}")
    return "\n".join(lines)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--formats", default=",".join(FORMATS))
    ap.add_argument("--presets", default="all")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--sets", default=",".join(SETS))
    ap.add_argument("--crop", type=int, default=0, help="measure only the top-left NxN of each image")
    ap.add_argument("--json", help="write every set's result here")
    ap.add_argument("--load", action="append", default=[], metavar="SET=JSON", help="a saved run, not measured again")
    args = ap.parse_args()
    if args.load:
        results = {}
        for item in args.load:
            name, path = item.split("=", 1)
            with open(path) as f:
                saved = json.load(f)
            results.update(saved if "rows" not in saved else {name: saved})
    else:
        sets = [s for s in args.sets.split(",") if s]
        for s in sets:
            if s not in SETS:
                ap.error(f"unknown set {s!r}; choose from {', '.join(SETS)}")
        presets = None if args.presets == "all" else args.presets.split(",")
        started = datetime.datetime.now(datetime.timezone.utc)
        with tempfile.TemporaryDirectory() as tmp:
            results = measure(sets, args.formats.split(","), presets, args.repeat, args.crop, tmp)
        print(f"{started:%Y-%m-%d %H:%M} UTC, {os.cpu_count()} cores: "
              f"python bench/bench_front.py {' '.join(sys.argv[1:])}")
        if args.json:
            with open(args.json, "w") as f:
                json.dump(results, f, indent=1, default=str)
    print(header(results))
    print()
    print(table(results))


if __name__ == "__main__":
    main()
