"""The live view's public port: a loopback TCP relay in front of the Foxglove SDK's WebSocket
server that also admits clients speaking the protocol's older name.

foxglove-sdk (0.30, the newest release) accepts only the subprotocol `foxglove.sdk.v1` and
answers HTTP 400 to `foxglove.websocket.v1`, which older Foxglove apps and Lichtblick
offer. The two name one protocol (same messages, same opcodes; Foxglove renamed it), so
nothing but the name in the handshake differs. The relay reads the client's HTTP upgrade
request, and when it offers only `foxglove.websocket.v1` it forwards it to the SDK as
`foxglove.sdk.v1` and names `foxglove.websocket.v1` again in the SDK's 101 answer (the
Sec-WebSocket-Accept key depends on the client's key alone, so it stays valid). After the
handshake it copies bytes both ways untouched: the SDK still does all of the protocol,
and a slow client still pushes back on it through the sockets. A request that offers
neither name gets a 400 saying which names are spoken, and one warning.
"""

from __future__ import annotations

import contextlib
import re
import socket
import threading

SDK_SUBPROTOCOL = "foxglove.sdk.v1"
LEGACY_SUBPROTOCOL = "foxglove.websocket.v1"
SUBPROTOCOLS = (SDK_SUBPROTOCOL, LEGACY_SUBPROTOCOL)
MAX_HEAD = 64 * 1024  # an HTTP upgrade request is a few hundred bytes
HANDSHAKE_TIMEOUT = 10.0  # seconds a client (or the SDK) may take to send its handshake
_PROTOCOL_HEADER = re.compile(rb"^sec-websocket-protocol:(.*)$", re.IGNORECASE | re.MULTILINE)


def offered_subprotocols(head: bytes) -> list[str]:
    """The subprotocols an HTTP upgrade request offers, in its order (all its headers)."""
    return [p.strip() for m in _PROTOCOL_HEADER.finditer(head) for p in m.group(1).decode("latin-1").split(",") if p.strip()]


def rename_subprotocol(head: bytes, name: str) -> bytes:
    """head with every Sec-WebSocket-Protocol header replaced by one naming `name` only."""
    lines = [line for line in head.split(b"\r\n") if not line.lower().startswith(b"sec-websocket-protocol:")]
    end = lines.index(b"")  # the blank line that ends the header block
    lines.insert(end, b"Sec-WebSocket-Protocol: " + name.encode())
    return b"\r\n".join(lines)


def _read_head(sock: socket.socket) -> tuple[bytes, bytes]:
    """(HTTP head up to and including the blank line, bytes read past it)."""
    data = b""
    while b"\r\n\r\n" not in data:
        if len(data) > MAX_HEAD:
            raise ConnectionError("HTTP head too long")
        chunk = sock.recv(4096)
        if not chunk:
            raise ConnectionError("closed during the handshake")
        data += chunk
    end = data.index(b"\r\n\r\n") + 4
    return data[:end], data[end:]


def _pump(src: socket.socket, dst: socket.socket) -> None:
    """Copy src to dst until either side closes; then close both (the other pump ends too)."""
    try:
        while chunk := src.recv(65536):
            dst.sendall(chunk)
    except OSError:
        pass
    finally:
        for s in (src, dst):
            with contextlib.suppress(OSError):
                s.shutdown(socket.SHUT_RDWR)


class SubprotocolBridge:
    """Listens on host:port (0: a free port) and relays each connection to the SDK server
    on 127.0.0.1:target_port. warn(text) is told of refused clients (the caller
    deduplicates)."""

    def __init__(self, host: str, port: int, target_port: int, warn=print):
        self.target_port = target_port
        self._warn = warn
        self._closed = threading.Event()
        self._sockets: set[socket.socket] = set()
        self._lock = threading.Lock()
        self._listener = socket.create_server((host, port))  # OSError: busy port, unknown host
        self._listener.settimeout(0.2)  # accept() wakes up to see close(): closing alone may not wake it
        self.port = self._listener.getsockname()[1]
        self._thread = threading.Thread(target=self._accept, name="zfloc-live-bridge", daemon=True)
        self._thread.start()

    def _track(self, *socks: socket.socket) -> None:
        with self._lock:
            self._sockets.update(socks)

    def _forget(self, *socks: socket.socket) -> None:
        with self._lock:
            self._sockets.difference_update(socks)
        for s in socks:
            with contextlib.suppress(OSError):
                s.close()

    def _accept(self) -> None:
        while not self._closed.is_set():
            try:
                client, _ = self._listener.accept()
            except TimeoutError:
                continue
            except OSError:  # the listener was closed
                return
            self._track(client)
            threading.Thread(target=self._serve, args=(client,), name="zfloc-live-client", daemon=True).start()

    def _serve(self, client: socket.socket) -> None:
        upstream = None
        try:
            client.settimeout(HANDSHAKE_TIMEOUT)
            head, rest = _read_head(client)
            offered = offered_subprotocols(head)
            if SDK_SUBPROTOCOL in offered:
                rename = None  # the SDK's own name: nothing to translate
            elif LEGACY_SUBPROTOCOL in offered:
                rename = LEGACY_SUBPROTOCOL
                head = rename_subprotocol(head, SDK_SUBPROTOCOL)
            else:
                self._refuse(client, offered)
                return
            upstream = socket.create_connection(("127.0.0.1", self.target_port), timeout=HANDSHAKE_TIMEOUT)
            self._track(upstream)
            upstream.sendall(head + rest)
            answer, extra = _read_head(upstream)
            if rename is not None and offered_subprotocols(answer) == [SDK_SUBPROTOCOL]:
                answer = rename_subprotocol(answer, rename)
            client.sendall(answer + extra)
            client.settimeout(None)
            upstream.settimeout(None)
        except OSError:  # the client left, or the SDK server stopped, during the handshake
            self._forget(*(s for s in (client, upstream) if s is not None))
            return
        back = threading.Thread(target=_pump, args=(upstream, client), name="zfloc-live-pump", daemon=True)
        back.start()
        _pump(client, upstream)
        back.join()
        self._forget(client, upstream)

    def _refuse(self, client: socket.socket, offered: list[str]) -> None:
        what = f"offered {', '.join(offered)}" if offered else "offered no WebSocket subprotocol"
        body = f"Foxglove WebSocket server: subprotocol {SDK_SUBPROTOCOL} or {LEGACY_SUBPROTOCOL} expected\n".encode()
        with contextlib.suppress(OSError):
            client.sendall(b"HTTP/1.1 400 Bad Request\r\nContent-Type: text/plain\r\nConnection: close\r\n"
                           b"Content-Length: %d\r\n\r\n%s" % (len(body), body))
        self._forget(client)
        self._warn(f"live view: refused a client that {what} (spoken: {SDK_SUBPROTOCOL}, {LEGACY_SUBPROTOCOL})")

    def close(self) -> None:
        """Stop listening and cut every relayed connection."""
        self._closed.set()
        with contextlib.suppress(OSError):
            self._listener.close()
        with self._lock:
            socks, self._sockets = list(self._sockets), set()
        for s in socks:
            with contextlib.suppress(OSError):
                s.shutdown(socket.SHUT_RDWR)
            with contextlib.suppress(OSError):
                s.close()
        self._thread.join(5)
