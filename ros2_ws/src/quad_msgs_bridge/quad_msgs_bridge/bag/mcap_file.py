"""An MCAP file being written: chunked, zstd-compressed, indexed, readable up to the last chunk if killed.

The structural records (header, schemas, channels, metadata, chunks, indexes, statistics, summary
offsets, footer) are built with the ``mcap`` package's record classes. Only the hot path, appending
a message record to the open chunk, is written here directly: ``mcap.writer.Writer.add_message``
costs about 3 us per message, this under 1 us with compression (see ``bench/bench_recording.py``).

Layout: magic, Header, then Schema, Channel and Metadata records outside chunks (flushed at once,
so a killed file still describes its channels), then each Chunk followed by its MessageIndex
records and a flush, so the OS holds every finished chunk; at :meth:`close` DataEnd, the summary
(schemas, channels, statistics, chunk and metadata indexes, summary offsets), Footer, magic.

A full chunk is compressed, checksummed and written by a background thread (zstd, crc32 and file
writes release the GIL, so this overlaps the caller's work) while the next chunk fills; the next
full chunk waits for it. Memory stays within two chunks (``chunk_size`` bytes uncompressed each)
and their message indexes.
"""
from __future__ import annotations

import struct
import sys
import zlib
from array import array
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Mapping

import zstandard
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (Channel, Chunk, ChunkIndex, DataEnd, Footer, Header, McapRecord, Metadata,
                          MetadataIndex, Schema, Statistics, SummaryOffset)
from mcap.writer import LIBRARY_IDENTIFIER

MAGIC = b'\x89MCAP0\r\n'
LIBRARY = f'quad_msgs_bridge.bag.mcap_file ({LIBRARY_IDENTIFIER} records)'
DEFAULT_CHUNK_SIZE = 1 << 20                     #: uncompressed bytes per chunk
_MESSAGE = int(Opcode.MESSAGE)
_MESSAGE_HEAD = struct.Struct('<BQHIQQ')          # opcode, record length, channel, sequence, log, publish
_MESSAGE_FIELDS = _MESSAGE_HEAD.size - 9          # bytes of a message record before its data
_pack_message_head = _MESSAGE_HEAD.pack
_MESSAGE_INDEX_HEAD = struct.Struct('<BQHI')      # opcode, record length, channel, entries length


class BagWriteError(OSError):
    """A bag file cannot be written (unwritable path, disk full, ...); names the file."""


class McapFileWriter:
    """Writes one MCAP file; its methods must be called from one thread at a time."""

    def __init__(self, path: str | Path, profile: str, chunk_size: int = DEFAULT_CHUNK_SIZE,
                 compression_level: int = 3):
        self.path = Path(path)
        self._chunk_size = chunk_size
        self._compressor = zstandard.ZstdCompressor(level=compression_level)
        self._schemas: list[Schema] = []
        self._channels: list[Channel] = []
        self._chunk = bytearray()
        self._chunk_index: list[array] = [array('Q')]   # per channel id: log_time, offset, log_time, ...
        self._chunk_indexes: list[ChunkIndex] = []
        self._metadata_indexes: list[MetadataIndex] = []
        self._message_counts: dict[int, int] = {}
        self._start_time: int | None = None
        self._end_time = 0
        self._position = 0
        self._builder = RecordBuilder()
        self._file = None
        self._storing: Future | None = None     # the chunk being written in the background
        self._worker: ThreadPoolExecutor | None = None
        self._error: BagWriteError | None = None
        self.closed = False
        try:
            self._file = open(self.path, 'wb')
        except OSError as error:
            self._fail(error)
        self._worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix='mcap-chunks')
        self._write(MAGIC)
        self._write_record(Header(profile=profile, library=LIBRARY))

    # --- errors and raw output ------------------------------------------------------------
    @property
    def error(self) -> BagWriteError | None:
        """The write error that stopped this file, if any."""
        return self._error

    def abandon(self) -> None:
        """Close the file as it is, unfinished (readable up to its last complete chunk)."""
        try:
            self._settle()
        except BagWriteError:
            pass   # the file ends at its last complete chunk all the same
        self._close_file()

    def _close_file(self) -> None:
        self.closed = True
        if self._file is not None:
            try:
                self._file.close()
            except OSError:
                pass   # buffered bytes that cannot be written: the file ends at its last flush
        if self._worker is not None:
            self._worker.shutdown(wait=False)

    def _fail(self, error: OSError):
        """Close the file unfinished; raise a BagWriteError naming it (now and from every later write)."""
        self._close_file()
        self._error = BagWriteError(error.errno, f'cannot write bag file: {error.strerror}', str(self.path))
        raise self._error from error

    def _settle(self) -> None:
        """Wait until the chunk being written in the background is on disk; raises its error."""
        storing, self._storing = self._storing, None
        if storing is not None:
            storing.result()

    def _write(self, data) -> None:
        try:
            self._file.write(data)
        except OSError as error:
            self._fail(error)
        self._position += len(data)

    def _write_record(self, record: McapRecord) -> int:
        """Write one record at the current position; returns its length in bytes."""
        record.write(self._builder)
        data = self._builder.end()
        self._write(data)
        return len(data)

    def flush(self) -> None:
        """Hand everything written so far to the OS (a killed process then loses none of it)."""
        self._settle()
        self._flush_file()

    def _flush_file(self) -> None:
        try:
            self._file.flush()
        except OSError as error:
            self._fail(error)

    # --- definitions ----------------------------------------------------------------------
    def add_schema(self, name: str, encoding: str, data: bytes) -> int:
        self._settle()
        schema = Schema(id=len(self._schemas) + 1, name=name, encoding=encoding, data=data)
        self._schemas.append(schema)
        self._write_record(schema)
        return schema.id

    def add_channel(self, topic: str, message_encoding: str, schema_id: int, metadata: Mapping[str, str]) -> int:
        self._settle()
        channel = Channel(id=len(self._channels) + 1, topic=topic, message_encoding=message_encoding,
                          schema_id=schema_id, metadata=dict(metadata))
        self._channels.append(channel)
        self._chunk_index.append(array('Q'))
        self._write_record(channel)
        return channel.id

    def add_metadata(self, name: str, values: Mapping[str, str]) -> None:
        self._settle()
        offset = self._position
        length = self._write_record(Metadata(name=name, metadata=dict(values)))
        self._metadata_indexes.append(MetadataIndex(offset=offset, length=length, name=name))

    # --- messages -------------------------------------------------------------------------
    def add_message(self, channel_id: int, log_time: int, publish_time: int, data: bytes) -> None:
        """Append one message [times in ns] to the open chunk; writes the chunk once it is full."""
        chunk = self._chunk
        index = self._chunk_index[channel_id]
        index.append(log_time)
        index.append(len(chunk))
        chunk += _pack_message_head(_MESSAGE, _MESSAGE_FIELDS + len(data), channel_id, 0, log_time, publish_time)
        chunk += data
        if len(chunk) >= self._chunk_size:
            self.write_open_chunk()

    def write_open_chunk(self) -> None:
        """Hand the open chunk to the background writer, once the one before it is on disk."""
        records = self._chunk
        if not records:
            return
        indexed = [(channel_id, entries) for channel_id, entries in enumerate(self._chunk_index) if entries]
        for channel_id, _ in indexed:
            self._chunk_index[channel_id] = array('Q')
        self._chunk = bytearray()
        self._settle()
        if self._error is not None:
            raise self._error
        self._storing = self._worker.submit(self._store_chunk, records, indexed)

    def _store_chunk(self, records: bytearray, indexed: list[tuple[int, array]]) -> None:
        """Compress and write one chunk and its message indexes, then flush (background thread)."""
        start = min(min(entries[0::2]) for _, entries in indexed)
        end = max(max(entries[0::2]) for _, entries in indexed)
        compressed = self._compressor.compress(records)
        chunk_offset = self._position
        chunk_length = self._write_record(Chunk(
            message_start_time=start, message_end_time=end, uncompressed_size=len(records),
            uncompressed_crc=zlib.crc32(records), compression='zstd', data=compressed))
        index_offsets = {}
        index_start = self._position
        for channel_id, entries in indexed:
            index_offsets[channel_id] = self._position
            if sys.byteorder != 'little':
                entries.byteswap()
            self._write(_MESSAGE_INDEX_HEAD.pack(Opcode.MESSAGE_INDEX, 6 + 8 * len(entries), channel_id,
                                                 8 * len(entries)))
            self._write(entries.tobytes())
            self._message_counts[channel_id] = self._message_counts.get(channel_id, 0) + len(entries) // 2
        self._chunk_indexes.append(ChunkIndex(
            message_start_time=start, message_end_time=end, chunk_start_offset=chunk_offset,
            chunk_length=chunk_length, message_index_offsets=index_offsets,
            message_index_length=self._position - index_start, compression='zstd',
            compressed_size=len(compressed), uncompressed_size=len(records)))
        self._start_time = start if self._start_time is None else min(start, self._start_time)
        self._end_time = max(end, self._end_time)
        self._flush_file()

    # --- end --------------------------------------------------------------------------------
    def message_counts(self) -> dict[int, int]:
        """Messages per channel id in the chunks written so far."""
        self._settle()
        return dict(self._message_counts)

    def time_range(self) -> tuple[int, int]:
        """(first, last) message log time [ns] in the chunks written so far; (0, 0) if none."""
        self._settle()
        return (self._start_time or 0, self._end_time)

    def close(self) -> None:
        """Write the open chunk, the summary and the footer; close the file. Idempotent."""
        if self.closed:
            return
        self.write_open_chunk()
        self._settle()
        self._write_record(DataEnd(data_section_crc=0))
        summary_start = self._position
        offsets = []
        groups = ((Opcode.SCHEMA, self._schemas), (Opcode.CHANNEL, self._channels),
                  (Opcode.STATISTICS, [self._statistics()]), (Opcode.CHUNK_INDEX, self._chunk_indexes),
                  (Opcode.METADATA_INDEX, self._metadata_indexes))
        summary = bytearray()
        for opcode, records in groups:
            if not records:
                continue
            group_start = summary_start + len(summary)
            for record in records:
                record.write(self._builder)
            summary += self._builder.end()
            offsets.append(SummaryOffset(group_opcode=opcode, group_start=group_start,
                                         group_length=summary_start + len(summary) - group_start))
        summary_offset_start = summary_start + len(summary)
        for offset in offsets:
            offset.write(self._builder)
        summary += self._builder.end()
        footer_head = struct.pack('<BQQQ', Opcode.FOOTER, 20, summary_start, summary_offset_start)
        self._write(summary)
        self._write_record(Footer(summary_start=summary_start, summary_offset_start=summary_offset_start,
                                  summary_crc=zlib.crc32(footer_head, zlib.crc32(summary))))
        self._write(MAGIC)
        try:
            self._file.close()
        except OSError as error:
            self._fail(error)
        self._close_file()

    def _statistics(self) -> Statistics:
        counts = self._message_counts
        return Statistics(
            message_count=sum(counts.values()), schema_count=len(self._schemas),
            channel_count=len(self._channels), attachment_count=0,
            metadata_count=len(self._metadata_indexes), chunk_count=len(self._chunk_indexes),
            message_start_time=self._start_time or 0, message_end_time=self._end_time,
            channel_message_counts=dict(counts))
