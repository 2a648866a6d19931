"""Texture containers: KTX2 (read and write)."""

from .ktx2 import FORMATS, FormatInfo, Ktx2File, describe, read_ktx2, write_ktx2  # noqa: F401
