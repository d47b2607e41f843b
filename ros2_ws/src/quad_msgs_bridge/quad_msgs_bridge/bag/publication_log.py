"""A node that records what it publishes: the cheap way to a bag of the stack's own flight.

A recorder process is one more DDS reader of every per-step topic: the simulator and the controllers then
deliver every message twice and take its acknowledgements, which nearly doubled their CPU per step here
(docs/BAGS.md). A publication log costs a publisher one append to an MCAP chunk per message instead: each
node of the stack started with ``record_dir`` writes the CDR bytes it publishes, as it publishes them, into
its own part bag ``<record_dir>/<node>`` (a rosbag2 directory; chunks are compressed and written by the
file's background thread). ``merge_parts`` then makes one bag of the parts after the flight.

Times of a logged message: the publish time is the wall time of the publish call; the log time is the sim
time of the step the node publishes for (the simulator: its own; a controller: the stamp of the odometry it
answers; the trajectory node: its clock under use_sim_time, else 0: it publishes its path once, before the
flight). A node stopped by a signal closes its part; a killed node's part keeps its complete chunks, which
the merge reads as they are.

It records only what this stack's nodes publish; the ``record`` node stays for topics other tools publish.
"""
from __future__ import annotations

import re
import time
from pathlib import Path
from typing import Callable

from quad_msgs_bridge.bag.writer import BagWriter
from quad_msgs_bridge.contract import TopicSpec


def part_path(record_dir: str | Path, node_name: str) -> Path:
    """The part bag of the node with the fully qualified ``node_name`` (``/uav1/nnit2fsmc_controller`` ->
    ``<record_dir>/uav1.nnit2fsmc_controller``)."""
    return Path(record_dir) / re.sub(r'[^A-Za-z0-9_]+', '.', node_name.strip('/'))


#: uncompressed bytes per chunk of a part bag: a killed node loses at most its open chunk, here about 0.1 s of a
#: controller's answers at 1 kHz (a recorder's 1 MiB chunk would be 1.7 s)
LOG_CHUNK_SIZE = 64 * 1024


class PublicationLog:
    """One node's part bag: what it publishes on contract topics, with the sim time it publishes for."""

    def __init__(self, path: str | Path, sim_time_ns: Callable[[], int]):
        """``sim_time_ns()``: the log time [ns, sim] of a message published now."""
        self.writer = BagWriter(path, (), overwrite=True, chunk_size=LOG_CHUNK_SIZE)
        self.sim_time_ns = sim_time_ns

    def recording(self, publisher, topic: TopicSpec) -> 'RecordingPublisher':
        """``publisher`` (of ``topic``) made to log what it publishes."""
        self.writer.add_topic(publisher.topic_name, topic)
        return RecordingPublisher(publisher, self)

    def close(self) -> None:
        self.writer.close()


class RecordingPublisher:
    """An rclpy publisher that logs each message it publishes: the CDR bytes as sent. It takes serialized messages
    only (the bridge's encoders, or a typestore's): rclpy's own serialize_message on Fast DDS leaves the alignment
    padding uninitialised, so its bytes would differ between two identical flights. Everything else is the
    publisher's."""

    def __init__(self, publisher, log: PublicationLog):
        self._publisher = publisher
        self._log = log
        self._name = publisher.topic_name

    def publish(self, message: bytes) -> None:
        if not isinstance(message, bytes):
            raise TypeError(f'{self._name}: a recording publisher publishes CDR bytes, not {type(message).__name__}')
        self._publisher.publish(message)
        self._log.writer.write_serialized(self._name, message, self._log.sim_time_ns(), time.time_ns())

    def __getattr__(self, name):
        return getattr(self._publisher, name)
