"""The messages of a finalized MCAP file in blocks of arrays, for reading a long bag fast.

:func:`message_blocks` decompresses the chunks in file order and finds their message records with a
compiled scan, so a block of many thousand messages costs a few numpy calls instead of a Python
object per message. Each :class:`MessageBlock` holds the uncompressed bytes of its chunks and, per
message, its channel id, log time and where its data lies; :meth:`MessageBlock.rows` gathers the
messages of one channel that all have the same size into an (N, size) byte array, which the array
decoders of :mod:`quad_msgs_bridge.fast_cdr` read. Memory holds one block (``block_bytes``).
"""
from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator

import numpy as np
import zstandard
from mcap.opcode import Opcode
from mcap.reader import make_reader
from numba import njit

import quad_msgs_bridge.kernel_cache  # noqa: F401  (its kernels' cache stamps)

_RECORD_HEAD = struct.Struct('<BQ')
BLOCK_BYTES = 16 << 20     #: uncompressed bytes of messages per block


class UnsupportedLayout(ValueError):
    """The file or a message is not in the layout this fast path reads (the caller reads it message by message)."""


@dataclass(frozen=True)
class Channel:
    """What the reader needs of an MCAP channel (the fields of a rosbags connection it uses)."""

    id: int
    topic: str
    msgtype: str        #: the ROS type, e.g. nav_msgs/msg/Odometry
    msgcount: int


@dataclass
class MessageBlock:
    """Messages of consecutive chunks: ``data`` (uint8) holds them; per message its ``channel``, ``log_time``
    [ns], ``start`` (offset of its data in ``data``) and ``size`` [bytes], in file order."""

    data: np.ndarray
    channel: np.ndarray
    log_time: np.ndarray
    start: np.ndarray
    size: np.ndarray

    def rows(self, channel_id: int) -> np.ndarray:
        """The data of ``channel_id``'s messages as rows of an (N, size) uint8 array, in log-time order;
        UnsupportedLayout when they differ in size (their layout is not fixed)."""
        mine = np.flatnonzero(self.channel == channel_id)
        mine = mine[np.argsort(self.log_time[mine], kind='stable')]      # in log-time order, as a bag is read
        starts, sizes = self.start[mine], self.size[mine]
        if not len(starts):
            return np.empty((0, 0), dtype=np.uint8)
        if (sizes != sizes[0]).any():
            raise UnsupportedLayout(f'messages of channel {channel_id} differ in size')
        return _gather(self.data, starts, int(sizes[0]))


@njit(cache=True)
def _gather(data, starts, size):
    """Rows of ``size`` bytes of ``data`` from each of ``starts``."""
    out = np.empty((len(starts), size), np.uint8)
    for i in range(len(starts)):
        out[i] = data[starts[i]:starts[i] + size]
    return out


def channels(path: Path) -> tuple[list[Channel], int, int]:
    """(channels, first log time, last log time [ns]) from the summary of a finalized MCAP file."""
    with path.open('rb') as stream:
        summary = make_reader(stream).get_summary()
    if summary is None or summary.statistics is None:
        raise UnsupportedLayout(f'{path}: no summary statistics')
    counts = summary.statistics.channel_message_counts
    found = [Channel(c.id, c.topic, summary.schemas[c.schema_id].name if c.schema_id in summary.schemas else '',
                     counts.get(c.id, 0)) for c in summary.channels.values()]
    return found, summary.statistics.message_start_time, summary.statistics.message_end_time


@njit(cache=True)
def _message_records(buffer):
    """(channel, log time, data start, data size) of every message record in ``buffer`` (the records of a
    chunk, uint8), and the offset where the scan stopped (len(buffer) when every record was whole)."""
    count = len(buffer) // 31 + 1
    channel = np.empty(count, np.int64)
    log_time = np.empty(count, np.int64)
    start = np.empty(count, np.int64)
    size = np.empty(count, np.int64)
    found, offset, end = 0, 0, len(buffer)
    while offset + 9 <= end:
        length = np.int64(0)
        for i in range(8):
            length |= np.int64(buffer[offset + 1 + i]) << (8 * i)
        body = offset + 9
        if length < 0 or body + length > end:
            break
        if buffer[offset] == 0x05 and length >= 22:
            channel[found] = np.int64(buffer[body]) | (np.int64(buffer[body + 1]) << 8)
            t = np.int64(0)
            for i in range(8):
                t |= np.int64(buffer[body + 6 + i]) << (8 * i)
            log_time[found] = t
            start[found] = body + 22
            size[found] = length - 22
            found += 1
        offset = body + length
    return channel[:found], log_time[:found], start[:found], size[:found], offset


def message_blocks(path: Path, block_bytes: int = BLOCK_BYTES,
                   on_bytes: Callable[[int], None] = lambda count: None) -> Iterator[MessageBlock]:
    """The messages of the MCAP file at ``path`` in blocks of about ``block_bytes`` uncompressed bytes, in file
    order; ``on_bytes(n)`` is told how many file bytes each record read took (for a progress bar).
    UnsupportedLayout for messages outside chunks or a compression other than zstd or none."""
    decompressor = zstandard.ZstdDecompressor()
    pieces: list[bytes] = []
    held = 0
    with path.open('rb') as stream:
        stream.seek(8)      # the magic
        while True:
            head = stream.read(_RECORD_HEAD.size)
            if len(head) < _RECORD_HEAD.size:
                break
            opcode, length = _RECORD_HEAD.unpack(head)
            if opcode in (Opcode.DATA_END, Opcode.FOOTER):
                break
            if opcode == Opcode.MESSAGE:
                raise UnsupportedLayout(f'{path}: messages outside chunks')
            if opcode != Opcode.CHUNK:
                stream.seek(length, 1)
                on_bytes(_RECORD_HEAD.size + length)
                continue
            body = stream.read(length)
            on_bytes(_RECORD_HEAD.size + length)
            pieces.append(_chunk_records(body, decompressor))
            held += len(pieces[-1])
            if held >= block_bytes:
                yield _block(pieces)
                pieces, held = [], 0
    if pieces:
        yield _block(pieces)


def _chunk_records(body: bytes, decompressor) -> bytes:
    """The uncompressed records of a chunk record's ``body``."""
    offset = 8 + 8 + 8 + 4
    uncompressed_size = struct.unpack_from('<Q', body, 16)[0]
    (name_length,) = struct.unpack_from('<I', body, offset)
    compression = body[offset + 4:offset + 4 + name_length].decode()
    offset += 4 + name_length
    (records_length,) = struct.unpack_from('<Q', body, offset)
    records = body[offset + 8:offset + 8 + records_length]
    if compression == '':
        return records
    if compression == 'zstd':
        return decompressor.decompress(records, max_output_size=uncompressed_size)
    raise UnsupportedLayout(f'chunk compression {compression!r}')


def _block(pieces: list[bytes]) -> MessageBlock:
    """One block of the records of consecutive chunks (each scanned on its own: a record never spans two)."""
    data = np.frombuffer(b''.join(pieces), dtype=np.uint8)
    parts, offset = [], 0
    for piece in pieces:
        channel, log_time, start, size, _ = _message_records(data[offset:offset + len(piece)])
        parts.append((channel, log_time, start + offset, size))
        offset += len(piece)
    return MessageBlock(data, *(np.concatenate(column) for column in zip(*parts)))
