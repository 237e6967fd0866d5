"""A twin config whose values no real robot or sensor has is refused where the value enters.

Probe 10's T_inertia_neg, T_inertia_triangle, T_cogging_p0, T_res_huge and T_mass_std_huge: each
refusal names the config file, the key and the value.
"""

from __future__ import annotations

from copy import deepcopy
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from id_learning.config_io import float_vector
from id_learning.errors import ConfigError
from id_learning.robot import load_robot_config
from id_learning.robot.drives import amperes_per_newton_metre
from id_learning.twin import load_twin_config, true_dynamics
from id_learning.twin.bounds import MAX_RESOLUTION_SHARE, check_drawn_masses, check_measurement
from id_learning.twin.effects import (
    MAX_MASS_REL_STD,
    effects_from_dict,
    non_positive_mass_chance,
)
from id_learning.twin.simulate import random_streams

REPO = Path(__file__).resolve().parents[2]
JOINTS = tuple(f'joint_{j}' for j in range(1, 7))
DEFAULT = yaml.safe_load((REPO / 'config/twin_default.yaml').read_text(encoding='utf-8'))


def _config_file(tmp_path: Path, change: dict[str, Any]) -> Path:
    """config/twin_default.yaml with ``change`` merged into its sections, as a file."""
    data = deepcopy(DEFAULT)
    data['robot'] = str(REPO / 'config/mabi_max100.yaml')
    for section, values in change.items():
        for key, value in values.items():
            if section in ('measurement', 'excitation'):
                data[section][key] = value
            else:
                data['effects'][section][key] = value
    path = tmp_path / 'twin.yaml'
    path.write_text(yaml.safe_dump(data), encoding='utf-8')
    return path


@pytest.mark.parametrize(
    ('change', 'match'),
    [
        ({'payload_mass': {'inertia_kgm2': [0.12, -0.35, 0.35]}},
         r'effects\.payload_mass\.inertia_kgm2: \[0\.12, -0\.35, 0\.35\]: .*negative moment'),
        ({'payload_mass': {'inertia_kgm2': [0.01, 0.01, 5.0]}},
         r'effects\.payload_mass\.inertia_kgm2: \[0\.01, 0\.01, 5\.0\]: .*triangle inequality'),
        ({'cogging': {'periods_per_motor_turn': 0}},
         r'effects\.cogging\.periods_per_motor_turn: expected an integer >= 1.*got 0'),
        ({'cogging': {'periods_per_motor_turn': True}},
         r'effects\.cogging\.periods_per_motor_turn: .*got True'),
        ({'measurement': {'current_resolution_a': 50.0}},
         r'measurement\.current_resolution_a: 50 A for joint_1 is more than 1% .*all 0'),
        ({'measurement': {'current_noise_std_a': 5.0}},
         r'measurement\.current_noise_std_a: 5 A for joint_1 is more than 10%'),
        ({'inertial_parameter_error': {'mass_rel_std': 5.0}},
         r'effects\.inertial_parameter_error\.mass_rel_std: must be <= 0\.25, got 5: .*42 %'),
        ({'excitation': {'home': [10.0, 0, 0, 0, -9.0, 0]}},
         r'excitation\.home must lie strictly inside the position limits of the robot config: '
         r'joint_1 10 rad, its limits \[-3, 3\] rad; joint_5 -9 rad, its limits'),
    ],
)  # fmt: skip
def test_a_value_no_robot_or_sensor_has_is_refused_naming_file_key_and_value(
    tmp_path: Path, change: dict[str, Any], match: str
) -> None:
    with pytest.raises(ConfigError, match=rf'^{tmp_path / "twin.yaml"}: {match}'):
        load_twin_config(_config_file(tmp_path, change))


def test_the_default_twin_is_within_every_bound() -> None:
    config = load_twin_config(REPO / 'config/twin_default.yaml')
    assert config.effects.enabled('cogging')
    assert config.measurement.current_resolution_a.max() > 0  # the bound is tested, not void


# -- payload inertia: accepted exactly when some body has it --------------------------------------
def _payload(inertia: list[float]) -> dict[str, Any]:
    return {'payload_mass': {'enabled': True, 'mass_kg': 10.0, 'inertia_kgm2': inertia}}


@settings(max_examples=60, deadline=None)
@given(
    masses=st.lists(st.floats(0.01, 10.0), min_size=1, max_size=6),
    points=st.lists(st.tuples(*(st.floats(-0.5, 0.5) for _ in range(3))), min_size=6, max_size=6),
)
def test_the_principal_moments_of_any_body_of_point_masses_are_accepted(
    masses: list[float], points: list[tuple[float, float, float]]
) -> None:
    """Two ways to one inertia: a body built of point masses, then its moments as config."""
    m = np.array(masses)
    r = np.array(points[: len(masses)])
    r = r - (m[:, None] * r).sum(axis=0) / m.sum()  # about the centre of mass
    pairs = zip(m, r, strict=True)
    inertia = sum(mk * (rk @ rk * np.eye(3) - np.outer(rk, rk)) for mk, rk in pairs)
    moments = np.clip(np.linalg.eigvalsh(inertia), 0.0, None).tolist()
    effects = effects_from_dict(_payload(moments), JOINTS)
    assert effects.enabled('payload_mass')


@settings(max_examples=60, deadline=None)
@given(
    small=st.lists(st.floats(0.0, 1.0), min_size=2, max_size=2),
    excess=st.floats(1e-3, 10.0),
    order=st.permutations(range(3)),
)
def test_moments_beyond_the_triangle_inequality_are_refused_in_any_order(
    small: list[float], excess: float, order: list[int]
) -> None:
    moments = [*small, small[0] + small[1] + excess]
    given_moments = [moments[k] for k in order]
    with pytest.raises(ConfigError, match=r'payload_mass\.inertia_kgm2: .*triangle inequality'):
        effects_from_dict(_payload(given_moments), JOINTS)


# -- the current resolution: a bound on each joint's full scale ---------------------------------
@settings(max_examples=40, deadline=None)
@given(share=st.floats(0.0, 0.05), joint=st.integers(0, 5))
def test_a_current_step_is_accepted_exactly_up_to_its_share_of_the_full_scale(
    share: float, joint: int
) -> None:
    assume(abs(share - MAX_RESOLUTION_SHARE) > 1e-12)  # a product's rounding decides there
    robot = load_robot_config(REPO / 'config/mabi_max100.yaml')
    full = robot.limits.torque * amperes_per_newton_metre(robot.drives)
    values = {key: np.zeros(6) for key in ('current_noise_std_a', 'joint_torque_noise_std',
                                           'velocity_noise_std')}  # fmt: skip
    values['current_resolution_a'] = np.zeros(6)
    values['current_resolution_a'][joint] = share * full[joint]
    if share <= MAX_RESOLUTION_SHARE:
        check_measurement(values, robot, 'twin.yaml')
    else:
        with pytest.raises(ConfigError, match=rf'current_resolution_a: .* for {JOINTS[joint]} '):
            check_measurement(values, robot, 'twin.yaml')


# -- drawn masses ---------------------------------------------------------------------------------
def test_the_mass_bound_makes_a_non_positive_mass_a_four_sigma_draw() -> None:
    assert non_positive_mass_chance(MAX_MASS_REL_STD) == pytest.approx(3.17e-5, rel=1e-2)
    assert non_positive_mass_chance(5.0) > 0.4  # the probe's value: nearly every other link


def test_a_draw_that_gives_a_body_no_mass_is_refused_naming_the_key_and_the_seed(
    tmp_path: Path,
) -> None:
    # robot_seed 14814 draws -4.13 standard deviations for the second body: at the bound
    # 0.25, a scale of 1 - 1.03 < 0.
    seed = 14814
    assert random_streams(seed)[1].standard_normal(6)[1] < -1 / MAX_MASS_REL_STD
    path = _config_file(tmp_path, {'inertial_parameter_error': {'mass_rel_std': 0.25}})
    config = load_twin_config(path, {'robot_seed': seed})
    with pytest.raises(
        ConfigError,
        match=rf'^{path}: effects\.inertial_parameter_error\.mass_rel_std: 0\.25 draws a mass of '
        r'-.* kg for the body moved by joint_2 .*robot_seed 14814',
    ):
        true_dynamics(config, random_streams(seed)[1])


def test_a_draw_leaves_massless_bodies_alone() -> None:
    urdf = np.array([0.0, 5.0])
    check_drawn_masses(urdf, np.array([0.0, 4.0]), ['a', 'b'], mass_rel_std=0.1, robot_seed=0,
                       where='twin.yaml')  # fmt: skip


@pytest.mark.parametrize(
    ('key', 'what'),
    [
        ('inertia_kgm2',
         'the principal moments of inertia Ixx, Iyy, Izz about the centre of mass [kg*m^2]'),
        ('com_m', "the x, y, z of the centre of mass in the robot's payload frame [m]"),
    ],
)  # fmt: skip
def test_a_payload_vector_of_the_wrong_length_says_what_its_three_values_are(tmp_path, key, what):
    # Probe T20: 2 inertia values were refused as 'expected 3 values (one per joint)'.
    path = _config_file(tmp_path, {'payload_mass': {key: [0.1, 0.2]}})
    with pytest.raises(ConfigError) as err:
        load_twin_config(path)
    message = str(err.value)
    assert message.startswith(f'{path}: effects.payload_mass.{key}: expected 3 values ({what})')
    assert 'per joint' not in message
    assert 'got [0.1, 0.2]' in message


def test_a_per_joint_vector_of_the_wrong_length_still_says_one_per_joint(tmp_path):
    path = _config_file(tmp_path, {'joint_offset': {'offset': [0.0] * 5}})
    with pytest.raises(
        ConfigError, match=r'effects\.joint_offset\.offset: expected 6 values \(one per joint\)'
    ):
        load_twin_config(path)


def test_float_vector_names_what_its_values_are():
    with pytest.raises(ConfigError, match=r'^k: expected 3 values \(x, y, z\), got \[1, 2\]$'):
        float_vector([1, 2], 'k', 3, each='x, y, z')
    assert float_vector([1, 2, 3], 'k', 3, each='x, y, z').tolist() == [1.0, 2.0, 3.0]
