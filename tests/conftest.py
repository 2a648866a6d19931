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


@pytest.fixture
def full_disk(tmp_path):
    """A 256 KiB tmpfs (root only; skipped elsewhere)."""
    import subprocess

    mnt = tmp_path / "small"
    mnt.mkdir()
    if os.geteuid() != 0 or subprocess.run(["mount", "-t", "tmpfs", "-o", "size=256k", "tmpfs", str(mnt)],
                                           capture_output=True).returncode != 0:
        pytest.skip("cannot mount a small tmpfs here")
    yield mnt
    subprocess.run(["umount", str(mnt)], check=False)


def interruptible():
    """preexec_fn for a child that must see Ctrl-C: a shell that started the
    tests in the background ignores SIGINT, and children inherit that."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_DFL)
