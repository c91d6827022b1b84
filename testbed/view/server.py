"""`testbed view RUN_DIR`: the run's replay in the browser, from its files.

Theory of operation: an aiohttp application (aiohttp: a well-kept asyncio HTTP server that
streams to many clients at once, WebSocket and server-sent events included, which the
standard library's http.server does not) with five routes and nothing else: the page, its
two static files (looked up by exact name, so no path from a request ever reaches the file
system), the run as JSON (testbed.view.replay), the map picture and the display's
snapshots. The page is plain HTML
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


def png(path) -> web.Response:
    """A PNG file the view knows about (never a path a request names), or 404."""
    if path and Path(path).is_file():
        return web.Response(body=Path(path).read_bytes(), content_type="image/png")
    raise web.HTTPNotFound()


def has_map(map_png: str | None) -> bool:
    """Whether the page should ask for /map.png (the empty terrain has no picture)."""
    return bool(map_png) and Path(map_png).is_file()


def page_routes(run_dir: Path | None, map_png: str | None) -> list:
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
        step = request.query.get("step", "")
        ok = step.isdigit() and run_dir is not None
        return png(replay.snapshot_path(run_dir, int(step)) if ok else None)

    async def map_image(_request: web.Request) -> web.Response:
        return png(map_png)  # none on the empty terrain: the page draws its walls itself

    return [
        web.get("/", index), web.get("/static/{name}", static),
        web.get("/display.png", display_png), web.get("/map.png", map_image),
    ]  # fmt: skip


def make_app(run_dir: str | Path) -> web.Application:
    run_dir = Path(run_dir).resolve()
    data = replay.load(run_dir)  # raises NotARun before anything listens
    map_png = (read_json(run_dir / "config.json") or {}).get("map")

    data["map"] = has_map(map_png)

    async def run(_request: web.Request) -> web.Response:
        return web.json_response(data)

    app = web.Application()
    app.add_routes([*page_routes(run_dir, map_png), web.get("/api/run", run)])
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
