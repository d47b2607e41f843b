"""The recorder's writer: a rosbag2 bag (MCAP storage) of contract topics, from serialized messages.

``BagWriter(path, topics)`` creates the bag directory, the MCAP file (profile ``ros2``, schemas
``ros2msg`` with the full message definition, channels ``cdr`` with offered QoS and RIHS01 type
hash) and a first ``metadata.yaml``, so even a killed recording is a recognisable bag (see
``recover``). Messages arrive as CDR bytes with their log and publish times [ns] (the embedded
backend stamps both with sim time; the ROS recorder passes the bytes it took from its raw
subscriptions). A write only appends to the open chunk: full chunks are compressed and written by
the MCAP file's background thread, so a writer never waits on the disk.

:meth:`close` writes the summary and the final ``metadata.yaml`` (counts, times). Message
definitions and type hashes come from the ``rosbags`` ROS 2 Jazzy typestore, whose RIHS01 hashes
equal those of the ROS 2 Jazzy interface packages (tested against their ``.json`` files).
"""
from __future__ import annotations

import errno
from pathlib import Path
from typing import Mapping, Sequence

from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Typestore

from quad_msgs_bridge.bag.metadata import (CUSTOM_DATA_RECORD, METADATA_FILE, ROS_DISTRO, TopicEntry, bagfile_information,
                           channel_metadata, information_yaml, offered_qos_profiles, write_metadata)
from quad_msgs_bridge.contract import DEFAULT_NAMESPACE, RECORDED_TOPICS, TopicSpec, resolve_all
from quad_msgs_bridge.bag.mcap_file import DEFAULT_CHUNK_SIZE, BagWriteError, McapFileWriter

def jazzy_typestore() -> Typestore:
    """The ``rosbags`` ROS 2 Jazzy typestore: message definitions, RIHS01 hashes, CDR."""
    return get_typestore(Stores.ROS2_JAZZY)


def cdr_as_sent(typestore: Typestore, message, msgtype: str) -> bytes:
    """``message`` (a ``typestore`` message object of ``msgtype``) as CDR bytes the way DDS carries them: the
    serialized payload padded with zeros to a multiple of 4 bytes (an RTPS serialized payload is 4-byte aligned;
    Fast DDS delivers a 3,491-byte ``robot_description`` as 3,492 bytes), so that what a node publishes, logs and
    a recorder receives are the same bytes, and an embedded flight's bag holds them too."""
    data = bytes(typestore.serialize_cdr(message, msgtype))
    return data + bytes(-len(data) % 4)


def _prepare_directory(path: Path, overwrite: bool) -> None:
    """Create the bag directory; an existing one must be empty, or a bag when ``overwrite``."""
    try:
        if path.exists():
            if not path.is_dir():
                raise BagWriteError(errno.EEXIST, 'bag path exists and is not a directory', str(path))
            entries = list(path.iterdir())
            is_bag = all(e.name == METADATA_FILE or e.suffix == '.mcap' for e in entries)
            if entries and not (overwrite and is_bag):
                raise BagWriteError(errno.EEXIST, 'bag directory exists and is not empty'
                                    + ('' if is_bag else ' (nor a bag)'), str(path))
            for entry in entries:
                entry.unlink()
        path.mkdir(parents=True, exist_ok=True)
    except BagWriteError:
        raise
    except OSError as error:
        raise BagWriteError(error.errno, f'cannot create bag directory: {error.strerror}', str(path)) from error


def bag_information(file: McapFileWriter, topics: Sequence[TopicEntry], channel_ids: Sequence[int],
                    custom_data: Mapping[str, str]) -> dict:
    """Bag information for the chunks ``file`` has written; ``channel_ids[i]`` records ``topics[i]``."""
    counts = file.message_counts()
    start, end = file.time_range()
    return bagfile_information(file.path.name, topics, [counts.get(c, 0) for c in channel_ids], start, end,
                               custom_data)


def write_bag_metadata(bag_dir: Path, information: dict) -> None:
    try:
        write_metadata(bag_dir, information)
    except OSError as error:
        raise BagWriteError(error.errno, f'cannot write bag metadata: {error.strerror}',
                            str(bag_dir / METADATA_FILE)) from error


def finish_bag(file: McapFileWriter, bag_dir: Path | None, topics: Sequence[TopicEntry],
               channel_ids: Sequence[int], custom_data: Mapping[str, str]) -> dict:
    """Finalize a bag: the open chunk, the final custom data record (what was added while recording,
    e.g. a failure, is kept by a lone MCAP file too: the last such record wins), a ``rosbag2`` metadata
    record (as rosbag2 writes it), the MCAP summary, then ``metadata.yaml`` in ``bag_dir`` (None: a
    lone MCAP file). Returns the bag information."""
    file.write_open_chunk()
    if custom_data:
        file.add_metadata(CUSTOM_DATA_RECORD, dict(custom_data))
    information = bag_information(file, topics, channel_ids, custom_data)
    file.add_metadata('rosbag2', {'serialized_metadata': information_yaml(information), 'ROS_DISTRO': ROS_DISTRO})
    file.close()
    if bag_dir is not None:
        write_bag_metadata(bag_dir, information)
    return information


class BagWriter:
    """A rosbag2 bag (directory, ``metadata.yaml``, one MCAP file) being recorded."""

    def __init__(self, path: str | Path, topics: Sequence[TopicSpec] = RECORDED_TOPICS,
                 namespace: str | Sequence[str] = DEFAULT_NAMESPACE, *,
                 custom_data: Mapping[str, str] | None = None,
                 overwrite: bool = False, chunk_size: int = DEFAULT_CHUNK_SIZE):
        """A bag of ``topics`` in ``namespace``, or in each of several (a fleet: one channel per vehicle
        and topic, ``/clock`` and ``/tf`` once)."""
        self.path = Path(path)
        self.custom_data = {str(k): str(v) for k, v in (custom_data or {}).items()}
        self.typestore = jazzy_typestore()
        self.closed = False
        _prepare_directory(self.path, overwrite)
        self._file = McapFileWriter(self.path / f'{self.path.resolve().name}_0.mcap', profile='ros2',
                                    chunk_size=chunk_size)
        self.topics: list[TopicEntry] = []
        self._types: dict[str, str] = {}
        self._channels: dict[str, int] = {}
        self._schemas: dict[str, int] = {}
        namespaces = [namespace] if isinstance(namespace, str) else namespace
        for name, spec in resolve_all(topics, namespaces):
            self.add_topic(name, spec)
        if self.custom_data:
            self._file.add_metadata(CUSTOM_DATA_RECORD, self.custom_data)
        self._file.flush()
        write_bag_metadata(self.path, bag_information(self._file, self.topics, list(self._channels.values()),
                                                      self.custom_data))

    def add_topic(self, name: str, spec: TopicSpec) -> None:
        """Record ``spec`` under the absolute ``name`` too (a channel with its schema, offered QoS and type hash);
        a topic already recorded is left as it is. The bag's ``metadata.yaml`` lists it from :meth:`close`."""
        if name in self._channels:
            return
        entry = TopicEntry(name, spec.type, offered_qos_profiles(spec.qos), self.typestore.hash_rihs01(spec.type))
        if spec.type not in self._schemas:
            msgdef, _ = self.typestore.generate_msgdef(spec.type, ros_version=2)
            self._schemas[spec.type] = self._file.add_schema(spec.type, 'ros2msg', msgdef.encode())
        self._channels[name] = self._file.add_channel(name, 'cdr', self._schemas[spec.type], channel_metadata(entry))
        self._types[name] = spec.type
        self.topics.append(entry)

    # --- writing ----------------------------------------------------------------------------
    def topic_names(self) -> list[str]:
        return list(self._channels)

    def write_serialized(self, topic: str, data: bytes, log_time_ns: int, publish_time_ns: int | None = None) -> None:
        """Record CDR bytes of ``topic`` (absolute name) at ``log_time_ns``; ``publish_time_ns`` defaults to it."""
        channel = self._channels.get(topic)
        if channel is None or self.closed:
            raise ValueError(f'bag {self.path} is closed' if self.closed else
                             f'topic {topic} is not recorded in bag {self.path} (topics: {", ".join(self._channels)})')
        self._file.add_message(channel, log_time_ns, log_time_ns if publish_time_ns is None else publish_time_ns,
                               data)

    def write_message(self, topic: str, msg, log_time_ns: int, publish_time_ns: int | None = None) -> None:
        """Record a ``rosbags`` message object (serialized here with the typestore, :func:`cdr_as_sent`)."""
        self.write_serialized(topic, cdr_as_sent(self.typestore, msg, self._types[topic]), log_time_ns,
                              publish_time_ns)

    # --- closing ------------------------------------------------------------------------------
    def close(self) -> None:
        """Finish the MCAP file and write the final ``metadata.yaml`` (with :attr:`custom_data` as it is
        now: a recorder may add to it until here). Idempotent.

        Raises BagWriteError if the bag could not be written, also if that was reported before
        (the MCAP file is then readable up to its last complete chunk; ``recover`` finalizes it).
        """
        if self.closed:
            return
        self.closed = True
        if self._file.error is not None:
            raise self._file.error
        finish_bag(self._file, self.path, self.topics, [self._channels[t.name] for t in self.topics],
                   self.custom_data)

    def __enter__(self) -> 'BagWriter':
        return self

    def __exit__(self, exc_type, exc, traceback) -> None:
        try:
            self.close()
        except BagWriteError:
            if not isinstance(exc, BagWriteError):   # the same failure is already on its way up
                raise
