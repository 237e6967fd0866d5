"""Storage files against metadata.yaml: files listed out of time order, a non-cdr encoding."""

from __future__ import annotations

import logging
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from support import sine_recording, write_contract_bag

from id_learning.bag import bag_info, iter_raw, read_joint_states
from id_learning.dataset.inspect import inspect_bag
from id_learning.dataset.recording import load_recording
from id_learning.errors import BagError

N_SAMPLES = 600


@pytest.fixture(scope='module')
def split_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A contract bag split into three storage files of 1.6 s each."""
    recording = sine_recording(N_SAMPLES)
    path = tmp_path_factory.mktemp('split') / 'bag'
    write_contract_bag(path, recording, split_duration_ns=1_600_000_000)
    assert len(listed(path)) == 3
    return path


def listed(path: Path) -> list[str]:
    meta = yaml.safe_load((path / 'metadata.yaml').read_text())
    return list(meta['rosbag2_bagfile_information']['relative_file_paths'])


def relisted(source: Path, target: Path, order: list[str]) -> Path:
    """A copy of ``source`` whose metadata.yaml lists its files in ``order``."""
    if target.exists():
        shutil.rmtree(target)
    shutil.copytree(source, target)
    meta = yaml.safe_load((target / 'metadata.yaml').read_text())
    meta['rosbag2_bagfile_information']['relative_file_paths'] = order
    (target / 'metadata.yaml').write_text(yaml.safe_dump(meta))
    return target


@settings(
    max_examples=6, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(order=st.permutations([0, 1, 2]))
def test_files_are_read_in_time_order_whatever_order_metadata_lists_them(
    split_bag: Path, tmp_path: Path, order: list[int]
) -> None:
    names = listed(split_bag)
    bag = relisted(split_bag, tmp_path / 'relisted', [names[k] for k in order])
    expected = list(iter_raw(split_bag, ['/joint_states', '/motor_currents']))
    assert list(iter_raw(bag, ['/joint_states', '/motor_currents'])) == expected
    note = bag_info(bag).order_note
    assert (note is None) == (order == [0, 1, 2])


def test_files_listed_backwards_are_named_and_every_reader_agrees(
    split_bag: Path, tmp_path: Path, mabi, caplog: pytest.LogCaptureFixture
) -> None:
    names = listed(split_bag)
    bag = relisted(split_bag, tmp_path / 'backwards', names[::-1])
    with caplog.at_level(logging.WARNING):
        stamps = read_joint_states(bag, '/joint_states').stamps_ns
    assert (np.diff(stamps) > 0).all()
    note = bag_info(bag).order_note
    assert note is not None
    assert f'as {", ".join(names[::-1])}' in note
    assert f'order {", ".join(names)}' in note
    assert any(note in record.getMessage() for record in caplog.records)
    assert load_recording(bag, mabi).n_samples == N_SAMPLES
    report = inspect_bag(bag, robot=mabi)
    assert report.contract.stamps_match
    assert [p for p in report.problems if 'relative_file_paths' in p] == [
        f'metadata: {note.removeprefix(f"{bag}: ")}'
    ]
    assert not any('backwards' in p for p in report.problems)


def test_a_topic_in_ros1_encoding_is_refused_naming_topic_encoding_and_cdr(
    split_bag: Path, tmp_path: Path, mabi
) -> None:
    from mcap.reader import make_reader
    from mcap.writer import Writer

    bag = tmp_path / 'ros1'
    shutil.copytree(split_bag, bag)
    first = bag / listed(bag)[0]
    with first.open('rb') as stream:
        records = list(make_reader(stream).iter_messages(log_time_order=True))
    with first.open('wb') as stream:  # the same messages, on channels that say ros1
        writer = Writer(stream)
        writer.start(profile='ros2', library='test')
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        for schema, channel, message in records:
            if schema.id not in schemas:
                schemas[schema.id] = writer.register_schema(
                    schema.name, schema.encoding, schema.data
                )
            if channel.id not in channels:
                channels[channel.id] = writer.register_channel(
                    channel.topic, 'ros1', schemas[schema.id], channel.metadata
                )
            writer.add_message(
                channels[channel.id], message.log_time, message.data, message.publish_time
            )
        writer.finish()
    expected = (
        rf"topic /joint_states is stored with message_encoding 'ros1' in {first.name} "
        r"\(\d+ messages\); rosbag2 \(ROS 2\) bags hold 'cdr'"
    )
    with pytest.raises(BagError, match=expected):
        list(iter_raw(bag, ['/joint_states']))
    with pytest.raises(BagError, match=expected):
        load_recording(bag, mabi)
    with pytest.raises(BagError, match=expected):
        inspect_bag(bag, robot=mabi)
