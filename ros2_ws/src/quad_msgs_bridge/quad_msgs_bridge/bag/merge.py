"""One bag from the part bags of a flight's publication logs (see ``publication_log``).

Each part holds what one node published, in the order it published it, its log times (sim time) never
decreasing. The merge streams every part at once and writes the messages into one rosbag2 bag in the
order of (log time, publish time): a step's /clock and odometry before the controllers' answers to it,
each topic in its publisher's order. Memory stays within a few chunks per part. A part a killed node
left unfinished is read up to its last complete chunk, and the merge says so; nothing is written twice.
"""
from __future__ import annotations

import argparse
import heapq
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator, Mapping, Sequence

from mcap.records import Channel, Message

from quad_msgs_bridge.bag.reader import BagReadError, McapPrefix, mcap_file
from quad_msgs_bridge.bag.writer import BagWriter
from quad_msgs_bridge.contract import RECORDED_TOPICS, TopicSpec


@dataclass
class MergeResult:
    messages: int                                            #: messages written into the bag
    parts: list[str] = field(default_factory=list)           #: the parts merged (their directory names)
    cut: dict[str, str] = field(default_factory=dict)        #: part -> why it ends early (a killed node's)
    not_recorded: dict[str, int] = field(default_factory=dict)   #: topic -> messages of a topic not in the bag


def part_bags(record_dir: str | Path) -> list[Path]:
    """The part bags in ``record_dir`` (each a directory holding an MCAP file), by name."""
    return sorted(path for path in Path(record_dir).iterdir() if path.is_dir())


def _part_messages(index: int, prefix: McapPrefix) -> Iterator[tuple[int, int, int, int, str, bytes]]:
    """(log time, publish time, part index, position in the part, topic, CDR bytes) of each message of a part."""
    topics: dict[int, str] = {}
    position = 0
    for record in prefix.records():
        if isinstance(record, Channel):
            topics[record.id] = record.topic
        elif isinstance(record, Message):
            yield record.log_time, record.publish_time, index, position, topics[record.channel_id], record.data
            position += 1


def contract_topic(name: str) -> TopicSpec | None:
    """The contract topic recorded under the absolute ``name`` (in any namespace), or None."""
    for spec in RECORDED_TOPICS:
        if name == spec.name or (not spec.name.startswith('/') and name.endswith('/' + spec.name)):
            return spec
    return None


def merge_parts(record_dir: str | Path, bag: str | Path, topics: Sequence[TopicSpec] | None = None,
                namespaces: str | Sequence[str] = (), custom_data: Mapping[str, str] | None = None,
                overwrite: bool = False) -> MergeResult:
    """Write the messages of every part bag in ``record_dir`` into the new bag ``bag``, in the order of (log time,
    publish time). The bag records ``topics`` in ``namespaces`` (as ``BagWriter``; a message of another topic is
    counted in ``not_recorded``, not written), or with ``topics`` None every contract topic the parts hold.
    Raises BagReadError if a part is no MCAP file."""
    parts = part_bags(record_dir)
    prefixes = [McapPrefix(mcap_file(part)) for part in parts]
    result = MergeResult(0, [part.name for part in parts])
    with BagWriter(bag, topics or (), namespaces, custom_data=custom_data, overwrite=overwrite) as writer:
        recorded = set(writer.topic_names())
        streams = [_part_messages(index, prefix) for index, prefix in enumerate(prefixes)]
        for log_time, publish_time, _, _, topic, data in heapq.merge(*streams):
            if topic not in recorded and topics is None and (spec := contract_topic(topic)) is not None:
                writer.add_topic(topic, spec)
                recorded.add(topic)
            if topic in recorded:
                writer.write_serialized(topic, data, log_time, publish_time)
                result.messages += 1
            else:
                result.not_recorded[topic] = result.not_recorded.get(topic, 0) + 1
    for part, prefix in zip(parts, prefixes):
        if not prefix.complete:
            result.cut[part.name] = prefix.stop_reason or 'unreadable'
    return result


def merge_main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog='merge', description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('record_dir', type=Path, help='the record_dir the nodes were started with')
    parser.add_argument('bag', type=Path, help='bag directory to create')
    parser.add_argument('--overwrite', action='store_true', help='replace an existing bag at the same path')
    args = parser.parse_args(argv)
    try:
        result = merge_parts(args.record_dir, args.bag, overwrite=args.overwrite)
    except (BagReadError, OSError) as error:
        print(f'error: {error}', file=sys.stderr)
        return 2 if isinstance(error, BagReadError) else 1
    print(f'merged {result.messages} messages of {len(result.parts)} parts into {args.bag}')
    for part, reason in result.cut.items():
        print(f'part {part} ends early (a killed node?): {reason}; its complete chunks are merged')
    for topic, count in result.not_recorded.items():
        print(f'{count} messages of {topic} (not a contract topic) left out')
    return 0


if __name__ == '__main__':
    sys.exit(merge_main())
