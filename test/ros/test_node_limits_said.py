"""Node processes given values past their limits (probes Y11, R24) end in one line naming the key,
never a traceback; a replay that plays for hours of wall time says so as it starts (probe Y08)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

pytest.importorskip('rclpy', reason='rclpy (ROS 2 Jazzy) is not installed')

from ros.log_wait import wait_for_log
from ros.ros_helpers import STARTUP_S
from support import sine_recording

from id_learning.dataset.recording import write_recording
from id_learning.nodes.process import NodeProcess

pytestmark = pytest.mark.ros


def test_a_huge_span_or_split_ends_the_start_in_one_line_naming_the_key(
    tmp_path: Path, nodes: Callable[..., NodeProcess]
) -> None:
    bag = write_recording(sine_recording(50), tmp_path / 'bag')
    replay = nodes('replay', {'bag': str(bag), 'duration_s': 1e308}, name='replay')
    recorder = nodes(
        'recorder', {'output': str(tmp_path / 'out'), 'split_duration_s': 1e308}, name='recorder'
    )
    for node, key in ((replay, 'duration_s'), (recorder, 'split_duration_s')):
        assert node.wait(STARTUP_S) == 2, node.log()
        assert f'{key}: must be a finite number in [0, 1000000000]' in node.log()
        assert 'Traceback' not in node.log()


def test_a_play_of_hours_says_its_wall_time_as_it_starts(
    tmp_path: Path, nodes: Callable[..., NodeProcess]
) -> None:
    bag = write_recording(sine_recording(500), tmp_path / 'bag')  # 3.99 s
    replay = nodes('replay', {'bag': str(bag), 'rate': 0.001, 'reference_mode': 'none'})
    wait_for_log(replay, 'of wall time')
    assert '1.1 h of wall time' in replay.log()
    assert replay.stop() == 0


def test_only_a_long_play_is_warned_of() -> None:
    from id_learning.nodes.replay import long_play_warning

    assert long_play_warning(4_000_000_000, 1.0, loop=False) is None
    assert long_play_warning(3_600_000_000_000, 1.0, loop=False) is None  # an hour: as recorded
    said = long_play_warning(3_992_000_000, 0.001, loop=False)
    assert said is not None
    assert '3.99 s of the bag at rate 0.001 take 1.1 h of wall time' in said
    looped = long_play_warning(3_992_000_000, 0.001, loop=True)
    assert looped is not None
    assert 'each loop' in looped
