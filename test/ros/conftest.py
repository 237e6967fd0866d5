"""Fixtures of the ROS tests: a DDS domain per test, node processes, an in-test listener."""

from __future__ import annotations

import pytest


@pytest.fixture
def domain_id() -> int:
    """A DDS domain of this test alone."""
    from ros.ros_helpers import random_domain

    return random_domain()


@pytest.fixture
def nodes(tmp_path, domain_id):
    """start(module, parameters, name=..., remaps=...) -> NodeProcess; all stopped afterwards."""
    from ros.ros_helpers import node_processes

    with node_processes(tmp_path, domain_id) as start:
        yield start


@pytest.fixture
def listener(domain_id):
    """An rclpy node in the test process, in the test's domain."""
    pytest.importorskip('rclpy', reason='rclpy (ROS 2 Jazzy) is not installed')
    from ros.ros_helpers import Listener

    node = Listener(domain_id)
    try:
        yield node
    finally:
        node.close()


@pytest.fixture(scope='session')
def tiny_artifacts(tmp_path_factory, mabi):
    """Folder per kind of a tiny fitted model (see test/predictor/tiny_artifacts.py)."""
    from predictor.tiny_artifacts import build_tiny_artifacts

    return build_tiny_artifacts(tmp_path_factory.mktemp('artifacts'), mabi)
