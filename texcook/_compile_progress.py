"""The live line a terminal shows while first-use kernels compile.

texcook._jit.first_use() prints one line naming what compiles and the
seconds it is expected to take, then starts an entry here; every entry of the
process shares one status line below it, redrawn a few times a second by one
thread with the seconds elapsed against the seconds expected and a spinner:

    texcook: compiling the astc-6x6 encoder for first use (about 30 s; cached afterwards)
      12 s of about 30 s |

The status line is cleared once numba has compiled nothing for a moment
after compiling something (the block that started the entry may run on for
minutes encoding a large image, and should not look like compiling then),
when the last entry's block ends, or when an exception (Ctrl-C) ends it, so
a transcript keeps only the first line. It is first drawn after a second: a
shorter compile needs none. The thread only sleeps and writes a line;
numba's compiler runs as fast beside it.
"""

import threading
import time

INTERVAL = 0.25  # seconds between redraws
IDLE = 1.0  # numba idle this long after compiling: the compile is over
FIRST_DRAW = 1.0  # seconds before the line is first drawn
_SPIN = "|/-\\"

_lock = threading.RLock()  # the entries, the drawn line and the thread
_entries = {}  # token -> _Entry, in the order they began
_drawer = None  # the thread redrawing the line, while there are entries
_wake = threading.Event()  # set to make the drawer look again at once
_next_token = 0


class _Entry:
    def __init__(self, stream, seconds, start):
        self.stream, self.seconds, self.start = stream, seconds, start


class _CompileWatch:
    """How many numba compilations run now in this process, and when the
    last one ended, from numba's compile events (every thread's)."""

    def __init__(self):
        self.depth = 0
        self.seen = False  # some compilation began since the entries began
        self.last_end = None
        self._lock = threading.Lock()

    def started(self):
        with self._lock:
            self.depth += 1
            self.seen = True

    def ended(self):
        with self._lock:
            self.depth = max(0, self.depth - 1)
            self.last_end = time.monotonic()

    def idle_since(self, now):
        """True when something compiled and nothing has for IDLE seconds."""
        with self._lock:
            return self.seen and self.depth == 0 and self.last_end is not None and now - self.last_end >= IDLE

    def reset(self):
        with self._lock:
            self.seen, self.last_end = self.depth > 0, None


_watch = _CompileWatch()
_listening = False


def _listen():
    """Follow numba's compile events (once per process; numba is loaded by
    the time an entry begins, as first_use() read its cache)."""
    global _listening
    if _listening:
        return
    try:
        from numba.core import event
    except ImportError:
        return

    class Listener(event.Listener):
        def on_start(self, ev):
            _watch.started()

        def on_end(self, ev):
            _watch.ended()

    event.register("numba:compile", Listener())
    _listening = True


def begin(stream, seconds):
    """Show a compile expected to take about `seconds` on the status line of
    `stream` (a terminal) until end(token) or the compile goes idle. Returns
    the token for end()."""
    global _drawer, _next_token
    with _lock:
        _listen()
        if not _entries:
            _watch.reset()
        _next_token += 1
        _entries[_next_token] = _Entry(stream, seconds, time.monotonic())
        if _drawer is None:
            _wake.clear()
            _drawer = threading.Thread(target=_draw_loop, name="texcook-compile-progress", daemon=True)
            _drawer.start()
        return _next_token


def end(token):
    """The block of `token` is over (done or raised): its entry leaves the
    line, which is cleared with the last one on its stream (else redrawn by
    the drawer). The drawer stops with the last entry."""
    with _lock:
        entry = _entries.pop(token, None)
        if entry is not None and entry.stream not in _by_stream():
            _clear(entry.stream)
        drawer = _stop_drawer()
    if drawer is not None:
        drawer.join()


def _stop_drawer():
    """The drawer, told to stop when no entry is left (under _lock), else None."""
    global _drawer
    drawer = _drawer if not _entries else None
    if drawer is not None:
        _drawer = None
        _wake.set()
    return None if drawer is threading.current_thread() else drawer


def _draw_loop():
    while True:
        _wake.wait(INTERVAL)
        with _lock:
            if _drawer is not threading.current_thread():
                return
            now = time.monotonic()
            if _watch.idle_since(now):  # every entry's compile is over
                for stream in _by_stream():
                    _clear(stream)
                _entries.clear()
                _stop_drawer()
                return
            _draw(now)


_drawn = {}  # stream -> width of the live line on it


def _line(entries, now):
    """The status of every entry on one stream: the first began at `start`,
    the last is expected to end `expected` seconds after it."""
    start = min(e.start for e in entries)
    if now - start < FIRST_DRAW:
        return None
    expected = max(e.start + e.seconds for e in entries) - start
    spin = _SPIN[int((now - start) / INTERVAL) % len(_SPIN)]
    return f"  {now - start:.0f} s of about {expected:.0f} s {spin}"


def _draw(now):
    for stream, entries in _by_stream().items():
        text = _line(entries, now)
        if text is None:
            continue
        _write(stream, "\r" + text.ljust(_drawn.get(stream, 0)))
        _drawn[stream] = len(text)


def _clear(stream):
    width = _drawn.pop(stream, None)
    if width is not None:
        _write(stream, "\r" + " " * width + "\r")


def _by_stream():
    out = {}
    for e in _entries.values():
        out.setdefault(e.stream, []).append(e)
    return out


def _write(stream, text):
    try:
        stream.write(text)
        stream.flush()
    except (OSError, ValueError):  # a closed terminal: the work goes on without its line
        pass
