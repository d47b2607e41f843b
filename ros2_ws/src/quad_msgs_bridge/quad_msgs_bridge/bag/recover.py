"""recover BAG: finalize a bag whose recording was killed (SIGKILL, power loss, full disk).

The readable prefix of the MCAP file (every complete, CRC-valid chunk) is rewritten into a finalized
file with a summary, which then replaces the original; a bag directory gets a metadata.yaml with the
true counts. Memory stays within two chunks (the one being read and the one being written).
"""
from __future__ import annotations

import argparse
import os
import sys
from dataclasses import dataclass
from pathlib import Path

from mcap.records import Channel, Header, Message, Metadata, Schema

from quad_msgs_bridge.bag.metadata import CUSTOM_DATA_RECORD, topic_from_channel
from quad_msgs_bridge.bag.reader import BagReadError, McapPrefix, describe_file, is_finalized, mcap_file
from quad_msgs_bridge.bag.writer import finish_bag
from quad_msgs_bridge.bag.mcap_file import McapFileWriter


@dataclass
class Recovery:
    path: Path                 #: the MCAP file, now finalized
    messages: int              #: messages kept
    dropped_bytes: int         #: bytes after the last complete record (a partial chunk)
    stop_reason: str           #: why reading stopped


def recover(bag: str | Path) -> Recovery:
    """Rewrite the bag's MCAP file (and ``metadata.yaml``) into a finalized bag; see the module doc.

    The original file is kept as ``<name>.killed`` while the new one is written and removed after.
    """
    bag = Path(bag)
    target = mcap_file(bag)
    description = describe_file(target)
    if not description.startswith('an MCAP file'):
        raise BagReadError(f'{target}: {description}, not an MCAP file; recover finalizes the MCAP file '
                           '(or the bag directory) of a killed recording')
    if is_finalized(target):
        raise BagReadError(f'{target}: already finalized, nothing to recover')
    source = target.with_name(target.name + '.killed')
    os.replace(target, source)
    prefix = McapPrefix(source)
    writer = None
    schemas: dict[int, Schema] = {}
    schema_ids: dict[int, int] = {}
    channel_ids: dict[int, int] = {}
    topics, custom_data, messages = [], {}, 0
    try:
        for record in prefix.records():
            if isinstance(record, Header):
                writer = McapFileWriter(target, profile=record.profile)
            elif writer is None:
                raise BagReadError(f'{target}: no MCAP header record')
            elif isinstance(record, Schema) and record.id not in schema_ids:
                schemas[record.id] = record
                schema_ids[record.id] = writer.add_schema(record.name, record.encoding, record.data)
            elif isinstance(record, Channel) and record.id not in channel_ids:
                channel_ids[record.id] = writer.add_channel(record.topic, record.message_encoding,
                                                            schema_ids.get(record.schema_id, 0), record.metadata)
                schema = schemas.get(record.schema_id)
                topics.append(topic_from_channel(record.topic, schema.name if schema else '', record.metadata,
                                                 record.message_encoding))
            elif isinstance(record, Metadata) and record.name != 'rosbag2':
                writer.add_metadata(record.name, record.metadata)
                if record.name == CUSTOM_DATA_RECORD:
                    custom_data = dict(record.metadata)
            elif isinstance(record, Message) and record.channel_id in channel_ids:
                writer.add_message(channel_ids[record.channel_id], record.log_time, record.publish_time, record.data)
                messages += 1
        if writer is None:
            raise BagReadError(f'{target}: no MCAP header record ({prefix.stop_reason})')
        finish_bag(writer, bag if bag.is_dir() else None, topics, list(channel_ids.values()), custom_data)
    except BaseException:
        if writer is not None:
            writer.abandon()
        os.replace(source, target)
        raise
    dropped = source.stat().st_size - prefix.valid_bytes
    source.unlink()
    return Recovery(target, messages, dropped, prefix.stop_reason)


def recover_main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog='recover', description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('bag', type=Path, help='bag directory (or .mcap file) of a killed recording')
    args = parser.parse_args(argv)
    try:
        result = recover(args.bag)
    except (BagReadError, OSError) as error:   # BagReadError: not a recoverable bag (wrong input)
        print(f'error: {error}', file=sys.stderr)
        return 2 if isinstance(error, BagReadError) else 1
    print(f'recovered {result.messages} messages into {result.path}'
          + (f'; dropped {result.dropped_bytes} bytes of an incomplete chunk ({result.stop_reason})'
             if result.dropped_bytes else ''))
    return 0


if __name__ == '__main__':
    sys.exit(recover_main())
