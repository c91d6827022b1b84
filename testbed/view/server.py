"""`testbed view RUN_DIR`: the run's replay in the browser, from its files.

Theory of operation: an aiohttp application (aiohttp: a well-kept asyncio HTTP server that
streams to many clients at once, WebSocket and server-sent events included, which the
standard library's http.server does not) with four routes and nothing else: the page, its
two static files (looked up by exact name, so no path from a request ever reaches the file
system), the run as JSON (testbed.view.replay) and the map picture. The page is plain HTML
and JavaScript shipped in the package (testbed/view/static), no build step. It binds only
where told (127.0.0.1 unless a host is given).
"""

from __future__ import annotations

from pathlib import Path

from aiohttp import web

from testbed.view import replay
from topology.jsonfile import read_json

STATIC = Path(__file__).parent / "static"
STATIC_FILES = {"view.js": "application/javascript", "view.css": "text/css"}


def make_app(run_dir: str | Path) -> web.Application:
    run_dir = Path(run_dir).resolve()
    data = replay.load(run_dir)  # raises NotARun before anything listens

    async def index(_request: web.Request) -> web.Response:
        return web.Response(text=(STATIC / "index.html").read_text(), content_type="text/html")

    async def static(request: web.Request) -> web.Response:
        name = request.match_info["name"]
        if name not in STATIC_FILES:
            raise web.HTTPNotFound()
        return web.Response(text=(STATIC / name).read_text(), content_type=STATIC_FILES[name])

    async def run(_request: web.Request) -> web.Response:
        return web.json_response(data)

    async def display_png(request: web.Request) -> web.Response:
        step = request.query.get("step", "")
        path = replay.snapshot_path(run_dir, int(step)) if step.isdigit() else None
        if path is None:
            raise web.HTTPNotFound()
        return web.Response(body=path.read_bytes(), content_type="image/png")

    async def map_png(_request: web.Request) -> web.Response:
        config = read_json(run_dir / "config.json") or {}
        src = config.get("map")
        if src and Path(src).is_file():
            return web.Response(body=Path(src).read_bytes(), content_type="image/png")
        raise web.HTTPNotFound()  # the empty terrain: the page draws its walls itself

    app = web.Application()
    app.add_routes([
        web.get("/", index), web.get("/static/{name}", static), web.get("/api/run", run),
        web.get("/map.png", map_png), web.get("/display.png", display_png),
    ])  # fmt: skip
    return app


def parse_bind(text: str) -> tuple[str, int]:
    """`[HOST:]PORT` -> (host, port); 127.0.0.1 unless a host is given."""
    host, _, port = text.rpartition(":")
    if not port.isdigit() or not 0 < int(port) < 65536:
        raise ValueError(f"--view {text!r}: expected [HOST:]PORT")
    return host or "127.0.0.1", int(port)


def serve(run_dir: str | Path, bind: str) -> int:
    host, port = parse_bind(bind)
    app = make_app(run_dir)
    print(f"replay of {Path(run_dir).name}: http://{host}:{port}/  (Ctrl-C ends it)", flush=True)
    web.run_app(app, host=host, port=port, print=None)
    return 0


def add_arguments(parser) -> None:
    parser.add_argument("run_dir", metavar="RUN_DIR", help="a run directory (testbed run --out)")
    parser.add_argument(
        "--view", metavar="[HOST:]PORT", default="8470",
        help="where to serve the page (default 127.0.0.1:8470; a host only if given)",
    )  # fmt: skip


def main(args) -> int:
    from testbed.errors import UsageError

    try:
        return serve(args.run_dir, args.view)
    except (ValueError, replay.NotARun) as e:
        raise UsageError(str(e)) from None
    except OSError as e:
        raise UsageError(f"--view {args.view}: cannot listen there: {e.strerror}") from None
