"""The words settings take: presets, mip filters, wrap modes, colour spaces.

Each list is written here once. The recipe, the mip and codec modules check
values against them, and the command line offers them as its options'
choices; this module imports nothing, so the command line can build its
options without loading NumPy.
"""

PRESETS = ("fastest", "fast", "medium", "thorough", "exhaustive")
DEFAULT_PRESET = "medium"  # what every codec encodes with when no preset is named
MIP_FILTERS = ("box", "triangle", "lanczos", "kaiser")
WRAPS = ("clamp", "repeat", "mirror")
COLOUR_SPACES = ("auto", "srgb", "linear")
CONTAINERS = ("ktx2", "dds", "astc")
# a model points at KTX2 or DDS images; an .astc file has no glTF extension (and one level)
SCENE_CONTAINERS = ("ktx2", "dds")
NORMAL_METRICS = ("psnr", "angular")  # what a normal map's encoder minimises
NORMAL_LAYOUTS = ("xy", "xyz")  # a normal map stored as X, Y (Z rebuilt by the reader) or X, Y, Z
RENORMALIZE_MODES = ("texture", "level")
SCENE_TARGETS = ("desktop", "mobile")
