"""Schema texts built like rosbag2's MCAP storage, and where the ``.msg`` files are found."""

import os
from pathlib import Path
import re
import sys

import pytest

from sensor_comp.io.msgdefs import message_definition, MessageDefinitionError, msg_file, type_hash

DELIMITER = '\n' + '=' * 80 + '\nMSG: '


def sections(text):
    """Split a schema text into (type, text) sections; the root has type None."""
    parts = text.split(DELIMITER)
    result = [(None, parts[0])]
    for part in parts[1:]:
        name, _, body = part.partition('\n')
        result.append((name, body))
    return result


def installed(name):
    """Return the installed .msg text of 'pkg/Type', read without sensor_comp."""
    package, msg = name.split('/')
    return msg_file(f'{package}/msg/{msg}').read_text()


def test_image_is_its_msg_text_then_header_then_time():
    parts = sections(message_definition('sensor_msgs/msg/Image'))
    assert parts[0][1] == installed('sensor_msgs/Image')
    assert [name for name, _ in parts[1:]] == ['std_msgs/Header', 'builtin_interfaces/Time']
    for name, body in parts[1:]:
        assert body == installed(name)


def test_diagnostic_array_dependencies_are_sorted_depth_first_each_once():
    names = [name for name, _ in sections(
        message_definition('diagnostic_msgs/msg/DiagnosticArray'))[1:]]
    # DiagnosticArray uses DiagnosticStatus (which uses KeyValue) and std_msgs/Header (which
    # uses Time): sorted by name, each followed by its own dependencies.
    assert names == ['diagnostic_msgs/DiagnosticStatus', 'diagnostic_msgs/KeyValue',
                     'std_msgs/Header', 'builtin_interfaces/Time']


def test_a_type_used_twice_appears_once():
    # TransformStamped -> Header, Transform -> Vector3, Quaternion; Time only via Header.
    names = [name for name, _ in sections(
        message_definition('geometry_msgs/msg/TransformStamped'))[1:]]
    assert len(names) == len(set(names))
    assert names.index('builtin_interfaces/Time') == names.index('std_msgs/Header') + 1


def test_string_has_no_dependency():
    assert message_definition('std_msgs/msg/String') == installed('std_msgs/String')


def test_definition_is_cached():
    assert message_definition('sensor_msgs/msg/Image') is \
        message_definition('sensor_msgs/msg/Image')


def test_without_ament_prefix_path_the_interpreter_prefix_is_searched(monkeypatch):
    monkeypatch.delenv('AMENT_PREFIX_PATH', raising=False)
    assert msg_file('std_msgs/msg/String') == \
        Path(sys.prefix) / 'share/std_msgs/msg/String.msg'


def test_ament_prefix_path_is_searched_through_the_ament_index(monkeypatch, tmp_path):
    share = tmp_path / 'share'
    (share / 'ament_index/resource_index/packages').mkdir(parents=True)
    (share / 'ament_index/resource_index/packages/my_msgs').touch()
    (share / 'my_msgs/msg').mkdir(parents=True)
    (share / 'my_msgs/msg/Thing.msg').write_text('std_msgs/Header header\nThing2 other\n')
    (share / 'my_msgs/msg/Thing2.msg').write_text('float64 x\n')
    monkeypatch.setenv('AMENT_PREFIX_PATH',
                       os.pathsep.join([str(tmp_path), os.environ.get('AMENT_PREFIX_PATH',
                                                                      sys.prefix)]))
    names = [name for name, _ in sections(message_definition('my_msgs/msg/Thing'))[1:]]
    assert names == ['my_msgs/Thing2', 'std_msgs/Header', 'builtin_interfaces/Time']


def test_missing_types_give_an_actionable_error(monkeypatch, tmp_path):
    with pytest.raises(MessageDefinitionError, match='no_such_msgs/msg/Foo.*install'):
        message_definition('no_such_msgs/msg/Foo')
    with pytest.raises(MessageDefinitionError, match='not a message type name'):
        message_definition('Image')
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(tmp_path))
    with pytest.raises(MessageDefinitionError, match='AMENT_PREFIX_PATH'):
        message_definition('std_msgs/msg/String')


def test_type_hash_agrees_with_an_independent_implementation():
    typestore = pytest.importorskip('rosbags.typesys').get_typestore(
        pytest.importorskip('rosbags.typesys').Stores.ROS2_JAZZY)
    for msgtype in ('sensor_msgs/msg/Image', 'diagnostic_msgs/msg/DiagnosticArray'):
        digest = type_hash(msgtype)
        assert re.fullmatch('RIHS01_[0-9a-f]{64}', digest)
        assert digest == typestore.hash_rihs01(msgtype)
