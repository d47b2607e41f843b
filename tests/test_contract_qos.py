"""QoS of the contract's per-step topics: a recorder that the lockstep does not wait for loses nothing."""
import yaml

from quad_msgs_bridge.bag.metadata import rosbag2_qos_overrides
from quad_msgs_bridge.contract import ALL_TOPICS, CLOCK, LOCKSTEP, ODOM


def test_clock_keeps_the_history_of_the_other_per_step_topics():
    """Issue 20: with keep-last 10, `ros2 bag record` on a loaded machine kept 5,967 of 6,000 /clock messages
    (every other topic, at depth 1000, whole): /clock is published and recorded with the lockstep depth."""
    assert CLOCK.qos == ODOM.qos == LOCKSTEP and LOCKSTEP.depth >= 1000
    per_step = [t for t in ALL_TOPICS if t.qos.durability == 'volatile' and t.name not in ('goal_pose', '/tf')]
    assert CLOCK in per_step and {t.qos for t in per_step} == {LOCKSTEP}
    overrides = yaml.safe_load(rosbag2_qos_overrides(['uav1']))
    assert overrides['/clock'] == overrides['/uav1/odom']
    assert (overrides['/clock']['reliability'], overrides['/clock']['depth']) == ('reliable', LOCKSTEP.depth)
