"""texcook view without a browser: what PATH is, what the page is told, and a
server that answers only for files inside its folder, on 127.0.0.1."""

import http.client
import json
import os
import signal
import subprocess
import sys

import numpy as np
import pytest
from click.testing import CliRunner

from texcook import formats, view
from texcook.cli import cli
from texcook.container.ktx2 import read_ktx2
from texcook.errors import InputError, UsageError
from texcook.pipeline import bake_file
from texcook.recipe import Recipe
from texcook.view import three
from texcook.view.server import Server

from conftest import encoded_image


def _image(path, size=16, seed=3):
    px = np.random.default_rng(seed).integers(0, 256, (size, size, 3), dtype=np.uint8)
    path.write_bytes(encoded_image(px))
    return path


@pytest.fixture
def folder(tmp_path):
    """served/: a texture and a few traps; secret.txt beside it, outside."""
    served = tmp_path / "served"
    (served / "sub").mkdir(parents=True)
    src = _image(tmp_path / "src.png")
    bake_file(src, served / "t.ktx2", Recipe.of(format="bc1", preset="fastest"))
    bake_file(src, served / "t.dds", Recipe.of(format="bc1", preset="fastest"))
    (served / "sub" / "a b.txt").write_bytes(b"inside")
    (tmp_path / "secret.txt").write_bytes(b"SECRET")
    os.symlink(tmp_path / "secret.txt", served / "link.txt")
    os.symlink(tmp_path, served / "up")
    os.symlink("t.ktx2", served / "same.ktx2")  # a symlink that stays inside is fine
    os.mkfifo(served / "fifo")
    return served


def get(server, path, host=None):
    conn = http.client.HTTPConnection("127.0.0.1", server.port, timeout=10)
    conn.putrequest("GET", path, skip_host=True)
    conn.putheader("Host", host or f"127.0.0.1:{server.port}")
    conn.endheaders()
    resp = conn.getresponse()
    body = resp.read()
    conn.close()
    return resp.status, body


def test_serves_inside_and_refuses_every_way_out(folder):
    site = view.open_site(folder / "t.ktx2")
    with Server(site, three.THREE_DIR).start() as server:
        assert server.httpd.server_address[0] == "127.0.0.1"
        assert get(server, "/files/t.ktx2") == (200, (folder / "t.ktx2").read_bytes())
        assert get(server, "/files/sub/a%20b.txt") == (200, b"inside")
        assert get(server, "/files/same.ktx2")[0] == 200
        refused = {
            "/files/../secret.txt": 404, "/files/%2e%2e/secret.txt": 404, "/files/%2E%2E%2Fsecret.txt": 404,
            "/files/sub/..%2f..%2fsecret.txt": 404, "/files/..%5csecret.txt": 404, "/files/%252e%252e/secret.txt": 404,
            "/files//etc/passwd": 404, "/files/%2Fetc%2Fpasswd": 404, "/files/./t.ktx2": 404,
            "/files/t.ktx2%00.png": 404, "/files/%ff": 404,
            "/files/link.txt": 403, "/files/up/secret.txt": 403, "/files/fifo": 403, "/files/sub": 403,
            "/_texcook/three/package.json": 404, "/_texcook/three/build/../../../../secret.txt": 404,
            "/_texcook/page/../server.py": 404, "/_texcook/made/../t.ktx2": 404, "/_texcook/original/x": 404,
            "/secret.txt": 404, "/etc/passwd": 404,
        }
        for path, status in refused.items():
            got, body = get(server, path)
            assert got == status, path
            assert b"SECRET" not in body and b"root:" not in body
        # another host name resolving to 127.0.0.1 (DNS rebinding) gets nothing
        assert get(server, "/files/t.ktx2", host="evil.example:80")[0] == 403
        status, page = get(server, "/")
        assert status == 200 and b"importmap" in page
        manifest = json.loads(get(server, "/_texcook/site.json")[1])
        assert manifest["kind"] == "texture" and manifest["texture"]["format"] == "bc1"
        conn = http.client.HTTPConnection("127.0.0.1", server.port, timeout=10)
        conn.request("POST", "/files/t.ktx2", body=b"x")
        assert conn.getresponse().status == 501  # GET and HEAD only
        conn.close()


def test_a_dds_texture_is_served_as_ktx2_with_the_same_blocks(folder):
    site = view.open_site(folder / "t.dds")
    ktx = read_ktx2(site.made["texture.ktx2"]())
    assert ktx.vk_format == 132 and ktx.levels == read_ktx2((folder / "t.ktx2").read_bytes()).levels
    assert site.manifest["texture"]["url"] == "_texcook/made/texture.ktx2"
    assert site.manifest["texture"]["container"] == "DDS"


def test_what_a_path_is(folder, tmp_path):
    with pytest.raises(UsageError, match="scene.json or one glTF model"):
        view.open_site(folder)
    with pytest.raises(UsageError, match="texcook view shows"):
        view.open_site(tmp_path / "src.png")
    with pytest.raises(InputError, match="no such file"):
        view.open_site(tmp_path / "nothing.ktx2")
    with pytest.raises(InputError, match="regular"):
        view.open_site(folder / "fifo")
    (folder / "broken.ktx2").write_bytes(b"\xabKTX 20\xbb\r\n\x1a\nxx")
    with pytest.raises(InputError):
        view.open_site(folder / "broken.ktx2")


def test_the_source_image_is_offered_for_the_difference_view(folder, tmp_path):
    site = view.open_site(folder / "t.ktx2", source=tmp_path / "src.png")
    assert site.manifest["source"]["url"] == "_texcook/made/source.png"
    assert site.made["source.png"]() == (tmp_path / "src.png").read_bytes()
    assert view.open_site(folder / "t.ktx2").manifest["source"]["url"] is None


def test_a_scene_json_names_no_file_outside_the_model_or_output_folder(tmp_path):
    """scene.json comes with a folder a user may have downloaded: the source
    image and the original model's files it leads to go through the scene's
    uri resolver, so `..`, absolute paths and symlinks out name nothing."""
    src, out = tmp_path / "src", tmp_path / "out"
    src.mkdir()
    out.mkdir()
    _image(src / "ok.png")
    _image(tmp_path / "secret.png", seed=4)
    os.symlink(tmp_path / "secret.png", src / "link.png")
    bake_file(src / "ok.png", out / "t.ktx2", Recipe.of(format="bc1", preset="fastest"))
    uris = {"t.ktx2": "ok.png", "a.ktx2": "../secret.png", "b.ktx2": "link.png", "c.ktx2": str(tmp_path / "secret.png")}
    for name in ("a.ktx2", "b.ktx2", "c.ktx2"):
        (out / name).write_bytes((out / "t.ktx2").read_bytes())
    model = {"images": [{"uri": u} for u in uris.values()], "buffers": [{"uri": "../secret.png"}]}
    (src / "m.gltf").write_text(json.dumps(model))
    (out / "scene.json").write_text(json.dumps({"model": str(src / "m.gltf"), "bakes": [
        {"output": k, "source": {"uri": u}} for k, u in uris.items()]}))
    for name in uris:
        shown = view.open_site(out / name).manifest["source"]["name"]
        assert shown == ("ok.png" if name == "t.ktx2" else None), name
    from texcook.view.site import _model_files

    assert sorted(_model_files(str(src / "m.gltf"))) == ["m.gltf", "ok.png"]


def test_the_vk_table_says_what_three_takes():
    table = three.vk_table()
    assert table[148] == {"format": formats.by_vk_format(148)[0].name, "srgb": True,
                          "webgl": ["WEBGL_compressed_texture_etc"], "three": True, "srgb_ignored": False}
    assert table[147]["three"] is False  # linear ETC RGB: three.js takes the sRGB variant only
    assert table[132]["webgl"] == ["WEBGL_compressed_texture_s3tc", "WEBGL_compressed_texture_s3tc_srgb"]
    assert table[141]["webgl"] == ["EXT_texture_compression_rgtc"] and table[141]["three"]
    assert table[171]["three"] is False and table[165]["three"] is True  # ASTC 8x8 no, 6x6 yes
    assert table[37]["webgl"] == []


def test_the_list_matches_the_installed_three_js():
    """THREE_KTX2_VK_FORMATS against KTX2Loader's FORMAT_MAP, its names read
    as numbers through ktx-parse's constants (tests/js)."""
    from conftest import JS_DIR

    loader = os.path.join(three.THREE_DIR, "examples", "jsm", "loaders", "KTX2Loader.js")
    constants = JS_DIR / "node_modules" / "ktx-parse" / "dist" / "index.mjs"
    if not os.path.isfile(loader) or not constants.is_file():
        if os.environ.get("CI"):
            pytest.fail(f"run `{three.INSTALL}` and `npm ci --prefix tests/js`")
        pytest.skip(f"three.js or ktx-parse not installed ({three.INSTALL}; npm ci --prefix tests/js)")
    import re

    text = open(loader, encoding="utf-8").read()
    body = text[text.index("const FORMAT_MAP"):]
    body = body[:body.index("};")]
    names = set(re.findall(r"\[\s*(VK_FORMAT_\w+)\s*\]", body))
    script = ("import * as k from 'ktx-parse'; const names = JSON.parse(process.argv[1]);"
              "console.log(JSON.stringify(names.map((n) => k[n])));")
    out = subprocess.run(["node", "--input-type=module", "-e", script, json.dumps(sorted(names))], cwd=JS_DIR,
                         capture_output=True, text=True, check=True, timeout=60)
    numbers = json.loads(out.stdout)
    assert None not in numbers, sorted(names)
    assert set(numbers) == three.THREE_KTX2_VK_FORMATS


def test_missing_three_js_is_one_line_with_the_install_command(folder, monkeypatch, tmp_path):
    monkeypatch.setattr(three, "THREE_DIR", str(tmp_path / "nowhere"))
    result = CliRunner().invoke(cli, ["view", str(folder / "t.ktx2")])
    assert result.exit_code == 2
    assert result.output.strip().splitlines() == [
        f"texcook: error: three.js is not installed for texcook view; run `{three.INSTALL}`"]


def test_size_is_checked():
    assert view.parse_size("640x360") == (640, 360)
    for bad in ("640", "ax3", "8x8", "9000x100"):
        with pytest.raises(UsageError):
            view.parse_size(bad)


def test_the_command_prints_its_address_serves_and_stops_on_ctrl_c(folder):
    if three.three_version() is None:
        pytest.skip(f"three.js not installed ({three.INSTALL})")
    proc = subprocess.Popen([sys.executable, "-m", "texcook.cli", "view", str(folder / "t.ktx2")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline()
        assert line.startswith("texcook view: http://127.0.0.1:") and "Ctrl-C" in line
        port = int(line.split("127.0.0.1:")[1].split("/")[0])
        conn = http.client.HTTPConnection("127.0.0.1", port, timeout=10)
        conn.request("GET", "/_texcook/three/build/three.module.js")
        resp = conn.getresponse()
        assert resp.status == 200 and resp.getheader("Content-Type").startswith("text/javascript")
        resp.read()
        conn.close()
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=20) == 130
        assert "interrupted" in proc.stderr.read()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
