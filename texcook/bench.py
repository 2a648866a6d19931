"""What accuracy costs in time: one harness over the codec registry.

For each format and preset: quality (as the format's row in texcook.formats
declares it is scored, on an independent decoder's output where one exists),
encode speed single-threaded and on every core, bits per texel, and the time
the first call takes beyond a warm run (compiling or loading the kernels).
Peers run on the same images when installed (astcenc's levels each in a
process of its own: Spawned). Figures come
back as one JSON-able dict; `plot` draws them.

Quality is measured on 8-bit values as stored (sRGB-encoded colour, straight
alpha), which is how the peers' own figures are quoted. Every image is
cropped to a multiple of the format's block size so no encoder is judged on
padding.
"""

from __future__ import annotations

import math
import os
import platform
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import __version__, codecs, formats
from ._jit import encoder_first_use
from .choices import DEFAULT_PRESET
from .errors import UsageError

CORPUS = Path(__file__).resolve().parent.parent / "corpus"
IMAGE_EXTENSIONS = (".png", ".tga", ".tif", ".tiff", ".jpg", ".jpeg", ".exr", ".hdr")

# Which bundled corpus folders each scoring is measured on by default.
CORPUS_FOLDERS = {"rgb": ("rgb", "rgba"), "rgba": ("rgb", "rgba"), "alpha": ("rgba",), "normal": ("normal",),
                  "hdr": ("hdr",)}

DEFAULT_FORMATS = ("bc1", "bc1a", "bc3", "bc4", "bc5", "etc1")


@dataclass
class Picture:
    name: str
    folder: str
    rgba: np.ndarray  # uint8 (H, W, 4), straight alpha
    has_alpha: bool  # "rgba" scoring counts alpha only for images that have it
    hdr: np.ndarray | None = None  # float sources: linear float32 (H, W, 4), what "hdr" scoring encodes


def source_of(scoring, pic):
    """The pixels a scoring's encoders take: linear floats for "hdr" (8-bit
    sources as linear light), 8-bit RGBA otherwise."""
    if scoring != "hdr":
        return pic.rgba
    if pic.hdr is not None:
        return pic.hdr
    from .colour import srgb_to_linear

    lin = pic.rgba.astype(np.float32) / 255.0
    lin[..., :3] = srgb_to_linear(lin[..., :3])
    return np.ascontiguousarray(lin, np.float32)


def _corpus_folder(top, path):
    """The corpus folder name (rgb, rgba, normal, hdr) an image sits in directly
    under a folder given to the bench, or "" (bench/outside_set.py writes a set
    laid out so)."""
    parts = path.relative_to(top).parts
    return parts[0] if len(parts) == 2 and parts[0] in _FOLDER_NAMES else ""


_FOLDER_NAMES = frozenset(f for folders in CORPUS_FOLDERS.values() for f in folders)


def load_images(paths=None):
    """Images as 8-bit RGBA; folders are searched for images. Without paths,
    the bundled corpus; the corpus, and a given folder laid out like it, are
    tagged by folder, so each scoring takes its own."""
    from .image import read_image
    from .colour import to_rgba

    if not paths:
        files = [(p, p.parent.name) for p in sorted(CORPUS.rglob("*")) if p.suffix in (".png", ".hdr", ".exr")]
    else:
        files = []
        for p in map(Path, paths):
            if p.is_dir():
                files += [(q, _corpus_folder(p, q)) for q in sorted(p.rglob("*"))
                          if q.suffix.lower() in IMAGE_EXTENSIONS]
            else:
                files.append((p, ""))
    out = []
    for f, folder in files:
        img = read_image(f)
        px = to_rgba(img.pixels, False)
        hdr = None
        if img.is_float:
            from .colour import encode_colour

            hdr = np.ascontiguousarray(px, np.float32)
            px = encode_colour(np.clip(px, 0.0, 1.0), True, 3)  # HDR shown as sRGB 8-bit, clipped
        rgba = np.clip(np.rint(px * 255.0), 0, 255).astype(np.uint8)
        out.append(Picture(f.name, folder, rgba, img.alpha != "none", hdr))
    if not out:
        raise UsageError("no images to measure")
    return out


def images_for(scoring, pictures):
    """The images a scoring is measured on: the corpus folders it names, or
    every given image."""
    folders = CORPUS_FOLDERS[scoring]
    tagged = [p for p in pictures if p.folder]
    if not tagged:
        return pictures
    return [p for p in pictures if p.folder in folders]


def prepare(scoring, rgba, block_w, block_h):
    """What the encoder is given for this scoring, cropped to whole blocks."""
    h = rgba.shape[0] // block_h * block_h
    w = rgba.shape[1] // block_w * block_w
    px = rgba[:h, :w]
    if scoring == "alpha":
        px = np.repeat(px[:, :, 3:4], 4, axis=2)
    return np.ascontiguousarray(px)


def score(scoring, src, dec, has_alpha=True):
    """(sum of squared errors, values counted, angles in degrees or None): sums
    so a set's PSNR can pool them (one exactly-kept image gives no infinity).
    "rgba" counts alpha only where the image has it, as astcenc's figures do."""
    src = src.astype(np.float64)
    dec = dec.astype(np.float64)
    if scoring == "hdr":
        from .metrics import hdr_log2_errors

        d = hdr_log2_errors(src[..., :3], dec[..., :3])
        return float(np.sum(d * d)), d.size, None
    chans = {"rgb": [0, 1, 2], "rgba": [0, 1, 2, 3] if has_alpha else [0, 1, 2], "alpha": [0],
             "normal": [0, 1]}[scoring]
    d = src[..., chans] - dec[..., chans]
    angles = None
    if scoring == "normal":
        from .metrics import normal_angular_errors

        angles = normal_angular_errors(src, dec)
    return float(np.sum(d * d)), d.size, angles


def psnr_of(se, n, peak=255.0):
    return math.inf if se == 0 else 10.0 * math.log10(peak**2 * n / se)


def peak_of(scoring, src):
    """The PSNR peak of a scoring: 255, or for "hdr" the source's range in
    stops (metrics.log2_psnr)."""
    if scoring != "hdr":
        return 255.0
    from .metrics import log2_peak

    return log2_peak(src[..., :3])


# --- independent decoders and peers -----------------------------------------------


def independent_decoder(fmt):
    """A function (data, w, h) -> RGBA uint8 from texture2ddecoder (the
    format's `t2d` function), or None."""
    f = formats.get(fmt)
    if not f.t2d:
        return None
    try:
        import texture2ddecoder
    except ImportError:
        return None
    fn = getattr(texture2ddecoder, f.t2d)
    blocks = (f.block_w, f.block_h) if f.family == "astc" else ()

    def dec(data, w, h):
        bgra = fn(bytes(data), w, h, *blocks)
        return np.frombuffer(bgra, np.uint8).reshape(h, w, 4)[:, :, [2, 1, 0, 3]]

    if not f.transform:
        return dec
    from .colour import quantize_unorm8
    from .transforms import KV_KEY, inverse, record_format_step

    # the step as a file of this format records it, undone as a reader undoes it
    record = record_format_step({}, f.transform)[KV_KEY]

    def dec_undone(data, w, h):
        # the stored format's texels, then the step undone (bc3-ycocg: the shader's RGB)
        stored = dec(data, w, h).astype(np.float32) / 255.0
        return quantize_unorm8(inverse([stored], record)[0])

    return dec_undone


def judge(fmt):
    """(name, decode(data, w, h) -> RGBA uint8) of the decoder every encoder of
    a format is scored through, or (None, None). ASTC is decoded by astcenc,
    the format's reference decoder, whose 8-bit output is the top byte of the
    16-bit interpolation as the specification says; texture2ddecoder rounds
    that value to nearest instead (a step apart in about a quarter of the
    values of a photograph), which scores an encoder that aims at the
    specified output up to 0.2 dB low. Other formats, and ASTC without
    astcenc, are decoded by texture2ddecoder."""
    f = formats.get(fmt)
    if f.family == "astc" and f.scoring != "hdr":
        try:
            import astc_encoder as A
        except ImportError:
            pass
        else:
            cfg = A.ASTCConfig(A.ASTCProfile.LDR, f.block_w, f.block_h, 1, A.ASTCQualityPreset.FASTEST,
                               A.ASTCConfigFlags.DECOMPRESS_ONLY)
            ctx, swizzle = A.ASTCContext(cfg, 1), A.ASTCSwizzle.from_str("RGBA")

            def dec(data, w, h):
                out = A.ASTCImage(A.ASTCType.U8, w, h, 1)
                ctx.decompress(bytes(data), out, swizzle)
                return np.frombuffer(out.data, np.uint8).reshape(h, w, 4)

            return "astcenc", dec
    dec = independent_decoder(fmt)
    return ("texture2ddecoder", dec) if dec else (None, None)


def scorer(fmt):
    """(name, decode) every encoder of a format is scored through: its judge,
    or texcook's own decoder where the format has none installed."""
    name, dec = judge(fmt)
    if dec is None:
        codec = codecs.get(fmt)
        name, dec = "texcook", lambda data, w, h: codec.decode(data, w, h)
    return name, dec


def measure_peer(fmt, peer, pictures, repeat):
    """One peer's row over the pictures (None when there is nothing to score):
    peer is (name, encode[, decode]) from `peers`; a Spawned encode is
    measured in a process of its own."""
    name, fn, *own_decoder = peer
    if isinstance(fn, Spawned):
        return fn.measure(fmt, name, pictures, repeat)
    f = formats.get(fmt)
    judge_name, decoder = scorer(fmt)
    if own_decoder:  # a peer of another format at the same bits per texel decodes its own data
        decoder, judge_name = own_decoder[0], name.split()[0]
    fn(prepare(f.scoring, source_of(f.scoring, pictures[0]), f.block_w, f.block_h))  # untimed warm-up
    row = measure(fn, decoder, f.scoring, pictures, (f.block_w, f.block_h), repeat)
    if row is not None:
        row.update(encoder=name, preset=None, judge=judge_name)
    return row


def etcpak_encoder(fmt):
    """etcpak's encoder of a format (the format's `etcpak` function):
    encode(rgba uint8) -> the blocks, or None when not installed."""
    f = formats.get(fmt)
    try:
        import etcpak

        fn = getattr(etcpak, f.etcpak)
    except (ImportError, AttributeError):
        return None

    def run(img):
        h, w = img.shape[:2]
        data = fn(img.tobytes(), w, h)
        # its EAC R11 returns w * h bytes: the blocks, then zeros
        return data if len(data) == f.level_size(w, h) else data[:f.level_size(w, h)]

    return run


def peers(fmt):
    """[(name, encode(rgba) -> bytes[, decode(data, w, h) -> pixels])] for the
    peers installed here, and the names of peers for this format that are
    missing. A peer with its own decode writes another format at the same
    bits per texel (astcenc 4x4 HDR beside BC6H)."""
    f = formats.get(fmt)
    out, missing = [], []
    try:
        import quicktex
        import quicktex.s3tc.bc1 as qb1
        import quicktex.s3tc.bc3 as qb3
        import quicktex.s3tc.bc4 as qb4
        import quicktex.s3tc.bc5 as qb5

        def qt(enc):
            def run(img):
                tex = quicktex.RawTexture.frombytes(img.tobytes(), img.shape[1], img.shape[0])
                return enc.encode(tex).tobytes()

            return run

        if fmt == "bc1":
            out += [(f"quicktex {lvl}", qt(qb1.BC1Encoder(lvl))) for lvl in (0, 5, 10, 18)]
        elif fmt == "bc3":
            out.append(("quicktex 5", qt(qb3.BC3Encoder(5))))
        elif fmt == "bc4":
            out.append(("quicktex", qt(qb4.BC4Encoder(0))))
        elif fmt == "bc5":
            out.append(("quicktex", qt(qb5.BC5Encoder(0, 1))))
    except ImportError:
        if fmt in ("bc1", "bc3", "bc4", "bc5"):
            missing.append("quicktex")
    if fmt == "bc7":
        try:
            import bc7enc

            # bc7enc_rdo's uber levels, scored on plain RGBA error (not its perceptual weights)
            out += [(f"bc7enc uber {u}", _bc7enc(bc7enc, u)) for u in (0, 2, 4)]
        except ImportError:
            missing.append("bc7enc (bc7enc-py)")
    if f.etcpak:
        run = etcpak_encoder(fmt)
        if run is None:
            missing.append("etcpak")
        else:
            out.append(("etcpak", run))
    if fmt in NVCOMPRESS_FLAGS:
        import shutil

        if shutil.which("nvcompress"):
            out += [("nvcompress" + (" -fast" if fast else ""), _nvcompress(fmt, fast)) for fast in (False, True)]
        else:
            missing.append("nvcompress (Debian libnvtt-bin)")
    astcenc_hdr = f.scoring == "hdr" and f.bits_per_texel == 8
    if f.family == "astc" or astcenc_hdr:
        try:
            import astc_encoder  # noqa: F401 (only whether it is here: each level is made in its own process)
        except ImportError:
            missing.append("astcenc (astc-encoder-py)")
        else:
            levels = ("fastest", "medium", "thorough")
            if f.family == "astc":
                out += [(f"astcenc {q}", Spawned(_astcenc_peer, fmt, q)) for q in levels]
            if astcenc_hdr:
                out += [(f"astcenc 4x4 HDR {q}", Spawned(_astcenc_hdr_peer, q)) for q in levels]
    return out, missing


class Spawned:
    """A peer measured in a spawned process of its own, where `make(*args)`
    builds its (encode[, decode]). astcenc keeps state between compressions at
    different levels in one process: after one 5x5 `fastest` or `medium`
    compress, a new 5x5 `thorough` context writes other blocks (grey corpus
    48.964 dB against 49.193 run alone). The worker times its own encodes."""

    def __init__(self, make, *args):
        self.make, self.args = make, args

    def measure(self, fmt, name, pictures, repeat):
        return in_spawned_process(_measure_made_peer, fmt, name, self.make, self.args, pictures, repeat)


def in_spawned_process(fn, *args):
    """fn(*args) in a fresh interpreter (module-level fn, picklable args)."""
    import concurrent.futures
    import multiprocessing

    ctx = multiprocessing.get_context("spawn")
    with concurrent.futures.ProcessPoolExecutor(1, mp_context=ctx) as ex:
        return ex.submit(fn, *args).result()


def _measure_made_peer(fmt, name, make, args, pictures, repeat):
    """Spawned.measure's work, in the spawned process."""
    return measure_peer(fmt, (name, *make(*args)), pictures, repeat)


def _astcenc_peer(fmt, quality):
    import astc_encoder

    return (_astcenc(astc_encoder, formats.get(fmt), quality),)


def _astcenc_hdr_peer(quality):
    import astc_encoder

    return _astcenc_hdr(astc_encoder, quality)


def _bc7enc(bc7enc, uber):
    params = bc7enc.bc7enc_compress_block_params_init()
    params.m_uber_level = uber
    params.m_perceptual = False
    for i in range(4):
        params.m_weights[i] = 1

    def run(img):
        return bc7enc.pack_dds(img.tobytes(), img.shape[1], img.shape[0], "BC7", params=params)

    return run


NVCOMPRESS_FLAGS = {"bc1": "-bc1", "bc3": "-bc3"}


def _nvcompress(fmt, fast):
    """nvcompress as a whole process (start, PNG read, encode, DDS write; our PNG
    write of its input is inside the time too, a small part at these sizes)."""
    import tempfile

    from .container.dds import read_dds
    from .fileio import read_bytes
    from .image import write_image

    def run(img):
        with tempfile.TemporaryDirectory() as tmp:
            src, dst = os.path.join(tmp, "in.png"), os.path.join(tmp, "out.dds")
            write_image(src, img)
            cmd = ["nvcompress", "-nomips", NVCOMPRESS_FLAGS[fmt]] + (["-fast"] if fast else []) + [src, dst]
            subprocess.run(cmd, check=True, capture_output=True)
            return read_dds(read_bytes(dst, "texture"), dst)[3][0]

    return run


def _astcenc(A, fmt, quality):
    """astcenc's compressor (LDR profile, one thread) as an encode function,
    told that its blocks are read by the 8-bit decode the judge uses (its
    decode_unorm8 flag: 0.002-0.08 dB better so judged, at the same speed)."""
    preset = getattr(A.ASTCQualityPreset, quality.upper())
    cfg = A.ASTCConfig(A.ASTCProfile.LDR, fmt.block_w, fmt.block_h, 1, preset, A.ASTCConfigFlags.USE_DECODE_UNORM8)
    ctx = A.ASTCContext(cfg, 1)
    swizzle = A.ASTCSwizzle.from_str("RGBA")

    def run(img):
        h, w = img.shape[:2]
        return bytes(ctx.compress(A.ASTCImage(A.ASTCType.U8, w, h, 1, img.tobytes()), swizzle))

    return run


def _astcenc_hdr(A, quality):
    """astcenc's HDR profile at 4x4 (8 bits per texel, one thread): encode on
    linear float RGBA, and its own decoder back to float."""
    preset = getattr(A.ASTCQualityPreset, quality.upper())
    ctx = A.ASTCContext(A.ASTCConfig(A.ASTCProfile.HDR, 4, 4, 1, preset), 1)
    swizzle = A.ASTCSwizzle.from_str("RGBA")

    def run(img):
        h, w = img.shape[:2]
        px = np.ascontiguousarray(img, np.float32)
        return bytes(ctx.compress(A.ASTCImage(A.ASTCType.F32, w, h, 1, px.tobytes()), swizzle))

    def dec(data, w, h):
        out = A.ASTCImage(A.ASTCType.F32, w, h, 1)
        ctx.decompress(data, out, swizzle)
        return np.frombuffer(out.data, np.float32).reshape(h, w, 4)

    return run, dec


# --- measuring ---------------------------------------------------------------------


REPEAT_BUDGET_S = 1.0  # a run slower than this is not repeated: its noise is small already


def _best_time(fn, repeat):
    best, res = math.inf, None
    for _ in range(max(1, repeat)):
        t = time.perf_counter()
        res = fn()
        best = min(best, time.perf_counter() - t)
        if best > REPEAT_BUDGET_S:
            break
    return res, best


def measure(encode, decode, scoring, pictures, block, repeat, all_cores=None):
    """One encoder over the images: quality, single-thread and all-core speed."""
    se_total, n_total, angles, psnrs = 0.0, 0, [], []
    seconds, seconds_all, pixels = 0.0, 0.0, 0
    peaks = []
    for pic in pictures:
        px = prepare(scoring, source_of(scoring, pic), *block)
        if px.size == 0:
            continue
        h, w = px.shape[:2]
        data, t = _best_time(lambda: encode(px), repeat)
        seconds += t
        if all_cores is not None:
            seconds_all += _best_time(lambda: all_cores(px), repeat)[1]
        pixels += w * h
        se, n, ang = score(scoring, px, decode(data, w, h), pic.has_alpha)
        se_total += se
        n_total += n
        peaks.append(peak_of(scoring, px))
        psnrs.append(psnr_of(se, n, peaks[-1]))
        if ang is not None:
            angles.append(ang)
    if not pixels:
        return None
    pooled = psnr_of(se_total, n_total, min(peaks))
    mean = float(np.mean(psnrs)) if all(map(math.isfinite, psnrs)) else None
    row = {
        # the mean of per-image PSNRs, as the peers' figures are quoted; pooled over
        # the set when an image comes back exactly (its PSNR is infinite)
        "psnr": pooled if mean is None else mean,
        "psnr_mean": mean,  # None when an image came back exactly
        "psnr_pooled": pooled,
        "images": len(psnrs),
        "megapixels": pixels / 1e6,
        "mpix_per_s": pixels / 1e6 / seconds if seconds else math.inf,
    }
    if all_cores is not None:
        row["mpix_per_s_all_cores"] = pixels / 1e6 / seconds_all if seconds_all else math.inf
    if angles:
        a = np.concatenate(angles)
        row["angle_mean_deg"] = float(a.mean())
        row["angle_p99_deg"] = float(np.percentile(a, 99))
    return row


def first_call_seconds(codec, preset):
    """Seconds the first encode of a tiny image takes in this process: the kernels'
    compile (cold cache) or load from the cache (warm)."""
    tiny = np.zeros((codec.block_h, codec.block_w, 4), np.float32 if codec.float_input else np.uint8)
    t = time.perf_counter()
    codec.encode(tiny, preset, threads=1)
    return time.perf_counter() - t


def cold_compile_seconds(fmt, preset):
    """The first encode in a fresh process with an empty numba cache."""
    import tempfile

    code = ("import time, numpy as np, texcook.codecs as c\n"
            f"k = c.get({fmt!r})\n"
            "x = np.zeros((k.block_h, k.block_w, 4), np.float32 if k.float_input else np.uint8)\n"
            f"t = time.perf_counter(); k.encode(x, {preset!r}, threads=1); print(time.perf_counter() - t)\n")
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    return float(out.stdout.strip().splitlines()[-1])


def machine():
    import numba

    info = {"platform": platform.platform(), "python": platform.python_version(), "cpus": os.cpu_count(),
            "processor": platform.processor() or platform.machine(), "texcook": __version__,
            "numpy": np.__version__, "numba": numba.__version__}
    for mod in ("quicktex", "etcpak", "texture2ddecoder", "astc_encoder", "matplotlib"):
        try:
            m = __import__(mod)
            info[mod] = getattr(m, "__version__", "installed")
        except ImportError:
            pass
    return info


def run(paths=None, format_names=None, presets=None, with_peers=True, threads=None, repeat=3,
        cold=False, progress=None, notices=None):
    """Measure every (format, preset) and peer; returns the JSON-able result.
    `progress(done, total, label)` is called before each row starts (label: what
    it measures) and once at the end (label None); `notices`, a stream, gets
    the first-use compile notices (default stderr, on a terminal only)."""
    pictures = load_images(paths)
    available = codecs.names()
    names = list(format_names or DEFAULT_FORMATS)
    if names == ["all"]:
        names = [n for n in available if formats.get(n).is_block_compressed]
    for n in names:
        if formats.get(n).name not in available:
            raise UsageError(f"format {n} is not available in this build")
    presets = list(presets or codecs.PRESETS)
    for p in presets:
        if p not in codecs.PRESETS:
            raise UsageError(f"unknown preset {p!r}; choose from {', '.join(codecs.PRESETS)}")
    rows, missing_peers, unscored = [], {}, {}
    jobs = []
    for n in names:
        jobs += [(n, "texcook", p) for p in presets]
        if with_peers:
            found, missing = peers(n)
            jobs += [(n, "peer", peer) for peer in found]
            if missing:
                missing_peers[n] = missing
    for i, (n, kind, what) in enumerate(jobs):
        if progress:
            progress(i, len(jobs), f"{n} {'texcook ' + what if kind == 'texcook' else what[0]}")
        fmt = formats.get(n)
        codec = codecs.get(n)
        pics = images_for(fmt.scoring, pictures)
        if not pics:
            # a set laid out like the corpus with no folder of this scoring
            # (bc5 without normal maps): nothing to measure, for any encoder
            unscored[n] = sorted(CORPUS_FOLDERS[fmt.scoring])
            continue
        block = (fmt.block_w, fmt.block_h)
        if kind == "texcook":
            judge_name, decoder = scorer(n)
            with encoder_first_use(codec, notices):
                first = first_call_seconds(codec, what)
            row = measure(lambda px, p=what: codec.encode(px, p, threads=1), decoder, fmt.scoring, pics, block,
                          repeat, all_cores=lambda px, p=what: codec.encode(px, p, threads=threads))
            if row is None:
                continue
            row.update(encoder="texcook", preset=what, first_call_s=first, judge=judge_name)
            if cold:
                row["cold_compile_s"] = cold_compile_seconds(n, what)
        else:
            row = measure_peer(n, what, pics, repeat)
            if row is None:
                continue
        row.update(format=n, family=fmt.family, scoring=fmt.scoring, bits_per_texel=fmt.bits_per_texel)
        rows.append(row)
    if progress:
        progress(len(jobs), len(jobs), None)
    return {
        "command": " ".join(sys.argv),
        "machine": machine(),
        "threads": threads or os.cpu_count(),
        "repeat": repeat,
        "images": [{"name": p.name, "folder": p.folder, "width": int(p.rgba.shape[1]),
                    "height": int(p.rgba.shape[0])} for p in pictures],
        "scorings": {k: v for k, v in formats.SCORINGS.items()},
        "missing_peers": missing_peers,
        "unscored": unscored,
        "rows": rows,
        "dominated": dominated(rows),
        "outranked": outranked(rows),
    }


# bench --stages's stages that run only when the bake's plan runs its step of that name
_PLANNED_STAGES = ("mips", "transform")


def stages(path, format_names, presets, threads=None, repeat=3):
    """Seconds per pipeline stage for a whole bake of one image, per format and
    preset (best of `repeat` by total), each bake of its plan (texcook.plan),
    made once: a row names the levels it builds and the stages it skips, and
    why."""
    import tempfile

    from .pipeline import STAGES, bake_file, plan_file
    from .recipe import Recipe

    out = []
    with tempfile.TemporaryDirectory() as tmp:
        dst = os.path.join(tmp, "out.ktx2")
        for n in format_names:
            for p in presets:
                plan = plan_file(path, dst, Recipe.of(format=n, preset=p))
                bake_file(path, dst, plan, threads=threads)  # load kernels first
                best = None
                for _ in range(max(1, repeat)):
                    t = {}
                    bake_file(path, dst, plan, threads=threads, timings=t)
                    if best is None or sum(t.values()) < sum(best.values()):
                        best = t
                skipped = {s: plan.step(s)[1] for s in _PLANNED_STAGES if not plan.step(s)[0]}
                out.append({"format": plan.format, "preset": plan.preset, "levels": len(plan.levels),
                            "seconds": {s: best.get(s, 0.0) for s in STAGES}, "skipped": skipped,
                            "total_s": sum(best.values())})
    return {"command": " ".join(sys.argv), "machine": machine(), "image": os.fspath(path), "rows": out}


# --- reading the result ------------------------------------------------------------


def quality(row):
    return row["psnr"]


def pareto(points):
    """Indices of the points no other point beats on both time (lower) and quality (higher)."""
    keep = []
    for i, (t, q) in enumerate(points):
        if not any((t2 <= t and q2 >= q) and (t2 < t or q2 > q) for j, (t2, q2) in enumerate(points) if j != i):
            keep.append(i)
    return sorted(keep, key=lambda i: points[i][0])


# PSNRs this close count as equal: the table shows two decimals
EQUAL_PSNR_DB = 0.005


def comparable_psnr(a, b):
    """(statistic, PSNR of a, PSNR of b), the same statistic for both rows of
    one format (same images): the mean of per-image PSNRs (the table's column)
    when both rows have it, else the pooled PSNR of both (an image came back
    exactly in one of them, so its mean is infinite)."""
    if a.get("psnr_mean") is not None and b.get("psnr_mean") is not None:
        return "mean", a["psnr_mean"], b["psnr_mean"]
    return "pooled", a["psnr_pooled"], b["psnr_pooled"]


def _beaten(rows, by_texcook):
    """Per texcook preset, the rows of the same format that beat it: PSNR
    better or equal (within EQUAL_PSNR_DB, on comparable_psnr's statistic)
    and faster on one thread; the peers' rows, or with by_texcook the other
    texcook presets'. One entry per preset beaten, with the rows that beat it
    (fastest first) and both rows' PSNR on the statistic compared."""
    out = []
    for r in rows:
        if r["encoder"] != "texcook":
            continue
        by = []
        for p in rows:
            if p["format"] != r["format"] or (p["encoder"] == "texcook") != by_texcook or p is r:
                continue
            statistic, mine, theirs = comparable_psnr(r, p)
            if theirs >= mine - EQUAL_PSNR_DB and p["mpix_per_s"] > r["mpix_per_s"]:
                name = f"texcook {p['preset']}" if by_texcook else p["encoder"]
                by.append({"encoder": name, "statistic": statistic, "psnr": theirs, "preset_psnr": mine,
                           "mpix_per_s": p["mpix_per_s"]})
        if by:
            by.sort(key=lambda p: -p["mpix_per_s"])
            out.append({"format": r["format"], "preset": r["preset"], "mpix_per_s": r["mpix_per_s"], "by": by})
    return out


def dominated(rows):
    """The texcook presets a peer row of the same format beats (better or
    equal PSNR, faster on one thread), so the preset is never the one to
    pick: _beaten's entries."""
    return _beaten(rows, by_texcook=False)


def outranked(rows):
    """The texcook presets another texcook preset of the same format beats
    (better or equal PSNR, faster): on these images the slower preset buys
    nothing, the presets' order does not hold. _beaten's entries."""
    return _beaten(rows, by_texcook=True)


def dominated_warnings(result):
    """One line per dominated or outranked preset of a run, for stderr."""
    lines = []
    for key, verb in (("dominated", "is dominated by"), ("outranked", "is outranked by")):
        for d in result.get(key, []):
            beaten = ", ".join(f"{p['encoder']} ({p['psnr']:.2f} dB against {p['preset_psnr']:.2f}, "
                               f"{p['statistic']} PSNR; {p['mpix_per_s']:.3g} Mpix/s)" for p in d["by"])
            lines.append(f"texcook: warning: {d['format']} {d['preset']} ({d['mpix_per_s']:.3g} Mpix/s on one "
                         f"thread) {verb} {beaten}")
    return lines


def table(result):
    """Markdown table of a run."""
    lines = ["| format | scored on | encoder | preset | PSNR dB | angle mean/p99 deg | bits/texel | "
             "Mpix/s 1 thread | Mpix/s all cores | first call s |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in result["rows"]:
        ang = f"{r['angle_mean_deg']:.3f} / {r['angle_p99_deg']:.2f}" if "angle_mean_deg" in r else ""
        allc = f"{r['mpix_per_s_all_cores']:.3g}" if "mpix_per_s_all_cores" in r else ""
        first = f"{r['first_call_s']:.2f}" if "first_call_s" in r else ""
        lines.append(f"| {r['format']} | {r['scoring']} | {r['encoder']} | {r['preset'] or ''} | {r['psnr']:.2f} | "
                     f"{ang} | {r['bits_per_texel']:.2f} | {r['mpix_per_s']:.3g} | {allc} | {first} |")
    return "\n".join(lines)


def plot(result, path, preset=DEFAULT_PRESET):
    """One PNG: a panel per format (quality against encode time, log scale,
    presets labelled, peers as crosses, the Pareto front drawn) and a last
    panel of quality against bits per texel across formats at `preset`."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = result["rows"]
    names = list(dict.fromkeys(r["format"] for r in rows))
    panels = len(names) + 1
    cols = min(3, panels)
    nrows = -(-panels // cols)
    fig, axes = plt.subplots(nrows, cols, figsize=(5.2 * cols, 4.2 * nrows), squeeze=False)
    flat = axes.ravel()
    for ax, n in zip(flat, names):
        mine = [r for r in rows if r["format"] == n]
        pts = [(1.0 / r["mpix_per_s"], quality(r)) for r in mine]  # seconds per megapixel
        front = pareto(pts)
        if len(front) > 1:
            ax.plot([pts[i][0] for i in front], [pts[i][1] for i in front], "-", color="0.7", zorder=1,
                    label="Pareto front")
        for r, (t, q) in zip(mine, pts):
            if r["encoder"] == "texcook":
                ax.scatter(t, q, color="C0", marker="o", zorder=2)
                ax.annotate(r["preset"], (t, q), textcoords="offset points", xytext=(4, 4), fontsize=8)
            else:
                ax.scatter(t, q, color="C3", marker="x", zorder=2)
                ax.annotate(r["encoder"], (t, q), textcoords="offset points", xytext=(4, -10), fontsize=8,
                            color="C3")
        ax.set_xscale("log")
        ax.set_xlabel("encode seconds per megapixel (1 thread, log)")
        ax.set_ylabel(f"PSNR dB ({mine[0]['scoring']})")
        ax.set_title(f"{n}: quality against time")
        ax.grid(True, which="both", alpha=0.3)
    ax = flat[len(names)]
    # colour formats only: alpha and normal scores measure other things
    at = [r for r in rows if r["encoder"] == "texcook" and r["preset"] == preset and r["scoring"] in ("rgb", "rgba")]
    for r in at:
        ax.scatter(r["bits_per_texel"], quality(r), color="C0")
        ax.annotate(f"{r['format']} ({r['scoring']})", (r["bits_per_texel"], quality(r)),
                    textcoords="offset points", xytext=(4, 4), fontsize=8)
    ax.set_xlabel("bits per texel")
    ax.set_ylabel("PSNR dB")
    ax.set_title(f"what accuracy costs in size (colour formats, {preset})")
    ax.grid(True, alpha=0.3)
    for extra in flat[panels:]:
        extra.set_visible(False)
    fig.tight_layout()
    from .fileio import atomic_write
    import io

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    plt.close(fig)
    atomic_write(path, buf.getvalue())
    return panels
