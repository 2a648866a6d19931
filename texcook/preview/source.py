"""What a preview samples: the texture's levels in linear light, how its
alpha is meant, and the sampler that reads it.

Levels come through `pipeline_levels`, the one place this package calls the
baking pipeline: a KTX2/DDS file's decoded levels, an .astc file's one level
(read as UNORM, as `texcook decode` reads it: the file names no colour space),
or an image's chain built as `texcook bake` builds it (the plan of the default
recipe, texcook.plan). sRGB levels are decoded to linear light before any
filtering, as a GPU's sRGB sampler does, and only the levels a filter reads
are converted.

The sampler: KTX2 and DDS carry none, so the default is glTF's (trilinear,
repeat). A `scene.json` written by `texcook scene` beside the texture supplies
the glTF sampler of the entry whose output is this file; flags override both.
"""

import json
import os
from dataclasses import dataclass

import numpy as np

from ..colour import decode_colour
from ..errors import InputError, UsageError
from ..pipeline import ALPHA_CUTOFF_KEY

# glTF filter names (texcook.scene.FILTER_NAMES holds their enum values) -> preview filters
GL_MIN_FILTERS = {
    "NEAREST": "nearest",
    "LINEAR": "bilinear",
    "NEAREST_MIPMAP_NEAREST": "nearest_mipmap_nearest",
    "LINEAR_MIPMAP_NEAREST": "linear_mipmap_nearest",
    "NEAREST_MIPMAP_LINEAR": "nearest_mipmap_linear",
    "LINEAR_MIPMAP_LINEAR": "trilinear",
}
DEFAULT_FILTER, DEFAULT_WRAP = "trilinear", ("repeat", "repeat")


@dataclass
class Texture:
    levels: list  # linear-light float32 (H, W, 4) for the levels asked for
    level_count: int  # levels the file holds (or the chain bake would build)
    srgb: bool
    has_alpha: bool
    alpha_cutoff: float  # from the file's key/value data, or None
    path: str

    @property
    def width(self):
        return self.levels[0].shape[1]

    @property
    def height(self):
        return self.levels[0].shape[0]


def pipeline_levels(path, mips, alpha_cutoff=None):
    """(levels, srgb, channels, linear, key/values, level count) from the
    baking pipeline. Textures (KTX2, DDS, .astc) give their stored levels
    (uint8 or float32 RGBA, `linear` False) and their count; images give the
    chain `bake` would build (float32, in linear light when sRGB, `linear`
    True), with a coverage-preserving chain at `alpha_cutoff`, and the count
    of levels the bake's plan builds (level 0 only is built without `mips`)."""
    from ..image import read_image
    from ..pipeline import TEXTURE_EXTENSIONS, build_levels, load_texture, plan_bake
    from ..recipe import Recipe

    ext = os.path.splitext(path)[1].lower()
    if ext in TEXTURE_EXTENSIONS:
        decoded = load_texture(path)
        kv = {k: decoded.kv[k] for k in (ALPHA_CUTOFF_KEY,) if k in decoded.kv}
        return decoded.levels, decoded.srgb, decoded.channels, False, kv, len(decoded.levels)
    image = read_image(path)
    # a cutoff is the sampler's: an image without alpha is previewed without one
    cutoff = alpha_cutoff if image.alpha != "none" else None
    plan = plan_bake(image, Recipe.of(alpha_cutoff=cutoff))
    count = len(plan.levels)
    if not mips:
        plan = plan_bake(image, Recipe.of(mips=False, alpha_cutoff=cutoff))
    channels = {1: 3, 2: 4, 3: 3, 4: 4}[image.channels]
    return build_levels(image, plan), plan.srgb, channels, True, {}, count


def _linear(level, srgb, decoded_linear):
    px = np.asarray(level)
    px = px.astype(np.float32) / 255.0 if px.dtype == np.uint8 else px.astype(np.float32)
    if srgb and not decoded_linear:
        px = decode_colour(px, True, 3)
    return np.ascontiguousarray(px, np.float32)


def load(path, mips=True, alpha_cutoff=None):
    """The texture at `path` with level 0 only, or every level when `mips`."""
    path = os.fspath(path)
    if not os.path.exists(path):
        raise InputError("no such file", path)
    levels, srgb, channels, decoded_linear, kv, count = pipeline_levels(path, mips, alpha_cutoff)
    levels = [_linear(lv, srgb, decoded_linear) for lv in (levels if mips else levels[:1])]
    cutoff = None
    if ALPHA_CUTOFF_KEY in kv:
        try:
            cutoff = float(kv[ALPHA_CUTOFF_KEY])
        except ValueError:
            raise InputError(f"bad {ALPHA_CUTOFF_KEY} value {kv[ALPHA_CUTOFF_KEY]!r}", path) from None
    return Texture(levels, count, srgb, channels == 4, cutoff, path)


# --- the sampler ---------------------------------------------------------------------


@dataclass(frozen=True)
class Sampler:
    filter: str = DEFAULT_FILTER
    mag_linear: bool = True  # None: as the filter does (nearest magnifies nearest, the rest linear)
    wrap: tuple = DEFAULT_WRAP
    alpha_cutoff: float = None
    source: str = "default"  # where the filter and wrap came from


def _scene_entry(path):
    """The entry of a scene.json beside `path` whose output is this file, or
    None. The file is read through texcook.fileio (a regular file within the
    memory budget: a FIFO is refused at once) and its shape checked: one line
    naming scene.json for anything texcook scene would not have written."""
    from ..fileio import read_bytes

    scene = os.path.join(os.path.dirname(os.path.abspath(path)), "scene.json")
    if not os.path.lexists(scene):
        return None, scene
    raw = read_bytes(scene, "scene.json")
    try:
        data = json.loads(raw)
    except (ValueError, UnicodeDecodeError) as exc:
        raise InputError(f"not readable JSON ({str(exc).splitlines()[0]})", scene) from None
    except RecursionError:
        raise InputError("not readable JSON (nested too deeply)", scene) from None
    entries = data.get("textures") if isinstance(data, dict) else None
    if not isinstance(entries, list):
        raise InputError("not a scene.json written by texcook scene (expected an object with a "
                         "\"textures\" list)", scene)
    name = os.path.basename(path)
    for i, entry in enumerate(entries):
        # an entry without "output" is a texture written into the model only (a GLB without loose files)
        if not isinstance(entry, dict) or not isinstance(entry.get("output", ""), str):
            raise InputError(f"textures[{i}] is not an object with an \"output\" name", scene)
        if os.path.basename(entry.get("output", "")) == name:
            return entry, scene
    return None, scene


def _entry_cutoff(entry, scene):
    """A cut-out's cutoff from a scene.json entry: its recipe's source.alpha_cutoff
    (texcook.recipe's saved form), else an alphaCutoff given beside the sampler;
    a number within 0..1, as --alpha-cutoff takes it."""
    recipe = entry.get("recipe")
    if recipe is not None and not isinstance(recipe, dict):
        raise InputError(f"the recipe of {entry['output']} is not an object", scene)
    source = recipe.get("source") if recipe else None
    if source is not None and not isinstance(source, dict):
        raise InputError(f"the recipe source of {entry['output']} is not an object", scene)
    cutoff = source.get("alpha_cutoff") if source else None
    cutoff = cutoff if cutoff is not None else entry.get("alphaCutoff")
    if cutoff is None:
        return None
    if isinstance(cutoff, bool) or not isinstance(cutoff, (int, float)) or not 0.0 <= cutoff <= 1.0:
        raise InputError(f"alpha cutoff of {entry['output']} must be a number within 0..1, not {cutoff!r}", scene)
    return float(cutoff)


def _gl_enum(sampler, key, table, entry, scene):
    """A glTF sampler field: an integer among `table`'s, or None when unset."""
    value = sampler.get(key)
    if value is None:
        return None
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    if isinstance(value, bool) or not isinstance(value, int) or value not in table:
        raise InputError(f"{key} of {entry['output']} is {value!r}, not a glTF value "
                         f"({', '.join(str(v) for v in table)})", scene)
    return table[value]


def scene_sampler(path):
    """The sampler a scene.json beside the texture gives it, or None."""
    entry, scene = _scene_entry(path)
    if entry is None:
        return None
    from ..scene import FILTER_NAMES, WRAP_MODES

    s = entry.get("sampler")
    if s is None:
        s = {}
    if not isinstance(s, dict):
        raise InputError(f"the sampler of {entry['output']} is not an object", scene)
    # an unset filter is the viewer's choice: trilinear, linear magnification; wrap defaults to repeat
    min_name = _gl_enum(s, "minFilter", FILTER_NAMES, entry, scene) or "LINEAR_MIPMAP_LINEAR"
    mag_name = _gl_enum(s, "magFilter", FILTER_NAMES, entry, scene) or "LINEAR"
    wrap = tuple(_gl_enum(s, k, WRAP_MODES, entry, scene) or "repeat" for k in ("wrapS", "wrapT"))
    # a magnified texture has no smaller level to pick: a mipmap filter given as
    # magFilter (which glTF does not allow, and models carry) magnifies by its first word
    return Sampler(GL_MIN_FILTERS[min_name], mag_name.startswith("LINEAR"), wrap, _entry_cutoff(entry, scene),
                   "scene.json")


def resolve_sampler(path, filter=None, wrap=None, alpha_cutoff=None):
    """Defaults, then scene.json, then the flags."""
    base = scene_sampler(path) or Sampler()
    if wrap is not None:
        if isinstance(wrap, str):
            wrap = tuple(wrap.split(",")) if "," in wrap else (wrap, wrap)
        from .sample import WRAP_CODES

        if len(wrap) != 2 or any(w not in WRAP_CODES for w in wrap):
            raise UsageError(f"wrap must be one or two of {', '.join(WRAP_CODES)} (s,t), not {','.join(wrap)}")
    if alpha_cutoff is not None and not 0.0 <= alpha_cutoff <= 1.0:
        raise UsageError(f"alpha cutoff must be within 0..1, not {alpha_cutoff}")
    flagged = filter is not None or wrap is not None
    mag_linear = base.mag_linear
    if filter is not None:
        filter = str(filter).lower()
        mag_linear = None  # a filter named on the command line magnifies its own way
    return Sampler(
        filter if filter is not None else base.filter,
        mag_linear,
        tuple(wrap or base.wrap),
        alpha_cutoff if alpha_cutoff is not None else base.alpha_cutoff,
        "flags" if flagged and base.source == "default" else (base.source + "+flags" if flagged else base.source),
    )
