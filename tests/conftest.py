import os
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent
CORPUS = ROOT / "corpus"


@pytest.fixture
def rng():
    return np.random.default_rng(1234)


@pytest.fixture(scope="session")
def corpus():
    return CORPUS


def corpus_images(folder):
    return sorted((CORPUS / folder).glob("*.png"))


@pytest.fixture
def cli_run():
    """Run the texcook CLI in-process; returns (exit_code, stdout, stderr)."""
    from click.testing import CliRunner

    from texcook.cli import cli

    def run(*args):
        result = CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False)
        return result.exit_code, result.stdout, result.stderr

    return run


def files_in(directory):
    return sorted(os.listdir(directory))


def load_rgba8(path, size=None):
    """An 8-bit corpus image as RGBA uint8 with straight alpha (grey and RGB
    expanded as a sampler sees them), optionally cropped to (rows, cols)."""
    from texcook.pipeline import load_texture

    px = load_texture(CORPUS / path).levels[0]
    if size:
        px = px[: size[0], : size[1]]
    return np.ascontiguousarray(px)
