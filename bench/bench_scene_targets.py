"""A whole scene bake per target, as a user runs it: `texcook scene` on a
five-texture model, one process per bake, warm kernel cache.

    python bench/bench_scene_targets.py [--size 2048] [--targets desktop,mobile]
                                        [--models smooth,detailed] [--preset medium] [--repeat 1]

Two models, each one material with base colour, normal, metallic-roughness,
occlusion and emissive textures of SIZE x SIZE (every texture with its mips):

- smooth: generated from a fixed seed with bench_astc_outside.py's generators
  (a PBR-like base colour of three materials with noise, a bump map's
  normals, smooth metallic-roughness, occlusion and emissive fields);
- detailed: corpus images tiled to SIZE (rgb-00 colour, xy-00 normal, rgb-03
  metallic-roughness, rgb-05 as grey occlusion, rgb-07 emissive).

Prints, per model and target, the wall seconds and the CPU seconds of the bake
process (its children's rusage: the machine may be shared, CPU time moves less
with other work), and each target's ratio to the first target's. A 576x576
model of each target is baked first (large enough to take the kernels a large
image takes) so that no figure includes compiling.
"""

import argparse
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "tests"))
from bench_astc import ROOT  # noqa: E402
from bench_astc_outside import _base_colour, _smooth_field, _u8  # noqa: E402
from outside_set import _normals  # noqa: E402
from test_scene import build  # noqa: E402

CORPUS = Path(ROOT)
SLOTS = ("baseColorTexture", "normalTexture", "metallicRoughnessTexture", "occlusionTexture", "emissiveTexture")


def smooth(size):
    rng = np.random.default_rng(36)
    grey = lambda f: np.repeat(f[..., None], 3, axis=-1)  # noqa: E731
    base = _u8(_base_colour(rng, size, size, 1.5))
    normal = _normals(_smooth_field(rng, size, size, 24), size / 48)
    mr = np.zeros((size, size, 3))
    mr[..., 1] = 60 + 150 * _smooth_field(rng, size, size, 6)
    mr[..., 2] = 255 * (_smooth_field(rng, size, size, 3) > 0.5)
    occ = grey(140 + 115 * _smooth_field(rng, size, size, 10))
    emi = _smooth_field(rng, size, size, 4)[..., None] * np.array([255.0, 120.0, 30.0]) * 0.6
    return [base, normal, _u8(mr), _u8(occ), _u8(emi)]


def detailed(size):
    def tiled(name, grey=False):
        sub = name.split("-")[1].replace("xy", "normal")
        px = oiio.ImageBuf(str(CORPUS / sub / f"{name}.png")).get_pixels(oiio.UINT8)[..., :3].astype(np.float64)
        if grey:
            px = np.repeat(px.mean(axis=-1, keepdims=True), 3, axis=-1)
        reps = (-(-size // px.shape[0]), -(-size // px.shape[1]), 1)
        return _u8(np.tile(px, reps)[:size, :size])

    return [tiled("ldr-rgb-00"), tiled("ldr-xy-00"), tiled("ldr-rgb-03"), tiled("ldr-rgb-05", grey=True),
            tiled("ldr-rgb-07")]


MODELS = {"smooth": smooth, "detailed": detailed}


def write_model(folder, textures):
    folder.mkdir(parents=True, exist_ok=True)
    images = {slot: px for slot, px in zip(SLOTS, textures)}
    material = {"name": "m", "slots": {slot: i for i, slot in enumerate(SLOTS)}}
    return build(folder / "model.gltf", images, [(slot, None) for slot in SLOTS], [material])


def bake(model, out, target, preset):
    """(wall s, CPU s) of one `texcook scene` process."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run([shutil.which("texcook") or "texcook", "scene", str(model), "-o", str(out), "--target", target,
                    "--preset", preset, "--quiet"], check=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=int, default=2048)
    ap.add_argument("--targets", default="desktop,mobile")
    ap.add_argument("--models", default="smooth,detailed")
    ap.add_argument("--preset", default="medium")
    ap.add_argument("--repeat", type=int, default=1, help="best of K bakes per model and target")
    args = ap.parse_args()
    targets = args.targets.split(",")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        # above the size where cutting blocks and colour conversion switch to their kernels
        warm = write_model(tmp / "warm", smooth(576))
        for target in targets:
            bake(warm, tmp / f"warm-{target}", target, args.preset)
        print(f"{args.size}x{args.size}, five textures, preset {args.preset}, "
              f"load {os.getloadavg()[0]:.2f} at the start")
        print("| model | target | wall s | CPU s | wall / " + targets[0] + " | CPU / " + targets[0] + " |")
        print("|---|---|---|---|---|---|")
        for name in args.models.split(","):
            model = write_model(tmp / name, MODELS[name](args.size))
            first = None
            for target in targets:
                runs = [bake(model, tmp / f"{name}-{target}-{k}", target, args.preset) for k in range(args.repeat)]
                wall, cpu = min(r[0] for r in runs), min(r[1] for r in runs)
                first = first or (wall, cpu)
                print(f"| {name} | {target} | {wall:.1f} | {cpu:.1f} | {wall / first[0]:.2f}x | "
                      f"{cpu / first[1]:.2f}x |", flush=True)


if __name__ == "__main__":
    main()
