"""inspect_bag names what load_recording refuses in the contract topics, in the same words."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer

from id_learning.bag import JOINT_STATE, BagWriter, encode_joint_state, iter_raw
from id_learning.bag.messages import typestore
from id_learning.dataset.inspect import inspect_bag, render_report
from id_learning.dataset.recording import joint_name_mismatch, load_recording
from id_learning.errors import BagError, DatasetError
from id_learning.robot import RobotConfig, load_robot_config

T0_NS = 1_700_000_000 * 1_000_000_000
PERIOD_NS = 8_000_000
JOINTS = tuple(f'joint_{i}' for i in range(1, 7))


@pytest.fixture(scope='module')
def robot() -> RobotConfig:
    return load_robot_config(Path(__file__).resolve().parents[2] / 'config/mabi_max100.yaml')


def contract_bag(
    path: Path,
    names_js: tuple[str, ...] = JOINTS,
    names_mc: tuple[str, ...] = JOINTS,
    *,
    velocity: bool = True,
    effort: bool = True,
    n: int = 60,
) -> Path:
    """Slow sines on both contract topics; velocities and currents can be left out."""
    empty = np.zeros(0)
    with BagWriter(path) as writer:
        writer.add_topic('/joint_states', JOINT_STATE)
        writer.add_topic('/motor_currents', JOINT_STATE)
        for k in range(n):
            stamp = T0_NS + k * PERIOD_NS
            t = k * PERIOD_NS * 1e-9
            q = 0.1 * np.sin(t + np.arange(len(names_js)))
            v = 0.1 * np.cos(t + np.arange(len(names_js)))
            data = encode_joint_state(stamp, names_js, q, v if velocity else empty, empty)
            writer.write('/joint_states', stamp, data)
            current = 0.5 * np.sin(5 * t + np.arange(len(names_mc))) if effort else empty
            data = encode_joint_state(stamp, names_mc, empty, empty, current)
            writer.write('/motor_currents', stamp, data)
    return path


def test_motor_currents_without_effort_are_a_problem_in_load_recordings_words(
    tmp_path: Path, robot: RobotConfig
) -> None:
    bag = contract_bag(tmp_path / 'bag', effort=False)
    words = '/motor_currents: messages carry no effort (the motor currents)'
    with pytest.raises(DatasetError, match=re.escape(words)):
        load_recording(bag, robot)  # precondition: train refuses the bag so

    for report in (inspect_bag(bag), inspect_bag(bag, robot)):
        assert words in report.problems
        assert report.contract.empty_fields == (('/motor_currents', 'effort'),)
        assert not report.contract.is_met
        assert '/motor_currents carries no effort' in render_report(report)


def test_joint_states_without_velocity_are_a_problem(tmp_path: Path) -> None:
    report = inspect_bag(contract_bag(tmp_path / 'bag', velocity=False))
    assert '/joint_states: messages carry no velocity' in report.problems
    assert not report.contract.is_met


def test_a_complete_contract_bag_has_no_empty_fields(tmp_path: Path, robot: RobotConfig) -> None:
    report = inspect_bag(contract_bag(tmp_path / 'bag'), robot)
    assert report.contract.empty_fields == ()
    assert report.contract.is_met
    assert report.problems == ()


def test_a_joint_on_one_topic_only_is_named(tmp_path: Path, robot: RobotConfig) -> None:
    bag = contract_bag(tmp_path / 'bag', names_js=(*JOINTS, 'gripper'))
    with pytest.raises(DatasetError, match=r"unexpected \['gripper'\]"):
        load_recording(bag, robot)

    problems = inspect_bag(bag).problems
    assert (
        'contract: /motor_currents and /joint_states name different joints (/motor_currents '
        "against /joint_states: missing ['gripper'], unexpected [])"
    ) in problems
    with_robot = '\n'.join(inspect_bag(bag, robot).problems)
    assert (
        "/joint_states: joints do not match mabi_max100 (missing [], unexpected ['gripper'])"
        in (with_robot)
    )


def test_a_joint_listed_twice_is_named_with_or_without_a_robot(
    tmp_path: Path, robot: RobotConfig
) -> None:
    twice = ('joint_1', *JOINTS)
    bag = contract_bag(tmp_path / 'bag', names_js=twice, names_mc=twice)
    with pytest.raises(DatasetError, match=r"repeated \['joint_1'\]"):
        load_recording(bag, robot)

    for report in (inspect_bag(bag), inspect_bag(bag, robot)):
        repeated = [p for p in report.problems if "joint name(s) ['joint_1'] repeated" in p]
        assert [p.split(':')[0] for p in repeated] == ['/joint_states', '/motor_currents']


def test_joints_in_another_order_are_told_apart_from_other_joints(tmp_path: Path) -> None:
    bag = contract_bag(tmp_path / 'bag', names_mc=tuple(reversed(JOINTS)))
    (line,) = [p for p in inspect_bag(bag).problems if 'name different joints' in p]
    assert 'the same joints, in another order' in line


def test_joint_name_mismatch_in_load_recordings_words() -> None:
    assert joint_name_mismatch(('b', 'a'), ('a', 'b')) is None
    assert joint_name_mismatch(('a', 'c'), ('a', 'b')) == "missing ['b'], unexpected ['c']"
    assert joint_name_mismatch(('a', 'a', 'b'), ('a', 'b')) == (
        "missing [], unexpected [], repeated ['a']"
    )


def test_a_topic_of_two_types_is_named_with_counts_not_called_missing(
    tmp_path: Path, robot: RobotConfig
) -> None:
    source = contract_bag(tmp_path / 'source', n=40)
    store = typestore()
    mixed = tmp_path / 'mixed'
    with Writer(mixed, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        topics = ('/joint_states', '/motor_currents')
        conns = {
            name: writer.add_connection(name, JOINT_STATE, typestore=store) for name in topics
        }
        string = writer.add_connection('/joint_states', 'std_msgs/msg/String', typestore=store)
        for topic, log_ns, data in iter_raw(source, topics):
            writer.write(conns[topic], log_ns, data)
        message = store.types['std_msgs/msg/String'](data='hello')
        writer.write(string, log_ns + 1, bytes(store.serialize_cdr(message, string.msgtype)))
    with pytest.raises(BagError, match='holds 2 message types'):
        load_recording(mixed, robot)  # precondition: train refuses the bag

    report = inspect_bag(mixed)

    assert report.several_types == (
        ('/joint_states', ((JOINT_STATE, 40), ('std_msgs/msg/String', 1))),
    )
    assert report.contract.missing == ()
    assert report.contract.several_types == ('/joint_states',)
    assert not report.contract.is_met
    assert report.topic('/joint_states').count == 40  # its JointState messages, analysed
    assert report.message_count == 81
    assert report.metadata_mismatches == ()
    text = '\n'.join(report.problems)
    assert (
        '/joint_states: holds 2 message types: sensor_msgs/msg/JointState (40 messages), '
        'std_msgs/msg/String (1 message)'
    ) in text
    assert 'missing' not in text
    assert 'std_msgs/msg/String, expected' not in text
