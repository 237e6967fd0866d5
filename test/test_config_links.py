"""A config reached through a symbolic link reads its relative paths as its author wrote them."""

from __future__ import annotations

import pytest
from support import REPO

from id_learning.errors import ConfigError
from id_learning.robot import load_robot_config
from id_learning.twin import load_twin_config


def test_a_linked_twin_config_finds_its_robot_and_its_robots_urdf(tmp_path):
    (tmp_path / 'twin.yaml').symlink_to(REPO / 'config' / 'twin_default.yaml')
    (tmp_path / 'robot.yaml').symlink_to(REPO / 'config' / 'mabi_max100.yaml')
    twin = load_twin_config(tmp_path / 'twin.yaml')
    assert twin.robot.source == (REPO / 'config' / 'mabi_max100.yaml').resolve()
    robot = load_robot_config(tmp_path / 'robot.yaml')
    assert robot.urdf_path == (REPO / 'urdf' / 'mabi_max100.urdf').resolve()


def test_a_path_beside_the_link_is_read_before_the_targets(tmp_path):
    (tmp_path / 'twin.yaml').symlink_to(REPO / 'config' / 'twin_default.yaml')
    mabi = (REPO / 'config' / 'mabi_max100.yaml').read_text()
    (tmp_path / 'mabi_max100.yaml').write_text(mabi.replace('../urdf/', f'{REPO}/urdf/'))
    twin = load_twin_config(tmp_path / 'twin.yaml')
    assert twin.robot.source == (tmp_path / 'mabi_max100.yaml').resolve()


def test_a_missing_robot_names_the_twin_config_and_its_key(tmp_path):
    (tmp_path / 'twin.yaml').write_text('robot: nothere.yaml\n')
    with pytest.raises(ConfigError, match=r"twin\.yaml: robot 'nothere\.yaml': .*nothere\.yaml"):
        load_twin_config(tmp_path / 'twin.yaml')
