"""colcon test: the installed bridge package carries its vehicle description and contract."""
from quad_msgs_bridge.contract import ALL_TOPICS, resolve
from quad_msgs_bridge.vehicle_params import DEFAULT_VEHICLE_FILE, load_vehicle_file


def test_packaged_vehicle_file_loads():
    params, disturbances = load_vehicle_file()
    assert DEFAULT_VEHICLE_FILE.exists()
    assert 4 * params.F_max > params.m * params.g
    assert disturbances.enabled


def test_contract_topic_names_are_unique_per_namespace():
    names = [resolve(topic, 'quad') for topic in ALL_TOPICS]
    assert len(set(names)) == len(names)
    assert resolve(ALL_TOPICS[0], 'quad').startswith('/quad/')
