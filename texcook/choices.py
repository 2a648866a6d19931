"""The words settings take (presets, mip filters, wrap modes, colour spaces)
and the defaults and limits of numeric ones (mip filters, Zstandard levels).

Each is written here once. The recipe, the mip and codec modules check
values against them, and the command line offers them as its options'
choices and defaults; this module imports only the format and container
tables (whose names these are), so the command line can build its options
without loading NumPy.
"""

from .container.table import DEFAULT as DEFAULT_CONTAINER, NAMES as CONTAINERS, SCENE_CONTAINERS  # noqa: F401

PRESETS = ("fastest", "fast", "medium", "thorough", "exhaustive")
DEFAULT_PRESET = "medium"  # what every codec encodes with when no preset is named
MIP_FILTERS = ("box", "triangle", "lanczos", "kaiser")
WRAPS = ("clamp", "repeat", "mirror")
# Kaiser-windowed sinc: radius 3 destination texels (12 taps per axis at 2:1)
# with alpha 4. Radius 3 keeps the passband as flat as Lanczos-3; alpha 4 puts
# the first sidelobe of the window near -30 dB, which removes most of the
# aliasing that Lanczos-3 lets through while ringing less than a higher alpha
# with the same radius would (docs/mips.md has the frequency figures).
KAISER_WIDTH = 3.0
KAISER_ALPHA = 4.0
LANCZOS_A = 3
# what the filters accept: (lowest, highest)
LANCZOS_A_RANGE = (1, 8)
KAISER_WIDTH_RANGE = (0.5, 8.0)  # destination texels
KAISER_ALPHA_RANGE = (0.0, 20.0)
COLOUR_SPACES = ("auto", "srgb", "linear")
NORMAL_METRICS = ("psnr", "angular")  # what a normal map's encoder minimises
NORMAL_LAYOUTS = ("xy", "xyz")  # a normal map stored as X, Y (Z rebuilt by the reader) or X, Y, Z
RENORMALIZE_MODES = ("texture", "level")
ZSTD_LEVELS = (1, 22)  # the Zstandard supercompression levels a KTX2 file may be written with
# desktop: BC; mobile: ASTC (ETC2/EAC in a build without an ASTC encoder);
# mobile-etc: ETC2/EAC, for OpenGL ES 3.0 and WebGL devices without ASTC;
# universal: Basis Universal ETC1S (KHR_texture_basisu), one file every GPU
# transcodes on load, near the size of JPEGs
SCENE_TARGETS = ("desktop", "mobile", "mobile-etc", "universal")
