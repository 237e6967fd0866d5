"""URDFs that cannot be the robot are refused, what misleads is said once: invariants and messages.

The invariants run over generated serial arms (``_arm``): any zero axis is refused, any arm
whose moving links are all massless is refused, any driven joint with a ``<mimic>`` is refused,
any arm of physical links (masses > 0, inertias of solid boxes turned any way) loads without a
word, and a massless link among massive ones is said once, naming it, unless it is a hinge
between joints through one point.
"""

from __future__ import annotations

import logging
import re
import tempfile
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from id_learning.errors import RobotModelError
from id_learning.robot import check_urdf, load_robot_config, urdf_checks

REPO = Path(__file__).resolve().parents[2]
URDF = REPO / 'urdf/mabi_max100.urdf'
MABI_JOINTS = tuple(f'joint_{i}' for i in range(1, 7))
SETTINGS = settings(max_examples=40, deadline=None, derandomize=True)


# -- generated arms -------------------------------------------------------------------------------
@dataclass(frozen=True)
class Link:
    """One link: mass [kg] (None: no <inertial>) and its inertia about the COM [kg*m^2]."""

    mass: float | None
    inertia: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))


@dataclass(frozen=True)
class Joint:
    """One revolute joint: its origin in the parent link and its axis text."""

    origin: tuple[float, float, float]
    axis: str = '0 0 1'
    mimic: str | None = None


def _arm(links: list[Link], joints: list[Joint]) -> str:
    """A serial arm base -> joint_1 -> link_1 ... -> joint_n -> link_n -> flange (a frame)."""
    parts = ['<?xml version="1.0"?>\n<robot name="arm">', '<link name="base_link"/>']
    parent = 'base_link'
    for i, (link, joint) in enumerate(zip(links, joints, strict=True), start=1):
        mimic = f'<mimic joint="{joint.mimic}"/>' if joint.mimic else ''
        parts.append(
            f'<joint name="joint_{i}" type="revolute"><parent link="{parent}"/>'
            f'<child link="link_{i}"/><origin xyz="{" ".join(map(str, joint.origin))}"/>'
            f'<axis xyz="{joint.axis}"/>'
            f'<limit lower="-3" upper="3" velocity="2" effort="1e7"/>{mimic}</joint>'
        )
        if link.mass is None:
            parts.append(f'<link name="link_{i}"/>')
        else:
            (ixx, ixy, ixz), (_, iyy, iyz), (_, _, izz) = link.inertia.tolist()
            parts.append(
                f'<link name="link_{i}"><inertial><origin xyz="0.05 0 0.1"/>'
                f'<mass value="{link.mass!r}"/><inertia ixx="{ixx!r}" ixy="{ixy!r}" '
                f'ixz="{ixz!r}" iyy="{iyy!r}" iyz="{iyz!r}" izz="{izz!r}"/></inertial></link>'
            )
        parent = f'link_{i}'
    parts.append(
        f'<joint name="flange_joint" type="fixed"><parent link="{parent}"/>'
        '<child link="flange"/><origin xyz="0 0 0.1"/></joint><link name="flange"/>'
    )
    return '\n'.join([*parts, '</robot>'])


def _check(text: str) -> tuple[Path, list[str]]:
    """Write the URDF and check it with joint_1 .. joint_n driven: (its path, the warnings)."""
    n = text.count('type="revolute"')
    with tempfile.TemporaryDirectory(prefix='urdf_checks_') as folder:
        path = Path(folder) / 'arm.urdf'
        path.write_text(text, encoding='utf-8')
        return path, check_urdf(path, [f'joint_{i}' for i in range(1, n + 1)])


def _rotation(quaternion: list[float]) -> np.ndarray:
    w, x, y, z = np.asarray(quaternion) / np.linalg.norm(quaternion)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


QUATERNIONS = st.lists(st.floats(-1, 1), min_size=4, max_size=4).filter(
    lambda q: np.linalg.norm(q) > 0.1
)


@st.composite
def physical_links(draw: st.DrawFn) -> Link:
    """A solid box of 0.1 .. 500 kg, 1 cm .. 1 m a side, turned any way: a rigid body."""
    mass = draw(st.floats(0.1, 500.0))
    a, b, c = (draw(st.floats(0.01, 1.0)) for _ in range(3))
    moments = mass / 12 * np.array([b * b + c * c, a * a + c * c, a * a + b * b])
    rotation = _rotation(draw(QUATERNIONS))
    return Link(mass, rotation @ np.diag(moments) @ rotation.T)


OFFSETS = st.tuples(*(st.floats(-1.0, 1.0) for _ in range(3))).filter(
    lambda xyz: np.linalg.norm(xyz) > 0.01
)
AXES = st.tuples(*(st.floats(-1.0, 1.0) for _ in range(3))).filter(
    lambda xyz: np.linalg.norm(xyz) > 0.01
)


@st.composite
def physical_arms(draw: st.DrawFn) -> tuple[list[Link], list[Joint]]:
    """An arm of 1 .. 7 physical links, each joint off its parent's origin, axes any way."""
    n = draw(st.integers(1, 7))
    links = [draw(physical_links()) for _ in range(n)]
    joints = [Joint(draw(OFFSETS), ' '.join(repr(x) for x in draw(AXES))) for _ in range(n)]
    return links, joints


@st.composite
def massless_links(draw: st.DrawFn, with_inertia: bool = True) -> Link:
    """A link without mass: no <inertial>, or mass 0 with (``with_inertia``) or without one."""
    kinds = ['none', 'zero', 'zero with inertia'] if with_inertia else ['none', 'zero']
    kind = draw(st.sampled_from(kinds))
    if kind == 'none':
        return Link(None)
    if kind == 'zero':
        return Link(0.0)
    return replace(draw(physical_links()), mass=0.0)


# -- invariants -----------------------------------------------------------------------------------
@SETTINGS
@given(physical_arms())
def test_any_arm_of_physical_links_loads_without_a_word(
    arm: tuple[list[Link], list[Joint]],
) -> None:
    _, said = _check(_arm(*arm))
    assert said == []


@SETTINGS
@given(physical_arms(), st.data())
def test_any_zero_axis_is_refused_naming_the_joint_and_the_file(
    arm: tuple[list[Link], list[Joint]], data: st.DataObject
) -> None:
    links, joints = arm
    k = data.draw(st.integers(0, len(joints) - 1))
    zero = data.draw(st.sampled_from(['0 0 0', '0.0 -0.0 0', '1e-9 0 0', '0 0 1e-12']))
    joints[k] = replace(joints[k], axis=zero)
    text = _arm(links, joints)
    with pytest.raises(RobotModelError, match=rf"joint joint_{k + 1}: axis '{zero}' has length"):
        _check(text)


@SETTINGS
@given(physical_arms(), st.data())
def test_any_arm_whose_moving_links_are_all_massless_is_refused(
    arm: tuple[list[Link], list[Joint]], data: st.DataObject
) -> None:
    _, joints = arm
    links = [data.draw(massless_links()) for _ in joints]
    with pytest.raises(RobotModelError) as err:
        _check(_arm(links, joints))
    message = str(err.value)
    assert re.search(
        rf'arm\.urdf: none of the {len(joints) + 1} links below joint\(s\) joint_1 carries mass',
        message,
    )
    assert 'no torque at all' in message
    assert '\n' not in message


@SETTINGS
@given(physical_arms(), st.data())
def test_any_driven_joint_that_mimics_another_is_refused(
    arm: tuple[list[Link], list[Joint]], data: st.DataObject
) -> None:
    links, joints = arm
    if len(joints) < 2:
        joints.append(Joint((0.0, 0.0, 0.3)))
        links.append(data.draw(physical_links()))
    k = data.draw(st.integers(1, len(joints) - 1))
    joints[k] = replace(joints[k], mimic=f'joint_{k}')
    with pytest.raises(
        RobotModelError, match=rf'arm\.urdf: joint joint_{k + 1} mimics joint_{k} \(<mimic'
    ):
        _check(_arm(links, joints))


@SETTINGS
@given(physical_arms(), st.data())
def test_a_massless_link_among_massive_ones_is_said_once_naming_it(
    arm: tuple[list[Link], list[Joint]], data: st.DataObject
) -> None:
    links, joints = arm
    if len(links) < 2:
        links.append(data.draw(physical_links()))
        joints.append(Joint((0.0, 0.0, 0.3)))
    k = data.draw(st.integers(0, len(links) - 1))
    links[k] = data.draw(massless_links())
    _, said = _check(_arm(links, joints))
    assert len(said) == 1
    assert re.search(
        rf'link link_{k + 1} \(moved by joint_{k + 1}\) has (no <inertial>|mass 0)', said[0]
    )
    assert 'the model misses its weight and inertia' in said[0]
    carriers = ', '.join(f'joint_{i}' for i in range(1, k + 2))
    assert f'the torques it predicts for {carriers} lack its share' in said[0]


@SETTINGS
@given(physical_arms(), st.data())
def test_a_massless_hinge_between_joints_through_one_point_is_no_missing_link(
    arm: tuple[list[Link], list[Joint]], data: st.DataObject
) -> None:
    links, joints = arm
    links.append(data.draw(physical_links()))
    joints.append(Joint((0.0, 0.0, 0.0), '1 0 0'))  # through the previous joint's origin
    links[-2] = data.draw(massless_links(with_inertia=False))  # the hinge: a link of no length
    _, said = _check(_arm(links, joints))
    assert said == []


@SETTINGS
@given(
    st.floats(0.1, 500.0),
    st.lists(st.floats(0.001, 10.0), min_size=3, max_size=3),
    QUATERNIONS,
)
def test_principal_moments_against_the_triangle_inequality_are_said_not_refused(
    mass: float, moments: list[float], quaternion: list[float]
) -> None:
    small = sorted(moments)[:2]
    broken = np.array([*small, 1.5 * sum(small)])  # I1 + I2 < I3
    rotation = _rotation(quaternion)
    link = Link(mass, rotation @ np.diag(broken) @ rotation.T)
    _, said = _check(_arm([link, Link(10.0, np.eye(3))], [Joint((0, 0, 0.5)), Joint((0, 0, 0.5))]))
    assert len(said) == 1
    assert 'link link_1: principal moments' in said[0]
    assert 'break the triangle inequality' in said[0]


@SETTINGS
@given(
    st.floats(1.0, 500.0),
    st.floats(0.01, 10.0),
    st.lists(st.floats(0.01, 10.0), min_size=2, max_size=2),
    QUATERNIONS,
)
def test_a_heavy_link_with_a_negative_principal_moment_is_refused(
    mass: float, negative: float, positive: list[float], quaternion: list[float]
) -> None:
    rotation = _rotation(quaternion)
    inertia = rotation @ np.diag([-negative, *positive]) @ rotation.T
    arm = _arm([Link(mass, inertia), Link(10.0, np.eye(3))], [Joint((0, 0, 0.5))] * 2)
    with pytest.raises(RobotModelError, match=r'link link_1: .*\(not positive semi-definite\)'):
        _check(arm)


# -- the probe's URDFs: edits of the MABI URDF, through load_robot_config -------------------------
#: link_3 of the shipped URDF: 150 kg.
LINK_3_INERTIAL = re.compile(r'(<link name="link_3">\s*)<inertial>.*?</inertial>', re.S)


def _mabi(tmp_path: Path, write_config, edit) -> Path:
    """A robot config of the MABI arm whose URDF is ``edit(text)``."""
    text = URDF.read_text(encoding='utf-8')
    edited = edit(text)
    assert edited != text
    urdf = tmp_path / 'edited.urdf'
    urdf.write_text(edited, encoding='utf-8')
    return write_config('mabi_max100', set={'urdf': str(urdf)})


def test_a_link_typed_massless_is_said_naming_it_and_what_the_model_misses(
    tmp_path: Path, write_config, caplog
) -> None:
    config = _mabi(
        tmp_path, write_config, lambda t: t.replace('<mass value="150"/>', '<mass value="0"/>')
    )
    load_robot_config(config)
    lines = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(lines) == 1
    assert lines[0].startswith(
        f'{tmp_path / "edited.urdf"}: link link_3 (moved by joint_3) has mass 0'
    )
    assert 'a mass typed as 0?' in lines[0]
    assert 'the torques it predicts for joint_1, joint_2, joint_3 lack its share' in lines[0]
    assert 'cannot mislead' not in caplog.text


def test_a_link_without_inertial_is_said_and_said_once_per_process(
    tmp_path: Path, write_config, caplog
) -> None:
    from id_learning.physics import RigidBodyDynamics

    config = _mabi(tmp_path, write_config, lambda t: LINK_3_INERTIAL.sub(r'\1', t))
    robot = load_robot_config(config)
    RigidBodyDynamics.from_config(robot)
    RigidBodyDynamics.from_config(load_robot_config(config))
    lines = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(lines) == 1
    assert (
        'link link_3 (moved by joint_3) has no <inertial> while the other moving links' in lines[0]
    )


def test_a_urdf_without_any_inertial_is_refused_in_one_line(tmp_path: Path, write_config) -> None:
    config = _mabi(
        tmp_path, write_config, lambda t: re.sub(r'<inertial>.*?</inertial>', '', t, flags=re.S)
    )
    with pytest.raises(RobotModelError) as err:
        load_robot_config(config)
    assert str(err.value).startswith(
        f'{tmp_path / "edited.urdf"}: none of the 8 links below joint(s) joint_1 carries mass '
        '(8 without <inertial>, 0 of mass 0)'
    )


def test_a_zero_axis_is_refused_naming_joint_and_file(tmp_path: Path, write_config) -> None:
    config = _mabi(
        tmp_path,
        write_config,
        lambda t: t.replace(
            '<axis xyz="1 0 0"/>\n    <limit lower="-6"',
            '<axis xyz="0 0 0"/>\n    <limit lower="-6"',
        ),
    )
    with pytest.raises(RobotModelError) as err:
        load_robot_config(config)
    assert str(err.value) == (
        f"{tmp_path / 'edited.urdf'}: joint joint_6: axis '0 0 0' has length 0, no direction "
        "for a revolute joint to move about or along; give its unit axis (such as '0 0 1')"
    )


@pytest.mark.parametrize('axis', ['0 0', 'x y z', '0 nan 1', '1 0 0 0'])
def test_an_axis_that_is_not_three_finite_numbers_is_refused(
    tmp_path: Path, write_config, axis: str
) -> None:
    config = _mabi(
        tmp_path,
        write_config,
        lambda t: t.replace('<axis xyz="0 1 0"/>', f'<axis xyz="{axis}"/>', 1),
    )
    with pytest.raises(
        RobotModelError, match=r'joint joint_2: axis .* is not three finite numbers'
    ):
        load_robot_config(config)


def test_a_driven_mimic_joint_is_refused_naming_both_joints_and_the_config(
    tmp_path: Path, write_config
) -> None:
    mimic = '<mimic joint="joint_5" multiplier="1.0" offset="0"/>'
    config = _mabi(
        tmp_path,
        write_config,
        lambda t: t.replace('effort="650"/>', f'effort="650"/>\n    {mimic}'),
    )
    with pytest.raises(RobotModelError) as err:
        load_robot_config(config)
    message = str(err.value)
    assert message.startswith(
        f'{tmp_path / "edited.urdf"}: joint joint_6 mimics joint_5 (<mimic joint="joint_5">) '
        f'but the robot config {config} lists it among the driven joints'
    )
    assert 'remove the <mimic> if the joint has its own drive' in message


# -- what ships loads without a word --------------------------------------------------------------
@pytest.mark.parametrize('name', ['mabi_max100', 'ur5', 'panda'])
def test_the_shipped_robots_load_and_build_without_a_warning(
    name: str, monkeypatch: pytest.MonkeyPatch, caplog
) -> None:
    from id_learning.physics import RigidBodyDynamics

    monkeypatch.setattr(urdf_checks, '_CHECKED', {})  # checked afresh: its warnings logged
    with caplog.at_level(logging.WARNING):
        robot = load_robot_config(REPO / 'config' / f'{name}.yaml')
        RigidBodyDynamics.from_config(robot)
        assert check_urdf(robot.urdf_path, robot.joints, robot.locked_joints) == []
    assert caplog.records == []


@pytest.mark.parametrize('name', ['twin_default', 'twin_rigid_body'])
def test_the_twins_robots_load_and_build_without_a_warning(
    name: str, monkeypatch: pytest.MonkeyPatch, caplog
) -> None:
    from id_learning.physics import RigidBodyDynamics
    from id_learning.twin.simulate import load_twin_config

    monkeypatch.setattr(urdf_checks, '_CHECKED', {})
    with caplog.at_level(logging.WARNING):
        twin = load_twin_config(REPO / 'config' / f'{name}.yaml')
        RigidBodyDynamics.from_config(twin.robot)
    assert caplog.records == []


def test_mabi_joint_axes_are_unit_and_no_joint_mimics() -> None:
    """The shipped URDF passes the checks by a margin, not by a rounding."""
    from xml.etree import ElementTree

    for joint in ElementTree.parse(URDF).getroot().iter('joint'):
        assert joint.find('mimic') is None
        axis = joint.find('axis')
        if axis is not None:
            length = np.linalg.norm([float(x) for x in axis.get('xyz').split()])
            assert length == pytest.approx(1.0)
    assert urdf_checks.MIN_AXIS_LENGTH < 1e-3
    assert tuple(load_robot_config(REPO / 'config/mabi_max100.yaml').joints) == MABI_JOINTS


# -- names given twice (probe 15, A48: pinocchio said "does not contain a valid URDF model") -----
@pytest.mark.parametrize(
    ('old', 'new', 'said'),
    [
        (
            'joint name="joint_3"',
            'joint name="joint_2"',
            'joint name(s) given more than once: joint_2',
        ),
        ('link name="link_2"', 'link name="link_1"', 'link name(s) given more than once: link_1'),
    ],
)
def test_a_name_given_twice_is_refused_naming_it(old: str, new: str, said: str) -> None:
    box = Link(5.0, np.diag([0.1, 0.1, 0.1]))
    text = _arm([box] * 3, [Joint((0.0, 0.0, 0.3))] * 3)
    assert old in text
    with pytest.raises(RobotModelError, match=re.escape(said)):
        _check(text.replace(old, new, 1))
