"""Scenes drive the recipes: a glTF 2.0 model's materials and samplers say what
each texture is for, and each image is baked with only the processing its uses
call for (docs/scene.md).

- base colour is sRGB colour; its material's alphaMode decides the alpha: OPAQUE
  drops it, MASK keeps alpha-test coverage at the cutoff down the chain, BLEND
  filters with premultiplied weighting;
- emissive is sRGB colour without alpha;
- occlusion (R) and metallic-roughness (G roughness, B metalness) are linear
  data: no sRGB curve, a format holding the channels those uses read;
- normal maps get renormalised normal-map mips (BC5 on desktop, Z rebuilt by
  the reader);
- a sampler's wrapS/wrapT become the mip filter's wrap modes, and a minFilter
  without mipmaps means no mips at all.

Uses are grouped per image: uses that agree (same kind, alpha treatment and
sampler settings) share one bake; an image used in incompatible ways is baked
once per way. The jobs are a plain list of (source, output, recipe) run through
texcook.pipeline.bake_file. The outputs are the baked textures, scene.json and
a rewritten model that references them while keeping the original images as
the fallback.
"""

from __future__ import annotations

import copy
import json
import os
import tempfile

from ..errors import InputError, UsageError
from ..fileio import atomic_write
from .model import ImageSource, Model, extract_images, image_bytes, load_model  # noqa: F401
from .plan import (DEFAULT_CUTOFF, FILTER_NAMES, FORMAT_TABLE, STEPS, TARGETS, WRAP_MODES, Bake,  # noqa: F401
                   Use, check_choices, choose_format, collect_uses, foreign_textures, plan, sampler_info,
                   texture_cutoff)
from .publish import (EXT_ASTC, EXT_DDS, EXT_KTX2, MIME_TYPES, SCENE_JSON, _finite, _glb_bytes,  # noqa: F401
                      _resource_copies, describe, extension_for, level0_psnr, name_outputs, rewrite_model)


def run_jobs(jobs, threads=None):
    """Bake each (source, output, recipe) job; the summaries in job order."""
    from ..pipeline import bake_file

    return [bake_file(src, dst, recipe, threads=threads) for src, dst, recipe in jobs]


def bake_scene(model_path, outdir, target="desktop", container="ktx2", preset="medium", threads=None,
               available=None):
    """Bake every texture of a glTF model for its uses into `outdir`, with
    scene.json and the rewritten model. Returns the scene.json content."""
    from ..pipeline import compare

    check_choices(target, container)
    model = load_model(model_path)
    outdir = os.fspath(outdir)
    if os.path.abspath(outdir) == model.folder:
        raise UsageError("the output folder is the model's own: the rewritten model and its files would "
                         "replace the originals; choose another -o", outdir)
    if os.path.exists(outdir) and not os.path.isdir(outdir):
        raise UsageError("the output must be a folder", outdir)
    gltf = model.gltf
    uses = collect_uses(gltf)
    textures = gltf.textures or []
    images = {textures[u.texture].source for u in uses
              if 0 <= u.texture < len(textures) and textures[u.texture].source is not None}
    model_name = os.path.basename(model.path)
    taken = {SCENE_JSON, model_name.lower()}
    with tempfile.TemporaryDirectory(prefix="texcook-scene-") as work:
        sources = extract_images(model, work, images)
        bakes, skipped = plan(model, target, container, preset, sources, available)
        new = copy.deepcopy(gltf)
        # the copied resources are named first, so that baked names avoid them
        copies = _resource_copies(model, new, taken)
        name_outputs(model, bakes, container, taken)
        os.makedirs(outdir, exist_ok=True)
        jobs = [(sources[b.image].path, os.path.join(outdir, b.output), b.recipe) for b in bakes]
        summaries = run_jobs(jobs, threads)
        psnr = [level0_psnr(compare(src, dst, level=0), b.read_channels) for (src, dst, _), b in zip(jobs, bakes)]
        baked_data = []
        for _, dst, _ in jobs:
            with open(dst, "rb") as fh:
                baked_data.append(fh.read())
    blob, texture_of = rewrite_model(model, new, bakes, container, baked_data)
    for src, rel in copies:
        dst = os.path.join(outdir, rel)
        os.makedirs(os.path.dirname(dst), exist_ok=True)
        try:
            with open(src, "rb") as fh:
                data = fh.read()
        except OSError as exc:
            raise InputError(f"cannot read ({exc.strerror})", src) from None
        atomic_write(dst, data)
    text = new.gltf_to_json()
    out_model = os.path.join(outdir, model_name)
    atomic_write(out_model, _glb_bytes(text, blob) if model.kind == "glb" else text.encode("utf-8"))
    report = describe(model, bakes, skipped, summaries, psnr, texture_of, target, container, preset,
                      model_name, [e for e in new.extensionsUsed if e in (EXT_DDS, EXT_ASTC, EXT_KTX2)])
    atomic_write(os.path.join(outdir, SCENE_JSON), (json.dumps(_finite(report), indent=2) + "\n").encode())
    return report
