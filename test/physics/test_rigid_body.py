"""RigidBodyDynamics against pinocchio called directly, closed forms and the MABI URDF itself."""

from __future__ import annotations

import re
import subprocess
import sys
import xml.etree.ElementTree as ET
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
import pytest
from pinocchio_reference import (
    G_WORLD,
    N_STATES,
    random_states,
    reference_model,
    urdf_axes,
    velocity_index,
    world_axes,
)

from id_learning.errors import RobotModelError
from id_learning.physics import RigidBodyDynamics, build_pinocchio_model
from id_learning.robot import RobotConfig, load_robot_config

REPO = Path(__file__).resolve().parents[2]
MABI_URDF = REPO / 'urdf/mabi_max100.urdf'


# -- agreement with pinocchio, and identities between computation paths --------------------------
def test_rnea_equals_pinocchio_rnea_on_an_independent_model(
    robot_name: str,
    robot_configs: dict[str, RobotConfig],
    robot_dynamics: dict[str, RigidBodyDynamics],
) -> None:
    config, dynamics = robot_configs[robot_name], robot_dynamics[robot_name]
    model = reference_model(config)
    data = model.createData()
    index = velocity_index(model, config.joints)
    assert model.nv == config.n_joints
    q, v, a = random_states(config, np.random.default_rng(11))

    tau = dynamics.rnea(q, v, a)

    expected = np.empty_like(q)
    for k in range(len(q)):
        q_pin, v_pin, a_pin = (np.zeros(model.nv) for _ in range(3))
        q_pin[index], v_pin[index], a_pin[index] = q[k], v[k], a[k]
        expected[k] = pin.rnea(model, data, q_pin, v_pin, a_pin)[index]
    assert np.abs(expected).max() > 1.0  # not a vacuous comparison of zeros
    np.testing.assert_allclose(tau, expected, rtol=1e-12, atol=1e-9)


def test_regressor_times_inertial_parameters_equals_rnea(
    robot_name: str,
    robot_configs: dict[str, RobotConfig],
    robot_dynamics: dict[str, RigidBodyDynamics],
) -> None:
    config, dynamics = robot_configs[robot_name], robot_dynamics[robot_name]
    q, v, a = random_states(config, np.random.default_rng(12))

    regressor = dynamics.regressor(q, v, a)
    parameters = dynamics.inertial_parameters()

    assert regressor.shape == (N_STATES, config.n_joints, 10 * dynamics.n_bodies)
    assert parameters.shape == (10 * dynamics.n_bodies,)
    tau = dynamics.rnea(q, v, a)
    scale = np.abs(tau).max()
    np.testing.assert_allclose(regressor @ parameters, tau, rtol=0, atol=1e-9 * scale)


def test_mass_matrix_coriolis_and_gravity_sum_to_rnea(
    robot_name: str,
    robot_configs: dict[str, RobotConfig],
    robot_dynamics: dict[str, RigidBodyDynamics],
) -> None:
    config, dynamics = robot_configs[robot_name], robot_dynamics[robot_name]
    q, v, a = random_states(config, np.random.default_rng(13))

    mass = dynamics.mass_matrix(q)
    total = np.einsum('bij,bj->bi', mass, a) + dynamics.coriolis(q, v) + dynamics.gravity(q)

    tau = dynamics.rnea(q, v, a)
    np.testing.assert_allclose(total, tau, rtol=0, atol=1e-9 * np.abs(tau).max())


def test_mass_matrix_columns_equal_rnea_of_unit_accelerations(
    robot_name: str,
    robot_configs: dict[str, RobotConfig],
    robot_dynamics: dict[str, RigidBodyDynamics],
) -> None:
    # CRBA and RNEA are different algorithms: M e_j = rnea(q, 0, e_j) - g(q).
    config, dynamics = robot_configs[robot_name], robot_dynamics[robot_name]
    q, _, _ = random_states(config, np.random.default_rng(14), count=10)
    n = config.n_joints
    zero = np.zeros_like(q)

    mass = dynamics.mass_matrix(q)

    gravity = dynamics.gravity(q)
    for j in range(n):
        unit = np.zeros_like(q)
        unit[:, j] = 1.0
        column = dynamics.rnea(q, zero, unit) - gravity
        np.testing.assert_allclose(mass[:, :, j], column, rtol=1e-10, atol=1e-10)


def test_mass_matrix_is_symmetric_positive_definite(
    robot_name: str,
    robot_configs: dict[str, RobotConfig],
    robot_dynamics: dict[str, RigidBodyDynamics],
) -> None:
    config, dynamics = robot_configs[robot_name], robot_dynamics[robot_name]
    q, _, _ = random_states(config, np.random.default_rng(15))

    mass = dynamics.mass_matrix(q)

    assert mass.shape == (N_STATES, config.n_joints, config.n_joints)
    np.testing.assert_array_equal(mass, np.swapaxes(mass, 1, 2))
    assert np.linalg.eigvalsh(mass).min() > 0.0


def test_zero_velocity_and_acceleration_give_gravity_torque_only(
    robot_name: str,
    robot_configs: dict[str, RobotConfig],
    robot_dynamics: dict[str, RigidBodyDynamics],
) -> None:
    config, dynamics = robot_configs[robot_name], robot_dynamics[robot_name]
    q, _, _ = random_states(config, np.random.default_rng(16))
    zero = np.zeros_like(q)

    gravity = dynamics.gravity(q)

    assert np.abs(gravity).max() > 1.0
    np.testing.assert_allclose(dynamics.rnea(q, zero, zero), gravity, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(dynamics.coriolis(q, zero), zero)


def test_coriolis_torque_is_quadratic_in_velocity(
    robot_name: str,
    robot_configs: dict[str, RobotConfig],
    robot_dynamics: dict[str, RigidBodyDynamics],
) -> None:
    config, dynamics = robot_configs[robot_name], robot_dynamics[robot_name]
    q, v, _ = random_states(config, np.random.default_rng(17))

    coriolis = dynamics.coriolis(q, v)

    assert np.abs(coriolis).max() > 1e-3
    np.testing.assert_allclose(dynamics.coriolis(q, 3.0 * v), 9.0 * coriolis, atol=1e-9)
    np.testing.assert_allclose(dynamics.coriolis(q, -v), coriolis, atol=1e-9)


def test_gravity_argument_scales_gravity_torque(
    robot_configs: dict[str, RobotConfig], robot_dynamics: dict[str, RigidBodyDynamics]
) -> None:
    config, dynamics = robot_configs['mabi_max100'], robot_dynamics['mabi_max100']
    q, _, _ = random_states(config, np.random.default_rng(18), count=5)
    nominal = dynamics.gravity(q)

    doubled = RigidBodyDynamics(dynamics.model, config.joints, gravity=2.0 * G_WORLD)

    np.testing.assert_allclose(doubled.gravity(q), 2.0 * nominal, rtol=1e-12)
    # The wrapped model is copied, so the nominal robot keeps its gravity.
    np.testing.assert_array_equal(dynamics.gravity(q), nominal)


def test_permuted_joint_order_permutes_every_output(
    robot_name: str,
    robot_configs: dict[str, RobotConfig],
    robot_dynamics: dict[str, RigidBodyDynamics],
) -> None:
    config, dynamics = robot_configs[robot_name], robot_dynamics[robot_name]
    rng = np.random.default_rng(19)
    perm = rng.permutation(config.n_joints)
    assert np.any(perm != np.arange(config.n_joints))
    limits = replace(
        config.limits,
        **{key: getattr(config.limits, key)[perm] for key in config.limits.__dataclass_fields__},
    )
    permuted = RigidBodyDynamics.from_config(
        replace(config, joints=tuple(config.joints[i] for i in perm), limits=limits)
    )
    q, v, a = random_states(config, rng, count=10)

    assert permuted.joints == tuple(config.joints[i] for i in perm)
    np.testing.assert_allclose(
        permuted.rnea(q[:, perm], v[:, perm], a[:, perm]), dynamics.rnea(q, v, a)[:, perm]
    )
    np.testing.assert_allclose(permuted.gravity(q[:, perm]), dynamics.gravity(q)[:, perm])
    np.testing.assert_allclose(
        permuted.coriolis(q[:, perm], v[:, perm]), dynamics.coriolis(q, v)[:, perm]
    )
    np.testing.assert_allclose(
        permuted.mass_matrix(q[:, perm]), dynamics.mass_matrix(q)[:, perm][:, :, perm]
    )


def test_single_sample_returns_single_sample_shapes(
    robot_name: str,
    robot_configs: dict[str, RobotConfig],
    robot_dynamics: dict[str, RigidBodyDynamics],
) -> None:
    config, dynamics = robot_configs[robot_name], robot_dynamics[robot_name]
    q, v, a = random_states(config, np.random.default_rng(20), count=3)
    n = config.n_joints

    assert dynamics.rnea(q[1], v[1], a[1]).shape == (n,)
    assert dynamics.gravity(q[1]).shape == (n,)
    assert dynamics.coriolis(q[1], v[1]).shape == (n,)
    assert dynamics.mass_matrix(q[1]).shape == (n, n)
    assert dynamics.regressor(q[1], v[1], a[1]).shape == (n, 10 * dynamics.n_bodies)
    np.testing.assert_array_equal(dynamics.rnea(q[1], v[1], a[1]), dynamics.rnea(q, v, a)[1])
    np.testing.assert_array_equal(dynamics.mass_matrix(q[1]), dynamics.mass_matrix(q)[1])


def test_mismatched_array_shapes_are_refused(
    robot_configs: dict[str, RobotConfig], robot_dynamics: dict[str, RigidBodyDynamics]
) -> None:
    dynamics = robot_dynamics['mabi_max100']
    # 6 samples of 7 joints hold 42 values, which also reshape into 7 samples of 6 joints.
    with pytest.raises(ValueError, match=r'expected arrays of one shape \(\.\.\., 6\)'):
        dynamics.rnea(np.zeros((6, 7)), np.zeros((6, 7)), np.zeros((6, 7)))
    with pytest.raises(ValueError, match=r'expected arrays of one shape \(\.\.\., 6\)'):
        dynamics.rnea(np.zeros((4, 6)), np.zeros((3, 6)), np.zeros((4, 6)))


def test_wrong_joint_count_is_refused_with_the_explicit_message(
    robot_dynamics: dict[str, RigidBodyDynamics],
) -> None:
    with pytest.raises(ValueError, match=r'expected arrays of one shape \(\.\.\., 6\)'):
        robot_dynamics['mabi_max100'].gravity(np.zeros((4, 7)))


def test_batch_of_windows_keeps_its_leading_axes(
    robot_configs: dict[str, RobotConfig], robot_dynamics: dict[str, RigidBodyDynamics]
) -> None:
    config, dynamics = robot_configs['mabi_max100'], robot_dynamics['mabi_max100']
    q, v, a = random_states(config, np.random.default_rng(21), count=6)

    tau = dynamics.rnea(q.reshape(2, 3, 6), v.reshape(2, 3, 6), a.reshape(2, 3, 6))

    assert tau.shape == (2, 3, 6)
    np.testing.assert_array_equal(tau.reshape(6, 6), dynamics.rnea(q, v, a))


# -- URDF / config mismatch ----------------------------------------------------------------------
def test_config_joint_missing_from_the_urdf_is_refused(
    robot_configs: dict[str, RobotConfig],
) -> None:
    config = robot_configs['mabi_max100']
    joints = (*config.joints[:5], 'joint_7')

    with pytest.raises(RobotModelError, match=r"the URDF has no joint\(s\) \['joint_7'\]"):
        RigidBodyDynamics.from_config(replace(config, joints=joints))


def test_urdf_joint_neither_actuated_nor_locked_is_refused(
    robot_configs: dict[str, RobotConfig],
) -> None:
    config = robot_configs['panda']

    with pytest.raises(
        RobotModelError, match=r"\['panda_finger_joint1', 'panda_finger_joint2'\] are neither"
    ):
        build_pinocchio_model(replace(config, locked_joints={}))
    with pytest.raises(RobotModelError, match=r"\['joint_6'\] are neither"):
        build_pinocchio_model(
            replace(robot_configs['mabi_max100'], joints=robot_configs['mabi_max100'].joints[:5])
        )


def test_unknown_locked_joint_and_payload_frame_are_refused(
    robot_configs: dict[str, RobotConfig],
) -> None:
    config = robot_configs['mabi_max100']
    with pytest.raises(RobotModelError, match=r"no joint\(s\) \['gripper'\]"):
        build_pinocchio_model(replace(config, locked_joints={'gripper': 0.0}))
    with pytest.raises(RobotModelError, match=r"payload_frame 'spindle'"):
        build_pinocchio_model(replace(config, payload_frame='spindle'))


def test_dynamics_refuses_a_model_whose_joints_differ(
    robot_configs: dict[str, RobotConfig], robot_dynamics: dict[str, RigidBodyDynamics]
) -> None:
    model = robot_dynamics['mabi_max100'].model
    with pytest.raises(RobotModelError, match='do not match the config joints'):
        RigidBodyDynamics(model, robot_configs['ur5'].joints)


def test_panda_model_has_seven_joints_with_fingers_locked(
    robot_dynamics: dict[str, RigidBodyDynamics],
) -> None:
    model = robot_dynamics['panda'].model
    assert model.nq == model.nv == 7
    assert list(model.names[1:]) == [f'panda_joint{i}' for i in range(1, 8)]


def urdf_link_inertials() -> dict[str, tuple[float, np.ndarray]]:
    """Mass [kg] and inertia tensor [kg*m^2] of every MABI link that has an inertial."""
    inertials = {}
    for link in ET.parse(MABI_URDF).getroot().findall('link'):
        inertial = link.find('inertial')
        if inertial is None:
            continue
        mass = float(inertial.find('mass').get('value'))
        i = {key: float(value) for key, value in inertial.find('inertia').attrib.items()}
        tensor = np.array(
            [
                [i['ixx'], i['ixy'], i['ixz']],
                [i['ixy'], i['iyy'], i['iyz']],
                [i['ixz'], i['iyz'], i['izz']],
            ]
        )
        inertials[link.get('name')] = (mass, tensor)
    return inertials


def test_mabi_masses_match_the_design_totals(robot_dynamics: dict[str, RigidBodyDynamics]) -> None:
    inertials = urdf_link_inertials()
    urdf_total = sum(mass for mass, _ in inertials.values())
    urdf_moving = urdf_total - inertials['base_link'][0]

    assert len(inertials) == 8  # base, six links, flange
    assert urdf_total == pytest.approx(1250.0, abs=1.0)
    assert robot_dynamics['mabi_max100'].total_moving_mass() == pytest.approx(813.1, abs=0.5)
    assert robot_dynamics['mabi_max100'].total_moving_mass() == pytest.approx(
        urdf_moving, abs=1e-9
    )


def test_every_mabi_link_inertia_is_physically_consistent() -> None:
    inertials = urdf_link_inertials()
    assert inertials
    for name, (mass, tensor) in inertials.items():
        assert mass > 0.0, name
        principal = np.linalg.eigvalsh(tensor)
        assert principal.min() > 0.0, name
        diagonal = np.diag(tensor)
        for moments in (principal, diagonal):
            for k in range(3):
                others = moments.sum() - moments[k]
                assert others >= moments[k] * (1.0 - 1e-9), (name, moments)


def test_mabi_wrist_axes_meet_in_one_point(
    robot_configs: dict[str, RobotConfig],
) -> None:
    config = robot_configs['mabi_max100']
    model = reference_model(config)
    data = model.createData()
    axes = urdf_axes(config.urdf_path)
    index = velocity_index(model, config.joints)
    q, _, _ = random_states(config, np.random.default_rng(27), count=20)

    for q_k in q:
        q_pin = np.zeros(model.nq)
        q_pin[index] = q_k
        pin.forwardKinematics(model, data, q_pin)
        lines = [world_axes(model, data, axes, f'joint_{i}') for i in (4, 5, 6)]
        center = lines[1][0]  # the origin of joint_5
        for origin, axis in lines:
            # Distance from the wrist centre to the axis line.
            assert np.linalg.norm(np.cross(axis, center - origin)) < 1e-12
        # A real wrist: consecutive axes are not parallel.
        assert np.linalg.norm(np.cross(lines[0][1], lines[1][1])) > 0.99
        assert np.linalg.norm(np.cross(lines[1][1], lines[2][1])) > 0.99
    # The wrist centre is not at the joint_4 origin, so the check above is not trivial.
    assert np.linalg.norm(lines[0][0] - center) > 0.5


def test_urdf_generator_reproduces_the_committed_urdf(tmp_path: Path) -> None:
    output = tmp_path / 'x.urdf'

    result = subprocess.run(
        [sys.executable, str(REPO / 'tools/make_mabi_urdf.py'), '--output', str(output)],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )

    assert result.returncode == 0, result.stderr
    assert 'total mass 1250 kg' in result.stdout
    assert output.read_bytes() == MABI_URDF.read_bytes()


@pytest.mark.parametrize(
    'name',
    [
        'mabi_max100',
        'ur5',
        'panda',
    ],
)
def test_config_limits_lie_within_the_urdf_limits(
    name: str, robot_configs: dict[str, RobotConfig]
) -> None:
    config = robot_configs[name]
    urdf_limits = {}
    for joint in ET.parse(config.urdf_path).getroot().findall('joint'):
        limit = joint.find('limit')
        if limit is not None:
            urdf_limits[joint.get('name')] = {k: float(v) for k, v in limit.attrib.items()}

    for i, joint in enumerate(config.joints):
        urdf = urdf_limits[joint]
        assert config.limits.position_lower[i] >= urdf['lower'] - 1e-9, joint
        assert config.limits.position_upper[i] <= urdf['upper'] + 1e-9, joint
        assert config.limits.velocity[i] <= urdf['velocity'] + 1e-9, joint
        assert config.limits.torque[i] <= urdf['effort'] + 1e-9, joint


def test_config_limits_wider_than_the_urdf_are_refused(write_config: Any) -> None:
    path = write_config('mabi_max100', set={'limits.velocity': [1.7, 1.4, 1.45, 2.35, 9.0, 3.45]})
    config = load_robot_config(path)
    with pytest.raises(
        RobotModelError, match=r'limits\.velocity of joint_5 \(9\) lies outside the URDF'
    ):
        RigidBodyDynamics.from_config(config)


def test_a_urdf_whose_fixed_joints_are_named_like_their_links_builds_reduces_and_takes_payloads(
    tmp_path, mabi
):
    """Vendor URDFs name fixed joints after their child links; pinocchio then cannot look either
    frame up by name ("Several frames match the filter"), also inside buildReducedModel."""
    from id_learning.physics.rigid_body import _unique_frame_names

    text = MABI_URDF.read_text()
    vendor = tmp_path / 'vendor.urdf'
    vendor.write_text(
        text.replace('"flange_joint"', '"flange"').replace('"tool0_joint"', '"tool0"')
    )
    plain = pin.buildModelFromUrdf(str(vendor))
    with pytest.raises(ValueError, match='Several frames'):
        plain.getFrameId('flange')  # the fault, as pinocchio has it
    ours = RigidBodyDynamics.from_config(replace(mabi, urdf_path=vendor))
    reference = RigidBodyDynamics.from_config(mabi)
    rng = np.random.default_rng(3)
    q, v, a = (rng.uniform(-1.0, 1.0, (4, 6)) for _ in range(3))
    np.testing.assert_array_equal(ours.rnea(q, v, a), reference.rnea(q, v, a))
    payload = (12.0, np.array([0.1, 0.0, 0.05]), np.diag([0.1, 0.2, 0.3]))
    np.testing.assert_allclose(
        ours.with_payload('flange', *payload).rnea(q, v, a),
        reference.with_payload('flange', *payload).rnea(q, v, a),
        rtol=1e-12,
    )
    assert _unique_frame_names(MABI_URDF) is None  # nothing to rename: the file as it is
    renamed = _unique_frame_names(vendor)
    assert renamed is not None
    full = pin.buildModelFromXML(renamed)
    reduced = pin.buildReducedModel(full, [full.getJointId('joint_6')], pin.neutral(full))
    assert reduced.nv == 5


# -- masses and inertias no drive could move -----------------------------------------------------
def _mabi_with(tmp_path: Path, mabi: RobotConfig, old: str, new: str) -> RobotConfig:
    text = MABI_URDF.read_text()
    assert text.count(old) == 1
    urdf = tmp_path / 'edited.urdf'
    urdf.write_text(text.replace(old, new))
    return replace(mabi, urdf_path=urdf)


def test_a_mass_gravity_loads_beyond_100_times_the_torque_limit_is_refused_in_one_line(
    tmp_path: Path, mabi: RobotConfig
) -> None:
    huge = _mabi_with(tmp_path, mabi, '<mass value="150"/>', '<mass value="1e30"/>')
    with pytest.raises(RobotModelError) as err:
        build_pinocchio_model(huge)
    message = str(err.value)
    assert re.match(
        rf'{re.escape(str(huge.urdf_path))}: joint joint_2: gravity alone loads it with '
        r'[0-9.e+]+ N\*m at q = \[.*\] rad, [0-9.e+]+ times its URDF effort 15000 N\*m; '
        r'beyond 100 times no drive could move the arm',
        message,
    )
    assert message.endswith('the heaviest link it moves is link_3 (1e+30 kg)')
    assert '\n' not in message


def test_an_inertia_no_drive_could_accelerate_is_refused(
    tmp_path: Path, mabi: RobotConfig
) -> None:
    link_3 = 'ixx="4.9964" ixy="0" ixz="-1.0061333" iyy="7.07" iyz="0" izz="5.6256"'
    huge = _mabi_with(
        tmp_path, mabi, link_3, 'ixx="1e9" ixy="0" ixz="0" iyy="1e9" iyz="0" izz="1e9"'
    )
    with pytest.raises(
        RobotModelError,
        match=r'joint joint_\d: accelerating it at its limit [0-9.]+ rad/s\^2 needs .* times its '
        r'URDF effort',
    ):
        build_pinocchio_model(huge)


@pytest.mark.parametrize('scale', [0.01, 1.0, 20.0])
def test_masses_within_a_hundred_times_what_the_drives_hold_are_accepted(
    tmp_path: Path, mabi: RobotConfig, scale: float
) -> None:
    """Every link mass and inertia scaled: up to 20 x the MABI stays below the 100 x bound."""
    root = ET.parse(MABI_URDF).getroot()
    for inertial in root.iter('inertial'):
        mass, inertia = inertial.find('mass'), inertial.find('inertia')
        mass.set('value', repr(scale * float(mass.get('value'))))
        for key, value in inertia.attrib.items():
            inertia.set(key, repr(scale * float(value)))
    urdf = tmp_path / 'scaled.urdf'
    urdf.write_text(ET.tostring(root, encoding='unicode'))
    model = build_pinocchio_model(replace(mabi, urdf_path=urdf))
    shipped = build_pinocchio_model(mabi)
    assert sum(model.inertias[i].mass for i in range(1, model.njoints)) == pytest.approx(
        scale * sum(shipped.inertias[i].mass for i in range(1, shipped.njoints))
    )


def test_the_torque_limit_weighed_against_is_the_urdfs_effort_else_the_configs(
    tmp_path: Path, mabi: RobotConfig
) -> None:
    tiny = replace(mabi, limits=replace(mabi.limits, torque=np.full(6, 1.0)))
    build_pinocchio_model(tiny)  # the URDF's efforts hold the arm: its config's limit is no mass
    no_effort = MABI_URDF.read_text().replace(' effort="15000"', ' effort="0"')
    urdf = tmp_path / 'no_effort.urdf'
    urdf.write_text(no_effort)
    build_pinocchio_model(replace(mabi, urdf_path=urdf))  # the config's 15000 N*m hold it too
    with pytest.raises(
        RobotModelError, match=r'joint joint_2: .* times limits\.torque of the robot config 1 N\*m'
    ):
        build_pinocchio_model(replace(tiny, urdf_path=urdf))
