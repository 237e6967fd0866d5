"""A robot config's ``urdf``: a path, file://, example-robot-data:// or package:// (U02/U04/U05).

Every refusal names what is wrong and the forms a ``urdf`` takes; a path inside a package never
leaves it.
"""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from id_learning.errors import ConfigError
from id_learning.robot import load_robot_config
from id_learning.robot.urdf_location import URDF_FORMS, resolve_urdf

REPO = Path(__file__).resolve().parents[2]
MABI_URDF = REPO / 'urdf/mabi_max100.urdf'


@pytest.fixture
def ros_prefix(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """An ament prefix installing ``mabi_description`` (a URDF in urdf/): AMENT_PREFIX_PATH's."""
    prefix = tmp_path / 'install'
    index = prefix / 'share/ament_index/resource_index/packages'
    index.mkdir(parents=True)
    (index / 'mabi_description').touch()
    (prefix / 'share/mabi_description/urdf').mkdir(parents=True)
    shutil.copy(MABI_URDF, prefix / 'share/mabi_description/urdf/mabi.urdf')
    (prefix / 'share/secret.urdf').write_text('<robot/>')  # beside the package, not in it
    monkeypatch.setenv('AMENT_PREFIX_PATH', f'{tmp_path / "empty"}:{prefix}')
    return prefix


def test_a_file_url_names_the_same_urdf_as_its_path(write_config: Any, tmp_path: Path) -> None:
    spaced = tmp_path / 'my robot' / 'mabi.urdf'
    spaced.parent.mkdir()
    shutil.copy(MABI_URDF, spaced)
    for value in (spaced.as_uri(), f'file://localhost{spaced.as_uri()[len("file://") :]}'):
        assert '%20' in value
        robot = load_robot_config(write_config('mabi_max100', set={'urdf': value}))
        assert robot.urdf_path == spaced.resolve()


def test_a_package_url_is_found_through_the_ament_index(
    write_config: Any, ros_prefix: Path
) -> None:
    value = 'package://mabi_description/urdf/mabi.urdf'
    robot = load_robot_config(write_config('mabi_max100', set={'urdf': value}))
    assert robot.urdf_path == (ros_prefix / 'share/mabi_description/urdf/mabi.urdf').resolve()


@pytest.mark.parametrize(
    ('value', 'match'),
    [
        ('example-robot-data://../../../../../etc/passwd',
         r"'\.\./\.\./\.\./\.\./\.\./etc/passwd' leaves the example-robot-data package"),
        ('example-robot-data:///etc/passwd', r"'/etc/passwd' leaves the example-robot-data"),
        ('package://mabi_description/../secret.urdf',
         r"'\.\./secret\.urdf' leaves the mabi_description"),
        ('package://mabi_description/urdf/none.urdf',
         r"no file urdf/none\.urdf in the ROS package 'mabi_description'"),
        ('package://ur_description/urdf/ur5.urdf',
         r"the ROS package 'ur_description' is not in the package index of AMENT_PREFIX_PATH"),
        ('package:///urdf/x.urdf', r'package:// names no package'),
        ('file://robots.example.com/mabi.urdf',
         r'a file on another host \(robots\.example\.com\)'),
        ('https://example.com/mabi.urdf', r'the scheme https:// is not one the urdf is read from'),
        ('file:///nonexistent/mabi.urdf', r'/nonexistent/mabi\.urdf: no such file'),
    ],
)  # fmt: skip
def test_each_urdf_refusal_says_why_and_names_every_form(
    tmp_path: Path, ros_prefix: Path, value: str, match: str
) -> None:
    with pytest.raises(ConfigError, match=rf"^robot\.yaml: urdf '.*': {match}") as err:
        resolve_urdf(value, tmp_path, 'robot.yaml')
    assert str(err.value).endswith(f'; the urdf may be {URDF_FORMS}')
    for form in ('file:///', 'example-robot-data://', 'package://', 'relative to the robot'):
        assert form in URDF_FORMS


def test_a_package_url_without_a_ros_workspace_says_it_needs_one(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.delenv('AMENT_PREFIX_PATH', raising=False)
    with pytest.raises(
        ConfigError, match=r'package:// needs a ROS package index, and AMENT_PREFIX_PATH is empty'
    ):
        resolve_urdf('package://ur_description/urdf/ur5_robot.urdf', tmp_path)


@settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(parts=st.lists(st.sampled_from(['urdf', '..', '.', 'mabi.urdf', 'share']), min_size=1,
                      max_size=5))  # fmt: skip
def test_a_package_path_resolves_inside_its_package_or_is_refused(
    tmp_path: Path, ros_prefix: Path, parts: list[str]
) -> None:
    value = 'package://mabi_description/' + '/'.join(parts)
    share = (ros_prefix / 'share/mabi_description').resolve()
    if '..' in parts:
        with pytest.raises(ConfigError, match='leaves the mabi_description package'):
            resolve_urdf(value, tmp_path)
    elif not share.joinpath(*parts).is_file():
        with pytest.raises(ConfigError, match=r"no file .* in the ROS package 'mabi_description'"):
            resolve_urdf(value, tmp_path)
    else:
        assert resolve_urdf(value, tmp_path).is_relative_to(share)
