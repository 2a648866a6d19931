import os
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent
CORPUS = ROOT / "corpus"


@pytest.fixture
def rng():
    return np.random.default_rng(1234)


@pytest.fixture
def many_chunks(monkeypatch):
    """Work split into chunks of any size, whatever the stage asks for, so that
    small test images still go through several chunks on several threads."""
    from texcook import _threads

    split = _threads.split
    monkeypatch.setattr(_threads, "split", lambda n, threads, min_chunk: split(n, threads, 1))
    return split


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


def read_straight(path):
    """An image file as float32 through OpenImageIO, an independent reader,
    with PNG alpha as stored (OpenImageIO premultiplies colour by default)."""
    import OpenImageIO as oiio

    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)
    return np.ascontiguousarray(oiio.ImageBuf(str(path), 0, 0, config).get_pixels(oiio.FLOAT), np.float32)


def encoded_image(px, ext=".png", quality=None):
    """File bytes of uint8 (H, W, C) pixels in the format `ext` names, as
    OpenImageIO writes it (tests build models and folders from these);
    `quality`: a JPEG's."""
    import tempfile

    import OpenImageIO as oiio

    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, "x" + ext)
        out = oiio.ImageOutput.create(path)
        spec = oiio.ImageSpec(px.shape[1], px.shape[0], px.shape[2], "uint8")
        if quality is not None:
            spec.attribute("Compression", f"jpeg:{quality}")
        out.open(path, spec)
        out.write_image(np.ascontiguousarray(px))
        out.close()
        with open(path, "rb") as fh:
            return fh.read()


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


JS_DIR = ROOT / "tests" / "js"


def node_tool(tool, module):
    """A runner for a tests/js script: run(paths) -> one JSON record per line.
    Skips when the npm package is missing, and fails in CI, which installs it."""
    import json
    import shutil
    import subprocess

    if shutil.which("node") is None or not (JS_DIR / "node_modules" / module).is_dir():
        if os.environ.get("CI"):
            pytest.fail(f"{module} is not installed: run `npm ci --prefix tests/js`")
        pytest.skip(f"{module} not installed (npm ci --prefix tests/js)")

    def run(paths):
        proc = subprocess.run(["node", str(JS_DIR / tool), *map(str, paths)], capture_output=True, text=True,
                              check=True, timeout=300)
        return [json.loads(line) for line in proc.stdout.splitlines()]

    return run


@pytest.fixture(scope="module")
def ktx_parse():
    """npm's ktx-parse, an independent KTX2 reader: run([paths]) -> records."""
    return node_tool("ktxparse.mjs", "ktx-parse")
