"""Texture containers: the table of them (table.py) and one module each:
KTX2 (ktx2.py), DDS (dds.py), astcenc's .astc (astcfile.py)."""

from .table import CONTAINERS, EXTENSIONS, Container, Stored, for_output, get, of_path  # noqa: F401

_KTX2_NAMES = ("FORMATS", "FormatInfo", "Ktx2File", "describe", "read_ktx2", "write_ktx2")


def __getattr__(name):
    # the KTX2 names this package has always offered, loaded when first asked for
    if name in _KTX2_NAMES:
        from . import ktx2

        return getattr(ktx2, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
