"""The explorer's server: Bokeh's, on the loopback address unless told otherwise (`host`), serving BokehJS itself (no
CDN: the page works offline), and answering only requests addressed to itself.

Every web page the user visits can send requests to a server on the user's machine: a page whose DNS name an attacker
rebinds to 127.0.0.1 sends them with its own name in the Host header, a page of another site with its site in the
Origin header. So every request — the page, BokehJS, the websocket, the download — is refused (403) unless its Host is
one of this server's names with its port and its Origin, when it has one, too (:func:`local`, a tornado rule in front
of Bokeh's application); Bokeh's own check of the websocket's origin (`allow_websocket_origin`) stands behind it. The
page runs the packaged scenarios and the file named on the command line, nothing a URL names (:mod:`.catalogue`,
:mod:`.view`)."""

from __future__ import annotations

import asyncio
import contextlib
import errno
import os
import signal
import sys
import threading
import webbrowser
from collections.abc import Callable, Iterable, Mapping
from concurrent.futures import Executor, ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from bokeh.application import Application
from bokeh.application.handlers.function import FunctionHandler
from bokeh.server.server import BaseServer
from bokeh.server.tornado import BokehTornado
from bokeh.settings import settings
from tornado.httpserver import HTTPServer
from tornado.ioloop import IOLoop
from tornado.netutil import bind_sockets
from tornado.routing import AnyMatches, Matcher, Rule, RuleRouter
from tornado.web import Application as TornadoApplication
from tornado.web import RequestHandler

from ..validation import ConfigError
from .app import document
from .catalogue import Catalogue
from .download import archive, filename
from .view import View

#: the loopback names a browser on this machine may use; an attacker's DNS name is never one of them
LOOPBACK = ("127.0.0.1", "localhost", "::1")


def allowed_hosts(host: str, port: int, extra: Iterable[str] = ()) -> frozenset[str]:
    """The `Host` (and Origin `host:port`) values this server answers: the loopback names and `host`, each with `port`
    (an IPv6 address in brackets), and the `extra` ones as given (`--allow-origin`)."""
    names = {*LOOPBACK, host}
    return frozenset({f"[{n}]:{port}" if ":" in n else f"{n}:{port}" for n in names} | {e.lower() for e in extra})


def local(headers: Mapping[str, str], allowed: frozenset[str]) -> bool:
    """Whether a request is addressed to this server: its Host is allowed, and its Origin's `host:port`, when it has
    an Origin (every websocket and cross-site request has), too."""
    origin = headers.get("Origin")
    return headers.get("Host", "").lower() in allowed and (origin is None or urlsplit(origin.lower()).netloc in allowed)


class _Foreign(Matcher):
    """Matches the requests :func:`local` refuses."""

    def __init__(self, allowed: frozenset[str]) -> None:
        self.allowed = allowed

    def match(self, request: Any) -> dict[str, Any] | None:
        return None if local(request.headers, self.allowed) else {}


class Refused(RequestHandler):
    """403 and one line for a request addressed to another host or from another origin."""

    def prepare(self) -> None:
        self.set_status(403)
        self.set_header("Content-Type", "text/plain; charset=utf-8")
        self.finish("robotadapt explore: refused: this server answers only requests addressed to it (Host) from its "
                    "own pages (Origin)\n")


class Download(RequestHandler):
    """`/download?…`: the zip of the view's run (:mod:`.download`); a bad view is 400 with the ConfigError's line."""

    def initialize(self, catalogue: Catalogue, executor: Executor) -> None:
        self.catalogue, self.executor = catalogue, executor

    async def get(self) -> None:
        loop = IOLoop.current()
        view, refused = View.of_query(self.request.query_arguments, self.catalogue.default).checked()
        try:
            if refused:
                raise refused[0]
            run = await loop.run_in_executor(self.executor, self.catalogue.run, view)
            data = await loop.run_in_executor(self.executor, archive, run)
        except ConfigError as exc:
            self.set_status(400)
            self.set_header("Content-Type", "text/plain; charset=utf-8")
            self.finish(f"robotadapt: error: {exc}\n")
            return
        self.set_header("Content-Type", "application/zip")
        self.set_header("Content-Disposition", f'attachment; filename="{filename(run)}"')
        self.finish(data)


@dataclass(eq=False)
class Explorer:
    """A started explorer: its Bokeh server, HTTP server, URL and the worker that runs the loops."""

    server: BaseServer
    http: HTTPServer
    url: str
    executor: ThreadPoolExecutor

    async def stop(self) -> None:
        """Stop serving, close the connections and the port; a run under way is left to end, its result dropped."""
        self.server.stop(wait=False)
        await self.http.close_all_connections()
        self.executor.shutdown(wait=False, cancel_futures=True)


def start(source: str | Path, host: str = "127.0.0.1", port: int = 5006, origins: Iterable[str] = ()) -> Explorer:
    """Start serving the explorer of `source` (a packaged scenario or a file) on `host`:`port` (0: a free port) in the
    running event loop; its first run starts at once, so that the first page finds it done."""
    settings.resources.set_value("server")  # BokehJS from this server, whatever BOKEH_RESOURCES says: works offline
    catalogue = Catalogue(source)
    executor = ThreadPoolExecutor(1, thread_name_prefix="robotadapt-explore")
    try:
        sockets = bind_sockets(port, host)
    except OSError as exc:  # the port taken, or an address that is not this machine's
        field = "--port" if exc.errno == errno.EADDRINUSE else "--host"
        raise ConfigError(field, f"cannot listen on {host}:{port}: {exc.strerror or exc}") from None
    port = sockets[0].getsockname()[1]
    allowed = allowed_hosts(host, port, origins)
    app = BokehTornado({"/": Application(FunctionHandler(document(catalogue, executor)))},
                       extra_websocket_origins=sorted(allowed),
                       extra_patterns=[(r"/download", Download, {"catalogue": catalogue, "executor": executor})])
    refuse = TornadoApplication([(r".*", Refused)])
    http = HTTPServer(RuleRouter([Rule(_Foreign(allowed), refuse), Rule(AnyMatches(), app)]))
    http.add_sockets(sockets)
    server = BaseServer(IOLoop.current(), app, http)
    server.start()
    executor.submit(catalogue.run, View(catalogue.default))
    shown = "127.0.0.1" if host in ("0.0.0.0", "::", "") else f"[{host}]" if ":" in host else host
    return Explorer(server, http, f"http://{shown}:{port}/", executor)


def has_display() -> bool:
    """Whether a browser could show a window here (on Linux: an X or Wayland display)."""
    return not sys.platform.startswith("linux") or bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


async def _serve(source: str | Path, host: str, port: int, origins: Iterable[str], browser: bool,
                 announce: Callable[[str], None]) -> None:
    explorer = start(source, host, port, origins)
    stopped = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(NotImplementedError):  # Windows: Ctrl-C ends it as KeyboardInterrupt
            loop.add_signal_handler(sig, stopped.set)
    announce(f"robotadapt explore: serving {explorer.url} (Ctrl-C stops it)")
    if browser and has_display():
        threading.Thread(target=webbrowser.open, args=(explorer.url,), daemon=True).start()
    await stopped.wait()
    await explorer.stop()
    announce("robotadapt explore: stopped")


def serve(source: str | Path, host: str = "127.0.0.1", port: int = 5006, origins: Iterable[str] = (),
          browser: bool = True, announce: Callable[[str], None] = print) -> None:
    """Serve the explorer until Ctrl-C (SIGINT) or SIGTERM, then close the port and return."""
    asyncio.run(_serve(source, host, port, origins, browser, announce))
