"""The live view of a run (`testbed run --view [HOST:]PORT`): the same page, fed as it runs.

Theory of operation: the run's step loop calls `LiveFeed.publish` once a step with what it
already has in hand (the step, the bodies' positions, the link set the topology controller
just applied, coverage, deadlines missed): one tuple stored by reference, no copy, no lock,
no IO, so the loop never waits for the view. The server (aiohttp) runs in a thread of its
own with its own event loop; each browser gets a server-sent-events stream (`/api/live`)
from which the newest frame is sent at most every FRAME_S. A slow browser skips frames; a
closed one ends its stream; neither can reach the step loop. The view reads nothing from
the robots' processes and sends nothing on the emulated radio.
"""

from __future__ import annotations

import asyncio
import json
import threading
from pathlib import Path

from aiohttp import web

from testbed.view import server

FRAME_S = 0.1  # 10 frames a second at most
SEND_TIMEOUT_S = 1.0  # a browser that takes longer to accept a frame is dropped


class LiveFeed:
    def __init__(self, meta: dict) -> None:
        self.meta = meta
        self.latest: tuple | None = None
        self.ended = False

    def publish(self, step: int, positions, links, coverage: float, missed: int, scale) -> None:
        self.latest = (step, positions, links, coverage, missed, scale)

    def frame(self) -> dict | None:
        latest = self.latest
        if latest is None:
            return None
        step, positions, links, coverage, missed, scale = latest
        return {
            "step": step,
            "positions": [round(v, 3) for p in positions for v in p],
            "links": sorted(links),
            "coverage": coverage,
            "missed": missed,
            "scale": scale,
            "ended": self.ended,
        }


def make_app(feed: LiveFeed, map_png: str | None) -> web.Application:
    async def index(_request):
        return web.Response(text=(server.STATIC / "index.html").read_text(),
                            content_type="text/html")  # fmt: skip

    async def static(request):
        name = request.match_info["name"]
        if name not in server.STATIC_FILES:
            raise web.HTTPNotFound()
        return web.Response(text=(server.STATIC / name).read_text(),
                            content_type=server.STATIC_FILES[name])  # fmt: skip

    async def run(_request):
        return web.json_response({**feed.meta, "live": True})

    async def live(request):
        resp = web.StreamResponse(headers={"Content-Type": "text/event-stream",
                                           "Cache-Control": "no-cache"})  # fmt: skip
        await resp.prepare(request)
        sent = None
        try:
            while True:
                latest = feed.latest
                if latest is not None and latest is not sent:
                    sent = latest
                    data = json.dumps(feed.frame())
                    await asyncio.wait_for(resp.write(f"data: {data}\n\n".encode()),
                                           SEND_TIMEOUT_S)  # fmt: skip
                if feed.ended and latest is sent:
                    data = json.dumps(feed.frame())  # the last frame, saying the run is over
                    await asyncio.wait_for(resp.write(f"data: {data}\n\n".encode()),
                                           SEND_TIMEOUT_S)  # fmt: skip
                    break
                await asyncio.sleep(FRAME_S)
        except (TimeoutError, ConnectionResetError, RuntimeError):
            pass  # the browser went away or is too slow: its stream ends, nothing else
        return resp

    async def map_image(_request):
        if map_png and Path(map_png).is_file():
            return web.Response(body=Path(map_png).read_bytes(), content_type="image/png")
        raise web.HTTPNotFound()

    app = web.Application()
    app.add_routes([
        web.get("/", index), web.get("/static/{name}", static), web.get("/api/run", run),
        web.get("/api/live", live), web.get("/map.png", map_image),
    ])  # fmt: skip
    return app


class LiveServer:
    """The view's server in a daemon thread; `stop()` ends it (the run's teardown calls it)."""

    def __init__(self, feed: LiveFeed, bind: str, map_png: str | None = None) -> None:
        self.feed = feed
        self.host, self.port = server.parse_bind(bind)
        self.loop = asyncio.new_event_loop()
        self.runner = web.AppRunner(make_app(feed, map_png), handle_signals=False)
        self.loop.run_until_complete(self.runner.setup())
        site = web.TCPSite(self.runner, self.host, self.port)
        self.loop.run_until_complete(site.start())  # OSError here: cannot listen there
        self.thread = threading.Thread(target=self.loop.run_forever, name="view", daemon=True)
        self.thread.start()

    def stop(self) -> None:
        """Let the streams send their last frame and end, then close the server."""
        self.feed.ended = True
        if self.thread.is_alive():
            done = asyncio.run_coroutine_threadsafe(self._close(), self.loop)
            try:
                done.result(timeout=10)
            except Exception:  # a view that fails to close must not fail the run
                pass
            self.loop.call_soon_threadsafe(self.loop.stop)
            self.thread.join(timeout=5)

    async def _close(self) -> None:
        await asyncio.sleep(3 * FRAME_S)
        await self.runner.cleanup()
