"""The merge of the nodes' publication logs into one bag (quad_msgs_bridge.bag.merge): order, bytes, a killed
node's part, and what an independent reader (rosbags) makes of the result. No ROS needed."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader

from quad_msgs_bridge.bag.merge import merge_parts, merge_main
from quad_msgs_bridge.bag.reader import mcap_file
from quad_msgs_bridge.bag.writer import BagWriter
from quad_msgs_bridge.contract import CLOCK, CONTROL_WRENCH, ROTOR_FORCES
from quad_msgs_bridge.fast_cdr import clock_encoder, rotor_forces_encoder, wrench_encoder

STEP_NS = 1_000_000   #: [ns, sim] one control step


def write_part(path: Path, messages, chunk_size: int = 1 << 20) -> None:
    """A part bag as a node's publication log writes it: ``messages`` [(topic name, spec, bytes, log, publish)]."""
    writer = BagWriter(path, (), overwrite=True, chunk_size=chunk_size)
    for name, spec, data, log_time, publish_time in messages:
        writer.add_topic(name, spec)
        writer.write_serialized(name, data, log_time, publish_time)
    writer.close()


def flight_parts(record_dir: Path, steps: int, chunk_size: int = 1 << 20) -> dict[str, list]:
    """A simulator's part (/clock per step) and a controller's (rotor_forces per step, published after the
    simulator's /clock of the same step and, every third step, after the next /clock too: a late answer).
    Returns {topic: [bytes in publication order]}."""
    clock, forces = clock_encoder(), rotor_forces_encoder()
    sim, controller = [], []
    for k in range(steps):
        published = 10 * k     # [ns, wall]
        sim.append((CLOCK.name, CLOCK, clock(0, k * STEP_NS), k * STEP_NS, published))
        late = 15 if k % 3 == 0 else 5
        controller.append(('/quad/rotor_forces', ROTOR_FORCES, forces((float(k), 1.0, 2.0, 3.0)), k * STEP_NS,
                           published + late))
    write_part(record_dir / 'quad.quad_sim', sim, chunk_size)
    write_part(record_dir / 'quad.nnit2fsmc_controller', controller, chunk_size)
    return {CLOCK.name: [m[2] for m in sim], '/quad/rotor_forces': [m[2] for m in controller]}


def read(bag: Path) -> list[tuple[str, int, int, bytes]]:
    """(topic, log time, publish time, bytes) of each message in the file's order (the mcap package's reader)."""
    with open(mcap_file(bag), 'rb') as stream:
        return [(channel.topic, m.log_time, m.publish_time, m.data)
                for _, channel, m in make_reader(stream).iter_messages(log_time_order=False)]


def test_the_merged_bag_orders_every_step_by_sim_time_then_by_publication_and_keeps_the_bytes(tmp_path):
    sent = flight_parts(tmp_path / 'parts', steps=300)
    result = merge_parts(tmp_path / 'parts', tmp_path / 'bag', [CLOCK, ROTOR_FORCES], '/quad',
                         custom_data={'controller': 'test'})
    assert result.messages == 600 and not result.cut and not result.not_recorded
    messages = read(tmp_path / 'bag')
    # step by step: the step's /clock, then the answer to it, even where the answer went out after the next /clock
    assert [(topic, log) for topic, log, _, _ in messages] == \
        [pair for k in range(300) for pair in ((CLOCK.name, k * STEP_NS), ('/quad/rotor_forces', k * STEP_NS))]
    for topic, data in sent.items():
        assert [m[3] for m in messages if m[0] == topic] == data, topic
    with AnyReader([tmp_path / 'bag']) as reader:    # an independent reader: the bag is a rosbag2 bag
        assert {c.topic: c.msgcount for c in reader.connections} == {CLOCK.name: 300, '/quad/rotor_forces': 300}
        first = next(reader.messages())
        assert reader.deserialize(first[2], first[0].msgtype).clock.sec == 0


def test_a_part_cut_by_a_killed_node_is_merged_up_to_its_last_complete_chunk_and_named(tmp_path):
    sent = flight_parts(tmp_path / 'parts', steps=3000, chunk_size=8 * 1024)
    controller = mcap_file(tmp_path / 'parts' / 'quad.nnit2fsmc_controller')
    data = controller.read_bytes()
    controller.write_bytes(data[:len(data) // 2])          # the node was killed half-way through its flight
    result = merge_parts(tmp_path / 'parts', tmp_path / 'bag', [CLOCK, ROTOR_FORCES], '/quad')
    assert list(result.cut) == ['quad.nnit2fsmc_controller']
    messages = read(tmp_path / 'bag')
    answers = [m[3] for m in messages if m[0] == '/quad/rotor_forces']
    assert 500 < len(answers) < 3000 and answers == sent['/quad/rotor_forces'][:len(answers)]   # a prefix
    assert [m[3] for m in messages if m[0] == CLOCK.name] == sent[CLOCK.name]   # the simulator's part: all of it
    assert result.messages == len(messages)


def test_without_topics_the_bag_records_the_contract_topics_the_parts_hold_and_leaves_others_out(tmp_path):
    foreign = replace(CLOCK, name='chatter')
    write_part(tmp_path / 'parts' / 'a', [(CLOCK.name, CLOCK, clock_encoder()(0, 0), 0, 1),
                                          ('/uav1/chatter', foreign, clock_encoder()(0, 0), 0, 2)])
    write_part(tmp_path / 'parts' / 'b', [('/uav1/control/wrench', CONTROL_WRENCH,
                                           wrench_encoder(0.2)(0, 0, (1.0, 2.0, 3.0, 4.0)), 0, 3)])
    result = merge_parts(tmp_path / 'parts', tmp_path / 'bag')
    assert result.not_recorded == {'/uav1/chatter': 1}
    assert [m[0] for m in read(tmp_path / 'bag')] == [CLOCK.name, '/uav1/control/wrench']
    with AnyReader([tmp_path / 'bag']) as reader:
        assert {c.topic: c.msgtype for c in reader.connections} == {CLOCK.name: CLOCK.type,
                                                                    '/uav1/control/wrench': CONTROL_WRENCH.type}
        wrench = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages() if c.topic.endswith('wrench')]
        assert wrench[0].wrench.force.z == 1.0 and wrench[0].wrench.torque.z == 4.0


def test_the_merge_command_merges_and_refuses_a_part_that_is_no_mcap_file(tmp_path, capsys):
    flight_parts(tmp_path / 'parts', steps=10)
    assert merge_main([str(tmp_path / 'parts'), str(tmp_path / 'bag')]) == 0
    assert 'merged 20 messages of 2 parts' in capsys.readouterr().out
    assert merge_main([str(tmp_path / 'parts'), str(tmp_path / 'bag')]) == 1     # the bag exists: not replaced
    assert 'not empty' in capsys.readouterr().err
    mcap_file(tmp_path / 'parts' / 'quad.quad_sim').write_bytes(b'not an mcap file')
    assert merge_main([str(tmp_path / 'parts'), str(tmp_path / 'bag2')]) == 2
    assert 'not an MCAP file' in capsys.readouterr().err



class Sent:
    """A stand-in for an rclpy publisher (no ROS here): its topic name and what it was given."""

    def __init__(self, topic_name: str):
        self.topic_name = topic_name
        self.sent = []

    def publish(self, data):
        self.sent.append(data)

    def get_subscription_count(self) -> int:
        return 7


def test_a_recording_publisher_publishes_and_logs_the_same_bytes_at_the_sim_time_and_refuses_message_objects(tmp_path):
    from quad_msgs_bridge.bag.publication_log import PublicationLog, part_path
    sim_time = [0]
    log = PublicationLog(part_path(tmp_path / 'parts', '/quad/quad_sim'), lambda: sim_time[0])
    publisher = Sent(CLOCK.name)
    clock = log.recording(publisher, CLOCK)
    encode = clock_encoder()
    for k in range(5):
        sim_time[0] = k * STEP_NS
        clock.publish(encode(0, k * STEP_NS))
    with pytest.raises(TypeError, match='publishes CDR bytes'):
        clock.publish(object())
    assert clock.get_subscription_count() == 7          # the rest is the publisher's
    log.close()
    assert (tmp_path / 'parts' / 'quad.quad_sim').is_dir()
    logged = read(tmp_path / 'parts' / 'quad.quad_sim')
    assert [m[3] for m in logged] == publisher.sent and len(publisher.sent) == 5
    assert [m[1] for m in logged] == [k * STEP_NS for k in range(5)]
