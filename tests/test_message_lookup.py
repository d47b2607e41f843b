"""The rclpy message kit finds generated classes by importlib, as rosidl_runtime_py's get_message would (no ROS
needed: a stand-in message package laid out as rosidl generates them, 'pkg/msg/__init__.py' exporting the class)."""
from __future__ import annotations

import pytest

from quad_msgs_bridge.conversions import generated_message_class, rclpy_kit


@pytest.fixture
def fake_msgs(tmp_path, monkeypatch):
    package = tmp_path / 'lookup_test_msgs' / 'msg'
    package.mkdir(parents=True)
    (package.parent / '__init__.py').write_text('')
    (package / '__init__.py').write_text('class Thing:\n    pass\n')
    monkeypatch.syspath_prepend(str(tmp_path))
    yield
    import sys
    for name in ('lookup_test_msgs.msg', 'lookup_test_msgs'):
        sys.modules.pop(name, None)


def test_a_type_name_is_looked_up_as_package_dot_msg_dot_type(fake_msgs):
    import lookup_test_msgs.msg
    assert generated_message_class('lookup_test_msgs/msg/Thing') is lookup_test_msgs.msg.Thing
    assert rclpy_kit()['lookup_test_msgs/msg/Thing'] is lookup_test_msgs.msg.Thing


def test_a_missing_package_or_message_is_an_import_error_naming_it(fake_msgs):
    with pytest.raises(ModuleNotFoundError, match='no_such_msgs'):
        generated_message_class('no_such_msgs/msg/TFMessage')
    with pytest.raises(ImportError, match='lookup_test_msgs/msg/Missing is not installed'):
        generated_message_class('lookup_test_msgs/msg/Missing')


@pytest.mark.parametrize('name', ['nav_msgs/Odometry', 'nav_msgs/srv/Odometry', 'nav_msgs/msg/Odo metry',
                                  'nav_msgs/msg/', '', 'a/b/c/d', None])
def test_a_malformed_type_name_is_a_value_error_naming_the_argument(name):
    with pytest.raises(ValueError, match='type_name'):
        generated_message_class(name)
