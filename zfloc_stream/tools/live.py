"""Live view: the session log's messages served to Foxglove while the run goes on
(`zfloc-stream run --live [PORT]`, `demo --live`), through the Foxglove SDK's WebSocket
server (`foxglove-sdk`, the [live] extra).

The server is fed the very records the SessionWriter writes (its `listeners` hook): same
topics, schemas and bytes as session.mcap, no second serialization. Channels live in a
context of their own, so nothing else logged through the SDK leaks in. The floorplan is
published once, with the first frame; a client that subscribes later gets it (and the
latest BEV) again at once, so opening Foxglove mid-run, or after it (`linger`), still
shows the map.

Clients reach the SDK through live_bridge's relay, which also admits the protocol's older
name (`foxglove.websocket.v1`, older Foxglove and Lichtblick). What the SDK logs (through
Python's logging, logger `foxglove`) becomes one `warning:` line per kind of message
instead of a raw line per event.
"""

from __future__ import annotations

import logging
import re
import threading
import time

from ..errors import InputError
from .cli_support import print_warning

LATCHED = ("/zfloc/floorplan", "/zfloc/bev", "/tf")  # topics a late subscriber gets the last message of
DEFAULT_PORT = 8765
POLL = 0.1  # seconds between looks for late subscribers while lingering
MAX_READVERTISE = 3  # times a channel is advertised anew after refused subscriptions


_UNKNOWN_CHANNEL = re.compile(r"subscribe to unknown channel: (\d+)")


class _OncePerKind(logging.Handler):
    """The SDK's log records as warn() lines, each kind once: records that differ only in
    numbers (client ports, channel ids) are one kind. on_unknown(channel id): a client's
    subscription the SDK refused as for an unknown channel."""

    def __init__(self, warn, on_unknown=None):
        super().__init__(logging.WARNING)
        self._warn = warn
        self._on_unknown = on_unknown
        self._seen: set[str] = set()
        self._lock_seen = threading.Lock()

    def say(self, text: str) -> None:
        """warn(text), unless a text like it was said before."""
        text = " ".join(text.split())
        kind = re.sub(r"\d+", "#", text)
        with self._lock_seen:
            if kind in self._seen:
                return
            self._seen.add(kind)
        self._warn(f"{text} (further ones like it are not shown)")

    def emit(self, record: logging.LogRecord) -> None:
        try:
            text = record.getMessage()
        except Exception:  # noqa: BLE001 - a malformed record must not break the SDK's thread
            return
        m = _UNKNOWN_CHANNEL.search(text)
        if m and self._on_unknown is not None:
            self._on_unknown(int(m.group(1)))
        self.say(f"live view (Foxglove SDK): {text}")


class LiveServer:
    def __init__(self, port: int = DEFAULT_PORT, host: str = "127.0.0.1", name: str = "zfloc-stream", warn=print_warning):
        """port 0: a free one (self.port says which). warn(text): where refused clients
        and the SDK's log lines go (one `warning:` line each by default)."""
        try:
            import foxglove
            from foxglove.websocket import ServerListener
        except ImportError:
            raise InputError("--live needs the Foxglove SDK: pip install 'zfloc-stream[live]' (foxglove-sdk)") from None
        from .live_bridge import SubprotocolBridge

        self._foxglove = foxglove
        self._context = foxglove.Context()
        self._channels: dict[tuple, object] = {}
        self._latched: dict[int, tuple[object, bytes, int]] = {}  # channel id -> (channel, last message, log time)
        self._lock = threading.Lock()
        self._resend: set[int] = set()
        self._readvertise: set[int] = set()  # channel ids a subscription to was refused as unknown
        self._readvertised: dict[tuple, int] = {}  # channel key -> times made anew
        self._records: dict[tuple, object] = {}  # channel key -> a record of it (to make it anew)
        self._log = logging.getLogger("foxglove")
        self._log_handler = _OncePerKind(warn, self._refused)
        self._log_state = (self._log.propagate, self._log.level)
        self._log.addHandler(self._log_handler)
        self._log.propagate = False  # else Python's last-resort handler prints each record raw
        if self._log.level == logging.NOTSET or self._log.level > logging.WARNING:
            self._log.setLevel(logging.WARNING)
        outer = self

        class _Listener(ServerListener):
            def on_subscribe(self, client, channel) -> None:
                # Not from the server's callback thread: the next batch (or linger) re-logs it.
                with outer._lock:
                    outer._resend.add(channel.id)

        self._server = self._bridge = None
        try:
            # the SDK on a loopback port of its own; clients come through the bridge
            self._server = foxglove.start_server(name=name, host="127.0.0.1", port=0, context=self._context,
                                                 server_listener=_Listener())
            self._bridge = SubprotocolBridge(host, port, self._server.port, warn=self._log_handler.say)
        except Exception as err:  # noqa: BLE001 - OSError from the bridge, the SDK's own error type
            self.close()
            raise InputError(f"--live: cannot serve on {host}:{port}: {err}".splitlines()[0]) from None
        self.host, self.port = host, self._bridge.port

    @property
    def url(self) -> str:
        return f"ws://{self.host}:{self.port}"

    def _channel(self, rec):
        key = (rec.topic, rec.schema_name)
        channel = self._channels.get(key)
        if channel is None:
            data = rec.schema
            if not isinstance(data, bytes):  # a protobuf class: its file descriptor set
                from mcap_protobuf.schema import build_file_descriptor_set

                data = build_file_descriptor_set(rec.schema).SerializeToString()
            schema = self._foxglove.Schema(name=rec.schema_name, encoding=rec.schema_encoding, data=data)
            channel = self._foxglove.Channel(rec.topic, schema=schema, message_encoding=rec.message_encoding,
                                             context=self._context, metadata=dict(rec.metadata))
            self._channels[key] = channel
            self._records[key] = rec
        return channel

    def _refused(self, channel_id: int) -> None:
        # foxglove-sdk 0.30 can refuse a subscription sent right after an advertisement
        # ("unknown channel": it sends the advertisement before it records the channel for
        # that client), and Foxglove does not ask again: the topic, the floorplan often,
        # stays empty. Advertising the channel anew (next flush) makes clients subscribe again.
        with self._lock:
            self._readvertise.add(channel_id)

    def _advertise_anew(self, channel_ids) -> None:
        for key, channel in list(self._channels.items()):
            if channel.id() not in channel_ids or self._readvertised.get(key, 0) >= MAX_READVERTISE:
                continue
            self._readvertised[key] = self._readvertised.get(key, 0) + 1
            old_id = channel.id()
            channel.close()  # clients get an unadvertise, then the advertisement of the new one
            del self._channels[key]
            fresh = self._channel(self._records[key])
            if old_id in self._latched:
                _, data, log_time = self._latched.pop(old_id)
                self._latched[fresh.id()] = (fresh, data, log_time)

    def __call__(self, batch) -> None:
        """One SessionWriter batch (a frame's inputs, or an estimate's outputs)."""
        for rec in batch:
            channel = self._channel(rec)
            if rec.topic in LATCHED:
                self._latched[channel.id()] = (channel, rec.data, rec.log_time)
            channel.log(rec.data, log_time=rec.log_time)
        self.flush()

    def flush(self) -> None:
        """Advertise anew the channels a subscription to was refused; re-log the latched
        messages of channels subscribed to since the last call."""
        with self._lock:
            resend, self._resend = self._resend, set()
            refused, self._readvertise = self._readvertise, set()
        if refused:
            self._advertise_anew(refused)
        for channel_id in resend:
            if channel_id in self._latched:
                channel, data, log_time = self._latched[channel_id]
                channel.log(data, log_time=log_time)

    def linger(self, seconds: float | None = None, stop: threading.Event | None = None) -> None:
        """Keep serving after the run (late viewers still get the floorplan and last BEV):
        for `seconds` (None: until Ctrl-C / SIGTERM, which end it without an error), or
        until `stop` is set."""
        deadline = None if seconds is None else time.monotonic() + seconds
        try:
            while stop is None or not stop.is_set():
                left = POLL if deadline is None else min(POLL, deadline - time.monotonic())
                if left <= 0:
                    break
                if stop is not None:
                    stop.wait(left)
                else:
                    time.sleep(left)
                self.flush()
        except KeyboardInterrupt:  # the way to end an open-ended linger: not an interruption of the run
            pass

    def close(self) -> None:
        if self._bridge is not None:
            self._bridge.close()
        if self._server is not None:
            self._server.stop()
        self._bridge = self._server = None
        if self._log_handler in self._log.handlers:
            self._log.removeHandler(self._log_handler)
            self._log.propagate, level = self._log_state
            self._log.setLevel(level)
