"""rosbag2 bag metadata as ROS 2 Jazzy writes it: ``metadata.yaml`` (version 9) and offered-QoS YAML.

A bag is a directory holding ``metadata.yaml`` and its storage file(s); ours has one MCAP file.
The offered QoS of a topic appears twice: as a YAML list in ``metadata.yaml`` and as the same list
serialized to a YAML string in the MCAP channel metadata (``offered_qos_profiles``), next to the
type hash (``topic_type_hash``, RIHS01).
"""
from __future__ import annotations

import argparse
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Sequence

import yaml

from quad_msgs_bridge.contract import DEFAULT_NAMESPACE, RECORDED_TOPICS, QosSpec, TopicSpec, resolve_all

METADATA_FILE = 'metadata.yaml'
BAG_VERSION = 9
ROS_DISTRO = 'jazzy'
#: MCAP metadata record holding the bag's custom data (so a lone .mcap file keeps it)
CUSTOM_DATA_RECORD = 'custom_data'
#: RMW_DURATION_INFINITE, what a publisher with default deadline/lifespan/lease offers
_INFINITE = {'sec': 9223372036, 'nsec': 854775807}


class _PlainDumper(yaml.SafeDumper):
    """Writes repeated mappings out in full (no YAML anchors), as rosbag2 does."""

    def ignore_aliases(self, data) -> bool:
        return True


def _dump(data) -> str:
    return yaml.dump(data, Dumper=_PlainDumper, sort_keys=False)


@dataclass(frozen=True)
class TopicEntry:
    """One recorded topic as the metadata describes it."""

    name: str                      #: absolute topic name
    type: str                      #: e.g. 'nav_msgs/msg/Odometry'
    offered_qos: list              #: offered QoS profiles, see :func:`offered_qos_profiles`
    type_hash: str                 #: 'RIHS01_<sha256 hex>'
    serialization_format: str = 'cdr'


def offered_qos_profiles(qos: QosSpec) -> list[dict]:
    """The offered QoS list of one publisher with profile ``qos`` (rosbag2 metadata version 9 form)."""
    return [{
        'history': 'keep_last',
        'depth': qos.depth,
        'reliability': qos.reliability,
        'durability': qos.durability,
        'deadline': dict(_INFINITE),
        'lifespan': dict(_INFINITE),
        'liveliness': 'automatic',
        'liveliness_lease_duration': dict(_INFINITE),
        'avoid_ros_namespace_conventions': False,
    }]


def rosbag2_qos_overrides(namespaces: Sequence[str], topics: Sequence[TopicSpec] = RECORDED_TOPICS) -> str:
    """YAML for ``ros2 bag record --qos-profile-overrides-path``: each topic of each vehicle with its contract QoS.

    rosbag2 subscribes with a history of 10 messages; at lockstep rates (about 2000 steps/s) its
    reader then drops some (seen here: 119 of 6000 odometry messages of one flight). With the
    contract's history depth (1000 per-step) it records every message.
    """
    return _dump({name: offered_qos_profiles(topic.qos)[0] for name, topic in resolve_all(topics, namespaces)})


def qos_overrides_main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog='rosbag2-qos', description='Print the QoS overrides that let `ros2 bag record` keep up with a '
        'lockstep flight: ros2 bag record -s mcap --qos-profile-overrides-path FILE TOPIC ...')
    parser.add_argument('--namespace', nargs='+', default=[DEFAULT_NAMESPACE],
                        help='vehicle namespace(s) (default %(default)s; a fleet: uav1 uav2 ...)')
    print(rosbag2_qos_overrides(parser.parse_args(argv).namespace), end='')
    return 0


def channel_metadata(topic: TopicEntry) -> dict[str, str]:
    """MCAP channel metadata of a topic, as rosbag2's MCAP storage plugin writes it."""
    return {'offered_qos_profiles': _dump(topic.offered_qos),
            'topic_type_hash': topic.type_hash}


def topic_from_channel(topic: str, type_name: str, metadata: Mapping[str, str], encoding: str) -> TopicEntry:
    """Inverse of :func:`channel_metadata`: the entry of an MCAP channel (missing fields left empty)."""
    return TopicEntry(topic, type_name, yaml.safe_load(metadata.get('offered_qos_profiles') or '[]') or [],
                      metadata.get('topic_type_hash', ''), encoding)


def bagfile_information(file_name: str, topics: Sequence[TopicEntry], counts: Sequence[int],
                        start_ns: int, end_ns: int, custom_data: Mapping[str, str]) -> dict:
    """The ``rosbag2_bagfile_information`` mapping; times are message log times [ns]."""
    total = sum(counts)
    duration = {'nanoseconds': max(0, end_ns - start_ns)}
    starting_time = {'nanoseconds_since_epoch': start_ns}
    return {
        'version': BAG_VERSION,
        'storage_identifier': 'mcap',
        'duration': duration,
        'starting_time': starting_time,
        'message_count': total,
        'topics_with_message_count': [
            {'topic_metadata': {'name': topic.name, 'type': topic.type,
                                'serialization_format': topic.serialization_format,
                                'offered_qos_profiles': topic.offered_qos,
                                'type_description_hash': topic.type_hash},
             'message_count': count}
            for topic, count in zip(topics, counts)],
        'compression_format': '',   # MCAP compresses chunks itself; rosbag2 file compression is off
        'compression_mode': '',
        'relative_file_paths': [file_name],
        'files': [{'path': file_name, 'starting_time': starting_time, 'duration': duration,
                   'message_count': total}],
        'custom_data': dict(custom_data) or None,
        'ros_distro': ROS_DISTRO,
    }


def information_yaml(information: dict) -> str:
    return _dump(information)


def write_metadata(bag_dir: Path, information: dict) -> Path:
    """Write ``metadata.yaml`` atomically (a reader never sees half a file)."""
    path = Path(bag_dir) / METADATA_FILE
    temporary = path.with_name(METADATA_FILE + '.tmp')
    temporary.write_text(_dump({'rosbag2_bagfile_information': information}))
    os.replace(temporary, path)
    return path


def read_metadata(bag_dir: Path) -> dict:
    """The ``rosbag2_bagfile_information`` mapping of a bag directory."""
    path = Path(bag_dir) / METADATA_FILE
    information = yaml.load(path.read_text(), Loader=getattr(yaml, 'CSafeLoader', yaml.SafeLoader))   # C: 10x faster
    if not isinstance(information, dict) or 'rosbag2_bagfile_information' not in information:
        raise ValueError(f'{path}: not a rosbag2 metadata file')
    return information['rosbag2_bagfile_information']

