"""A recipe says how one texture is baked, in five parts a reader can see:

- source: what the source is and what it is for (a normal map, a cut-out at
  an alpha cutoff, whether NaN/Inf may be replaced);
- mips: whether a chain is built and how it is filtered;
- transform: what is done to the levels before encoding (a swizzle, a
  renormalisation of each channel's range);
- codec: the format, the preset and the codec's declared options;
- output: the colour encoding of the stored texels, how a normal map's vector
  is laid out in them, supercompression, DDS header style, and whether a
  summed-area table is written beside it.

Recipes are frozen and hashable, and `to_dict`/`from_dict` give a versioned
schema of plain values that JSON and TOML can hold (absent keys take their
defaults, so a `None` is never written). Everything is validated when the
recipe is made, before any pixel is read; `check_container` adds what depends
on the output file's kind. Runtime settings (threads) are not part of a recipe.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field, fields

from . import formats
from .choices import COLOUR_SPACES, NORMAL_LAYOUTS, NORMAL_METRICS, RENORMALIZE_MODES, WRAPS
from .choices import MIP_FILTERS as FILTERS
from .errors import UsageError
from .mips.filters import LANCZOS_A

SCHEMA_VERSION = 1
SWIZZLE_CHARS = "rgba01"


def _number(part, name, value, lo=None, hi=None, integer=False):
    kind = "an integer" if integer else "a number"
    if isinstance(value, bool) or not isinstance(value, (int, float)) or (integer and not isinstance(value, int)):
        raise UsageError(f"{part}.{name} must be {kind}, not {value!r}")
    if value != value or (lo is not None and value < lo) or (hi is not None and value > hi):
        rng = f"within {lo}..{hi}" if hi is not None else f"at least {lo}"
        raise UsageError(f"{part}.{name} must be {rng}, not {value}")
    return value


def _flag(part, name, value):
    if not isinstance(value, bool):
        raise UsageError(f"{part}.{name} must be true or false, not {value!r}")


@dataclass(frozen=True)
class Source:
    normal_map: bool = False  # tangent-space vectors: renormalised mips, never sRGB
    alpha_cutoff: float | None = None  # a cut-out: keep alpha-test coverage at this cutoff
    nan_to_zero: bool = False  # replace NaN/Inf in float sources instead of refusing them
    clamp: bool = False  # clamp values beyond the format's range (rgba16f) instead of refusing them

    def __post_init__(self):
        _flag("source", "normal_map", self.normal_map)
        _flag("source", "nan_to_zero", self.nan_to_zero)
        _flag("source", "clamp", self.clamp)
        if self.alpha_cutoff is not None:
            _number("source", "alpha_cutoff", self.alpha_cutoff, 0.0, 1.0)


@dataclass(frozen=True)
class Mips:
    enabled: bool = True
    filter: str = "box"
    wrap: tuple = ("clamp", "clamp")  # (x, y); "repeat" or "clamp,repeat" accepted
    lanczos_a: int = LANCZOS_A
    kaiser_width: float | None = None  # None: the mip module's documented default
    kaiser_alpha: float | None = None
    premultiply: bool = False  # filter colour weighted by alpha

    def __post_init__(self):
        _flag("mips", "enabled", self.enabled)
        _flag("mips", "premultiply", self.premultiply)
        if self.filter not in FILTERS:
            raise UsageError(f"unknown mip filter {self.filter!r}; choose one of {', '.join(FILTERS)}")
        wrap = self.wrap
        if isinstance(wrap, str):
            wrap = tuple(wrap.split(",")) if "," in wrap else (wrap, wrap)
        wrap = tuple(wrap)
        if len(wrap) != 2 or any(w not in WRAPS for w in wrap):
            raise UsageError(f"wrap must be one or two of {', '.join(WRAPS)} (x,y), not {','.join(map(str, wrap))}")
        object.__setattr__(self, "wrap", wrap)
        _number("mips", "lanczos_a", self.lanczos_a, 1, 16, integer=True)
        if self.kaiser_width is not None:
            _number("mips", "kaiser_width", self.kaiser_width, 0.5, 16.0)
        if self.kaiser_alpha is not None:
            _number("mips", "kaiser_alpha", self.kaiser_alpha, 0.0, 64.0)


RENORMALIZE_CLIP_MAX = 25.0  # percent cut at each end; beyond this half the texels would be clipped


@dataclass(frozen=True)
class Transform:
    swizzle: str | None = None  # output channel i takes source channel swizzle[i] (r, g, b, a, 0 or 1)
    renormalize: str | None = None  # stretch each channel's range to 0..1: per "texture" or per "level"
    renormalize_clip: float | None = None  # percent of values cut at each end (None: min/max)

    def __post_init__(self):
        if self.renormalize is not None and self.renormalize not in RENORMALIZE_MODES:
            raise UsageError(f"renormalize must be one of {', '.join(RENORMALIZE_MODES)}, not {self.renormalize!r}")
        if self.renormalize_clip is not None:
            if self.renormalize is None:
                raise UsageError("--renormalize-clip needs --renormalize texture or level")
            _number("transform", "renormalize_clip", self.renormalize_clip, 0.0, RENORMALIZE_CLIP_MAX)
            if self.renormalize_clip == 0:
                object.__setattr__(self, "renormalize_clip", None)  # clipping nothing is min/max
        s = self.swizzle
        if s is not None:
            if not isinstance(s, str) or len(s) != 4 or any(c not in SWIZZLE_CHARS for c in s.lower()):
                raise UsageError(f"swizzle must be four of r, g, b, a, 0, 1 (like bgra or rrr1), not {s!r}")
            s = s.lower()
            object.__setattr__(self, "swizzle", None if s == "rgba" else s)

    @property
    def steps(self):
        """(name, parameters) of each transform that runs, in order."""
        steps = [("swizzle", self.swizzle)] if self.swizzle else []
        if self.renormalize:
            steps.append(("renormalize", {"mode": self.renormalize, "clip": self.renormalize_clip}))
        return steps


@dataclass(frozen=True)
class CodecSettings:
    format: str | None = None  # None: an uncompressed format keeping the source's channels
    preset: str = "medium"
    options: tuple = ()  # (name, value) pairs the codec declares, sorted by name

    def __post_init__(self):
        opts = self.options
        if isinstance(opts, dict):
            opts = opts.items()
        given = {str(name): value for name, value in opts}
        if self.format is not None:
            object.__setattr__(self, "format", formats.get(self.format).name)
            codec = self.codec(options=given)  # format encodable, preset and options valid
            checked = codec.check_options(given)
            # stored as the codec normalises them (floats, tuples), so equal recipes hash equal
            object.__setattr__(self, "options", tuple(sorted((k, checked[k]) for k in given)))
        elif given:
            raise UsageError("codec options need a --format")
        elif self.preset not in formats_presets():
            raise UsageError(f"unknown preset {self.preset!r}; choose one of {', '.join(formats_presets())}")

    def codec(self, format_name=None, options=None):
        """The codec object, with the preset and options checked against it."""
        from . import codecs

        codec = codecs.get(format_name or self.format)
        codec.check_preset(self.preset)
        codec.check_options(dict(self.options) if options is None else options)
        return codec


def check_normal_layout(codec, layout, path=None):
    """UsageError unless the codec can store a normal map in `layout` (None: its own)."""
    have = codec.normal_layouts
    if layout is not None and layout not in have:
        can = f"as {' or '.join(have)} only" if have else "in no layout (too few channels)"
        raise UsageError(f"{codec.name} stores a normal map {can}, not {layout}", path)


def formats_presets():
    from .codecs import PRESETS

    return PRESETS


@dataclass(frozen=True)
class Output:
    # None: sRGB for sRGB colour sources when the format has it; "auto": sRGB or
    # linear light by the share of bright values (texcook.colour.auto_colour_space)
    colour_space: str | None = None
    # a normal map's stored vector: "xyz" (X, Y, Z in R, G, B, as glTF reads
    # normal textures) or "xy" (X and Y; astc-*: X in RGB, Y in alpha; the
    # reader rebuilds Z); None: the format's own (Codec.normal_layouts)
    normal_layout: str | None = None
    zstd: int | None = None  # KTX2 Zstandard supercompression level
    dds_dx10: bool = False  # DDS: always write the DX10 header
    sat: bool = False  # also write a summed-area table of the source

    def __post_init__(self):
        if self.colour_space is not None and self.colour_space not in COLOUR_SPACES:
            raise UsageError(f"colour space must be one of {', '.join(COLOUR_SPACES)}, not {self.colour_space!r}")
        if self.normal_layout is not None and self.normal_layout not in NORMAL_LAYOUTS:
            raise UsageError(f"normal layout must be one of {', '.join(NORMAL_LAYOUTS)}, not {self.normal_layout!r}")
        if self.zstd is not None:
            _number("output", "zstd", self.zstd, 1, 22, integer=True)
        _flag("output", "dds_dx10", self.dds_dx10)
        _flag("output", "sat", self.sat)


_PARTS = {"source": Source, "mips": Mips, "transform": Transform, "codec": CodecSettings, "output": Output}

# Flat names (as the command line spells them) -> (part, field).
FLAT = {
    "normal_map": ("source", "normal_map"),
    "alpha_cutoff": ("source", "alpha_cutoff"),
    "nan_to_zero": ("source", "nan_to_zero"),
    "clamp": ("source", "clamp"),
    "mips": ("mips", "enabled"),
    "mip_filter": ("mips", "filter"),
    "wrap": ("mips", "wrap"),
    "lanczos_a": ("mips", "lanczos_a"),
    "kaiser_width": ("mips", "kaiser_width"),
    "kaiser_alpha": ("mips", "kaiser_alpha"),
    "premultiply": ("mips", "premultiply"),
    "swizzle": ("transform", "swizzle"),
    "renormalize": ("transform", "renormalize"),
    "renormalize_clip": ("transform", "renormalize_clip"),
    "format": ("codec", "format"),
    "preset": ("codec", "preset"),
    "colour_space": ("output", "colour_space"),
    "normal_layout": ("output", "normal_layout"),
    "zstd": ("output", "zstd"),
    "dds_dx10": ("output", "dds_dx10"),
    "sat": ("output", "sat"),
}


@dataclass(frozen=True)
class Recipe:
    source: Source = field(default_factory=Source)
    mips: Mips = field(default_factory=Mips)
    transform: Transform = field(default_factory=Transform)
    codec: CodecSettings = field(default_factory=CodecSettings)
    output: Output = field(default_factory=Output)

    def __post_init__(self):
        for name, cls in _PARTS.items():
            if not isinstance(getattr(self, name), cls):
                raise UsageError(f"recipe part {name} must be a {cls.__name__}")
        if self.source.normal_map and self.output.colour_space == "srgb":
            raise UsageError("a normal map holds vectors, not colour: it cannot be stored as sRGB")
        if self.codec.format is not None and self.output.colour_space == "srgb":
            formats.get(self.codec.format).vk_format(True)  # refuses formats without an sRGB variant
        if dict(self.codec.options).get("angular") and not self.source.normal_map:
            raise UsageError("--normal-metric angular judges normals: it needs --normal-map")
        self._check_normal_layout()

    def _check_normal_layout(self):
        layout = self.output.normal_layout
        if layout is None:
            return
        if not self.source.normal_map:
            raise UsageError("--normal-layout says how a normal map is stored: it needs --normal-map")
        options = dict(self.codec.options)
        if options.get("normal_layout", layout) != layout:
            raise UsageError(f"the codec option normal_layout {options['normal_layout']!r} contradicts "
                             f"--normal-layout {layout}")
        if layout == "xyz" and options.get("angular"):
            raise UsageError("--normal-metric angular judges X and Y with Z rebuilt: it needs --normal-layout xy")
        if self.codec.format is not None:
            check_normal_layout(self.codec.codec(), layout)

    @classmethod
    def of(cls, **flat):
        """A recipe from flat settings, as the command line names them:
        `Recipe.of(format="bc1", preset="thorough", mips=False)`. `srgb`
        True/False is shorthand for colour_space; `weights` is the codec option;
        `normal_metric` "angular" or "psnr" sets the codec option `angular`."""
        return cls().replace(**flat)

    def replace(self, srgb=None, weights=None, normal_metric=None, **flat):
        """A copy with flat settings changed (see `of`)."""
        changes = {name: {} for name in _PARTS}
        for key, value in flat.items():
            if key not in FLAT:
                raise UsageError(f"unknown recipe setting {key!r}; known: {', '.join(sorted(FLAT))}, srgb, weights, "
                                 "normal_metric")
            part, name = FLAT[key]
            changes[part][name] = value
        if srgb is not None:
            changes["output"]["colour_space"] = "srgb" if srgb else "linear"
        if weights is not None:
            changes["codec"]["options"] = dict(self.codec.options, weights=tuple(weights))
        if normal_metric is not None:
            if normal_metric not in NORMAL_METRICS:
                raise UsageError(f"normal metric must be one of {', '.join(NORMAL_METRICS)}, not {normal_metric!r}")
            options = dict(changes["codec"].get("options", self.codec.options))
            options.pop("angular", None)  # psnr is the codecs' default objective
            if normal_metric == "angular":
                fmt = changes["codec"].get("format", self.codec.format)
                from . import codecs

                if fmt is None or "angular" not in {o.name for o in codecs.get(fmt).options}:
                    raise UsageError(f"--normal-metric angular needs a format that searches by angle (bc5 or astc-*), "
                                     f"not {fmt or 'an uncompressed one'}")
                options["angular"] = True
            changes["codec"]["options"] = options
        parts = {}
        for name, values in changes.items():
            part = getattr(self, name)
            # rebuilt from its fields so that each part validates the new values
            parts[name] = type(part)(**{**{f.name: getattr(part, f.name) for f in fields(part)}, **values})
        return Recipe(**parts)

    # -- serialisation --------------------------------------------------------

    def to_dict(self) -> dict:
        """Plain values only; settings at their default are left out."""
        out = {"version": SCHEMA_VERSION}
        for name in _PARTS:
            part = getattr(self, name)
            default = type(part)()
            values = {}
            for f in fields(part):
                value = getattr(part, f.name)
                if value == getattr(default, f.name) or value is None:
                    continue
                if f.name == "options":
                    value = {k: list(v) if isinstance(v, tuple) else v for k, v in value}
                elif isinstance(value, tuple):
                    value = list(value)
                values[f.name] = value
            if values:
                out[name] = values
        return out

    @classmethod
    def from_dict(cls, d) -> "Recipe":
        if not isinstance(d, dict):
            raise UsageError(f"a recipe is a table of settings, not {type(d).__name__}")
        version = d.get("version", SCHEMA_VERSION)
        if version != SCHEMA_VERSION:
            raise UsageError(f"recipe schema version {version!r} is not supported (this texcook reads {SCHEMA_VERSION})")
        unknown = sorted(set(d) - set(_PARTS) - {"version"})
        if unknown:
            raise UsageError(f"unknown recipe part(s) {', '.join(unknown)}; parts are {', '.join(_PARTS)}")
        parts = {}
        for name, cls_ in _PARTS.items():
            values = d.get(name, {})
            if not isinstance(values, dict):
                raise UsageError(f"recipe part {name} must be a table, not {values!r}")
            known = {f.name for f in fields(cls_)}
            bad = sorted(set(values) - known)
            if bad:
                raise UsageError(f"unknown setting(s) {', '.join(name + '.' + b for b in bad)}; "
                                 f"{name} has {', '.join(sorted(known))}")
            values = {k: tuple(v) if isinstance(v, list) else v for k, v in values.items()}
            parts[name] = cls_(**values)
        return cls(**parts)

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), sort_keys=True)

    def digest(self) -> str:
        """A stable hash of what the recipe bakes (for incremental builds)."""
        return hashlib.sha256(self.to_json().encode()).hexdigest()[:16]

    # -- checks that need the output's kind ------------------------------------

    def check_container(self, container, path=None):
        """UsageError unless this recipe's output fits the container (its row in container.table)."""
        from .container import table

        table.get(container).check_recipe(self, path)
        return self
