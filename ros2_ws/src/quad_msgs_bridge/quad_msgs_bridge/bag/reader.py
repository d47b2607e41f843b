"""Finding and reading the storage of a bag, including one whose recording was killed.

A bag is a rosbag2 directory (``metadata.yaml`` + storage files) or a lone ``.mcap`` file. A
finalized MCAP file ends with a summary and a footer; a killed recording leaves a file that stops
anywhere. :class:`McapPrefix` reads such a file record by record with the ``mcap`` package's record
parsers and stops cleanly at the first incomplete or corrupt record, so every complete chunk
(CRC-checked) is still readable.
"""
from __future__ import annotations

import struct
from io import BytesIO
from pathlib import Path
from typing import Iterator

from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, DataEnd, Header, McapRecord, Message, Metadata, Schema
from mcap.stream_reader import breakup_chunk

from quad_msgs_bridge.bag.metadata import CUSTOM_DATA_RECORD, METADATA_FILE, read_metadata
from quad_msgs_bridge.bag.mcap_file import MAGIC

_RECORD_HEAD = struct.Struct('<BQ')
_FOOTER_SIZE = 9 + 20
_READERS = {Opcode.HEADER: Header.read, Opcode.SCHEMA: Schema.read, Opcode.CHANNEL: Channel.read,
            Opcode.METADATA: Metadata.read, Opcode.CHUNK: Chunk.read, Opcode.DATA_END: DataEnd.read}
_KNOWN = {int(opcode) for opcode in Opcode}


class BagReadError(ValueError):
    """The path is not a readable bag; the message says what is wrong with it."""


EXPECTED_BAG = 'expected a rosbag2 bag directory (holding metadata.yaml) or an MCAP file'


def describe_file(path: Path) -> str:
    """What the file at ``path`` looks like, for a message: 'an empty file', 'a text file (it begins ...)', ..."""
    size = path.stat().st_size
    with path.open('rb') as stream:
        head = stream.read(512)
    if not head:
        return 'an empty file (0 bytes)'
    if head.startswith(MAGIC):
        return f'an MCAP file of {size} bytes'
    if MAGIC.startswith(head):
        return f'a file of {size} bytes, cut off within the MCAP magic'
    try:
        text = head.decode('utf-8')
    except UnicodeDecodeError as error:   # a multi-byte character cut at the end of the 512 bytes is still text
        text = head[:error.start].decode('utf-8') if error.start >= len(head) - 3 else None
    if text is not None and '\0' not in text:
        first_line = text.strip().splitlines()[0] if text.strip() else ''
        return f'a text file of {size} bytes (it begins {first_line[:40]!r})'
    return f'a binary file of {size} bytes without the MCAP magic'


def check_bag_path(bag: Path) -> None:
    """Raise BagReadError saying what ``bag`` is unless it is a rosbag2 bag directory or an MCAP file; the .mcap
    files of a directory must begin with the MCAP magic bytes (a recording cut short still does)."""
    if not bag.exists():
        raise BagReadError(f'{bag}: no such file or directory; {EXPECTED_BAG}')
    if bag.is_dir():
        if not ((bag / METADATA_FILE).is_file() or any(bag.glob('*.mcap'))):
            raise BagReadError(f'{bag}: a directory without {METADATA_FILE} or .mcap file, not a bag; {EXPECTED_BAG}')
        for path in sorted(bag.glob('*.mcap')):
            description = describe_file(path)
            if not description.startswith('an MCAP file'):
                raise BagReadError(f'{path}: {description}, not an MCAP file (every MCAP file begins with its '
                                   'magic bytes, even a recording cut short: recover cannot make one of it)')
        return
    if bag.name == METADATA_FILE and (bag.parent / METADATA_FILE).is_file():
        raise BagReadError(f'{bag}: the metadata file of a bag, not the bag; give its directory: {bag.parent}')
    description = describe_file(bag)
    if not description.startswith('an MCAP file'):
        raise BagReadError(f'{bag}: {description}, not a bag; {EXPECTED_BAG}')


def mcap_file(bag: str | Path) -> Path:
    """The MCAP file of a bag directory (or the file itself if ``bag`` is one)."""
    bag = Path(bag)
    if bag.is_file():
        return bag
    if not bag.is_dir():
        raise BagReadError(f'{bag}: no such bag (neither a bag directory nor an .mcap file)')
    if (bag / METADATA_FILE).is_file():
        information = read_metadata(bag)
        files = [bag / name for name in information.get('relative_file_paths') or []]
        if len(files) == 1 and files[0].suffix == '.mcap' and files[0].is_file():
            return files[0]
    files = sorted(bag.glob('*.mcap'))
    if len(files) != 1:
        raise BagReadError(f'{bag}: expected one .mcap file in the bag directory, found {len(files)}')
    return files[0]


def is_finalized(path: str | Path) -> bool:
    """True if the MCAP file ends with a footer and the closing magic (its recording was closed)."""
    path = Path(path)
    size = path.stat().st_size
    if size < len(MAGIC) * 2 + _FOOTER_SIZE:
        return False
    with path.open('rb') as stream:
        stream.seek(size - len(MAGIC) - _FOOTER_SIZE)
        tail = stream.read()
    return tail[-len(MAGIC):] == MAGIC and tail[0] == Opcode.FOOTER


class McapPrefix:
    """The readable prefix of an MCAP file, finalized or not: iterate :meth:`records`.

    After iterating, ``complete`` tells whether the data section ended properly (DataEnd reached)
    and ``stop_reason`` why reading stopped otherwise; ``valid_bytes`` is the offset after the
    last complete record.
    """

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.complete = False
        self.stop_reason = ''
        self.valid_bytes = 0

    def records(self) -> Iterator[McapRecord]:
        """Header, Schema, Channel, Metadata and Message records (messages of chunks unpacked), in file order."""
        with self.path.open('rb') as stream:
            if stream.read(len(MAGIC)) != MAGIC:
                raise BagReadError(f'{self.path}: not an MCAP file (bad magic)')
            self.valid_bytes = len(MAGIC)
            while True:
                head = stream.read(_RECORD_HEAD.size)
                if len(head) < _RECORD_HEAD.size:
                    self.stop_reason = 'file ends without a data-end record'
                    return
                opcode, length = _RECORD_HEAD.unpack(head)
                if opcode not in _KNOWN:
                    self.stop_reason = f'invalid record (opcode {opcode:#x}) at byte {self.valid_bytes}'
                    return
                body = stream.read(length)
                if len(body) < length:
                    self.stop_reason = f'record at byte {self.valid_bytes} is cut off'
                    return
                try:
                    records = self._parse(opcode, body)
                except Exception as error:   # corrupt content: any parser or decompressor error
                    self.stop_reason = f'corrupt record at byte {self.valid_bytes}: {error}'
                    return
                self.valid_bytes += _RECORD_HEAD.size + length
                if opcode == Opcode.DATA_END:
                    self.complete = True
                    return
                yield from records

    @staticmethod
    def _parse(opcode: int, body: bytes) -> list[McapRecord]:
        if opcode == Opcode.MESSAGE:
            return [Message.read(ReadDataStream(BytesIO(body)), len(body))]
        reader = _READERS.get(opcode)
        if reader is None:       # indexes, statistics, attachments: not needed to read the data
            return []
        record = reader(ReadDataStream(BytesIO(body)))
        if isinstance(record, Chunk):
            return breakup_chunk(record, validate_crc=True)
        return [record]


def read_custom_data(bag: str | Path) -> dict[str, str]:
    """The bag's custom data: ``metadata.yaml`` custom_data, else the last MCAP ``custom_data`` metadata
    record (the one written when the bag was closed)."""
    bag = Path(bag)
    if bag.is_dir() and (bag / METADATA_FILE).is_file():
        custom = read_metadata(bag).get('custom_data')
        if custom:
            return {str(k): str(v) for k, v in custom.items()}
    path = mcap_file(bag)
    if not is_finalized(path):
        return {}
    with path.open('rb') as stream:
        records = [record for record in make_reader(stream).iter_metadata() if record.name == CUSTOM_DATA_RECORD]
    return dict(records[-1].metadata) if records else {}
