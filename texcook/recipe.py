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

import dataclasses
import hashlib
import json
from dataclasses import dataclass, field, fields

from . import formats
from .choices import (COLOUR_SPACES, DEFAULT_PRESET, KAISER_ALPHA, KAISER_ALPHA_RANGE, KAISER_WIDTH,
                      KAISER_WIDTH_RANGE, LANCZOS_A, LANCZOS_A_RANGE, NORMAL_LAYOUTS, NORMAL_METRICS, PRESETS,
                      RENORMALIZE_MODES, WRAPS, ZSTD_LEVELS)
from .choices import MIP_FILTERS as FILTERS
from .errors import UsageError

SCHEMA_VERSION = 1
SWIZZLE_CHARS = "rgba01"
RENORMALIZE_CLIP_MAX = 25.0  # percent cut at each end; beyond this half the texels would be clipped
RDO_MAX = 1e6  # squared error per byte: far beyond this every candidate block is taken


@dataclass(frozen=True)
class Setting:
    """One recipe setting, declared once: the recipe checks a value by it when
    it is made, and the command line makes the setting's option from it
    (texcook.cli.recipe_options), so its flag, help, choices and default are
    written nowhere else."""

    name: str  # flat name: Recipe.of's keyword and the option's parameter
    flags: tuple  # the option's flags ("--mips/--no-mips" for a pair); () when it has none
    help: str
    kind: str  # "bool", "int", "float", "choice" or "text"
    default: object = None  # None: decided later (the help says by what)
    choices: tuple = ()
    lo: float | None = None
    hi: float | None = None
    shown: str | None = None  # the default as help shows it, where the stored default is None
    metavar: str | None = None
    parse: object = None  # (setting, value) -> stored value, for text settings (wrap, swizzle, weights)
    part: str | None = None  # where the value is stored (None: a shorthand Recipe.replace applies)
    key: str | None = None

    @property
    def label(self):
        """How a message names it: as a recipe file and as the command line do."""
        flag = self.flags[0].split("/")[0] if self.flags else None
        if self.part is None:
            return flag or self.name
        return f"{self.part}.{self.key} ({flag})" if flag else f"{self.part}.{self.key}"

    def check(self, value):
        """The value as the recipe stores it, or UsageError naming the setting."""
        if value is None and self.default is None:
            return None
        if self.parse is not None:
            return self.parse(self, value)
        if self.kind == "bool" and not isinstance(value, bool):
            raise UsageError(f"{self.label} must be true or false, not {value!r}")
        if self.kind in ("int", "float"):
            _number(self.label, value, self.lo, self.hi, integer=self.kind == "int")
        if self.kind == "choice" and value not in self.choices:
            raise UsageError(f"{self.label} must be one of {', '.join(self.choices)}, not {value!r}")
        return value


def _number(label, value, lo=None, hi=None, integer=False):
    kind = "an integer" if integer else "a number"
    if isinstance(value, bool) or not isinstance(value, (int, float)) or (integer and not isinstance(value, int)):
        raise UsageError(f"{label} must be {kind}, not {value!r}")
    if value != value or (lo is not None and value < lo) or (hi is not None and value > hi):
        rng = f"within {lo:g}..{hi:g}" if hi is not None else f"at least {lo:g}"
        raise UsageError(f"{label} must be {rng}, not {value}")
    return value


def _wrap(setting, value):
    wrap = value
    if isinstance(wrap, str):
        wrap = tuple(wrap.split(",")) if "," in wrap else (wrap, wrap)
    if not isinstance(wrap, (tuple, list)) or len(wrap) != 2 or any(w not in WRAPS for w in wrap):
        shown = ",".join(map(str, wrap)) if isinstance(wrap, (tuple, list)) else repr(wrap)
        raise UsageError(f"{setting.label} must be one or two of {', '.join(WRAPS)} (x,y), not {shown}")
    return tuple(wrap)


def _swizzle(setting, value):
    if not isinstance(value, str) or len(value) != 4 or any(c not in SWIZZLE_CHARS for c in value.lower()):
        raise UsageError(f"{setting.label} must be four of r, g, b, a, 0, 1 (like bgra or rrr1), not {value!r}")
    value = value.lower()
    return None if value == "rgba" else value  # the identity is no transform


def _lambda(setting, value):
    """A number within range, stored as a float so 100 and 100.0 make one recipe digest."""
    return float(_number(setting.label, value, setting.lo, setting.hi))


def _format(setting, value):
    if not isinstance(value, str):
        raise UsageError(f"{setting.label} must be a format name, not {value!r}")
    return formats.get(value).name


def _weights(setting, value):
    """Numbers, or text of numbers separated by commas (as the command line
    gives them); how many and how large is the codec's to check."""
    try:
        if isinstance(value, str):
            return tuple(float(v) for v in value.split(","))
        if isinstance(value, (tuple, list)) and not any(isinstance(v, (bool, str)) for v in value):
            return tuple(float(v) for v in value)
    except (TypeError, ValueError):
        pass
    raise UsageError(f"{setting.label} must be numbers separated by commas, like 1,2,1, not {value!r}")


def _setting(default, flags, help, kind, name=None, **more):
    """A part's field, declared with its setting (completed by _part)."""
    return field(default=default, metadata={"setting": Setting(name, tuple(flags.split()), help, kind, default,
                                                               **more)})


# every setting, by flat name, in the order the command line lists them
SETTINGS = {}


def _shorthand(name, flags, help, kind, **more):
    SETTINGS[name] = Setting(name, tuple(flags.split()), help, kind, **more)


class _Part:
    """A recipe part: each field declared with _setting is checked (and
    normalised) when the part is made; `_check` adds what spans fields."""

    def __post_init__(self):
        for f in fields(self):
            if "setting" in f.metadata:
                setting = SETTINGS[f.metadata["setting"].name or f.name]
                object.__setattr__(self, f.name, setting.check(getattr(self, f.name)))
        self._check()

    def _check(self):
        pass


def _part(name):
    """A frozen dataclass whose declared fields join SETTINGS as `name`.field."""

    def make(cls):
        cls = dataclass(frozen=True)(cls)
        for f in fields(cls):
            declared = f.metadata.get("setting")
            if declared is not None:
                flat = declared.name or f.name
                SETTINGS[flat] = dataclasses.replace(declared, name=flat, part=name, key=f.name)
        return cls

    return make


@_part("source")
class Source(_Part):
    # tangent-space vectors: renormalised mips, never sRGB
    normal_map: bool = _setting(False, "--normal-map", "Source is a tangent-space normal map: renormalise mips.",
                                "bool")
    # a cut-out: keep alpha-test coverage at this cutoff
    alpha_cutoff: float | None = _setting(None, "--alpha-cutoff",
                                          "Keep alpha-test coverage at this cutoff down the chain.", "float",
                                          lo=0.0, hi=1.0)
    # linear values that are not colour (roughness, metalness, masks): never
    # decoded from sRGB, also when stored sRGB-encoded for a reader that takes
    # only a format's sRGB variant (its sampler's decode gives them back)
    data: bool = _setting(False, "--data", "Source values are linear data, kept as they are; with --srgb they "
                          "are stored through the sRGB curve, which the sampler's sRGB decode undoes.", "bool")
    nan_to_zero: bool = _setting(False, "--nan-to-zero",
                                 "Replace NaN and Inf in float sources with 0 instead of failing.", "bool")
    clamp: bool = _setting(False, "--clamp", "Clamp values beyond the format's range (rgba16f: +-65504) instead "
                           "of failing.", "bool")


@_part("mips")
class Mips(_Part):
    enabled: bool = _setting(True, "--mips/--no-mips", "Write a full mip chain.", "bool", name="mips")
    filter: str = _setting("box", "--mip-filter", "How each level is filtered from the one before.", "choice",
                           name="mip_filter", choices=FILTERS)
    # (x, y); "repeat" or "clamp,repeat" accepted
    wrap: tuple = _setting(("clamp", "clamp"), "--wrap", "clamp, repeat or mirror; X,Y for each axis.", "text",
                           parse=_wrap, shown="clamp")
    lanczos_a: int = _setting(LANCZOS_A, "--lanczos-a", "Lanczos lobes.", "int",
                              lo=LANCZOS_A_RANGE[0], hi=LANCZOS_A_RANGE[1])
    # None: the mip module's default
    kaiser_width: float | None = _setting(None, "--kaiser-width", "Kaiser kernel radius in destination texels.",
                                          "float", lo=KAISER_WIDTH_RANGE[0], hi=KAISER_WIDTH_RANGE[1],
                                          shown=f"{KAISER_WIDTH:g}")
    kaiser_alpha: float | None = _setting(None, "--kaiser-alpha", "Kaiser window shape.", "float",
                                          lo=KAISER_ALPHA_RANGE[0], hi=KAISER_ALPHA_RANGE[1],
                                          shown=f"{KAISER_ALPHA:g}")
    premultiply: bool = _setting(False, "--premultiply", "Filter colour weighted by alpha.", "bool")


@_part("transform")
class Transform(_Part):
    # output channel i takes source channel swizzle[i] (r, g, b, a, 0 or 1)
    swizzle: str | None = _setting(None, "--swizzle", "Reorder channels before encoding, e.g. bgra or rrr1 "
                                   "(undone on decode).", "text", parse=_swizzle)
    renormalize: str | None = _setting(None, "--renormalize", "Stretch each channel's range to the full range "
                                       "before encoding; the scale and bias a shader applies are stored per "
                                       "texture or per level (key texcook.transforms).", "choice",
                                       choices=RENORMALIZE_MODES)
    # None: min/max
    renormalize_clip: float | None = _setting(None, "--renormalize-clip", "With --renormalize: cut P percent of "
                                              "the values at each end instead of using min/max.", "float",
                                              lo=0.0, hi=RENORMALIZE_CLIP_MAX, metavar="P")

    def _check(self):
        if self.renormalize_clip is not None:
            if self.renormalize is None:
                raise UsageError("--renormalize-clip needs --renormalize texture or level")
            if self.renormalize_clip == 0:
                object.__setattr__(self, "renormalize_clip", None)  # clipping nothing is min/max

    @property
    def steps(self):
        """(name, parameters) of each transform that runs, in order."""
        steps = [("swizzle", self.swizzle)] if self.swizzle else []
        if self.renormalize:
            steps.append(("renormalize", {"mode": self.renormalize, "clip": self.renormalize_clip}))
        return steps


# the codec options a command line names
_shorthand("normal_metric", "--normal-metric", "With --normal-map and bc5 or astc-*: minimise the X/Y error (psnr, "
           "the default) or the angle of the normal after Z is rebuilt (angular).", "choice",
           choices=NORMAL_METRICS)
_shorthand("weights", "--weights", "Channel error weights (r,g,b) for colour codecs.", "text", parse=_weights)
_shorthand("quality", "--quality", "etc1s, etc1s-rgba: how many distinct endpoints and selector patterns the "
           "file may use, 1..255 [default: 128]; higher is larger and closer to the source.", "int", lo=1, hi=255,
           metavar="1..255")


@_part("codec")
class CodecSettings(_Part):
    # None: an uncompressed format keeping the source's channels
    format: str | None = _setting(None, "-f --format", "Output format (texcook formats lists them) [default: "
                                  "uncompressed, keeping the source's channels].", "text", parse=_format)
    preset: str = _setting(DEFAULT_PRESET, "--preset", "Encoder effort.", "choice", choices=PRESETS)
    # rate-distortion optimisation after encoding (texcook.rdo): squared error per zstd byte saved; 0: off
    rdo: float = _setting(0.0, "--rdo", "bc1, bc1a, bc3, bc4, bc5: make blocks repeat earlier ones where the added "
                          "squared error is at most LAMBDA per byte Zstandard is expected to save (0: off; see "
                          "docs/rdo.md).", "float", lo=0.0, hi=RDO_MAX, metavar="LAMBDA",
                          parse=_lambda)
    options: tuple = ()  # (name, value) pairs the codec declares, sorted by name

    def _check(self):
        opts = self.options
        if isinstance(opts, dict):
            opts = opts.items()
        given = {str(name): value for name, value in opts}
        if self.format is not None:
            # stored as the codec normalises them (floats, tuples), so equal recipes hash equal
            checked = self.codec().check_options(given)
            object.__setattr__(self, "options", tuple(sorted((k, checked[k]) for k in given)))
        elif given:
            raise UsageError("codec options need a --format")

    def codec(self, format_name=None):
        """The codec of `format_name`, or of the recipe's format."""
        from . import codecs

        return codecs.get(format_name or self.format)


def check_normal_layout(codec, layout, path=None):
    """UsageError unless the codec can store a normal map in `layout` (None: its own)."""
    have = codec.normal_layouts
    if layout is not None and layout not in have:
        can = f"as {' or '.join(have)} only" if have else "in no layout (too few channels)"
        raise UsageError(f"{codec.name} stores a normal map {can}, not {layout}", path)


# shorthands for output.colour_space
_shorthand("srgb", "--srgb", "Store the output as sRGB [default: sRGB for 8-bit colour sources].", "bool")
_shorthand("linear", "--linear", "Store the output as linear (data, not colour).", "bool")


@_part("output")
class Output(_Part):
    # None: sRGB for sRGB colour sources when the format has it; "auto": sRGB or
    # linear light by the share of bright values (texcook.colour.auto_colour_space)
    colour_space: str | None = _setting(None, "--colour-space --color-space", "Colour encoding of the output; "
                                        "auto: linear when at least 75% of the colour values are above 116/255, "
                                        "else sRGB (--srgb/--linear are shorthands).", "choice",
                                        choices=COLOUR_SPACES)
    # a normal map's stored vector: "xyz" (X, Y, Z in R, G, B, as glTF reads
    # normal textures) or "xy" (X and Y; astc-*: X in RGB, Y in alpha; the
    # reader rebuilds Z); None: the format's own (Codec.normal_layouts)
    normal_layout: str | None = _setting(None, "--normal-layout", "With --normal-map: store X, Y, Z in R, G, B "
                                         "(xyz, as glTF reads normal textures) or X, Y with Z rebuilt by the "
                                         "reader (xy; astc-*: X in RGB, Y in alpha, KTXswizzle ra01) [default: "
                                         "the format's own: xy for bc5, rg8 and astc-*, xyz for the others].",
                                         "choice", choices=NORMAL_LAYOUTS)
    zstd: int | None = _setting(None, "--zstd", "Zstandard supercompression level.", "int",
                                lo=ZSTD_LEVELS[0], hi=ZSTD_LEVELS[1])  # KTX2 only
    dds_dx10: bool = _setting(False, "--dx10", "DDS output: always write the DX10 header.", "bool")
    # also write a summed-area table of the source, beside the output: no flag of
    # its own, as bake's --sat FILE (a runtime option) names where to write one
    sat: bool = _setting(False, "", "Write a summed-area table of the source beside the output.", "bool")


PARTS = {"source": Source, "mips": Mips, "transform": Transform, "codec": CodecSettings, "output": Output}


@dataclass(frozen=True)
class Recipe:
    source: Source = field(default_factory=Source)
    mips: Mips = field(default_factory=Mips)
    transform: Transform = field(default_factory=Transform)
    codec: CodecSettings = field(default_factory=CodecSettings)
    output: Output = field(default_factory=Output)

    def __post_init__(self):
        for name, cls in PARTS.items():
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
        True/False and `linear` True are shorthands for colour_space; `weights`
        and `quality` are the codec options; `normal_metric` "angular" or "psnr" sets the codec
        option `angular`. SETTINGS lists every name."""
        return cls().replace(**flat)

    def replace(self, srgb=None, linear=None, weights=None, normal_metric=None, quality=None, **flat):
        """A copy with flat settings changed (see `of`); the parts changed are
        made anew, which checks their values."""
        changes = {name: {} for name in PARTS}
        for key, value in flat.items():
            if key not in SETTINGS:
                raise UsageError(f"unknown recipe setting {key!r}; known: {', '.join(sorted(SETTINGS))}")
            setting = SETTINGS[key]
            changes[setting.part][setting.key] = value
        srgb, linear, weights, normal_metric, quality = (
            SETTINGS[name].check(value) for name, value in
            (("srgb", srgb), ("linear", linear), ("weights", weights), ("normal_metric", normal_metric),
             ("quality", quality)))
        if srgb and linear:
            raise UsageError("--srgb and --linear contradict each other; give one")
        if srgb is not None or linear:
            if flat.get("colour_space") is not None:
                raise UsageError("give either --colour-space or --srgb/--linear, not both")
            changes["output"]["colour_space"] = "srgb" if srgb else "linear"
        if weights is not None:
            changes["codec"]["options"] = dict(self.codec.options, weights=weights)
        if quality is not None:
            changes["codec"]["options"] = dict(changes["codec"].get("options", self.codec.options), quality=quality)
        if normal_metric is not None:
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
        parts = {name: dataclasses.replace(getattr(self, name), **values) if values else getattr(self, name)
                 for name, values in changes.items()}
        return Recipe(**parts)

    # -- serialisation --------------------------------------------------------

    def to_dict(self) -> dict:
        """Plain values only; settings at their default are left out."""
        out = {"version": SCHEMA_VERSION}
        for name in PARTS:
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
        unknown = sorted(set(d) - set(PARTS) - {"version"})
        if unknown:
            raise UsageError(f"unknown recipe part(s) {', '.join(unknown)}; parts are {', '.join(PARTS)}")
        parts = {}
        for name, cls_ in PARTS.items():
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
