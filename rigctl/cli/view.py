"""``rigctl view``: the take's light field in a browser (WebGL2), served from this machine."""

from __future__ import annotations

import argparse
import ipaddress
import logging
import os
import signal
import sys
import threading

from rigctl.cli import args
from rigctl.cli.helptext import examples
from rigctl.errors import ParameterError

log = logging.getLogger(__name__)


def port(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a port number 0..65535, got {text!r}") from None
    if not 0 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"expected a port number 0..65535, got {text!r}")
    return value


def address(text: str) -> str:
    """An IP address to listen on (never a name: what is reachable should be what was typed)."""
    try:
        ip = ipaddress.ip_address(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an IP address such as 127.0.0.1 or 0.0.0.0, got {text!r}") from None
    # ::ffff:127.0.0.1 is 127.0.0.1 (the same clients reach it), which Python does not call loopback: as IPv4,
    # the server keeps refusing other hosts' names on it
    return str(getattr(ip, "ipv4_mapped", None) or ip)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "view",
        epilog=examples(
            ("an ideal simulated take with its true disparity, the page opened in the browser",
             "rigctl view takes/ideal --disparity takes/ideal/truth/disparity --open"),
            ("the demo's take and depth on a fixed port, for another machine of the network",
             "rigctl view rigctl-demo/takes/presenter-rectified --disparity rigctl-demo/depth --bind 0.0.0.0 "
             "--port 8080"),
        ),
        help="look around a take in the browser: a real-time light-field viewer (WebGL2) on a local web server",
        description="Serves one page and the take's frame sets; the page renders novel views on the GPU by the "
        "method of rigctl render, moves the eye within the array's window, plays the take, and shows stereo "
        "and WebXR. Listens on 127.0.0.1 unless --bind names another address; Ctrl-C stops it.",
    )
    args.add_views_input(p)
    p.add_argument(
        "--bind", type=address, default="127.0.0.1", metavar="ADDR",
        help="address to listen on (default 127.0.0.1: this machine only; 0.0.0.0: every network)",
    )  # fmt: skip
    p.add_argument("--port", type=port, default=0, help="port (default: a free one)")
    p.add_argument("--open", action="store_true", help="open the page in the default browser")
    p.set_defaults(func=run)


def run(ns: argparse.Namespace) -> int:
    from rigctl.viewer.bundle import Bundles
    from rigctl.viewer.server import ViewerServer

    if not ns.input.exists():
        raise ParameterError(f"{ns.input}: does not exist")
    bundles = Bundles(ns.input, ns.disparity)
    server = ViewerServer(bundles, ns.bind, ns.port)
    if not ipaddress.ip_address(ns.bind).is_loopback:
        log.warning("listening on %s: anyone who can reach this machine there can see the take", ns.bind)
    print(f"rigctl view: {ns.input} ({len(bundles.numbers)} frame sets) at {server.url} (Ctrl-C stops)", flush=True)
    if ns.open:
        import webbrowser

        webbrowser.open(server.url)
    try:
        server.serve_forever(poll_interval=0.2)
    except KeyboardInterrupt:
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # a second Ctrl-C while stopping stops nothing twice
        server.server_close()  # (again in finally: closing twice is harmless)
        sys.stderr.write("rigctl view: stopped\n")
        if any(t.daemon and t.is_alive() for t in threading.enumerate()):
            # a frame set still being made ahead is in numba's or OpenCV's threads: the interpreter's exit
            # beside them can abort in C++ ("terminate called without an active exception", exit -6). The
            # viewer writes nothing, so nothing is lost by leaving at once
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(0)
    finally:
        server.server_close()
    return 0
