"""The HTTP server of `texcook view`: 127.0.0.1 only, GET and HEAD only, and
only these files:

- /                       the page (page/index.html)
- /_texcook/page/NAME     the page's own files (page/)
- /_texcook/three/PATH    three.js as npm installed it (build/ and examples/jsm/)
- /_texcook/site.json     what the page shows (texcook.view.site)
- /_texcook/made/NAME     files made for the page (a DDS or .astc file as KTX2, a source image)
- /_texcook/original/URI  the files of the original model that scene.json names, and only them
- /files/PATH             the served folder

A path is decoded once; any `..` or `.` part, a backslash, a NUL or an empty
part is refused (404), and what the path names is resolved through symlinks
and refused (403) unless it is a regular file inside its folder.
"""

import http.server
import os
import posixpath
import threading
import urllib.parse

from ..container import table as containers
from ..errors import TexcookError
from ..fileio import check_regular, read_bytes

TYPES = {
    ".html": "text/html; charset=utf-8", ".js": "text/javascript; charset=utf-8", ".mjs": "text/javascript",
    ".css": "text/css", ".json": "application/json", ".png": "image/png", ".jpg": "image/jpeg",
    ".jpeg": "image/jpeg", ".bin": "application/octet-stream",
    ".gltf": "model/gltf+json", ".glb": "model/gltf-binary", ".wasm": "application/wasm",
}
# texture files as a glTF model names them (the container table's mimeType)
TYPES.update({ext: box.mime for box in containers.CONTAINERS.values() if box.mime for ext in box.extensions})
PAGE_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "page")
THREE_PARTS = ("build", "examples/jsm")  # what the page imports of the three package


class Refused(Exception):
    def __init__(self, status, why):
        super().__init__(why)
        self.status = status


def parts_of(url_path):
    """The parts of a request path below its route, decoded once; Refused(404)
    for anything that could step out of a folder or name it oddly."""
    text = urllib.parse.unquote(url_path, errors="strict")
    parts = text.split("/")
    if any(p in ("", ".", "..") or "\\" in p or "\0" in p for p in parts):
        raise Refused(404, "not a plain relative path")
    return parts


def inside(folder, parts):
    """The real path of `parts` under `folder`, which must be a regular file
    there after every symlink is followed; Refused(404 or 403) otherwise."""
    base = os.path.realpath(folder)
    path = os.path.realpath(os.path.join(base, *parts))
    if os.path.commonpath([base, path]) != base:
        raise Refused(403, "outside the served folder")
    if not os.path.exists(path):
        raise Refused(404, "no such file")
    try:
        check_regular(path)
    except TexcookError:
        raise Refused(403, "not a regular file") from None
    return path


class Routes:
    """Maps a request path to (bytes, content type) for one site."""

    def __init__(self, site, three_dir):
        self.site = site
        self.three_dir = three_dir

    def get(self, raw_path):
        path = urllib.parse.urlsplit(raw_path).path
        if path in ("/", "/index.html"):
            return self._file(os.path.join(PAGE_DIR, "index.html"))
        if path == "/_texcook/site.json":
            return self.site.manifest_bytes(), TYPES[".json"]
        for prefix, handler in (("/_texcook/page/", self._page), ("/_texcook/three/", self._three),
                                ("/_texcook/made/", self._made), ("/_texcook/original/", self._original),
                                ("/files/", self._served)):
            if path.startswith(prefix):
                return handler(parts_of(path[len(prefix):]))
        raise Refused(404, "no such route")

    def _file(self, path):
        return read_bytes(path, "served file"), TYPES.get(os.path.splitext(path)[1].lower(),
                                                          "application/octet-stream")

    def _page(self, parts):
        return self._file(inside(PAGE_DIR, parts))

    def _three(self, parts):
        if not any(posixpath.join(*parts).startswith(p + "/") for p in THREE_PARTS):
            raise Refused(404, "not a part of three.js the page uses")
        return self._file(inside(self.three_dir, parts))

    def _made(self, parts):
        made = self.site.made.get("/".join(parts))
        if made is None:
            raise Refused(404, "no such file")
        return made(), TYPES.get(os.path.splitext(parts[-1])[1].lower(), "application/octet-stream")

    def _original(self, parts):
        path = self.site.original_files.get("/".join(parts))
        if path is None:
            raise Refused(404, "not a file of the original model")
        return self._file(path)

    def _served(self, parts):
        return self._file(inside(self.site.root, parts))


def _handler(routes, log):
    class Handler(http.server.BaseHTTPRequestHandler):
        server_version = "texcook-view"

        def do_GET(self):
            self._answer(body=True)

        def do_HEAD(self):
            self._answer(body=False)

        def _answer(self, body):
            host = (self.headers.get("Host") or "").rsplit(":", 1)[0]
            try:
                if host not in ("127.0.0.1", "localhost"):
                    # another name resolving here (DNS rebinding) gets nothing
                    raise Refused(403, "not addressed to 127.0.0.1")
                data, kind = routes.get(self.path)
            except Refused as exc:
                self._plain(exc.status, str(exc), body)
                return
            except (UnicodeDecodeError, ValueError):
                self._plain(404, "undecodable path", body)
                return
            except TexcookError as exc:
                self._plain(403 if "regular" in str(exc) else 404, str(exc), body)
                return
            self.send_response(200)
            self.send_header("Content-Type", kind)
            self.send_header("Content-Length", str(len(data)))
            self.send_header("Cache-Control", "no-store")
            self.end_headers()
            if body:
                self.wfile.write(data)

        def _plain(self, status, why, body):
            data = f"{status}: {why}\n".encode()
            self.send_response(status)
            self.send_header("Content-Type", "text/plain; charset=utf-8")
            self.send_header("Content-Length", str(len(data)))
            self.end_headers()
            if body:
                self.wfile.write(data)

        def log_message(self, fmt, *args):
            if log is not None:
                log(fmt % args)

    return Handler


class Server:
    """A running server for one site on 127.0.0.1; `port` 0 takes a free one."""

    def __init__(self, site, three_dir, port=0, log=None):
        self.httpd = http.server.ThreadingHTTPServer(("127.0.0.1", port), _handler(Routes(site, three_dir), log))
        self.httpd.daemon_threads = True
        self.port = self.httpd.server_address[1]
        self.url = f"http://127.0.0.1:{self.port}/"
        self._thread = None

    def start(self):
        """Serve on a background thread (screenshots and tests)."""
        self._thread = threading.Thread(target=self.httpd.serve_forever, daemon=True)
        self._thread.start()
        return self

    def serve_forever(self):
        self.httpd.serve_forever()

    def close(self):
        if self._thread is not None:
            self.httpd.shutdown()
        self.httpd.server_close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
