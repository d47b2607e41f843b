"""Real message timing of a flight recorded from ROS topics: loop rate and odometry-to-force latency.

The recorder stores each message's publish time (the publisher's wall clock, DDS source timestamp).
``control/wrench`` carries the stamp of the odometry it answers and pairs by order with
``rotor_forces`` (published just before it, see :mod:`.contract`), so for every answer

    latency = publish time of the rotor_forces - publish time of the odometry it answers.

Bags written by the embedded backend have sim-time publish times; their figures are meaningless
and :func:`message_timing` is for bags recorded from a ROS flight.
"""
from __future__ import annotations

import statistics
from pathlib import Path

from mcap.reader import make_reader

from quad_msgs_bridge.bag.reader import mcap_file
from quad_msgs_bridge.contract import CONTROL_WRENCH, ODOM, ROTOR_FORCES, resolve
from quad_msgs_bridge.timebase import NANOSECONDS_PER_SECOND


def _stamp_ns(cdr: bytes) -> int:
    """Header stamp of a CDR message whose first field is a std_msgs/Header (after the 4-byte encapsulation)."""
    sec = int.from_bytes(cdr[4:8], 'little', signed=True)
    return sec * NANOSECONDS_PER_SECOND + int.from_bytes(cdr[8:12], 'little')


def message_timing(bag: str | Path, namespace: str) -> dict:
    """{'odometry_rate_hz', 'answered', 'latency_median_ms', 'latency_p99_ms'} from the publish times."""
    names = {resolve(t, namespace): t for t in (ODOM, ROTOR_FORCES, CONTROL_WRENCH)}
    odom_published: dict[int, int] = {}
    forces_published: list[int] = []
    answered_stamps: list[int] = []
    with open(mcap_file(bag), 'rb') as stream:
        for _, channel, message in make_reader(stream).iter_messages(topics=list(names)):
            topic = names[channel.topic]
            if topic is ODOM:
                odom_published[_stamp_ns(message.data)] = message.publish_time
            elif topic is ROTOR_FORCES:
                forces_published.append(message.publish_time)
            else:
                answered_stamps.append(_stamp_ns(message.data))
    if len(odom_published) < 2:
        raise ValueError(f'{bag}: fewer than two odometry messages, no timing')
    span = (max(odom_published.values()) - min(odom_published.values())) / NANOSECONDS_PER_SECOND
    latencies = sorted((sent - odom_published[stamp]) / 1e6
                       for sent, stamp in zip(forces_published, answered_stamps) if stamp in odom_published)
    timing = {'odometry_rate_hz': (len(odom_published) - 1) / span if span > 0 else None, 'answered': len(latencies)}
    if latencies:
        timing['latency_median_ms'] = statistics.median(latencies)
        timing['latency_p99_ms'] = latencies[min(len(latencies) - 1, int(0.99 * len(latencies)))]
    return timing
