"""A metadata.yaml that is empty or not a rosbag2 mapping is refused naming the file and why."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from support import sine_recording

from id_learning.bag import bag_info
from id_learning.dataset.recording import write_recording
from id_learning.errors import BagError


@pytest.fixture(scope='module')
def bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path: Path = write_recording(sine_recording(30), tmp_path_factory.mktemp('meta') / 'bag')
    return path


@pytest.mark.parametrize(
    ('text', 'said'),
    [
        ('', 'is empty'),
        ('\n  \n', 'is empty'),
        ('# only a comment\n', 'holds no YAML value'),
        ('- a\n- b\n', 'holds a list, not a mapping'),
        ('42\n', 'holds a int, not a mapping'),
        ('other: 1\n', 'has no rosbag2_bagfile_information mapping'),
        ('rosbag2_bagfile_information: 3\n', 'has no rosbag2_bagfile_information mapping'),
    ],
)
def test_a_metadata_yaml_that_is_not_a_bag_mapping_is_refused(
    bag: Path, tmp_path: Path, text: str, said: str
) -> None:
    copy = Path(shutil.copytree(bag, tmp_path / 'copy'))
    (copy / 'metadata.yaml').write_text(text, encoding='utf-8')
    with pytest.raises(BagError) as caught:
        bag_info(copy)
    message = str(caught.value)
    assert message.startswith(f'{copy / "metadata.yaml"} {said}')
    assert 'bag recover' in message
    assert 'NoneType' not in message
