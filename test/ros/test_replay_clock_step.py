"""A clock step on the recorder: the replay plays the bag in header-stamp order, as train reads it.

The recorder's log times step back while the header stamps advance, so the bag (in log-time
order) holds late samples before or among early ones. The replay plays such a bag in header-stamp
order with one warning naming the step, the same plan as the bag recorded without the step; a
span inside the stepped part plays too (it is not skipped for its early log times). Header stamps
a sender stepped back (log times running on) are still refused, as before. Real bags written with
the package's writer; the plan, and the node over DDS.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip('rclpy', reason='rclpy (ROS 2 Jazzy) is not installed')

from bag.test_log_time_steps import LATENCY_NS, stepped_logs, write_bag
from support import sine_recording

from id_learning.bag import decode_joint_state, iter_raw
from id_learning.dataset.recording import Recording
from id_learning.errors import BagError
from id_learning.nodes.params import ReplayConfig
from id_learning.nodes.replay import ReplayPlan, build_plan

pytestmark = pytest.mark.ros

STEP_NS = 10_000_000_000


def _stamps_as_read(bag: Path) -> np.ndarray:
    """The /joint_states header stamps in the bag's (log-time) order."""
    return np.array(
        [decode_joint_state(data).stamp_ns for _, _, data in iter_raw(bag, ['/joint_states'])]
    )


def _played(plan: ReplayPlan) -> list[tuple[int, list[tuple[int, bytes]]]]:
    return [(cycle.stamp_ns, cycle.messages) for cycle in plan.cycles]


@pytest.mark.parametrize(
    ('n', 'at'),
    [
        (1500, 900),  # the later samples interleave with earlier ones in the bag
        (500, 300),  # the later samples all come first in the bag
    ],
)
def test_a_clock_step_on_the_recorder_plays_in_header_stamp_order_with_one_warning(
    tmp_path: Path, mabi, n: int, at: int
) -> None:
    recording = sine_recording(n)
    stepped = write_bag(
        tmp_path / 'stepped', recording, stepped_logs(recording.stamps_ns, at, STEP_NS)
    )
    steady = write_bag(tmp_path / 'steady', recording, recording.stamps_ns + LATENCY_NS)
    assert (np.diff(_stamps_as_read(stepped)) < 0).any()  # as read, the stamps step back

    plan = build_plan(ReplayConfig(bag=str(stepped)), mabi)

    assert [cycle.stamp_ns for cycle in plan.cycles] == recording.stamps_ns.tolist()
    # The same cycles, bytes and reference as the bag recorded without the step.
    assert _played(plan) == _played(build_plan(ReplayConfig(bag=str(steady)), mabi))
    warnings = [w for w in plan.warnings if 'clock step' in w]
    assert len(warnings) == 1, plan.warnings
    assert warnings[0].startswith(
        f'{stepped}: /joint_states: the log times step back by 10.000 s at sample {at} '
    )
    assert warnings[0].endswith(
        'played in header-stamp order (so are /motor_currents, whose log times step back too)'
    )


def test_a_span_inside_the_stepped_part_is_played_not_skipped(tmp_path: Path, mabi) -> None:
    recording = sine_recording(1500)
    bag = write_bag(tmp_path / 'bag', recording, stepped_logs(recording.stamps_ns, 900, STEP_NS))
    # 8 s to 10 s: samples 1000 to 1250, logged 2.8 s before the bag's first sample was.
    plan = build_plan(ReplayConfig(bag=str(bag), start_offset_s=8.0, duration_s=2.0), mabi)
    assert [cycle.stamp_ns for cycle in plan.cycles] == recording.stamps_ns[1000:1251].tolist()
    for cycle, k in zip(plan.cycles, range(1000, 1251), strict=True):
        state = decode_joint_state(cycle.messages[0][1])
        np.testing.assert_array_equal(state.position, recording.position[k])
    assert sum('clock step' in w for w in plan.warnings) == 1


def test_header_stamps_a_sender_stepped_back_are_still_refused(tmp_path: Path, mabi) -> None:
    recording = sine_recording(600)
    stamps = recording.stamps_ns.copy()
    stamps[400:] -= 1_003_000_000  # the sender's clock: log times run on
    sent = Recording(
        recording.joints, stamps, recording.position, recording.velocity, recording.current, None
    )
    bag = write_bag(tmp_path / 'bag', sent, recording.stamps_ns + LATENCY_NS)
    with pytest.raises(BagError) as refused:
        build_plan(ReplayConfig(bag=str(bag)), mabi)
    message = str(refused.value)
    assert '/joint_states: time stamp goes backwards at sample 400' in message
    assert 'never re-sorts stamps a sender put out of order' in message
    assert 'the log times step back by' not in message  # no clock step is found


def test_the_replay_node_plays_a_stepped_bag_in_header_stamp_order(
    tmp_path: Path, mabi, nodes, listener
) -> None:
    from sensor_msgs.msg import JointState

    recording = sine_recording(500)
    bag = write_bag(tmp_path / 'bag', recording, stepped_logs(recording.stamps_ns, 300, STEP_NS))
    listener.subscribe(JointState, '/joint_states')
    replay = nodes('replay', {'bag': str(bag), 'rate': 4.0, 'wait_for_subscribers': 1})
    assert replay.wait(120) == 0
    listener.wait_for(
        lambda: len(listener.messages['/joint_states']) >= 500, 30, '500 joint states'
    )
    with listener.condition:
        received = [
            m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec
            for m in listener.messages['/joint_states']
        ]
    assert received == recording.stamps_ns.tolist()  # in the order they were published
    said = replay.log()
    assert said.count('clock step') == 1
    assert 'published 500 cycles' in said
