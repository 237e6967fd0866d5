"""The replay's plan: cycles on the IPO grid, the span, and the reference built from the bag."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

pytest.importorskip('rclpy', reason='rclpy (ROS 2 Jazzy) is not installed')

from support import sine_recording

from id_learning.bag import iter_raw
from id_learning.dataset.recording import write_recording
from id_learning.errors import BagError, ConfigError
from id_learning.nodes.params import ReplayConfig
from id_learning.nodes.replay import build_plan

pytestmark = pytest.mark.ros

PERIOD_NS = 8_000_000


@pytest.fixture(scope='module')
def bag(tmp_path_factory):
    return write_recording(sine_recording(400), tmp_path_factory.mktemp('plan') / 'bag')


def test_each_cycle_holds_the_recorded_bytes_of_its_stamp_then_the_reference(bag, mabi):
    from rclpy.serialization import deserialize_message
    from trajectory_msgs.msg import JointTrajectory

    plan = build_plan(ReplayConfig(bag=str(bag), reference_inputs='recorded'), mabi)
    assert len(plan.cycles) == 400
    assert plan.message_count == 800
    assert plan.period_ns == PERIOD_NS
    offsets = np.array([cycle.offset_ns for cycle in plan.cycles])
    np.testing.assert_array_equal(offsets, np.arange(400) * PERIOD_NS)
    recorded = {topic: [data for _, _, data in iter_raw(bag, [topic])] for topic in plan.topics}
    recording = sine_recording(400)
    for k, cycle in enumerate(plan.cycles):
        (i0, first), (i1, second), (i2, reference) = cycle.messages
        assert (i0, i1, i2) == (0, 1, -1)
        assert first == recorded['/joint_states'][k]
        assert second == recorded['/motor_currents'][k]
        msg = deserialize_message(reference, JointTrajectory)
        assert msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec == cycle.stamp_ns
        np.testing.assert_array_equal(msg.points[0].positions, recording.position[k])
    # Accelerations: second-order differences of the recorded velocities, against the closed
    # form of sine_recording's v = 0.5 w cos(w t); the differences err by at most
    # h^2 / 3 max|d3v/dt3| (one-sided at the ends, half that inside), max|d3v/dt3| = 0.5 w^4.
    omega = 2 * np.pi * (0.1 + 0.05 * np.arange(6))
    t = (recording.stamps_ns - recording.stamps_ns[0]) * 1e-9
    exact = -0.5 * omega**2 * np.sin(omega * t[:, None])
    accelerations = np.array(
        [
            deserialize_message(cycle.messages[2][1], JointTrajectory).points[0].accelerations
            for cycle in plan.cycles
        ]
    )
    bound = 0.008**2 / 3 * 0.5 * omega**4
    assert np.all(np.abs(accelerations - exact) <= bound)
    assert np.all(np.abs(accelerations[1:-1] - exact[1:-1]) <= bound / 2)


def test_start_offset_and_duration_select_the_span(bag, mabi):
    plan = build_plan(
        ReplayConfig(bag=str(bag), start_offset_s=1.0, duration_s=0.5, reference_mode='none'),
        mabi,
    )
    stamps = sine_recording(400).stamps_ns
    assert [c.stamp_ns for c in plan.cycles] == stamps[125:188].tolist()  # 1.0 s .. 1.5 s
    assert plan.cycles[0].offset_ns == 0
    assert all(len(cycle.messages) == 2 for cycle in plan.cycles)


def test_the_low_passed_reference_of_a_span_is_filtered_over_padding_around_it(bag, mabi):
    whole = build_plan(ReplayConfig(bag=str(bag)), mabi)
    span = build_plan(ReplayConfig(bag=str(bag), start_offset_s=1.0, duration_s=0.5), mabi)
    # The span's first sample was filtered with the same samples around it as in the whole bag.
    np.testing.assert_allclose(velocity_at(span, 0), velocity_at(whole, 125), rtol=1e-9)


def velocity_at(plan, k):
    from rclpy.serialization import deserialize_message
    from trajectory_msgs.msg import JointTrajectory

    msg = deserialize_message(plan.cycles[k].messages[-1][1], JointTrajectory)
    return np.array(msg.points[0].velocities)


def test_log_time_scheduling_and_joint_state_references(bag, mabi):
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import JointState

    plan = build_plan(
        ReplayConfig(bag=str(bag), timing='log_time', reference_mode='joint_state'), mabi
    )
    assert len(plan.cycles) == 400
    msg = deserialize_message(plan.cycles[3].messages[-1][1], JointState)
    assert len(msg.position) == 6
    assert len(msg.velocity) == 6
    assert len(msg.effort) == 0


def test_a_plan_refuses_an_empty_span_or_a_missing_topic(bag, mabi):
    with pytest.raises(ConfigError, match='nothing to play'):
        build_plan(ReplayConfig(bag=str(bag), start_offset_s=100.0, reference_mode='none'), mabi)
    with pytest.raises(BagError, match='/wrench'):
        build_plan(ReplayConfig(bag=str(bag), topics=('/wrench',)), mabi)


@pytest.mark.parametrize(
    ('field', 'sample', 'value', 'message'),
    [
        ('position', 57, np.nan, r'sample 57 .*joint_3: value nan is not finite'),
        ('velocity', 80, 6 * 1.7, r'sample 80 .*joint_1: velocity 10.2 rad/s exceeds 1.5 x'),
        ('position', 90, 1e300, r'sample 90 .*joint_2: position 1e\+300 rad is outside'),
    ],
)
def test_a_plan_refuses_an_impossible_reference_naming_the_sample(
    tmp_path, mabi, field, sample, value, message
):
    recording = sine_recording(200)
    array = getattr(recording, field).copy()
    column = {'position': 2, 'velocity': 0}[field] if value != 1e300 else 1
    array[sample, column] = value
    broken = write_recording(replace(recording, **{field: array}), tmp_path / 'broken')
    with pytest.raises(BagError, match=message) as caught:
        build_plan(ReplayConfig(bag=str(broken)), mabi)
    assert 'nothing is played' in str(caught.value)
    # Without a reference the recorded messages are replayed as recorded, NaN and all.
    plan = build_plan(ReplayConfig(bag=str(broken), reference_mode='none'), mabi)
    assert plan.message_count == 400


def test_a_plan_refuses_a_reference_whose_accelerations_no_arm_reaches(tmp_path, mabi):
    recording = sine_recording(200)
    velocity = recording.velocity.copy()
    velocity[100:, 3] += 1.0  # a 1 rad/s step in one IPO cycle: ~10^2 rad/s^2 after smoothing
    broken = write_recording(replace(recording, velocity=velocity), tmp_path / 'step')
    with pytest.raises(BagError, match=r'joint_4: acceleration .* exceeds 2 x its limit'):
        build_plan(ReplayConfig(bag=str(broken)), mabi)
    build_plan(
        ReplayConfig(bag=str(broken), reference_inputs='recorded', reference_mode='none'), mabi
    )


def test_a_smoothing_cut_off_at_nyquist_is_refused_naming_both(bag, mabi):
    with pytest.raises(ConfigError, match=r'reference_smoothing_hz 62\.5 Hz .* Nyquist .* 62\.5'):
        build_plan(ReplayConfig(bag=str(bag), reference_smoothing_hz=62.5), mabi)


def test_a_recording_whose_positions_jump_is_not_played(tmp_path, mabi):
    recording = sine_recording(200)
    position = recording.position.copy()
    position[120:, 2] += 0.5  # a jump no velocity explains
    broken = write_recording(replace(recording, position=position), tmp_path / 'jump')
    with pytest.raises(BagError, match=r'sample 120 .* joint_3 .* nothing is played'):
        build_plan(ReplayConfig(bag=str(broken)), mabi)


@pytest.mark.parametrize('where', ['reference', 'stamp'])
def test_bytes_that_are_no_message_of_their_type_are_named_not_a_traceback(tmp_path, mabi, where):
    from id_learning.bag import JOINT_STATE, BagWriter, encode_joint_state

    recording = sine_recording(60)
    with BagWriter(tmp_path / 'bag') as writer:
        writer.add_topic('/joint_states', JOINT_STATE)
        writer.add_topic('/note', 'std_msgs/msg/String')
        for k, stamp in enumerate(recording.stamps_ns.tolist()):
            data = encode_joint_state(
                stamp, recording.joints, recording.position[k], recording.velocity[k], []
            )
            writer.write('/joint_states', stamp, b'\x00\x01\xff\xff\xff\xff' if k == 30 else data)
            writer.write('/note', stamp, data)  # JointState bytes under a String type
    topics = ['/joint_states'] if where == 'reference' else ['/joint_states', '/note']
    config = ReplayConfig(bag=str(tmp_path / 'bag'), topics=topics)
    message = 'not a valid' if where == 'reference' else r'/note message 0: not a valid'
    with pytest.raises(BagError, match=message):
        build_plan(config, mabi)
