"""The studio talks only to its own page and trusts no control value (issue 18, points 7-8, acceptance 3).

A websocket client speaking viser's protocol stands in for a hostile page: a foreign Origin (or a
DNS-rebinding Host) is refused at the handshake; crafted control values (a file path as the Character,
Strides 3000, Steps 100000) are refused with a message, nothing is computed, no file is read, and the
session keeps its last good result.
"""
from __future__ import annotations

import socket
import sys
import time

import msgspec
import pytest

from froude.apps.studio.guard import allowed_hosts, handshake_refusal, is_loopback
from froude.apps.studio.session import LIMITS, Params
from froude.errors import FroudeError
from froude.flow import pipeline
from froude.io.samples import sample_path

viser = pytest.importorskip("viser")
zstandard = pytest.importorskip("zstandard")
ws_client = pytest.importorskip("websockets.sync.client")


# ---- the handshake rule (pure) ---------------------------------------------------------------------
def test_handshake_rule_accepts_only_the_studios_own_page():
    hosts = allowed_hosts("127.0.0.1")
    ok = [("127.0.0.1:8080", "http://127.0.0.1:8080"), ("localhost:8080", "http://localhost:8080"),
          ("127.0.0.1:8080", None), ("[::1]:8080", "http://[::1]:8080")]
    for host, origin in ok:
        assert handshake_refusal(host, origin, hosts, 8080) is None, (host, origin)
    bad = [("127.0.0.1:8080", "http://evil.example"),  # another site's page
           ("127.0.0.1:8080", "http://127.0.0.1:9999"),  # another local server's page
           ("127.0.0.1:8080", "null"),  # a sandboxed iframe or a file:// page
           ("evil.example:8080", "http://evil.example:8080"),  # DNS rebinding: same-origin but foreign Host
           ("127.0.0.1:9999", None), (None, None), ("", "http://127.0.0.1:8080")]
    for host, origin in bad:
        assert handshake_refusal(host, origin, hosts, 8080) is not None, (host, origin)


def test_loopback_and_beyond():
    assert is_loopback("127.0.0.1") and is_loopback("localhost") and is_loopback("::1")
    assert not is_loopback("0.0.0.0") and not is_loopback("192.168.1.5")
    assert allowed_hosts("127.0.0.1") == frozenset({"127.0.0.1", "localhost", "::1"})
    assert "127.0.0.1" in allowed_hosts("0.0.0.0")


def test_params_are_checked_against_the_controls_limits_and_options():
    presets = ("same", "child", "giant")
    assert Params(strides=12, steps=60).check(presets).strides == 12
    for bad, words in [(Params(strides=3000), "Strides 3000 is outside 1 to 12"),
                       (Params(steps=100000), "Steps 100000 is outside 1 to 60"),
                       (Params(strides=2.5), "Strides must be a whole number"),
                       (Params(speed=float("nan")), "Speed nan× is outside"),
                       (Params(height=0.0), "Height 0 m is outside 0.5 m to 4 m"),
                       (Params(character="/etc/passwd"), "Character must be one of the presets"),
                       (Params(mode="rm -rf"), "Mode must be scale or accelerate")]:
        with pytest.raises(FroudeError, match=words):
            bad.check(presets)
    assert set(LIMITS) == {"height", "mass", "leg_scale", "speed", "strides", "to_factor", "steps"}


# ---- a live studio and a websocket client ------------------------------------------------------------
def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def studio():
    from froude.apps.studio.app import Studio

    st = Studio(pipeline.prepare(sample_path()), port=_free_port()).start()
    yield st
    st.stop()


class _Client:
    """A websocket client speaking viser's protocol, decoding what it receives."""

    def __init__(self, port: int, origin: str | None = None, host: str | None = None):
        # host: the name in the URL (and so the Host header); the socket always goes to 127.0.0.1, as a
        # DNS-rebound name would
        sock = socket.create_connection(("127.0.0.1", port), timeout=10)
        self.ws = ws_client.connect(f"ws://{host or '127.0.0.1'}:{port}", sock=sock, origin=origin,
                                    subprotocols=[f"viser-v{viser.__version__}"], max_size=None, open_timeout=10)
        self.unzip = zstandard.ZstdDecompressor()
        self.received: list[bytes] = []

    def send(self, msg_type: str, **fields) -> None:
        self.ws.send(msgspec.msgpack.encode({"type": msg_type, **fields}))

    def hello(self) -> None:
        """What a page sends first (viser registers a client at its first camera message)."""
        self.send("ViewerCameraMessage", wxyz=(1.0, 0.0, 0.0, 0.0), position=(0.0, 1.0, 4.0), fov=1.0, near=0.01,
                  far=100.0, image_height=600, image_width=800, look_at=(0.0, 1.0, 0.0), up_direction=(0.0, 1.0, 0.0))

    def drain(self, seconds: float) -> None:
        t_end = time.monotonic() + seconds
        while time.monotonic() < t_end:
            try:
                msg = self.ws.recv(timeout=max(0.01, t_end - time.monotonic()))
            except TimeoutError:
                return
            size, packed = int.from_bytes(msg[:8], "little"), int.from_bytes(msg[8:16], "little")
            self.received.append(self.unzip.decompress(msg[16:16 + packed], max_output_size=size))

    def close(self) -> None:
        self.ws.close()


def _refused(port: int, **kw) -> tuple[int | None, str]:
    """Connect and read until closed: (close code, reason). (None, '') if the server kept talking."""
    from websockets.exceptions import ConnectionClosed

    c = _Client(port, **kw)
    try:
        c.hello()
        for _ in range(200):
            c.ws.recv(timeout=5)
    except ConnectionClosed as e:
        return (e.rcvd.code if e.rcvd else None), (e.rcvd.reason if e.rcvd else "")
    except TimeoutError:
        pass
    finally:
        c.close()
    return None, ""


def test_foreign_origins_are_refused_own_page_accepted(studio):
    port = studio.server.get_port()
    code, reason = _refused(port, origin="http://evil.example")
    assert code == 1008 and "Origin" in reason
    code, reason = _refused(port, origin=f"http://evil.example:{port}", host="evil.example")
    assert code == 1008 and "Host" in reason
    # the page itself (same origin) and a script without an Origin get the scene
    for origin in (f"http://127.0.0.1:{port}", None):
        c = _Client(port, origin=origin)
        try:
            c.hello()
            c.drain(1.5)
            assert any(b"state:" in m for m in c.received)
        finally:
            c.close()


def test_a_socket_closed_before_its_request_prints_no_traceback(studio):
    """A browser's spare socket (or a port probe) closed before it sent a request is not an error; other
    handshake failures are still logged."""
    import logging

    from froude.apps.studio.guard import QuietSpareSockets

    log = logging.getLogger("websockets.server")
    assert any(isinstance(f, QuietSpareSockets) for f in log.filters)  # the studio put it there

    def record(exc):
        try:
            raise exc
        except Exception:
            return log.makeRecord(log.name, logging.ERROR, __file__, 0, "opening handshake failed", (),
                                  sys.exc_info())

    quiet = QuietSpareSockets()
    assert not quiet.filter(record(EOFError("connection closed while reading HTTP request line")))
    assert quiet.filter(record(ValueError("invalid HTTP request line: x")))


def _wait(cond, timeout=10.0) -> bool:
    t_end = time.monotonic() + timeout
    while time.monotonic() < t_end:
        if cond():
            return True
        time.sleep(0.05)
    return False


def test_crafted_control_values_are_refused_and_the_result_stays(studio, tmp_path):
    secret = tmp_path / "secret.yaml"
    secret.write_text("api_token: SECRET-TOKEN-123\ndb_password: hunter2\n")
    c = _Client(studio.server.get_port())
    try:
        c.hello()
        c.drain(1.0)
        tab = max(studio.wait_for_tabs(1), key=lambda t: t.client.client_id)  # this connection's own session
        good = tab.good
        crafted = [(tab.gui_char, str(secret), "Character must be one of the presets"),
                   (tab.gui_char, str(tmp_path / "missing.yaml"), "Character must be one of the presets"),
                   (tab.gui_strides, 3000, "Strides 3000 is outside 1 to 12"),
                   (tab.gui_steps, 100000, "Steps 100000 is outside 1 to 60"),
                   (tab.gui_speed, 1e9, "Speed 1e+09× is outside"),
                   (tab.gui_camera, "/etc/passwd", "Camera must be one of side"),
                   (tab.gui_rate, float("nan"), "Playback speed nan× is outside"),
                   (tab.gui_time, -5.0, "Time -5 s is outside"),
                   (tab.gui_bvh_units, "/etc/passwd", None)]
        for handle, value, words in crafted:
            t0 = time.perf_counter()
            c.send("GuiUpdateMessage", uuid=handle._impl.uuid, updates={"value": value})
            if words is None:  # an export option: checked when the download is asked for (its own test)
                continue
            assert _wait(lambda words=words: words in tab.message), (value, tab.message)
            assert time.perf_counter() - t0 < 5.0  # refused at once, nothing computed
            assert tab.good is good and tab.shown is good
            c.drain(0.5)
            assert handle.value != value  # the control is put back to the last good value
        c.drain(1.0)
        everything = b"".join(c.received) + tab.message.encode()
        assert b"SECRET-TOKEN" not in everything and b"api_token" not in everything and b"hunter2" not in everything
        assert b"Strides 3000 is outside 1 to 12" in everything  # the message reached the page
        # a legitimate change still works after all that
        c.send("GuiUpdateMessage", uuid=tab.gui_speed._impl.uuid, updates={"value": 1.2})
        assert _wait(lambda: tab.good is not good and tab.good.params.speed == 1.2, timeout=30)
    finally:
        c.close()


def test_view_refuses_out_of_range_start_values(capsys):
    from froude.apps.cli import main as cli_main
    from froude.apps.cli.view import VIEW_SPEED_RANGE, VIEW_STRIDES

    assert VIEW_SPEED_RANGE == (LIMITS["speed"].lo, LIMITS["speed"].hi)  # the CLI's ranges are the page's
    assert VIEW_STRIDES == (LIMITS["strides"].lo, LIMITS["strides"].hi)
    with pytest.raises(SystemExit) as e:
        cli_main(["view", "--strides", "3000", "--port", "0"])
    assert e.value.code == 2
    assert cli_main(["view", "--character", "/etc/passwd", "--port", "0"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and "strides" in err[0] and "3000" in err[0] and "unknown character" in err[1]


def test_view_beyond_loopback_warns_and_prints_real_addresses():
    import re
    import signal
    import subprocess
    import sys

    port = _free_port()
    proc = subprocess.Popen([sys.executable, "-m", "froude", "view", "--host", "0.0.0.0", "--port", str(port)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        lines = []
        t_end = time.monotonic() + 60
        while time.monotonic() < t_end:
            line = proc.stdout.readline()
            if not line:
                break
            lines.append(line)
            if "froude studio: http" in line:
                break
        urls = re.findall(r"froude studio: (?:also )?(http://\S+)", "".join(lines))
        assert urls, lines
        assert not any("localhost" in u or "0.0.0.0" in u for u in urls)
        assert urls[0].endswith(f":{port}")
    finally:
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=20)
    assert "WARNING: --host 0.0.0.0 makes the studio reachable from other machines" in err
    assert proc.returncode == 0 and "Traceback" not in err
