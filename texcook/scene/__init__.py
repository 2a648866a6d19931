"""Scenes drive the recipes: a glTF 2.0 model's materials and samplers say what
each texture is for, and each image is baked with only the processing its uses
call for (docs/scene.md).

- base colour is sRGB colour; its material's alphaMode decides the alpha: OPAQUE
  drops it, MASK keeps alpha-test coverage at the cutoff down the chain, BLEND
  filters with premultiplied weighting;
- emissive is sRGB colour without alpha;
- occlusion (R) and metallic-roughness (G roughness, B metalness) are linear
  data: no sRGB curve, a format holding the channels those uses read;
- normal maps get renormalised normal-map mips;
- a sampler's wrapS/wrapT become the mip filter's wrap modes, and a minFilter
  without mipmaps means no mips at all.

Uses are grouped per image: uses that agree (same kind, alpha treatment and
sampler settings) share one bake; an image used in incompatible ways is baked
once per way. Each bake is planned once (texcook.plan): scene.json's steps are
read from that plan, and the jobs, a plain list of (source, output, plan), run
it through texcook.pipeline.bake_file.

The outputs (baked textures, copies of the model's files, the rewritten model
and scene.json) are made in a private folder inside OUTDIR and moved into
place together at the end: a failure or an interrupt before then leaves OUTDIR
as it was.
"""

from __future__ import annotations

import json
import os
import tempfile
import urllib.parse

from ..choices import DEFAULT_PRESET, ZSTD_LEVELS
from ..container import table as containers
from ..errors import TexcookError, UsageError
from ..fileio import atomic_write, format_size, read_bytes
from .model import (  # noqa: F401
    ImageSource,
    Model,
    Refusal,
    extract_images,
    image_bytes,
    load_model,
    read_resource,
    read_sources,
    refusals_error,
    resolve_uri,
    resource_bytes,
)
from .plan import (  # noqa: F401
    DEFAULT_CUTOFF,
    FILTER_NAMES,
    FORMAT_TABLE,
    STEPS,
    TARGETS,
    WRAP_MODES,
    Bake,
    Use,
    check_choices,
    choose_format,
    collect_uses,
    foreign_textures,
    plan,
    sampler_info,
    texture_cutoff,
)
from .publish import (  # noqa: F401
    EXT_ASTC,
    EXT_DDS,
    EXT_KTX2,
    FALLBACKS,
    INCOMPLETE,
    MIME_TYPES,
    SCENE_JSON,
    Stage,
    _finite,
    _glb_bytes,
    _identities,
    check_outdir,
    check_targets,
    default_fallback,
    describe,
    extension_for,
    level0_psnr,
    model_bytes,
    name_copies,
    name_outputs,
    rewrite_model,
)

# Zstandard level for a scene's KTX2 files: a model is baked once and loaded
# many times, and decoding costs the same at every level. 19 made corpus BC1
# files 7% smaller than level 3 at about 6 MB/s, a small part of a bake.
DEFAULT_ZSTD = 19


def run_jobs(jobs, threads=None, progress=None, keep_going=False, shown=None):
    """Bake each (source, output, recipe or its plan for output) job, in order. Returns per job its
    summary, or with `keep_going` the TexcookError that stopped it.
    `progress(index, result, count)` is called as each job finishes (and
    once with index None before the first starts);
    `shown[i]` is what an error names instead of job i's output (a file in
    a private folder means nothing to the user)."""
    from ..pipeline import bake_file

    results = []
    if progress is not None:
        progress(None, None, len(jobs))
    for i, (src, dst, recipe) in enumerate(jobs):
        try:
            result = bake_file(src, dst, recipe, threads=threads)
        except TexcookError as exc:
            if shown is not None and exc.path == os.fspath(dst):
                exc = type(exc)(exc.message, shown[i])
            if not keep_going:
                raise exc from None
            result = exc
        results.append(result)
        if progress is not None:
            progress(i, result, len(jobs))
    return results


def _zstd_level(container, zstd):
    box = containers.get(container)
    if not box.zstd:
        if zstd:
            raise UsageError(f"--zstd applies to KTX2 outputs, not {box.title}")
        return None
    level = DEFAULT_ZSTD if zstd is None else int(zstd)
    if not (level == 0 or ZSTD_LEVELS[0] <= level <= ZSTD_LEVELS[1]):
        raise UsageError(f"zstd level must be 0 (none) or {ZSTD_LEVELS[0]}..{ZSTD_LEVELS[1]}, not {zstd}")
    return level or None


def _size(path):
    try:
        return os.stat(path).st_size
    except OSError:
        return 0


def bake_scene(model_path, outdir, target="desktop", container=containers.DEFAULT, preset=DEFAULT_PRESET, threads=None,
               available=None, zstd=None, fallback=None, keep_going=False, progress=None, rdo=None):
    """Bake every texture of a glTF model for its uses into `outdir`, with
    scene.json and the rewritten model. Returns the scene.json content.

    zstd: KTX2 supercompression level (None: DEFAULT_ZSTD; 0: none).
    rdo: the RDO lambda (texcook.rdo) of the bakes in formats it reworks (None or 0: none).
    fallback: "keep" or "drop" the source images in the rewritten model
    (None: default_fallback of the model's kind). keep_going: bake what can
    be baked and list the rest (`not_baked`); otherwise a refused file or a
    failed bake stops the scene and OUTDIR is left as it was.
    progress(index, summary or error, count) is called as each bake ends,
    and with index None before the first."""
    from ..pipeline import compare

    check_choices(target, container)
    level = _zstd_level(container, zstd)
    if fallback is not None and fallback not in FALLBACKS:
        raise UsageError(f"fallback must be one of {', '.join(FALLBACKS)}, not {fallback!r}")
    model = load_model(model_path)
    fallback = fallback or default_fallback(model.kind)
    outdir = os.fspath(outdir)
    check_outdir(model, outdir)
    gltf = model.gltf
    textures = gltf.textures or []
    images = {textures[u.texture].source for u in collect_uses(gltf)
              if 0 <= u.texture < len(textures) and textures[u.texture].source is not None}
    with tempfile.TemporaryDirectory(prefix="texcook-scene-") as work:
        sources, refusals = read_sources(model, work, images)
        if refusals and not keep_going:  # found before any bake
            raise refusals_error(model, refusals)
        bakes, skipped = plan(model, target, container, preset, sources, available, level, rdo)
        model_name = os.path.basename(model.path)
        taken = {SCENE_JSON, model_name.lower(), INCOMPLETE}
        copies = name_copies(model, model.doc, taken, {r.uri for r in refusals})
        name_outputs(model.doc, bakes, container, taken)
        # every name an output may take, checked before any work
        ids = _identities([model.path] + [src for src, _ in copies.values()]
                          + [s.path for s in sources.values() if s.path])
        names = [rel for _, rel in copies.values()] + [model_name, SCENE_JSON]
        check_targets(outdir, names + ([b.output for b in bakes] if model.kind != "glb" else []), ids)
        stage = Stage(outdir)
        try:
            jobs = []
            for i, b in enumerate(bakes):  # each runs the plan its scene.json steps were read from
                dst = os.path.join(stage.path, f"bake{i}.{container}")
                jobs.append((sources[b.image].path, dst, b.plan.writing_to(dst)))
            summaries = run_jobs(jobs, threads, progress, keep_going,
                                 [os.path.join(outdir, model_name if model.kind == "glb" else b.output)
                                  for b in bakes])
            results, baked = [], []
            for (src, dst, _), b, summary in zip(jobs, bakes, summaries):
                if isinstance(summary, TexcookError):
                    results.append(None)
                    baked.append(None)
                    continue
                results.append((summary, level0_psnr(compare(src, dst, level=0), b.read_channels)))
                baked.append(read_bytes(dst, "baked texture"))
            report, files = _outputs(model, model_name, bakes, skipped, summaries, results, baked, jobs, refusals,
                                     {"target": target, "container": container, "preset": preset, "zstd": level,
                                      "rdo": float(rdo or 0.0), "fallback": fallback}, stage, copies)
            check_targets(outdir, [rel for rel, _ in files], ids)  # again: OUTDIR may have changed meanwhile
            stage.publish(files)
        finally:
            stage.close()
    return report


def _outputs(model, model_name, bakes, skipped, summaries, results, baked, jobs, refusals, settings, stage,
             copies):
    """scene.json's content and the (name in OUTDIR, staged file) list."""
    not_baked = [dict(u.to_dict(), texture=u.texture, why=why) for u, why in skipped]
    for b, summary in zip(bakes, summaries):
        if isinstance(summary, TexcookError):
            not_baked += [dict(u.to_dict(), texture=u.texture, why=str(summary)) for u in b.uses]
    unserved = {row["texture"] for row in not_baked}
    doc, blob, texture_of, image_of = rewrite_model(model, bakes, baked, settings["container"],
                                                    settings["fallback"], unserved, copies)
    data = model_bytes(model, doc, blob)
    files = []
    referenced = {obj.get("uri") for kind in ("buffers", "images") for obj in doc.get(kind) or []}
    before = _size(model.path)
    seen = set()
    for src, rel in copies.values():
        if src in seen:
            continue
        seen.add(src)
        before += _size(src)
        if urllib.parse.quote(rel) in referenced:
            path = stage.file(rel)
            atomic_write(path, read_resource(model, src, rel))
            files.append((rel, path))
    on_disk = model.kind != "glb"  # a GLB holds its baked textures: no loose copies beside it
    if on_disk:
        files += [(b.output, dst) for (_, dst, _), b, r in zip(jobs, bakes, results) if r is not None]
    after = len(data) + sum(_size(path) for _, path in files)
    settings = dict(settings, output_model=model_name, extensionsUsed=doc.get("extensionsUsed", []),
                    extensionsRequired=doc.get("extensionsRequired", []),
                    size={"before": before, "after": after})
    if refusals:
        settings["refused"] = [r.to_dict() for r in refusals]
    report = describe(model, bakes, results, texture_of, image_of, not_baked, settings, on_disk)
    path = stage.file(model_name)
    atomic_write(path, data)
    files.append((model_name, path))
    path = stage.file(SCENE_JSON)
    atomic_write(path, (json.dumps(_finite(report), indent=1) + "\n").encode())
    files.append((SCENE_JSON, path))
    return report, files


def summary_line(report, outdir):
    """The last line `texcook scene` prints."""
    done = {t["texture"] for t in report["textures"]}
    size = report["size"]
    text = (f"{os.path.join(outdir, report['output_model'])}, {os.path.join(outdir, SCENE_JSON)}: "
            f"{len(done)} texture{'s' if len(done) != 1 else ''} in {len(report['bakes'])} "
            f"bake{'s' if len(report['bakes']) != 1 else ''}")
    if report["not_baked"]:
        n = len({row["texture"] for row in report["not_baked"]})
        text += f", {n} texture{'s' if n != 1 else ''} not baked"
    what = "model" if report["output_model"].lower().endswith(".glb") else "model with its files"
    text += f"; {what} {format_size(size['before'])} -> {format_size(size['after'])}"
    if report["bakes"]:
        kind = "GLB" if report["output_model"].lower().endswith(".glb") else ".gltf"
        why = {("GLB", "drop"): "the GLB default: every reader downloads the whole file",
               ("GLB", "keep"): "for viewers without the extension",
               (".gltf", "keep"): "the .gltf default: fetched only by viewers without the extension",
               (".gltf", "drop"): "readers need the extension"}[(kind, report["fallback"])]
        text += (f"; source images {'kept' if report['fallback'] == 'keep' else 'dropped'} "
                 f"({why}; --fallback {'drop' if report['fallback'] == 'keep' else 'keep'} to change)")
    return text
