"""rigctl view's server as a real process: the address it binds, the only paths it serves (``..`` and encoded
variants refused), Ctrl-C, and bad input as one line."""

from __future__ import annotations

import http.client
import shutil
import signal
import socket
import subprocess
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from tests_support import rigctl_exe, run_rigctl

import rigctl.viewer.bundle as bundle_module
import rigctl.viewer.server as server_module
from rigctl.viewer.bundle import Bundles
from rigctl.viewer.server import ViewerServer

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def take(module_tmp: Callable[[str], Path]) -> Path:
    out = module_tmp("view-server")
    rig = (REPO / "rigs" / "sim-3x3.yaml").read_text()
    rig = rig.replace("width_px: 960", "width_px: 160").replace("height_px: 540", "height_px: 90")
    (out / "tiny.yaml").write_text(rig)
    res = run_rigctl(
        "record", str(out / "tiny.yaml"), "--take", "t", "--frames", "2", "--out", str(out),
        "--sim", "ideal=true", "--sim", "motion=false", "--sim", "deterministic=true", "--force",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    (out / "secret.txt").write_text("not for the network")
    return out / "t"


class Served:
    def __init__(self, proc: subprocess.Popen[str], line: str) -> None:
        self.proc = proc
        self.line = line
        self.url = line.split(" at ")[1].split(" ")[0]
        self.host, port = self.url.removeprefix("http://").rstrip("/").rsplit(":", 1)
        self.port = int(port)

    def get(self, path: str, method: str = "GET") -> tuple[int, bytes]:
        conn = http.client.HTTPConnection(self.host, self.port, timeout=30)
        try:
            conn.putrequest(method, path, skip_host=False, skip_accept_encoding=True)  # the path as given
            conn.endheaders()
            res = conn.getresponse()
            return res.status, res.read()
        finally:
            conn.close()


def serve(take: Path, *extra: str) -> Served:
    proc = subprocess.Popen(
        [*rigctl_exe(), "view", str(take), "--disparity", str(take / "truth" / "disparity"), *extra],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, stdin=subprocess.DEVNULL, text=True,
    )  # fmt: skip
    assert proc.stdout is not None
    line = proc.stdout.readline()
    assert line.startswith("rigctl view: "), (line, proc.stderr.read() if proc.poll() is not None else "")  # type: ignore[union-attr]
    return Served(proc, line)


@pytest.fixture(scope="module")
def served(take: Path) -> Iterator[Served]:
    s = serve(take)
    yield s
    if s.proc.poll() is None:
        s.proc.send_signal(signal.SIGINT)
        s.proc.wait(30)


def test_it_listens_on_127_0_0_1_on_a_free_port_unless_told(served: Served) -> None:
    assert served.host == "127.0.0.1" and served.port > 0
    assert "2 frame sets" in served.line and "Ctrl-C" in served.line
    status, body = served.get("/")
    assert status == 200 and b"<canvas" in body
    status, body = served.get("/api/take.json")
    assert status == 200 and b'"frames": [0, 1]' in body
    status, body = served.get("/api/frame/1.bin")
    assert status == 200 and body[:4] == b"RGFS" and len(body) > 9 * 160 * 90 * 8
    for shader in ("splat.vert", "shade.frag", "fill.frag", "scan.frag"):
        status, body = served.get(f"/static/shaders/{shader}.glsl")
        assert status == 200 and body.startswith(b"#version 300 es"), shader


@pytest.mark.parametrize(
    "path",
    [
        "/../secret.txt", "/static/../../secret.txt", "/static/../t/take.yaml", "/%2e%2e/secret.txt",
        "/static/%2e%2e/%2e%2e/secret.txt", "/static/..%2f..%2fsecret.txt", "/static/%252e%252e/secret.txt",
        "/%2E%2E%2F%2E%2E%2Fetc%2Fpasswd", "/static/shaders/..%5c..%5cserver.py", "//etc/passwd",
        "/take.yaml", "/t/take.yaml", "/truth/disparity/000000/r1c1.pfm", "/static/../server.py",
        "/static/viewer.js%00.html", "/api/frame/2.bin", "/api/frame/-1.bin", "/api/frame/..%2f1.bin",
        "/api/result", "/static/", "/static/shaders",
    ],
)  # fmt: skip
def test_nothing_outside_the_page_and_the_take_is_served(served: Served, path: str) -> None:
    status, body = served.get(path)
    assert status in (400, 404), (path, status)
    assert b"not for the network" not in body and b"spec:" not in body and b"import" not in body


@pytest.mark.parametrize(
    "number",
    ["01", "001", "00", "%2B1", "+1", "%201", "1%20", "1_0", "0_1", "%D9%A1", "%EF%BC%91", "%E0%A5%A7", "1.0", "0x1"],
)
def test_a_frame_set_is_served_under_its_canonical_number_only(served: Served, number: str) -> None:
    """A hostile-user review: int() took "01", "١" (Arabic-Indic one) and "１" (full-width) as frame set 1, so
    one frame set had many URLs; only the decimal number as take.json lists it is served, anything else 404."""
    status, body = served.get(f"/api/frame/{number}.bin")
    assert status == 404 and body[:4] != b"RGFS", (number, status)
    assert served.get("/api/frame/0.bin")[0] == 200 and served.get("/api/frame/1.bin")[0] == 200


@pytest.mark.parametrize(
    ("host", "status"),
    [("evil.example", 403), ("evil.example:80", 403), ("10.0.0.7", 403), ("localhost", 200),
     ("127.0.0.1:1", 200), ("[::1]:8080", 200), ("LOCALHOST", 200)],
)  # fmt: skip
def test_a_request_naming_another_host_is_refused_on_loopback(served: Served, host: str, status: int) -> None:
    """DNS rebinding (a hostile-user review): a page whose name resolves to 127.0.0.1 would read the take
    through the user's browser; on loopback the viewer answers only to loopback names."""
    for path in ("/api/take.json", "/api/frame/0.bin", "/"):
        conn = http.client.HTTPConnection(served.host, served.port, timeout=30)
        try:
            conn.putrequest("GET", path, skip_host=True, skip_accept_encoding=True)
            conn.putheader("Host", host)
            conn.endheaders()
            res = conn.getresponse()
            body = res.read()
        finally:
            conn.close()
        assert res.status == status, (host, path, res.status)
        assert status == 200 or (b"frames" not in body and b"RGFS" not in body)


def test_results_are_not_accepted_by_rigctl_view(served: Served) -> None:
    assert served.get("/api/result?tag=x", "POST")[0] == 404


def test_ctrl_c_stops_it_cleanly(take: Path) -> None:
    s = serve(take, "--port", "0")
    assert s.get("/")[0] == 200
    s.proc.send_signal(signal.SIGINT)
    _out, err = s.proc.communicate(timeout=30)
    assert s.proc.returncode == 0, err
    assert err.strip().splitlines()[-1] == "rigctl view: stopped" and "Traceback" not in err, err
    with socket.socket() as again:  # the port is free again
        again.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        again.bind(("127.0.0.1", s.port))


def test_an_explicit_address_is_used_and_warned_about(take: Path) -> None:
    s = serve(take, "--bind", "0.0.0.0")
    try:
        assert s.host == "0.0.0.0"
        assert s.get("/")[0] == 200
    finally:
        s.proc.send_signal(signal.SIGINT)
        _out, err = s.proc.communicate(timeout=30)
    assert "anyone who can reach this machine" in err


def one_line(res: subprocess.CompletedProcess[str], *words: str) -> None:
    assert res.returncode != 0
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and all(w in lines[0] for w in words), lines


def test_bad_input_is_one_line(take: Path, tmp_path: Path) -> None:
    truth = str(take / "truth" / "disparity")
    one_line(run_rigctl("view", str(tmp_path / "nope"), "--disparity", truth), "nope", "does not exist")
    one_line(run_rigctl("view", str(tmp_path), "--disparity", truth), "not a take")
    one_line(run_rigctl("view", str(take), "--disparity", str(tmp_path / "none")), "disparity folder does not exist")
    one_line(run_rigctl("view", str(take), "--disparity", truth, "--bind", "example.com"), "IP address")
    one_line(run_rigctl("view", str(take), "--disparity", truth, "--port", "70000"), "port")
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        one_line(run_rigctl("view", str(take), "--disparity", truth, "--port", str(port)), "cannot listen", str(port))


def test_a_rerun_on_the_same_port_starts_while_the_last_ones_connections_close(take: Path) -> None:
    """Ctrl-C with a browser connected leaves the port's connections in TIME_WAIT for a minute; the README's
    fixed --port must serve again at once (a hostile-user review: it said "cannot listen ... in use")."""
    first = serve(take)
    conn = http.client.HTTPConnection(first.host, first.port, timeout=30)
    conn.request("GET", "/")
    assert conn.getresponse().read()  # kept alive: the server's side closes first, at exit
    first.proc.send_signal(signal.SIGINT)
    first.proc.communicate(timeout=30)
    conn.close()
    again = serve(take, "--port", str(first.port))
    try:
        assert again.port == first.port and again.get("/")[0] == 200
    finally:
        again.proc.send_signal(signal.SIGINT)
        again.proc.communicate(timeout=30)


def test_a_second_viewer_on_a_port_in_use_is_refused(served: Served, take: Path) -> None:
    truth = str(take / "truth" / "disparity")
    one_line(run_rigctl("view", str(take), "--disparity", truth, "--port", str(served.port)), "cannot listen")
    assert served.get("/")[0] == 200


def test_a_damaged_frame_set_is_a_500_and_one_line_naming_its_file(take: Path, tmp_path: Path) -> None:
    """A truncated disparity of one frame set (a hostile-user review: the connection was dropped with no
    response and nothing on the terminal); the other frame sets are still served."""
    copy = tmp_path / "t"
    shutil.copytree(take, copy)
    bad = copy / "truth" / "disparity" / "000001" / "r1c1.pfm"
    bad.write_bytes(bad.read_bytes()[:100])
    s = serve(copy)
    try:
        status, body = s.get("/api/frame/1.bin")
        assert status == 500 and b"frame set 1" in body and b"RGFS" not in body
        status, body = s.get("/api/frame/0.bin")
        assert status == 200 and body[:4] == b"RGFS"
    finally:
        s.proc.send_signal(signal.SIGINT)
        _out, err = s.proc.communicate(timeout=30)
    lines = err.strip().splitlines()
    assert lines[-1] == "rigctl view: stopped" and "Traceback" not in err, err
    assert len(lines) == 2 and str(bad) in lines[0] and "byte" in lines[0], lines


@pytest.mark.parametrize("length", ["abc", "-5", "1e3", "99999999999999999999999", ""])
def test_a_post_with_a_bad_length_is_a_404_and_the_server_goes_on(served: Served, length: str) -> None:
    """A Content-Length that is not a number (a hostile-user review: the connection was dropped unanswered)."""
    with socket.create_connection((served.host, served.port), timeout=30) as s:
        s.sendall(f"POST /api/result?tag=x HTTP/1.1\r\nHost: localhost\r\nContent-Length: {length}\r\n\r\n".encode())
        answer = s.makefile("rb").readline()
    assert answer.startswith(b"HTTP/1.1 404"), (length, answer)
    assert served.get("/")[0] == 200


@pytest.fixture(scope="module")
def full(module_tmp: Callable[[str], Path]) -> Path:
    """Four frame sets at the simulated rig's own 960x540: a bundle takes about half a second to make."""
    out = module_tmp("view-full")
    res = run_rigctl(
        "record", "sim-3x3", "--take", "t", "--frames", "4", "--out", str(out),
        "--sim", "ideal=true", "--sim", "motion=false", "--sim", "deterministic=true", "--force",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    return out / "t"


@pytest.fixture
def quick(full: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[ViewerServer]:
    """The viewer's server dropping a client silent for 1 s (30 s in use), on bundles of 37 MB: larger than
    the sockets' buffers."""
    monkeypatch.setattr(server_module, "IDLE_S", 1.0, raising=False)
    bundles = Bundles(full, full / "truth" / "disparity")
    srv = ViewerServer(bundles)
    srv.start()
    yield srv
    srv.shutdown()
    srv.server_close()
    bundles.close()  # its thread and the take's open files end here, not with the test process


def test_a_silent_or_vanished_client_is_dropped(quick: ViewerServer) -> None:
    """A hostile-user review: a client that sent half a request, or asked for a frame set and read none of
    it, held its connection and a thread for ever (idle connections exhaust the descriptors: the viewer then
    accepts no one)."""
    host, port = quick.server_address[:2]
    with socket.create_connection((str(host), port), timeout=10) as silent:
        silent.sendall(b"GET / HTTP/1.1\r\n")
        assert silent.recv(1 << 16) == b""  # closed by the server well before our 10 s
    with socket.socket() as stalled:
        stalled.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        stalled.settimeout(30)
        stalled.connect((str(host), port))
        stalled.sendall(b"GET /api/frame/0.bin HTTP/1.1\r\nHost: localhost\r\n\r\n")
        time.sleep(4)
        got = b""
        while chunk := stalled.recv(1 << 20):
            got += chunk
        head, _, body = got.partition(b"\r\n\r\n")
        length = int(head.split(b"Content-Length: ")[1].split(b"\r\n")[0])
        assert b"200 OK" in head and 0 < len(body) < length  # cut off, not waited for
    conn = http.client.HTTPConnection(str(host), port, timeout=30)
    conn.request("GET", "/api/take.json")
    assert conn.getresponse().status == 200


def test_a_slow_but_steady_reader_gets_the_whole_frame_set(quick: ViewerServer) -> None:
    host, port = quick.server_address[:2]
    with socket.socket() as slow:
        slow.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 16)
        slow.settimeout(30)
        slow.connect((str(host), port))
        slow.sendall(b"GET /api/frame/0.bin HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\n\r\n")
        got, start = b"", time.monotonic()
        while chunk := slow.recv(1 << 16):
            got += chunk
            time.sleep(0.005)
        head, _, body = got.partition(b"\r\n\r\n")
    length = int(head.split(b"Content-Length: ")[1].split(b"\r\n")[0])
    assert len(body) == length and body[:4] == b"RGFS"
    assert time.monotonic() - start > 1.0  # longer in all than the server waits for one write


def test_a_grid_whose_spacings_put_cameras_at_infinity_is_one_line(tmp_path: Path) -> None:
    """grid.yaml with spacing_y / spacing_x beyond a float (a hostile-user review: take.json said Infinity,
    which no JSON reader takes, and the page never started). The grid folder's reader now refuses such
    spacings itself, naming the field; the viewer's own check of take.json's numbers stays behind it."""
    from rigctl.depth.scenes import SCENES, write_grid_folder

    grid = write_grid_folder(SCENES["surfaces"]((32, 32)), tmp_path / "grid")
    for png in set(grid.glob("r*c*.png")) - {grid / "r1c1.png"}:  # the scene's truth is r1c1's only: every camera's
        shutil.copyfile(grid / "truth" / "r1c1.pfm", grid / "truth" / f"{png.stem}.pfm")
    (grid / "grid.yaml").write_text("spacing_x: 1.0e-300\nspacing_y: 1.0e+300\nfocal_px: 100\n")
    res = run_rigctl("view", str(grid), "--disparity", str(grid / "truth"), "--port", "0", timeout=60)
    one_line(res, str(grid / "grid.yaml"), "spacing_x")


@pytest.mark.parametrize("bind", ["::ffff:127.0.0.1", "127.0.0.2"])
def test_every_loopback_address_refuses_other_hosts_names_and_is_not_warned_about(take: Path, bind: str) -> None:
    """A hostile-user review: --bind ::ffff:127.0.0.1 (127.0.0.1 written as IPv6) answered a page of any
    name (DNS rebinding) and, like 127.0.0.2, was warned about as open to the network."""
    s = serve(take, "--bind", bind)
    try:
        conn = http.client.HTTPConnection(s.host, s.port, timeout=30)
        conn.putrequest("GET", "/api/take.json", skip_host=True, skip_accept_encoding=True)
        conn.putheader("Host", f"evil.example:{s.port}")
        conn.endheaders()
        assert conn.getresponse().status == 403
        conn.close()
    finally:
        s.proc.send_signal(signal.SIGINT)
        _out, err = s.proc.communicate(timeout=30)
    assert "anyone who can reach" not in err, err


def test_ctrl_c_twice_while_frame_sets_are_made_ahead_stops_without_a_traceback(full: Path) -> None:
    """A hostile-user review: Ctrl-C waited for the bundle being made ahead, and a second Ctrl-C meanwhile
    printed a traceback of the interpreter's exit."""
    s = serve(full)
    assert s.get("/api/frame/0.bin")[0] == 200  # frame sets 1-3 are now being made ahead
    s.proc.send_signal(signal.SIGINT)
    time.sleep(0.3)
    if s.proc.poll() is None:
        s.proc.send_signal(signal.SIGINT)
    _out, err = s.proc.communicate(timeout=30)
    assert "Traceback" not in err, err
    assert s.proc.returncode == 0 and err.strip().splitlines()[-1] == "rigctl view: stopped", err


def test_the_bundles_kept_fit_in_a_memory_budget(full: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A hostile-user review: 16 bundles were kept and 8 made ahead whatever their size: at the paper's UHD
    rig 600 MB each, 5 GB after the first request and 9.5 GB in all."""
    monkeypatch.setattr(bundle_module, "MEMORY", 3 * 9 * 960 * 540 * 8, raising=False)  # three bundles
    bundles = Bundles(full, full / "truth" / "disparity")
    try:
        assert bundles.get(0)[:4] == b"RGFS"
        time.sleep(3)  # what is made ahead is made
        assert len(bundles.made.kept()) <= 3
        assert bundles.get(1)[:4] == b"RGFS" and bundles.get(3)[:4] == b"RGFS"
        assert len(bundles.made.kept()) <= 3
    finally:
        bundles.close()
