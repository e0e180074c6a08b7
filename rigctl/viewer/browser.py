"""A headless Chromium driving the viewer's page, for the tests and the benchmark: started on a probe URL of a
server that accepts results, it renders, reads back and posts; ``Probe.collect`` waits for the page's
``done`` (or its ``error``). Software WebGL (SwiftShader) is enough; no browser automation library needed."""

from __future__ import annotations

import json
import os
import queue
import shutil
import signal
import subprocess
import tempfile
import time
from pathlib import Path
from urllib.parse import urlencode

from rigctl.errors import ParameterError
from rigctl.viewer.server import ViewerServer

BROWSERS = ("chromium", "chromium-browser", "google-chrome")
FLAGS = (
    "--headless=new", "--no-sandbox", "--no-first-run", "--no-default-browser-check", "--disable-extensions",
    "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--ignore-gpu-blocklist", "--mute-audio",
    "--disable-background-timer-throttling", "--disable-renderer-backgrounding", "--window-size=1400,900",
    "--remote-debugging-port=0",  # keeps the browser running until we stop it
)  # fmt: skip


def chromium() -> str:
    """The Chromium executable ($RIGCTL_CHROMIUM, else the first of BROWSERS on PATH)."""
    found = os.environ.get("RIGCTL_CHROMIUM") or next(filter(None, map(shutil.which, BROWSERS)), None)
    if not found:
        raise ParameterError("no Chromium found (apt-get install chromium, or set RIGCTL_CHROMIUM)")
    return found


class Probe:
    """One browser on one probe page of ``server`` (which must accept results)."""

    def __init__(self, server: ViewerServer, **params: str) -> None:
        if not server.accept_results:
            raise ValueError("the server does not accept results")
        self.server = server
        self.url = f"{server.url}?{urlencode(params)}"
        self.profile = tempfile.TemporaryDirectory(prefix="rigctl-chromium-")
        self.log = Path(self.profile.name) / "browser.log"
        with self.log.open("wb") as out:
            self.proc = subprocess.Popen(
                [chromium(), *FLAGS, f"--user-data-dir={self.profile.name}", self.url],
                stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, start_new_session=True,
            )  # fmt: skip

    def collect(self, timeout: float = 180.0) -> dict[str, bytes]:
        """Every result the page posted, by tag, once it posted ``done``; raises with the page's error or the
        browser's log when it posts ``error``, exits or runs out of time."""
        got: dict[str, bytes] = {}
        end = time.monotonic() + timeout
        while "done" not in got:
            try:
                tag, body = self.server.results.get(timeout=0.5)
            except queue.Empty:
                if self.proc.poll() is not None or time.monotonic() > end:
                    why = "exited" if self.proc.poll() is not None else f"gave nothing in {timeout:g} s"
                    raise RuntimeError(f"the browser {why}; its log:\n{self._tail()}") from None
                continue
            if tag == "error":
                raise RuntimeError(f"the page failed: {body.decode(errors='replace')}\n{self._tail()}")
            got[tag] = body
        return got

    def _tail(self) -> str:
        try:
            return self.log.read_text(errors="replace")[-3000:]
        except OSError:
            return ""

    def close(self) -> None:
        if self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGTERM)
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait()
        self.profile.cleanup()

    def __enter__(self) -> Probe:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def done_info(results: dict[str, bytes]) -> dict[str, str]:
    info: dict[str, str] = json.loads(results["done"])
    return info
