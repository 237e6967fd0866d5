"""Shared fixtures: the repo's robot configs and small twin recordings built in code."""

from __future__ import annotations

import os
import random
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any

import pytest
import yaml
from hypothesis import settings
from support import REPO, twin_config

from id_learning.physics import RigidBodyDynamics
from id_learning.robot import RobotConfig, load_robot_config

# Property tests are reproducible and never time out on a loaded 2-core machine.
settings.register_profile('id_learning', derandomize=True, deadline=None, max_examples=60)
settings.load_profile('id_learning')

# Every test run stays on this machine's loopback and in its own DDS domain.
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.setdefault('ROS_DOMAIN_ID', str(random.SystemRandom().randint(1, 100)))


@pytest.fixture(scope='session')
def repo() -> Path:
    """The source checkout."""
    return REPO


@pytest.fixture(scope='session')
def mabi():
    """The MABI MAX 100 robot config."""
    from id_learning.robot import load_robot_config

    return load_robot_config(REPO / 'config/mabi_max100.yaml')


@pytest.fixture(scope='session')
def short_twin():
    """A 26 s default twin run (one excitation segment) and its config."""
    from id_learning.twin import simulate

    config = twin_config(30.0)
    return config, simulate(config)


# -- the shipped robot configs and edited copies (robot and physics tests) ----------------------
ROBOT_NAMES = ('mabi_max100', 'ur5', 'panda')

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
