"""The viewer's web server: the page's static files (shipped in the package), the take's description and its
frame sets as bundles; nothing else. Every path is matched exactly against that list after one
percent-decoding, so no request reaches a file outside it (``..``, ``%2e%2e``, ``%252e``, absolute paths).

With ``accept_results`` (tests and the benchmark only), ``POST /api/result?tag=NAME`` takes what the page
read back (pixels, timings) into ``results``: a queue of (tag, bytes)."""

from __future__ import annotations

import ipaddress
import json
import logging
import queue
import re
import socket
import sys
import threading
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources
from pathlib import Path
from urllib.parse import parse_qs, unquote, urlsplit

from rigctl.errors import ParameterError, RigctlError
from rigctl.viewer.bundle import Bundles

log = logging.getLogger(__name__)

TYPES = {".html": "text/html; charset=utf-8", ".js": "text/javascript; charset=utf-8", ".css": "text/css",
         ".glsl": "text/plain; charset=utf-8", ".png": "image/png"}  # fmt: skip
# a frame set's one URL: its number as take.json lists it (no leading zero, ASCII digits only: int() would also
# take "01", "١" or "１" for 1, and \d matches any script's digits)
FRAME = re.compile(r"/api/frame/(0|[1-9][0-9]{0,8})\.bin")
MAX_RESULT = 1 << 28  # a 4K RGBA read-back with room to spare
IDLE_S = 30.0  # a client that sends or takes nothing this long (gone, or holding a connection) is dropped
CHUNK = 1 << 16  # a body is written in these, each within IDLE_S: a slow but steady reader gets it whole


def static_files() -> dict[str, bytes]:
    """Every file under the package's ``static`` folder, by its URL path (``/static/...``); ``/`` is the page."""
    root = resources.files("rigctl.viewer") / "static"
    files: dict[str, bytes] = {}

    def walk(folder: resources.abc.Traversable, prefix: str) -> None:
        for entry in folder.iterdir():
            if entry.is_dir():
                walk(entry, f"{prefix}{entry.name}/")
            elif Path(entry.name).suffix in TYPES:
                files[f"/static/{prefix}{entry.name}"] = entry.read_bytes()

    walk(root, "")
    if "/static/index.html" not in files:
        raise ParameterError("the viewer's page is missing from the installed package (rigctl/viewer/static)")
    files["/"] = files["/static/index.html"]
    return files


class ViewerServer(ThreadingHTTPServer):
    daemon_threads = True
    # the port of a viewer just stopped is in TIME_WAIT while its browser's connections close: a rerun on the
    # same --port must not be refused for a minute (a live listener still is); Windows' SO_REUSEADDR would
    # share a port in use, so not there
    allow_reuse_address = sys.platform != "win32"

    def __init__(self, bundles: Bundles, host: str = "127.0.0.1", port: int = 0, accept_results: bool = False) -> None:
        self.bundles = bundles
        self.files = static_files()
        self.accept_results = accept_results
        self.results: queue.Queue[tuple[str, bytes]] = queue.Queue()
        if ":" in host:
            self.address_family = socket.AF_INET6
        try:
            super().__init__((host, port), _Handler)
        except OSError as exc:
            raise ParameterError(f"cannot listen on {host}:{port}: {exc.strerror or exc}") from None

    def server_close(self) -> None:
        super().server_close()
        self.bundles.close()

    def handle_error(self, request: object, client_address: object) -> None:
        """A browser that goes away mid-request (a closed tab, a stopped test) is not an error worth a traceback."""
        log.debug("request from %s ended early", client_address, exc_info=True)

    @property
    def url(self) -> str:
        host, port = self.server_address[:2]
        name = host.decode() if isinstance(host, bytes) else str(host)
        shown = f"[{name}]" if ":" in name else name
        return f"http://{shown}:{port}/"

    def start(self) -> threading.Thread:
        """Serve on a thread of its own (tests, the benchmark); ``shutdown()`` then ``server_close()`` stop it."""
        t = threading.Thread(target=self.serve_forever, name="rigctl-view", daemon=True)
        t.start()
        return t


class _Handler(BaseHTTPRequestHandler):
    server: ViewerServer
    protocol_version = "HTTP/1.1"

    def setup(self) -> None:
        super().setup()
        self.connection.settimeout(IDLE_S)  # without it a silent client held its connection and thread for ever

    def log_message(self, format: str, *args: object) -> None:
        log.debug("%s %s", self.address_string(), format % args)

    def _send(self, status: HTTPStatus, body: bytes, ctype: str = "text/plain; charset=utf-8") -> None:
        self.send_response(status)
        self.send_header("Content-Type", ctype)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        self.send_header("X-Content-Type-Options", "nosniff")
        self.end_headers()
        if self.command != "HEAD":
            view = memoryview(body)
            for at in range(0, len(view), CHUNK):
                self.wfile.write(view[at : at + CHUNK])

    def _path(self) -> str | None:
        """The request's path decoded once, or None when it could name anything outside our list."""
        raw = urlsplit(self.path).path
        path = unquote(raw, errors="strict") if "%" in raw else raw
        if ".." in path or "\\" in path or "\x00" in path or "%" in path or not path.startswith("/"):
            return None
        return path

    def _foreign_host(self) -> bool:
        """A request naming another host while we listen on loopback only: a web page whose name was made to
        resolve to 127.0.0.1 (DNS rebinding) reading the take through the user's browser. Refused (403)."""
        if not ipaddress.ip_address(str(self.server.server_address[0])).is_loopback:
            return False  # --bind shares the viewer on a network: any name of the machine is the user's
        host = self.headers.get("Host")
        if host is None:
            return False  # HTTP/1.0 without a Host: no browser (a browser always sends one)
        name = host[1 : host.find("]")] if host.startswith("[") else host.rsplit(":", 1)[0]
        if name.lower() == "localhost":
            return False
        try:
            return not ipaddress.ip_address(name).is_loopback
        except ValueError:
            return True

    def do_HEAD(self) -> None:
        self.do_GET()

    def do_GET(self) -> None:
        if self._foreign_host():
            self._send(HTTPStatus.FORBIDDEN, b"this viewer answers to localhost and 127.0.0.1 only\n")
            return
        try:
            path = self._path()
        except UnicodeDecodeError:
            path = None
        if path is None:
            self._send(HTTPStatus.BAD_REQUEST, b"bad path\n")
            return
        srv = self.server
        if path in srv.files:
            self._send(HTTPStatus.OK, srv.files[path], TYPES[Path(path if path != "/" else "/x.html").suffix])
        elif path == "/api/take.json":
            info = {**srv.bundles.info, "results": srv.accept_results}
            self._send(HTTPStatus.OK, json.dumps(info).encode(), "application/json")
        elif (m := FRAME.fullmatch(path)) and int(m[1]) in srv.bundles.numbers:
            try:
                bundle = srv.bundles.get(int(m[1]))
            except RigctlError as exc:  # a damaged file of the take: named on the terminal, the page shows the 500
                log.error("%s", exc)
                self._send(HTTPStatus.INTERNAL_SERVER_ERROR, f"frame set {m[1]} could not be read\n".encode())
                return
            self._send(HTTPStatus.OK, bundle, "application/octet-stream")
        else:
            self._send(HTTPStatus.NOT_FOUND, b"not found\n")

    def do_POST(self) -> None:
        url = urlsplit(self.path)
        try:
            length = int(self.headers.get("Content-Length") or 0)
        except ValueError:
            length = -1  # not a length: refused below as any other unwanted body
        wanted = self.server.accept_results and url.path == "/api/result" and 0 <= length <= MAX_RESULT
        if self._foreign_host() or not wanted:
            self.close_connection = True  # its body is not read
            self._send(HTTPStatus.NOT_FOUND, b"not found\n")
            return
        body = self.rfile.read(length)
        tag = parse_qs(url.query).get("tag", [""])[0]
        self.server.results.put((tag, body))
        self._send(HTTPStatus.OK, b"ok\n")
