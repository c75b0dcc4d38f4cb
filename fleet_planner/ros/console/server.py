"""The console's web end: an aiohttp server in a thread of its own (:class:`ConsoleServer`).

    GET /            the page (static/index.html, with console.js and console.css: no CDN, nothing
                     fetched from outside)
    GET /api/state   the fleet now, as JSON (what the websocket pushes)
    GET /ws          a websocket: the server sends the layout once, then the state every
                     ``1 / rate_hz`` s; the page sends requests ({"ref": n, "type": "command" |
                     "manual" | "drive" | "submit", ...}) and gets {"type": "reply", "ref": n, "ok",
                     "message"} back.

aiohttp is asyncio's own HTTP server and client with websockets built in: one well-kept package
(no separate ASGI server), and its event loop runs beside rclpy's executor without either
blocking the other. It listens on localhost only by default.
"""
from __future__ import annotations

import asyncio
import json
import threading
from importlib import resources
from typing import Any

from aiohttp import WSMsgType, web

from fleet_planner.ros.console.node import ConsoleNode

#: the largest message the page may send (bytes)
MAX_REQUEST_BYTES = 16 * 1024
_TYPES = {".html": "text/html", ".js": "text/javascript", ".css": "text/css", ".svg": "image/svg+xml"}


def _static(name: str) -> bytes:
    return resources.files("fleet_planner.ros.console").joinpath("static", name).read_bytes()


class ConsoleServer:
    """Serves ``node``'s view on ``host``:``port`` (0: any free port) from a background thread;
    :attr:`url` once :meth:`start` returned."""

    def __init__(self, node: ConsoleNode, host: str = "127.0.0.1", port: int = 8080, rate_hz: float = 4.0):
        if not 0.1 <= rate_hz <= 50.0:
            raise ValueError(f"rate_hz: must be in [0.1, 50] (got {rate_hz!r})")
        self.node = node
        self.host, self.port, self.period = host, int(port), 1.0 / rate_hz
        self.url = ""
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._runner: web.AppRunner | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._sockets: set[web.WebSocketResponse] = set()

    # -- life -------------------------------------------------------------------------------------
    def start(self, timeout: float = 10.0) -> str:
        """Start serving; the page's URL. OSError if the port cannot be had."""
        self._thread = threading.Thread(target=self._run, name="fleet-console-web", daemon=True)
        self._thread.start()
        if not self._ready.wait(timeout):
            raise OSError(f"the console's web server did not start within {timeout:g} s")
        if self._error is not None:
            raise OSError(f"the console cannot serve on {self.host}:{self.port}: {self._error}")
        return self.url

    def stop(self) -> None:
        loop = self._loop
        if loop is not None and loop.is_running():
            asyncio.run_coroutine_threadsafe(self._shutdown(), loop).result(timeout=10)
            loop.call_soon_threadsafe(loop.stop)
        if self._thread is not None:
            self._thread.join(timeout=10)

    def _run(self) -> None:
        loop = self._loop = asyncio.new_event_loop()
        asyncio.set_event_loop(loop)
        try:
            loop.run_until_complete(self._serve())
        except BaseException as exc:  # a port in use, say: reported by start()
            self._error = exc
            self._ready.set()
            return
        self._ready.set()
        try:
            loop.run_forever()
        finally:
            loop.close()

    async def _serve(self) -> None:
        app = web.Application(client_max_size=MAX_REQUEST_BYTES)
        app.router.add_get("/", self._page)
        app.router.add_get("/static/{name}", self._file)
        app.router.add_get("/api/state", self._state)
        app.router.add_get("/ws", self._websocket)
        self._runner = web.AppRunner(app, handle_signals=False, access_log=None)
        await self._runner.setup()
        site = web.TCPSite(self._runner, self.host, self.port)
        await site.start()
        host, port = self._runner.addresses[0][:2]
        self.port = int(port)
        self.url = f"http://{'localhost' if host in ('127.0.0.1', '::1') else host}:{self.port}/"

    async def _shutdown(self) -> None:
        for ws in list(self._sockets):
            await ws.close()
        if self._runner is not None:
            await self._runner.cleanup()

    # -- handlers ---------------------------------------------------------------------------------
    async def _page(self, request: web.Request) -> web.Response:
        return web.Response(body=_static("index.html"), content_type="text/html")

    async def _file(self, request: web.Request) -> web.Response:
        name = request.match_info["name"]
        suffix = name[name.rfind("."):] if "." in name else ""
        if "/" in name or ".." in name or suffix not in _TYPES:
            raise web.HTTPNotFound()
        try:
            body = _static(name)
        except (FileNotFoundError, OSError):
            raise web.HTTPNotFound() from None
        return web.Response(body=body, content_type=_TYPES[suffix])

    async def _state(self, request: web.Request) -> web.Response:
        return web.json_response(self.node.snapshot())

    async def _websocket(self, request: web.Request) -> web.WebSocketResponse:
        ws = web.WebSocketResponse(heartbeat=20.0, max_msg_size=MAX_REQUEST_BYTES)
        await ws.prepare(request)
        self._sockets.add(ws)
        pusher = asyncio.create_task(self._push(ws))
        try:
            await ws.send_json(self.node.layout())
            async for msg in ws:
                if msg.type == WSMsgType.TEXT:
                    asyncio.create_task(self._handle(ws, msg.data))
                elif msg.type == WSMsgType.ERROR:
                    break
        finally:
            pusher.cancel()
            self._sockets.discard(ws)
        return ws

    async def _push(self, ws: web.WebSocketResponse) -> None:
        try:
            while not ws.closed:
                await ws.send_json(self.node.snapshot())
                await asyncio.sleep(self.period)
        except (ConnectionError, RuntimeError, asyncio.CancelledError):
            pass

    async def _handle(self, ws: web.WebSocketResponse, text: str) -> None:
        ref: Any = None
        try:
            data = json.loads(text)
            ref = data.get("ref") if isinstance(data, dict) else None
            if not (ref is None or isinstance(ref, int) and not isinstance(ref, bool)):
                ref = None
            answer = await asyncio.wrap_future(self.node.request(data))
        except (ValueError, RecursionError) as exc:
            answer = {"ok": False, "message": f"request: not valid JSON ({exc})"[:300]}
        try:
            await ws.send_json({"type": "reply", "ref": ref, **answer})
        except (ConnectionError, RuntimeError):
            pass
