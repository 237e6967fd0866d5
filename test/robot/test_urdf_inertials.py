"""URDF links no rigid body can be are refused where the robot config names the URDF."""

from __future__ import annotations

from pathlib import Path

import pytest

from id_learning.errors import RobotModelError
from id_learning.robot import check_urdf_inertials, load_robot_config
from id_learning.robot.urdf_inertials import read_urdf

REPO = Path(__file__).resolve().parents[2]
URDF = REPO / 'urdf/mabi_max100.urdf'
#: link_3 of the shipped URDF: 150 kg.
LINK_3 = 'ixx="4.9964" ixy="0" ixz="-1.0061333" iyy="7.07" iyz="0" izz="5.6256"'


def _edited(tmp_path: Path, old: str, new: str) -> Path:
    text = URDF.read_text()
    assert text.count(old) == 1
    path = tmp_path / 'arm.urdf'
    path.write_text(text.replace(old, new))
    return path


@pytest.mark.parametrize(
    ('inertia', 'message'),
    [
        ('ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"', r'mass 150 kg .*\(all zero\)'),
        ('ixx="-1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"', r'\(not positive semi-definite\)'),
        ('ixx="nan" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"', 'must be finite'),
        (
            'ixx="4.9964" ixy="0" ixz="-1.0061333" iyy="-7.07" iyz="0" izz="5.6256"',
            r'\(not positive semi-definite\)',
        ),
    ],
    ids=['all-zero', 'negative', 'nan', 'negative-moment'],
)
def test_a_heavy_link_with_an_impossible_inertia_is_refused_naming_link_and_file(
    tmp_path: Path, inertia: str, message: str
) -> None:
    path = _edited(tmp_path, LINK_3, inertia)
    with pytest.raises(RobotModelError, match=rf'link link_3: .*{message}') as err:
        check_urdf_inertials(path)
    assert str(path) in str(err.value)


@pytest.mark.parametrize(
    ('old', 'new', 'said'),
    [
        (LINK_3, 'ixx="0" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"', 'a thin rod'),
        (LINK_3, 'ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="3"', 'triangle inequality'),
        ('<mass value="150"/>', '<mass value="0"/>', 'mass 0 with principal moments'),
    ],
    ids=['rod', 'triangle', 'massless'],
)
def test_an_inertia_that_bends_the_rules_is_said_not_refused(
    tmp_path: Path, old: str, new: str, said: str, caplog
) -> None:
    path = _edited(tmp_path, old, new)
    lines = check_urdf_inertials(path)
    assert len(lines) == 1
    assert lines[0].startswith(f'{path}: link link_3: ')
    assert said in lines[0]
    assert caplog.messages == lines  # one warning line per link, no summary around it


def test_a_massive_link_typed_massless_is_not_said_to_be_harmless(tmp_path: Path) -> None:
    (line,) = check_urdf_inertials(_edited(tmp_path, '<mass value="150"/>', '<mass value="0"/>'))
    assert 'a mass typed as 0?' in line
    assert 'not the weight' in line
    assert 'cannot mislead' not in line


def test_a_light_link_with_a_zero_inertia_is_said_not_refused(tmp_path: Path) -> None:
    zero = 'ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"'
    light = _edited(tmp_path, '<mass value="150"/>', '<mass value="0.0001"/>')
    light.write_text(light.read_text().replace(LINK_3, zero))
    said = check_urdf_inertials(light)
    assert len(said) == 1
    assert 'link_3: mass 0.0001 kg' in said[0]
    assert 'loaded, as a link this light (under 1 kg' in said[0]


@pytest.mark.parametrize('name', ['mabi_max100', 'ur5', 'panda'])
def test_the_shipped_robots_urdfs_pass(name: str) -> None:
    robot = load_robot_config(REPO / 'config' / f'{name}.yaml')
    check_urdf_inertials(robot.urdf_path)


def test_loading_a_robot_config_checks_its_urdf(tmp_path: Path, write_config) -> None:
    urdf = _edited(tmp_path, LINK_3, 'ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"')
    config = write_config('mabi_max100', set={'urdf': str(urdf)})
    with pytest.raises(RobotModelError, match='link link_3: mass 150 kg') as err:
        load_robot_config(config)
    assert str(urdf) in str(err.value)


def test_a_locked_joint_position_and_a_topic_name_are_checked(write_config) -> None:
    from id_learning.errors import ConfigError

    nan = write_config('panda', set={'locked_joints': {'panda_finger_joint1': float('nan')}})
    with pytest.raises(ConfigError, match=r'locked_joints: .*panda_finger_joint1: nan'):
        load_robot_config(nan)
    topic = write_config('mabi_max100', set={'topics': {'motor_currents': '/motor currents'}})
    with pytest.raises(ConfigError, match=r"topics\.motor_currents: '/motor currents' is no ROS"):
        load_robot_config(topic)
    same = write_config('mabi_max100', set={'topics': {'motor_currents': '/joint_states'}})
    with pytest.raises(ConfigError, match=r'joint_states and topics\.motor_currents are both'):
        load_robot_config(same)


def test_a_negative_mass_is_refused(tmp_path: Path) -> None:
    path = _edited(tmp_path, '<mass value="150"/>', '<mass value="-150"/>')
    with pytest.raises(RobotModelError, match='link link_3: mass -150 kg'):
        check_urdf_inertials(path)


def test_building_the_dynamics_checks_the_urdf_too(tmp_path: Path) -> None:
    from dataclasses import replace

    from id_learning.physics.rigid_body import build_pinocchio_model

    robot = load_robot_config(REPO / 'config/mabi_max100.yaml')
    zero = _edited(tmp_path, LINK_3, 'ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"')
    with pytest.raises(RobotModelError, match='link link_3: mass 150 kg'):
        build_pinocchio_model(replace(robot, urdf_path=zero))


def test_a_massless_frame_with_no_inertia_is_fine(tmp_path: Path) -> None:
    frame = _edited(tmp_path, '<mass value="150"/>', '<mass value="0"/>')
    zero = 'ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"'
    frame.write_text(frame.read_text().replace(LINK_3, zero))
    assert check_urdf_inertials(frame) == []  # a frame: no mass, no inertia


@pytest.mark.parametrize('encoding', ['utf-16', 'utf-16-be', 'utf-32'])
def test_a_urdf_in_a_wide_encoding_is_named_as_such(tmp_path, encoding):
    text = (REPO / 'urdf/mabi_max100.urdf').read_text(encoding='utf-8')
    wide = tmp_path / 'arm.urdf'
    wide.write_bytes(
        text.replace(
            '<?xml version="1.0"?>', f'<?xml version="1.0" encoding="{encoding}"?>'
        ).encode(encoding)
    )

    with pytest.raises(RobotModelError, match=r'arm\.urdf: the URDF is UTF-16 or UTF-32 text'):
        read_urdf(wide)


def test_a_urdf_in_latin_1_names_the_first_byte_that_is_not_utf_8(tmp_path):
    latin = tmp_path / 'arm.urdf'
    latin.write_bytes('<robot name="Gerät"><link name="base"/></robot>'.encode('latin-1'))

    with pytest.raises(RobotModelError, match=r'not UTF-8 text \(byte 16 is 0xe4\)'):
        read_urdf(latin)
