"""texcook: bake source art into GPU-ready textures.

The public API is small and lazy so that `texcook --version` does not pay for
numba or OpenImageIO start-up:

    from texcook import read_image, bake, Recipe
"""

__version__ = "0.1.0"

_LAZY = {
    "Image": "texcook.image",
    "read_image": "texcook.image",
    "write_image": "texcook.image",
    "Recipe": "texcook.recipe",
    "bake": "texcook.pipeline",
    "bake_file": "texcook.pipeline",
    "TexcookError": "texcook.errors",
}


def __getattr__(name):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'texcook' has no attribute {name!r}")
    import importlib

    return getattr(importlib.import_module(module), name)
