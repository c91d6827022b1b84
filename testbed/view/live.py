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
import threading
import time

from aiohttp import web

from aodv.statsfile import DaemonStats, StatsError
from node import events
from testbed.view import server
from testbed.view.served import snapshot_steps

FRAME_S = 0.1  # 10 frames a second at most
SEND_TIMEOUT_S = 1.0  # a browser that takes longer to accept a frame is dropped


class LiveFeed:
    def __init__(self, meta: dict, routes=None, run_dir=None, stats_files=(), events=None) -> None:
        """`routes(dest)`: {robot: next hop or None} from the robots' kernel tables (see
        KernelRoutes), or None where the view has no network to ask. `run_dir`: where the
        display's snapshots appear; `stats_files`: the AODV daemons' statistics, for the
        routing packets per second."""
        self.meta = meta
        self.routes = routes
        self.run_dir = run_dir
        self.stats_files = list(stats_files)
        self.events = events  # RobotEvents: goals and messages per second, or None
        self._rate: tuple[float, int, float | None] = (0.0, 0, None)  # (when, sent, rate)
        self.latest: tuple | None = None
        self.ended = False

    def publish(
        self, step: int, positions, links, coverage: float | None, missed: int, scale
    ) -> None:
        self.latest = (step, positions, links, coverage, missed, scale)

    def _robot_events(self) -> dict:
        if self.events is None:
            return {"goals": {}, "messages_ps": None}
        self.events.poll()
        return {"goals": {str(k): g for k, g in self.events.goals.items()},
                "messages_ps": self.events.rate}  # fmt: skip

    def routing_rate(self) -> float | None:
        """Routing packets sent per second by all daemons, from their statistics files
        (rewritten by the daemons every second), read at most once a second."""
        if not self.stats_files:
            return None
        now = time.monotonic()
        when, sent, rate = self._rate
        if now - when < 1.0:
            return rate
        total = 0
        for f in self.stats_files:
            try:
                total += DaemonStats.read(f).sent_total
            except StatsError:
                continue  # not written yet, or not one: it counts nothing
        if when:
            rate = round((total - sent) / (now - when), 1)
        self._rate = (now, total, rate)
        return rate

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
            "routing_pps": self.routing_rate(),
            **self._robot_events(),
            "snapshots": snapshot_steps(self.run_dir) if self.run_dir else [],
            "ended": self.ended,
            # A view whose drawn area follows the robots (netview) says where it is now.
            **({"origin": self.meta["origin"], "map_m": self.meta["map_m"]}
               if "origin" in self.meta else {}),
        }  # fmt: skip


def make_app(feed: LiveFeed, map_png: str | None) -> web.Application:
    server.quiet_bad_requests()  # a malformed request is one line in the log, not a traceback

    async def run(_request):
        return server.json_response({**feed.meta, "live": True, "map": server.has_map(map_png)})

    async def live(request):
        resp = web.StreamResponse(headers={"Content-Type": "text/event-stream",
                                           "Cache-Control": "no-cache"})  # fmt: skip
        await resp.prepare(request)

        async def send() -> None:
            event = f"data: {server.json_text(feed.frame())}\n\n".encode()
            await asyncio.wait_for(resp.write(event), SEND_TIMEOUT_S)

        sent = None
        try:
            while True:
                latest = feed.latest
                if latest is not None and latest is not sent:
                    sent = latest
                    await send()
                if feed.ended and latest is sent:
                    await send()  # the last frame, saying the run is over
                    break
                await asyncio.sleep(FRAME_S)
        except (TimeoutError, ConnectionResetError, RuntimeError):
            pass  # the browser went away or is too slow: its stream ends, nothing else
        return resp

    async def routes(request):
        to = server.query_index(request, "to", 1, feed.meta["robots"])  # else HTTP 400
        if feed.routes is None:
            raise web.HTTPNotFound()  # no network to ask
        hops = await asyncio.get_running_loop().run_in_executor(None, feed.routes, to)
        return server.json_response({str(k): nh for k, nh in hops.items()})

    app = web.Application()
    app.add_routes([
        *server.page_routes(feed.run_dir, map_png), web.get("/api/run", run),
        web.get("/api/live", live), web.get("/api/routes", routes),
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


class KernelRoutes:
    """Where each robot's kernel would send a packet for robot `dest` now: an RTM_GETROUTE
    lookup (topology.kernel.routequery) through a netlink socket opened once in each robot's
    namespace (read only; no packet is sent). Used by the view when a robot is clicked."""

    def __init__(self, testbed: str, robots: int) -> None:
        self.testbed, self.robots = testbed, robots
        self._socks: dict = {}
        self._lock = threading.Lock()  # one lookup at a time on the shared sockets

    def _sock(self, k: int):
        if k not in self._socks:
            from topology import names
            from topology.kernel import netns, rtnl

            self._socks[k] = netns.run_in(names.robot_ns(self.testbed, k), rtnl.open_socket)
        return self._socks[k]

    def __call__(self, dest: int) -> dict[int, int | None]:
        from topology import names
        from topology.kernel import routequery

        out: dict[int, int | None] = {}
        with self._lock:
            for k in range(1, self.robots + 1):
                if k != dest:
                    out[k] = routequery.next_hop(self._sock(k), names.robot_addr(dest))
        return out

    def close(self) -> None:
        for s in self._socks.values():
            s.close()
        self._socks.clear()


SEND_LINE, PLAN_LINE = events.line_prefix("send"), events.line_prefix("plan")


class RobotEvents:
    """The robots' own event logs (robots/rK.events.jsonl, written by the robot processes as
    they run), followed like `tail -f`: each robot's newest goal (its plan events) and the
    messages the team sent per second (its send events). Read at most once a second."""

    def __init__(self, paths: dict[int, str]) -> None:
        self.paths = paths
        self.offsets = dict.fromkeys(paths, 0)
        self.goals: dict[int, list[float]] = {}
        self.rate: float | None = None
        self._last = 0.0

    def poll(self) -> None:
        now = time.monotonic()
        if now - self._last < 1.0:
            return
        sent = 0
        for k, path in self.paths.items():
            try:
                with open(path, "rb") as f:
                    f.seek(self.offsets[k])
                    chunk = f.read()
            except OSError:
                continue
            end = chunk.rfind(b"\n") + 1  # whole lines only; the rest next time
            self.offsets[k] += end
            for line in chunk[:end].splitlines():
                if line.startswith(SEND_LINE):
                    sent += 1
                elif line.startswith(PLAN_LINE):
                    ev = events.parse(line)
                    goal = ev.get("goal") if ev else None
                    if goal:
                        self.goals[k] = goal
        if self._last:
            self.rate = round(sent / (now - self._last), 1)
        self._last = now
