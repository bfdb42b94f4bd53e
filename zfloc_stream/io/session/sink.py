"""Ordered MCAP record writing, inline or on one background thread.

The SessionWriter builds and serializes messages on the caller's thread and hands them
over one batch per call (a frame's inputs, an estimate's outputs). The sink registers
schemas and channels, adds the messages, closes chunks when asked (compression happens
there) and hands the bytes to the OS after every batch. With a background thread the
caller only pays for serialization: zstd compression and file writes release the GIL and
overlap the next frame's processing. Batches are applied strictly in submission order by
a single thread, so the file's bytes do not depend on the mode.

A crash loses at most the batches still queued (bounded by max_pending) plus the chunk
in progress. A failure on the worker (disk full...) is raised on the caller's next call.
"""

from __future__ import annotations

import queue
import threading
from dataclasses import dataclass

from mcap.writer import Writer
from mcap_protobuf.schema import build_file_descriptor_set


@dataclass(frozen=True)
class Record:
    topic: str
    schema_name: str
    schema_encoding: str
    schema: object  # bytes, or a protobuf message class (its descriptor set is built once)
    message_encoding: str
    metadata: tuple  # sorted (key, value) pairs of the channel metadata
    log_time: int
    sequence: int
    data: bytes


class RecordSink:
    def __init__(self, mcap: Writer, file, background: bool, max_pending: int):
        self._mcap = mcap
        self._file = file
        self._schemas: dict[str, int] = {}
        self._channels: dict[tuple, int] = {}
        self._error: BaseException | None = None
        self._queue: queue.Queue | None = None
        self._thread: threading.Thread | None = None
        if background:
            self._queue = queue.Queue(maxsize=max(1, max_pending))
            self._thread = threading.Thread(target=self._work, name="zfloc-session-writer", daemon=True)
            self._thread.start()

    @property
    def error(self) -> BaseException | None:
        return self._error

    def submit(self, batch: list[Record], close_chunk_first: bool, close_chunk_after: bool = False, then=None) -> None:
        """Queue (or write) one batch; raises the worker's failure if one happened.
        close_chunk_after: the chunk ends with this batch (a frame is complete). then: called
        (on the writing thread) once the batch is handed to the OS: outputs that must never
        be ahead of the log (trajectory.csv) are written there."""
        self._raise_pending()
        if self._queue is None:
            self._apply(batch, close_chunk_first, close_chunk_after, then)
        else:
            self._queue.put((batch, close_chunk_first, close_chunk_after, then))  # blocks while max_pending are queued

    def finish(self) -> None:
        """Write everything queued, then the MCAP summary and footer."""
        if self._thread is not None:
            self._queue.put(None)
            self._thread.join()
            self._thread = None
        self._raise_pending()
        self._mcap.finish()

    def abandon(self) -> None:
        """Stop the worker without writing what is queued (after a reported failure)."""
        if self._thread is not None:
            self._error = self._error or RuntimeError("abandoned")
            self._queue.put(None)
            self._thread.join()
            self._thread = None

    # --- worker side --------------------------------------------------------------------
    def _raise_pending(self) -> None:
        if self._error is not None:
            raise self._error

    def _work(self) -> None:
        while True:
            item = self._queue.get()
            if item is None:
                return
            if self._error is None:  # after a failure, drain without writing
                try:
                    self._apply(*item)
                except BaseException as err:  # noqa: BLE001 - re-raised on the caller's thread
                    self._error = err

    def _apply(self, batch: list[Record], close_chunk_first: bool, close_chunk_after: bool = False, then=None) -> None:
        if close_chunk_first:
            self._mcap.flush()  # finish the chunk in progress: bounds what a crash can lose
        for rec in batch:
            self._mcap.add_message(self._channel(rec), log_time=rec.log_time, data=rec.data, publish_time=rec.log_time, sequence=rec.sequence)
        if close_chunk_after and batch:
            self._mcap.flush()  # the frame just completed is in a finished chunk: a kill cannot lose it
        self._file.flush()  # finished chunks reach the OS: they survive a killed process
        if then is not None:
            then()

    def _channel(self, rec: Record) -> int:
        key = (rec.topic, rec.schema_name, rec.metadata)
        channel = self._channels.get(key)
        if channel is None:
            schema = self._schemas.get(rec.schema_name)
            if schema is None:
                data = rec.schema if isinstance(rec.schema, bytes) else build_file_descriptor_set(rec.schema).SerializeToString()
                schema = self._mcap.register_schema(name=rec.schema_name, encoding=rec.schema_encoding, data=data)
                self._schemas[rec.schema_name] = schema
            channel = self._mcap.register_channel(topic=rec.topic, message_encoding=rec.message_encoding, schema_id=schema, metadata=dict(rec.metadata))
            self._channels[key] = channel
        return channel
