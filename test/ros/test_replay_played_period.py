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
