"""`texcook view`: a baked scene or texture in three.js, served on 127.0.0.1.

    open_site(path, source=None) -> Site          what PATH is and what the page shows (site.py)
    Server(site, THREE_DIR, port=0).start()       the HTTP server (server.py)
    screenshot(path, output, size, query)         the page in headless Chromium, as a PNG
    Browser()                                     headless Chromium over the DevTools pipe (browser.py)

The page (page/) and three.js (installed by npm from package.json and its lock
file into node_modules/ here) are served with the folder.
"""

import json
import urllib.parse

from ..errors import UsageError
from ..fileio import atomic_write
from .browser import Browser, BrowserError, find_chromium  # noqa: F401
from .server import Server
from .site import Site, open_site  # noqa: F401
from .three import INSTALL, THREE_DIR, require_three, three_version  # noqa: F401

DEFAULT_SIZE = (1280, 720)


def parse_size(text):
    """"WxH" -> (W, H), each 16..8192."""
    try:
        w, h = (int(v) for v in str(text).lower().split("x"))
    except ValueError:
        raise UsageError(f"--size takes WxH, such as 1280x720, not {text!r}") from None
    if not (16 <= w <= 8192 and 16 <= h <= 8192):
        raise UsageError(f"--size {text}: each side must be 16..8192")
    return w, h


def page_url(server, query=None):
    return server.url + ("?" + urllib.parse.urlencode(query) if query else "")


def render(site, size=DEFAULT_SIZE, query=None, timeout=120, browser=None):
    """(PNG bytes of the page as headless Chromium draws it, the page's report
    of each texture); BrowserError when the page fails. `browser`: a running
    Browser to reuse (its size stands), else one is started for this page."""
    require_three()
    if browser is None:
        with Browser(*size, timeout=timeout) as browser:
            return render(site, size, query, timeout, browser)
    with Server(site, THREE_DIR).start() as server:
        url = page_url(server, query)
        browser.goto(url)
        # a reused browser still shows the last page until the new one commits
        browser.wait_for(f"location.href === {json.dumps(url)} && window.texcook && texcook.state !== 'loading'",
                         timeout)
        state = browser.evaluate("({state: texcook.state, error: texcook.error, textures: texcook.textures})")
        if state["state"] != "ready":
            raise BrowserError(f"the page failed: {state['error']}")
        broken = [m for m in browser.console if "Shader Error" in m]
        if broken:
            raise BrowserError(f"the page's shader failed: {broken[0][:2000]}")
        return browser.screenshot(), state["textures"]


def screenshot(path, output, size=DEFAULT_SIZE, source=None, query=None):
    """Render PATH's page to the PNG `output`; returns the page's texture report."""
    png, textures = render(open_site(path, source), size, query)
    atomic_write(output, png)
    return textures
