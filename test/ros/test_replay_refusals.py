"""The replay's plan refuses topics that would never be published, and names an unpaired tail."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
import yaml

pytest.importorskip('rclpy', reason='rclpy (ROS 2 Jazzy) is not installed')

from support import sine_recording

from id_learning.dataset.recording import write_recording
from id_learning.errors import BagError
from id_learning.nodes.params import ReplayConfig
from id_learning.nodes.replay import build_plan
from id_learning.nodes.replay_span import unpaired_tail

pytestmark = pytest.mark.ros


@pytest.fixture(scope='module')
def bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path: Path = write_recording(sine_recording(200), tmp_path_factory.mktemp('refuse') / 'bag')
    return path


def test_a_topic_typed_otherwise_in_metadata_is_refused_naming_it(
    bag: Path, tmp_path: Path, mabi: object
) -> None:
    copy = Path(shutil.copytree(bag, tmp_path / 'retyped'))
    meta = copy / 'metadata.yaml'
    data = yaml.safe_load(meta.read_text(encoding='utf-8'))
    topics = data['rosbag2_bagfile_information']['topics_with_message_count']
    topics[1]['topic_metadata']['type'] = 'std_msgs/msg/Float64MultiArray'
    meta.write_text(yaml.safe_dump(data), encoding='utf-8')
    with pytest.raises(BagError, match=r'/motor_currents has type std_msgs'):
        build_plan(ReplayConfig(bag=str(copy)), mabi)  # type: ignore[arg-type]


def test_an_empty_reference_source_is_refused_naming_it(tmp_path: Path, mabi: object) -> None:
    from id_learning.bag import BagWriter, iter_raw

    source = write_recording(sine_recording(50), tmp_path / 'full')
    with BagWriter(tmp_path / 'no_states') as writer:
        writer.add_topic('/joint_states', 'sensor_msgs/msg/JointState')
        writer.add_topic('/motor_currents', 'sensor_msgs/msg/JointState')
        for topic, log_ns, data in iter_raw(source, ['/motor_currents']):
            writer.write(topic, log_ns, data)
    with pytest.raises(BagError, match=r'topic /joint_states yields no message'):
        build_plan(ReplayConfig(bag=str(tmp_path / 'no_states')), mabi)  # type: ignore[arg-type]


def test_an_unpaired_tail_is_played_with_a_warning(tmp_path: Path, mabi: object) -> None:
    from id_learning.bag import BagWriter, iter_raw

    source = write_recording(sine_recording(50), tmp_path / 'full')
    messages = list(iter_raw(source, ['/joint_states', '/motor_currents']))
    with BagWriter(tmp_path / 'tail') as writer:
        writer.add_topic('/joint_states', 'sensor_msgs/msg/JointState')
        writer.add_topic('/motor_currents', 'sensor_msgs/msg/JointState')
        for topic, log_ns, data in messages[:-1]:  # the last current is lost
            writer.write(topic, log_ns, data)
    plan = build_plan(ReplayConfig(bag=str(tmp_path / 'tail')), mabi)  # type: ignore[arg-type]
    assert len(plan.cycles) == 50
    assert len(plan.warnings) == 1
    assert 'unpaired tail' in plan.warnings[0]
    assert '/motor_currents' in plan.warnings[0]
    clean = build_plan(ReplayConfig(bag=str(source)), mabi)  # type: ignore[arg-type]
    assert clean.warnings == ()


def test_unpaired_tail_ignores_complete_cycles_and_single_topics() -> None:
    path = Path('b')
    assert unpaired_tail(path, ('/a', '/b'), [[0, 1, -1], [0, 1, -1]], [0, 8]) is None
    assert unpaired_tail(path, ('/a',), [[0], [0]], [0, 8]) is None
    said = unpaired_tail(path, ('/a', '/b'), [[0, 1], [0, -1], [0]], [0, 8, 16])
    assert said is not None
    assert 'last 2 cycle(s) (stamps from 8 ns) lack /b' in said


def test_a_robot_config_of_other_joints_is_refused_before_the_timing(bag: Path) -> None:
    """Another robot's config (another IPO period too) is refused naming the joints, not a gap."""
    from id_learning.robot.config import load_robot_config

    panda = load_robot_config(Path(__file__).parents[2] / 'config' / 'panda.yaml')
    with pytest.raises(BagError, match=r'joints \[.*\] are not the robot panda joints') as caught:
        build_plan(ReplayConfig(bag=str(bag)), panda)
    assert 'gap' not in str(caught.value)
    assert 'IPO' not in str(caught.value)
