"""A replay holds its bag shared while it plays: a recorder told to overwrite it is refused in one
line naming the bag and its reader, and the bag is left whole (probe Y02). Both in their own
processes."""

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


def _files(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


def test_a_recorder_does_not_overwrite_the_bag_a_replay_plays(
    tmp_path: Path, nodes: Callable[..., NodeProcess]
) -> None:
    bag = write_recording(sine_recording(100), tmp_path / 'played')
    before = _files(bag)
    replay = nodes(
        'replay', {'bag': str(bag), 'rate': 0.01, 'reference_mode': 'none', 'loop': True}
    )
    wait_for_log(replay, 'loaded 100 cycles')
    recorder = nodes('recorder', {'output': str(bag), 'overwrite': True}, name='recorder')
    assert recorder.wait(STARTUP_S) == 2, recorder.log()
    log = recorder.log()
    assert f'{bag}: another process (pid {replay.process.pid}, a replay) is reading it' in log
    assert 'Traceback' not in log
    assert replay.is_running
    assert _files(bag) == before
    assert replay.stop() == 0
    assert not bag.with_name('played.lock').exists()  # let go with the replay
