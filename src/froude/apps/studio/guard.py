"""Who may talk to the studio: only its own page (an Origin and Host check, the way Jupyter does).

A web page on another site can open a websocket to ``127.0.0.1`` (browsers do not apply the same-origin
policy to websockets); it sends its own ``Origin``. And a page served from a name the attacker controls that
resolves to 127.0.0.1 (DNS rebinding) has a matching Origin but a foreign ``Host``. So a handshake is
accepted only when its Host names this machine's loopback or the address the studio is bound to, and its
Origin, when a browser sent one, is that same host and port. Clients without an Origin are not browsers
(a local script can read the files itself) and are accepted on an allowed Host.
"""
from __future__ import annotations

import ipaddress
import logging
import socket
from urllib.parse import urlsplit

LOOPBACK_NAMES = ("localhost", "127.0.0.1", "::1")


def is_loopback(host: str) -> bool:
    """True when binding to ``host`` keeps the studio on this machine."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def reachable_addresses(host: str) -> list[str]:
    """The addresses a browser can use for a server bound to ``host`` (the wildcard → this machine's
    network addresses, loopback last)."""
    if host not in ("0.0.0.0", "::", ""):
        return [host]
    found: list[str] = []
    try:
        for info in socket.getaddrinfo(socket.gethostname(), None, socket.AF_INET):
            found.append(str(info[4][0]))
    except OSError:
        pass
    found.append("127.0.0.1")
    seen = []
    for a in found:
        if a not in seen and not (a.startswith("127.") and a != "127.0.0.1"):
            seen.append(a)
    return seen


def allowed_hosts(bound: str) -> frozenset[str]:
    """Host names (no port) a handshake may name: loopback, plus the bound address and this machine's
    names and addresses when bound beyond loopback."""
    names = set(LOOPBACK_NAMES)
    if not is_loopback(bound):
        names.update(reachable_addresses(bound))
        try:
            names.update({socket.gethostname(), socket.getfqdn()})
        except OSError:
            pass
    return frozenset(n.lower() for n in names if n)


def _split_host(hostport: str) -> tuple[str, int | None]:
    """'[::1]:8080' / 'a.b:80' / 'a.b' -> (host lowercased without brackets, port or None)."""
    u = urlsplit("//" + hostport.strip())
    try:
        port = u.port
    except ValueError:
        port = -1
    return (u.hostname or "").lower(), port


def handshake_refusal(host_header: str | None, origin: str | None, hosts: frozenset[str], port: int) -> str | None:
    """Why a websocket handshake must be refused (None: accept).

    host_header: the request's Host; origin: its Origin (None when absent); hosts: ``allowed_hosts``;
    port: the studio's port.
    """
    if not host_header:
        return "no Host header"
    host, hport = _split_host(host_header)
    if host not in hosts or hport not in (None, port):
        return f"Host {host_header[:80]!r} is not this studio"
    if origin is None:
        return None
    u = urlsplit(origin.strip())
    try:
        oport = u.port or {"http": 80, "https": 443}.get(u.scheme)
    except ValueError:
        oport = None
    if u.scheme not in ("http", "https") or (u.hostname or "").lower() not in hosts or oport != port:
        return f"Origin {origin[:80]!r} is not this studio's page"
    return None


class QuietSpareSockets(logging.Filter):
    """Drops websockets' "opening handshake failed" record (logged with a traceback) when the connection
    closed before it sent its HTTP request line: a browser's spare preconnected socket, or a port probe.
    Nothing went wrong, and a traceback on a running studio's terminal says otherwise (viser filters the
    message too, but only from the first request it serves on). Other handshake failures are kept."""

    def filter(self, record: logging.LogRecord) -> bool:
        exc = record.exc_info[1] if record.exc_info else None
        return not (record.getMessage() == "opening handshake failed" and isinstance(exc, EOFError))


def install(server, port_of, bound: str, on_refused=None) -> set:
    """Refuse foreign handshakes on a viser server before it hears or sends anything.

    The check runs first among the websocket server's connect callbacks, before the connection's message
    loops start, and closes refused connections with 1008 (policy violation); viser registers a client
    (and calls the studio's connect handler) only after its first camera message, so a refused one never
    gets a session. port_of: () -> the bound port. Returns the set of refused client ids.
    """
    log = logging.getLogger("websockets.server")
    if not any(isinstance(f, QuietSpareSockets) for f in log.filters):
        log.addFilter(QuietSpareSockets())
    ws = server._websock_server  # viser has no public hook for the handshake; this is its connection list
    hosts = allowed_hosts(bound)
    refused: set = set()

    async def check(conn) -> None:
        raw = ws._live_connections.get(conn.client_id)
        if raw is None:
            return
        headers = raw.request.headers
        host, origin = headers.get_all("Host"), headers.get_all("Origin")
        why: str | None = None
        if len(host) != 1 or len(origin) > 1:
            why = "repeated Host or Origin headers"
        else:
            why = handshake_refusal(host[0], origin[0] if origin else None, hosts, port_of())
        if why is not None:
            refused.add(conn.client_id)
            if on_refused is not None:
                on_refused(why)
            await raw.close(1008, f"froude studio: refused: {why}"[:120])

    ws._client_connect_cb.insert(0, check)
    return refused
