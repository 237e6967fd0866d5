"""inspect_bag / render_report / plot_report on small bags built in code."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from id_learning.bag import JOINT_STATE, BagWriter, encode_joint_state, read_joint_states
from id_learning.dataset.inspect import inspect_bag, plot_report, render_report
from id_learning.dataset.recording import Recording, load_recording, write_recording
from id_learning.errors import BagError, DatasetError
from id_learning.robot import RobotConfig, load_robot_config

PERIOD_NS = 8_000_000
T0_NS = 1_700_000_000 * 1_000_000_000
PNG_MAGIC = b'\x89PNG\r\n\x1a\n'


@pytest.fixture(scope='module')
def robot() -> RobotConfig:
    return load_robot_config(Path(__file__).resolve().parents[2] / 'config/mabi_max100.yaml')


def make_recording(robot: RobotConfig, stamps_ns: np.ndarray) -> Recording:
    """Sines of different frequency per joint, well inside the limits."""
    t = (stamps_ns - stamps_ns[0]) * 1e-9
    freq = np.linspace(0.2, 0.7, robot.n_joints)
    phase = 2 * np.pi * freq * t[:, None]
    return Recording(
        joints=robot.joints,
        stamps_ns=stamps_ns,
        position=0.5 * np.sin(phase),
        velocity=0.5 * 2 * np.pi * freq * np.cos(phase),
        current=np.cos(phase + 0.3),
        joint_torque=None,
    )


def regular_stamps(n: int) -> np.ndarray:
    return T0_NS + PERIOD_NS * np.arange(n, dtype=np.int64)


def test_clean_bag_reports_counts_rate_and_no_gaps(tmp_path: Path, robot: RobotConfig) -> None:
    recording = make_recording(robot, regular_stamps(500))
    bag = write_recording(recording, tmp_path / 'bag', robot.topics)

    report = inspect_bag(bag, robot)

    assert report.message_count == 1000
    assert report.start_ns == T0_NS
    assert report.start_iso == '2023-11-14T22:13:20.000000Z'
    assert report.duration_s == pytest.approx(499 * 0.008)
    for name in (robot.topics.joint_states, robot.topics.motor_currents):
        topic = report.topic(name)
        assert topic.count == 500
        assert topic.timing.time_base == 'header'
        assert topic.timing.rate_hz == pytest.approx(125.0, rel=1e-12)
        assert topic.timing.median_period_s == pytest.approx(0.008)
        assert topic.timing.jitter_p99_ms == pytest.approx(0.0, abs=1e-9)
        assert topic.timing.gap_count == 0
        assert topic.timing.repeated_count == topic.timing.backward_count == 0
        assert [joint.name for joint in topic.joints] == list(robot.joints)
    assert report.contract.is_met
    assert report.problems == ()


def test_joint_statistics_equal_numpy_over_the_written_samples(
    tmp_path: Path, robot: RobotConfig
) -> None:
    recording = make_recording(robot, regular_stamps(500))
    report = inspect_bag(write_recording(recording, tmp_path / 'bag', robot.topics), robot)

    states = report.topic(robot.topics.joint_states)
    for column, joint in enumerate(states.joints):
        assert joint.position is not None
        assert joint.velocity is not None
        assert joint.effort is None  # joint_torque was not recorded: effort left empty
        assert joint.position.minimum == recording.position[:, column].min()
        assert joint.position.maximum == recording.position[:, column].max()
        assert joint.position.mean == pytest.approx(
            recording.position[:, column].mean(), abs=1e-15
        )
        assert joint.velocity.non_finite == 0
        assert joint.position_outside_limits == 0.0
        assert joint.velocity_outside_limits == 0.0
    currents = report.topic(robot.topics.motor_currents)
    assert currents.joints[2].position is None
    assert currents.joints[2].effort is not None
    assert currents.joints[2].effort.maximum == recording.current[:, 2].max()


def test_gap_and_repeated_stamp_are_reported_at_their_samples(
    tmp_path: Path, robot: RobotConfig
) -> None:
    steps = np.full(499, PERIOD_NS, dtype=np.int64)
    steps[199] = 5 * PERIOD_NS  # between samples 199 and 200
    steps[349] = 0  # sample 350 repeats sample 349's stamp
    stamps = T0_NS + np.concatenate([[0], np.cumsum(steps)])
    bag = write_recording(make_recording(robot, stamps), tmp_path / 'bag', robot.topics)
    with pytest.raises(DatasetError, match='repeats at sample 350'):
        load_recording(bag, robot)  # precondition: the validated load rejects this bag

    report = inspect_bag(bag, robot)

    timing = report.topic(robot.topics.joint_states).timing
    assert timing.nominal_period_s == robot.ipo_period_s
    assert timing.gap_count == 1
    assert timing.gaps[0].sample == 200
    assert timing.gaps[0].stamp_ns == int(stamps[200])
    assert timing.gaps[0].periods == pytest.approx(5.0)
    assert timing.repeated_count == 1
    assert timing.repeated == (350,)
    assert timing.backward_count == 0
    assert timing.jitter_std_ms == pytest.approx(0.0, abs=1e-9)  # gaps are not jitter
    assert timing.jitter_p99_ms == pytest.approx(0.0, abs=1e-9)
    assert any('before sample 200' in line for line in report.problems)
    text = render_report(report)
    assert 'repeated stamps on /joint_states (1) at samples 350' in text


def test_backward_header_stamp_is_counted_even_when_log_times_advance(tmp_path: Path) -> None:
    stamps = regular_stamps(50)
    stamps[30] = stamps[28]  # header stamp jumps back two periods; log time keeps going
    joints = ('a', 'b')
    with BagWriter(tmp_path / 'bag') as writer:
        writer.add_topic('/joint_states', JOINT_STATE)
        for k, stamp in enumerate(stamps.tolist()):
            data = encode_joint_state(stamp, joints, np.zeros(2), np.zeros(2), np.zeros(0))
            writer.write('/joint_states', T0_NS + k * PERIOD_NS, data)

    report = inspect_bag(tmp_path / 'bag')

    timing = report.topic('/joint_states').timing
    assert timing.backward == (30,)
    assert timing.backward_count == 1
    assert timing.nominal_period_s == pytest.approx(0.008)  # the median step, without a robot
    assert report.contract.missing == ('/motor_currents',)
    assert not report.contract.is_met
    # Probe 16 (C25): without a robot, what is not checked is said, and how to have it checked.
    assert 'robot     - (not given: limits, the IPO grid and whether samples follow' in (
        render_report(report)
    )
    assert 'pass --robot CONFIG' in render_report(report)


def test_non_finite_values_are_counted_instead_of_raised(
    tmp_path: Path, robot: RobotConfig
) -> None:
    recording = make_recording(robot, regular_stamps(200))
    recording.position[10, 2] = np.nan
    recording.position[11, 2] = np.inf
    recording.current[5, 0] = np.nan
    bag = write_recording(recording, tmp_path / 'bag', robot.topics)
    with pytest.raises(DatasetError, match='not finite'):
        load_recording(bag, robot)

    report = inspect_bag(bag, robot)

    states = report.topic(robot.topics.joint_states)
    assert states.joints[2].position is not None
    assert states.joints[2].position.non_finite == 2
    finite = np.delete(recording.position[:, 2], [10, 11])
    assert states.joints[2].position.maximum == finite.max()
    assert all(j.position.non_finite == 0 for j in states.joints if j.name != 'joint_3')
    currents = report.topic(robot.topics.motor_currents)
    assert currents.joints[0].effort is not None
    assert currents.joints[0].effort.non_finite == 1
    assert 'joint_3 position: 2 non-finite value(s)' in '\n'.join(report.problems)


def test_samples_outside_the_robot_limits_are_counted_per_joint(
    tmp_path: Path, robot: RobotConfig
) -> None:
    recording = make_recording(robot, regular_stamps(500))
    recording.position[:, 0] *= 7.0  # amplitude 3.5 rad against limits of +-3.0 rad
    recording.velocity[:, 1] = np.linspace(-2.0, 2.0, 500)  # limit 1.4 rad/s
    bag = write_recording(recording, tmp_path / 'bag', robot.topics)

    joints = inspect_bag(bag, robot).topic(robot.topics.joint_states).joints

    expected_q = np.mean(np.abs(recording.position[:, 0]) > 3.0)
    expected_v = np.mean(np.abs(recording.velocity[:, 1]) > 1.4)
    assert expected_q > 0
    assert expected_v > 0
    assert joints[0].name == 'joint_1'
    assert joints[0].position_outside_limits == pytest.approx(expected_q)
    assert joints[1].velocity_outside_limits == pytest.approx(expected_v)
    assert joints[2].position_outside_limits == 0.0


def test_contract_mismatch_names_the_first_differing_sample(tmp_path: Path) -> None:
    stamps = regular_stamps(100)
    joints = ('a', 'b')
    empty = np.zeros(0)
    with BagWriter(tmp_path / 'bag') as writer:
        writer.add_topic('/joint_states', JOINT_STATE)
        writer.add_topic('/motor_currents', JOINT_STATE)
        for k, stamp in enumerate(stamps.tolist()):
            q = np.full(2, 0.1 * k)
            writer.write('/joint_states', stamp, encode_joint_state(stamp, joints, q, q, empty))
            # 137 ns pairs (a driver stamping each topic itself); 2 ms is another sample.
            current_stamp = stamp + (2_000_000 if k >= 42 else 137)
            data = encode_joint_state(current_stamp, joints, empty, empty, q)
            writer.write('/motor_currents', stamp, data)

    contract = inspect_bag(tmp_path / 'bag').contract

    assert contract.missing == ()
    assert contract.names_match is True
    assert contract.stamps_match is False
    assert contract.first_mismatch == 42


def test_a_contract_topic_of_another_type_is_named_with_the_type_found(tmp_path: Path) -> None:
    stamps = regular_stamps(10)
    zeros = np.zeros(2)
    string_cdr = b'\x00\x01\x00\x00' + (3).to_bytes(4, 'little') + b'hi\x00'
    with BagWriter(tmp_path / 'bag') as writer:
        writer.add_topic('/joint_states', JOINT_STATE)
        writer.add_topic('/motor_currents', 'std_msgs/msg/String')
        for stamp in stamps.tolist():
            data = encode_joint_state(stamp, ('a', 'b'), zeros, zeros, zeros)
            writer.write('/joint_states', stamp, data)
            writer.write('/motor_currents', stamp, string_cdr)

    report = inspect_bag(tmp_path / 'bag')

    assert report.contract.missing == ('/motor_currents',)
    assert report.contract.wrong_types == (('/motor_currents', 'std_msgs/msg/String'),)
    expected = 'contract: /motor_currents has type std_msgs/msg/String, expected sensor_msgs'
    assert any(problem.startswith(expected) for problem in report.problems)
    assert 'missing /motor_currents (it has type std_msgs/msg/String)' in render_report(report)


def test_contract_reports_where_a_shorter_topic_ends(tmp_path: Path, robot: RobotConfig) -> None:
    recording = make_recording(robot, regular_stamps(100))
    bag = write_recording(recording, tmp_path / 'bag', robot.topics)
    short = make_recording(robot, regular_stamps(90))
    with BagWriter(tmp_path / 'short') as writer:
        for topic, source in (('/joint_states', recording), ('/motor_currents', short)):
            writer.add_topic(topic, JOINT_STATE)
            for k, stamp in enumerate(source.stamps_ns.tolist()):
                q = source.position[k]
                writer.write(topic, stamp, encode_joint_state(stamp, robot.joints, q, q, q))
    assert inspect_bag(bag, robot).contract.stamps_match is True  # precondition

    contract = inspect_bag(tmp_path / 'short', robot).contract

    assert contract.stamps_match is False
    assert contract.first_mismatch == 90


def test_undecodable_and_renamed_messages_are_counted_not_raised(tmp_path: Path) -> None:
    stamps = regular_stamps(20)
    zeros = np.zeros(2)
    with BagWriter(tmp_path / 'bag') as writer:
        writer.add_topic('/joint_states', JOINT_STATE)
        for k, stamp in enumerate(stamps.tolist()):
            joints = ('a', 'c') if k in (12, 15) else ('a', 'b')
            data = encode_joint_state(stamp, joints, zeros + k, zeros, zeros)
            writer.write('/joint_states', stamp, data[:9] if k == 17 else data)
    with pytest.raises(DatasetError, match='sample 12'):
        read_joint_states(tmp_path / 'bag', '/joint_states')  # precondition: a strict read fails

    topic = inspect_bag(tmp_path / 'bag').topic('/joint_states')

    assert topic.count == 20
    assert topic.undecodable == 1
    assert topic.inconsistent == 2
    assert topic.first_inconsistent == 12
    assert topic.joints[0].position is not None
    assert topic.joints[0].position.maximum == 19.0  # the 17 consistent messages
    assert topic.timing.gap_count == 1  # sample 17 is missing from the stamps
    assert topic.timing.gaps[0].sample == 18


def test_render_report_aligns_the_topic_table(tmp_path: Path, robot: RobotConfig) -> None:
    bag = write_recording(
        make_recording(robot, regular_stamps(100)), tmp_path / 'bag', robot.topics
    )

    text = render_report(inspect_bag(bag, robot))

    lines = text.splitlines()
    start = lines.index('topics') + 1
    table = lines[start : start + 4]  # header, rule, two topics
    assert table[2].startswith('  /joint_states ')
    assert table[3].startswith('  /motor_currents ')
    assert len({line.index('125.000') for line in table[2:]}) == 1  # rate column aligned
    assert 'stamps match sample for sample' in text
    assert 'problems  none' in text


def test_plot_report_writes_a_png(tmp_path: Path, robot: RobotConfig) -> None:
    bag = write_recording(
        make_recording(robot, regular_stamps(300)), tmp_path / 'bag', robot.topics
    )
    report = inspect_bag(bag, robot)

    out = plot_report(report, tmp_path / 'plots' / 'bag.png', max_points=100)

    assert out == tmp_path / 'plots' / 'bag.png'
    assert out.read_bytes()[:8] == PNG_MAGIC
    assert out.stat().st_size > 10_000


def test_missing_bag_raises_bag_error(tmp_path: Path) -> None:
    with pytest.raises(BagError, match='no such bag'):
        inspect_bag(tmp_path / 'nowhere')


@pytest.mark.parametrize('with_effort', [True, False])
def test_joint_torques_without_motor_currents_are_no_problem_but_positions_alone_are(
    tmp_path: Path, robot: RobotConfig, with_effort: bool
) -> None:
    """Joint-torque sensors in /joint_states' effort need no currents (``--target joint``)."""
    recording = make_recording(robot, regular_stamps(40))
    with BagWriter(tmp_path / 'bag') as writer:
        writer.add_topic('/joint_states', JOINT_STATE)
        for k, stamp in enumerate(recording.stamps_ns.tolist()):
            effort = 100.0 * recording.current[k] if with_effort else np.zeros(0)
            data = encode_joint_state(
                stamp, robot.joints, recording.position[k], recording.velocity[k], effort
            )
            writer.write('/joint_states', stamp, data)
    report = inspect_bag(tmp_path / 'bag', robot)
    assert report.contract.missing == ('/motor_currents',)
    assert report.contract.joint_torques_only is with_effort
    missing = [p for p in report.problems if 'missing JointState topic' in p]
    assert len(missing) == (0 if with_effort else 1)
    text = render_report(report)
    assert ('labels for --target joint' in text) is with_effort


def test_samples_whose_motion_contradicts_itself_are_counted_and_named(
    tmp_path: Path, robot: RobotConfig
) -> None:
    recording = make_recording(robot, regular_stamps(300))
    position = recording.position.copy()
    position[150, 2] += 0.8  # one pose off the motion: a spike
    bag = write_recording(
        Recording(**{**vars(recording), 'position': position}), tmp_path / 'bag', robot.topics
    )
    topic = inspect_bag(bag, robot).topic(robot.topics.joint_states)
    assert topic.contradictions >= 2  # the spike and the way back
    assert topic.first_contradiction is not None
    assert topic.first_contradiction.startswith('sample 150 ')
    assert 'position of joint_3 changed by 0.79' in topic.first_contradiction
    assert any('do not follow from the ones before' in p for p in inspect_bag(bag, robot).problems)
    clean = write_recording(recording, tmp_path / 'clean', robot.topics)
    assert inspect_bag(clean, robot).topic(robot.topics.joint_states).contradictions == 0
