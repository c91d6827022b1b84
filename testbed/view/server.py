"""`testbed view RUN_DIR`: the run's replay in the browser, from its files.

Theory of operation: an aiohttp application (aiohttp: a well-kept asyncio HTTP server that
streams to many clients at once, WebSocket and server-sent events included, which the
standard library's http.server does not) with five routes and nothing else: the page, its
two static files (looked up by exact name, so no path from a request ever reaches the file
system), the run as JSON (testbed.view.replay), the map picture and the display's
snapshots. The page is plain HTML
and JavaScript shipped in the package (testbed/view/static), no build step. It binds only
where told (127.0.0.1 unless a host is given). What it reads and serves of a run directory
is testbed.view.served's rule (the run's own files, real PNGs); its JSON is always valid
JSON (a value that is not finite goes out as null); a query parameter that is not what the
page sends is an HTTP 400 with one line saying why.
"""

from __future__ import annotations

import json
import logging
import math
import re
import socket
import sys
from pathlib import Path

from aiohttp import web

from testbed.files.resultvalues import one_line
from testbed.view import replay, served

STATIC = Path(__file__).parent / "static"
STATIC_FILES = {"view.js": "application/javascript", "view.css": "text/css"}
INDEX_PATTERN = re.compile(r"[0-9]{1,9}")  # a step or a robot in a query: ASCII digits


def _finite(obj):
    """`obj` with every float that is not finite replaced by None (JSON has no NaN)."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_finite(v) for v in obj]
    return obj


def json_text(obj) -> str:
    """`obj` as strict JSON: never NaN or Infinity, which browsers' JSON.parse refuses."""
    try:
        return json.dumps(obj, allow_nan=False)
    except ValueError:
        return json.dumps(_finite(obj), allow_nan=False)


def json_response(obj) -> web.Response:
    return web.json_response(obj, dumps=json_text)


def query_index(request: web.Request, key: str, lo: int, hi: int) -> int:
    """The whole number `key` in the request's query, in lo..hi, else HTTP 400 saying so."""
    text = request.query.get(key, "")
    if INDEX_PATTERN.fullmatch(text) is None or not lo <= int(text) <= hi:
        raise web.HTTPBadRequest(text=f"{key} must be a whole number in {lo}..{hi}\n")
    return int(text)


def png(path) -> web.Response:
    """A PNG file the view knows about (never a path a request names), or 404."""
    if path and served.is_png(Path(path)):
        return web.Response(body=Path(path).read_bytes(), content_type="image/png")
    raise web.HTTPNotFound()


def has_map(map_png: str | None) -> bool:
    """Whether the page should ask for /map.png (the empty terrain has no picture)."""
    return bool(map_png and served.is_png(Path(map_png)))


def page_routes(run_dir: Path | None, map_png: str | Path | None) -> list:
    """What the replay and the live view serve alike: the page, its static files (by exact
    name), the map picture and the display's snapshots (only steps the run saved)."""

    async def index(_request: web.Request) -> web.Response:
        return web.Response(text=(STATIC / "index.html").read_text(), content_type="text/html")

    async def static(request: web.Request) -> web.Response:
        name = request.match_info["name"]
        if name not in STATIC_FILES:
            raise web.HTTPNotFound()
        return web.Response(text=(STATIC / name).read_text(), content_type=STATIC_FILES[name])

    async def display_png(request: web.Request) -> web.Response:
        step = query_index(request, "step", 0, replay.MAX_STEP)
        return png(replay.snapshot_path(run_dir, step) if run_dir is not None else None)

    async def map_image(_request: web.Request) -> web.Response:
        return png(map_png)  # none on the empty terrain: the page draws its walls itself

    return [
        web.get("/", index), web.get("/static/{name}", static),
        web.get("/display.png", display_png), web.get("/map.png", map_image),
    ]  # fmt: skip


class OneLineErrors(logging.Filter):
    """aiohttp logs every request it cannot parse (a bad header, a NUL in the path) with its
    whole traceback, so whoever can connect could flood the operator's terminal: this makes
    each such record one line, "Error handling request from ADDR: BadHttpMessage: why"."""

    def filter(self, record: logging.LogRecord) -> bool:
        exc = record.exc_info[1] if record.exc_info else None
        if exc is not None:
            why = " ".join(part.strip() for part in str(exc).splitlines() if part.strip())
            record.msg = f"{record.getMessage()}: {type(exc).__name__}: {one_line(why, 200)}"
            record.args = ()
            record.exc_info = record.exc_text = None
        return True


def quiet_bad_requests() -> None:
    """OneLineErrors on aiohttp's server logger (once)."""
    logger = logging.getLogger("aiohttp.server")
    if not any(isinstance(f, OneLineErrors) for f in logger.filters):
        logger.addFilter(OneLineErrors())


def make_app(run_dir: str | Path, warn=None) -> web.Application:
    """The replay of `run_dir`; `warn(line)` is told when the run's map is not served."""
    quiet_bad_requests()
    run_dir = Path(run_dir).resolve()
    data = replay.load(run_dir)  # raises NotARun before anything listens
    map_png, why_not = served.map_picture(run_dir, replay.read_config(run_dir)["map"])
    if why_not and warn:
        warn(why_not)
    data["map"] = map_png is not None
    text = json_text(data)  # once: the run does not change

    async def run(_request: web.Request) -> web.Response:
        return web.Response(text=text, content_type="application/json")

    app = web.Application()
    app.add_routes([*page_routes(run_dir, map_png), web.get("/api/run", run)])
    return app


def parse_bind(text: str) -> tuple[str, int]:
    """`[HOST:]PORT` -> (host, port); 127.0.0.1 unless a host is given."""
    host, _, port = text.rpartition(":")
    if not INDEX_PATTERN.fullmatch(port) or not 0 < int(port) < 65536:
        raise ValueError(f"--view {text[:60]!r}: expected [HOST:]PORT")
    return host or "127.0.0.1", int(port)


def check_bind(bind: str) -> None:
    """ValueError (one line) unless the view can listen at `bind` ([HOST:]PORT) now: what
    is checked before anything is started, so that a busy port is refused, not found dead."""
    host, port = parse_bind(bind)
    try:
        family, kind, proto, _, addr = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)[0]
        with socket.socket(family, kind, proto) as s:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as the view's server does
            s.bind(addr)
    except OSError as e:
        raise ValueError(f"--view {bind}: cannot listen there: {e.strerror or e}") from None
    except UnicodeError:  # a host name that IDNA cannot encode
        raise ValueError(f"--view {bind[:60]!r}: cannot listen there: a bad host") from None


def serve(run_dir: str | Path, bind: str) -> int:
    host, port = parse_bind(bind)
    app = make_app(run_dir, warn=lambda line: print(f"testbed view: {line}", file=sys.stderr))
    check_bind(bind)
    name = one_line(Path(run_dir).name)  # a directory's name may hold terminal escapes
    print(f"replay of {name}: http://{host}:{port}/  (Ctrl-C ends it)", flush=True)
    web.run_app(app, host=host, port=port, print=None)
    return 0


def add_arguments(parser) -> None:
    parser.description = (
        "Replay a finished run in the browser, from its files. Only the run's own files are "
        "read and served (regular files inside RUN_DIR, symlinks followed, at most "
        f"{served.MAX_FILE_BYTES >> 20} MiB each; pictures only if PNG; the map also from "
        "the packaged maps): see docs/security.md."
    )
    parser.add_argument("run_dir", metavar="RUN_DIR", help="a run directory (testbed run --out)")
    parser.add_argument(
        "--view", metavar="[HOST:]PORT", default="8470",
        help="where to serve the page (default 127.0.0.1:8470; a host only if given)",
    )  # fmt: skip


def main(args) -> int:
    from common.errors import UsageError

    try:
        return serve(args.run_dir, args.view)
    except (ValueError, replay.NotARun) as e:
        raise UsageError(str(e)) from None
    except OSError as e:
        raise UsageError(f"--view {args.view}: cannot listen there: {e.strerror}") from None
