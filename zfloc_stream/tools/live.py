"""Live view: the session log's messages served to Foxglove while the run goes on
(`zfloc-stream run --live [PORT]`, `demo --live`), through the Foxglove SDK's WebSocket
server (`foxglove-sdk`, the [live] extra).

The server is fed the very records the SessionWriter writes (its `listeners` hook): same
topics, schemas and bytes as session.mcap, no second serialization. Channels live in a
context of their own, so nothing else logged through the SDK leaks in. The floorplan is
published once, with the first frame; a client that subscribes later gets it (and the
latest BEV) again at once, so opening Foxglove mid-run still shows the map.
"""

from __future__ import annotations

import threading

from ..errors import InputError

LATCHED = ("/zfloc/floorplan", "/zfloc/bev")  # topics a late subscriber gets the last message of
DEFAULT_PORT = 8765


class LiveServer:
    def __init__(self, port: int = DEFAULT_PORT, host: str = "127.0.0.1", name: str = "zfloc-stream"):
        try:
            import foxglove
            from foxglove.websocket import ServerListener
        except ImportError:
            raise InputError("--live needs the Foxglove SDK: pip install 'zfloc-stream[live]' (foxglove-sdk)") from None
        self._foxglove = foxglove
        self._context = foxglove.Context()
        self._channels: dict[tuple, object] = {}
        self._latched: dict[int, tuple[bytes, int]] = {}  # channel id -> (last message, log time)
        self._lock = threading.Lock()
        self._resend: set[int] = set()
        outer = self

        class _Listener(ServerListener):
            def on_subscribe(self, client, channel) -> None:
                # Not from the server's callback thread: the next batch re-logs it.
                with outer._lock:
                    outer._resend.add(channel.id)

        try:
            self._server = foxglove.start_server(name=name, host=host, port=port, context=self._context,
                                                 server_listener=_Listener())
        except Exception as err:  # noqa: BLE001 - the SDK raises its own error type for a busy port
            raise InputError(f"--live: cannot serve on {host}:{port}: {err}".splitlines()[0]) from None
        self.host, self.port = host, self._server.port

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
        return channel

    def __call__(self, batch) -> None:
        """One SessionWriter batch (a frame's inputs, or an estimate's outputs)."""
        for rec in batch:
            channel = self._channel(rec)
            if rec.topic in LATCHED:
                self._latched[channel.id()] = (rec.data, rec.log_time)
            channel.log(rec.data, log_time=rec.log_time)
        with self._lock:
            resend, self._resend = self._resend, set()
        for channel_id in resend:
            if channel_id in self._latched:
                data, log_time = self._latched[channel_id]
                for channel in self._channels.values():
                    if channel.id() == channel_id:
                        channel.log(data, log_time=log_time)

    def close(self) -> None:
        self._server.stop()
