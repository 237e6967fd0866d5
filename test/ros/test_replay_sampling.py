"""The replay against the robot's IPO period, log times that do not advance, files out of order."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml

pytest.importorskip('rclpy', reason='rclpy (ROS 2 Jazzy) is not installed')

from support import sine_recording, write_contract_bag

from id_learning.bag import JOINT_STATE, BagWriter, encode_joint_state
from id_learning.dataset.recording import write_recording
from id_learning.errors import BagError
from id_learning.nodes.params import ReplayConfig
from id_learning.nodes.replay import build_plan

pytestmark = pytest.mark.ros


def test_a_reference_from_a_4_ms_bag_is_refused_with_both_periods(tmp_path: Path, mabi) -> None:
    bag = write_recording(sine_recording(800, period_s=0.004), tmp_path / 'ipo4')
    with pytest.raises(BagError, match=r'sampled every 4 ms .*IPO period is 8 ms') as caught:
        build_plan(ReplayConfig(bag=str(bag)), mabi)
    assert 'nothing is played' in str(caught.value)
    plan = build_plan(ReplayConfig(bag=str(bag), reference_mode='none'), mabi)
    assert len(plan.cycles) == 800
    assert any('sampled every 4 ms' in w and 'played as recorded' in w for w in plan.warnings)
    clean = write_recording(sine_recording(800), tmp_path / 'ipo8')
    assert build_plan(ReplayConfig(bag=str(clean), reference_mode='none'), mabi).warnings == ()


def test_log_times_that_do_not_advance_refuse_log_time_timing(tmp_path: Path, mabi) -> None:
    recording = sine_recording(300)
    bag = tmp_path / 'logtime0'
    empty = np.empty(0)
    with BagWriter(bag) as writer:
        writer.add_topic('/joint_states', JOINT_STATE)
        writer.add_topic('/motor_currents', JOINT_STATE)
        for k, stamp in enumerate(recording.stamps_ns.tolist()):
            q, v, i = recording.position[k], recording.velocity[k], recording.current[k]
            writer.write(
                '/joint_states', 0, encode_joint_state(stamp, recording.joints, q, v, empty)
            )
            writer.write(
                '/motor_currents', 0, encode_joint_state(stamp, recording.joints, empty, empty, i)
            )
    with pytest.raises(BagError, match=r'/joint_states: all 300 log times are 0 ns') as caught:
        build_plan(ReplayConfig(bag=str(bag), timing='log_time', reference_mode='none'), mabi)
    assert str(bag) in str(caught.value)
    assert 'timing:=stamp' in str(caught.value)
    assert len(build_plan(ReplayConfig(bag=str(bag)), mabi).cycles) == 300


def test_files_listed_out_of_time_order_play_in_time_order(tmp_path: Path, mabi) -> None:
    source = write_recording(sine_recording(600), tmp_path / 'whole')
    bag = tmp_path / 'split'
    write_contract_bag(bag, sine_recording(600), split_duration_ns=2_000_000_000)
    meta = yaml.safe_load((bag / 'metadata.yaml').read_text())
    files = meta['rosbag2_bagfile_information']['relative_file_paths']
    assert len(files) > 1
    meta['rosbag2_bagfile_information']['relative_file_paths'] = files[::-1]
    (bag / 'metadata.yaml').write_text(yaml.safe_dump(meta))
    plan = build_plan(ReplayConfig(bag=str(bag)), mabi)
    whole = build_plan(ReplayConfig(bag=str(source)), mabi)
    assert [c.stamp_ns for c in plan.cycles] == [c.stamp_ns for c in whole.cycles]
    shutil.rmtree(source)
