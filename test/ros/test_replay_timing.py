"""The replay runs train's timing checks first: a hole or stamps out of order are named as train
names them (never re-sorted silently, never left to surface as an impossible acceleration), and
what the message advises plays. Real bags, the replay's plan and its node."""

from __future__ import annotations

import re
from dataclasses import replace

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

pytest.importorskip('rclpy', reason='rclpy (ROS 2 Jazzy) is not installed')

from support import sine_recording, write_contract_bag

from id_learning.dataset.recording import write_recording
from id_learning.errors import BagError
from id_learning.nodes.params import ReplayConfig
from id_learning.nodes.replay import build_plan

pytestmark = pytest.mark.ros

N = 600
PERIOD_NS = 8_000_000


def _with_hole(before: int, periods: int):
    """A recording whose samples from ``before`` on come ``periods`` periods late."""
    recording = sine_recording(N)
    stamps = recording.stamps_ns.copy()
    stamps[before:] += (periods - 1) * PERIOD_NS
    return replace(recording, stamps_ns=stamps)


def _advice(message: str) -> dict[str, float]:
    """The start_offset_s and duration_s a refusal advises."""
    found = re.findall(r'(duration_s|start_offset_s) ([\d.]+)', message)
    return {key: float(value) for key, value in found}


@settings(
    max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(before=st.integers(150, N - 150), periods=st.integers(4, 2000))
def test_a_hole_in_the_span_is_named_as_train_names_it_and_the_advice_plays(
    before, periods, tmp_path_factory, mabi
):
    bag = write_recording(_with_hole(before, periods), tmp_path_factory.mktemp('hole') / 'bag')
    with pytest.raises(BagError) as refused:
        build_plan(ReplayConfig(bag=str(bag)), mabi)
    message = str(refused.value)
    assert f'/joint_states: gap of {periods * 8:.1f} ms before sample {before} ' in message
    assert 'exceeds 3 IPO periods of 8 ms' in message
    advice = _advice(message)
    after = build_plan(ReplayConfig(bag=str(bag), start_offset_s=advice['start_offset_s']), mabi)
    assert len(after.cycles) == N - before
    ahead = build_plan(ReplayConfig(bag=str(bag), duration_s=advice['duration_s']), mabi)
    assert len(ahead.cycles) == before


def test_a_hole_in_the_padding_only_ends_the_padding(tmp_path, mabi):
    bag = write_recording(_with_hole(300, 500), tmp_path / 'bag')  # 4 s after 2.4 s
    plan = build_plan(ReplayConfig(bag=str(bag), duration_s=1.0), mabi)
    assert len(plan.cycles) == 126  # 0 .. 1 s
    plan = build_plan(ReplayConfig(bag=str(bag), start_offset_s=7.0), mabi)
    assert plan.cycles[0].stamp_ns >= int(_with_hole(300, 500).stamps_ns[300])


def test_stamps_swapped_in_the_log_order_are_named_not_re_sorted(tmp_path, mabi):
    recording = sine_recording(N)
    stamps = recording.stamps_ns.copy()
    stamps[[200, 201]] = stamps[[201, 200]]
    swapped = write_contract_bag(tmp_path / 'swapped', replace(recording, stamps_ns=stamps))
    with pytest.raises(BagError) as refused:
        build_plan(ReplayConfig(bag=str(swapped)), mabi)
    message = str(refused.value)
    assert f'/joint_states: time stamp goes backwards at sample 201: {stamps[200]} ns' in message
    assert 'never re-sorts' in message
    # What the message advises plays the bag as recorded.
    plan = build_plan(
        ReplayConfig(bag=str(swapped), timing='log_time', reference_mode='none'), mabi
    )
    assert plan.message_count == 2 * N


def test_a_played_topic_with_stamps_out_of_order_is_named_too(tmp_path, mabi):
    recording = sine_recording(N)
    currents = recording.stamps_ns.copy()
    currents[[50, 51]] = currents[[51, 50]]
    bag = write_contract_bag(tmp_path / 'bag', recording, stamps_mc=currents)
    with pytest.raises(BagError, match=r'/motor_currents: time stamp goes backwards at sample 51'):
        build_plan(ReplayConfig(bag=str(bag)), mabi)
    plan = build_plan(ReplayConfig(bag=str(bag), timing='log_time'), mabi)
    assert len(plan.cycles) == N


def test_the_replay_node_refuses_a_bag_with_a_hole_in_one_line(tmp_path, nodes):
    bag = write_recording(_with_hole(250, 1251), tmp_path / 'bag')  # a 10 s hole
    replay = nodes('replay', {'bag': str(bag), 'wait_for_subscribers': 0})
    assert replay.wait(120) == 2
    said = replay.log()
    assert 'error: ' in said
    assert 'gap of 10008.0 ms before sample 250' in said
    assert 'acceleration' not in said
    assert 'Traceback' not in said
