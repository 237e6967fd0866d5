"""Shared fixtures: the repo's robot configs and small twin recordings built in code."""

from __future__ import annotations

import os
import random
from pathlib import Path

import pytest
from hypothesis import settings
from support import REPO, twin_config

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
