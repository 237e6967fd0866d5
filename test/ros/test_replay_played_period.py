"""The replay judges lateness against the period it plays, the IPO period / rate (the probe's
B66: at rate 100 it counted against the bag's 8 ms, so a cycle 80 played periods late was on
time)."""

from __future__ import annotations

import pytest

pytest.importorskip('rclpy', reason='rclpy (ROS 2 Jazzy) is not installed')

from support import sine_recording

from id_learning.dataset.recording import write_recording

pytestmark = pytest.mark.ros


@pytest.mark.parametrize(('rate', 'grid'), [(100.0, '0.08 ms grid'), (0.5, '16 ms grid')])
def test_a_replay_reports_lateness_against_the_played_period(tmp_path, nodes, rate, grid):
    bag = write_recording(sine_recording(50), tmp_path / 'bag')
    replay = nodes('replay', {'bag': str(bag), 'rate': rate, 'publish_clock': False})
    assert replay.wait(120) == 0, replay.log()
    assert f'at rate {rate:g}; lateness against the {grid}' in replay.log()  # before: 8 ms


def test_a_replay_on_sim_time_waits_for_other_nodes_not_its_own_clock_reader(tmp_path, nodes):
    # Probe 16 (D39): with use_sim_time the replay's own /clock subscription counted as the
    # subscriber it waited for, so it played at once to nobody.
    bag = write_recording(sine_recording(50), tmp_path / 'bag')
    replay = nodes('replay', {
        'bag': str(bag), 'use_sim_time': True, 'wait_for_subscribers': 1, 'wait_timeout_s': 2.0,
    })  # fmt: skip
    assert replay.wait(120) == 0, replay.log()
    assert 'playing with fewer than 1 subscriptions after 2 s' in replay.log()
