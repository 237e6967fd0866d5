"""Shared fixtures of the robot tests: the three shipped configs and edited copies of them."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any

import pytest
import yaml

from id_learning.robot import RigidBodyDynamics, RobotConfig, load_robot_config

REPO = Path(__file__).resolve().parents[2]
ROBOT_NAMES = ('mabi_max100', 'ur5', 'panda')
EXPECTED_JOINT_COUNT = {'mabi_max100': 6, 'ur5': 6, 'panda': 7}

WriteConfig = Callable[..., Path]


@pytest.fixture(scope='session')
def robot_configs() -> dict[str, RobotConfig]:
    """The shipped robot configs, by name."""
    return {name: load_robot_config(REPO / 'config' / f'{name}.yaml') for name in ROBOT_NAMES}


@pytest.fixture(scope='session')
def robot_dynamics(robot_configs: dict[str, RobotConfig]) -> dict[str, RigidBodyDynamics]:
    """The nominal rigid-body dynamics of every shipped robot, by name."""
    return {name: RigidBodyDynamics.from_config(c) for name, c in robot_configs.items()}


@pytest.fixture(params=ROBOT_NAMES)
def robot_name(request: pytest.FixtureRequest) -> str:
    """Each shipped robot in turn."""
    return request.param


def _set(data: dict[str, Any], dotted: str, value: Any) -> None:
    *parents, key = dotted.split('.')
    for parent in parents:
        data = data[parent]
    data[key] = value


def _delete(data: dict[str, Any], dotted: str) -> None:
    *parents, key = dotted.split('.')
    for parent in parents:
        data = data[parent]
    del data[key]


@pytest.fixture
def write_config(tmp_path: Path) -> WriteConfig:
    """Return a writer of edited copies of a shipped config into tmp_path.

    ``write(name, set={'drives.gear_ratio': 0}, delete=['payload_frame'])`` loads
    config/<name>.yaml, makes a relative ``urdf`` path absolute (it is relative to the YAML's
    folder, which the copy leaves), applies the edits and returns the path of the copy.
    """

    def write(
        name: str,
        set: Mapping[str, Any] | None = None,
        delete: Iterable[str] = (),
        filename: str | None = None,
    ) -> Path:
        source = REPO / 'config' / f'{name}.yaml'
        data = yaml.safe_load(source.read_text(encoding='utf-8'))
        if not str(data['urdf']).startswith('example-robot-data://'):
            data['urdf'] = str((source.parent / data['urdf']).resolve())
        for dotted, value in (set or {}).items():
            _set(data, dotted, value)
        for dotted in delete:
            _delete(data, dotted)
        path = tmp_path / (filename or f'{name}.yaml')
        path.write_text(yaml.safe_dump(data, sort_keys=False), encoding='utf-8')
        return path

    return write
