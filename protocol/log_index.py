"""A complete session log's messages of some channels only, found through the log's own index.

Reading one agent out of a ten-chair log with the stream reader parses every record of every chunk
(each edge replaying the bench's shared game spent three quarters of its replay CPU on the other
nine chairs). A log that was closed properly ends in a summary: every channel, and per chunk where
each channel's message index lies; a message index lists (log time, offset in the chunk) of that
channel's messages. So only the chunks holding wanted channels are decompressed, and only the
wanted messages are cut out of them, in file order (chunk by chunk, by offset), as the stream
reader would have yielded them.

A log without a summary (truncated, still being written) or with one that does not describe its
chunks gives None here, and the caller reads it as a stream, which keeps everything before damage.
The record layouts are the MCAP specification's (https://mcap.dev/spec): Message (opcode 0x05)
and Message Index (opcode 0x07), little-endian.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np
from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Chunk, Metadata
from mcap.stream_reader import get_chunk_data_stream

MESSAGE, MESSAGE_INDEX = 0x05, 0x07
_MESSAGE_HEAD = struct.Struct("<BQHIQQ")  # opcode, record length, channel id, sequence, log time, publish time
_INDEX_HEAD = struct.Struct("<BQHI")  # opcode, record length, channel id, entries' byte length
_RECORD_HEAD = 1 + 8  # opcode and record length
_MESSAGE_FIELDS = 2 + 4 + 8 + 8  # channel id, sequence, log time, publish time


class IndexedLog:
    """The summary of a complete log; `messages(wanted)` reads the wanted channels' messages."""

    def __init__(self, stream: BinaryIO, summary: Any):
        self._stream = stream
        self.summary = summary
        self.channels = summary.channels  # id -> mcap Channel
        self.schemas = summary.schemas  # id -> mcap Schema
        counts = summary.statistics.channel_message_counts if summary.statistics else None
        self.message_counts: dict[int, int] = dict(counts or {})

    @classmethod
    def open(cls, stream: BinaryIO) -> "IndexedLog | None":
        """None when the log has no usable summary (read it as a stream instead)."""
        try:
            summary = make_reader(stream).get_summary()
        except (McapError, ValueError, EOFError, OSError, struct.error):
            return None
        if summary is None or not summary.chunk_indexes or summary.statistics is None:
            return None
        if sum(summary.statistics.channel_message_counts.values()) != summary.statistics.message_count:
            return None
        return cls(stream, summary)

    def metadata(self, name: str) -> Metadata | None:
        for index in self.summary.metadata_indexes:
            if index.name == name:
                self._stream.seek(index.offset + _RECORD_HEAD)
                return Metadata.read(ReadDataStream(self._stream))
        return None

    def messages(self, wanted: Callable[[int], bool]) -> Iterator[tuple[int, int, bytes]]:
        """(log time, channel id, payload) of every message on a channel `wanted(channel_id)` accepts, in
        file order. McapError (or ValueError) on a damaged chunk or index, after what came before."""
        chosen = {channel_id for channel_id in self.channels if wanted(channel_id)}
        for chunk_index in sorted(self.summary.chunk_indexes, key=lambda c: c.chunk_start_offset):
            offsets = [chunk_index.message_index_offsets[c] for c in chosen if c in chunk_index.message_index_offsets]
            if not offsets:
                continue
            entries = np.sort(np.concatenate([self._index_offsets(offset) for offset in offsets]))
            data = self._chunk_data(chunk_index.chunk_start_offset)
            for offset in entries.tolist():
                opcode, length, channel_id, _, log_time, _ = _MESSAGE_HEAD.unpack_from(data, offset)
                end = offset + _RECORD_HEAD + length
                if opcode != MESSAGE or end > len(data):
                    raise McapError(f"chunk at {chunk_index.chunk_start_offset}: no message record at offset {offset}")
                yield log_time, channel_id, data[offset + _RECORD_HEAD + _MESSAGE_FIELDS:end]

    def _index_offsets(self, position: int) -> np.ndarray:
        """The chunk offsets a Message Index record lists."""
        self._stream.seek(position)
        head = self._stream.read(_INDEX_HEAD.size)
        opcode, _, _, size = _INDEX_HEAD.unpack(head)
        body = self._stream.read(size)
        if opcode != MESSAGE_INDEX or size % 16 or len(body) != size:
            raise McapError(f"no message index record at file offset {position}")
        return np.frombuffer(body, dtype="<u8").reshape(-1, 2)[:, 1].astype(np.int64)

    def _chunk_data(self, position: int) -> bytes:
        self._stream.seek(position + _RECORD_HEAD)
        chunk = Chunk.read(ReadDataStream(self._stream))
        try:
            records, size = get_chunk_data_stream(chunk)
        except Exception as error:  # noqa: BLE001 - zstandard's and lz4's own errors on bad bytes
            raise McapError(f"chunk at {position}: {chunk.compression} data do not decompress ({error})") from None
        if size != chunk.uncompressed_size:
            raise McapError(f"chunk at {position}: {size} bytes decompressed, its record says {chunk.uncompressed_size}")
        return records.read(size)


def open_indexed(path: Path) -> tuple[BinaryIO, IndexedLog] | None:
    """The open file and its index, or None (and the file closed) for a log to read as a stream."""
    stream = open(path, "rb")
    indexed = IndexedLog.open(stream)
    if indexed is None:
        stream.close()
        return None
    return stream, indexed
