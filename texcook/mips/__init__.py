"""Mip chains in linear light: filters, wrap modes, premultiplied alpha,
normal maps and alpha-coverage preservation. See docs/mips.md."""

from .chain import ChainSettings, build_chain, chain_level_count, chain_sizes, iter_chain
from .coverage import alpha_coverage, coverage_scale, scale_alpha_to_coverage
from .filters import FILTERS, KAISER_ALPHA, KAISER_WIDTH, LANCZOS_A
from .resample import WRAPS, resample, tap_table

__all__ = [
    "build_chain",
    "iter_chain",
    "ChainSettings",
    "chain_sizes",
    "chain_level_count",
    "alpha_coverage",
    "coverage_scale",
    "scale_alpha_to_coverage",
    "resample",
    "tap_table",
    "FILTERS",
    "WRAPS",
    "KAISER_WIDTH",
    "KAISER_ALPHA",
    "LANCZOS_A",
]
