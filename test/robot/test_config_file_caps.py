"""Config and URDF files are read with a cap: a device or a file past it is refused, naming it.

``--robot /dev/zero`` once read without bound until the kernel killed the process (22 GB).
"""

from __future__ import annotations

import os
import re
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from id_learning.config_io import MAX_CONFIG_BYTES, load_yaml_mapping, read_capped
from id_learning.errors import ConfigError, IdLearningError, RobotModelError
from id_learning.robot import check_urdf, load_robot_config

REPO = Path(__file__).resolve().parents[2]


def _loaders() -> dict[str, Callable[[Path], Any]]:
    from id_learning.dataset.import_mapping import load_import_mapping
    from id_learning.twin.simulate import load_twin_config

    return {
        'robot': load_robot_config,
        'twin': load_twin_config,
        'mapping': load_import_mapping,
        'yaml': load_yaml_mapping,
    }


@pytest.mark.parametrize('loader', ['robot', 'twin', 'mapping', 'yaml'])
def test_an_endless_device_is_refused_at_once_naming_it(loader: str) -> None:
    start = time.monotonic()
    with pytest.raises(ConfigError) as err:
        _loaders()[loader](Path('/dev/zero'))
    assert (
        str(err.value)
        == '/dev/zero: cannot read config file: a character device, not a regular file'
    )
    assert time.monotonic() - start < 5.0


@pytest.mark.parametrize('loader', ['robot', 'twin', 'mapping', 'yaml'])
def test_a_config_past_the_cap_is_refused_before_it_is_read_whole(
    tmp_path: Path, loader: str
) -> None:
    big = tmp_path / 'big.yaml'
    with big.open('wb') as stream:
        stream.truncate(MAX_CONFIG_BYTES + 1)  # sparse: no disk, and no memory if read capped
    with pytest.raises(ConfigError) as err:
        _loaders()[loader](big)
    assert str(err.value) == (
        f'{big}: cannot read config file: larger than 16 MiB, which no config file is: is this '
        'the right file?'
    )


def test_the_cap_is_inclusive_and_a_missing_file_says_so(tmp_path: Path) -> None:
    path = tmp_path / 'ten.yaml'
    path.write_bytes(b'a: 1234567')
    assert read_capped(path, limit=10) == b'a: 1234567'
    with pytest.raises(ConfigError, match='larger than'):
        read_capped(path, limit=9)
    with pytest.raises(ConfigError, match=r'missing\.yaml: cannot read config file: No such file'):
        load_yaml_mapping(tmp_path / 'missing.yaml')
    with pytest.raises(ConfigError, match=r'cannot read config file: Is a directory'):
        load_yaml_mapping(tmp_path)


def test_a_pipe_is_still_read(tmp_path: Path) -> None:
    """``--robot <(...)`` hands over a pipe: read as it comes, not refused as no regular file."""
    fifo = tmp_path / 'config.fifo'
    os.mkfifo(fifo)

    def write() -> None:
        with fifo.open('w', encoding='utf-8') as stream:
            stream.write('name: piped\nvalue: 3\n')

    writer = threading.Thread(target=write, daemon=True)
    writer.start()
    assert load_yaml_mapping(fifo) == {'name': 'piped', 'value': 3}
    writer.join(5.0)


def test_a_urdf_past_the_cap_or_a_device_is_refused_naming_it(tmp_path: Path) -> None:
    big = tmp_path / 'big.urdf'
    with big.open('wb') as stream:
        stream.truncate(MAX_CONFIG_BYTES + 1)
    with pytest.raises(
        RobotModelError, match=rf'^{re.escape(str(big))}: cannot read URDF: larger than 16 MiB'
    ):
        check_urdf(big, ['joint_1'])
    with pytest.raises(RobotModelError, match=r'^/dev/zero: cannot read URDF: a character device'):
        check_urdf('/dev/zero', ['joint_1'])


def test_a_robot_config_naming_a_device_as_its_urdf_is_refused(write_config) -> None:
    with pytest.raises(
        IdLearningError, match=r"urdf '/dev/zero': /dev/zero: a character device, not"
    ):
        load_robot_config(write_config('mabi_max100', set={'urdf': '/dev/zero'}))
